"""Meter configuration from a TOML file (``--config``).

Example (see ``configs/example.toml``)::

    [meter]
    bed = "color"          # "color" (union of classes) or "dark" (backlit drum)
    min_share = 0.005      # a class below this share of the drum's pixels -> NaN + flag
    opening = false        # true: class opening (drops thin rims/gaps of JPEG chroma blur)
    island_px = 0          # > 0: islands of a class up to this many px inside another take its class
    roi = [320, 318, 312]  # optional manual drum circle cx, cy, r (px)

    [[classes]]            # two or more counted classes; the MI uses the first two
    name = "blue"
    hsv = [[[95, 90, 50], [130, 255, 255]]]   # list of [[h,s,v] low, [h,s,v] high]
    display_bgr = [255, 80, 0]

A learned class (what ``classes suggest`` prints) has ``lab_mean``, ``lab_cov`` and
``lab_weight`` (one entry per Gaussian) and ``max_distance`` instead of ``hsv``;
``reject = true`` marks the learned background. Unknown keys, wrong types, non-finite
numbers and inverted HSV ranges are ``VisionError``s naming the key.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vision.colours import (
    DEFAULT_CLASSES,
    Classifier,
    ColourClass,
    LabComponent,
    check_class_set,
    counted_classes,
    is_learned,
    overlapping_classes,
)
from vision.errors import VisionError
from vision.meter import BED_MODES, Meter
from vision.photometric import check_class_reference, check_reference
from vision.roi import DrumROI

__all__ = ["MeterConfig", "config_to_toml", "load_config", "parse_config"]

_METER_KEYS = {"bed", "min_pixels", "min_share", "collapse_ratio", "history", "dark_v_max", "stride", "roi",
               "roi_kind", "half_w_px", "half_h_px", "opening", "erode", "light_reference", "camera_rotation_deg",
               "light_reference_classes", "island_px",
               "mirror"}  # erode: a clear error
_CLASS_KEYS = {"name", "hsv", "display_bgr", "lab_mean", "lab_cov", "lab_weight", "max_distance", "reject"}
_TOP_KEYS = {"meter", "classes", "drum", "particles", "drive", "endpoint"}
MIXER_KEYS = ("drum", "particles")  # the twin's tables (sim.mixer parses them; vision only hands them over)


@dataclass(frozen=True)
class MeterConfig:
    """Everything a ``Meter`` needs; ``roi=None`` means detect the drum (per frame size).

    ``classes`` may hold learned reject classes (never counted); ``warnings`` are notes for
    the user (e.g. overlapping HSV ranges), not errors."""

    classes: tuple[ColourClass, ...] = DEFAULT_CLASSES
    roi: DrumROI | None = None
    bed: str = "color"
    min_pixels: int = 50
    dark_v_max: int = 80
    stride: int = 1
    source: str = field(default="<defaults>", compare=False)
    min_share: float = 0.005
    collapse_ratio: float = 0.4
    history: int = 25
    warnings: tuple[str, ...] = field(default=(), compare=False)
    opening: bool = False
    """Class opening before the sums (see ``vision.meter.Meter``): JPEG chroma blur between
    particles of one hue; ``classes suggest`` sets it when it matters on its frames."""
    light_reference: tuple[tuple[float, ...], ...] | None = None
    """The light at set-up (``vision.photometric``: per-channel quantiles B, G, R of the drum's
    pixels); given, the meter tracks exposure and white balance against it."""
    light_reference_classes: tuple[tuple[float, ...], ...] | None = None
    """The same per class (no class, then each counted class; B, G, R quantiles; -1 = not seen)."""
    camera_rotation_deg: float = 0.0
    """How far the camera is turned: the image is gravity's view turned counter-clockwise by
    this (deg); the slope, curvature and overlay are given in gravity's frame."""
    mirror: bool = False
    """True when the drum is filmed through a mirror (the image is gravity's view flipped left-right, then turned)."""
    island_px: int = 0
    """The island filter (``vision.islands``): a component of one class of at most this many px
    enclosed by another class takes that class (the specular highlights of glossy particles);
    0 = off."""
    mixer_tables: dict = field(default_factory=dict, compare=False)
    """The config's ``[drum]`` and ``[[particles]]`` tables as read (the twin's mixer, parsed by
    ``sim.mixer.parse_mixer``); empty when the config has none."""
    drive_table: dict = field(default_factory=dict, compare=False)
    """The config's ``[drive]`` table as read (the mill's drive: ``control.modbus.link.drive_hz_per_rpm``
    parses it; vision only hands it over); empty when the config has none."""
    endpoint_table: dict = field(default_factory=dict, compare=False)
    """The config's ``[endpoint]`` table as read (the batch endpoint's settings:
    ``control.endpoint.endpoint_settings`` parses it; vision only hands it over); empty when none."""

    @property
    def is_default(self) -> bool:
        """True when no config was given (the paper's red and blue)."""
        return self.source == "<defaults>"

    @property
    def counted(self) -> tuple[ColourClass, ...]:
        """The measured classes (reject classes left out)."""
        return counted_classes(self.classes)

    def make_meter(self, roi: DrumROI | None = None, bed: str | None = None) -> Meter:
        """A fresh ``Meter``; ``roi``/``bed`` override the config (e.g. from the CLI)."""
        return Meter(
            self.classes, roi if roi is not None else self.roi, bed or self.bed, self.min_pixels,
            dark_v_max=self.dark_v_max, stride=self.stride, min_share=self.min_share,
            collapse_ratio=self.collapse_ratio, history=self.history, opening=self.opening,
            light_reference=None if self.light_reference is None else np.asarray(self.light_reference),
            light_reference_classes=(None if self.light_reference_classes is None
                                     else np.asarray(self.light_reference_classes)),
            camera_rotation_deg=self.camera_rotation_deg, mirror=self.mirror, island_px=self.island_px,
        )


def load_config(path: str | Path | None) -> MeterConfig:
    """Read a TOML config; ``None`` gives the defaults (red and blue, auto ROI)."""
    if path is None:
        return MeterConfig()
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such config file: {p}")
    return parse_config(p.read_text(encoding="utf-8", errors="replace"), source=str(p))


def _int(where: str, key: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise VisionError(f"{where}: {key} must be an integer, got {v!r}")
    if not lo <= v <= hi:
        raise VisionError(f"{where}: {key} must be within {lo}..{hi}, got {v}")
    return v


def _float(where: str, key: str, v, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise VisionError(f"{where}: {key} must be a number, got {v!r}")
    if not math.isfinite(v) or not lo <= v <= hi:
        raise VisionError(f"{where}: {key} must be a finite number within {lo}..{hi}, got {v}")
    return float(v)


def _px(where: str, key: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise VisionError(f"{where}: {key} must be a finite number of px, got {v!r}")
    return float(v)


def _rows(w: str, key: str, v, width: int) -> list[list[float]]:
    if not isinstance(v, list) or not v or not all(isinstance(r, list) and len(r) == width for r in v):
        raise VisionError(f"{w}: {key} must be a list of [{', '.join(['x'] * width)}] rows, got {v!r}")
    for r in v:
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in r):
            raise VisionError(f"{w}: {key} must hold finite numbers, got {r!r}")
    return [[float(x) for x in r] for r in v]


@contextmanager
def _named(where: str) -> Iterator[None]:
    """A ``VisionError`` raised inside is raised again with ``where`` (the file, table, key) in front."""
    try:
        yield
    except VisionError as exc:
        raise VisionError(f"{where}: {exc}") from None


def _parse_class(w: str, c: dict) -> ColourClass:
    unknown = set(c) - _CLASS_KEYS
    if unknown:
        raise VisionError(f"{w}: unknown key(s) {sorted(unknown)} (allowed: {sorted(_CLASS_KEYS)})")
    if "name" not in c or not isinstance(c["name"], str):
        raise VisionError(f"{w}: needs name = \"...\"")
    bgr = c.get("display_bgr", [255, 255, 255])
    if not isinstance(bgr, list):
        raise VisionError(f"{w}: display_bgr must be [b, g, r], three integers 0..255, got {bgr!r}")
    learned = any(k in c for k in ("lab_mean", "lab_cov", "lab_weight"))
    reject = c.get("reject", False)
    if not isinstance(reject, bool):
        raise VisionError(f"{w}: reject must be true or false, got {reject!r}")
    max_d = _float(w, "max_distance", c.get("max_distance", 4.0), 0.5, 50.0)
    if learned:
        if "hsv" in c:
            raise VisionError(f"{w}: give either hsv or lab_mean/lab_cov, not both")
        means = _rows(w, "lab_mean", c.get("lab_mean"), 3)
        covs = _rows(w, "lab_cov", c.get("lab_cov"), 6)
        weights = c.get("lab_weight", [1.0] * len(means))
        if not isinstance(weights, list):
            raise VisionError(f"{w}: lab_weight must be a list of numbers")
        weights = [_float(w, "lab_weight", x, 1e-9, 1.0) for x in weights]
        if not len(means) == len(covs) == len(weights):
            raise VisionError(f"{w}: lab_mean, lab_cov and lab_weight need one entry per component")
        with _named(w):
            comps = tuple(LabComponent(tuple(m), tuple(cv), wt) for m, cv, wt in zip(means, covs, weights, strict=True))  # type: ignore[arg-type]
            return ColourClass(c["name"], display_bgr=tuple(bgr), lab=comps, max_distance=max_d, reject=reject)
    if "hsv" not in c or not isinstance(c["hsv"], list) or not c["hsv"]:
        raise VisionError(f"{w}: needs hsv = [[[h,s,v],[h,s,v]], ...] (or a learned lab_mean/lab_cov)")
    if reject:
        raise VisionError(f"{w}: reject = true needs a learned class (lab_mean/lab_cov)")
    with _named(w):
        return ColourClass(c["name"], tuple(c["hsv"]), tuple(bgr))


def _parse_roi(where: str, meter: dict) -> DrumROI | None:
    """``[meter]``'s manual drum ROI (``roi = [cx, cy, r]`` px, ``roi_kind``, ``half_w_px``/``half_h_px``
    of a rect), None without one."""
    if "roi" not in meter:
        if any(k in meter for k in ("roi_kind", "half_w_px", "half_h_px")):
            raise VisionError(f"{where}: roi_kind/half_w_px/half_h_px need roi = [cx, cy, r]")
        return None
    r = meter["roi"]
    if not (isinstance(r, list) and len(r) == 3):
        raise VisionError(f"{where}: roi must be [cx, cy, r] in px, got {r!r}")
    vals = [_px(where, "roi", v) for v in r]
    kind = meter.get("roi_kind", "circle")
    half = [None if k not in meter else _px(where, k, meter[k]) for k in ("half_w_px", "half_h_px")]
    if kind == "rect" and any(h is not None and h <= 0 for h in half):
        raise VisionError(f"{where}: half_w_px and half_h_px must be > 0 px, got {half}")
    with _named(where):
        return DrumROI(vals[0], vals[1], vals[2], kind, half[0], half[1])


def parse_config(text: str, source: str = "<string>") -> MeterConfig:
    """Parse TOML text into a ``MeterConfig`` (strict: unknown keys are errors)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise VisionError(f"config {source}: not valid TOML ({exc})") from None
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise VisionError(f"config {source}: unknown key(s) {sorted(unknown)} (allowed: {sorted(_TOP_KEYS)})")
    meter = data.get("meter", {})
    if not isinstance(meter, dict):
        raise VisionError(f"config {source}: [meter] must be a table")
    unknown = set(meter) - _METER_KEYS
    if unknown:
        raise VisionError(
            f"config {source}: unknown key(s) {sorted(unknown)} in [meter] (allowed: {sorted(_METER_KEYS)})"
        )
    where = f"config {source} [meter]"
    bed = meter.get("bed", "color")
    if bed not in BED_MODES:
        raise VisionError(f"{where}: bed must be one of {BED_MODES}, got {bed!r}")
    min_pixels = _int(where, "min_pixels", meter.get("min_pixels", 50), 1, 10**9)
    min_share = _float(where, "min_share", meter.get("min_share", 0.005), 0.0, 0.5)
    collapse_ratio = _float(where, "collapse_ratio", meter.get("collapse_ratio", 0.4), 0.0, 1.0)
    history = _int(where, "history", meter.get("history", 25), 1, 10_000)
    dark_v_max = _int(where, "dark_v_max", meter.get("dark_v_max", 80), 0, 255)
    stride = _int(where, "stride", meter.get("stride", 1), 1, 16)
    if "erode" in meter:
        raise VisionError(f"{where}: erode was replaced by opening (the same rims dropped, particles kept whole): "
                          "write opening = true")
    opening = meter.get("opening", False)
    if not isinstance(opening, bool):
        raise VisionError(f"{where}: opening must be true or false, got {opening!r}")
    island_px = _int(where, "island_px", meter.get("island_px", 0), 0, 10**6)
    light_ref = None
    if "light_reference" in meter:
        with _named(where):
            arr = check_reference(meter["light_reference"], "light_reference")
        light_ref = tuple(tuple(float(v) for v in row) for row in arr)
    rot = _float(where, "camera_rotation_deg", meter.get("camera_rotation_deg", 0.0), -360.0, 360.0)
    mirror = meter.get("mirror", False)
    if not isinstance(mirror, bool):
        raise VisionError(f"{where}: mirror must be true or false, got {mirror!r}")
    roi = _parse_roi(where, meter)
    classes = DEFAULT_CLASSES
    if "classes" in data:
        raw = data["classes"]
        if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
            raise VisionError(f"config {source}: classes must be an array of tables [[classes]]")
        classes = tuple(_parse_class(f"config {source} classes[{i}]", c) for i, c in enumerate(raw))
    if len(counted_classes(classes)) < 2:
        raise VisionError(f"config {source}: at least two counted [[classes]] are needed for a mixing index")
    light_cls = None
    if "light_reference_classes" in meter:
        if light_ref is None:
            raise VisionError(f"{where}: light_reference_classes needs light_reference")
        n_labels = len(counted_classes(classes)) + 1
        with _named(where):
            arr = check_class_reference(meter["light_reference_classes"], n_labels, "light_reference_classes")
        light_cls = tuple(tuple(float(v) for v in row.ravel()) for row in arr)
    with _named(f"config {source}"):
        check_class_set(classes)
        if not is_learned(classes):
            Classifier(classes)  # e.g. too many HSV ranges
    warnings = tuple(
        f"config {source}: HSV ranges of {a!r} and {b!r} overlap; {a!r} wins there (use `drumtwin classes suggest`"
        " for a learned model)" for a, b in overlapping_classes(classes)
    )
    return MeterConfig(classes, roi, bed, min_pixels, dark_v_max, stride, source, min_share, collapse_ratio, history,
                       warnings, opening, light_ref, light_cls, rot, mirror,
                       island_px, {k: data[k] for k in MIXER_KEYS if k in data}, drive_table=data.get("drive", {}),
                       endpoint_table=data.get("endpoint", {}))


def _nums(values, digits: int = 6) -> str:
    return "[" + ", ".join(format(float(v), f".{digits}g") for v in values) + "]"


def config_to_toml(cfg: MeterConfig, comment: str = "") -> str:
    """TOML text that ``parse_config`` reads back into ``cfg``."""
    lines = [f"# {ln}" if ln else "#" for ln in comment.splitlines()] if comment else []
    lines += ["[meter]", f'bed = "{cfg.bed}"', f"min_pixels = {cfg.min_pixels}", f"min_share = {cfg.min_share:g}"]
    if cfg.collapse_ratio != 0.4:
        lines.append(f"collapse_ratio = {cfg.collapse_ratio:g}")
    if cfg.history != 25:
        lines.append(f"history = {cfg.history}")
    if cfg.dark_v_max != 80:
        lines.append(f"dark_v_max = {cfg.dark_v_max}")
    if cfg.stride != 1:
        lines.append(f"stride = {cfg.stride}")
    if cfg.opening:
        lines.append("opening = true")
    if cfg.island_px:
        lines.append(f"island_px = {cfg.island_px}  # highlights of glossy particles: see vision.islands")
    if cfg.camera_rotation_deg != 0.0:
        lines.append(f"camera_rotation_deg = {cfg.camera_rotation_deg:g}  # the image is gravity's view turned "
                     "counter-clockwise by this")
    if cfg.mirror:
        lines.append("mirror = true")
    if cfg.light_reference is not None:
        lines.append("# the light at set-up: per-channel quantiles (B, G, R) of the drum ROI (photometric tracking)")
        lines.append("light_reference = [" + ", ".join(_nums(row) for row in cfg.light_reference) + "]")
    if cfg.light_reference_classes is not None:
        lines.append("# the same per class: no class, then each counted class; B, G, R quantiles (-1: not seen)")
        lines.append("light_reference_classes = [" + ", ".join(_nums(r) for r in cfg.light_reference_classes) + "]")
    if cfg.roi is not None:
        r = cfg.roi
        lines.append(f"roi = [{r.cx_px:.1f}, {r.cy_px:.1f}, {r.r_px:.1f}]")
        if r.kind != "circle":
            lines += [f'roi_kind = "{r.kind}"', f"half_w_px = {r.half_w_px:.1f}", f"half_h_px = {r.half_h_px:.1f}"]
    for c in cfg.classes:
        lines += ["", "[[classes]]", f'name = "{c.name}"']
        if c.learned:
            if c.reject:
                lines.append("reject = true  # background, rim, shadows, glare: never counted")
            else:
                lines.append(f"max_distance = {c.max_distance:g}  # sigmas; farther colours are no class")
            lines.append("lab_mean = [" + ", ".join(_nums(p.mean_lab) for p in c.lab) + "]  # CIELAB L, a, b")
            lines.append("lab_cov = [" + ", ".join(_nums(p.cov) for p in c.lab) + "]  # LL, La, Lb, aa, ab, bb")
            lines.append("lab_weight = " + _nums([p.weight for p in c.lab]))
        else:
            rngs = ", ".join(f"[[{lo[0]}, {lo[1]}, {lo[2]}], [{hi[0]}, {hi[1]}, {hi[2]}]]" for lo, hi in c.hsv_ranges)
            lines.append(f"hsv = [{rngs}]")
        lines.append(f"display_bgr = [{c.display_bgr[0]}, {c.display_bgr[1]}, {c.display_bgr[2]}]")
    return "\n".join(lines) + "\n"

"""Meter configuration from a TOML file (``--config``).

Example (see ``configs/example.toml``)::

    [meter]
    bed = "color"          # "color" (union of classes) or "dark" (backlit drum)
    min_pixels = 50        # fewer pixels of a class -> NaN + flag
    roi = [320, 318, 312]  # optional manual drum circle cx, cy, r (px)

    [[classes]]            # two or more; the MI uses the first two
    name = "blue"
    hsv = [[[95, 90, 50], [130, 255, 255]]]   # list of [[h,s,v] low, [h,s,v] high]
    display_bgr = [255, 80, 0]

Unknown keys, wrong types and inverted HSV ranges are ``VisionError``s.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from vision.colours import DEFAULT_CLASSES, ColourClass
from vision.errors import VisionError
from vision.meter import BED_MODES, Meter
from vision.roi import DrumROI

__all__ = ["MeterConfig", "load_config", "parse_config", "config_to_toml"]

_METER_KEYS = {"bed", "min_pixels", "dark_v_max", "stride", "roi", "roi_kind", "half_w_px", "half_h_px"}
_CLASS_KEYS = {"name", "hsv", "display_bgr"}
_TOP_KEYS = {"meter", "classes"}


@dataclass(frozen=True)
class MeterConfig:
    """Everything a ``Meter`` needs; ``roi=None`` means detect the drum."""

    classes: tuple[ColourClass, ...] = DEFAULT_CLASSES
    roi: DrumROI | None = None
    bed: str = "color"
    min_pixels: int = 50
    dark_v_max: int = 80
    stride: int = 1
    source: str = field(default="<defaults>", compare=False)

    def make_meter(self, roi: DrumROI | None = None, bed: str | None = None) -> Meter:
        """A fresh ``Meter``; ``roi``/``bed`` override the config (e.g. from the CLI)."""
        return Meter(
            self.classes, roi if roi is not None else self.roi, bed or self.bed, self.min_pixels,
            dark_v_max=self.dark_v_max, stride=self.stride,
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
        raise VisionError(f"config {source}: unknown key(s) {sorted(unknown)} in [meter] (allowed: {sorted(_METER_KEYS)})")
    where = f"config {source} [meter]"
    bed = meter.get("bed", "color")
    if bed not in BED_MODES:
        raise VisionError(f"{where}: bed must be one of {BED_MODES}, got {bed!r}")
    min_pixels = _int(where, "min_pixels", meter.get("min_pixels", 50), 1, 10**9)
    dark_v_max = _int(where, "dark_v_max", meter.get("dark_v_max", 80), 0, 255)
    stride = _int(where, "stride", meter.get("stride", 1), 1, 16)
    roi = None
    if "roi" in meter:
        r = meter["roi"]
        if not (isinstance(r, list) and len(r) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in r)):
            raise VisionError(f"{where}: roi must be [cx, cy, r] in px, got {r!r}")
        kind = meter.get("roi_kind", "circle")
        roi = DrumROI(float(r[0]), float(r[1]), float(r[2]), kind, meter.get("half_w_px"), meter.get("half_h_px"))
    elif any(k in meter for k in ("roi_kind", "half_w_px", "half_h_px")):
        raise VisionError(f"{where}: roi_kind/half_w_px/half_h_px need roi = [cx, cy, r]")
    classes = DEFAULT_CLASSES
    if "classes" in data:
        raw = data["classes"]
        if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
            raise VisionError(f"config {source}: classes must be an array of tables [[classes]]")
        out = []
        for i, c in enumerate(raw):
            w = f"config {source} classes[{i}]"
            unknown = set(c) - _CLASS_KEYS
            if unknown:
                raise VisionError(f"{w}: unknown key(s) {sorted(unknown)} (allowed: {sorted(_CLASS_KEYS)})")
            if "name" not in c or not isinstance(c["name"], str):
                raise VisionError(f"{w}: needs name = \"...\"")
            if "hsv" not in c or not isinstance(c["hsv"], list) or not c["hsv"]:
                raise VisionError(f"{w}: needs hsv = [[[h,s,v],[h,s,v]], ...]")
            try:
                out.append(ColourClass(c["name"], tuple(c["hsv"]), tuple(c.get("display_bgr", (255, 255, 255)))))
            except VisionError as exc:
                raise VisionError(f"config {source}: {exc}") from None
            except TypeError:
                raise VisionError(f"{w}: display_bgr must be [b, g, r]") from None
        classes = tuple(out)
    if len(classes) < 2:
        raise VisionError(f"config {source}: at least two [[classes]] are needed for a mixing index")
    names = [c.name for c in classes]
    if len(set(names)) != len(names):
        raise VisionError(f"config {source}: class names must be unique, got {names}")
    cfg = MeterConfig(classes, roi, bed, min_pixels, dark_v_max, stride, source)
    cfg.make_meter()  # validates the class set (e.g. too many HSV ranges)
    return cfg


def config_to_toml(cfg: MeterConfig, comment: str = "") -> str:
    """TOML text that ``parse_config`` reads back into ``cfg``."""
    lines = [f"# {ln}" if ln else "#" for ln in comment.splitlines()] if comment else []
    lines += ["[meter]", f'bed = "{cfg.bed}"', f"min_pixels = {cfg.min_pixels}"]
    if cfg.dark_v_max != 80:
        lines.append(f"dark_v_max = {cfg.dark_v_max}")
    if cfg.stride != 1:
        lines.append(f"stride = {cfg.stride}")
    if cfg.roi is not None:
        r = cfg.roi
        lines.append(f"roi = [{r.cx_px:.1f}, {r.cy_px:.1f}, {r.r_px:.1f}]")
        if r.kind != "circle":
            lines += [f'roi_kind = "{r.kind}"', f"half_w_px = {r.half_w_px:.1f}", f"half_h_px = {r.half_h_px:.1f}"]
    for c in cfg.classes:
        rngs = ", ".join(f"[[{lo[0]}, {lo[1]}, {lo[2]}], [{hi[0]}, {hi[1]}, {hi[2]}]]" for lo, hi in c.hsv_ranges)
        lines += ["", "[[classes]]", f'name = "{c.name}"', f"hsv = [{rngs}]",
                  f"display_bgr = [{c.display_bgr[0]}, {c.display_bgr[1]}, {c.display_bgr[2]}]"]
    return "\n".join(lines) + "\n"

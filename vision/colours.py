"""Colour classes: a learned colour model (CIELAB Gaussians) or named sets of HSV boxes.

Two forms, one per class set (not mixed):

- learned (``classes suggest``): each class is a small mixture of Gaussians in CIELAB
  (OpenCV float scale: L 0..100, a and b about -128..127) with a reject distance
  ``max_distance`` (Mahalanobis, in sigmas); ``reject=True`` classes are background,
  rim, shadow or glare colours that are never counted. A pixel goes to the component
  with the highest likelihood; it counts for that component's class when the class is
  not a reject class and the pixel lies within its ``max_distance``. Otherwise it is
  class 0 (no class).
- HSV boxes (hand-written configs): OpenCV's 8-bit scale, H in 0..179 (degrees / 2),
  S and V in 0..255. A class is the union of its boxes; red wraps around hue 0, so it
  is two boxes. Where boxes of two classes overlap the first class wins (the config
  loader warns, see :func:`overlapping_classes`).

Both forms are baked into the same exact BGR lookup table (``vision.moments``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from vision.errors import VisionError

__all__ = [
    "DEFAULT_CLASSES",
    "MAX_RANGES",
    "Classifier",
    "ColourClass",
    "HSVRange",
    "LabComponent",
    "bgr_to_lab",
    "check_class_set",
    "class_lut",
    "classify",
    "counted_classes",
    "is_learned",
    "lut_labels",
    "overlapping_classes",
]

HSVRange = tuple[tuple[int, int, int], tuple[int, int, int]]
"""``((h_lo, s_lo, v_lo), (h_hi, s_hi, v_hi))``, inclusive, OpenCV 8-bit HSV scale."""

MAX_RANGES = 8
"""At most this many HSV boxes over all classes (one bit each in the lookup tables)."""

_CHANNEL_MAX = (179, 255, 255)
_CHANNEL_NAME = ("H", "S", "V")


def _finite(where: str, key: str, values, n: int) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise VisionError(f"{where}: {key} must be {n} numbers, got {values!r}") from None
    if len(out) != n or any(isinstance(v, bool) for v in values):
        raise VisionError(f"{where}: {key} must be {n} numbers, got {values!r}")
    if not all(math.isfinite(v) for v in out):
        raise VisionError(f"{where}: {key} must be finite numbers, got {values!r}")
    return out


@dataclass(frozen=True)
class LabComponent:
    """One Gaussian of a learned colour class in CIELAB (OpenCV float scale: L 0..100).

    ``mean_lab`` = (L, a, b); ``cov`` = upper triangle (LL, La, Lb, aa, ab, bb) of the
    covariance, positive definite; ``weight`` > 0 = its share in the fitted mixture.
    """

    mean_lab: tuple[float, float, float]
    cov: tuple[float, float, float, float, float, float]
    weight: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean_lab", _finite("Lab component", "lab_mean", self.mean_lab, 3))
        cov = _finite("Lab component", "lab_cov", self.cov, 6)
        object.__setattr__(self, "cov", cov)
        w = float(self.weight)
        if not (math.isfinite(w) and w > 0):
            raise VisionError(f"Lab component: weight must be a finite number > 0, got {self.weight!r}")
        object.__setattr__(self, "weight", w)
        if not np.all(np.linalg.eigvalsh(self.matrix()) > 1e-9):
            raise VisionError(f"Lab component: lab_cov {cov} is not positive definite")

    def matrix(self) -> np.ndarray:
        """The 3x3 covariance matrix."""
        ll, la, lb, aa, ab, bb = self.cov
        return np.array([[ll, la, lb], [la, aa, ab], [lb, ab, bb]], np.float64)


@dataclass(frozen=True)
class ColourClass:
    """A named particle colour and its display colour (BGR).

    Either ``hsv_ranges`` (inclusive HSV boxes) or ``lab`` (learned Gaussians, with the
    reject distance ``max_distance`` in sigmas). ``reject=True``: a learned background
    colour (never counted, it only claims pixels so that no particle class does).
    """

    name: str
    hsv_ranges: tuple[HSVRange, ...] = ()
    display_bgr: tuple[int, int, int] = (255, 255, 255)
    lab: tuple[LabComponent, ...] = ()
    max_distance: float = 4.0
    reject: bool = False

    def __post_init__(self) -> None:
        name = str(self.name)
        if not name or not all(ch.isalnum() or ch in "_-" for ch in name):
            raise VisionError(f"colour class name {self.name!r} must be non-empty letters, digits, '_' or '-'")
        ranges = tuple(_check_range(name, r) for r in self.hsv_ranges)
        lab = tuple(self.lab)
        if not ranges and not lab:
            raise VisionError(f"colour class {name!r} has no HSV range")
        if ranges and lab:
            raise VisionError(f"colour class {name!r}: give either hsv ranges or a learned lab model, not both")
        if not all(isinstance(c, LabComponent) for c in lab):
            raise VisionError(f"colour class {name!r}: lab must be LabComponent values")
        dist = self.max_distance
        number = not isinstance(dist, bool) and isinstance(dist, (int, float))
        if not number or not math.isfinite(dist) or not 0.5 <= dist <= 50:
            raise VisionError(
                f"colour class {name!r}: max_distance must be a number within 0.5..50 (sigmas), got {dist!r}"
            )
        if self.reject and not lab:
            raise VisionError(f"colour class {name!r}: only learned (lab) classes can be reject classes")
        object.__setattr__(self, "lab", lab)
        object.__setattr__(self, "max_distance", float(dist))
        object.__setattr__(self, "reject", bool(self.reject))
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "hsv_ranges", ranges)
        raw = self.display_bgr
        try:
            ok = len(raw) == 3 and all(isinstance(c, (int, np.integer)) and not isinstance(c, bool) for c in raw)
        except TypeError:
            ok = False
        if not ok or not all(0 <= int(c) <= 255 for c in raw):
            raise VisionError(f"colour class {name!r}: display_bgr must be three integers 0..255, got {raw!r}")
        object.__setattr__(self, "display_bgr", tuple(int(c) for c in raw))

    @property
    def learned(self) -> bool:
        """True for a learned (CIELAB model) class."""
        return bool(self.lab)


def _check_range(name: str, rng) -> HSVRange:
    try:
        lo, hi = rng
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (*lo, *hi)):
            raise TypeError
        lo = tuple(int(v) for v in lo)
        hi = tuple(int(v) for v in hi)
    except (TypeError, ValueError, OverflowError):
        raise VisionError(f"colour class {name!r}: an HSV range must be [[h,s,v],[h,s,v]], got {rng!r}") from None
    if len(lo) != 3 or len(hi) != 3:
        raise VisionError(f"colour class {name!r}: an HSV range must be [[h,s,v],[h,s,v]], got {rng!r}")
    for i in range(3):
        if not (0 <= lo[i] <= _CHANNEL_MAX[i] and 0 <= hi[i] <= _CHANNEL_MAX[i]):
            raise VisionError(
                f"colour class {name!r}: {_CHANNEL_NAME[i]} must be within 0..{_CHANNEL_MAX[i]}, got {lo[i]}..{hi[i]}"
            )
        if lo[i] > hi[i]:
            raise VisionError(
                f"colour class {name!r}: inverted {_CHANNEL_NAME[i]} range {lo[i]}..{hi[i]} "
                "(for red, which wraps around hue 0, give two ranges)"
            )
    return (lo, hi)


def class_mean_lab(c: ColourClass) -> np.ndarray:
    """CIELAB (L, a, b) of a class's colour: its learned components' weighted mean, or the
    display colour of an HSV class."""
    if c.lab:
        w = np.array([comp.weight for comp in c.lab])
        return np.array([comp.mean_lab for comp in c.lab]).T @ w / w.sum()
    return bgr_to_lab(np.array([[c.display_bgr]], np.uint8)).reshape(3).astype(np.float64)


def is_learned(classes: Sequence[ColourClass]) -> bool:
    """True when the class set is a learned (CIELAB) model."""
    return any(c.learned for c in classes)


def counted_classes(classes: Sequence[ColourClass]) -> tuple[ColourClass, ...]:
    """The classes that are measured (reject classes left out), in order."""
    return tuple(c for c in classes if not c.reject)


def check_class_set(classes: Sequence[ColourClass]) -> tuple[ColourClass, ...]:
    """Validate a class set: unique names, one form (all HSV or all learned), >= 1 counted class."""
    classes = tuple(classes)
    if not classes:
        raise VisionError("at least one colour class is needed")
    names = [c.name for c in classes]
    if len(set(names)) != len(names):
        raise VisionError(f"colour class names must be unique, got {names}")
    kinds = {c.learned for c in classes}
    if len(kinds) > 1:
        raise VisionError("a class set is either HSV ranges or a learned lab model, not a mix of both")
    if not counted_classes(classes):
        raise VisionError("every colour class is a reject class; at least one must be counted")
    if len(counted_classes(classes)) > 254:
        raise VisionError("too many colour classes")
    return classes


def overlapping_classes(classes: Sequence[ColourClass]) -> list[tuple[str, str]]:
    """Pairs ``(earlier, later)`` of HSV classes whose boxes overlap (the earlier one wins there)."""
    out = []
    hsv = [c for c in classes if c.hsv_ranges]
    for k, ck in enumerate(hsv):
        for cj in hsv[:k]:
            if any(_boxes_overlap(a, b) for a in ck.hsv_ranges for b in cj.hsv_ranges):
                out.append((cj.name, ck.name))
    return out


DEFAULT_CLASSES: tuple[ColourClass, ...] = (
    ColourClass("red", (((0, 90, 50), (10, 255, 255)), ((165, 90, 50), (179, 255, 255))), (0, 0, 255)),
    ColourClass("blue", (((95, 90, 50), (130, 255, 255)),), (255, 80, 0)),
)
"""The paper's two classes: red (wrapping hue 0) and blue."""


class Classifier:
    """Exclusive HSV classification, compiled once into a few OpenCV SIMD primitives.

    Each class is the OR over its HSV boxes; boxes of a class that share their S and V
    ranges share those tests. A channel range that is full is skipped, one open at the top
    is a ``threshold``, others an ``inRange``; identical tests are computed once per frame.
    Classes are exclusive (first class wins) only when their boxes overlap.
    ``class_masks`` writes into reusable buffers (no per-frame allocation).
    """

    def __init__(self, classes: tuple[ColourClass, ...] | list[ColourClass]) -> None:
        classes = check_class_set(classes)
        if is_learned(classes):
            raise VisionError("Classifier takes HSV classes; learned classes are classified by their lookup table")
        nbits = sum(len(c.hsv_ranges) for c in classes)
        if nbits > MAX_RANGES:
            raise VisionError(f"at most {MAX_RANGES} HSV ranges over all classes, got {nbits}")
        self.classes = classes
        # plan: per class, list of groups (hue tests, s test, v test); a test is (ch, lo, hi) or None
        self._plan: list[list[tuple[list, tuple | None, tuple | None]]] = []
        for cls in classes:
            groups: dict[tuple, list] = {}
            for lo, hi in cls.hsv_ranges:
                key = ((lo[1], hi[1]), (lo[2], hi[2]))
                groups.setdefault(key, []).append(_test(0, lo[0], hi[0]))
            plan = []
            for (srng, vrng), htests in groups.items():
                hs = [] if any(t is None for t in htests) else htests
                plan.append((hs, _test(1, *srng), _test(2, *vrng)))
            self._plan.append(plan)
        self._exclusive = [
            any(_boxes_overlap(a, b) for j in range(k) for a in classes[k].hsv_ranges for b in classes[j].hsv_ranges)
            for k in range(len(classes))
        ]
        self._bufs: dict[str, np.ndarray] = {}
        self._shape: tuple[int, int] | None = None

    def _buf(self, key: str) -> np.ndarray:
        b = self._bufs.get(key)
        if b is None:
            b = self._bufs[key] = np.empty(self._shape, np.uint8)  # type: ignore[arg-type]
        return b

    def class_masks(
        self, h: np.ndarray, s: np.ndarray, v: np.ndarray, mask_u8: np.ndarray | None = None
    ) -> list[np.ndarray]:
        """One 0/255 uint8 mask per class from the 8-bit HSV planes (buffers are reused).

        ``mask_u8`` (0/255, same size) limits every class mask (the ROI).
        """
        shape = h.shape
        if shape != self._shape:
            self._bufs.clear()
            self._shape = shape
        planes = (h, s, v)
        cache: dict[tuple, np.ndarray] = {}

        def run(t: tuple) -> np.ndarray:
            out = cache.get(t)
            if out is None:
                ch, lo, hi = t
                out = self._buf(f"t{ch}_{lo}_{hi}")
                top = 179 if ch == 0 else 255
                if hi >= top:
                    cv2.threshold(planes[ch], lo - 1, 255, cv2.THRESH_BINARY, dst=out)
                elif lo <= 0:
                    cv2.threshold(planes[ch], hi, 255, cv2.THRESH_BINARY_INV, dst=out)
                else:
                    cv2.inRange(planes[ch], lo, hi, dst=out)
                cache[t] = out
            return out

        base_cache: dict[tuple, np.ndarray | None] = {}

        def base(stest: tuple | None, vtest: tuple | None) -> np.ndarray | None:
            """AND of the S test, the V test and the ROI mask, shared between classes."""
            key = (stest, vtest)
            if key in base_cache:
                return base_cache[key]
            parts = [run(t) for t in (stest, vtest) if t is not None]
            if mask_u8 is not None:
                parts.append(mask_u8)
            out: np.ndarray | None
            if not parts:
                out = None
            elif len(parts) == 1:
                out = parts[0]
            else:
                out = self._buf(f"base{len(base_cache)}")
                cv2.bitwise_and(parts[0], parts[1], dst=out)
                for p in parts[2:]:
                    cv2.bitwise_and(out, p, dst=out)
            base_cache[key] = out
            return out

        result: list[np.ndarray] = []
        for k, plan in enumerate(self._plan):
            out = self._buf(f"class{k}")
            for i, (htests, stest, vtest) in enumerate(plan):
                g = self._buf("group") if len(plan) > 1 else out
                self._group_mask(g, self._hue_mask(htests, run), base(stest, vtest))
                if g is not out:
                    if i == 0:
                        np.copyto(out, g)
                    else:
                        cv2.bitwise_or(out, g, dst=out)
            if self._exclusive[k]:
                for prev in result:
                    cv2.subtract(out, prev, dst=out)
            result.append(out)
        return result

    def _hue_mask(self, htests: Sequence[tuple], run: Callable[[tuple], np.ndarray]) -> np.ndarray | None:
        """The OR of a group's hue tests (None: the group has none)."""
        if not htests:
            return None
        if len(htests) == 1:
            return run(htests[0])
        hue = self._buf("hue")
        cv2.bitwise_or(run(htests[0]), run(htests[1]), dst=hue)
        for t in htests[2:]:
            cv2.bitwise_or(hue, run(t), dst=hue)
        return hue

    @staticmethod
    def _group_mask(g: np.ndarray, hue: np.ndarray | None, b: np.ndarray | None) -> None:
        """``g`` = the AND of a group's hue mask and its base (S, V, ROI) mask; either may be
        None (no test: every pixel)."""
        if b is None:
            if hue is None:
                g[...] = 255
            else:
                np.copyto(g, hue)
        elif hue is None:
            np.copyto(g, b)
        else:
            cv2.bitwise_and(hue, b, dst=g)

    def labels(self, bgr: np.ndarray, mask_u8: np.ndarray | None = None) -> np.ndarray:
        """Label map (uint8, same h x w) of a BGR uint8 image: 0 = none, ``k + 1`` = class k."""
        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
        h, s, v = cv2.split(hsv)
        masks = self.class_masks(h, s, v, mask_u8)
        lab = np.zeros(h.shape, np.uint8)
        for k, m in enumerate(masks):
            lab[(m != 0) & (lab == 0)] = k + 1
        return lab


def _test(ch: int, lo: int, hi: int) -> tuple[int, int, int] | None:
    top = 179 if ch == 0 else 255
    if lo <= 0 and hi >= top:
        return None
    return (ch, int(lo), int(hi))


def _boxes_overlap(a: HSVRange, b: HSVRange) -> bool:
    return all(max(a[0][i], b[0][i]) <= min(a[1][i], b[1][i]) for i in range(3))


def _as_bgr(image_bgr: np.ndarray) -> np.ndarray:
    img = np.asarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3:
        raise VisionError(f"expected a 3-channel BGR image, got shape {img.shape}")
    if img.dtype != np.uint8:
        raise VisionError(f"expected an 8-bit image, got dtype {img.dtype}")
    return img


def bgr_to_lab(bgr: np.ndarray) -> np.ndarray:
    """CIELAB (float32, OpenCV float scale: L 0..100, a, b about -128..127) of uint8 BGR
    colours of shape (..., 3), through OpenCV's exact 8-bit conversion (the lookup
    table and the fitting see the same numbers)."""
    a = np.ascontiguousarray(bgr, dtype=np.uint8)
    flat = a.reshape(-1, 1, 3)
    lab8 = np.empty_like(flat)
    # cvtColor takes at most 2^31 bytes per call; chunk rows
    step = 1 << 22
    for i in range(0, flat.shape[0], step):
        lab8[i:i + step] = cv2.cvtColor(flat[i:i + step], cv2.COLOR_BGR2Lab)
    out = lab8.reshape(-1, 3).astype(np.float32)
    out[:, 0] *= np.float32(100.0 / 255.0)
    out[:, 1:] -= np.float32(128.0)
    return out.reshape(a.shape)


def _every_bgr(row0: int = 0, rows: int = 4096) -> np.ndarray:
    """All 2^24 BGR colours as a (4096, 4096, 3) image (colour index = B << 16 | G << 8 | R
    = row * 4096 + column), or its rows ``row0 .. row0 + rows`` (tables built in chunks
    peak at a fraction of the memory)."""
    every = np.arange(row0 << 12, (row0 + rows) << 12, dtype=np.uint32).view(np.uint8).reshape(-1, 4)  # R, G, B, 0
    return np.ascontiguousarray(every[:, 2::-1]).reshape(rows, 4096, 3)


@lru_cache(maxsize=8)
def class_lut(classes: tuple[ColourClass, ...]) -> np.ndarray:
    """The exact class of every BGR colour: uint8 array of 2^24, index ``B << 16 | G << 8 | R``;
    0 = no class (or a reject class), ``k`` = the k-th counted class (1-based).

    HSV classes go through :class:`Classifier` itself (pixel for pixel what it gives on
    OpenCV's HSV); learned classes through their Gaussians (most likely component, within
    its class's ``max_distance``). Built once per class set (about 1-3 s) and cached.
    """
    classes = check_class_set(classes)
    if is_learned(classes):
        from vision.lablut import lab_lut  # (it imports this module)

        return lab_lut(classes)
    fine = np.zeros(1 << 24, np.uint8)
    clf = Classifier(classes)
    step = 256  # rows of 4096 colours per chunk: 1 M colours (the whole table at once peaked at ~200 MB)
    for r0 in range(0, 4096, step):
        h, s, v = cv2.split(cv2.cvtColor(_every_bgr(r0, step), cv2.COLOR_BGR2HSV))
        masks = clf.class_masks(h, s, v)
        part = fine[r0 << 12:(r0 + step) << 12]
        for k in range(len(masks) - 1, -1, -1):  # exclusive: the first class wins, so it is written last
            part[masks[k].ravel() != 0] = k + 1
    return fine


def lut_labels(image_bgr: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """Label map (uint8, h x w) of a BGR uint8 image through a :func:`class_lut` table."""
    img = _as_bgr(image_bgr)
    idx = (img[..., 0].astype(np.int32) << 16) | (img[..., 1].astype(np.int32) << 8) | img[..., 2]
    return lut[idx]


def classify(image_bgr: np.ndarray, classes=DEFAULT_CLASSES, mask: np.ndarray | None = None) -> np.ndarray:
    """Label map of an image: uint8, 0 = no class, ``k + 1`` = the k-th counted class of ``classes``
    (reject classes are 0). The same lookup table as the meter's.

    ``mask`` (bool or uint8, image-sized) restricts classification; outside it is 0.
    """
    img = _as_bgr(image_bgr)
    lab = lut_labels(img, class_lut(tuple(classes)))
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != img.shape[:2]:
            raise VisionError(f"mask shape {mask.shape} does not match image {img.shape[:2]}")
        lab[~mask.astype(bool)] = 0
    return lab

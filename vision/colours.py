"""Colour classes: named sets of HSV boxes, and the one pixel classifier.

HSV uses OpenCV's 8-bit scale: H in 0..179 (degrees / 2), S and V in 0..255.
A class is the union of its boxes; red wraps around hue 0, so it is two boxes.
Classification is exclusive: a pixel matching several classes goes to the first.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vision.errors import VisionError

__all__ = ["HSVRange", "ColourClass", "DEFAULT_CLASSES", "Classifier", "classify", "MAX_RANGES"]

HSVRange = tuple[tuple[int, int, int], tuple[int, int, int]]
"""``((h_lo, s_lo, v_lo), (h_hi, s_hi, v_hi))``, inclusive, OpenCV 8-bit HSV scale."""

MAX_RANGES = 8
"""At most this many HSV boxes over all classes (one bit each in the lookup tables)."""

_CHANNEL_MAX = (179, 255, 255)
_CHANNEL_NAME = ("H", "S", "V")


@dataclass(frozen=True)
class ColourClass:
    """A named particle colour: one or more inclusive HSV boxes and a display colour (BGR)."""

    name: str
    hsv_ranges: tuple[HSVRange, ...]
    display_bgr: tuple[int, int, int] = (255, 255, 255)

    def __post_init__(self) -> None:
        name = str(self.name)
        if not name or not all(ch.isalnum() or ch in "_-" for ch in name):
            raise VisionError(f"colour class name {self.name!r} must be non-empty letters, digits, '_' or '-'")
        ranges = tuple(_check_range(name, r) for r in self.hsv_ranges)
        if not ranges:
            raise VisionError(f"colour class {name!r} has no HSV range")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "hsv_ranges", ranges)
        bgr = tuple(int(c) for c in self.display_bgr)
        if len(bgr) != 3 or not all(0 <= c <= 255 for c in bgr):
            raise VisionError(f"colour class {name!r}: display_bgr must be three values 0..255, got {self.display_bgr!r}")
        object.__setattr__(self, "display_bgr", bgr)


def _check_range(name: str, rng) -> HSVRange:
    try:
        lo, hi = rng
        lo = tuple(int(v) for v in lo)
        hi = tuple(int(v) for v in hi)
    except (TypeError, ValueError):
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
    return (lo, hi)  # type: ignore[return-value]


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
        classes = tuple(classes)
        if not classes:
            raise VisionError("at least one colour class is needed")
        names = [c.name for c in classes]
        if len(set(names)) != len(names):
            raise VisionError(f"colour class names must be unique, got {names}")
        if len(classes) > 254:
            raise VisionError("too many colour classes")
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
            first = True
            for htests, stest, vtest in plan:
                g = self._buf("group") if len(plan) > 1 else out
                hue: np.ndarray | None = None
                if len(htests) == 1:
                    hue = run(htests[0])
                elif htests:
                    hue = self._buf("hue")
                    cv2.bitwise_or(run(htests[0]), run(htests[1]), dst=hue)
                    for t in htests[2:]:
                        cv2.bitwise_or(hue, run(t), dst=hue)
                b = base(stest, vtest)
                if hue is None and b is None:
                    g[...] = 255
                elif hue is None or b is None:
                    np.copyto(g, hue if b is None else b)
                else:
                    cv2.bitwise_and(hue, b, dst=g)
                if g is not out:
                    if first:
                        np.copyto(out, g)
                    else:
                        cv2.bitwise_or(out, g, dst=out)
                first = False
            if self._exclusive[k]:
                for prev in result:
                    cv2.subtract(out, prev, dst=out)
            result.append(out)
        return result

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


def classify(image_bgr: np.ndarray, classes=DEFAULT_CLASSES, mask: np.ndarray | None = None) -> np.ndarray:
    """Label map of an image: uint8, 0 = no class, ``k + 1`` = ``classes[k]``.

    ``mask`` (bool or uint8, image-sized) restricts classification; outside it is 0.
    """
    img = _as_bgr(image_bgr)
    m = None
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != img.shape[:2]:
            raise VisionError(f"mask shape {mask.shape} does not match image {img.shape[:2]}")
        m = np.where(mask.astype(bool), np.uint8(255), np.uint8(0))
    return Classifier(classes).labels(img, m)

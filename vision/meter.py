"""The meter: one BGR frame in, one ``Reading`` (centroids, spreads, MI, slope) out.

Per frame it crops to the ROI's bounding box, converts to HSV once, classifies every
pixel with lookup tables, and gets each class's pixel count, centroid and spread from
row/column projections (``cv2.reduce``) dotted with precomputed coordinate vectors.
Masks and coordinate vectors are built once per ROI and frame size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.colours import DEFAULT_CLASSES, Classifier, ColourClass
from vision.errors import VisionError
from vision.mixing import mixing_indices
from vision.roi import DrumROI, _mask_in_box, detect_drum, roi_bbox
from vision.slope import slope_from_moments

__all__ = ["ClassStats", "Reading", "Meter", "BED_MODES"]

BED_MODES = ("color", "dark")
_NAN = float("nan")


@dataclass(frozen=True, slots=True)
class ClassStats:
    """One colour class in one frame: centroid and spread (px, original image), pixel count, share.

    ``sigma_px = sqrt(var_x + var_y)``; ``frac`` = this class's pixels / all classified pixels.
    NaN centroid/spread when the class has fewer than ``min_pixels`` pixels.
    """

    name: str
    cx_px: float
    cy_px: float
    sigma_px: float
    n_px: int
    frac: float


@dataclass(frozen=True)
class Reading:
    """Everything measured in one frame.

    ``mi`` (eq. 4), ``mi_sigmoid`` (eq. 3), ``mi_linear`` (eq. 1, relative to the first
    valid frame), ``d_px``, ``dsigma_px``, ``slope_deg`` (free surface, see vision.slope),
    ``concentration`` = n_1 / (n_1 + n_2). ``valid`` is False when ``mi`` is NaN; ``flags``
    say why (e.g. ``few_pixels:blue``, ``bad_frame:...``, ``size_changed:...``).
    """

    mi: float
    mi_sigmoid: float
    mi_linear: float
    d_px: float
    dsigma_px: float
    slope_deg: float
    concentration: float
    valid: bool
    flags: tuple[str, ...]
    classes: tuple[ClassStats, ...]
    roi: DrumROI | None

    def cls(self, name: str) -> ClassStats:
        """The stats of the class called ``name``."""
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(name)


@dataclass
class _Geometry:
    shape_hw: tuple[int, int]
    box: tuple[int, int, int, int]
    mask: np.ndarray  # uint8 0/255, (strided) crop size
    xs: np.ndarray  # float64 x of each (strided) crop column, original px
    ys: np.ndarray
    xs2: np.ndarray
    ys2: np.ndarray
    hsv: np.ndarray  # reusable per-frame buffers
    planes: list[np.ndarray]
    colsum: np.ndarray
    rowsum: np.ndarray


class Meter:
    """Measures mixing in BGR frames with a fixed set of colour classes.

    ``roi=None`` detects the drum on the first good frame (``detect_drum``). ``bed``:
    ``"color"`` takes the bed for the slope angle as the union of the classes; ``"dark"``
    takes the pixels with V <= ``dark_v_max`` inside the ROI (dark bed on a backlit drum).
    Classes with fewer than ``min_pixels`` pixels give NaN and a flag. ``stride`` > 1 is an
    explicit, opt-in decimation (every ``stride``-th row and column); the default 1 uses
    every pixel. The slope uses a 4-px grid of the bed mask (``slope_stride``).
    The MI uses the first two classes.
    """

    def __init__(
        self,
        classes: tuple[ColourClass, ...] | list[ColourClass] = DEFAULT_CLASSES,
        roi: DrumROI | None = None,
        bed: str = "color",
        min_pixels: int = 50,
        *,
        dark_v_max: int = 80,
        stride: int = 1,
        slope_stride: int = 4,
    ) -> None:
        self.classes = tuple(classes)
        if len(self.classes) < 2:
            raise VisionError(f"the mixing index needs at least two colour classes, got {len(self.classes)}")
        if bed not in BED_MODES:
            raise VisionError(f"bed must be one of {BED_MODES}, got {bed!r}")
        if int(stride) < 1 or int(slope_stride) < 1:
            raise VisionError("stride and slope_stride must be >= 1")
        if not 0 <= int(dark_v_max) <= 255:
            raise VisionError(f"dark_v_max must be within 0..255, got {dark_v_max}")
        self.classifier = Classifier(self.classes)
        self.bed = bed
        self.min_pixels = int(min_pixels)
        self.dark_v_max = int(dark_v_max)
        self.stride = int(stride)
        self.slope_stride = int(slope_stride)
        self._roi = roi
        self._roi_given = roi is not None
        self._geom: _Geometry | None = None
        self._d0: float | None = None
        self._dark_lut = np.where(np.arange(256) <= self.dark_v_max, 255, 0).astype(np.uint8).reshape(256, 1)

    @property
    def roi(self) -> DrumROI | None:
        """The ROI in use (None until the first frame when auto-detecting)."""
        return self._roi

    @property
    def d0_px(self) -> float | None:
        """Reference centroid distance of eq. 1 (first valid frame), px."""
        return self._d0

    def reset(self) -> None:
        """Forget the eq. 1 reference distance (and an auto-detected ROI)."""
        self._d0 = None
        self._geom = None
        if not self._roi_given:
            self._roi = None

    # -- geometry --------------------------------------------------------------------
    def _geometry(self, shape_hw: tuple[int, int]) -> _Geometry:
        g = self._geom
        if g is not None and g.shape_hw == shape_hw:
            return g
        assert self._roi is not None
        x0, y0, x1, y1 = roi_bbox(self._roi, shape_hw)
        s = self.stride
        if s > 1:  # whole s x s blocks, so the nearest-neighbour downscale takes pixels [::s, ::s]
            x1 = x0 + max(1, (x1 - x0) // s) * s if x0 + s <= shape_hw[1] else x1
            y1 = y0 + max(1, (y1 - y0) // s) * s if y0 + s <= shape_hw[0] else y1
        box = (x0, y0, x1, y1)
        full = _mask_in_box(self._roi, box)
        mask = np.ascontiguousarray(np.where(full[::s, ::s], 255, 0).astype(np.uint8))
        xs = np.arange(x0, x1, s, dtype=np.float64)
        ys = np.arange(y0, y1, s, dtype=np.float64)
        hh, ww = mask.shape
        g = _Geometry(
            shape_hw, box, mask, xs, ys, xs * xs, ys * ys,
            np.empty((hh, ww, 3), np.uint8), [np.empty((hh, ww), np.uint8) for _ in range(3)],
            np.empty((1, ww), np.int32), np.empty((hh, 1), np.int32),
        )
        self._geom = g
        return g

    # -- per frame -------------------------------------------------------------------
    def _invalid(self, flag: str) -> Reading:
        stats = tuple(ClassStats(c.name, _NAN, _NAN, _NAN, 0, _NAN) for c in self.classes)
        return Reading(_NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, False, (flag,), stats, self._roi)

    def measure(self, image_bgr: np.ndarray) -> Reading:
        """Measure one BGR uint8 frame. Bad frames give an invalid, flagged Reading.

        Raises ``VisionError`` only when the drum cannot be found on the first frame.
        """
        img = image_bgr
        if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            shape = getattr(img, "shape", None)
            dtype = getattr(img, "dtype", type(img).__name__)
            return self._invalid(f"bad_frame:not a 3-channel 8-bit BGR image (shape {shape}, dtype {dtype})")
        shape_hw = (int(img.shape[0]), int(img.shape[1]))
        if self._roi is None:
            self._roi = detect_drum(img)
        g = self._geom
        if g is not None and g.shape_hw != shape_hw:
            return self._invalid(
                f"size_changed:frame is {shape_hw[1]}x{shape_hw[0]}, stream started at {g.shape_hw[1]}x{g.shape_hw[0]}"
            )
        g = self._geometry(shape_hw)
        x0, y0, x1, y1 = g.box
        s = self.stride
        crop = img[y0:y1, x0:x1]
        if s > 1:  # every s-th row and column, exactly (nearest neighbour at 1/s)
            crop = cv2.resize(crop, (g.hsv.shape[1], g.hsv.shape[0]), interpolation=cv2.INTER_NEAREST)
        cv2.cvtColor(crop, cv2.COLOR_BGR2HSV, dst=g.hsv)
        cv2.split(g.hsv, g.planes)
        hp, sp, vp = g.planes
        masks = self.classifier.class_masks(hp, sp, vp, g.mask)
        return self._reading(masks, vp, g)

    def _reading(self, masks: list[np.ndarray], vp: np.ndarray, g: _Geometry) -> Reading:
        roi = self._roi
        assert roi is not None
        area = float(self.stride * self.stride)
        flags: list[str] = []
        raw: list[tuple[float, float, float, float, float]] = []  # n, sx, sy, sxx, syy (strided px)
        col, row = g.colsum, g.rowsum
        for mk in masks:
            cv2.reduce(mk, 0, cv2.REDUCE_SUM, dst=col, dtype=cv2.CV_32S)
            cv2.reduce(mk, 1, cv2.REDUCE_SUM, dst=row, dtype=cv2.CV_32S)
            c = col.ravel()
            r = row.ravel()
            n = float(c.sum()) / 255.0
            raw.append((n, float(c @ g.xs) / 255.0, float(r @ g.ys) / 255.0,
                        float(c @ g.xs2) / 255.0, float(r @ g.ys2) / 255.0))
        total = sum(r[0] for r in raw)
        stats: list[ClassStats] = []
        for cls, (n, sx, sy, sxx, syy) in zip(self.classes, raw):
            n_px = int(round(n * area))
            frac = n / total if total > 0 else _NAN
            if n_px < self.min_pixels or n <= 0:
                flags.append(f"few_pixels:{cls.name}")
                stats.append(ClassStats(cls.name, _NAN, _NAN, _NAN, n_px, frac))
                continue
            cx, cy = sx / n, sy / n
            var = max(sxx / n - cx * cx, 0.0) + max(syy / n - cy * cy, 0.0)
            stats.append(ClassStats(cls.name, cx, cy, math.sqrt(var), n_px, frac))
        a, b = stats[0], stats[1]
        mix = mixing_indices((a.cx_px, a.cy_px), (b.cx_px, b.cy_px), a.sigma_px, b.sigma_px, roi.r_px, self._d0)
        if self._d0 is None and math.isfinite(mix.d_px) and mix.d_px > 0:
            self._d0 = mix.d_px
            mix = mixing_indices((a.cx_px, a.cy_px), (b.cx_px, b.cy_px), a.sigma_px, b.sigma_px, roi.r_px, self._d0)
        n12 = raw[0][0] + raw[1][0]
        conc = raw[0][0] / n12 if n12 > 0 else _NAN
        slope = self._slope(masks, vp, g)
        valid = math.isfinite(mix.mi)
        return Reading(
            mix.mi, mix.mi_sigmoid, mix.mi_linear, mix.d_px, mix.dsigma_px, slope, conc, valid,
            tuple(flags), tuple(stats), roi,
        )

    def _slope(self, masks: list[np.ndarray], vp: np.ndarray, g: _Geometry) -> float:
        ss = self.slope_stride
        if self.bed == "dark":
            sub = np.ascontiguousarray(vp[::ss, ::ss])
            cv2.LUT(sub, self._dark_lut, dst=sub)
            cv2.bitwise_and(sub, np.ascontiguousarray(g.mask[::ss, ::ss]), dst=sub)
        else:
            sub = np.ascontiguousarray(masks[0][::ss, ::ss])
            for mk in masks[1:]:
                cv2.bitwise_or(sub, np.ascontiguousarray(mk[::ss, ::ss]), dst=sub)
        mo = cv2.moments(sub, binaryImage=True)
        step = float(self.stride * ss)
        x0, y0 = g.box[0], g.box[1]
        roi = self._roi
        assert roi is not None
        # moments are in sub-grid units: map the drum centre into the same frame
        return slope_from_moments(
            mo["m00"], mo["m10"], mo["m01"], mo["m20"], mo["m11"], mo["m02"],
            (roi.cx_px - x0) / step, (roi.cy_px - y0) / step,
            min_px=max(1.0, self.min_pixels / (step * step)),
        )

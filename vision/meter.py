"""The meter: one BGR frame in, one ``Reading`` (centroids, spreads, MI, slope) out.

Per frame one compiled pass over the ROI (``vision.moments``) classifies every pixel
with lookup tables made from the colour classes (exactly the classes' HSV boxes) and
sums each class's pixel count and first and second moments; centroids, spreads, the
MI and the bed's slope angle follow from those sums. The ROI's row spans are built
once per ROI and frame size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vision.colours import DEFAULT_CLASSES, Classifier, ColourClass
from vision.errors import VisionError
from vision.mixing import mixing_indices
from vision.moments import class_tables, frame_moments, row_spans
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
    box: tuple[int, int, int, int]  # x0, y0, x1, y1 of the ROI's bounding box, px
    first: np.ndarray  # per grid row of the box: first and one-past-last grid column inside the ROI
    last: np.ndarray


class Meter:
    """Measures mixing in BGR frames with a fixed set of colour classes.

    ``roi=None`` detects the drum on the first good frame (``detect_drum``). ``bed``:
    ``"color"`` takes the bed for the slope angle as the union of the classes; ``"dark"``
    takes the pixels with V <= ``dark_v_max`` inside the ROI (dark bed on a backlit drum).
    Classes with fewer than ``min_pixels`` pixels give NaN and a flag. ``stride`` > 1 is an
    explicit, opt-in decimation (every ``stride``-th row and column); the default 1 uses
    every pixel. The slope uses the exact moments of the whole bed. The MI uses the
    first two classes.
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
    ) -> None:
        self.classes = tuple(classes)
        if len(self.classes) < 2:
            raise VisionError(f"the mixing index needs at least two colour classes, got {len(self.classes)}")
        if bed not in BED_MODES:
            raise VisionError(f"bed must be one of {BED_MODES}, got {bed!r}")
        if int(stride) < 1:
            raise VisionError(f"stride must be >= 1, got {stride}")
        if not 0 <= int(dark_v_max) <= 255:
            raise VisionError(f"dark_v_max must be within 0..255, got {dark_v_max}")
        self.classifier = Classifier(self.classes)
        self.bed = bed
        self.min_pixels = int(min_pixels)
        self.dark_v_max = int(dark_v_max)
        self.stride = int(stride)
        self._tables = class_tables(self.classifier)
        self._sums = np.zeros((len(self.classes) + 1, 6), np.int64)
        self._roi = roi
        self._roi_given = roi is not None
        self._geom: _Geometry | None = None
        self._d0: float | None = None

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
        box = roi_bbox(self._roi, shape_hw)
        s = self.stride
        inside = _mask_in_box(self._roi, box)[::s, ::s]
        first, last = row_spans(inside)
        g = _Geometry(shape_hw, box, first, last)
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
        dark = self.dark_v_max if self.bed == "dark" else -1
        sums = frame_moments(img, self._tables, g.box[:2], g.first, g.last, self.stride, dark, out=self._sums)
        return self._reading(sums)

    def _reading(self, sums: np.ndarray) -> Reading:
        roi = self._roi
        assert roi is not None
        area = float(self.stride * self.stride)
        flags: list[str] = []
        k = len(self.classes)
        ns = [float(sums[i, 0]) for i in range(k)]
        total = sum(ns)
        stats: list[ClassStats] = []
        for i, cls in enumerate(self.classes):
            n, sx, sy, sxx, syy, _ = (float(v) for v in sums[i])
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
        n12 = ns[0] + ns[1]
        conc = ns[0] / n12 if n12 > 0 else _NAN
        bed = sums[k] if self.bed == "dark" else sums[:k].sum(axis=0)  # classes are exclusive: moments add up
        m00, m10, m01, m20, m02, m11 = (float(v) for v in bed)
        slope = slope_from_moments(
            m00, m10, m01, m20, m11, m02, roi.cx_px, roi.cy_px, min_px=max(1.0, self.min_pixels / area)
        )
        valid = math.isfinite(mix.mi)
        return Reading(
            mix.mi, mix.mi_sigmoid, mix.mi_linear, mix.d_px, mix.dsigma_px, slope, conc, valid,
            tuple(flags), tuple(stats), roi,
        )

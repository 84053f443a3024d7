"""The meter: one BGR frame in, one ``Reading`` (centroids, spreads, MI, slope) out.

Per frame one compiled pass over the ROI (``vision.moments``) classifies every pixel
with the exact BGR lookup table of the colour classes (learned model or HSV boxes) and
sums each class's pixel count and first and second moments, and the bed's pixels per
small cell; centroids, spreads and the MI follow from the sums, the free-surface angle
from the cells (``vision.slope``), in gravity's frame when the camera is turned or mirrored
(``vision.gravity``). The drum is detected, and the ROI's grid, row spans and cells built
(``vision.grid``), once per frame size. On a frame with glare (clipped light) the spots and their halos are
filled with the class mix around them (``vision.glare``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from vision.colours import DEFAULT_CLASSES, ColourClass, check_class_set, counted_classes
from vision.errors import VisionError
from vision.glare import HALO, RING, glare_fill
from vision.gravity import from_gravity, gravity_matrix, turn_grid, turn_moments
from vision.grid import Geometry, build_geometry
from vision.islands import island_relabel, relabel_moments
from vision.mixing import mixing_indices
from vision.moments import class_tables, frame_moments, kernel_labels, remapped_tables
from vision.photometric import (
    JUMP,
    REBAKE_AT_ONCE,
    LightEstimate,
    channel_maps,
    check_class_reference,
    check_reference,
    classes_in_reference,
    roi_sample_index,
    sample_means,
    track_light,
)
from vision.roi import DrumROI, detect_drum
from vision.slope import slope_from_moments, surface_from_occupancy

__all__ = ["BED_MODES", "MAX_OUTSIDE", "ClassStats", "Meter", "Reading", "check_meter_numbers", "gravity_matrix"]

BED_MODES = ("color", "dark")
MAX_OUTSIDE = 0.05
"""A drum with more than this share of its area outside the frame gives no MI (``roi_outside_frame``)."""
_NAN = float("nan")


@dataclass(frozen=True, slots=True)
class ClassStats:
    """One colour class in one frame: centroid and spread (px, original image), pixel count, shares.

    ``sigma_px = sqrt(var_x + var_y)``; ``frac`` = this class's pixels / all classified pixels;
    ``roi_share`` = this class's pixels / the ROI's pixels. NaN centroid/spread when the class
    is too small (see ``Meter``).
    """

    name: str
    cx_px: float
    cy_px: float
    sigma_px: float
    n_px: int
    frac: float
    roi_share: float = _NAN


@dataclass(frozen=True)
class Reading:
    """Everything measured in one frame.

    ``mi`` (eq. 4), ``mi_sigmoid`` (eq. 3), ``mi_linear`` (eq. 1, relative to the first
    valid frame), ``d_px``, ``dsigma_px``, ``concentration`` = n_1 / (n_1 + n_2).
    ``slope_deg`` = angle of the bed's free surface over the central chord,
    ``surface_curvature`` = its S-shape, ``slope_axis_deg`` = the bed's principal axis
    (see ``vision.slope``); ``surface_mid_px`` = a point of the fitted surface line.
    ``roi`` = the drum region used for this frame. ``valid`` is
    False when ``mi`` is NaN; ``flags`` say why (``few_pixels:blue``, ``collapsed:blue``,
    ``roi_outside_frame:12%`` (more than ``MAX_OUTSIDE`` of the drum out of view; the
    classes in view are still measured), ``bad_frame:...``).
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
    slope_axis_deg: float = _NAN
    surface_curvature: float = _NAN
    surface_mid_px: tuple[float, float] = (_NAN, _NAN)
    surface_image_deg: float = _NAN
    """The fitted surface line's angle in the image itself (= ``slope_deg`` for a camera not
    turned or mirrored; what the overlay draws through ``surface_mid_px``)."""

    def cls(self, name: str) -> ClassStats:
        """The stats of the class called ``name``."""
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(name)


class Meter:
    """Measures mixing in BGR frames with a fixed set of colour classes.

    ``classes``: HSV classes or a learned model (reject classes included; they are never
    counted). ``roi=None`` detects the drum on the first good frame of every frame size
    (``detect_drum``; :meth:`redetect` forgets it). ``bed``: ``"color"`` takes the bed for
    the slope as the union of the classes; ``"dark"`` the pixels with V <= ``dark_v_max``
    inside the ROI (dark bed on a backlit drum). ``stride`` > 1 is an explicit, opt-in
    decimation (every ``stride``-th row and column). The MI uses the first two counted classes.

    Validity is relative to the ROI: a class with less than ``min_share`` of the ROI's
    pixels (or fewer than ``min_pixels``) is ``few_pixels``; one whose share drops below
    ``collapse_ratio`` x its running median over the last ``history`` good frames is
    ``collapsed``. Either gives MI = NaN (collapsed frames do not enter the median), and so
    does a drum with more than ``MAX_OUTSIDE`` of its area outside the frame.

    ``opening``: the class opening of ``vision.moments.open_labels`` on the stride grid
    (a one-pixel erosion, then a dilation back inside the class): drops the thin rims and
    gaps that chroma blur (JPEG 4:2:0) or anti-aliasing give the wrong class -- between
    light particles, the colour of a darker class of the same hue -- and keeps every pixel
    of a particle at least 3 grid pixels across, so its centroid does not move. Off by
    default (it halves the frame rate); ``classes suggest`` turns it on when it changes
    the centroids on the frames it learned from. The free surface uses the pixels before
    the opening.

    ``glare_fill``: fill glare spots (clipped light no class claims) and their halos with
    the class mix seen around them (``vision.glare``); it costs nothing on frames without
    glare.
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
        min_share: float = 0.005,
        collapse_ratio: float = 0.4,
        history: int = 25,
        opening: bool = False,
        glare_fill: bool = True,
        light_reference: np.ndarray | None = None,
        light_reference_classes: np.ndarray | None = None,
        camera_rotation_deg: float = 0.0,
        mirror: bool = False,
        track_every: int = 4,
        rebake_threshold: float = 0.03,
        island_px: int = 0,
    ) -> None:
        self.colour_classes = check_class_set(classes)
        self.classes = counted_classes(self.colour_classes)
        if len(self.classes) < 2:
            raise VisionError(f"the mixing index needs at least two colour classes, got {len(self.classes)}")
        if bed not in BED_MODES:
            raise VisionError(f"bed must be one of {BED_MODES}, got {bed!r}")
        check_meter_numbers(min_pixels=min_pixels, dark_v_max=dark_v_max, stride=stride, min_share=min_share,
                            collapse_ratio=collapse_ratio, history=history)
        self.bed = bed
        self.min_pixels = int(min_pixels)
        self.dark_v_max = int(dark_v_max)
        self.stride = int(stride)
        self.min_share = float(min_share)
        self.collapse_ratio = float(collapse_ratio)
        self.history = int(history)
        if not isinstance(opening, (bool, np.bool_)):
            raise VisionError(f"opening must be true or false, got {opening!r}")
        self.opening = bool(opening)
        self.glare_fill = bool(glare_fill)
        self._tables = self._base_tables = class_tables(self.colour_classes)
        self._light_ref = None if light_reference is None else check_reference(light_reference)
        self._class_ref = (None if light_reference_classes is None or self._light_ref is None
                           else check_class_reference(light_reference_classes, len(self.classes) + 1))
        self._n_ref = classes_in_reference(self._class_ref)
        self._est_row = np.zeros(8)  # the light kernel's result row, reused frame to frame
        check_meter_numbers(track_every=track_every, rebake_threshold=rebake_threshold,
                            camera_rotation_deg=camera_rotation_deg, island_px=island_px)
        self.island_px = int(island_px)
        # each counted class's CIELAB L (of its display colour): islands go only into a darker class
        self._lightness = [float(v) for v in cv2.cvtColor(
            np.array([[c.display_bgr for c in self.classes]], np.uint8), cv2.COLOR_BGR2LAB)[0, :, 0]]
        if not isinstance(mirror, (bool, np.bool_)):
            raise VisionError(f"mirror must be true or false, got {mirror!r}")
        self.camera_rotation_deg = float(camera_rotation_deg)
        self.mirror = bool(mirror)
        self._gravity = gravity_matrix(self.camera_rotation_deg, self.mirror)
        self.track_every = int(track_every)
        self.rebake_threshold = float(rebake_threshold)
        self._baked_gains = (1.0, 1.0, 1.0)
        self._confirm = False  # a small light move seen once: the next frame is estimated to confirm it
        self._light: LightEstimate | None = None
        self._accepted: LightEstimate | None = None  # the last estimate that mapped back
        self._n_frames = 0
        self._means_now = np.zeros(3)
        self._means_then = [-1e9] * 3  # the sample means at the last full estimate (none yet)
        self.rebakes = 0
        self.estimates = 0  # full light estimates made (``vision.photometric.track_light``)
        self._sums = np.zeros((len(self.classes) + 2, 6), np.int64)
        self._roi = roi
        self._roi_given = roi is not None
        self._rois: dict[tuple[int, int], DrumROI] = {}
        self._geoms: dict[tuple[int, int], Geometry] = {}
        self._shares: list[deque[float]] = [deque(maxlen=self.history) for _ in self.classes]
        self._d0: float | None = None

    @property
    def roi(self) -> DrumROI | None:
        """The ROI of the last measured frame (None until the first frame when auto-detecting)."""
        return self._roi

    @property
    def light(self) -> LightEstimate | None:
        """The last light estimate (None without a light reference or before the first frame)."""
        return self._light

    def _track_light(self, flat: np.ndarray, g: Geometry) -> None:
        assert self._light_ref is not None and g.sample is not None
        last = self._accepted
        est = track_light(flat, g.sample, self._light_ref, self._class_ref, self._base_tables.fine,
                          None if last is None else last.gains_bgr, n_ref=self._n_ref, out=self._est_row)
        self._light = est
        self.estimates += 1
        if est.cause is not None:
            return
        self._accepted = est
        moved = max(abs(math.log(a / b)) for a, b in zip(est.gains_bgr, self._baked_gains, strict=True))
        if moved <= math.log1p(self.rebake_threshold):
            self._confirm = False
            return
        if moved <= math.log1p(REBAKE_AT_ONCE) and not self._confirm:
            # a small move seen once may be the estimate's own scatter (a noisy frame): estimate
            # the next frame too, and re-bake when it sees the move as well
            self._confirm = True
            return
        self._confirm = False
        self._tables = remapped_tables(self.colour_classes, channel_maps(est.gains_bgr))
        self._baked_gains = est.gains_bgr
        self.rebakes += 1

    @property
    def d0_px(self) -> float | None:
        """Reference centroid distance of eq. 1 (first valid frame), px."""
        return self._d0

    def reset(self) -> None:
        """Forget the eq. 1 reference distance, the share history and auto-detected ROIs."""
        self._d0 = None
        for h in self._shares:
            h.clear()
        self.redetect()

    def redetect(self) -> None:
        """Detect the drum again on the next frame (of every size); a given ROI is kept."""
        self._rois.clear()
        self._geoms.clear()
        if not self._roi_given:
            self._roi = None

    # -- geometry --------------------------------------------------------------------
    def _geometry(self, img: np.ndarray, shape_hw: tuple[int, int]) -> Geometry:
        g = self._geoms.get(shape_hw)
        if g is not None:
            return g
        if self._roi_given:
            roi = self._roi
        else:
            roi = self._rois.get(shape_hw)
            if roi is None:
                roi = self._rois[shape_hw] = detect_drum(img)
        assert roi is not None
        g = self._geoms[shape_hw] = build_geometry(roi, shape_hw, self.stride)
        return g

    # -- per frame -------------------------------------------------------------------
    def invalid(self, flag: str) -> Reading:
        """An invalid reading with one flag (a frame that cannot be measured), on the current ROI."""
        stats = tuple(ClassStats(c.name, _NAN, _NAN, _NAN, 0, _NAN) for c in self.classes)
        return Reading(_NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, False, (flag,), stats, self._roi)

    def measure(self, image_bgr: np.ndarray) -> Reading:
        """Measure one BGR uint8 frame. Bad frames give an invalid, flagged Reading.

        Raises ``VisionError`` only when the drum cannot be found in a frame of a new size.
        """
        img = image_bgr
        if not isinstance(img, np.ndarray) or img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            shape = getattr(img, "shape", None)
            dtype = getattr(img, "dtype", type(img).__name__)
            return self.invalid(f"bad_frame:not a 3-channel 8-bit BGR image (shape {shape}, dtype {dtype})")
        shape_hw = (int(img.shape[0]), int(img.shape[1]))
        g = self._geometry(img, shape_hw)
        self._roi = g.roi
        dark = self.dark_v_max if self.bed == "dark" else -1

        def moments() -> np.ndarray:
            return frame_moments(img, self._tables, g.box[:2], g.first, g.last, self.stride, dark, out=self._sums,
                                 occupancy=g.occ, occ_shift=g.shift, opening=self.opening, glare_cells=g.gocc,
                                 cell_offset_xy=g.cell_off)

        # the pass first, then the light: the light's scattered samples then read a frame the
        # pass has brought into the cache (before the pass, they cost 2-3x as much); when the
        # estimate re-bakes the table, the pass runs again in the new table's terms
        sums = moments()
        if self._light_ref is not None:
            if g.sample is None:
                g.sample = roi_sample_index(g.roi, (img.shape[0], img.shape[1]))
            flat = np.ascontiguousarray(img).reshape(-1, 3)
            means = sample_means(flat, g.sample, self._means_now).tolist()  # 3 floats: no ufunc overhead
            if self._n_frames % self.track_every == 0 or self._confirm or any(
                    abs(a - b) > max(3.0, JUMP * b) for a, b in zip(means, self._means_then, strict=True)):
                tables = self._tables
                self._track_light(flat, g)
                self._means_then = means
                if self._tables is not tables:
                    sums = moments()
        self._n_frames += 1
        k = len(self.classes)
        rows = sums.tolist()  # Python ints: one conversion, not one per element
        deltas = []
        if self.island_px > 0:
            deltas.append(self._island_delta(img, g))
        if self.glare_fill and rows[k][0] > 0:
            deltas.append(self._glare_delta(img, g, rows[k][0]))
        for delta in deltas:
            for i, d in enumerate(delta.tolist()):
                rows[i] = [a + b for a, b in zip(rows[i], d, strict=True)]
        return self._reading(rows, g)

    def _grid_labels(self, img: np.ndarray, g: Geometry, ia: int, ib: int, ja: int,
                     jb: int) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
        """The kernel's labels of grid rows ``ia:ib`` and columns ``ja:jb`` (0 outside the ROI's
        spans), that window's inside mask, and the image px of its first grid pixel."""
        s = self.stride
        x0, y0 = g.box[:2]
        sub = np.ascontiguousarray(img[y0 + ia * s: y0 + ib * s: s, x0 + ja * s: x0 + jb * s: s])
        jj = np.arange(ja, ja + sub.shape[1])
        rows = slice(ia, ia + sub.shape[0])
        inside = (jj[None, :] >= g.first[rows, None]) & (jj[None, :] < g.last[rows, None])  # the spans
        return kernel_labels(sub, self._tables.fine, inside, self.opening), inside, (x0 + ja * s, y0 + ia * s)

    def _island_delta(self, img: np.ndarray, g: Geometry) -> np.ndarray:
        """The class moments' change from the island filter (``vision.islands``) over the ROI."""
        k = len(self.classes)
        labels, _, origin = self._grid_labels(img, g, 0, len(g.first), 0, int(g.last.max()))
        area = max(1, self.island_px // (self.stride * self.stride))  # image px -> grid px
        new = island_relabel(labels, k, area, lightness=self._lightness)
        return relabel_moments(labels, new, k, origin, self.stride)

    def _glare_delta(self, img: np.ndarray, g: Geometry, n_glare: float) -> np.ndarray:
        """``vision.glare.glare_fill`` on the grid window around the frame's glare cells."""
        s = self.stride
        ci, cj = np.nonzero(g.gocc)
        cell = 1 << g.shift
        margin = (HALO + RING) * math.sqrt(n_glare / math.pi) + 6.0  # grid px beyond the glare's cells
        ox, oy = g.cell_off
        ia = max(0, int((ci.min() * cell - oy) / s - margin))
        ib = min(len(g.first), int(math.ceil(((ci.max() + 1) * cell - oy) / s + margin)))
        ja = max(0, int((cj.min() * cell - ox) / s - margin))
        jb = min(int(g.last.max()), int(math.ceil(((cj.max() + 1) * cell - ox) / s + margin)))
        labels, inside, origin = self._grid_labels(img, g, ia, ib, ja, jb)
        return glare_fill(labels, inside, len(self.classes), origin, s)

    def _reading(self, rows: list[list[float]], g: Geometry) -> Reading:
        roi = g.roi
        area = float(self.stride * self.stride)
        flags: list[str] = []
        k = len(self.classes)
        ns = [float(rows[i][0]) for i in range(k)]
        total = sum(ns)
        stats: list[ClassStats] = []
        for i, cls in enumerate(self.classes):
            n, sx, sy, sxx, syy, _ = (float(v) for v in rows[i])
            n_px = int(round(n * area))
            frac = n / total if total > 0 else _NAN
            share = n / g.roi_px if g.roi_px > 0 else _NAN
            hist = self._shares[i]
            bad = None
            if n_px < self.min_pixels or n <= 0 or not share >= self.min_share:
                bad = "few_pixels"
            elif len(hist) >= 5 and share < self.collapse_ratio * _median(hist):
                bad = "collapsed"
            else:
                hist.append(share)
            if bad is not None:
                flags.append(f"{bad}:{cls.name}")
                stats.append(ClassStats(cls.name, _NAN, _NAN, _NAN, n_px, frac, share))
                continue
            cx, cy = sx / n, sy / n
            var = max(sxx / n - cx * cx, 0.0) + max(syy / n - cy * cy, 0.0)
            stats.append(ClassStats(cls.name, cx, cy, math.sqrt(var), n_px, frac, share))
        a, b = stats[0], stats[1]
        light = self._light
        if light is not None and light.cause is not None:  # the classes cannot be trusted in this light
            flags.append(f"lighting_changed:{light.cause}")
            a = b = ClassStats(a.name, _NAN, _NAN, _NAN, 0, _NAN)
        if g.outside > MAX_OUTSIDE:  # the centroids are those of the part in view, not the bed's
            flags.append(f"roi_outside_frame:{100.0 * g.outside:.0f}%")
            a = b = ClassStats(a.name, _NAN, _NAN, _NAN, 0, _NAN)
        mix = mixing_indices((a.cx_px, a.cy_px), (b.cx_px, b.cy_px), a.sigma_px, b.sigma_px, roi.r_px, self._d0)
        if self._d0 is None and math.isfinite(mix.d_px) and mix.d_px > 0:
            self._d0 = mix.d_px
            mix = mixing_indices((a.cx_px, a.cy_px), (b.cx_px, b.cy_px), a.sigma_px, b.sigma_px, roi.r_px, self._d0)
        n12 = ns[0] + ns[1]
        conc = ns[0] / n12 if n12 > 0 else _NAN
        # the classes are exclusive: their moments add up to the bed's
        bed = rows[k + 1] if self.bed == "dark" else [sum(c) for c in zip(*rows[:k], strict=True)]
        m00, m10, m01, m20, m02, m11 = (float(v) for v in bed)
        min_bed = max(1.0, self.min_pixels / area, self.min_share * g.roi_px)
        t = self._gravity
        if t is not None:
            m10, m01, m20, m11, m02 = turn_moments(t, m00, m10, m01, m20, m11, m02, roi.cx_px, roi.cy_px)
        axis = slope_from_moments(m00, m10, m01, m20, m11, m02, roi.cx_px, roi.cy_px, min_px=min_bed)
        image_deg = _NAN
        if m00 >= min_bed:
            if t is None:
                surf = surface_from_occupancy(g.occ, g.area, g.full_area, g.cells_xy, g.shift, roi.r_px, g.work)
                mid = surf.mid_px
                image_deg = surf.slope_deg
            else:
                occ, cell_area, origin = turn_grid(t, g, g.occ)
                surf = surface_from_occupancy(occ, cell_area, g.full_area, origin, g.shift, roi.r_px)
                mid, image_deg = from_gravity(t, surf.mid_px, surf.slope_deg, roi)
            slope, curv = surf.slope_deg, surf.curvature
            if not math.isfinite(slope):
                flags.append("no_surface:no free surface found (too few surface points)")
            elif not math.isfinite(curv):
                flags.append("no_curvature:surface points too few or collinear for the S-shape")
            if not math.isfinite(axis):
                flags.append("no_axis:the bed has no principal axis (isotropic)")
        else:
            slope = curv = _NAN
            mid = (_NAN, _NAN)
            flags.append(f"no_surface:bed of {int(m00 * area)} px")
        valid = math.isfinite(mix.mi)
        return Reading(
            mix.mi, mix.mi_sigmoid, mix.mi_linear, mix.d_px, mix.dsigma_px, slope, conc, valid,
            tuple(flags), tuple(stats), roi, axis, curv, mid, image_deg,
        )


def _median(values: deque[float]) -> float:
    v = sorted(values)
    n = len(v)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


def check_meter_numbers(**values: float) -> None:
    """Validate the meter's numeric settings by name (one clear ``VisionError`` naming the key)."""
    limits = {
        "min_pixels": (1, 10**9, True), "dark_v_max": (0, 255, True), "stride": (1, 16, True),
        "min_share": (0.0, 0.5, False), "collapse_ratio": (0.0, 1.0, False), "history": (1, 10_000, True),
        "track_every": (1, 10_000, True), "rebake_threshold": (0.001, 1.0, False),
        "camera_rotation_deg": (-360.0, 360.0, False), "island_px": (0, 10**6, True),
    }
    for key, v in values.items():
        lo, hi, integer = limits[key]
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise VisionError(f"{key} must be a number within {lo}..{hi}, got {v!r}")
        if integer and not float(v).is_integer():
            raise VisionError(f"{key} must be an integer within {lo}..{hi}, got {v!r}")
        if not math.isfinite(v) or not lo <= v <= hi:
            raise VisionError(f"{key} must be within {lo}..{hi}, got {v!r}")

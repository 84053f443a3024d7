"""Photometric tracking: each frame's exposure and white balance against the light at set-up.

The light is estimated from what does not change with the bed's composition: each particle
class's own colour. ``classes suggest`` keeps, with the classes, the per-channel quantiles of
each class's pixels in the set-up light (``[meter] light_reference_classes``); a frame's
samples (a few thousand drum pixels on a fixed grid) are classified in the reference's terms
(through the inverse of the current gains, :func:`channel_maps`), and each channel's gain in
linear light (sensor gamma :data:`GAMMA`) is the weighted median of log(now / then) over the
(class, level) entries both see unclipped and above the black level, each weighing its
display value squared -- a dark class, or a class's dark edge levels (which move with the mix
and with where in an unevenly lit drum a class lies), counts little. Classify again, fit again
(:func:`track_light`, from the last light; when the light moved, also from the drum-wide
quantiles' gains -- a guess only, they follow the class shares -- and from an exposure-only
start; the result that keeps every class in view, then fits more channels, then leaves the
lower spread, wins). The drum's empty region and the gaps between particles (no class) are
not fitted: how much of them a frame shows is the bed's doing.

The classification is then done in the reference's terms: the class table is re-baked
through per-channel maps (``vision.moments.remapped_tables``) when the gains move beyond a
threshold -- a one-off cost, the per-pixel pass stays one lookup. A clipped channel (255
under a gain > 1) maps to the middle of the reference values that clip.

When the light cannot be mapped back -- nothing left unclipped and above the black level, the
clipped levels saying the gain is beyond what the rest fits (saturation), a gain outside
:data:`GAIN_RANGE`, or entries that one gain per channel leaves far apart (a tone curve or
cast: the pooled spread over :data:`MAX_CLASS_SPREAD`) -- the estimate names the cause, and the
meter gives no MI for the frame and a ``lighting_changed:<cause>`` flag. A config without a
per-class reference is tracked on the drum-wide quantiles (``[meter] light_reference``,
:func:`estimate_light`), as before. History and measurements: docs/validation.md, section 15.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vision.errors import VisionError
from vision.lightkernels import GAIN_RANGE, GAMMA, kernels, maps_into
from vision.roi import DrumROI, _mask_in_box, roi_bbox

__all__ = [
    "CLASS_LEVELS",
    "GAIN_RANGE",
    "GAMMA",
    "LEVELS",
    "REBAKE_AT_ONCE",
    "LightEstimate",
    "channel_maps",
    "check_class_reference",
    "check_reference",
    "class_quantiles",
    "class_reference_from_frames",
    "classes_in_reference",
    "estimate_light",
    "light_quantiles",
    "reference_from_frames",
    "refine_light",
    "roi_sample_index",
    "sample_labels",
    "sample_means",
    "track_light",
]

LEVELS = np.linspace(0.30, 0.98, 35)
"""Quantile levels of the ROI's pixels (per channel) in the light reference."""
MAX_SPREAD = 0.2
"""Largest median |log ratio - log gain| over a channel's levels that one gain explains (the
real PMMA frames, unperturbed, reach 0.11 against a reference from another frame: the bed's
share of the drum moves the levels near the bed/background step)."""
MAX_CLASS_SPREAD = 0.17
"""The largest pooled weighted spread (:func:`track_light`) one gain per channel explains: the
rule of ``vision.loro.spread_rule`` (twice the 99th percentile at the set-up light) on every
rig of the cross-rig bench, rounded up (0.162; docs/validation.md, section 15: checked
leave-one-rig-out)."""
MAX_DISAGREEMENT = 0.26
"""The largest range of the classes' own gains at their median level (log, any channel) that one
light explains: a tone curve or a cast that the pooled fit absorbs moves bright classes apart
(``vision.lightkernels``); the rule of ``vision.loro.spread_rule`` on every rig of the cross-rig
bench, rounded up (0.256; docs/validation.md, section 15: checked leave-one-rig-out)."""
JUMP = 0.03
"""Between two full estimates, a frame whose sampled mean moved by more than this share in a
channel (or 3 display levels) since the last estimate is estimated at once (``Meter``)."""
REBAKE_AT_ONCE = 0.1
"""A light move beyond the re-bake threshold but within this share (per channel) re-bakes the
table only when the next frame's estimate sees it too (``Meter``): on a steady bed under a
webcam's noise (sigma 8) single estimates scatter by up to 4.6 % in a dim channel, and each
re-bake costs ~12 ms; a jump beyond it re-bakes at once."""
SAMPLES = 2000
"""About this many ROI pixels per frame for the estimate."""
CLASS_LEVELS = np.array([0.1, 0.25, 0.5, 0.75, 0.9])
"""Quantile levels of each class's pixels (per channel) in the per-class light reference."""
MIN_CLASS_SAMPLES = 40
"""A class with fewer sampled pixels has no quantiles (written as -1)."""
_NAMES = ("blue", "green", "red")


@dataclass(frozen=True, slots=True)
class LightEstimate:
    """Gains (linear light, B, G, R) of a frame against the reference, how far one gain per
    channel leaves the entries (``spread``: median |log ratio - log gain|), how far apart the
    classes' own gains are (``disagreement``, log; 0 without a per-class reference), and the
    cause when it cannot be mapped back (``None`` when it can)."""

    gains_bgr: tuple[float, float, float]
    spread: float
    cause: str | None = None
    disagreement: float = 0.0


def check_reference(ref, where: str = "light_reference") -> np.ndarray:
    """A light reference as a float (3, len(LEVELS)) array of non-decreasing display values 0..255."""
    try:
        a = np.asarray(ref, dtype=np.float64)
    except (TypeError, ValueError):
        raise VisionError(f"{where} must be 3 rows of {len(LEVELS)} numbers") from None
    if a.shape != (3, len(LEVELS)):
        raise VisionError(f"{where} must be 3 rows (B, G, R) of {len(LEVELS)} numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 255:
        raise VisionError(f"{where} must hold finite numbers within 0..255")
    if np.any(np.diff(a, axis=1) < -1e-9):
        raise VisionError(f"{where}: each row must be non-decreasing (quantiles)")
    return a


def check_class_reference(ref, n_labels: int, where: str = "light_reference_classes") -> np.ndarray:
    """A per-class light reference as a float (n_labels, 3, len(CLASS_LEVELS)) array (rows of
    3 x L numbers, B then G then R; -1 = a class not seen); ``n_labels`` = counted classes + 1."""
    try:
        a = np.asarray(ref, dtype=np.float64)
    except (TypeError, ValueError):
        raise VisionError(f"{where} must be rows of {3 * len(CLASS_LEVELS)} numbers") from None
    if a.ndim == 2:
        a = a.reshape(a.shape[0], 3, -1) if a.shape[1] == 3 * len(CLASS_LEVELS) else a[:, None, :]
    if a.shape != (n_labels, 3, len(CLASS_LEVELS)):
        raise VisionError(f"{where} must be {n_labels} rows (no class, then each counted class) of "
                          f"{3 * len(CLASS_LEVELS)} numbers (B, G, R quantiles)")
    if not np.all(np.isfinite(a)) or a.min() < -1 or a.max() > 255:
        raise VisionError(f"{where} must hold finite numbers within 0..255 (-1: class not seen)")
    return a


def class_quantiles(pixels_bgr: np.ndarray, labels: np.ndarray, n_labels: int) -> np.ndarray:
    """Per label (0 = no class, k = k-th counted class) and channel, the quantiles at
    :data:`CLASS_LEVELS` of (N, 3) pixels; -1 for a label with under ``MIN_CLASS_SAMPLES``."""
    px = np.ascontiguousarray(pixels_bgr, np.uint8).reshape(-1, 3)
    out = np.empty((n_labels, 3, len(CLASS_LEVELS)))
    kernels()[0](px, np.ascontiguousarray(labels, np.int64), n_labels, CLASS_LEVELS, MIN_CLASS_SAMPLES, out)
    return out


def roi_sample_index(roi: DrumROI, shape_hw: tuple[int, int], n: int = SAMPLES) -> np.ndarray:
    """Flat pixel indices (into an H x W image) of about ``n`` ROI pixels on a regular grid."""
    box = roi_bbox(roi, shape_hw)
    x0, y0 = box[:2]
    inside = _mask_in_box(roi, box)
    step = max(1, int(math.sqrt(max(float(inside.sum()), 1.0) / n)))
    # the grid through the pixel nearest the drum centre: a camera turned by quarter turns or
    # mirrored samples the same pixels of the drum, so it estimates the same light
    ox, oy = (round(roi.cx_px) - x0) % step, (round(roi.cy_px) - y0) % step
    ys, xs = np.nonzero(inside[oy::step, ox::step])
    return ((ys * step + oy + y0) * shape_hw[1] + xs * step + ox + x0).astype(np.intp)


def light_quantiles(pixels_bgr: np.ndarray) -> np.ndarray:
    """Per-channel quantiles at :data:`LEVELS` of (N, 3) uint8 pixels, display values (3, L)."""
    px = np.ascontiguousarray(pixels_bgr, np.uint8).reshape(-1, 3)
    out = np.empty((1, 3, len(LEVELS)))
    kernels()[0](px, np.zeros(px.shape[0], np.int64), 1, LEVELS, 1, out)
    return out[0]


def _samples(frames: list[np.ndarray], rois: list[DrumROI]) -> np.ndarray:
    parts = []
    for img, roi in zip(frames, rois, strict=True):
        idx = roi_sample_index(roi, (img.shape[0], img.shape[1]))
        parts.append(np.ascontiguousarray(img).reshape(-1, 3)[idx])
    return np.concatenate(parts)


def reference_from_frames(frames: list[np.ndarray], rois: list[DrumROI]) -> np.ndarray:
    """The light reference (3, L) of set-up frames: the quantiles of their ROI pixels together."""
    return light_quantiles(_samples(frames, rois))


def class_reference_from_frames(frames: list[np.ndarray], rois: list[DrumROI], lut: np.ndarray,
                                n_labels: int) -> np.ndarray:
    """The per-class light reference (n_labels, 3, L) of set-up frames: ``lut`` (a
    ``vision.colours.class_lut``) labels their ROI pixels, :func:`class_quantiles` of each."""
    px = _samples(frames, rois)
    return class_quantiles(px, sample_labels(lut, px, n_labels), n_labels)


def sample_labels(lut: np.ndarray, pixels_bgr: np.ndarray, n_labels: int,
                  maps: np.ndarray | None = None) -> np.ndarray:
    """Labels of (N, 3) pixels through a class table, read through per-channel ``maps``
    (:func:`channel_maps`) when given; labels >= ``n_labels`` (glare) become 0."""
    px = np.asarray(pixels_bgr)
    b, g, r = (px[:, c] if maps is None else maps[c][px[:, c]] for c in range(3))
    lab = lut[(b.astype(np.int32) << 16) | (g.astype(np.int32) << 8) | r]
    return np.where(lab < n_labels, lab, 0)


def _fit_gains(ref3: np.ndarray, cur3: np.ndarray, start: tuple[float, float, float] | None,
               max_spread: float, weighted: bool = False) -> LightEstimate:
    """One linear gain per channel from matched values (3, M) of the reference and the frame
    (:func:`_fit_py`); a channel with too few usable entries follows the others from its
    ``start`` gain, or (no start) ends the estimate as saturated or too dark."""
    res = np.empty(6)
    st = np.ones(3) if start is None else np.asarray(start, np.float64)
    kernels()[1](np.ascontiguousarray(ref3, np.float64), np.ascontiguousarray(cur3, np.float64), st,
                  start is not None, weighted, res)
    return _verdict(res, max_spread)


_NO_CLASS_REF = np.zeros((1, 3, len(CLASS_LEVELS)))  # the kernel's placeholder without a per-class reference
_SET_UP_GAINS = np.ones(3)  # gain 1: the set-up light (read only)


def _verdict(res: np.ndarray, max_spread: float, n_ref: int = 0) -> LightEstimate:
    """A :class:`LightEstimate` from a fit's result row (gains, spread, status, fitted, classes in
    view, the classes' disagreement; the last three when the row has them); ``n_ref``: the
    counted classes the per-class reference saw -- one of them out of view after mapping back
    is a light the gains did not explain (a class's colour turned into another's, or none)."""
    status = int(res[4])
    if status:
        cause = "saturated" if status <= 3 else "too_dark"
        return LightEstimate((math.nan,) * 3, math.nan, f"{cause}:{_NAMES[(status - 1) % 3]}")
    g = (float(res[0]), float(res[1]), float(res[2]))
    spread = float(res[3])
    if not all(GAIN_RANGE[0] <= v <= GAIN_RANGE[1] for v in g):
        return LightEstimate(g, spread, "gain:" + "/".join(f"{v:.2f}" for v in g))
    apart = float(res[7]) if res.shape[0] > 7 else 0.0
    if n_ref and res[6] < n_ref:
        return LightEstimate(g, spread, f"unexplained_cast:class_lost_{n_ref - int(res[6])}", apart)
    if spread > max_spread:
        return LightEstimate(g, spread, f"unexplained_cast:{spread:.2f}", apart)
    if apart > MAX_DISAGREEMENT:
        return LightEstimate(g, spread, f"unexplained_cast:classes_apart_{apart:.2f}", apart)
    return LightEstimate(g, spread, None, apart)


def track_light(flat_bgr: np.ndarray, sample: np.ndarray, ref: np.ndarray, ref_cls: np.ndarray | None,
                lut: np.ndarray, prev: tuple[float, float, float] | None = None, *,
                n_ref: int | None = None, out: np.ndarray | None = None) -> LightEstimate:
    """The whole estimate of one frame in one compiled call (``vision.lightkernels``): the
    pixels ``sample`` (flat indices into ``flat_bgr``, (H*W, 3) uint8) classified through
    ``lut`` (the base class table) in the reference's terms, and the counted classes'
    quantiles fitted against ``ref_cls`` (the module's doc), from ``prev`` (the last accepted
    gains; the set-up light, gain 1, when None) and, when the light moved, from two more
    starts. Without a per-class reference, the drum-wide quantiles against ``ref``.
    ``n_ref`` (:func:`classes_in_reference` of ``ref_cls``) and ``out`` (float64 (8,), the
    kernel's result row) let a caller that estimates every frame compute them once."""
    res = np.zeros(8) if out is None else out
    n = 0 if ref_cls is None else ref_cls.shape[0]
    rc = _NO_CLASS_REF if ref_cls is None else ref_cls
    pv = _SET_UP_GAINS if prev is None else np.asarray(prev, np.float64)
    kernels()[2](flat_bgr, sample, ref, rc, n, lut, LEVELS, CLASS_LEVELS, MIN_CLASS_SAMPLES, pv, res)
    if n_ref is None:
        n_ref = classes_in_reference(ref_cls)
    return _verdict(res, MAX_CLASS_SPREAD if n else MAX_SPREAD, n_ref)


def classes_in_reference(ref_cls: np.ndarray | None) -> int:
    """The counted classes a per-class light reference saw (0 without one)."""
    return 0 if ref_cls is None else int((ref_cls[1:, 0, 0] >= 0).sum())


def sample_means(flat_bgr: np.ndarray, sample: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Mean B, G, R (display values) of the sampled pixels: the meter's per-frame check for a
    sudden light change (an auto-exposure jump) between two full estimates (~2 us). Every
    sampled pixel, not a subset: on the real PMMA frames (steady light, 27 frames x 3, the
    default ``track_every = 4``) every 8th pixel's mean moved past :data:`JUMP` on its own and
    started a full estimate on 56% of frames; all of them, on 28% (the 25% of the schedule
    and 3% jump checks)."""
    if out is None:
        out = np.empty(3)
    kernels()[4](flat_bgr, sample, out)
    return out


def estimate_light(ref: np.ndarray, cur: np.ndarray) -> LightEstimate:
    """Per-channel linear gains of quantiles ``cur`` against ``ref`` (both (3, L) display values)."""
    return _fit_gains(ref, cur, None, MAX_SPREAD)


def refine_light(ref_cls: np.ndarray, cur_cls: np.ndarray, first: LightEstimate) -> LightEstimate:
    """Gains from per-class quantiles (:func:`class_quantiles` of the frame's pixels, grouped by
    their class in the reference's terms) against the per-class reference: unlike the whole
    drum's quantiles, they do not move when the bed's mix of colours in view does. Pools every
    (class, level) both see unclipped per channel; keeps ``first``'s gain for a channel with
    fewer than ``MIN_LEVELS`` such entries."""
    return _fit_gains(ref_cls[1:].transpose(1, 0, 2).reshape(3, -1), cur_cls[1:].transpose(1, 0, 2).reshape(3, -1),
                      first.gains_bgr, MAX_CLASS_SPREAD, weighted=True)


def channel_maps(gains_bgr: tuple[float, float, float]) -> np.ndarray:
    """uint8 (3, 256): each frame value of a channel -> its value in the reference light
    (linear gain undone, rounded, clipped to 0..255; a clipped 255 under a gain > 1 -> the
    middle of the reference values that clip)."""
    out = np.empty((3, 256), np.uint8)
    maps_into(np.asarray(gains_bgr, np.float64), out)
    return out

"""Photometric tracking: each frame's exposure and white balance against the light at set-up.

What does not change while the drum turns is *what* is in it: the same particles, the same
drum, the same background, in nearly the same shares of the drum's area. The bed moves and
mixes, but the distribution of each colour channel over the drum ROI stays put; an exposure
or white-balance change moves every value of a channel the same (monotone) way, and a
monotone change keeps ranks: the q-quantile of a channel now is the image of the q-quantile
at set-up. So the reference is a set of per-channel quantiles of the ROI's pixels
(:data:`LEVELS`) from the frames ``classes suggest`` learned on, kept in the config
(``[meter] light_reference``), and each frame's quantiles, from a few thousand ROI pixels
on a fixed grid, give one gain per channel in linear light (sensor gamma :data:`GAMMA`):
the median ratio over the quantile levels both frames see unclipped and above the black
level. This uses the drum's empty region and rim, the achromatic particles and the bed's
own colours at once, needs no segmentation (which the light change would itself upset),
and costs a gather and three 256-bin histograms per tracked frame.

The classification is then done in the reference's terms: the class table is re-baked
through per-channel maps (frame value -> value at set-up, :func:`channel_maps`,
``vision.moments.remapped_tables``) when the gains move beyond a threshold -- a one-off
cost, the per-pixel pass stays one lookup. A clipped channel maps to the lowest value it
can have come from.

When the light cannot be mapped back -- too few unclipped levels in a channel (saturated or
black), a gain outside :data:`GAIN_RANGE`, or ratios that disagree along a channel (a colour
cast or tone curve that no gain explains) -- :func:`estimate_light` names the cause and the
meter gives no MI for the frame and a ``lighting_changed:<cause>`` flag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vision.errors import VisionError
from vision.roi import DrumROI, _mask_in_box, roi_bbox

__all__ = [
    "CLASS_LEVELS",
    "GAIN_RANGE",
    "GAMMA",
    "LEVELS",
    "LightEstimate",
    "channel_maps",
    "check_class_reference",
    "check_reference",
    "class_quantiles",
    "class_reference_from_frames",
    "estimate_light",
    "light_quantiles",
    "reference_from_frames",
    "refine_light",
    "roi_sample_index",
    "sample_labels",
]

GAMMA = 2.2
"""Sensor gamma: display value v (0..255) is linear light (v / 255) ** GAMMA."""
LEVELS = np.linspace(0.30, 0.98, 35)
"""Quantile levels of the ROI's pixels (per channel) in the light reference."""
FLOOR = 20.0
"""Display values at or below this carry no gain information (black level, noise)."""
CEIL = 247.0
"""Display values at or above this may be clipped."""
GAIN_RANGE = (0.4, 2.5)
"""Linear-light gains outside this range are too far to map back."""
MIN_LEVELS = 5
"""A channel needs at least this many usable quantile levels."""
MAX_SPREAD = 0.2
"""Largest median |log ratio - log gain| over a channel's levels that one gain explains (the
real PMMA frames, unperturbed, reach 0.11 against a reference from another frame: the bed's
share of the drum moves the levels near the bed/background step)."""
MAX_CLASS_SPREAD = 0.16
"""The same for the per-class quantiles (:func:`refine_light`), which one gain explains closely."""
SAMPLES = 4000
"""About this many ROI pixels per frame for the estimate."""
CLASS_LEVELS = np.array([0.1, 0.25, 0.5, 0.75, 0.9])
"""Quantile levels of each class's pixels (per channel) in the per-class light reference."""
MIN_CLASS_SAMPLES = 40
"""A class with fewer sampled pixels has no quantiles (written as -1)."""
_NAMES = ("blue", "green", "red")


@dataclass(frozen=True, slots=True)
class LightEstimate:
    """Gains (linear light, B, G, R) of a frame against the reference, the largest disagreement
    along a channel (median |log ratio - log gain|), and the cause when it cannot be mapped back
    (``None`` when it can)."""

    gains_bgr: tuple[float, float, float]
    spread: float
    cause: str | None = None


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
    out = np.full((n_labels, 3, len(CLASS_LEVELS)), -1.0)
    px = np.asarray(pixels_bgr)
    lab = np.asarray(labels)
    for k in range(n_labels):
        sel = px[lab == k]
        if sel.shape[0] >= MIN_CLASS_SAMPLES:
            out[k] = np.quantile(sel, CLASS_LEVELS, axis=0).T
    return out


def roi_sample_index(roi: DrumROI, shape_hw: tuple[int, int], n: int = SAMPLES) -> np.ndarray:
    """Flat pixel indices (into an H x W image) of about ``n`` ROI pixels on a regular grid."""
    box = roi_bbox(roi, shape_hw)
    x0, y0 = box[:2]
    inside = _mask_in_box(roi, box)
    step = max(1, int(math.sqrt(max(float(inside.sum()), 1.0) / n)))
    ys, xs = np.nonzero(inside[::step, ::step])
    return ((ys * step + y0) * shape_hw[1] + xs * step + x0).astype(np.intp)


def light_quantiles(pixels_bgr: np.ndarray) -> np.ndarray:
    """Per-channel quantiles at :data:`LEVELS` of (N, 3) uint8 pixels, display values (3, L)."""
    px = np.asarray(pixels_bgr)
    out = np.empty((3, len(LEVELS)))
    n = max(px.shape[0], 1)
    centres = np.arange(256, dtype=np.float64)
    for c in range(3):
        cdf = np.cumsum(np.bincount(px[:, c], minlength=256)) / n
        # the value at which the cumulative share crosses each level, linear within a bin
        lo = np.concatenate(([0.0], cdf[:-1]))
        i = np.minimum(np.searchsorted(cdf, LEVELS, side="left"), 255)
        width = np.maximum(cdf[i] - lo[i], 1e-12)
        out[c] = centres[i] - 0.5 + np.clip((LEVELS - lo[i]) / width, 0.0, 1.0)
    return np.clip(out, 0.0, 255.0)


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
               max_spread: float) -> LightEstimate:
    """One linear gain per channel from matched values (3, M) of the reference and the frame:
    the median log ratio over the entries both see unclipped and above the black level. A
    channel with fewer than ``MIN_LEVELS`` such entries keeps its ``start`` gain, or (no
    start) ends the estimate as saturated or too dark."""
    gains = list(start) if start is not None else [math.nan] * 3
    spread = 0.0
    for c in range(3):
        r, q = ref3[c], cur3[c]
        ok = (r > FLOOR) & (r < CEIL) & (q > FLOOR) & (q < CEIL)
        if ok.sum() < MIN_LEVELS:
            if start is not None:
                continue
            hi = (q >= CEIL).sum() > (r >= CEIL).sum()
            return LightEstimate((math.nan,) * 3, math.nan, f"{'saturated' if hi else 'too_dark'}:{_NAMES[c]}")
        lr = GAMMA * (np.log(q[ok]) - np.log(r[ok]))
        lg = float(np.median(lr))
        spread = max(spread, float(np.median(np.abs(lr - lg))))
        gains[c] = math.exp(lg)
    g = (gains[0], gains[1], gains[2])
    if not all(GAIN_RANGE[0] <= v <= GAIN_RANGE[1] for v in g):
        return LightEstimate(g, spread, "gain:" + "/".join(f"{v:.2f}" for v in g))
    if spread > max_spread:
        return LightEstimate(g, spread, f"unexplained_cast:{spread:.2f}")
    return LightEstimate(g, spread, None)


def estimate_light(ref: np.ndarray, cur: np.ndarray) -> LightEstimate:
    """Per-channel linear gains of quantiles ``cur`` against ``ref`` (both (3, L) display values)."""
    return _fit_gains(ref, cur, None, MAX_SPREAD)


def refine_light(ref_cls: np.ndarray, cur_cls: np.ndarray, first: LightEstimate) -> LightEstimate:
    """Gains from per-class quantiles (:func:`class_quantiles` of the frame's pixels, grouped by
    their class in the reference's terms) against the per-class reference: unlike the whole
    drum's quantiles, they do not move when the bed's mix of colours in view does. Pools every
    (class, level) both see unclipped per channel; keeps ``first``'s gain for a channel with
    fewer than ``MIN_LEVELS`` such entries."""
    return _fit_gains(ref_cls.transpose(1, 0, 2).reshape(3, -1), cur_cls.transpose(1, 0, 2).reshape(3, -1),
                      first.gains_bgr, MAX_CLASS_SPREAD)


def channel_maps(gains_bgr: tuple[float, float, float]) -> np.ndarray:
    """uint8 (3, 256): each frame value of a channel -> its value in the reference light
    (linear gain undone, rounded, clipped to 0..255)."""
    v = np.arange(256, dtype=np.float64) / 255.0
    out = np.empty((3, 256), np.uint8)
    for c, g in enumerate(gains_bgr):
        out[c] = np.clip(np.round(255.0 * (v**GAMMA / g) ** (1.0 / GAMMA)), 0, 255).astype(np.uint8)
    return out

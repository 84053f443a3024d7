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

The drum-wide quantiles have one weakness: they follow the bed's colour *shares*, and a bed
that shows more of one class than at set-up (the fully mixed bed of a set-up on a segregated
one) moves the levels near a class step. So, with a per-class reference (``[meter]
light_reference_classes``), each estimate is refined on per-class quantiles, the pixels
classified in the reference's terms -- which do not move with the mix -- and the refinement
is started twice when the two guesses disagree: from the drum-wide gains and from the last
accepted estimate (:func:`track_light`); the fit that explains more channels, then with the
lower spread, wins. Measured on the robustness suite's blue/white pair, mix 1.0 at x1.3:
the drum-wide start alone settled on red x1.60 (white clipped, blue's labels off), the second
start on 1.29-1.31 in every channel.

The classification is then done in the reference's terms: the class table is re-baked
through per-channel maps (frame value -> value at set-up, :func:`channel_maps`,
``vision.moments.remapped_tables``) when the gains move beyond a threshold -- a one-off
cost, the per-pixel pass stays one lookup. A clipped channel (255 under a gain > 1) maps to
the middle of the reference values that clip: a pale class whose brightest channels clip
keeps those channels near its own values instead of dropping to the darkest guess, which
would turn it into a grey.

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
    "REBAKE_AT_ONCE",
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
    "sample_means",
    "track_light",
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
PREV_START = 0.02
"""The per-class refinement also starts from the last accepted gains when its result from the
drum-wide ones differs from them by more than this (|log ratio| in a channel; :func:`track_light`)."""
SETTLED = 0.003
"""A per-class refinement pass that moves no gain by more than this (|log ratio|) ends it."""
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
    px = np.ascontiguousarray(pixels_bgr, np.uint8).reshape(-1, 3)
    out = np.empty((n_labels, 3, len(CLASS_LEVELS)))
    _kernels()[0](px, np.ascontiguousarray(labels, np.int64), n_labels, CLASS_LEVELS, MIN_CLASS_SAMPLES, out)
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
    _kernels()[0](px, np.zeros(px.shape[0], np.int64), 1, LEVELS, 1, out)
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
               max_spread: float) -> LightEstimate:
    """One linear gain per channel from matched values (3, M) of the reference and the frame
    (:func:`_fit_py`); a channel with too few usable entries keeps its ``start`` gain, or (no
    start) ends the estimate as saturated or too dark."""
    res = np.empty(6)
    st = np.ones(3) if start is None else np.asarray(start, np.float64)
    _kernels()[1](np.ascontiguousarray(ref3, np.float64), np.ascontiguousarray(cur3, np.float64), st,
                  start is not None, res)
    return _verdict(res, max_spread)


def _verdict(res: np.ndarray, max_spread: float) -> LightEstimate:
    """A :class:`LightEstimate` from a fit's result row (gains, spread, status)."""
    status = int(res[4])
    if status:
        cause = "saturated" if status <= 3 else "too_dark"
        return LightEstimate((math.nan,) * 3, math.nan, f"{cause}:{_NAMES[(status - 1) % 3]}")
    g = (float(res[0]), float(res[1]), float(res[2]))
    spread = float(res[3])
    if not all(GAIN_RANGE[0] <= v <= GAIN_RANGE[1] for v in g):
        return LightEstimate(g, spread, "gain:" + "/".join(f"{v:.2f}" for v in g))
    if spread > max_spread:
        return LightEstimate(g, spread, f"unexplained_cast:{spread:.2f}")
    return LightEstimate(g, spread, None)


def track_light(flat_bgr: np.ndarray, sample: np.ndarray, ref: np.ndarray, ref_cls: np.ndarray | None,
                lut: np.ndarray, prev: tuple[float, float, float] | None = None) -> LightEstimate:
    """The whole estimate of one frame in one compiled call: the drum's quantiles of the pixels
    ``sample`` (flat indices into ``flat_bgr``, (H*W, 3) uint8) against ``ref`` (:func:`estimate_light`),
    then, with a per-class reference, twice the per-class refinement (:func:`refine_light`) with
    the pixels classified through ``lut`` (the base class table) in the reference's terms.

    The refinement starts from the drum-wide gains and, when it lands more than
    :data:`PREV_START` away from ``prev`` (the last accepted estimate; the set-up light, gain 1,
    when None), once more from ``prev`` (a light that moved, or a misled start). The
    drum-wide quantiles follow the bed's colour shares (a bed that shows more of one class
    than at set-up moves the levels near a class step), and a refinement started from their
    gains can settle on the labels those gains give; the light of the last estimate, or of
    set-up, is the other honest guess, and the per-class fit says which labels one gain explains:
    the one that fits more channels from the frame (not kept at their start), then the lower spread."""
    res = np.empty(6)
    n = 0 if ref_cls is None else ref_cls.shape[0]
    rc = np.zeros((1, 3, len(CLASS_LEVELS))) if ref_cls is None else ref_cls
    pv = np.ones(3) if prev is None else np.asarray(prev, np.float64)
    _kernels()[2](flat_bgr, sample, ref, rc, n, lut, LEVELS, CLASS_LEVELS, MIN_CLASS_SAMPLES, MAX_SPREAD, pv, res)
    return _verdict(res, MAX_CLASS_SPREAD if n else MAX_SPREAD)


def _quantiles_py(px, labels, n_labels, levels, min_count, out):  # pragma: no cover - compiled
    """out[k, c, :] = quantiles at ``levels`` of channel c of the pixels labelled k (-1 when
    fewer than ``min_count``): 256-bin histograms, linear within a bin."""
    hist = np.zeros((n_labels, 3, 256), np.int64)
    cnt = np.zeros(n_labels, np.int64)
    for i in range(px.shape[0]):
        k = labels[i]
        if k < 0 or k >= n_labels:
            continue
        cnt[k] += 1
        for c in range(3):
            hist[k, c, px[i, c]] += 1
    for k in range(n_labels):
        for c in range(3):
            if cnt[k] < min_count or cnt[k] == 0:
                for j in range(levels.shape[0]):
                    out[k, c, j] = -1.0
                continue
            acc = 0.0
            v = 0
            for j in range(levels.shape[0]):
                target = levels[j] * cnt[k]
                while v < 255 and acc + hist[k, c, v] < target:
                    acc += hist[k, c, v]
                    v += 1
                h = hist[k, c, v]
                frac = (target - acc) / h if h > 0 else 0.0
                q = v - 0.5 + min(max(frac, 0.0), 1.0)
                out[k, c, j] = min(max(q, 0.0), 255.0)


def _fit_py(ref3, cur3, start, has_start, res):  # pragma: no cover - compiled
    """res = (gain b, g, r, spread, status, fitted): per channel the median over usable entries
    of GAMMA x log(cur / ref); spread = the largest median |deviation|; status 0, or 1 + c
    (saturated channel c) / 4 + c (too dark) when a channel has too few entries and no start;
    fitted = the number of channels fitted (not kept at ``start``)."""
    spread = 0.0
    res[4] = 0.0
    res[5] = 0.0
    m = ref3.shape[1]
    lr = np.empty(m)
    for c in range(3):
        n = 0
        n_hi = 0
        for j in range(m):
            r = ref3[c, j]
            q = cur3[c, j]
            if q >= CEIL and r < CEIL:
                n_hi += 1
            if r > FLOOR and r < CEIL and q > FLOOR and q < CEIL:
                lr[n] = GAMMA * (math.log(q) - math.log(r))
                n += 1
        if n < MIN_LEVELS:
            if has_start:
                res[c] = start[c]
                continue
            res[4] = (1 + c) if n_hi > 0 else (4 + c)
            return
        res[5] += 1.0
        lg = np.median(lr[:n])
        dev = np.abs(lr[:n] - lg)
        spread = max(spread, np.median(dev))
        res[c] = math.exp(lg)
    res[3] = spread


def _refine_py(px, ref3, n_cls, lut, cls_levels, min_cls, start, res):  # pragma: no cover - compiled
    """Up to two per-class refinements (:func:`refine_light`) from the gains ``start`` (one when
    it moves no gain by :data:`SETTLED`): the pixels ``px``
    classified through ``lut`` in the reference's terms at the current gains, their per-class
    quantiles fitted against ``ref3`` (the per-class reference, (3, n_cls x L)); ``res`` as
    :func:`_fit_py`'s."""
    ns = px.shape[0]
    maps = np.empty((3, 256), np.uint8)
    lab = np.empty(ns, np.int64)
    ccur = np.empty((n_cls, 3, cls_levels.shape[0]))
    st = np.empty(3)
    q3 = np.empty((3, n_cls * cls_levels.shape[0]))
    for c in range(3):
        res[c] = start[c]
    for _ in range(2):
        for c in range(3):
            st[c] = res[c]
        _maps(st, _LIN, _BOUNDS, maps)
        for i in range(ns):
            k = lut[(np.int64(maps[0, px[i, 0]]) << 16) | (np.int64(maps[1, px[i, 1]]) << 8) | maps[2, px[i, 2]]]
            lab[i] = k if k < n_cls else 0
        _quantiles(px, lab, n_cls, cls_levels, min_cls, ccur)
        for c in range(3):
            for k in range(n_cls):
                for j in range(cls_levels.shape[0]):
                    q3[c, k * cls_levels.shape[0] + j] = ccur[k, c, j]
        _fit(ref3, q3, st, True, res)
        moved = 0.0
        for c in range(3):
            moved = max(moved, abs(math.log(res[c] / st[c])))
        if moved < SETTLED:
            return  # the labels these gains give would be the same: a second pass changes nothing


def _track_py(flat, sample, ref, ref_cls, n_cls, lut, levels, cls_levels, min_cls, max_spread, prev,
              res):  # pragma: no cover - compiled
    """:func:`track_light` in one pass: gather, quantiles, fit, then (n_cls > 0) the per-class
    refinement from the drum-wide gains and, when it lands away from ``prev``, from ``prev``: the one that fits more
    channels (a channel without enough unclipped entries keeps its start), then the lower spread, wins."""
    ns = sample.shape[0]
    px = np.empty((ns, 3), np.uint8)
    for i in range(ns):
        for c in range(3):
            px[i, c] = flat[sample[i], c]
    zeros = np.zeros(ns, np.int64)
    cur = np.empty((1, 3, levels.shape[0]))
    _quantiles(px, zeros, 1, levels, 1, cur)
    _fit(ref, cur[0], np.ones(3), False, res)
    if res[4] != 0 or n_cls == 0:
        return
    if not (GAIN_RANGE[0] <= min(res[0], res[1], res[2]) and max(res[0], res[1], res[2]) <= GAIN_RANGE[1]):
        return  # out of range on the whole drum's quantiles: too far to map back
    m = n_cls * cls_levels.shape[0]
    r3 = np.empty((3, m))
    for c in range(3):
        for k in range(n_cls):
            for j in range(cls_levels.shape[0]):
                r3[c, k * cls_levels.shape[0] + j] = ref_cls[k, c, j]
    first = res[:3].copy()
    _refine(px, r3, n_cls, lut, cls_levels, min_cls, first, res)
    far = 0.0
    for c in range(3):
        far = max(far, abs(math.log(prev[c] / res[c])))
    if far < PREV_START:
        return  # the refinement landed on the last light (a steady video): the only candidate
    alt = np.empty(6)
    _refine(px, r3, n_cls, lut, cls_levels, min_cls, prev, alt)
    if alt[5] > res[5] or (alt[5] == res[5] and alt[3] < res[3]):  # more channels fitted, or closer
        for c in range(4):
            res[c] = alt[c]


def _maps_py(gains, lin, bounds, out):  # pragma: no cover - compiled
    """out[c, v] = round(255 (lin[v] / gains[c]) ** (1 / GAMMA)), clipped: the number of
    rounding bounds ((k + 0.5) / 255) ** GAMMA at or below lin[v] / gain (one merge walk, no powers);
    under a gain > 1 the clipped value 255 maps to the middle of the values it can have come from."""
    for c in range(3):
        p = 0
        for v in range(256):
            t = lin[v] / gains[c]
            while p < 255 and bounds[p] <= t:
                p += 1
            out[c, v] = p
        if gains[c] > 1.0:  # a clipped value came from anywhere between its map and 255: the middle
            out[c, 255] = (out[c, 255] + 256) // 2


def _means_py(flat, sample, out):  # pragma: no cover - compiled
    """out = mean B, G, R of the sampled pixels."""
    s0 = 0
    s1 = 0
    s2 = 0
    for i in range(sample.shape[0]):
        k = sample[i]
        s0 += flat[k, 0]
        s1 += flat[k, 1]
        s2 += flat[k, 2]
    n = max(sample.shape[0], 1)
    out[0] = s0 / n
    out[1] = s1 / n
    out[2] = s2 / n


def sample_means(flat_bgr: np.ndarray, sample: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Mean B, G, R (display values) of the sampled pixels: the meter's per-frame check for a
    sudden light change (an auto-exposure jump) between two full estimates (~2 us). Every
    sampled pixel, not a subset: on the real PMMA frames (steady light, 27 frames x 3, the
    default ``track_every = 4``) every 8th pixel's mean moved past :data:`JUMP` on its own and
    started a full estimate on 56% of frames; all of them, on 28% (the 25% of the schedule
    and 3% jump checks)."""
    if out is None:
        out = np.empty(3)
    _kernels()[4](flat_bgr, sample, out)
    return out


_LIN = (np.arange(256) / 255.0) ** GAMMA
_BOUNDS = ((np.arange(255) + 0.5) / 255.0) ** GAMMA
_compiled: tuple | None = None
_quantiles = _quantiles_py  # replaced by their compiled forms before _track_py is compiled
_fit = _fit_py
_maps = _maps_py
_refine = _refine_py


def _kernels() -> tuple:
    global _compiled, _quantiles, _fit, _maps, _refine
    if _compiled is None:
        import numba  # imported here: the CLI starts fast when no frame is measured

        _quantiles = numba.njit(nogil=True, cache=True)(_quantiles_py)
        _fit = numba.njit(nogil=True, cache=True)(_fit_py)
        _maps = numba.njit(nogil=True, cache=True)(_maps_py)
        _refine = numba.njit(nogil=True, cache=True)(_refine_py)
        _compiled = (_quantiles, _fit, numba.njit(nogil=True, cache=True)(_track_py), _maps,
                     numba.njit(nogil=True, cache=True)(_means_py))
    return _compiled


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
    (linear gain undone, rounded, clipped to 0..255; a clipped 255 under a gain > 1 -> the
    middle of the reference values that clip)."""
    out = np.empty((3, 256), np.uint8)
    _kernels()[3](np.asarray(gains_bgr, np.float64), _LIN, _BOUNDS, out)
    return out

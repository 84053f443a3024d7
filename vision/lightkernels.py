"""The light tracker's compiled kernels (``vision.photometric``; pure, numba).

Per-class quantiles (256-bin histograms), the gain fit (weighted medians of log ratios, the
clipped entries' check), the per-class refinement from a start, the tracker's starts and the
choice among them, the channel maps that undo a gain, and the sampled means of the jump check.
Their constants are read when they are compiled.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CEIL", "FLOOR", "GAIN_RANGE", "GAMMA", "MIN_LEVELS", "PASSES", "PREV_START", "SETTLED", "kernels",
           "maps_into"]

GAMMA = 2.2
"""Sensor gamma: display value v (0..255) is linear light (v / 255) ** GAMMA."""
FLOOR = 20.0
"""Display values at or below this carry no gain information (black level, noise)."""
CEIL = 247.0
"""Display values at or above this may be clipped."""
GAIN_RANGE = (0.4, 2.0)
"""Linear-light gains outside this range are too far to map back. The aims hold x0.6-x1.5 (read at
0.94-1.74 on the cross-rig bench's rigs, docs/validation.md section 15); past about x2 the clipped
channels carry no gain and read it low (x3 as 2.26-2.50 on the teal/white rigs, whose frames were
then measured wrong without a flag): the top is 2.0."""
MIN_LEVELS = 5
"""A channel needs at least this many usable quantile levels."""
PREV_START = 0.02
"""The per-class refinement from the last accepted gains is the only one when it lands within
this of them (|log ratio| in every channel); beyond, the light moved and two more starts are tried."""
SETTLED = 0.003
"""A per-class refinement pass that moves no gain by more than this (|log ratio|) ends it."""
PASSES = 3
"""At most this many per-class refinement passes from one start."""

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


def _wmedian_py(v, w, n):  # pragma: no cover - compiled
    """The weighted median of ``v[:n]`` (weights ``w[:n]``)."""
    order = np.argsort(v[:n])
    half = 0.5 * w[:n].sum()
    acc = 0.0
    for i in order:
        acc += w[i]
        if acc >= half:
            return v[i]
    return v[order[n - 1]]


def _fit_py(ref3, cur3, start, has_start, weighted, res):  # pragma: no cover - compiled
    """res = (gain b, g, r, spread, status, fitted): per channel the median over usable entries
    (both unclipped and above the black level) of GAMMA x log(cur / ref); fitted = the number
    of channels fitted; spread = how far one gain per channel leaves the entries: the largest
    median |deviation| of a channel (unweighted), or the median |deviation| of every fitted
    entry pooled (weighted).

    ``weighted``: each entry weighs (its smaller display value)^2 -- a log ratio's error goes
    as 1 / value, so a dark class (or a class's dark edge levels, which move with the bed's
    mix and with where in an unevenly lit drum a class lies) counts little against a bright
    one, in the gains and in the spread. And the clipped entries must agree: one that clipped
    (its reference did not) says the gain is at least (CEIL / ref)^GAMMA; when most of the
    clipped weight (and it more than a quarter of the usable weight) says so beyond the fit, the
    fit rests on the few levels left below the clip (shaded edges) and is not the light:
    status saturated. A channel with fewer than :data:`MIN_LEVELS` entries is not fitted: with
    ``has_start`` it keeps its start gain moved by the exposure change the fitted channels saw
    (their mean log gain against their start); with no channel fitted, or without a start,
    status = 1 + c (saturated channel c) / 4 + c (too dark)."""
    spread = 0.0
    res[4] = 0.0
    res[5] = 0.0
    m = ref3.shape[1]
    lr = np.empty(m)
    wt = np.empty(m)
    hb = np.empty(m)
    hw = np.empty(m)
    dev = np.empty(3 * m)
    dwt = np.empty(3 * m)
    nd = 0
    moved = 0.0
    weak = np.zeros(3, np.bool_)
    worst = -1
    worst_hi = 0
    for c in range(3):
        n = 0
        n_hi = 0
        for j in range(m):
            r = ref3[c, j]
            q = cur3[c, j]
            if q >= CEIL and r < CEIL:
                if r > FLOOR:  # the gain that clips it, less 3 display levels of quantile interpolation
                    hb[n_hi] = GAMMA * (math.log(CEIL) - math.log(r)) - GAMMA * 3.0 / r
                    hw[n_hi] = r * r
                n_hi += 1
            if r > FLOOR and r < CEIL and q > FLOOR and q < CEIL:
                lr[n] = GAMMA * (math.log(q) - math.log(r))
                wt[n] = min(q, r) ** 2 if weighted else 1.0
                n += 1
        if n < MIN_LEVELS:
            if not has_start:
                res[4] = (1 + c) if n_hi > 0 else (4 + c)
                return
            weak[c] = True
            if worst < 0 or n_hi > worst_hi:
                worst, worst_hi = c, n_hi
            continue
        lg = _wmedian(lr, wt, n)
        if weighted and _clipping_disagrees(hb, hw, min(n_hi, m), lg, wt[:n].sum()):
            res[4] = 1 + c
            return
        res[5] += 1.0
        for i in range(n):
            dev[nd] = abs(lr[i] - lg)
            dwt[nd] = wt[i]
            nd += 1
        if not weighted:
            spread = max(spread, _wmedian(dev[nd - n:nd], dwt[nd - n:nd], n))
        res[c] = math.exp(lg)
        moved += lg - math.log(start[c]) if has_start else 0.0
    if res[5] == 0.0:
        res[4] = (1 + worst) if worst_hi > 0 else (4 + worst)
        return
    for c in range(3):
        if weak[c]:
            res[c] = start[c] * math.exp(moved / res[5])
    res[3] = _wmedian(dev, dwt, nd) if weighted else spread


def _clipping_disagrees_py(hb, hw, n_hi, lg, usable):  # pragma: no cover - compiled
    """Whether most of the clipped entries' weight (``hw[:n_hi]``, more than a quarter of the
    ``usable`` weight) needs a log gain above ``lg`` (their bounds ``hb``) to clip."""
    total = 0.0
    above = 0.0
    for i in range(n_hi):
        total += hw[i]
        if hb[i] > lg:
            above += hw[i]
    return total > 0.25 * usable and above > 0.5 * total


def _refine_py(px, ref3, n_cls, lut, cls_levels, min_cls, start, res):  # pragma: no cover - compiled
    """Per-class refinements (:func:`refine_light`) from the gains ``start``, up to
    :data:`PASSES` (until one moves no gain by :data:`SETTLED`): the pixels ``px`` classified
    through ``lut`` in the reference's terms at the current gains, the counted classes'
    quantiles (``n_cls`` labels, 0 = no class: not fitted, its pixels are whatever the bed's
    mix leaves between the particles) fitted against ``ref3`` (the counted classes' reference,
    (3, (n_cls - 1) x L)), weighted; ``res`` as :func:`_fit_py`'s."""
    ns = px.shape[0]
    nl = cls_levels.shape[0]
    maps = np.empty((3, 256), np.uint8)
    lab = np.empty(ns, np.int64)
    ccur = np.empty((n_cls, 3, nl))
    st = np.empty(3)
    q3 = np.empty((3, (n_cls - 1) * nl))
    for c in range(3):
        res[c] = start[c]
    for _ in range(PASSES):
        for c in range(3):
            st[c] = res[c]
        _maps(st, _LIN, _BOUNDS, maps)
        for i in range(ns):
            k = lut[(np.int64(maps[0, px[i, 0]]) << 16) | (np.int64(maps[1, px[i, 1]]) << 8) | maps[2, px[i, 2]]]
            lab[i] = k if k < n_cls else 0
        _quantiles(px, lab, n_cls, cls_levels, min_cls, ccur)
        for c in range(3):
            for k in range(1, n_cls):
                for j in range(nl):
                    q3[c, (k - 1) * nl + j] = ccur[k, c, j]
        _fit(ref3, q3, st, True, True, res)
        res[6] = 0.0
        for k in range(1, n_cls):
            res[6] += 1.0 if ccur[k, 0, 0] >= 0.0 else 0.0  # (a class with too few pixels: -1)
        res[7] = _disagreement(ref3, q3, n_cls - 1, nl)
        if res[4] != 0:
            return
        moved = 0.0
        for c in range(3):
            moved = max(moved, abs(math.log(res[c] / st[c])))
        if moved < SETTLED:
            return  # the labels these gains give would be the same: another pass changes nothing


def _disagreement_py(ref3, q3, n_cls, nl):  # pragma: no cover - compiled
    """How far apart the classes' own gains are: per channel, the range over the classes of
    GAMMA x log(now / then) at their median level (classes bright enough there: both at least
    3 x :data:`FLOOR`, unclipped), the largest over the channels (0 with fewer than two such
    classes). One light gives every class the same gain; a tone curve or a cast does not -- and
    a class's median, unlike its dark edge levels, does not move with the mix."""
    worst = 0.0
    mid = nl // 2
    for c in range(3):
        lo = 1e30
        hi = -1e30
        for k in range(n_cls):
            r = ref3[c, k * nl + mid]
            q = q3[c, k * nl + mid]
            if r >= 3.0 * FLOOR and q >= 3.0 * FLOOR and r < CEIL and q < CEIL:
                g = GAMMA * (math.log(q) - math.log(r))
                lo = min(lo, g)
                hi = max(hi, g)
        if hi > lo:
            worst = max(worst, hi - lo)
    return worst


def _track_py(flat, sample, ref, ref_cls, n_cls, lut, levels, cls_levels, min_cls, prev,
              res):  # pragma: no cover - compiled
    """:func:`track_light` in one pass: gather the samples; without a per-class reference
    (``n_cls`` = 0) the drum-wide quantiles fitted against ``ref``; with one, the per-class
    refinement from ``prev`` (the last light) and, when it fails, loses a class from view or
    lands away from it (the light moved), from two more starts: the drum-wide quantiles' gains (a guess only: they
    follow the bed's colour shares) and the best result's gains made grey (their mean in every
    channel: an exposure change, which a white balance misled by the first labels cannot pull
    aside). Of the results that map back, the one that fits more channels, then the lower
    spread, wins."""
    ns = sample.shape[0]
    px = np.empty((ns, 3), np.uint8)
    for i in range(ns):
        for c in range(3):
            px[i, c] = flat[sample[i], c]
    cur = np.empty((1, 3, levels.shape[0]))
    if n_cls == 0:
        _quantiles(px, np.zeros(ns, np.int64), 1, levels, 1, cur)
        _fit(ref, cur[0], np.ones(3), False, False, res)
        return
    nl = cls_levels.shape[0]
    r3 = np.empty((3, (n_cls - 1) * nl))
    for c in range(3):
        for k in range(1, n_cls):
            for j in range(nl):
                r3[c, (k - 1) * nl + j] = ref_cls[k, c, j]
    seen = 0
    for k in range(1, n_cls):
        seen += 1 if ref_cls[k, 0, 0] >= 0.0 else 0
    _refine(px, r3, n_cls, lut, cls_levels, min_cls, prev, res)
    if res[4] == 0 and res[6] >= seen:
        far = 0.0
        for c in range(3):
            far = max(far, abs(math.log(prev[c] / res[c])))
        if far < PREV_START:
            return  # the refinement landed on the last light, every class in view (a steady video)
    alt = np.zeros(8)
    _quantiles(px, np.zeros(ns, np.int64), 1, levels, 1, cur)
    _fit(ref, cur[0], np.ones(3), False, False, alt)
    if alt[4] == 0 and GAIN_RANGE[0] <= min(alt[0], alt[1], alt[2]) and max(alt[0], alt[1], alt[2]) <= GAIN_RANGE[1]:
        _refine(px, r3, n_cls, lut, cls_levels, min_cls, alt[:3].copy(), alt)
        _better(alt, res)
    if res[4] != 0:
        return
    grey = math.exp((math.log(res[0]) + math.log(res[1]) + math.log(res[2])) / 3.0)
    _refine(px, r3, n_cls, lut, cls_levels, min_cls, np.full(3, grey), alt)
    _better(alt, res)


def _better_py(alt, res):  # pragma: no cover - compiled
    """res = alt when alt maps back and res does not, or alt keeps more classes in view (gains
    that turn every particle into one class fit that class closely: a false light), or as
    many and fits more channels, or as many with a lower spread."""
    if alt[4] != 0:
        return
    key_a = (alt[6], alt[5], -alt[3])
    key_r = (res[6], res[5], -res[3])
    if res[4] != 0 or key_a > key_r:
        for c in range(8):
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


_LIN = (np.arange(256) / 255.0) ** GAMMA
_BOUNDS = ((np.arange(255) + 0.5) / 255.0) ** GAMMA
_compiled: tuple | None = None
_quantiles = _quantiles_py  # replaced by their compiled forms before _track_py is compiled
_wmedian = _wmedian_py
_better = _better_py
_clipping_disagrees = _clipping_disagrees_py
_disagreement = _disagreement_py
_fit = _fit_py
_maps = _maps_py
_refine = _refine_py


def kernels() -> tuple:
    """The compiled kernels: (quantiles, fit, track, maps, means), compiled on first use."""
    global _compiled, _quantiles, _wmedian, _better, _clipping_disagrees, _disagreement, _fit, _maps, _refine
    if _compiled is None:
        import numba  # imported here: the CLI starts fast when no frame is measured

        _quantiles = numba.njit(nogil=True, cache=True)(_quantiles_py)
        _wmedian = numba.njit(nogil=True, cache=True)(_wmedian_py)
        _better = numba.njit(nogil=True, cache=True)(_better_py)
        _clipping_disagrees = numba.njit(nogil=True, cache=True)(_clipping_disagrees_py)
        _disagreement = numba.njit(nogil=True, cache=True)(_disagreement_py)
        _fit = numba.njit(nogil=True, cache=True)(_fit_py)
        _maps = numba.njit(nogil=True, cache=True)(_maps_py)
        _refine = numba.njit(nogil=True, cache=True)(_refine_py)
        _compiled = (_quantiles, _fit, numba.njit(nogil=True, cache=True)(_track_py), _maps,
                     numba.njit(nogil=True, cache=True)(_means_py))
    return _compiled


def maps_into(gains_bgr: np.ndarray, out: np.ndarray) -> None:
    """``out`` (uint8 (3, 256)) = the compiled channel maps of ``gains_bgr`` (:func:`_maps_py`)."""
    kernels()[3](gains_bgr, _LIN, _BOUNDS, out)

"""The island filter: small components of one class enclosed by another class take its class.

A glossy particle shows a specular highlight: a small bright spot inside it. On a same-hue
pair (dark green and light green) the highlight of a dark particle has the colour of the
light class, so the light class gains a scatter of small islands wherever the dark
particles are and its centroid is pulled towards them (8-9% of R on the robustness suite's
glossy dark/light green pair with the opening off). A highlight is small (a fraction of the
particle) and surrounded by the particle's own colour; a real particle of the light class
is at least a particle's area and borders the background or particles of either class.

So a 4-connected component of class c with at most ``max_area`` grid pixels whose outer
ring (its 4-neighbours outside it) is, apart from unclassified pixels, one other counted
class d -- and at least ``min_share`` of the ring is d -- is relabelled d, when c is the
lighter of the two (a highlight is brighter than its particle; given ``lightness``).
Unclassified pixels may sit in the ring (the highlight's anti-aliased halo); glare (label >
``n_classes``) or a third class in the ring keeps the island as it is. A whole particle
alone among particles of the other class has the gaps between the particles in its ring
(unclassified), which keeps it below ``min_share`` (0.8): at 0.5, the half-resolution pale
teal/white pair of the suite lost lone pale particles to white (4.4% of R), because the
island size ``classes suggest`` estimated was larger than a particle there. The bed (the
union of the classes) does not change, only which class a few pixels count for.

Cost: one connected-components pass and one 3x3 dilation per class over the ROI's label
map (``drumtwin bench vision`` row ``centroid_cpu_fps_islands``); off unless
``[meter] island_px`` is set.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

__all__ = ["MIN_RING_SHARE", "island_relabel", "relabel_moments"]

MIN_RING_SHARE = 0.8
"""At least this share of an island's ring must be the enclosing class."""
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)


def island_relabel(labels: np.ndarray, n_classes: int, max_area: int, min_share: float = MIN_RING_SHARE,
                   lightness: Sequence[float] | None = None) -> np.ndarray:
    """A new label map (uint8, as ``labels``: 0 = no class, 1..``n_classes`` the counted
    classes, above that glare) with every island of at most ``max_area`` pixels relabelled
    to the class that encloses it (see the module docstring); ``lightness`` (one number per
    counted class, e.g. CIELAB L): only into a darker class. Pure; ``labels`` is not changed."""
    lab = np.ascontiguousarray(labels, np.uint8)
    out = lab.copy()
    if max_area <= 0:
        return out
    for c in range(1, n_classes + 1):
        mask = (lab == c).astype(np.uint8)
        n, cc, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=4, ltype=cv2.CV_32S)
        if n <= 1:
            continue
        small = stats[:, cv2.CC_STAT_AREA] <= max_area
        small[0] = False
        if not small.any():
            continue
        ids = np.where(small[cc], cc, 0)
        grown = cv2.dilate(ids.astype(np.float32), _CROSS).astype(np.int64)  # exact below 2^24 components
        ring = (grown > 0) & (ids == 0)
        comp = grown[ring]
        under = lab[ring].astype(np.int64)
        total = np.bincount(comp, minlength=n)
        other = (under > 0) & (under != c)
        bad = np.bincount(comp[other & (under > n_classes)], minlength=n) > 0  # glare in the ring
        good = other & (under <= n_classes)
        # the enclosing class: one counted class only (its min and max over the ring agree)
        hi = np.zeros(n, np.int64)
        lo = np.full(n, n_classes + 1, np.int64)
        np.maximum.at(hi, comp[good], under[good])
        np.minimum.at(lo, comp[good], under[good])
        share = np.bincount(comp[good], minlength=n)
        take = small & ~bad & (hi == lo) & (hi > 0) & (share >= min_share * np.maximum(total, 1))
        if lightness is not None:  # only a lighter island into a darker class
            lit = np.concatenate([[np.inf], np.asarray(lightness, np.float64)])
            take &= lit[np.minimum(hi, n_classes)] < lit[c]
        if take.any():
            target = np.where(take, hi, 0).astype(np.uint8)
            t = target[cc]
            sel = t > 0
            out[sel] = t[sel]
    return out


def relabel_moments(before: np.ndarray, after: np.ndarray, n_classes: int, origin_xy: tuple[int, int],
                    step: int) -> np.ndarray:
    """The change of each counted class's moments (rows 0..n_classes-1; columns n, sx, sy,
    sxx, syy, sxy in image px, int64) from label map ``before`` to ``after`` of the grid whose
    pixel (i, j) is image pixel (x0 + j * step, y0 + i * step)."""
    out = np.zeros((n_classes, 6), np.int64)
    ii, jj = np.nonzero(before != after)
    if ii.size == 0:
        return out
    x = origin_xy[0] + jj.astype(np.int64) * step
    y = origin_xy[1] + ii.astype(np.int64) * step
    m = np.stack([np.ones_like(x), x, y, x * x, y * y, x * y], axis=1)
    for lab, sign in ((before[ii, jj], -1), (after[ii, jj], 1)):
        for c in range(1, n_classes + 1):
            sel = lab == c
            if sel.any():
                out[c - 1] += sign * m[sel].sum(axis=0)
    return out

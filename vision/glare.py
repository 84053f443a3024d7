"""Glare: clipped light that hides part of the bed, and the class moments it hides.

A reflection of a lamp on the drum's front wall saturates the camera: a pixel with every
channel at or above ``vision.moments.GLARE_MIN`` that no counted class claims is *glare*
(the meter's lookup tables give it its own label). Around the clipped core the light
falls off and blends the particles below towards white, so the core is ringed by wrong
colours: a dark class blended with white looks like a lighter class of the same hue, and
no colour rule can tell the two apart. Leaving the spot out is not enough either: the
particles under it are missing from their class, and a class centroid moves away from
the spot by its share of the class.

So the meter treats a disc around each glare spot as unseen and fills it with the mix of
the bed seen just outside it: the moments of the disc's pixels are taken out of the
classes they were given and added back to every class, weighted by that class's share of
the pixels in a ring around the disc (no class, background and gaps included, so an empty
drum top fills with nothing). The disc's radius is ``HALO`` times the radius of a circle
with the clipped core's area, plus one grid pixel: for a spot whose light falls off like a
Gaussian and clips at its centre (gain 1.5: a blend of 1.5 g towards white) the blend is
below 8 % there; a stronger spot has a larger core for the same fall-off, so the disc
covers its halo with room to spare.

Pure functions of a grid label map; ``vision.meter`` calls them only on frames with glare.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["HALO", "RING", "glare_fill", "region_moments"]

HALO = 2.7
"""Radius of the unseen disc around a glare spot, in units of the core's equivalent radius."""
RING = 1.0
"""Width of the ring whose class mix fills the disc, in core radii (at least 2 grid pixels)."""


def region_moments(mask: np.ndarray, origin_xy: tuple[float, float], step: int) -> np.ndarray:
    """Moments ``n, sum x, sum y, sum x^2, sum y^2, sum xy`` (px, px^2; float64, shape (6,)) of
    the grid pixels set in ``mask`` (h, w); grid pixel (i, j) lies at px
    ``(x0 + j * step, y0 + i * step)``."""
    ii, jj = np.nonzero(mask)
    x = origin_xy[0] + jj.astype(np.float64) * step
    y = origin_xy[1] + ii.astype(np.float64) * step
    return np.array([x.size, x.sum(), y.sum(), (x * x).sum(), (y * y).sum(), (x * y).sum()])


def glare_fill(labels: np.ndarray, inside: np.ndarray, n_classes: int, origin_xy: tuple[float, float],
               step: int = 1) -> np.ndarray:
    """The change to every class's moments (float64, (n_classes, 6), the columns of
    ``vision.moments.MOMENT_FIELDS`` in px) that fills each glare spot of a grid label map
    with the class mix around it (module docstring).

    ``labels`` (h, w) uint8: 0 = no class, k = class k, ``n_classes + 1`` = glare, as the
    meter sees them (after its opening); ``inside`` (h, w) bool: grid pixels in the ROI;
    ``origin_xy``: px of grid pixel (0, 0); ``step``: grid spacing, px. Spots are the
    8-connected glare components inside the ROI, largest first; a pixel belongs to the
    disc of the first spot that reaches it.
    """
    glare = n_classes + 1
    delta = np.zeros((n_classes, 6))
    core = ((labels == glare) & inside).astype(np.uint8)
    n, comp, stats, _ = cv2.connectedComponentsWithStats(core, connectivity=8)
    if n <= 1:
        return delta
    h, w = labels.shape
    done = np.zeros((h, w), bool)
    for b in sorted(range(1, n), key=lambda k: -int(stats[k, cv2.CC_STAT_AREA])):
        r0 = math.sqrt(float(stats[b, cv2.CC_STAT_AREA]) / math.pi)
        r_in = HALO * r0 + 1.0
        r_out = r_in + max(RING * r0, 2.0)
        m = int(math.ceil(r_out)) + 1
        left, top = int(stats[b, cv2.CC_STAT_LEFT]), int(stats[b, cv2.CC_STAT_TOP])
        i0, i1 = max(0, top - m), min(h, top + int(stats[b, cv2.CC_STAT_HEIGHT]) + m)
        j0, j1 = max(0, left - m), min(w, left + int(stats[b, cv2.CC_STAT_WIDTH]) + m)
        spot = comp[i0:i1, j0:j1] == b
        dist = cv2.distanceTransform((~spot).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        free = inside[i0:i1, j0:j1] & ~done[i0:i1, j0:j1]
        lab = labels[i0:i1, j0:j1]
        disc = (dist <= r_in) & free
        ring = (dist > r_in) & (dist <= r_out) & free & (lab != glare)
        n_ring = int(ring.sum())
        origin = (origin_xy[0] + j0 * step, origin_xy[1] + i0 * step)
        whole = region_moments(disc, origin, step)
        for k in range(1, n_classes + 1):
            share = float(((lab == k) & ring).sum()) / n_ring if n_ring else 0.0
            delta[k - 1] += share * whole - region_moments(disc & (lab == k), origin, step)
        done[i0:i1, j0:j1] |= disc
    return delta

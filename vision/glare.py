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


def _terms(ii: np.ndarray, jj: np.ndarray, origin_xy: tuple[float, float], step: int) -> np.ndarray:
    """Per grid pixel (row ``ii``, column ``jj``) its moment terms ``1, x, y, x^2, y^2, xy``
    (px; float64, shape (6, n)); grid pixel (i, j) lies at px ``(x0 + j * step, y0 + i * step)``."""
    x = origin_xy[0] + jj.astype(np.float64) * step
    y = origin_xy[1] + ii.astype(np.float64) * step
    return np.stack([np.ones_like(x), x, y, x * x, y * y, x * y])


def region_moments(mask: np.ndarray, origin_xy: tuple[float, float], step: int) -> np.ndarray:
    """Moments ``n, sum x, sum y, sum x^2, sum y^2, sum xy`` (px, px^2; float64, shape (6,)) of
    the grid pixels set in ``mask`` (h, w); grid pixel (i, j) lies at px
    ``(x0 + j * step, y0 + i * step)``."""
    ii, jj = np.nonzero(mask)
    return _terms(ii, jj, origin_xy, step).sum(axis=1)


def glare_fill(labels: np.ndarray, inside: np.ndarray, n_classes: int, origin_xy: tuple[float, float],
               step: int = 1) -> np.ndarray:
    """The change to every class's moments (float64, (n_classes, 6), the columns of
    ``vision.moments.MOMENT_FIELDS`` in px) that fills each glare spot of a grid label map
    with the class mix around it (module docstring).

    ``labels`` (h, w) uint8: 0 = no class, k = class k, ``n_classes + 1`` = glare, as the
    meter sees them (after its opening); ``inside`` (h, w) bool: grid pixels in the ROI;
    ``origin_xy``: px of grid pixel (0, 0); ``step``: grid spacing, px. Spots are the
    connected glare components inside the ROI; a pixel belongs to the nearest spot (one
    distance transform for all of them, so a frame with hundreds of small spots costs
    about what one with three does).
    """
    glare = n_classes + 1
    delta = np.zeros((n_classes, 6))
    core = (labels == glare) & inside
    if not core.any():
        return delta
    dist, near = cv2.distanceTransformWithLabels((~core).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE,
                                                 labelType=cv2.DIST_LABEL_CCOMP)
    n_spots = int(near.max()) + 1
    area = np.bincount(near[core], minlength=n_spots).astype(np.float64)
    r0 = np.sqrt(area / math.pi)
    r_in = HALO * r0 + 1.0
    r_out = r_in + np.maximum(RING * r0, 2.0)
    disc = (dist <= r_in[near]) & inside
    ring = (dist > r_in[near]) & (dist <= r_out[near]) & inside & (labels != glare)
    # each spot's ring: pixels per label (column 0: no class, background, ...; the ring holds no glare)
    counts = np.bincount(near[ring] * (n_classes + 1) + labels[ring], minlength=n_spots * (n_classes + 1))
    counts = counts.reshape(n_spots, n_classes + 1).astype(np.float64)
    share = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)
    ii, jj = np.nonzero(disc)
    terms = _terms(ii, jj, origin_xy, step)  # (6, n) per disc pixel
    spot = near[ii, jj]
    lab = labels[ii, jj]
    for k in range(1, n_classes + 1):
        delta[k - 1] = terms @ share[spot, k] - terms[:, lab == k].sum(axis=1)
    return delta

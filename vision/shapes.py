"""A particle's outline as the camera sees it: traced from a picture, and round or not.

Pure functions of images and polygons (``trace_outline`` reads one file). Outlines are (k, 2)
polygons in px, y up, counter-clockwise. ``particle_shape`` decides from the single particles
of a class in the frames (``vision.census.single_particle_crops``) whether they are discs or
something else, with thresholds tuned on the real PMMA frames of tests/data; the twin turns its
answer into its own shape (``sim.mixer.shape_from_crops``).

The polygon helpers (area, centroid, simplicity) hold for any unit: the twin's mixer uses them
on outlines in metres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vision.errors import VisionError

TRACE_TOLERANCE = 0.02  # simplification tolerance of a traced outline, in particle sizes
ROUND_FILL = 0.75  # a particle covering this much of its enclosing circle (``mask_fill``) and
ROUND_SOLIDITY = 0.92  # this much of its traced outline's convex hull is a disc (the real PMMA discs of
# tests/data: 0.81, 0.96 at 22 px; a 90-degree cut disc of that size: 0.65, 0.90)
SHAPE_MIN_PX = 16.0  # particles fewer pixels across than this show no shape (the PMMA discs at 11.5 px read 0.72-0.76)


# ------------------------------------------------------------------ polygons (any unit)
def polygon_area(vertices: np.ndarray) -> float:
    """Signed shoelace area of a closed polygon (k, 2), in its unit squared (> 0 counter-clockwise)."""
    v = np.asarray(vertices, dtype=float)
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_centroid(v: np.ndarray) -> np.ndarray:
    """Area centroid (2,) of a closed polygon (k, 2) (its vertices' mean when it has no area)."""
    x, y = v[:, 0], v[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a = 0.5 * cross.sum()
    if abs(a) < 1e-30:
        return v.mean(axis=0)
    cx = ((x + np.roll(x, -1)) * cross).sum() / (6 * a)
    cy = ((y + np.roll(y, -1)) * cross).sum() / (6 * a)
    return np.array([cx, cy])


def _segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> bool:
    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> float:
        return float((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    o1, o2, o3, o4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
    return o1 * o2 < 0 and o3 * o4 < 0


def is_simple_polygon(vertices: np.ndarray) -> bool:
    """True if the closed polygon (k, 2) has >= 3 vertices, a non-zero area and no two
    non-adjacent edges crossing."""
    v = np.asarray(vertices, dtype=float)
    k = len(v)
    if k < 3 or abs(polygon_area(v)) <= 1e-18:
        return False
    for i in range(k):
        for j in range(i + 1, k):
            if j == i + 1 or (i == 0 and j == k - 1):
                continue
            if _segments_cross(v[i], v[(i + 1) % k], v[j], v[(j + 1) % k]):
                return False
    return True


def circumscribed_diameter(v: np.ndarray) -> float:
    """Twice the largest distance of a polygon's (k, 2) vertices from its area centroid."""
    v = np.asarray(v, dtype=float)
    c = polygon_centroid(v if polygon_area(v) > 0 else v[::-1])
    return 2.0 * float(np.max(np.hypot(v[:, 0] - c[0], v[:, 1] - c[1])))


# ------------------------------------------------------------------ tracing
def trace_outline(path: Path, where: str = "traced shape") -> np.ndarray:
    """Outline (k, 2, px, y up, counter-clockwise) of the one particle in a picture: the
    largest dark-on-light or light-on-dark blob, traced by ``pymunk.autogeometry.march_soft``
    and simplified to a polygon (``TRACE_TOLERANCE`` of its size). A picture that cannot be
    read or shows no particle is a one-line ``VisionError`` starting with ``where``."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise VisionError(f"{where}: cannot read the image {path}")
    g = img.astype(float) / 255.0
    if np.median(np.concatenate([g[0], g[-1], g[:, 0], g[:, -1]])) > 0.5:
        g = 1.0 - g  # dark particle on a light background
    return trace_particle(g, where, str(path))


def trace_particle(g: np.ndarray, where: str = "traced shape", what: str = "the picture") -> np.ndarray:
    """Outline (k, 2, px, y up) of the largest bright blob of ``g`` (2D, 0..1, particle > 0.5),
    traced by ``pymunk.autogeometry.march_soft`` and simplified (``TRACE_TOLERANCE`` of its size)."""
    import pymunk
    import pymunk.autogeometry as ag

    g = np.asarray(g, dtype=float)
    h, w = g.shape
    pad = np.zeros((h + 2, w + 2))
    pad[1:-1, 1:-1] = g

    def sample(p: tuple[float, float]) -> float:
        x, y = int(round(p[0])), int(round(p[1]))
        return float(pad[min(max(y, 0), h + 1), min(max(x, 0), w + 1)])

    lines = ag.march_soft(pymunk.BB(0, 0, w + 1, h + 1), w + 2, h + 2, 0.5, sample)
    if not lines:
        raise VisionError(f"{where}: no particle found in {what}")
    best = max(lines, key=lambda ln: abs(polygon_area(np.array([[p.x, p.y] for p in ln]))))
    simple = ag.simplify_curves(best, TRACE_TOLERANCE * max(h, w))
    v = np.array([[p.x, -p.y] for p in simple], dtype=float)  # image y down -> y up
    if len(v) > 1 and np.allclose(v[0], v[-1]):
        v = v[:-1]
    if len(v) < 3:
        raise VisionError(f"{where}: the outline traced from {what} has fewer than three corners")
    return v


# ------------------------------------------------------------------ round or not
def outline_roundness(v: np.ndarray) -> tuple[float, float]:
    """(fill, solidity) of a polygon (k, 2): its area over its circumscribed circle's (about its
    centroid; a disc ~1, a 90-degree cut disc 0.75, a hexagon 0.83) and over its convex hull's
    (a disc or any convex shape 1, a 90-degree cut disc 0.82)."""
    import cv2

    v = np.asarray(v, dtype=float)
    area = abs(polygon_area(v))
    r = 0.5 * circumscribed_diameter(v)
    hull = cv2.convexHull(v.astype(np.float32)).reshape(-1, 2).astype(float)
    hull_area = abs(polygon_area(hull))
    return (area / (math.pi * r * r) if r > 0 else 0.0, area / hull_area if hull_area > 0 else 0.0)


def mask_fill(mask: np.ndarray) -> float:
    """A particle mask's area over the circle of its 98th-percentile pixel distance from its
    centroid (+ half a pixel): 0.94 for a disc of 22 px, 0.65 for a 90-degree cut disc (its centroid
    is off the disc's centre); robust to a few stray pixels (a traced outline's circumscribed circle
    is not)."""
    ys, xs = np.nonzero(np.asarray(mask, dtype=bool))
    if xs.size < 3:
        return 0.0
    r = float(np.percentile(np.hypot(xs - xs.mean(), ys - ys.mean()), 98)) + 0.5
    return float(xs.size / (math.pi * r * r))


@dataclass(frozen=True)
class ParticleShape:
    """What a class's single particles look like: ``outline_px`` None for round particles, else
    the median particle's traced outline (k, 2, px, y up); ``how`` says how it was decided (a
    comment for the written mixer)."""

    outline_px: np.ndarray | None
    how: str

    @property
    def is_round(self) -> bool:
        return self.outline_px is None


def particle_shape(crops: Sequence[np.ndarray], diameter_px: float) -> ParticleShape:
    """A class's particle shape from boolean crops of its single particles, each traced
    (``trace_particle``): round when the median particle covers ``ROUND_FILL`` of its enclosing
    circle (``mask_fill``) and its outline ``ROUND_SOLIDITY`` of its convex hull, else the median
    particle's outline. Particles under ``SHAPE_MIN_PX`` across (``diameter_px``) are round: too
    few pixels to tell; so is a class without a particle to trace."""
    if diameter_px < SHAPE_MIN_PX:
        return ParticleShape(None, f"round assumed: particles {diameter_px:.0f} px across are too few pixels to "
                                   f"show a shape (fewer than {SHAPE_MIN_PX:g}); edit for other shapes")
    traced = []
    for c in crops:
        try:
            v = trace_particle(np.asarray(c, dtype=float))
        except VisionError:
            continue
        if is_simple_polygon(v):
            traced.append(((mask_fill(c), outline_roundness(v)[1]), v))
    if not traced:
        return ParticleShape(None, "round assumed (no single particle to trace); edit for other shapes")
    fills = np.array([t[0][0] for t in traced])
    fill, sol = float(np.median(fills)), float(np.median([t[0][1] for t in traced]))
    how = (f"traced from {len(traced)} single particles in the frames: median {fill:.2f} of the enclosing "
           f"circle, {sol:.2f} of the convex hull")
    if fill >= ROUND_FILL and sol >= ROUND_SOLIDITY:
        return ParticleShape(None, how + f" (>= {ROUND_FILL:g}, {ROUND_SOLIDITY:g}: round)")
    _, v = traced[int(np.argsort(fills, kind="stable")[len(fills) // 2])]
    return ParticleShape(v, how)


__all__ = [
    "ROUND_FILL",
    "ROUND_SOLIDITY",
    "SHAPE_MIN_PX",
    "TRACE_TOLERANCE",
    "ParticleShape",
    "circumscribed_diameter",
    "is_simple_polygon",
    "mask_fill",
    "outline_roundness",
    "particle_shape",
    "polygon_area",
    "polygon_centroid",
    "trace_outline",
    "trace_particle",
]

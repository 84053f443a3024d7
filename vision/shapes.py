"""A particle's outline as the camera sees it: traced from a picture, and what shape it is.

Pure functions of images and polygons (``trace_outline`` reads one file). Outlines are (k, 2)
polygons in px, y up, counter-clockwise. ``particle_shape`` decides from the single particles
of a class in the frames (``vision.census.single_particles_at``) what they are: discs, discs with a
notch (a convexity defect: its depth and opening), elongated pellets, polygons, or their traced
outline; outlines too rough to read (a class map at a size the camera barely resolves) fall back to
the coarse area test tuned on the real PMMA frames of tests/data. The twin turns the answer into its
own shape (``sim.mixer.shape_from_traced``; docs/commissioning.md).

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
ROUND_FILL = 0.75  # rough outlines: a particle covering this much of its enclosing circle (``mask_fill``) and
ROUND_SOLIDITY = 0.92  # this much of its convex hull is round; convex from this solidity (the real PMMA discs of
# tests/data: 0.81-0.84, 0.96 at 22 px; a 90-degree cut disc of that size: 0.65, 0.90)
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


# ------------------------------------------------------------------ what a particle's outline is
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


def _circle_fit(p: np.ndarray) -> tuple[float, float, float]:
    """Least-squares circle (cx, cy, r) through points (k, 2) (Kasa's algebraic fit)."""
    x, y = p[:, 0], p[:, 1]
    sol = np.linalg.lstsq(np.stack([x, y, np.ones_like(x)], axis=1), x * x + y * y, rcond=None)[0]
    cx, cy = 0.5 * sol[0], 0.5 * sol[1]
    return float(cx), float(cy), math.sqrt(max(float(sol[2]) + cx * cx + cy * cy, 0.0))


@dataclass(frozen=True)
class Outline:
    """What one particle's outline (a boolean crop's outer contour, px) shows.

    ``radius_px``: the circle through the outline outside its deepest concavity (least squares; the
    pixel edge half a pixel outside the contour's pixel centres); ``round_rms``: the rms distance of
    those points from it, in radii (a disc of 22 px 0.02, a hexagon 0.03, a square 0.06);
    ``notch_depth``: the deepest concavity's (convexity defect's) apex below that circle, in radii
    (0: none; a cut disc ~1); ``notch_deg``: its opening, the angle at the apex between the points
    where the outline leaves the convex hull; ``elongation``: long over short axis (second moments;
    a disc 1); ``corners``: the convex hull's corners (``cv2.approxPolyDP`` at ``CORNER_TOL`` of the
    radius) and ``corner_rms`` the outline's rms distance from that polygon, in radii (a clean polygon's
    outline lies on it, a rough disc's does not); ``solidity``: area over the convex hull's."""

    radius_px: float
    round_rms: float
    notch_depth: float
    notch_deg: float
    elongation: float
    corners: int
    solidity: float
    corner_rms: float = math.inf


CORNER_TOL = 0.12  # a hull corner: the outline leaves the hull's simplification by this many radii
NOTCH_MIN_DEPTH = 0.12  # a concavity this many radii deep (and ``NOTCH_MIN_PX``) is a notch; a disc of 22 px
NOTCH_MIN_PX = 2.0  # ... shows up to 0.08 from its pixels, the real PMMA discs up to ... (docs/commissioning.md)
ROUND_RMS = 0.045  # an outline within this many radii (rms) of its circle is round (a hexagon 0.03 is round too:
# below ``POLYGON_MIN_PX`` a camera cannot tell them)
ELONGATED = 1.25  # long over short axis from this: elongated (a pellet)
MAX_SIDES = 6  # more corners than this look round to a camera (an octagon is within 0.03 radii of its circle)
CORNER_RMS = 0.04  # a polygon's outline within this many radii (rms) of its corners' polygon (a rough disc's is not)
POLYGON_MIN_PX = 24.0  # particles this many px across (their circle's diameter) show their corners (fewer: round,
# elongated or their traced outline)


WALL_SPAN = (0.25, 0.75)  # a notch's walls are fitted between these shares of the way from its apex to the rim
# (the apex and the rim's corners are rounded by the camera's blur and the crop's opening)


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    n = float(np.linalg.norm(u) * np.linalg.norm(v))
    return math.degrees(math.acos(min(max(float(np.dot(u, v)) / n, -1.0), 1.0))) if n > 0 else math.nan


def _opening_deg(p: np.ndarray, notch: tuple[np.ndarray, np.ndarray, np.ndarray], circle: tuple[float, float, float],
                 ) -> float:
    """A notch's opening (deg): the angle between straight lines fitted to its two walls (the contour ``p``
    from the hull's departure point to the apex, and on to its return, over ``WALL_SPAN``), else the angle
    at the apex between those points."""
    import cv2

    ps, pe, pf = notch
    cx, cy, r = circle
    a = math.hypot(pf[0] - cx, pf[1] - cy)
    lo, hi = a + WALL_SPAN[0] * (r - a), a + WALL_SPAN[1] * (r - a)
    fi = int(np.flatnonzero((p == pf).all(axis=1))[0])
    walls = []
    for end in (ps, pe):
        ei = int(np.flatnonzero((p == end).all(axis=1))[0])
        i0, i1 = sorted((fi, ei))
        seg = p[i0:i1 + 1] if i1 - i0 <= len(p) // 2 else np.concatenate([p[i1:], p[:i0 + 1]])
        rr = np.hypot(seg[:, 0] - cx, seg[:, 1] - cy)
        wall = seg[(rr >= lo) & (rr <= hi)]
        if len(wall) < 3:
            return _angle_deg(ps - pf, pe - pf)
        d = cv2.fitLine(wall.astype(np.float32), cv2.DIST_L2, 0, 0.01, 0.01).ravel()[:2]
        walls.append(d if float(np.dot(d, wall.mean(axis=0) - pf)) > 0 else -d)
    return _angle_deg(walls[0], walls[1])


def outline_of(mask: np.ndarray) -> Outline | None:
    """The ``Outline`` of the largest blob of a boolean crop (None: no blob of 5 pixels or more)."""
    import cv2

    m = np.pad(np.asarray(mask, dtype=np.uint8), 2)
    cnts, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not cnts:
        return None
    c = max(cnts, key=cv2.contourArea)
    area = float(cv2.contourArea(c))
    if len(c) < 5 or area < 5:
        return None
    p = c.reshape(-1, 2).astype(float)
    hull_idx = cv2.convexHull(c, returnPoints=False)
    try:
        defects = cv2.convexityDefects(c, hull_idx) if len(hull_idx) > 3 else None
    except cv2.error:  # a contour that touches itself (a one-pixel neck): its hull indices are not monotonic
        defects = None
    rim = np.ones(len(p), dtype=bool)
    far = None
    if defects is not None and len(defects):
        d = defects.reshape(-1, 4)
        s, e, f, _ = (int(v) for v in d[int(np.argmax(d[:, 3]))])
        idx = np.arange(len(p))
        rim = ~(((idx >= s) & (idx <= e)) if s <= e else ((idx >= s) | (idx <= e)))
        far = (p[s], p[e], p[f])
    cx, cy, r = _circle_fit(p[rim] if rim.sum() >= 5 else p)
    res = np.hypot(p[rim, 0] - cx, p[rim, 1] - cy) - r
    depth, opening = 0.0, math.nan
    if far is not None and r > 0:
        depth = max(0.0, 1.0 - math.hypot(far[2][0] - cx, far[2][1] - cy) / r)
        opening = _opening_deg(p, far, (cx, cy, r))
    mu = cv2.moments(c)
    cov = np.array([[mu["mu20"], mu["mu11"]], [mu["mu11"], mu["mu02"]]]) / max(mu["m00"], 1e-9)
    ev = np.linalg.eigvalsh(cov)
    hull = cv2.convexHull(c)
    poly = cv2.approxPolyDP(hull, CORNER_TOL * max(r, 1.0), True)
    off = [cv2.pointPolygonTest(poly, (float(x), float(y)), True) for x, y in p]
    return Outline(radius_px=r + 0.5, round_rms=float(np.sqrt(np.mean(res ** 2))) / r if r > 0 else math.inf,
                   notch_depth=depth, notch_deg=opening,
                   elongation=math.sqrt(ev[1] / ev[0]) if ev[0] > 0 else math.inf, corners=len(poly),
                   solidity=area / max(float(cv2.contourArea(hull)), 1e-9),
                   corner_rms=float(np.sqrt(np.mean(np.square(off)))) / r if r > 0 else math.inf)


KINDS = ("disc", "notched_disc", "pellet", "polygon", "outline")  # ``outline_kind``'s answers (ties: the first)


def outline_kind(o: Outline) -> str:
    """What one particle is: ``"notched_disc"`` (round, with a concavity ``NOTCH_MIN_DEPTH`` deep),
    ``"disc"`` (within ``ROUND_RMS`` of its circle), ``"pellet"`` (``ELONGATED``), ``"polygon"``
    (convex, at most ``MAX_SIDES`` corners it lies on within ``CORNER_RMS``, seen ``POLYGON_MIN_PX``
    across), else ``"outline"`` (its traced outline)."""
    notch_px = o.notch_depth * o.radius_px
    if o.round_rms <= ROUND_RMS and o.notch_depth >= NOTCH_MIN_DEPTH and notch_px >= NOTCH_MIN_PX:
        return "notched_disc"
    if o.elongation >= ELONGATED and o.solidity >= ROUND_SOLIDITY:
        return "pellet"
    if o.round_rms <= ROUND_RMS and o.solidity >= ROUND_SOLIDITY:
        return "disc"
    if (o.solidity >= ROUND_SOLIDITY and 2 * o.radius_px >= POLYGON_MIN_PX and 3 <= o.corners <= MAX_SIDES
            and o.corner_rms <= CORNER_RMS):
        return "polygon"
    return "outline"


@dataclass(frozen=True)
class ParticleShape:
    """What a class's single particles look like: ``kind`` (``outline_kind`` of most of them),
    ``outline_px`` the median particle's traced outline (k, 2, px, y up; None for round particles),
    ``diameter_px`` (the circle's diameter of a disc or notched disc, the long axis of a pellet, the
    circumscribed diameter otherwise), ``notch_deg``/``notch_depth`` (a notched disc's, medians),
    ``width_px`` (a pellet's short axis), ``sides`` (a polygon's), ``n`` particles traced; ``how``
    says how it was decided (a comment for the written mixer); ``sized``: the outlines were clean (of
    a kind), so ``diameter_px`` is their circle's (a disc's gray edge: within 1 % on rendered discs,
    where the gray-image circles of a packed bed read 2 % large)."""

    outline_px: np.ndarray | None
    how: str
    kind: str = "disc"
    diameter_px: float = math.nan
    notch_deg: float = math.nan
    notch_depth: float = math.nan
    width_px: float = math.nan
    sides: int = 0
    n: int = 0
    sized: bool = False  # ``diameter_px`` from clean outlines (the majority kind's), not from rough ones

    @property
    def is_round(self) -> bool:
        return self.kind == "disc"


def _traced(crops: Sequence[np.ndarray]) -> list[tuple[Outline, np.ndarray, np.ndarray]]:
    """(outline measures, traced polygon, crop) of each crop that traces to a simple polygon."""
    out = []
    for c in crops:
        o = outline_of(c)
        if o is None:
            continue
        try:
            v = trace_particle(np.asarray(c, dtype=float))
        except VisionError:
            continue
        if is_simple_polygon(v):
            out.append((o, v, np.asarray(c)))
    return out


def particle_shape(crops: Sequence[np.ndarray], diameter_px: float) -> ParticleShape:
    """A class's particle shape from boolean crops of its single particles: each one's ``Outline``
    (convexity defects for notches, the circle's residual for roundness, the axes for elongation, the
    hull's corners) and ``outline_kind``; the kind of most of them wins, its numbers the medians of
    the particles of that kind. When most outlines fit no kind (rough: a class map's edges at a
    particle size the camera barely resolves), the coarse test decides: round when the median particle
    covers ``ROUND_FILL`` of its enclosing circle (``mask_fill``) and ``ROUND_SOLIDITY`` of its hull,
    else its traced outline, and the note says the outlines were too rough for a notch or corners.
    Particles under ``SHAPE_MIN_PX`` across (``diameter_px``) are round: too few pixels to tell; so
    is a class without a particle to trace."""
    if diameter_px < SHAPE_MIN_PX:
        return ParticleShape(None, f"round assumed: particles {diameter_px:.0f} px across are too few pixels to "
                                   f"show a shape (fewer than {SHAPE_MIN_PX:g}); edit for other shapes")
    traced = _traced(crops)
    if not traced:
        return ParticleShape(None, "round assumed (no single particle to trace); edit for other shapes")
    kinds = [outline_kind(o) for o, _, _ in traced]
    kind = max(KINDS, key=kinds.count)
    mine = [t for t, k in zip(traced, kinds, strict=True) if k == kind]
    os_ = [o for o, _, _ in mine]

    def med(f: str, of: Sequence[Outline] = os_) -> float:
        return float(np.median([getattr(o, f) for o in of]))

    how = f"traced from {len(traced)} single particles in the frames"
    if kind == "outline":  # rough outlines: the coarse test (area against the enclosing circle and the hull)
        alls = [o for o, _, _ in traced]
        fill = float(np.median([mask_fill(c) for _, _, c in traced]))
        how += (f": outlines too rough to see a notch or corners (median {med('round_rms', alls):.3f} radii from "
                f"their circle; {len(mine)} of {len(traced)} fit no shape); median {fill:.2f} of the enclosing circle, "
                f"{med('solidity', alls):.2f} of the hull")
        if fill >= ROUND_FILL and med("solidity", alls) >= ROUND_SOLIDITY:
            return ParticleShape(None, how + f" (>= {ROUND_FILL:g}, {ROUND_SOLIDITY:g}: round)", "disc",
                                 2 * med("radius_px", alls), n=len(traced))
    else:
        how += (f", {len(mine)} of them {kind.replace('_', ' ')} (median {med('round_rms'):.3f} radii from their "
                f"circle, deepest concavity {med('notch_depth'):.2f} radii, {med('elongation'):.2f} long over short")
    fills = np.array([mask_fill(c) for _, _, c in mine])
    v = mine[int(np.argsort(fills, kind="stable")[len(fills) // 2])][1]  # the median particle's outline
    if kind == "disc":
        return ParticleShape(None, how + f": round, no concavity {NOTCH_MIN_DEPTH:g} radii deep)", kind,
                             2 * med("radius_px"), n=len(traced), sized=True)
    if kind == "notched_disc":
        return ParticleShape(v, how + f": a notch of {med('notch_deg'):.0f} deg, {med('notch_depth'):.2f} of the "
                                      "radius deep)", kind, 2 * med("radius_px"), med("notch_deg"),
                             med("notch_depth"), n=len(traced), sized=True)
    d = float(np.median([circumscribed_diameter(t[1]) for t in mine]))
    if kind == "pellet":
        return ParticleShape(v, how + ": elongated)", kind, d, width_px=d / med("elongation"), n=len(traced))
    if kind == "polygon":
        sides = int(np.median([o.corners for o in os_]))
        return ParticleShape(v, how + f": convex, {sides} corners)", kind, d, sides=sides, n=len(traced))
    return ParticleShape(v, how + ": not round", kind, d, n=len(traced))


__all__ = [
    "CORNER_RMS",
    "CORNER_TOL",
    "ELONGATED",
    "KINDS",
    "MAX_SIDES",
    "NOTCH_MIN_DEPTH",
    "NOTCH_MIN_PX",
    "POLYGON_MIN_PX",
    "ROUND_FILL",
    "ROUND_RMS",
    "ROUND_SOLIDITY",
    "SHAPE_MIN_PX",
    "TRACE_TOLERANCE",
    "Outline",
    "ParticleShape",
    "circumscribed_diameter",
    "is_simple_polygon",
    "mask_fill",
    "outline_kind",
    "outline_of",
    "particle_shape",
    "polygon_area",
    "polygon_centroid",
    "trace_outline",
    "trace_particle",
]

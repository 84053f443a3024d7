"""The pymunk twin's particles: each a DYNAMIC body; discs are ``Circle``; convex outlines
(regular polygon, pellet) one ``Poly`` with a corner radius ``CORNER_R`` of the particle's radius
(the vertices pulled in by it, so the outer size stays); non-convex outlines one body of several
convex ``Poly`` pieces (a cut disc or a notched disc: two or three fans from the notch's apex, each
seeing less than 144 deg of the rim; other outlines: ``pymunk.autogeometry.convex_decomposition``).
The flat particle's own moment of inertia (2D is the real physics of a monolayer).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pymunk.autogeometry

from sim.mixer import Shape, shape_outline_m

CORNER_R = 0.02  # corner radius of polygon shapes, in the particle's radius
PIECE_SEGMENTS = 16  # round parts of a polygon piece: vertices per full turn (cost of Chipmunk's poly contacts)


def _is_convex(v: np.ndarray) -> bool:
    d = np.roll(v, -1, axis=0) - v
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross >= -1e-15) or np.all(cross <= 1e-15))


def convex_pieces(shape: Shape) -> list[np.ndarray]:
    """The shape's outline (body frame, m, about its centroid) as convex polygons (k, 2); [] for a disc."""
    if shape.kind == "disc":
        return []
    outline = shape_outline_m(shape, segments=PIECE_SEGMENTS)
    if shape.kind in ("cut_disc", "notched_disc"):
        return _fan_pieces(outline[0], outline[1:])
    if _is_convex(outline):
        return [outline]
    closed = [tuple(p) for p in outline] + [tuple(outline[0])]
    hulls = pymunk.autogeometry.convex_decomposition(closed, 1e-3 * shape.radius_m)
    return [np.asarray([(p.x, p.y) for p in h[:-1]]) for h in hulls]


def _fan_pieces(apex: np.ndarray, arc: np.ndarray) -> list[np.ndarray]:
    """A disc with a wedge or notch cut out (the apex inside the disc, the rim's ``arc`` around it) as
    convex fans sharing the apex, each seeing less than 144 deg of the arc from the apex (convex, few
    pairs): a cut disc's sectors (the apex at the centre), a notched disc's pieces."""
    seen = np.unwrap(np.arctan2(arc[:, 1] - apex[1], arc[:, 0] - apex[0]))
    cum = np.abs(seen - seen[0])
    k = max(1, math.ceil(float(cum[-1]) / (0.8 * math.pi) - 1e-9))
    idx = np.rint(np.interp(np.linspace(0.0, float(cum[-1]), k + 1), cum, np.arange(len(arc)))).astype(int)
    return [np.vstack([apex, arc[idx[j]: idx[j + 1] + 1]]) for j in range(k)]


def moment_kg_m2(shape: Shape, mass_kg: float) -> float:
    """Polar moment of inertia of the flat particle about its centroid (kg m^2)."""
    if shape.kind == "disc":
        return 0.5 * mass_kg * shape.radius_m ** 2
    v = shape_outline_m(shape, segments=96)
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    j = (cross * (x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1)).sum() / 12.0
    return float(mass_kg * j / area)


def particle_body(shape: Shape, mass_kg: float, moment_kg_m2_: float, pos_m: tuple[float, float],
                  angle_rad: float, scale: float) -> tuple[pymunk.Body, list[pymunk.Shape]]:
    """A particle's body at ``pos_m`` (m), turned by ``angle_rad``, and its shapes at ``scale`` of full
    size (a disc's circle, else its convex pieces with the corner radius)."""
    body = pymunk.Body(mass_kg, moment_kg_m2_)
    body.position = pos_m
    body.angle = angle_rad
    pieces = convex_pieces(shape)
    shapes: list[pymunk.Shape]
    if not pieces:
        shapes = [pymunk.Circle(body, shape.radius_m * scale)]
    else:
        c = CORNER_R * shape.radius_m
        pull = (shape.radius_m - c) / shape.radius_m
        shapes = [pymunk.Poly(body, [tuple(p) for p in piece * pull * scale], radius=c * scale)
                  for piece in pieces]
    return body, shapes


def scale_particle(shapes: list[pymunk.Shape], shape: Shape, is_round: bool, scale: float) -> None:
    """Set one particle's shapes to ``scale`` times full size (inflation)."""
    if is_round:
        for s in shapes:
            assert isinstance(s, pymunk.Circle)
            s.unsafe_set_radius(shape.radius_m * scale)
        return
    c = CORNER_R * shape.radius_m
    pull = (shape.radius_m - c) / shape.radius_m
    for s, piece in zip(shapes, convex_pieces(shape), strict=True):
        assert isinstance(s, pymunk.Poly)
        s.unsafe_set_vertices([tuple(q) for q in piece * pull * scale])
        s.unsafe_set_radius(c * scale)


__all__ = ["CORNER_R", "PIECE_SEGMENTS", "convex_pieces", "moment_kg_m2", "particle_body", "scale_particle"]

"""The user's mixer: drum, baffles and particle classes, as the config describes them.

This module is the one definition of the twin's mixer (issue 20). The config holds it
next to the colour classes::

    [drum]
    diameter_mm = 300          # inner diameter
    depth_mm = 100             # distance between the end plates; or monolayer = true
    monolayer = false          # quasi-2D drum one particle thick: depth = the particles' thickness
    fill = 0.5                 # share of the cross-section the bed covers (at random packing)
    rotation = "ccw"           # as the camera sees it: "ccw" (surface rises to the right) or "cw"
    density_kg_m3 = 1180       # drum material (not used by the physics yet)

    [drum.baffles]             # optional: lifters on the wall, turning with the drum
    count = 4
    height_mm = 20             # radial length from the wall inwards
    thickness_mm = 4

    [[particles]]              # one table per colour class, same name as the camera's class
    name = "blue"
    shape = "disc"             # disc | polygon | pellet | cut_disc | vertices | traced
    diameter_mm = 10           # circumscribed diameter (disc, polygon, cut_disc, vertices) or length (pellet)
    density_kg_m3 = 1190
    share = 0.5                # share of the bed's solid area; or count = 120
    # polygon:  sides = 6
    # pellet:   width_mm = 5, corner_mm = 1   (rounded rectangle diameter_mm x width_mm)
    # cut_disc: wedge_deg = 90                 (a disc with a wedge cut out: non-convex)
    # vertices: vertices_mm = [[x, y], ...]    (a simple polygon about its centroid)
    # traced:   image = "particle.png"         (outline of one particle, pymunk.autogeometry)
    thickness_mm = 5           # monolayer drums: the particle's thickness (default its diameter)

Frame: origin at the drum axis, x to the right, y up, as the camera sees the front face
(the DEM's frame, ``sim.drum``). ``direction`` +1 is counter-clockwise as seen.

Everything here is data: dataclasses and pure functions, no I/O (``parse_mixer`` takes
the TOML's dict; a ``traced`` shape is resolved to vertices by the caller that reads the
picture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from sim.recipe import DrumSpec

ShapeKind = Literal["disc", "polygon", "pellet", "cut_disc", "vertices"]
ROUND_SHAPES: tuple[str, ...] = ("disc",)


@dataclass(frozen=True)
class Shape:
    """A particle's outline in its body frame (m), centred on its centroid.

    ``diameter_m``: the circumscribed diameter (disc, polygon, cut_disc, vertices) or the
    length (pellet). ``sides`` for a regular polygon; ``width_m`` and ``corner_m`` for a
    pellet (rounded rectangle); ``wedge_deg`` for a cut disc; ``vertices_m`` (k, 2) for a
    simple polygon given by its vertices (counter-clockwise, about its centroid).
    """

    kind: ShapeKind = "disc"
    diameter_m: float = 0.010
    sides: int | None = None
    width_m: float | None = None
    corner_m: float | None = None
    wedge_deg: float | None = None
    vertices_m: tuple[tuple[float, float], ...] | None = None

    @property
    def is_round(self) -> bool:
        """True for a disc: the compiled DEM can hold it."""
        return self.kind in ROUND_SHAPES

    @property
    def radius_m(self) -> float:
        """Circumscribed radius (m)."""
        return 0.5 * self.diameter_m


@dataclass(frozen=True)
class ParticleKind:
    """One particle class of the twin, named as the camera's colour class.

    Exactly one of ``count`` (particles in the slice) or ``share`` (share of the bed's
    solid area, 0..1) is set. ``thickness_m`` None: the particle's diameter (a sphere's
    slice, or a monolayer particle as thick as it is wide).
    """

    name: str
    shape: Shape
    density_kg_m3: float = 1190.0
    count: int | None = None
    share: float | None = None
    thickness_m: float | None = None
    colour_bgr: tuple[int, int, int] = (0, 0, 220)


@dataclass(frozen=True)
class Baffles:
    """Lifters on the drum wall, evenly spaced, turning with it (m)."""

    count: int
    height_m: float
    thickness_m: float


@dataclass(frozen=True)
class Mixer:
    """The user's mixer: the drum (``DrumSpec``: diameter, depth), the bed and its rotation.

    ``fill``: share of the drum's cross-section the bed covers at random packing;
    ``direction``: +1 counter-clockwise as the camera sees it, -1 clockwise;
    ``monolayer``: a quasi-2D drum one particle thick (the end plates touch every particle).
    """

    drum: DrumSpec
    particles: tuple[ParticleKind, ...]
    fill: float = 0.5
    direction: int = 1
    monolayer: bool = False
    baffles: Baffles | None = None
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def all_round(self) -> bool:
        """Every class is a disc and the drum has no baffles (the DEM's domain)."""
        return all(p.shape.is_round for p in self.particles) and self.baffles is None

    @property
    def class_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.particles)


def shape_area_m2(shape: Shape) -> float:
    """Area of the outline (m^2)."""
    r = shape.radius_m
    if shape.kind == "disc":
        return math.pi * r * r
    if shape.kind == "cut_disc":
        return math.pi * r * r * (1.0 - float(shape.wedge_deg or 0.0) / 360.0)
    if shape.kind == "pellet":
        w = float(shape.width_m or shape.diameter_m)
        c = min(float(shape.corner_m or 0.0), 0.5 * w, 0.5 * shape.diameter_m)
        return shape.diameter_m * w - (4.0 - math.pi) * c * c
    return polygon_area_m2(shape_outline_m(shape))


def polygon_area_m2(vertices: np.ndarray) -> float:
    """Signed shoelace area of a closed polygon (k, 2) in m^2 (> 0 counter-clockwise)."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def shape_outline_m(shape: Shape, segments: int = 48) -> np.ndarray:
    """The outline as a counter-clockwise polygon (k, 2) in m about the shape's centre
    (a disc or the round parts approximated with ``segments`` per full turn)."""
    r = shape.radius_m
    if shape.kind == "disc":
        a = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    if shape.kind == "polygon":
        k = int(shape.sides or 6)
        a = np.linspace(0.0, 2 * math.pi, k, endpoint=False) + math.pi / 2
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    if shape.kind == "pellet":
        half_l, half_w = 0.5 * shape.diameter_m, 0.5 * float(shape.width_m or shape.diameter_m)
        c = min(float(shape.corner_m or 0.0), half_w, half_l)
        pts: list[tuple[float, float]] = []
        quarter = max(2, segments // 4)
        for cx, cy, a0 in ((half_l - c, half_w - c, 0.0), (-half_l + c, half_w - c, 0.5 * math.pi),
                           (-half_l + c, -half_w + c, math.pi), (half_l - c, -half_w + c, 1.5 * math.pi)):
            for a in np.linspace(a0, a0 + 0.5 * math.pi, quarter):
                pts.append((cx + c * math.cos(a), cy + c * math.sin(a)))
        return np.asarray(pts)
    if shape.kind == "cut_disc":
        wedge = math.radians(float(shape.wedge_deg or 90.0))
        k = max(8, int(round(segments * (1 - wedge / (2 * math.pi)))))
        a = np.linspace(0.5 * wedge, 2 * math.pi - 0.5 * wedge, k)
        pts_arr = np.concatenate([[[0.0, 0.0]], np.stack([r * np.cos(a), r * np.sin(a)], axis=1)])
        return pts_arr - _centroid(pts_arr)
    if shape.kind == "vertices":
        v = np.asarray(shape.vertices_m, dtype=float)
        if polygon_area_m2(v) < 0:
            v = v[::-1]
        return v - _centroid(v)
    raise ValueError(f"unknown shape {shape.kind!r}")


def _centroid(v: np.ndarray) -> np.ndarray:
    x, y = v[:, 0], v[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a = 0.5 * cross.sum()
    if abs(a) < 1e-30:
        return v.mean(axis=0)
    cx = ((x + np.roll(x, -1)) * cross).sum() / (6 * a)
    cy = ((y + np.roll(y, -1)) * cross).sum() / (6 * a)
    return np.array([cx, cy])


__all__ = [
    "ROUND_SHAPES",
    "Baffles",
    "Mixer",
    "ParticleKind",
    "Shape",
    "ShapeKind",
    "polygon_area_m2",
    "shape_area_m2",
    "shape_outline_m",
]

"""The user's mixer as data: the drum, its baffles and the particle classes, and what the engines
take from it (counts, areas, masses, the DEM's disc classes).

This package is the one definition of the twin's mixer (issue 20); its config tables are read and
written by ``sim.mixer.config``. Everything here is data: dataclasses and pure functions, no I/O.

Counts: a class with ``count`` has that many particles in the slice; classes with ``share``
divide the bed's solid area ``fill * PACKING_2D * pi R^2`` (``sim.recipe.slice_2d``'s rule)
by their shares, ``n_k = round(share_k * A / area_k)``.

Frame: origin at the drum axis, x to the right, y up, as the camera sees the front face
(the DEM's frame, ``sim.drum``). ``direction`` +1 is counter-clockwise as seen.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from sim.errors import SimError
from sim.recipe import BLUE_BGR, MAX_FILL, PACKING_2D, PAPER_DRUM, RED_BGR, DiskClass, DrumSpec
from vision.shapes import (
    ParticleShape,
    circumscribed_diameter,
    is_simple_polygon,
    particle_shape,
    polygon_area,
    polygon_centroid,
)

ShapeKind = Literal["disc", "polygon", "pellet", "cut_disc", "notched_disc", "vertices"]
ROUND_SHAPES: tuple[str, ...] = ("disc",)


@dataclass(frozen=True)
class Shape:
    """A particle's outline in its body frame (m), centred on its centroid.

    ``diameter_m``: the circumscribed diameter (disc, polygon, cut_disc, vertices), the disc's
    diameter (notched_disc) or the length (pellet). ``sides`` for a regular polygon; ``width_m``
    and ``corner_m`` for a pellet (rounded rectangle); ``wedge_deg`` for a cut disc (a wedge cut
    to the centre); ``notch_deg`` and ``notch_depth`` for a notched disc (a V-notch of that
    opening cut from the rim, its apex ``notch_depth`` of the radius in from the rim: 1 is a cut
    disc); ``vertices_m`` (k, 2) for a simple polygon given by its vertices (counter-clockwise,
    about its centroid).
    """

    kind: ShapeKind = "disc"
    diameter_m: float = 0.010
    sides: int | None = None
    width_m: float | None = None
    corner_m: float | None = None
    wedge_deg: float | None = None
    notch_deg: float | None = None
    notch_depth: float | None = None
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
    solid area, 0..1) is set. ``thickness_m`` None: in a monolayer drum the particle's
    diameter (as thick as it is wide); in a deep drum the bed's sphere-slice slab
    ``4/3 r_max`` (the largest disc weighs what its ball weighs, as ``sim.recipe.DiskClass``).
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
class Friction:
    """The twin's friction for this rig (``[drum.friction]``; ``drumtwin commission`` writes its
    calibration here): ``sliding`` and ``rolling`` friction between particles and ``end_plates``
    (the end plates'; a monolayer's is calibrated). None: the engines' defaults (the plates: the
    wall's, Taberlet's law of a deep drum). A twin made without friction given takes these."""

    sliding: float | None = None
    rolling: float | None = None
    end_plates: float | None = None


@dataclass(frozen=True)
class Mixer:
    """The user's mixer: the drum (``DrumSpec``: diameter, depth), the bed and its rotation.

    ``fill``: share of the drum's cross-section the bed covers at random packing;
    ``direction``: +1 counter-clockwise as the camera sees it, -1 clockwise;
    ``monolayer``: a quasi-2D drum one particle thick (the end plates touch every particle);
    ``friction``: the contact friction calibrated for this rig (None: the engines' defaults).
    """

    drum: DrumSpec
    particles: tuple[ParticleKind, ...]
    fill: float = 0.5
    direction: int = 1
    monolayer: bool = False
    baffles: Baffles | None = None
    friction: Friction | None = None
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def end_friction(self) -> float | None:
        """The end plates' friction its twins start with (``friction.end_plates``; None: the wall's)."""
        return None if self.friction is None else self.friction.end_plates

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
    if shape.kind == "notched_disc":
        apex, half = notch_geometry(shape)
        return math.pi * r * r - (half * r * r - apex * r * math.sin(half))  # the disc less the notch
    if shape.kind == "pellet":
        w = float(shape.width_m or shape.diameter_m)
        c = min(float(shape.corner_m or 0.0), 0.5 * w, 0.5 * shape.diameter_m)
        return shape.diameter_m * w - (4.0 - math.pi) * c * c
    return polygon_area(shape_outline_m(shape))



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
        return pts_arr - polygon_centroid(pts_arr)
    if shape.kind == "notched_disc":
        apex, half = notch_geometry(shape)
        k = max(8, int(round(segments * (1 - half / math.pi))))
        a = np.linspace(half, 2 * math.pi - half, k)
        pts_arr = np.concatenate([[[apex, 0.0]], np.stack([r * np.cos(a), r * np.sin(a)], axis=1)])
        return pts_arr - polygon_centroid(pts_arr)
    if shape.kind == "vertices":
        v = np.asarray(shape.vertices_m, dtype=float)
        if polygon_area(v) < 0:
            v = v[::-1]
        return v - polygon_centroid(v)
    raise ValueError(f"unknown shape {shape.kind!r}")




def notch_geometry(shape: Shape) -> tuple[float, float]:
    """A notched disc's notch about the disc's centre, notch on +x: (the apex's distance from the
    centre (m), the half-angle (rad) at the centre of the rim the notch takes). The notch's walls
    are straight lines from the apex at +-``notch_deg``/2 about +x to the rim."""
    r = shape.radius_m
    apex = r * (1.0 - float(shape.notch_depth if shape.notch_depth is not None else 0.4))
    phi = math.radians(0.5 * float(shape.notch_deg if shape.notch_deg is not None else 90.0))
    t = -apex * math.cos(phi) + math.sqrt(r * r - (apex * math.sin(phi)) ** 2)  # apex + t (cos, sin) on the rim
    return apex, math.atan2(t * math.sin(phi), apex + t * math.cos(phi))


# ------------------------------------------------------------------ resolved view
@dataclass(frozen=True)
class ResolvedKind:
    """One class as the engines consume it: the particle count in the slice and its mass.

    ``area_m2``: the outline's area; ``slab_m``: the thickness its mass is computed with
    (``mass_kg = density * area * slab``); ``radius_m``: circumscribed radius (m).
    """

    name: str
    shape: Shape
    count: int
    density_kg_m3: float
    area_m2: float
    slab_m: float
    colour_bgr: tuple[int, int, int]

    @property
    def radius_m(self) -> float:
        return self.shape.radius_m

    @property
    def mass_kg(self) -> float:
        """Mass of one particle (kg)."""
        return self.density_kg_m3 * self.area_m2 * self.slab_m


def bed_area_m2(mixer: Mixer) -> float:
    """Solid area the bed covers in the slice (m^2): ``fill * PACKING_2D * pi R^2``."""
    return mixer.fill * PACKING_2D * math.pi * mixer.drum.radius_m ** 2


def resolve_counts(mixer: Mixer) -> tuple[int, ...]:
    """Particles per class in the slice: ``count`` as given, else ``round(share * bed area / area)``
    (at least one particle for a positive share)."""
    area = bed_area_m2(mixer)
    out = []
    for p in mixer.particles:
        if p.count is not None:
            out.append(int(p.count))
        else:
            n = int(round(float(p.share or 0.0) * area / shape_area_m2(p.shape)))
            out.append(max(n, 1) if (p.share or 0.0) > 0 else 0)
    return tuple(out)


def _slab_m(mixer: Mixer, p: ParticleKind) -> float:
    if p.thickness_m is not None:
        return float(p.thickness_m)
    if mixer.monolayer:
        return p.shape.diameter_m
    return 4.0 / 3.0 * max(q.shape.radius_m for q in mixer.particles)


def resolve(mixer: Mixer) -> tuple[ResolvedKind, ...]:
    """The resolved per-class view (counts, areas, slabs, masses) in the mixer's class order."""
    return tuple(
        ResolvedKind(p.name, p.shape, n, p.density_kg_m3, shape_area_m2(p.shape), _slab_m(mixer, p), p.colour_bgr)
        for p, n in zip(mixer.particles, resolve_counts(mixer), strict=True)
    )


def disk_classes(mixer: Mixer) -> tuple[DiskClass, ...]:
    """The DEM's disc classes of an all-round mixer (``sim.drum.DrumSim``'s ``classes``).

    A class whose slab is the deep drum's default (``4/3 r_max``) leaves ``DiskClass.slab_m``
    unset, so the paper's bed is the very classes ``slice_2d`` makes."""
    if not all(p.shape.is_round for p in mixer.particles):
        raise SimError("the compiled DEM holds discs only: use the pymunk engine for this mixer")
    out = []
    for p, k in zip(mixer.particles, resolve(mixer), strict=True):
        default = p.thickness_m is None and not mixer.monolayer
        out.append(DiskClass(p.name, k.radius_m, k.count, k.density_kg_m3, k.colour_bgr,
                             slab_m=None if default else k.slab_m))
    return tuple(out)


# ------------------------------------------------------------------ the paper's mixer
def paper_mixer() -> Mixer:
    """The demo's mixer: the paper's 300 x 100 mm drum, 20 mm and 10 mm polyethylene discs at equal
    shares of the bed's area (the 250 + 2000 balls' equal volumes), fill 0.5: 45 + 180 discs, the
    very counts ``sim.recipe.slice_2d`` gives (at any other fill too: the same rule)."""
    return Mixer(
        drum=PAPER_DRUM,
        particles=(
            ParticleKind("red", Shape("disc", 0.020), 931.0, share=0.5, colour_bgr=RED_BGR),
            ParticleKind("blue", Shape("disc", 0.010), 931.0, share=0.5, colour_bgr=BLUE_BGR),
        ),
        fill=0.5, direction=1, monolayer=False, baffles=None,
    )



def polygon_shape(where: str, v: np.ndarray, d_m: float) -> Shape:
    """A ``vertices`` shape from polygon ``v`` scaled so its circumscribed diameter (about
    its centroid) is ``d_m``."""
    if not is_simple_polygon(v):
        raise SimError(f"{where}: the polygon is not simple (self-crossing, or fewer than three corners)")
    if polygon_area(v) < 0:
        v = v[::-1]
    v = v - polygon_centroid(v)
    scale = d_m / (2.0 * float(np.max(np.hypot(v[:, 0], v[:, 1]))))
    v = v * scale
    return Shape("vertices", d_m, vertices_m=tuple((float(x), float(y)) for x, y in v))



def shape_from_crops(crops: Sequence[np.ndarray], diameter_m: float, mm_per_px: float,
                     where: str = "traced shape") -> tuple[Shape, str]:
    """A class's particle shape from boolean crops of its single particles in the camera's frames
    (``vision.census.single_particle_crops``), as ``vision.shapes.particle_shape`` decides it
    (``shape_from_traced``)."""
    d_px = diameter_m * 1e3 / mm_per_px if mm_per_px > 0 else math.inf
    return shape_from_traced(particle_shape(crops, d_px), diameter_m, mm_per_px, where)


def shape_from_traced(traced: ParticleShape, diameter_m: float, mm_per_px: float,
                      where: str = "traced shape") -> tuple[Shape, str]:
    """The twin's shape of a class's traced particles (``vision.shapes.ParticleShape``): a ``disc``
    of ``diameter_m`` (the census's size), a ``notched_disc`` (its circle's diameter, the notch's
    opening and depth), a ``pellet`` (long and short axis, the corner from its area), a regular
    ``polygon`` (its corners), else the median particle's outline as a ``vertices`` shape; lengths
    from the trace at ``mm_per_px``. The second item says how (a comment for the mixer)."""
    m_px = mm_per_px * 1e-3
    if traced.outline_px is None:
        return Shape("disc", diameter_m), traced.how
    v = traced.outline_px
    d_m = (traced.diameter_px if math.isfinite(traced.diameter_px) else circumscribed_diameter(v)) * m_px
    if traced.kind == "notched_disc":
        return (Shape("notched_disc", d_m, notch_deg=round(min(max(traced.notch_deg, 1.0), 179.0), 1),
                      notch_depth=round(min(max(traced.notch_depth, 0.01), 1.0), 3)),
                traced.how + f": a disc {d_m * 1e3:.3g} mm across with a notch")
    if traced.kind == "pellet":
        w_m = traced.width_px * m_px
        corner = math.sqrt(max(d_m * w_m - abs(polygon_area(v)) * m_px ** 2, 0.0) / (4.0 - math.pi))
        return (Shape("pellet", d_m, width_m=w_m, corner_m=min(corner, 0.5 * w_m)),
                traced.how + f": {d_m * 1e3:.3g} x {w_m * 1e3:.3g} mm")
    if traced.kind == "polygon":
        return Shape("polygon", d_m, sides=traced.sides), traced.how + f": {d_m * 1e3:.3g} mm across"
    d_m = circumscribed_diameter(v) * m_px
    return polygon_shape(where, v, d_m), (traced.how + f": the median particle's outline "
                                                       f"({len(v)} corners, {d_m * 1e3:.3g} mm across)")


def check_fits(mixer: Mixer, source: str = "mixer") -> None:
    """A one-line SimError if the bed cannot fit the drum: more solid area than the drum holds at
    the highest fill (``MAX_FILL`` at ``PACKING_2D``), or no particle at all."""
    counts = resolve_counts(mixer)
    if sum(counts) == 0:
        raise SimError(f"{source}: the bed has no particles")
    solid = sum(n * shape_area_m2(p.shape) for n, p in zip(counts, mixer.particles, strict=True))
    room = MAX_FILL * PACKING_2D * math.pi * mixer.drum.radius_m ** 2
    if mixer.baffles is not None:
        room -= mixer.baffles.count * mixer.baffles.height_m * mixer.baffles.thickness_m
    if solid > room:
        raise SimError(
            f"{source}: the bed does not fit the drum: {sum(counts)} particles cover {solid * 1e4:.1f} cm^2, the "
            f"{mixer.drum.diameter_m * 1e3:g} mm drum holds at most {room * 1e4:.1f} cm^2 (fill {MAX_FILL:g})")


def with_counts(mixer: Mixer, counts: Sequence[int]) -> Mixer:
    """The same mixer with every class given by its count."""
    return replace(mixer, particles=tuple(replace(p, count=int(n), share=None)
                                          for p, n in zip(mixer.particles, counts, strict=True)))




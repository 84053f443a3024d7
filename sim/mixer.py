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
    end_friction = 0.02        # optional: the end plates' friction (``sim.drum``'s law; default the wall's);
                               # a monolayer's is calibrated (``sim.calibrate``), which may write it here

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
    colour_bgr = [255, 60, 0]  # optional: the twin's render colour (default: the camera class's display colour)

Counts: a class with ``count`` has that many particles in the slice; classes with ``share``
divide the bed's solid area ``fill * PACKING_2D * pi R^2`` (``sim.recipe.slice_2d``'s rule)
by their shares, ``n_k = round(share_k * A / area_k)``. Give every class a count, or every
class a share (summing to 1).

Frame: origin at the drum axis, x to the right, y up, as the camera sees the front face
(the DEM's frame, ``sim.drum``). ``direction`` +1 is counter-clockwise as seen.

Everything here is data: dataclasses and pure functions, no I/O (``parse_mixer`` takes
the TOML's dict; a ``traced`` shape is resolved to vertices by the caller that reads the
picture).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from sim.errors import SimError, check_number
from sim.recipe import BLUE_BGR, MAX_FILL, PACKING_2D, PAPER_DRUM, RED_BGR, DiskClass, DrumSpec

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
class Mixer:
    """The user's mixer: the drum (``DrumSpec``: diameter, depth), the bed and its rotation.

    ``fill``: share of the drum's cross-section the bed covers at random packing;
    ``direction``: +1 counter-clockwise as the camera sees it, -1 clockwise;
    ``monolayer``: a quasi-2D drum one particle thick (the end plates touch every particle);
    ``end_friction``: the end plates' friction its twins start with (None: the engines' default, the wall's).
    """

    drum: DrumSpec
    particles: tuple[ParticleKind, ...]
    fill: float = 0.5
    direction: int = 1
    monolayer: bool = False
    baffles: Baffles | None = None
    notes: tuple[str, ...] = field(default=(), compare=False)
    end_friction: float | None = None

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


# ------------------------------------------------------------------ parsing
SHAPE_KINDS: tuple[str, ...] = ("disc", "sphere", "polygon", "pellet", "cut_disc", "vertices", "traced")
_DRUM_KEYS = {"diameter_mm", "depth_mm", "monolayer", "fill", "rotation", "density_kg_m3", "baffles", "end_friction"}
_BAFFLE_KEYS = {"count", "height_mm", "thickness_mm"}
_PARTICLE_KEYS = {"name", "shape", "diameter_mm", "density_kg_m3", "share", "count", "thickness_mm", "sides",
                  "width_mm", "corner_mm", "wedge_deg", "vertices_mm", "image", "colour_bgr"}
_SHAPE_KEYS = {"polygon": {"sides"}, "pellet": {"width_mm", "corner_mm"}, "cut_disc": {"wedge_deg"},
               "vertices": {"vertices_mm"}, "traced": {"image"}}
MAX_PARTICLE_SHARE_OF_DRUM = 0.25  # a particle's diameter over the drum's, at most
MAX_BAFFLES = 36


def _num(where: str, key: str, value: object, lo: float, hi: float, *, lo_open: bool = False,
         integer: bool = False) -> float:
    if isinstance(value, bool):
        value = repr(value)
    return check_number(f"{where}: {key}", value, lo, hi, lo_open=lo_open, integer=integer)


def _unknown(where: str, table: Mapping, allowed: set[str]) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SimError(f"{where}: unknown key(s) {unknown} (allowed: {sorted(allowed)})")


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
    if k < 3 or abs(polygon_area_m2(v)) <= 1e-18:
        return False
    for i in range(k):
        for j in range(i + 1, k):
            if j == i + 1 or (i == 0 and j == k - 1):
                continue
            if _segments_cross(v[i], v[(i + 1) % k], v[j], v[(j + 1) % k]):
                return False
    return True


def _bgr(where: str, value: object) -> tuple[int, int, int]:
    if not (isinstance(value, list) and len(value) == 3
            and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in value)):
        raise SimError(f"{where}: colour_bgr must be [b, g, r], three integers 0..255 (got {value!r})")
    return (int(value[0]), int(value[1]), int(value[2]))


def _parse_shape(where: str, t: Mapping, drum_d_m: float, base_dir: Path | None) -> Shape:
    kind = t.get("shape", "disc")
    if kind not in SHAPE_KINDS:
        raise SimError(f"{where}: unknown shape {kind!r} (one of {', '.join(SHAPE_KINDS)})")
    kind = "disc" if kind == "sphere" else kind
    for other, keys in _SHAPE_KEYS.items():
        stray = sorted(keys & set(t)) if other != kind else []
        if stray:
            raise SimError(f"{where}: {stray[0]} belongs to shape = {other!r}, not {kind!r}")
    if "diameter_mm" not in t:
        raise SimError(f"{where}: needs diameter_mm (the particle's size)")
    d_m = 1e-3 * _num(where, "diameter_mm", t["diameter_mm"], 0.0, 1e4, lo_open=True)
    if d_m > MAX_PARTICLE_SHARE_OF_DRUM * drum_d_m:
        raise SimError(f"{where}: diameter_mm = {d_m * 1e3:g} does not fit a {drum_d_m * 1e3:g} mm drum "
                       f"(at most {MAX_PARTICLE_SHARE_OF_DRUM:g} of its diameter)")
    if kind == "disc":
        return Shape("disc", d_m)
    if kind == "polygon":
        sides = int(_num(where, "sides", t.get("sides", 6), 3, 64, integer=True))
        return Shape("polygon", d_m, sides=sides)
    if kind == "pellet":
        w_m = 1e-3 * _num(where, "width_mm", t.get("width_mm", d_m * 1e3), 0.0, d_m * 1e3, lo_open=True)
        c_m = 1e-3 * _num(where, "corner_mm", t.get("corner_mm", 0.0), 0.0, 0.5 * w_m * 1e3)
        return Shape("pellet", d_m, width_m=w_m, corner_m=c_m)
    if kind == "cut_disc":
        wedge = _num(where, "wedge_deg", t.get("wedge_deg", 90.0), 0.0, 180.0, lo_open=True)
        return Shape("cut_disc", d_m, wedge_deg=wedge)
    if kind == "vertices":
        raw = t.get("vertices_mm")
        if not (isinstance(raw, list) and len(raw) >= 3 and all(isinstance(r, list) and len(r) == 2 for r in raw)):
            raise SimError(f"{where}: vertices_mm must be a list of at least three [x, y] pairs (got {raw!r})")
        v = np.array([[_num(where, "vertices_mm", c, -1e4, 1e4) for c in r] for r in raw]) * 1e-3
        return _polygon_shape(where, v, d_m)
    # traced: the outline of one particle in a picture
    if base_dir is None:
        raise SimError(f"{where}: shape = 'traced' needs the config's folder to find its image")
    img = t.get("image")
    if not isinstance(img, str) or not img:
        raise SimError(f"{where}: shape = 'traced' needs image = \"particle.png\"")
    path = Path(img) if Path(img).is_absolute() else Path(base_dir) / img
    return _polygon_shape(where, trace_outline(path, where), d_m)


def _polygon_shape(where: str, v: np.ndarray, d_m: float) -> Shape:
    """A ``vertices`` shape from polygon ``v`` scaled so its circumscribed diameter (about
    its centroid) is ``d_m``."""
    if not is_simple_polygon(v):
        raise SimError(f"{where}: the polygon is not simple (self-crossing, or fewer than three corners)")
    if polygon_area_m2(v) < 0:
        v = v[::-1]
    v = v - _centroid(v)
    scale = d_m / (2.0 * float(np.max(np.hypot(v[:, 0], v[:, 1]))))
    v = v * scale
    return Shape("vertices", d_m, vertices_m=tuple((float(x), float(y)) for x, y in v))


TRACE_TOLERANCE = 0.02  # simplification tolerance of a traced outline, in particle sizes


def trace_outline(path: Path, where: str = "traced shape") -> np.ndarray:
    """Outline (k, 2, px, y up, counter-clockwise) of the one particle in a picture: the
    largest dark-on-light or light-on-dark blob, traced by ``pymunk.autogeometry.march_soft``
    and simplified to a polygon (``TRACE_TOLERANCE`` of its size)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise SimError(f"{where}: cannot read the image {path}")
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
        raise SimError(f"{where}: no particle found in {what}")
    best = max(lines, key=lambda ln: abs(polygon_area_m2(np.array([[p.x, p.y] for p in ln]))))
    size = max(h, w)
    simple = ag.simplify_curves(best, TRACE_TOLERANCE * size)
    v = np.array([[p.x, -p.y] for p in simple], dtype=float)  # image y down -> y up
    if len(v) > 1 and np.allclose(v[0], v[-1]):
        v = v[:-1]
    if len(v) < 3:
        raise SimError(f"{where}: the outline traced from {what} has fewer than three corners")
    return v


ROUND_FILL = 0.75  # a particle covering this much of its enclosing circle (``mask_fill``) and
ROUND_SOLIDITY = 0.92  # this much of its traced outline's convex hull is a disc (the real PMMA discs of
# tests/data: 0.81, 0.96 at 22 px; a 90-degree cut disc of that size: 0.65, 0.90)
SHAPE_MIN_PX = 16.0  # particles fewer pixels across than this show no shape (the PMMA discs at 11.5 px read 0.72-0.76)


def outline_roundness(v: np.ndarray) -> tuple[float, float]:
    """(fill, solidity) of a polygon (k, 2): its area over its circumscribed circle's (about its
    centroid; a disc ~1, a 90-degree cut disc 0.75, a hexagon 0.83) and over its convex hull's
    (a disc or any convex shape 1, a 90-degree cut disc 0.82)."""
    import cv2

    v = np.asarray(v, dtype=float)
    area = abs(polygon_area_m2(v))
    c = _centroid(v if polygon_area_m2(v) > 0 else v[::-1])
    r = float(np.max(np.hypot(v[:, 0] - c[0], v[:, 1] - c[1])))
    hull = cv2.convexHull(v.astype(np.float32)).reshape(-1, 2).astype(float)
    hull_area = abs(polygon_area_m2(hull))
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


def shape_from_crops(crops: Sequence[np.ndarray], diameter_m: float, mm_per_px: float,
                     where: str = "traced shape") -> tuple[Shape, str]:
    """A class's particle shape from boolean crops of its single particles in the camera's frames
    (``vision.census.single_particle_crops``): each traced (``trace_particle``); round
    (``Shape("disc", diameter_m)``) when the median particle covers ``ROUND_FILL`` of its
    enclosing circle (``mask_fill``) and its outline ``ROUND_SOLIDITY`` of its convex hull, else the median particle's
    outline as a ``vertices`` shape (its circumscribed diameter from the trace, ``mm_per_px``).
    Particles under ``SHAPE_MIN_PX`` across (``diameter_m`` at ``mm_per_px``) are round: too few
    pixels to tell. The second item says how (a comment for the written mixer)."""
    d_px = diameter_m * 1e3 / mm_per_px if mm_per_px > 0 else math.inf
    if d_px < SHAPE_MIN_PX:
        return Shape("disc", diameter_m), (f"round assumed: particles {d_px:.0f} px across are too few pixels to show "
                                           f"a shape (fewer than {SHAPE_MIN_PX:g}); edit for other shapes")
    traced = []
    for c in crops:
        try:
            v = trace_particle(np.asarray(c, dtype=float), where)
        except SimError:
            continue
        if is_simple_polygon(v):
            traced.append(((mask_fill(c), outline_roundness(v)[1]), v))
    if not traced:
        return Shape("disc", diameter_m), "round assumed (no single particle to trace); edit for other shapes"
    fills = np.array([t[0][0] for t in traced])
    solid = np.array([t[0][1] for t in traced])
    fill, sol = float(np.median(fills)), float(np.median(solid))
    how = (f"traced from {len(traced)} single particles in the frames: median {fill:.2f} of the enclosing "
           f"circle, {sol:.2f} of the convex hull")
    if fill >= ROUND_FILL and sol >= ROUND_SOLIDITY:
        return Shape("disc", diameter_m), how + f" (>= {ROUND_FILL:g}, {ROUND_SOLIDITY:g}: round)"
    _, v = traced[int(np.argsort(fills, kind="stable")[len(fills) // 2])]
    c = _centroid(v if polygon_area_m2(v) > 0 else v[::-1])
    d_m = 2.0 * float(np.max(np.hypot(v[:, 0] - c[0], v[:, 1] - c[1]))) * mm_per_px * 1e-3
    shape = _polygon_shape(where, v, d_m)
    return shape, how + f": not round, the median particle's outline ({len(v)} corners, {d_m * 1e3:.3g} mm across)"


def parse_mixer(
    table: Mapping,
    class_names: Sequence[str] | None = None,
    *,
    base_dir: str | Path | None = None,
    colours: Mapping[str, tuple[int, int, int]] | None = None,
    source: str = "config",
) -> Mixer:
    """The mixer from a config's ``[drum]`` and ``[[particles]]`` tables (see the module doc).

    ``class_names``: the camera's counted colour classes; every particle class must be one of
    them and each of them needs a particle class (the result is in the camera's order).
    ``colours``: display colours by class name (the render colour unless ``colour_bgr`` is given).
    Every number is checked; a bad one is a one-line ``SimError`` naming the key.
    """
    drum_t = table.get("drum")
    parts = table.get("particles")
    if not isinstance(drum_t, Mapping):
        raise SimError(f"{source}: a mixer needs a [drum] table")
    if not (isinstance(parts, list) and parts and all(isinstance(p, Mapping) for p in parts)):
        raise SimError(f"{source}: a mixer needs [[particles]] tables, one per colour class")
    w = f"{source} [drum]"
    _unknown(w, drum_t, _DRUM_KEYS)
    if "diameter_mm" not in drum_t:
        raise SimError(f"{w}: needs diameter_mm (the drum's inner diameter)")
    d_m = 1e-3 * _num(w, "diameter_mm", drum_t["diameter_mm"], 10.0, 1e4)
    monolayer = drum_t.get("monolayer", False)
    if not isinstance(monolayer, bool):
        raise SimError(f"{w}: monolayer must be true or false (got {monolayer!r})")
    if monolayer and "depth_mm" in drum_t:
        raise SimError(f"{w}: give depth_mm or monolayer = true, not both (a monolayer drum is one particle deep)")
    if not monolayer and "depth_mm" not in drum_t:
        raise SimError(f"{w}: needs depth_mm (the end plates' distance) or monolayer = true")
    fill = _num(w, "fill", drum_t.get("fill", 0.5), 0.0, MAX_FILL, lo_open=True)
    rotation = drum_t.get("rotation", "ccw")
    if rotation not in ("ccw", "cw"):
        raise SimError(f"{w}: rotation must be \"ccw\" or \"cw\" as the camera sees it (got {rotation!r})")
    rho_drum = _num(w, "density_kg_m3", drum_t.get("density_kg_m3", 1180.0), 0.0, 1e5, lo_open=True)
    end_f = _num(w, "end_friction", drum_t["end_friction"], 0.0, 5.0) if "end_friction" in drum_t else None
    baffles = None
    if "baffles" in drum_t:
        bt = drum_t["baffles"]
        wb = f"{source} [drum.baffles]"
        if not isinstance(bt, Mapping):
            raise SimError(f"{wb}: must be a table")
        _unknown(wb, bt, _BAFFLE_KEYS)
        for key in ("count", "height_mm", "thickness_mm"):
            if key not in bt:
                raise SimError(f"{wb}: needs {key}")
        count = int(_num(wb, "count", bt["count"], 1, MAX_BAFFLES, integer=True))
        height = 1e-3 * _num(wb, "height_mm", bt["height_mm"], 0.0, 1e4, lo_open=True)
        thick = 1e-3 * _num(wb, "thickness_mm", bt["thickness_mm"], 0.0, 1e4, lo_open=True)
        if height >= 0.5 * d_m:
            raise SimError(f"{wb}: height_mm = {height * 1e3:g} is longer than the drum's radius "
                           f"({0.5 * d_m * 1e3:g} mm)")
        if count * thick >= math.pi * d_m:
            raise SimError(f"{wb}: {count} baffles of {thick * 1e3:g} mm do not fit on the wall")
        baffles = Baffles(count, height, thick)
    names = None if class_names is None else list(class_names)
    kinds: list[ParticleKind] = []
    for i, t in enumerate(parts):
        name = t.get("name")
        wp = f"{source} [[particles]] {name!r}" if isinstance(name, str) else f"{source} particles[{i}]"
        _unknown(wp, t, _PARTICLE_KEYS)
        if not isinstance(name, str) or not name:
            raise SimError(f"{wp}: needs name = \"...\" (the camera's colour class)")
        if any(k.name == name for k in kinds):
            raise SimError(f"{wp}: the class is described twice")
        if names is not None and name not in names:
            raise SimError(f"{wp}: the camera has no colour class {name!r} (its classes: {', '.join(names)})")
        shape = _parse_shape(wp, t, d_m, None if base_dir is None else Path(base_dir))
        rho = _num(wp, "density_kg_m3", t.get("density_kg_m3", 1190.0), 0.0, 1e5, lo_open=True)
        if ("count" in t) == ("share" in t):
            raise SimError(f"{wp}: give either count or share (got {'both' if 'count' in t else 'neither'})")
        count_v = int(_num(wp, "count", t["count"], 1, 1e6, integer=True)) if "count" in t else None
        share_v = _num(wp, "share", t["share"], 0.0, 1.0, lo_open=True) if "share" in t else None
        thick_v = (1e-3 * _num(wp, "thickness_mm", t["thickness_mm"], 0.0, 1e4, lo_open=True)
                   if "thickness_mm" in t else None)
        if "colour_bgr" in t:
            bgr = _bgr(wp, t["colour_bgr"])
        elif colours is not None and name in colours:
            bgr = tuple(int(c) for c in colours[name])  # type: ignore[assignment]
        else:
            bgr = (RED_BGR, BLUE_BGR)[i % 2]
        kinds.append(ParticleKind(name, shape, rho, count=count_v, share=share_v, thickness_m=thick_v,
                                  colour_bgr=bgr))
    if names is not None:
        missing = [n for n in names if n not in {k.name for k in kinds}]
        if missing:
            raise SimError(f"{source}: no [[particles]] table for the camera's class {missing[0]!r}")
        kinds.sort(key=lambda k: names.index(k.name))
    by_share = [k.share is not None for k in kinds]
    if any(by_share) and not all(by_share):
        raise SimError(f"{source} [[particles]]: give every class a count or every class a share, not a mix")
    if all(by_share):
        total = sum(float(k.share or 0.0) for k in kinds)
        if abs(total - 1.0) > 0.01:
            raise SimError(f"{source} [[particles]]: the shares add up to {total:g}, not 1")
    thickest = max(k.thickness_m if k.thickness_m is not None else k.shape.diameter_m for k in kinds)
    depth = thickest if monolayer else 1e-3 * _num(w, "depth_mm", drum_t["depth_mm"], 0.0, 1e4, lo_open=True)
    if depth < thickest * (1.0 - 1e-9):
        raise SimError(f"{w}: depth_mm = {depth * 1e3:g} is thinner than the particles ({thickest * 1e3:g} mm; "
                       "give their thickness_mm)")
    mixer = Mixer(DrumSpec(d_m, depth, rho_drum), tuple(kinds), fill=fill, direction=1 if rotation == "ccw" else -1,
                  monolayer=monolayer, baffles=baffles, end_friction=end_f)
    check_fits(mixer, source)
    return mixer


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


def mixer_from_config(cfg: Any, *, default: Mixer | None = None) -> Mixer | None:
    """The mixer a vision ``MeterConfig`` carries (its ``[drum]``/``[[particles]]`` tables, named as
    its counted colour classes and drawn in their display colours), else ``default``."""
    tables = getattr(cfg, "mixer_tables", None) or {}
    if not tables:
        return default
    source = str(getattr(cfg, "source", "config"))
    base = Path(source).parent if source and not source.startswith("<") else Path.cwd()
    counted = tuple(getattr(cfg, "counted", ()))
    return parse_mixer(tables, [c.name for c in counted], base_dir=base,
                       colours={c.name: tuple(c.display_bgr) for c in counted}, source=f"config {source}")


# ------------------------------------------------------------------ writing
def _f(v: float) -> str:
    return format(float(v), ".4g")


def mixer_to_toml(mixer: Mixer, notes: Mapping[str, str] | None = None) -> str:
    """The ``[drum]`` and ``[[particles]]`` tables of ``mixer`` as TOML text (``parse_mixer``
    reads it back). ``notes``: a comment per key, ``"drum.fill"`` or ``"particles.blue.share"``
    (where the number came from)."""
    notes = notes or {}

    def line(key: str, value: str, where: str) -> str:
        note = notes.get(f"{where}.{key}")
        return f"{key} = {value}" + (f"  # {note}" if note else "")

    out = ["[drum]", line("diameter_mm", _f(mixer.drum.diameter_m * 1e3), "drum")]
    if mixer.monolayer:
        out.append(line("monolayer", "true", "drum"))
    else:
        out.append(line("depth_mm", _f(mixer.drum.depth_m * 1e3), "drum"))
    out.append(line("fill", _f(mixer.fill), "drum"))
    out.append(line("rotation", '"ccw"' if mixer.direction > 0 else '"cw"', "drum"))
    out.append(line("density_kg_m3", _f(mixer.drum.density_kg_m3), "drum"))
    if mixer.end_friction is not None:
        out.append(line("end_friction", _f(mixer.end_friction), "drum"))
    if mixer.baffles is not None:
        b = mixer.baffles
        out += ["", "[drum.baffles]", line("count", str(b.count), "drum.baffles"),
                line("height_mm", _f(b.height_m * 1e3), "drum.baffles"),
                line("thickness_mm", _f(b.thickness_m * 1e3), "drum.baffles")]
    for p in mixer.particles:
        w = f"particles.{p.name}"
        s = p.shape
        out += ["", "[[particles]]", line("name", f'"{p.name}"', w), line("shape", f'"{s.kind}"', w),
                line("diameter_mm", _f(s.diameter_m * 1e3), w)]
        if s.kind == "polygon":
            out.append(line("sides", str(s.sides), w))
        elif s.kind == "pellet":
            out += [line("width_mm", _f(float(s.width_m or s.diameter_m) * 1e3), w),
                    line("corner_mm", _f(float(s.corner_m or 0.0) * 1e3), w)]
        elif s.kind == "cut_disc":
            out.append(line("wedge_deg", _f(float(s.wedge_deg or 90.0)), w))
        elif s.kind == "vertices":
            pts = ", ".join(f"[{_f(x * 1e3)}, {_f(y * 1e3)}]" for x, y in (s.vertices_m or ()))
            out.append(line("vertices_mm", f"[{pts}]", w))
        out.append(line("density_kg_m3", _f(p.density_kg_m3), w))
        if p.count is not None:
            out.append(line("count", str(p.count), w))
        else:
            out.append(line("share", _f(float(p.share or 0.0)), w))
        if p.thickness_m is not None:
            out.append(line("thickness_mm", _f(p.thickness_m * 1e3), w))
    return "\n".join(out) + "\n"


__all__ = [
    "ROUND_FILL",
    "ROUND_SHAPES",
    "ROUND_SOLIDITY",
    "SHAPE_KINDS",
    "SHAPE_MIN_PX",
    "Baffles",
    "Mixer",
    "ParticleKind",
    "ResolvedKind",
    "Shape",
    "ShapeKind",
    "bed_area_m2",
    "check_fits",
    "disk_classes",
    "is_simple_polygon",
    "mask_fill",
    "mixer_from_config",
    "mixer_to_toml",
    "outline_roundness",
    "paper_mixer",
    "parse_mixer",
    "polygon_area_m2",
    "resolve",
    "resolve_counts",
    "shape_area_m2",
    "shape_from_crops",
    "shape_outline_m",
    "trace_outline",
    "trace_particle",
    "with_counts",
]

"""Drum geometry, the 3D particle recipe, and its 2D slice (equal volume fraction + fill level).

The 2D twin cannot hold the 3D experiment's particle counts: a slice of the drum
holds disks. The rule used here (:func:`slice_2d`):

1. **Equal volume fraction.** Each class keeps its share of the solid volume of
   the 3D recipe: ``phi_k = n_k * d_k**3 / sum_j n_j * d_j**3``. The paper's
   250 red 20 mm + 2000 blue 10 mm balls hold equal volumes (phi = 0.5 each).
2. **Fill level.** The bed fills a fraction ``fill`` of the drum's cross-section
   (the paper's "filling degree" 0.5). At the 2D random packing fraction of a
   bidisperse disk bed (``PACKING_2D = 0.80``) the disks cover
   ``A = fill * PACKING_2D * pi * R**2``.
3. **Counts.** Class k gets ``n_k = round(phi_k * A / (pi * r_k**2))`` disks of the
   same diameter as the balls.

For the paper (R = 0.15 m, fill 0.5) this gives 45 disks of 20 mm and 180 of
10 mm (each class 0.0141 m^2). Cross-check with the 3D recipe: its solid volume
(2.09e-3 m^3) at a 3D random packing of 0.60 fills 0.49 of the 7.07e-3 m^3 drum,
i.e. the paper's filling degree of 0.5 is the recipe's own fill level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from sim.errors import SimError

G_M_S2 = 9.81
PACKING_2D = 0.80  # random packing fraction of a bidisperse disk bed
PACKING_3D = 0.60  # random packing fraction of spheres
MAX_FILL = 0.85  # above this the bed touches the top of the drum and cannot flow


@dataclass(frozen=True)
class ParticleSpec:
    """One particle class of the 3D experiment (diameter in m, density in kg/m^3, colour BGR)."""

    name: str
    diameter_m: float
    count: int
    density_kg_m3: float = 931.0  # polyethylene, paper table 1
    colour_bgr: tuple[int, int, int] = (0, 0, 220)


@dataclass(frozen=True)
class Recipe:
    """The 3D experiment: particle classes and the drum's filling degree (0..1)."""

    particles: tuple[ParticleSpec, ...]
    fill: float = 0.5


@dataclass(frozen=True)
class DrumSpec:
    """Drum geometry: diameter and depth in m (paper: 300 x 100 mm acrylic)."""

    diameter_m: float = 0.300
    depth_m: float = 0.100
    density_kg_m3: float = 1180.0  # acrylic, paper table 1

    @property
    def radius_m(self) -> float:
        return self.diameter_m / 2.0

    @property
    def critical_rpm(self) -> float:
        """Critical (centrifuging) speed ``n_c = 42.3 / sqrt(D_m)`` rpm (77.2 rpm for 0.3 m)."""
        return 42.3 / math.sqrt(self.diameter_m)


@dataclass(frozen=True)
class DiskClass:
    """One class of disks in the 2D slice (radius in m, sphere mass in kg)."""

    name: str
    radius_m: float
    count: int
    density_kg_m3: float
    colour_bgr: tuple[int, int, int]
    slab_m: float | None = None  # the disc's own thickness (m); None: the bed's slab ``mass_kg`` is given

    def mass_kg(self, slab_m: float) -> float:
        """Mass of the disk as a slab of thickness ``slab_m`` (its own ``self.slab_m`` if set):
        ``rho * pi r^2 * slab_m``.

        Every disk of a given density has the same mass per unit area, so the 2D slice
        has no hidden density contrast between sizes (3D ball masses would make the
        large disks twice as dense per area and sink them into the core, turning
        size segregation around). The twin uses ``slab_m = 4/3 r_max`` so the largest
        disk weighs what its ball weighs.
        """
        return self.density_kg_m3 * math.pi * self.radius_m**2 * (slab_m if self.slab_m is None else self.slab_m)


RED_BGR = (0, 0, 220)
BLUE_BGR = (220, 60, 0)

PAPER_RECIPE = Recipe(
    particles=(
        ParticleSpec("red", 0.020, 250, 931.0, RED_BGR),
        ParticleSpec("blue", 0.010, 2000, 931.0, BLUE_BGR),
    ),
    fill=0.5,
)
PAPER_DRUM = DrumSpec()


def _check_recipe(recipe: Recipe, drum: DrumSpec) -> None:
    if drum.diameter_m <= 0 or drum.depth_m <= 0 or not math.isfinite(drum.diameter_m):
        raise SimError(f"drum size must be positive (got D={drum.diameter_m} m, depth={drum.depth_m} m)")
    if not recipe.particles:
        raise SimError("recipe has no particle classes")
    if not 0.0 < recipe.fill <= MAX_FILL:
        raise SimError(f"fill level {recipe.fill:g} is impossible: it must be in (0, {MAX_FILL}]")
    for p in recipe.particles:
        if p.count < 0 or p.diameter_m <= 0 or p.density_kg_m3 <= 0:
            raise SimError(f"particle class {p.name!r}: count, diameter and density must be positive")
        if p.diameter_m > 0.25 * drum.diameter_m:
            raise SimError(
                f"particle class {p.name!r}: {p.diameter_m * 1e3:g} mm balls do not fit a "
                f"{drum.diameter_m * 1e3:g} mm drum (max a quarter of the diameter)"
            )
    if sum(p.count for p in recipe.particles) == 0:
        raise SimError("recipe has no particles")
    solid_m3 = sum(p.count * math.pi / 6.0 * p.diameter_m**3 for p in recipe.particles)
    drum_m3 = math.pi * drum.radius_m**2 * drum.depth_m
    if solid_m3 > PACKING_3D * drum_m3:
        raise SimError(
            f"recipe does not fit: {solid_m3 * 1e3:.2f} L of balls in a {drum_m3 * 1e3:.2f} L drum "
            f"(at most {PACKING_3D * drum_m3 * 1e3:.2f} L at random packing)"
        )


def slice_2d(recipe: Recipe, drum: DrumSpec) -> list[DiskClass]:
    """The 2D disk classes of a 3D recipe by equal volume fraction and fill level (see module doc)."""
    _check_recipe(recipe, drum)
    vols = [p.count * p.diameter_m**3 for p in recipe.particles]
    total = sum(vols)
    area_m2 = recipe.fill * PACKING_2D * math.pi * drum.radius_m**2
    out = []
    for p, v in zip(recipe.particles, vols, strict=False):
        r = p.diameter_m / 2.0
        n = int(round(v / total * area_m2 / (math.pi * r * r))) if total > 0 else 0
        if p.count > 0 and n == 0:
            n = 1
        b, g, rr = (int(c) for c in p.colour_bgr)
        out.append(DiskClass(p.name, r, n, p.density_kg_m3, (b, g, rr)))
    return out


def recipe_fill_3d(recipe: Recipe, drum: DrumSpec) -> float:
    """Filling degree implied by the 3D recipe itself: solid volume / (PACKING_3D * drum volume)."""
    solid_m3 = sum(p.count * math.pi / 6.0 * p.diameter_m**3 for p in recipe.particles)
    return solid_m3 / (PACKING_3D * math.pi * drum.radius_m**2 * drum.depth_m)


def with_fill(recipe: Recipe, fill: float) -> Recipe:
    """The same recipe at another filling degree."""
    return replace(recipe, fill=float(fill))


__all__ = [
    "BLUE_BGR",
    "G_M_S2",
    "PACKING_2D",
    "PAPER_DRUM",
    "PAPER_RECIPE",
    "RED_BGR",
    "DiskClass",
    "DrumSpec",
    "ParticleSpec",
    "Recipe",
    "recipe_fill_3d",
    "slice_2d",
    "with_fill",
]

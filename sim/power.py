"""Drive torque, power and energy of the drum from the twin, scaled from the 2D slice to the drum.

The twin measures the torque the bed puts on the drum about its axis (``Twin.drum_torque_nm``:
N m on the 2D slice as simulated, positive in the drum's positive-rpm sense, so negative while
the drum lifts the bed). The drive supplies the opposite torque; its power is
``P = -tau * omega`` (W; ``omega`` in rad/s, the drum's actual speed).

**Slice to drum** (``depth_scale``): the slice's disks weigh ``rho * A * slab`` (``sim.drum``:
a slab ``4/3 r_max`` thick; a monolayer's own thickness) and cover ``PACKING_2D`` of the bed's
cross-section; the real drum holds that cross-section over its whole depth ``W`` at the 3D
packing ``PACKING_3D``. Torque is weight x lever arm and the lever arms (the bed's shape in the
cross-section) are the slice's, so the drum's torque is the slice's times the mass ratio
``sum(rho A) * W * PACKING_3D / PACKING_2D / sum(rho A slab)``: 5.6 for the paper's 300 x 100 mm
drum (its 250 + 2000 balls weigh 5.55 times the 225 discs). A monolayer drum is its slice: 1.
This assumes a bed uniform along the axis and leaves out the end plates' extra drag of a deep
bed, which the slice has only in proportion to its depth.

**Hand check** (``rigid_bed_torque_nm``): a bed held rigid with its free surface at the angle
``beta`` is a circular segment of the drum's cross-section (its share of it: the fill) turned
by ``beta``; the torque on the drum is its weight times the lever arm of its centroid,
``M g d sin(beta)`` with ``d = 4 R sin^3(theta/2) / (3 (theta - sin theta))`` the centroid's
distance from the axis (``theta``: the segment's central angle). ``gravity_torque_nm`` is the
same moment for the particles as they lie.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sim.mixer import resolve
from sim.params import rpm_to_rad_s
from sim.recipe import G_M_S2, PACKING_2D, PACKING_3D
from sim.twin_base import Particles

__all__ = [
    "class_masses_kg",
    "depth_scale",
    "drive_power_w",
    "gravity_torque_nm",
    "rigid_bed_torque_nm",
    "segment_angle_rad",
    "segment_centroid_m",
]


def class_masses_kg(sim: Any) -> tuple[np.ndarray, np.ndarray, bool]:
    """Per class of the twin ``sim``: mass of one particle in the slice (kg), ``rho * area`` of one
    particle (kg/m, its mass per unit thickness) and whether the drum is a monolayer."""
    classes = getattr(sim, "classes", None)
    if classes is not None:  # the compiled DEM: its disk classes (``sim.drum``)
        from sim.drum import _slab_m

        slab = _slab_m(classes)
        mass = np.array([c.mass_kg(slab) for c in classes])
        per_m = np.array([c.density_kg_m3 * math.pi * c.radius_m**2 for c in classes])
    else:
        kinds = resolve(sim.mixer)
        mass = np.array([k.mass_kg for k in kinds])
        per_m = np.array([k.density_kg_m3 * k.area_m2 for k in kinds])
    mono = bool(sim.mixer is not None and sim.mixer.monolayer)
    return mass, per_m, mono


def depth_scale(sim: Any) -> float:
    """Factor from the slice's torque (or power) to the drum's (module doc): 1 for a monolayer."""
    mass, per_m, mono = class_masses_kg(sim)
    if mono:
        return 1.0
    counts = np.bincount(np.asarray(sim.particles().cls, dtype=np.int64), minlength=mass.size)
    m2d = float(np.dot(counts, mass))
    m3d = float(np.dot(counts, per_m)) * sim.drum.depth_m * PACKING_3D / PACKING_2D
    return m3d / m2d if m2d > 0 else math.nan


def drive_power_w(bed_torque_nm: float | np.ndarray, rpm: float | np.ndarray) -> Any:
    """Power the drive supplies (W): ``-tau * omega`` for the bed's torque on the drum ``tau`` (N m,
    positive in the positive-rpm sense) at ``rpm``."""
    return -np.asarray(bed_torque_nm, float) * rpm_to_rad_s(1.0) * np.asarray(rpm, float)


def gravity_torque_nm(particles: Particles, masses_kg: np.ndarray, direction: int = 1) -> float:
    """Moment about the axis that the particles' weight, carried by the drum, puts on it (N m, positive
    in the positive-rpm sense of a drum that turns ``direction`` +1 counter-clockwise): ``-g sum m x``
    counter-clockwise. ``masses_kg``: per particle."""
    return float(direction * -G_M_S2 * np.dot(np.asarray(masses_kg, float), particles.x_m))


def segment_angle_rad(fill: float) -> float:
    """Central angle ``theta`` (rad) of the circular segment that covers ``fill`` of a circle:
    ``(theta - sin theta) / (2 pi) = fill``, by bisection."""
    lo, hi = 0.0, 2.0 * math.pi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if (mid - math.sin(mid)) / (2.0 * math.pi) < fill:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def segment_centroid_m(fill: float, radius_m: float) -> float:
    """Distance (m) from the axis of the centroid of the segment covering ``fill`` of the circle."""
    th = segment_angle_rad(fill)
    return 4.0 * radius_m * math.sin(0.5 * th) ** 3 / (3.0 * (th - math.sin(th)))


def rigid_bed_torque_nm(mass_kg: float, fill: float, radius_m: float, slope_deg: float) -> float:
    """Hand calculation (module doc): the torque (N m) a rigid bed of ``mass_kg`` covering ``fill`` of
    the cross-section, its surface held at ``slope_deg``, puts on the drum against its rotation
    (a positive number for a positive slope): ``M g d sin(beta)``."""
    return float(mass_kg * G_M_S2 * segment_centroid_m(fill, radius_m) * math.sin(math.radians(slope_deg)))

"""The one probe of the twin: advance it on a time grid and sample it (issue 25 item 5).

``probe(sim, duration_s, sample_s)`` yields a :class:`Sample` at the start (optionally) and after
every slice ``duration_s / n`` (``n = round(duration_s / sample_s)``): what-if studies
(``sim.whatif``), calibration (``sim.calibrate``), validation (``sim.validation``) and the CLI's
``drumtwin sim`` all reduce these samples instead of writing the loop themselves. A sample's
measurements are computed when first read (MI and the free surface are the costly ones), from
the one set of particle-level meters (``sim.measure``).

Units: s, rpm, N m (the bed's torque on the drum, 2D slice as simulated: ``Twin.drum_torque_nm``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from sim.errors import SimError
from sim.measure import FreeSurface, free_surface, particle_mi
from sim.recipe import DrumSpec
from sim.twin_base import Particles
from vision.mixing import MixingIndices

__all__ = ["Sample", "probe"]


@dataclass
class Sample:
    """The twin at one instant of a probe: ``t_s`` since the probe started (after any spin-up), the
    particles, the drum's actual speed (rpm), the airborne fraction of the last step, and the bed's
    mean torque on the drum over the slice that ended here (N m, NaN for the start sample)."""

    t_s: float
    particles: Particles
    drum: DrumSpec
    rpm_actual: float
    airborne: float
    bed_torque_nm: float
    sim_t_s: float = math.nan  # the twin's own clock (s)

    @cached_property
    def mi(self) -> MixingIndices:
        """Particle-level mixing indices (``sim.measure.particle_mi``)."""
        return particle_mi(self.particles, self.drum)

    @cached_property
    def surface(self) -> FreeSurface:
        """The bed's free surface (``sim.measure.free_surface``)."""
        return free_surface(self.particles, self.drum)


def _sample(sim: Any, t0_s: float, torque: float) -> Sample:
    return Sample(t_s=sim.t_s - t0_s, particles=sim.particles(), drum=sim.drum, rpm_actual=float(sim.rpm_actual),
                  airborne=float(sim.stats().airborne), bed_torque_nm=torque, sim_t_s=float(sim.t_s))


def probe(sim: Any, duration_s: float, sample_s: float, *, spin_up_s: float = 0.0,
          include_start: bool = True) -> Iterator[Sample]:
    """Advance ``sim`` (a ``sim.engine.Twin``) by ``duration_s`` in ``n = max(1, round(duration_s /
    sample_s))`` equal slices, yielding a :class:`Sample` after each (and one before the first when
    ``include_start``). ``spin_up_s`` > 0 first runs the twin that long unsampled, then starts its
    contact statistics afresh (``reset_stats``). Bad durations: SimError."""
    if not (duration_s > 0) or not math.isfinite(duration_s):
        raise SimError(f"probe duration must be > 0 s (got {duration_s})")
    if not (sample_s > 0) or not math.isfinite(sample_s):
        raise SimError(f"sample interval must be > 0 s (got {sample_s})")
    if spin_up_s < 0 or not math.isfinite(spin_up_s):
        raise SimError(f"spin-up must be >= 0 s (got {spin_up_s})")
    if spin_up_s > 0:
        sim.advance(spin_up_s)
        sim.reset_stats()
    sim.drum_torque_nm()  # the torque means start here
    t0 = float(sim.t_s)
    if include_start:
        yield _sample(sim, t0, math.nan)
    n = max(1, int(round(duration_s / sample_s)))
    for _ in range(n):
        sim.advance(duration_s / n)
        yield _sample(sim, t0, float(sim.drum_torque_nm()))

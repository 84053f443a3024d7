"""How many particles a twin may hold, and the one check that a mixer can become a twin.

Every command that reads a mixer (``twin.config.load_checked_config``) asks ``check_twin``
before it builds anything, so a config either runs or is refused at once, in one line that
names the bound and the count.

- ``LIVE_MAX_PARTICLES``, the live twin of ``drumtwin run``: it must keep up with the camera on
  one core beside the meter, the supervisor and the dashboard. The DEM runs the 16x paper bed
  (3600 discs of 10 and 20 mm at its 0.283 ms step) at 1.25x real time on one core here, 3600
  discs of 8.8 mm (the PMMA rig's, 0.229 ms) at 1.37x, 8100 paper discs at 0.42x
  (``drumtwin bench twin``; docs/validation.md, "How many particles"). Lighter discs have a
  shorter step and cost more per particle; a pymunk bed costs about ten times a DEM bed per
  particle: both fall behind the camera below the bound (the twin then skips ahead: a
  ``twin_lag`` event), so the bound is the DEM's best case, not a promise of real time.
- ``MAX_PARTICLES``, every other twin (``sim``, ``whatif``, ``calibrate``): offline a twin may
  run slower than real time, but it is placed and settled (one simulated second) before its
  first frame: 20,000 discs of 8.8 mm take about 16 s on one core here and then run at 0.15x
  real time (a 60 s ``sim`` in about 7 minutes); 200,000 would take minutes before the first.
"""

from __future__ import annotations

from sim.drum import default_dt_s
from sim.engine import engine_for
from sim.errors import SimError
from sim.mixer import Mixer, check_fits, disk_classes, resolve_counts
from sim.params import SimParams, check_params

LIVE_MAX_PARTICLES = 3600  # the live twin (``drumtwin run``): what the DEM runs in real time on one core here
MAX_PARTICLES = 20_000  # any other twin (sim, whatif, calibrate): built and settled in seconds, not minutes


def twin_particles(mixer: Mixer) -> int:
    """Particles in the twin of ``mixer`` (the slice's, every class)."""
    return int(sum(resolve_counts(mixer)))


def check_twin(mixer: Mixer, engine: str | None = None, *, live: bool = False, source: str = "mixer") -> str:
    """The engine that runs ``mixer`` (``sim.engine.engine_for``) once a twin of it can be built:
    the bed fits the drum (``check_fits``), it holds at most ``MAX_PARTICLES`` (and, ``live``: the
    live twin, ``LIVE_MAX_PARTICLES``), and on the DEM its discs' default step is one the DEM runs.
    Else a one-line ``SimError`` starting with ``source``."""
    name = engine_for(mixer, engine)
    check_fits(mixer, source)
    n = twin_particles(mixer)
    for bound, what, why in ((MAX_PARTICLES, "a twin", "beyond, it takes minutes to build"),
                             (LIVE_MAX_PARTICLES if live else MAX_PARTICLES, "a live twin",
                              "what the DEM runs in real time on one core")):
        if n > bound:
            raise SimError(f"{source}: the twin would hold {n} particles; {what} holds at most {bound} ({why}; "
                           "sim.capacity)")
    if name == "dem":
        classes = disk_classes(mixer)
        try:
            check_params(SimParams(dt_s=default_dt_s(classes)))
        except SimError as exc:
            lightest = min(classes, key=lambda c: c.radius_m)
            raise SimError(f"{source}: the DEM cannot step discs this light (the smallest "
                           f"{2e3 * lightest.radius_m:g} mm across): {exc}") from None
    return name


__all__ = ["LIVE_MAX_PARTICLES", "MAX_PARTICLES", "check_twin", "twin_particles"]

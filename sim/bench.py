"""Twin benchmark (``drumtwin bench twin``): real-time factors of both engines and the cost of placing a bed.

The DEM's paper bed at 5 and 30 rpm and 4x and 16x the particles at 5 rpm; the pymunk engine's
paper bed and the cut-disc rig (configs/pmma-cutdisc.toml), each at its default step. The 4x/16x
beds keep the particles and fill level and grow the drum (diameter and depth x2, x4: the paper's
drum scaled, its end plates as far apart relative to its size), so the particle count grows at
the same time step and contact physics. Timed by this process's CPU time (a shared machine's other
jobs do not count), the best of three equal chunks. Placement (``sim.placement.place_random``) of
``PLACEMENT_BEDS`` discs of 8.8 mm at fill 0.5 is timed beside them (wall clock, one call each).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from sim.drum import DEFAULT_DT_S, DrumSim
from sim.engine import make_twin
from sim.mixer import paper_mixer
from sim.placement import place_random
from sim.pymunk_twin import PymunkDrumSim
from sim.recipe import PACKING_2D, PAPER_DRUM, PAPER_RECIPE, DiskClass, DrumSpec

DEM_BEDS: tuple[tuple[str, DrumSpec, float], ...] = (
    ("rtf_paper_5rpm", PAPER_DRUM, 5.0),
    ("rtf_paper_30rpm", PAPER_DRUM, 30.0),
    ("rtf_4x", DrumSpec(diameter_m=PAPER_DRUM.diameter_m * 2, depth_m=PAPER_DRUM.depth_m * 2), 5.0),
    ("rtf_16x", DrumSpec(diameter_m=PAPER_DRUM.diameter_m * 4, depth_m=PAPER_DRUM.depth_m * 4), 5.0),
)
PYMUNK_BEDS = (("rtf_paper_5rpm_pymunk", "pymunk: paper, 5 rpm"),
               ("rtf_cutdisc_10rpm_pymunk", "pymunk: cut-disc rig, 10 rpm"))
PLACEMENT_BEDS = (20_000, 200_000)  # discs placed (two classes of 8.8 mm, fill 0.5): the second is issue 42's 10 m bed


def cpu_rtf(sim: Any, duration_s: float) -> float:
    """Sim seconds per CPU second of a twin: warmed up past the start transient, the best of three equal chunks."""
    sim.advance(min(1.0, duration_s))
    best = math.inf
    for _ in range(3):
        t0 = time.process_time()
        sim.advance(duration_s / 3)
        best = min(best, time.process_time() - t0)
    return duration_s / 3 / max(best, 1e-9)


def placement_s(n: int, seed: int = 0) -> float:
    """Wall seconds to place ``n`` discs of 8.8 mm (two classes) in a drum they fill to 0.5."""
    r = 4.4e-3
    radius_m = math.sqrt(n * r * r / (0.5 * PACKING_2D))
    classes = [DiskClass("a", r, n // 2, 1190.0, (0, 0, 255)), DiskClass("b", r, n - n // 2, 1190.0, (255, 0, 0))]
    t0 = time.perf_counter()
    place_random(classes, "C", radius_m, np.random.default_rng(seed))
    return time.perf_counter() - t0


def run_twin_bench(duration_s: float, progress: Callable[[], None] | None = None) -> dict[str, Any]:
    """Every number of ``drumtwin bench twin --json``; ``progress()`` after each DEM bed."""
    from sim.validation_pymunk import rig

    out: dict[str, Any] = {}
    for name, drum, rpm in DEM_BEDS:
        sim = DrumSim(drum, PAPER_RECIPE, case="C", seed=0, rpm=rpm, settle_s=0.3)
        out[name] = cpu_rtf(sim, duration_s)
        out[name.replace("rtf_", "n_")] = len(sim.particles())
        if progress is not None:
            progress()
    out["dt_ms"] = DEFAULT_DT_S * 1e3
    for (name, _), mixer, rpm in zip(PYMUNK_BEDS, (paper_mixer(), rig(True)), (5.0, 10.0), strict=True):
        twin = make_twin(mixer, "pymunk", case="C", seed=0, rpm=rpm, settle_s=0.3)
        out[name] = cpu_rtf(twin, duration_s)
        out[name.replace("rtf_", "n_")] = len(twin.particles())
        out[name.replace("rtf_", "dt_ms_")] = twin.substep_s() * 1e3  # each bed's own default step
    # where the cut-disc rig's step goes: shapes, contacts, iterations, Chipmunk against the post-step pass
    assert isinstance(twin, PymunkDrumSim)
    out["profile_cutdisc_pymunk"] = twin.cost_profile(duration_s / 3)
    out["clock"] = "process cpu time, best of 3 chunks"
    # total cost per simulated second grows as N^k from the paper bed to the 16x bed
    out["cost_exponent_16x"] = math.log(out["rtf_paper_5rpm"] / out["rtf_16x"]) / math.log(
        out["n_16x"] / out["n_paper_5rpm"])
    for n in PLACEMENT_BEDS:
        out[f"placement_s_{n}"] = placement_s(n)
    return out


__all__ = ["DEM_BEDS", "PLACEMENT_BEDS", "PYMUNK_BEDS", "cpu_rtf", "placement_s", "run_twin_bench"]

"""How the calibration measures the twin's free-surface slope: one statistic, two run lengths.

* **The statistic** (``frames_slope_deg``): the median of the frames' slopes (deg, frames without a free
  surface left out). The twin-vs-camera check (``twin.commission``) takes the camera's and the rendered
  twin's slopes with it too: one definition, so the calibration aims at the number the check compares
  (a monolayer's avalanches skew the frames' slopes: mean and median differ by 0.5-1 deg).
* **A search run** (``twin_surface``): one seed, ``window_s`` after a spin-up, cheap and noisy (one
  5 s window of one seed of a monolayer is good to 2-4 deg: the bed's packing wanders slowly, and
  one seed's bed differs from another's by 1-4 deg).
* **A confirming run** (``SlopeRun``, ``CONFIRM_RUN``): several seeds from mixed starts, each spun up
  and sampled for ``window_s``, their frames pooled; its noise is known from the seeds' own medians
  (``seeds_se_deg``). The calibration's final point is measured with it, and the twin-vs-camera check
  runs the same run (rendered, ``twin.commission.twin_check``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.drum import DrumSim
from sim.engine import make_twin
from sim.mixer import Mixer
from sim.probe import probe
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec, Recipe

SPIN_UP_S = 3.0  # each twin run's start before its slope is taken, s, at least ...
SPIN_UP_TURNS = 0.25  # ... this share of a drum turn: a bed from rest must first turn up to its slope


def default_spin_up_s(rpm: float) -> float:
    """The start of a twin run at ``rpm`` before its slope is taken (s): ``SPIN_UP_S``, or
    ``SPIN_UP_TURNS`` of a turn when that is longer (at 2 rpm a bed from rest needs 7.5 s to turn up)."""
    return max(SPIN_UP_S, SPIN_UP_TURNS * 60.0 / abs(rpm)) if rpm else SPIN_UP_S


def frames_slope_deg(slopes_deg: Sequence[float] | np.ndarray) -> float:
    """The slope (deg) a set of frames shows: the median of their finite slopes; NaN when none has one."""
    a = np.asarray(slopes_deg, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else math.nan


@dataclass(frozen=True)
class SlopeRun:
    """A confirming measurement: one twin per seed from a mixed start (case C), spun up
    ``default_spin_up_s`` (at least ``spin_up_s``), a frame every ``every_s`` for ``window_s`` (s).

    Four seeds of 15 s: a monolayer's frame slopes swing 6-9 deg (avalanches) and one run's median
    wanders by 1-4 deg with its packing; four 15 s runs put the pooled median within about 0.5-1 deg
    of the long-run slope (docs/validation.md section 6)."""

    seeds: tuple[int, ...] = (101, 102, 103, 104)
    spin_up_s: float = SPIN_UP_S
    window_s: float = 15.0
    every_s: float = 0.5

    @property
    def per_seed(self) -> int:
        return max(1, int(round(self.window_s / self.every_s)))

    @property
    def frames(self) -> int:
        return len(self.seeds) * self.per_seed

    def spin_up_at(self, rpm: float) -> float:
        """Each run's spin-up at ``rpm`` (s)."""
        return max(self.spin_up_s, default_spin_up_s(rpm))


CONFIRM_RUN = SlopeRun()


def seeds_se_deg(slopes_deg: Sequence[float] | np.ndarray, per_seed: int) -> float:
    """The standard error (deg) of a pooled run's slope: the spread (sd) of its seeds' own medians
    (``per_seed`` frames each, one after another) over the square root of their number; NaN for one seed."""
    a = np.asarray(slopes_deg, dtype=float)
    meds = [frames_slope_deg(a[i:i + per_seed]) for i in range(0, a.size, per_seed)]
    meds = [m for m in meds if math.isfinite(m)]
    return float(np.std(meds, ddof=1) / math.sqrt(len(meds))) if len(meds) > 1 else math.nan


@dataclass(frozen=True)
class Measured:
    """A confirming run's slope magnitude (deg, ``frames_slope_deg`` of its pooled frames) and its
    standard error (deg, ``seeds_se_deg``)."""

    slope_deg: float
    se_deg: float


Measure = Callable[[float, float, "float | None"], Measured]
"""``measure(sliding, rolling, end-plate friction or None: the twin's own)``: a confirming run."""


def _make(friction: float, rolling: float, rpm: float, *, drum: DrumSpec, recipe: Recipe, seed: int, case: str,
          mixer: Mixer | None, engine: str | None, **sim_kwargs: Any) -> Any:
    if mixer is not None:
        return make_twin(mixer, engine, case=case, seed=seed, rpm=rpm, friction=friction, rolling=rolling, **sim_kwargs)
    return DrumSim(drum, recipe, case=case, seed=seed, rpm=rpm, friction=friction, rolling=rolling, **sim_kwargs)


def twin_frames(friction: float, rolling: float, rpm: float, *, drum: DrumSpec = PAPER_DRUM,
                recipe: Recipe = PAPER_RECIPE, seed: int = 0, case: str = "C", spin_up_s: float = 3.0,
                window_s: float = 5.0, sample_s: float = 0.1, mixer: Mixer | None = None, engine: str | None = None,
                **sim_kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's free-surface slope (deg) and curvature of a fresh twin at ``rpm``, a frame every
    ``sample_s`` for ``window_s`` after ``spin_up_s`` (of ``mixer`` on ``engine`` when given, else the
    ``drum`` + ``recipe`` DEM)."""
    sim = _make(friction, rolling, rpm, drum=drum, recipe=recipe, seed=seed, case=case, mixer=mixer, engine=engine,
                **sim_kwargs)
    n = max(1, int(round(window_s / sample_s)))
    smp = list(probe(sim, n * sample_s, sample_s, spin_up_s=spin_up_s, include_start=False))
    return (np.array([s.surface.slope_deg for s in smp], dtype=float),
            np.array([s.surface.curvature for s in smp], dtype=float))


def twin_surface(friction: float, rolling: float, rpm: float, **kwargs: Any) -> tuple[float, float]:
    """A search run: the slope (deg, ``frames_slope_deg``) and mean curvature of a fresh twin's frames
    (``twin_frames``, the same arguments)."""
    s, c = twin_frames(friction, rolling, rpm, **kwargs)
    c = c[np.isfinite(c)]
    return frames_slope_deg(s), (float(np.mean(c)) if c.size else math.nan)


def twin_slope_deg(friction: float, rolling: float, rpm: float, **kwargs: Any) -> float:
    """A search run's slope (deg; ``twin_surface``'s first number)."""
    return twin_surface(friction, rolling, rpm, **kwargs)[0]


def twin_measure(rpm: float, twin_kw: dict[str, Any], run: SlopeRun = CONFIRM_RUN) -> Measure:
    """The confirming measurement of the particle twin ``twin_kw`` describes (``twin_frames``'
    arguments; its seed, spin-up and window are the ``run``'s)."""
    kw = {k: v for k, v in twin_kw.items() if k not in ("seed", "spin_up_s", "window_s", "sample_s")}

    def measure(friction: float, rolling: float, end_friction: float | None) -> Measured:
        ekw = kw if end_friction is None else {**kw, "end_friction": end_friction}
        s = np.concatenate([twin_frames(friction, rolling, rpm, seed=seed, spin_up_s=run.spin_up_at(rpm),
                                        window_s=run.window_s, sample_s=run.every_s, **ekw)[0]
                            for seed in run.seeds])
        return Measured(abs(frames_slope_deg(s)), seeds_se_deg(s, run.per_seed))

    return measure


__all__ = ["CONFIRM_RUN", "SPIN_UP_S", "SPIN_UP_TURNS", "Measure", "Measured", "SlopeRun", "default_spin_up_s",
           "frames_slope_deg", "seeds_se_deg", "twin_frames", "twin_measure", "twin_slope_deg", "twin_surface"]

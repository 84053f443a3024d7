"""Calibration of the twin by the bed's slope angle (the approach of the paper's ref. [31]).

The twin's dynamic slope angle at a given rpm grows with sliding friction and, past
the friction at which the disks interlock, with rolling resistance. ``calibrate``
walks one monotone path through both -- first sliding friction from ``FRICTION_RANGE``
(rolling resistance tied to it by ``rolling_ratio``), then, if the target is steeper
still, rolling resistance up to ``ROLLING_MAX`` at the top friction -- and bisects
(regula falsi) the path parameter until the twin's mean slope matches the target.
Every evaluation uses the same seed (common random numbers), so the slope is a
smooth function of the path parameter.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sim.drum import DEFAULT_FRICTION, DEFAULT_ROLLING, DrumSim, check_rpm
from sim.errors import SimError
from sim.measure import particle_slope_deg
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec, Recipe

FRICTION_RANGE = (0.05, 1.0)
ROLLING_MAX = 1.0

__all__ = ["Calibration", "calibrate", "twin_slope_deg", "FRICTION_RANGE", "ROLLING_MAX"]


@dataclass(frozen=True)
class Calibration:
    """Fitted contact parameters and how well the twin's slope matches (deg)."""

    friction: float
    rolling: float
    twin_slope_deg: float
    residual_deg: float  # twin - target
    target_slope_deg: float
    rpm: float
    evaluations: int
    history: tuple[tuple[float, float, float], ...]  # (friction, rolling, slope_deg) per evaluation

    def as_dict(self) -> dict:
        return {
            "friction": self.friction, "rolling": self.rolling, "twin_slope_deg": self.twin_slope_deg,
            "residual_deg": self.residual_deg, "target_slope_deg": self.target_slope_deg, "rpm": self.rpm,
            "evaluations": self.evaluations,
        }


def twin_slope_deg(
    friction: float,
    rolling: float,
    rpm: float,
    *,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    seed: int = 0,
    case: str = "C",
    spin_up_s: float = 4.0,
    window_s: float = 6.0,
    sample_s: float = 0.1,
    **sim_kwargs,
) -> float:
    """Mean free-surface slope (deg) of a fresh twin at ``rpm`` over ``window_s`` after ``spin_up_s``."""
    sim = DrumSim(drum, recipe, case=case, seed=seed, rpm=rpm, friction=friction, rolling=rolling, **sim_kwargs)
    sim.advance(spin_up_s)
    vals = []
    for _ in range(max(1, int(round(window_s / sample_s)))):
        sim.advance(sample_s)
        vals.append(particle_slope_deg(sim.particles(), drum))
    v = np.asarray(vals, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def _path(u: float, rolling_ratio: float) -> tuple[float, float]:
    """(friction, rolling) at path parameter u in [0, 2]."""
    lo, hi = FRICTION_RANGE
    if u <= 1.0:
        f = lo * (hi / lo) ** u  # geometric in friction
        return f, rolling_ratio * f
    r0 = rolling_ratio * hi
    return hi, r0 + (u - 1.0) * (max(ROLLING_MAX, r0) - r0)


def calibrate(
    target_slope_deg: float,
    rpm: float,
    *,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    rolling_ratio: float | None = None,
    seed: int = 0,
    spin_up_s: float = 4.0,
    window_s: float = 6.0,
    tol_deg: float = 0.4,
    max_evals: int = 9,
    progress: Callable[[int, int], None] | None = None,
    **sim_kwargs,
) -> Calibration:
    """Fit friction (and rolling resistance) so the twin's slope at ``rpm`` is ``target_slope_deg``.

    ``rolling_ratio`` ties rolling resistance to friction on the first leg of the path
    (default: the twin defaults' ratio). Returns the best evaluation seen; the residual
    says how close it came (a target outside the reachable range ends at the nearest end).
    """
    try:
        target = float(target_slope_deg)
    except (TypeError, ValueError):
        raise SimError(f"target slope must be a number of degrees (got {target_slope_deg!r})") from None
    if not math.isfinite(target) or not (0.0 < abs(target) < 80.0):
        raise SimError(f"target slope must be between 0 and 80 degrees (got {target_slope_deg})")
    rpm = check_rpm(rpm, drum)
    if rpm == 0:
        raise SimError("calibration needs a turning drum (rpm > 0)")
    sign = 1.0 if target > 0 else -1.0  # compare magnitudes; report with the target's sign
    target_mag = abs(target)
    ratio = (DEFAULT_ROLLING / DEFAULT_FRICTION) if rolling_ratio is None else float(rolling_ratio)
    if ratio < 0:
        raise SimError(f"rolling_ratio must be >= 0 (got {ratio})")
    history: list[tuple[float, float, float]] = []

    def slope_at(u: float) -> float:
        f, r = _path(u, ratio)
        s = abs(twin_slope_deg(f, r, abs(rpm), drum=drum, recipe=recipe, seed=seed, spin_up_s=spin_up_s,
                                  window_s=window_s, **sim_kwargs))
        history.append((f, r, s))
        if progress is not None:
            progress(len(history), max_evals)
        return s

    # bracket on [0, 1] (friction leg), extend to the rolling leg only if needed
    lo_u, hi_u = 0.0, 1.0
    s_lo, s_hi = slope_at(lo_u), slope_at(hi_u)
    if s_hi < target_mag and max_evals > 2:
        lo_u, s_lo = hi_u, s_hi
        hi_u = 2.0
        s_hi = slope_at(hi_u)
    while len(history) < max_evals:
        best = min(history, key=lambda h: abs(h[2] - target_mag))
        if abs(best[2] - target_mag) <= tol_deg:
            break
        if not (s_lo < target_mag < s_hi):
            break  # target out of reach (or non-monotone): keep the nearest end
        # regula falsi, kept away from the ends so the bracket shrinks
        w = (target_mag - s_lo) / (s_hi - s_lo)
        w = min(max(w, 0.15), 0.85)
        u = lo_u + w * (hi_u - lo_u)
        s = slope_at(u)
        if s < target_mag:
            lo_u, s_lo = u, s
        else:
            hi_u, s_hi = u, s
    f, r, s = min(history, key=lambda h: abs(h[2] - target_mag) if math.isfinite(h[2]) else math.inf)
    return Calibration(
        friction=float(f), rolling=float(r), twin_slope_deg=float(sign * s), residual_deg=float(sign * (s - target_mag)),
        target_slope_deg=target, rpm=rpm, evaluations=len(history), history=tuple(history),
    )

"""Calibration of the twin by the bed's free surface (the approach of the paper's ref. [31]).

The twin's dynamic slope angle at a given rpm grows with sliding friction and with
rolling friction. ``calibrate`` searches the (sliding, rolling) plane between
``FRICTION_RANGE`` and ``ROLLING_RANGE``:

1. **Reachable range.** The least-friction corner gives the lowest slope. The highest is
   not at the other corner: at the largest rolling friction the slope peaks at moderate
   sliding friction (with more, the bed locks into slabs that slump), so the high end is
   the best of ``HIGH_EDGE`` points on the ``rolling = ROLLING_RANGE[1]`` edge. A target
   outside that range (with ``RANGE_TOL_DEG`` of grace) is a ``SimError`` that names
   the range -- never a silent best effort.
2. **Slope.** Along a path from the low corner to the high point the slope is monotone,
   and a bracketing search (regula falsi) finds the point whose mean free-surface slope
   matches the target. Every evaluation uses the same seed (common random numbers).
3. **Curvature** (when measured). Several paths through the plane -- sliding friction
   first, both together, rolling friction first -- each give a point on the target's
   iso-slope line; the one whose surface S-shape (``sim.measure.FreeSurface.curvature``)
   is nearest the measured one wins. That is the second dimension of the search.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.drum import DrumSim, check_rpm
from sim.engine import make_twin
from sim.errors import SimError
from sim.mixer import Mixer
from sim.probe import probe
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec, Recipe

FRICTION_RANGE = (0.05, 1.0)  # sliding friction searched (geometric)
ROLLING_RANGE = (0.0, 1.0)  # rolling friction searched
RANGE_TOL_DEG = 1.0  # a target this close outside the range still calibrates (to the end)
HIGH_EDGE = (0.25, 0.5, 1.0)  # sliding friction tried at the largest rolling friction for the top of the range
PATHS = ("diagonal", "sliding-first", "rolling-first")

__all__ = [
    "FRICTION_RANGE", "HIGH_EDGE", "PATHS", "RANGE_TOL_DEG", "ROLLING_RANGE", "Calibration", "calibrate", "path_point",
    "reachable_range", "twin_slope_deg", "twin_surface",
]


@dataclass(frozen=True)
class Calibration:
    """Fitted contact parameters and how well the twin's free surface matches (deg)."""

    friction: float
    rolling: float
    twin_slope_deg: float
    residual_deg: float  # twin - target
    target_slope_deg: float
    rpm: float
    evaluations: int
    history: tuple[tuple[float, float, float], ...]  # (friction, rolling, slope_deg) per evaluation
    range_deg: tuple[float, float] = (math.nan, math.nan)  # reachable slopes at this rpm
    twin_curvature: float = math.nan
    target_curvature: float | None = None
    path: str = "diagonal"

    def as_dict(self) -> dict:
        return {
            "friction": self.friction, "rolling": self.rolling, "twin_slope_deg": self.twin_slope_deg,
            "residual_deg": self.residual_deg, "target_slope_deg": self.target_slope_deg, "rpm": self.rpm,
            "evaluations": self.evaluations, "range_deg": list(self.range_deg),
            "twin_curvature": self.twin_curvature, "target_curvature": self.target_curvature, "path": self.path,
        }


def twin_surface(
    friction: float,
    rolling: float,
    rpm: float,
    *,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    seed: int = 0,
    case: str = "C",
    spin_up_s: float = 3.0,
    window_s: float = 5.0,
    sample_s: float = 0.1,
    mixer: Mixer | None = None,
    engine: str | None = None,
    **sim_kwargs,
) -> tuple[float, float]:
    """Mean free-surface slope (deg) and curvature of a fresh twin at ``rpm`` over ``window_s`` after ``spin_up_s``
    (of ``mixer`` on ``engine`` when given, else the ``drum`` + ``recipe`` DEM)."""
    sim: Any
    if mixer is not None:
        drum = mixer.drum
        sim = make_twin(mixer, engine, case=case, seed=seed, rpm=rpm, friction=friction, rolling=rolling,
                        **sim_kwargs)
    else:
        sim = DrumSim(drum, recipe, case=case, seed=seed, rpm=rpm, friction=friction, rolling=rolling, **sim_kwargs)
    slopes, curvs = [], []
    n = max(1, int(round(window_s / sample_s)))
    for smp in probe(sim, n * sample_s, sample_s, spin_up_s=spin_up_s, include_start=False):
        slopes.append(smp.surface.slope_deg)
        curvs.append(smp.surface.curvature)
    s = np.asarray(slopes, dtype=float)
    c = np.asarray(curvs, dtype=float)
    s, c = s[np.isfinite(s)], c[np.isfinite(c)]
    return (float(np.mean(s)) if s.size else math.nan, float(np.mean(c)) if c.size else math.nan)


def twin_slope_deg(friction: float, rolling: float, rpm: float, **kwargs) -> float:
    """Mean free-surface slope (deg) of a fresh twin (``twin_surface``'s first number)."""
    return twin_surface(friction, rolling, rpm, **kwargs)[0]


def path_point(u: float, path: str = "diagonal", high: tuple[float, float] | None = None) -> tuple[float, float]:
    """(sliding, rolling friction) at ``u`` in [0, 1] along one of ``PATHS`` from the least-friction
    corner (u=0) to ``high`` (u=1; default the most-friction corner); sliding friction is geometric."""
    if path not in PATHS:
        raise SimError(f"calibration path must be one of {', '.join(PATHS)} (got {path!r})")
    u = min(max(float(u), 0.0), 1.0)
    lo, r_lo = FRICTION_RANGE[0], ROLLING_RANGE[0]
    hi, r_hi = (FRICTION_RANGE[1], ROLLING_RANGE[1]) if high is None else high
    if path == "diagonal":
        us, ur = u, u
    elif path == "sliding-first":
        us, ur = min(2 * u, 1.0), max(2 * u - 1.0, 0.0)
    else:
        us, ur = max(2 * u - 1.0, 0.0), min(2 * u, 1.0)
    return lo * (hi / lo) ** us, r_lo + ur * (r_hi - r_lo)


def _check_target(target_slope_deg: float) -> float:
    try:
        target = float(target_slope_deg)
    except (TypeError, ValueError):
        raise SimError(f"target slope must be a number of degrees (got {target_slope_deg!r})") from None
    if not math.isfinite(target) or not (0.0 < abs(target) < 90.0):
        raise SimError(f"target slope must be between 0 and 90 degrees (got {target_slope_deg})")
    return target


def _range_ends(slope: Callable[[float, float], float], rpm: float) -> tuple[float, float, tuple[float, float]]:
    """The ends of the reachable range from ``slope(friction, rolling)`` (deg magnitude, NaN: no free
    surface): the least-friction corner's slope, the best ``HIGH_EDGE`` point's slope and that point.
    No free surface at either end is a ``SimError``."""
    s_lo = slope(*path_point(0.0))
    edge = [(slope(f, ROLLING_RANGE[1]), f) for f in HIGH_EDGE]
    finite = [e for e in edge if math.isfinite(e[0])]
    if not (math.isfinite(s_lo) and finite):
        raise SimError(f"the twin shows no free surface at {rpm:g} rpm: it cannot be calibrated by slope there")
    s_hi, f_hi = max(finite)
    return s_lo, s_hi, (f_hi, ROLLING_RANGE[1])


def reachable_range(rpm: float, *, seed: int = 0, **kwargs) -> tuple[float, float]:
    """(lowest, highest) free-surface slope magnitude (deg) the twin reaches at ``rpm`` within the
    search bounds: the least-friction corner and the best ``HIGH_EDGE`` point, as ``calibrate`` sees them."""
    def slope(f: float, r: float) -> float:
        return abs(twin_slope_deg(f, r, abs(rpm), seed=seed, **kwargs))

    s_lo, s_hi, _ = _range_ends(slope, rpm)
    return min(s_lo, s_hi), max(s_lo, s_hi)


def _check_calibration(rpm: float, drum: DrumSpec, target_curvature: float | None, tol_deg: float,
                       max_evals: int) -> float:
    """``calibrate``'s arguments checked (one-line ``SimError``s); the rpm as a float."""
    rpm = check_rpm(rpm, drum)
    if rpm == 0:
        raise SimError("calibration needs a turning drum (rpm > 0)")
    if target_curvature is not None and not math.isfinite(float(target_curvature)):
        raise SimError(f"target curvature must be a finite number (got {target_curvature})")
    if not (math.isfinite(tol_deg) and tol_deg > 0):
        raise SimError(f"tolerance must be > 0 deg (got {tol_deg})")
    if max_evals < 1:
        raise SimError(f"calibration needs at least 1 search evaluation (got {max_evals})")
    return rpm


def _check_reachable(target_mag: float, lo_b: float, hi_b: float, rpm: float) -> None:
    """A ``SimError`` naming the reachable range when the target slope (deg) lies outside it."""
    if not (lo_b - RANGE_TOL_DEG <= target_mag <= hi_b + RANGE_TOL_DEG):
        raise SimError(
            f"target slope {target_mag:.1f} deg is outside the twin's reachable range {lo_b:.1f}-{hi_b:.1f} deg "
            f"at {abs(rpm):g} rpm (sliding friction {FRICTION_RANGE[0]:g}-{FRICTION_RANGE[1]:g}, "
            f"rolling friction {ROLLING_RANGE[0]:g}-{ROLLING_RANGE[1]:g})"
        )


def _search_path(evaluate: Callable[[float, float], float], history: list[tuple[float, float, float]], path: str,
                 ends: list[tuple[float, float, float]], slopes: tuple[float, float], high: tuple[float, float],
                 target_mag: float, tol_deg: float, max_evals: int) -> tuple[float, float, float]:
    """The point of ``path`` (friction, rolling, slope) nearest the target slope: a bracketing search
    (regula falsi, kept off the ends) from the range ends, at most ``max_evals`` evaluations."""
    start = len(history)
    lo_u, hi_u = 0.0, 1.0
    sl, sh = slopes
    own: list[tuple[float, float, float]] = list(ends)
    while len(history) - start < max_evals:
        best = min(own, key=lambda h: abs(h[2] - target_mag))
        if abs(best[2] - target_mag) <= tol_deg or not (sl < target_mag < sh):
            break
        w = min(max((target_mag - sl) / (sh - sl), 0.15), 0.85)  # regula falsi, kept off the ends
        u = lo_u + w * (hi_u - lo_u)
        s = evaluate(*path_point(u, path, high))
        own.append(history[-1])
        if not math.isfinite(s):
            break
        if s < target_mag:
            lo_u, sl = u, s
        else:
            hi_u, sh = u, s
    return min(own, key=lambda h: abs(h[2] - target_mag))


def _pick(candidates: list[tuple[str, tuple[float, float, float]]], curv: dict[tuple[float, float], float],
          target_mag: float, tol_deg: float,
          target_curvature: float | None) -> tuple[str, tuple[float, float, float]]:
    """The calibration among the paths' best points: the slope decides first (only points within the
    tolerance, or the best slope found, compete); with a measured curvature the surface shape then
    picks among them."""
    def err(c: tuple[str, tuple[float, float, float]]) -> float:
        return abs(c[1][2] - target_mag)

    best_err = min(err(c) for c in candidates)
    fits = [c for c in candidates if err(c) <= max(tol_deg, best_err)]
    if target_curvature is None:
        return min(fits, key=err)
    return min(fits, key=lambda c: abs(curv[(c[1][0], c[1][1])] - float(target_curvature)))


def calibrate(
    target_slope_deg: float,
    rpm: float,
    *,
    target_curvature: float | None = None,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    seed: int = 0,
    spin_up_s: float = 3.0,
    window_s: float = 5.0,
    tol_deg: float = 0.4,
    max_evals: int = 8,
    progress: Callable[[int, int], None] | None = None,
    mixer: Mixer | None = None,
    engine: str | None = None,
    **sim_kwargs,
) -> Calibration:
    """Fit sliding and rolling friction so the twin's free surface at ``rpm`` matches the target.

    ``max_evals`` is the budget of the bracketing search per path (after the range runs: the
    low corner and the ``HIGH_EDGE`` points). A target outside the reachable range is a
    ``SimError`` naming the range.
    """
    target = _check_target(target_slope_deg)
    if mixer is not None:
        drum = mixer.drum
    rpm = _check_calibration(rpm, drum, target_curvature, tol_deg, max_evals)
    sign = 1.0 if target > 0 else -1.0  # compare magnitudes; report with the target's sign
    target_mag = abs(target)
    paths = PATHS if target_curvature is not None else PATHS[:1]
    total = 1 + len(HIGH_EDGE) + len(paths) * max_evals
    history: list[tuple[float, float, float]] = []
    curv: dict[tuple[float, float], float] = {}

    def evaluate(f: float, r: float) -> float:
        s, c = twin_surface(f, r, abs(rpm), drum=drum, recipe=recipe, seed=seed, spin_up_s=spin_up_s,
                            window_s=window_s, mixer=mixer, engine=engine, **sim_kwargs)
        s = abs(s) if math.isfinite(s) else math.nan
        history.append((f, r, s))
        curv[(f, r)] = c
        if progress is not None:
            progress(len(history), total)
        return s

    s_lo, s_hi, high = _range_ends(evaluate, rpm)
    lo_b, hi_b = min(s_lo, s_hi), max(s_lo, s_hi)
    _check_reachable(target_mag, lo_b, hi_b, rpm)
    ends = [history[0], next(h for h in history if (h[0], h[1]) == high)]
    candidates = [(path, _search_path(evaluate, history, path, ends, (s_lo, s_hi), high, target_mag, tol_deg,
                                      max_evals)) for path in paths]
    path, (f, r, s) = _pick(candidates, curv, target_mag, tol_deg, target_curvature)
    return Calibration(
        friction=float(f), rolling=float(r), twin_slope_deg=float(sign * s),
        residual_deg=float(sign * (s - target_mag)),
        target_slope_deg=target, rpm=rpm, evaluations=len(history), history=tuple(history),
        range_deg=(float(lo_b), float(hi_b)), twin_curvature=float(curv[(f, r)]),
        target_curvature=None if target_curvature is None else float(target_curvature), path=path,
    )

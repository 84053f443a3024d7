"""Calibration of the twin by the bed's free surface (the approach of the paper's ref. [31]).

The twin's dynamic slope angle at a given rpm grows with sliding friction, with rolling friction
and with the friction of the drum's end plates. ``calibrate`` searches sliding friction in
``FRICTION_RANGE`` and rolling friction in ``ROLLING_RANGE`` (the "plane"); the end plates take
the wall's friction (Taberlet's side-wall law, valid for a deep drum), except in a **monolayer**
drum, whose plates are a third calibrated parameter (docs/validation.md, section 6):

* A monolayer's discs stand upright between plates one disc thick, so their contacts push along
  the plates, not into them: the thick-slice law overstates the plates' grip many times over.
  Per unit of a disc's in-plane contact load the plates' friction is ``k = mu_end r / W`` (``W``
  the plates' gap), bounded by the rig's materials and clearance: the plates' friction
  coefficient times the tilt a disc can take in its gap, at most ``END_LOAD_MAX``. Near it the
  twin's bed begins to stop flowing and turn with its plates.
* The plane is searched with no plate friction; the plates take only what the slope needs beyond
  the plane's top (the "plates" leg: from the plane's high point to the best of ``PLATE_EDGE``).
  An ``end_friction`` the caller gives is kept fixed (not searched).

1. **Reachable range.** The least-friction corner gives the lowest slope. The highest is not at
   the other corner: at the largest rolling friction the slope peaks at moderate sliding friction
   (with more, the bed locks into slabs that slump), so the high end is the best of ``HIGH_EDGE``
   points on the ``rolling = ROLLING_RANGE[1]`` edge (for a monolayer, then the best of the ``PLATE_EDGE``
   plate frictions there: with too much the bed turns with its plates and stands lower again).
   A target outside that range (with ``RANGE_TOL_DEG`` of grace) is a ``SimError`` that names the
   range and the parameter that would have to leave its range -- never a silent best effort.
2. **Slope.** Along a path from the low corner to the high point the slope is monotone, and a
   bracketing search (regula falsi) finds the point whose free-surface slope matches the
   target. Every evaluation uses the same seed (common random numbers).
3. **Curvature** (when measured). Several paths through the plane -- sliding friction first, both
   together, rolling friction first -- each give a point on the target's iso-slope line; the one
   whose surface S-shape (``sim.measure.FreeSurface.curvature``) is nearest the measured one wins.
4. **Confirmation.** A search run (one seed, a few seconds) is good to 2-4 deg on a monolayer, so the
   search stops within ``SEARCH_TOL_DEG`` and its answer is only a start: the monotone fit of the
   chosen path's runs gives where the slope crosses the target, and confirming runs (several seeds,
   long windows: ``sim.calibrate_slope.CONFIRM_RUN``, or the caller's ``measure``, e.g. the
   twin-vs-camera check's own run) settle it (``sim.calibrate_confirm``): ``confirm_evals`` of them at
   most, ``CONFIRM_EVALS`` where the answer must land within the tolerance (commissioning's). The
   answer's slope and residual are a confirming run's, with its standard error. Every slope is the
   median of the frames' (``sim.calibrate_slope.frames_slope_deg``), as the twin-vs-camera check
   takes it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from sim.calibrate_confirm import confirm
from sim.calibrate_slope import (
    CONFIRM_RUN,
    SPIN_UP_S,
    SPIN_UP_TURNS,
    Measure,
    SlopeRun,
    default_spin_up_s,
    twin_measure,
    twin_slope_deg,
    twin_surface,
)
from sim.errors import SimError
from sim.mixer import Mixer
from sim.params import SimParams, check_rpm
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec, Recipe

FRICTION_RANGE = (0.05, 1.0)  # sliding friction searched (geometric)
ROLLING_RANGE = (0.0, 1.0)  # rolling friction searched
END_LOAD_MAX = 0.08  # a monolayer's plates: the most friction per unit in-plane contact load, mu_end r / W
PLATE_EDGE = (0.5, 1.0)  # shares of a monolayer's most plate friction tried at the plane's high point (the top)
RANGE_TOL_DEG = 1.0  # a target this close outside the range still calibrates (to the end)
HIGH_EDGE = (0.25, 0.5, 1.0)  # sliding friction tried at the largest rolling friction for the top of the range
PATHS = ("diagonal", "sliding-first", "rolling-first")
PLATES = "plates"  # the leg from the plane's high point up the plates' friction (a monolayer's)
CONFIRM_EVALS = 3  # confirming runs a calibration that must land within its tolerance asks for (commissioning)
SEARCH_TOL_DEG = 1.5  # with confirming runs, the search stops this close: its single runs are no better

Run = tuple[float, float, float, float]  # (sliding friction, rolling friction, end-plate friction, slope deg)

__all__ = [
    "CONFIRM_EVALS", "CONFIRM_RUN", "END_LOAD_MAX", "FRICTION_RANGE", "HIGH_EDGE", "PATHS", "PLATES", "PLATE_EDGE",
    "RANGE_TOL_DEG", "ROLLING_RANGE", "SEARCH_TOL_DEG", "SPIN_UP_S", "SPIN_UP_TURNS", "Calibration", "SlopeRun",
    "calibrate", "default_spin_up_s", "end_friction_max", "path_point", "reachable_range", "twin_slope_deg",
    "twin_surface",
]


@dataclass(frozen=True)
class Calibration:
    """Fitted contact parameters and how well the twin's free surface matches (deg).

    ``end_friction`` is the end plates' friction in effect at the fit (the engines' ``end_friction``:
    the wall's for a deep drum, the searched one for a monolayer); ``end_friction_max`` the most the
    search gave the plates (0: not searched). ``history``: every twin run as ``Run`` (a confirming run
    as one, its pooled slope). ``twin_slope_deg`` is the confirming run's at the answer when there were
    any (``confirmations`` > 0; ``slope_se_deg`` its standard error), else the search's closest run's."""

    friction: float
    rolling: float
    twin_slope_deg: float
    residual_deg: float  # twin - target
    target_slope_deg: float
    rpm: float
    evaluations: int
    history: tuple[Run, ...]
    range_deg: tuple[float, float] = (math.nan, math.nan)  # reachable slopes at this rpm
    twin_curvature: float = math.nan
    target_curvature: float | None = None
    path: str = "diagonal"
    end_friction: float = math.nan
    end_friction_max: float = 0.0
    slope_se_deg: float = math.nan
    confirmations: int = 0

    def as_dict(self) -> dict:
        return {
            "friction": self.friction, "rolling": self.rolling, "end_friction": self.end_friction,
            "twin_slope_deg": self.twin_slope_deg, "residual_deg": self.residual_deg,
            "target_slope_deg": self.target_slope_deg, "rpm": self.rpm, "evaluations": self.evaluations,
            "range_deg": list(self.range_deg), "twin_curvature": self.twin_curvature,
            "target_curvature": self.target_curvature, "path": self.path, "end_friction_max": self.end_friction_max,
            "slope_se_deg": self.slope_se_deg, "confirmations": self.confirmations,
        }

    def twin_kwargs(self) -> dict[str, float]:
        """The fitted parameters as a twin takes them (``make_twin``, ``set_friction``)."""
        return {"friction": self.friction, "rolling": self.rolling, "end_friction": self.end_friction}


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


def end_friction_max(mixer: Mixer | None, sim_kwargs: dict | None = None) -> float:
    """The most end-plate friction (the engines' ``end_friction``) the search gives ``mixer``'s plates:
    ``END_LOAD_MAX W / r`` of its largest particle for a monolayer, 0 (not searched: the plates take the
    wall's friction) for a deep drum, the paper's drum or when ``sim_kwargs`` fixes ``end_friction``."""
    if mixer is None or not mixer.monolayer or (sim_kwargs or {}).get("end_friction") is not None:
        return 0.0
    return END_LOAD_MAX * mixer.drum.depth_m / max(p.shape.radius_m for p in mixer.particles)


def _check_target(target_slope_deg: float) -> float:
    try:
        target = float(target_slope_deg)
    except (TypeError, ValueError):
        raise SimError(f"target slope must be a number of degrees (got {target_slope_deg!r})") from None
    if not math.isfinite(target) or not (0.0 < abs(target) < 90.0):
        raise SimError(f"target slope must be between 0 and 90 degrees (got {target_slope_deg})")
    return target


class _Runs:
    """The calibration's twin runs: each point's slope magnitude (NaN: no free surface), its
    curvature, the history and the progress. A point is (sliding, rolling, end-plate friction);
    an end-plate friction of None leaves the plates to the twin (the wall's, or the caller's)."""

    def __init__(self, rpm: float, twin_kw: dict, progress: Callable[[int, int], None] | None, total: int) -> None:
        self.rpm, self.twin_kw, self.progress, self.total = abs(rpm), twin_kw, progress, total
        self.history: list[Run] = []
        self.curv: dict[Run, float] = {}

    def __call__(self, f: float, r: float, e: float | None = None) -> Run:
        kw = self.twin_kw if e is None else {**self.twin_kw, "end_friction": e}
        s, c = twin_surface(f, r, self.rpm, **kw)
        return self.record(f, r, e, s, c)

    def record(self, f: float, r: float, e: float | None, s: float, c: float = math.nan) -> Run:
        """A run at (``f``, ``r``, ``e``) that showed slope ``s`` (deg) and curvature ``c``, kept."""
        kw = self.twin_kw if e is None else {**self.twin_kw, "end_friction": e}
        mixer, end = kw.get("mixer"), kw.get("end_friction")
        end = mixer.end_friction if end is None and mixer is not None else end  # as make_twin resolves it
        e_eff = SimParams(friction=f, rolling=r, wall_friction=kw.get("wall_friction"), end_friction=end).end_mu
        run = (f, r, e_eff, abs(s) if math.isfinite(s) else math.nan)
        self.history.append(run)
        self.curv[run] = c
        if self.progress is not None:
            self.progress(len(self.history), self.total)
        return run


@dataclass(frozen=True)
class _Ends:
    """The reachable range's runs: the low corner, the plane's high point, the top of the range (the
    plates leg's end when the plates are searched and steepen the bed, else the plane's high point).
    ``plane_e``: the plates' friction in the plane (0 for a monolayer, None: the twin's own)."""

    low: Run
    plane_top: Run
    top: Run
    plane_e: float | None

    @property
    def range_deg(self) -> tuple[float, float]:
        return min(self.low[3], self.top[3]), max(self.low[3], self.top[3])

    def leg_point(self, u: float, path: str) -> tuple[float, float, float | None]:
        """The point at ``u`` in [0, 1] on ``path`` (``PATHS`` through the plane, or ``PLATES``)."""
        if path == PLATES:
            return self.top[0], self.top[1], min(max(float(u), 0.0), 1.0) * self.top[2]
        f, r = path_point(u, path, (self.plane_top[0], self.plane_top[1]))
        return f, r, self.plane_e


def _range_ends(runs: _Runs, rpm: float, end_max: float) -> _Ends:
    """Run the reachable range's ends (the plates leg's only when ``end_max`` > 0). No free surface at
    the low corner or along the whole high edge is a ``SimError``."""
    plane_e = 0.0 if end_max > 0 else None
    low = runs(*path_point(0.0), plane_e)
    finite = [h for h in (runs(f, ROLLING_RANGE[1], plane_e) for f in HIGH_EDGE) if math.isfinite(h[3])]
    if not (math.isfinite(low[3]) and finite):
        raise SimError(f"the twin shows no free surface at {abs(rpm):g} rpm: it cannot be calibrated by slope there")
    plane_top = max(finite, key=lambda h: (h[3], h[0]))  # a tie: the larger sliding friction
    top = plane_top
    for share in PLATE_EDGE if end_max > 0 else ():
        leg_end = runs(plane_top[0], plane_top[1], share * end_max)
        top = leg_end if leg_end[3] > top[3] else top
    return _Ends(low, plane_top, top, plane_e)


def reachable_range(rpm: float, *, seed: int = 0, **kwargs) -> tuple[float, float]:
    """(lowest, highest) free-surface slope magnitude (deg) the twin reaches at ``rpm`` within the
    search bounds, as ``calibrate`` sees them (``kwargs`` as ``calibrate``'s twin arguments)."""
    if kwargs.get("spin_up_s") is None:
        kwargs["spin_up_s"] = default_spin_up_s(rpm)
    runs = _Runs(rpm, {"seed": seed, **kwargs}, None, 0)
    return _range_ends(runs, rpm, end_friction_max(kwargs.get("mixer"), kwargs)).range_deg


def _out_of_range(target: float, ends: _Ends, rpm: float, end_max: float) -> SimError:
    """The error of a target outside the range: the range, the box, and which friction would have to leave it."""
    lo, hi = ends.range_deg
    box = (f"sliding friction {FRICTION_RANGE[0]:g}-{FRICTION_RANGE[1]:g}, "
           f"rolling friction {ROLLING_RANGE[0]:g}-{ROLLING_RANGE[1]:g}")
    if end_max > 0:
        box += f", end-plate friction 0-{end_max:.3g}"
    if target < lo:
        need = f"sliding friction below {FRICTION_RANGE[0]:g}"
    elif end_max > 0:
        need = f"end-plate friction above {end_max:.3g}, where a monolayer turns with its plates"
    else:
        need = f"rolling friction above {ROLLING_RANGE[1]:g}"
    return SimError(f"target slope {target:.1f} deg is outside the twin's reachable range {lo:.1f}-{hi:.1f} deg "
                    f"at {abs(rpm):g} rpm ({box}): it needs {need}")


Leg = list[tuple[float, Run]]  # a path's runs with their u


def _search(runs: _Runs, ends: _Ends, path: str, lo: Run, hi: Run, target: float, tol_deg: float,
            max_evals: int) -> Leg:
    """Regula falsi along ``path`` between the runs ``lo`` (u=0) and ``hi`` (u=1) for ``target`` (deg),
    kept 15 % off the bracket's ends, at most ``max_evals`` runs; the path's runs with their u."""
    start = len(runs.history)
    lo_u, hi_u, sl, sh = 0.0, 1.0, lo[3], hi[3]
    own = [lo, hi]
    us = [0.0, 1.0]
    while len(runs.history) - start < max_evals:
        best = min(own, key=lambda h: abs(h[3] - target))
        if abs(best[3] - target) <= tol_deg or not (sl < target < sh):
            break
        w = min(max((target - sl) / (sh - sl), 0.15), 0.85)
        u = lo_u + w * (hi_u - lo_u)
        own.append(runs(*ends.leg_point(u, path)))
        us.append(u)
        s = own[-1][3]
        if not math.isfinite(s):
            break
        if s < target:
            lo_u, sl = u, s
        else:
            hi_u, sh = u, s
    return list(zip(us, own, strict=True))


def _nearest(leg: Leg, target: float) -> Run:
    return min((h for _, h in leg), key=lambda h: abs(h[3] - target))


def _check_search(rpm: float, drum: DrumSpec, target_curvature: float | None, tol_deg: float, max_evals: int) -> float:
    """The checked rpm; one-line SimErrors for a drum at rest, a bad curvature, tolerance or budget."""
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


def calibrate(
    target_slope_deg: float,
    rpm: float,
    *,
    target_curvature: float | None = None,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    seed: int = 0,
    spin_up_s: float | None = None,
    window_s: float = 5.0,
    tol_deg: float = 0.4,
    max_evals: int = 8,
    progress: Callable[[int, int], None] | None = None,
    mixer: Mixer | None = None,
    engine: str | None = None,
    confirm_evals: int = 0,
    measure: Measure | None = None,
    confirm_run: SlopeRun | None = None,
    **sim_kwargs,
) -> Calibration:
    """Fit sliding and rolling friction (and a monolayer's end-plate friction) so the twin's free
    surface at ``rpm`` matches the target.

    ``spin_up_s`` None: ``default_spin_up_s(rpm)``. ``max_evals`` is the budget of the bracketing search
    per path (after the range runs: the low corner, the ``HIGH_EDGE`` points and a monolayer's
    ``PLATE_EDGE`` points). A target outside the reachable range is a ``SimError`` naming the range and
    the friction that would have to leave its range. Then at most ``confirm_evals`` confirming runs
    (``sim.calibrate_confirm``; 0: none, the search's closest run is the answer; ``CONFIRM_EVALS`` for
    an answer within ``tol_deg``) measured by ``measure`` (None: the particle twin's ``confirm_run``,
    default ``CONFIRM_RUN``) settle the answer.
    """
    target = _check_target(target_slope_deg)
    drum = mixer.drum if mixer is not None else drum
    rpm = _check_search(rpm, drum, target_curvature, tol_deg, max_evals)
    sign = 1.0 if target > 0 else -1.0  # compare magnitudes; report with the target's sign
    target_mag = abs(target)
    end_max = end_friction_max(mixer, sim_kwargs)
    paths = PATHS if target_curvature is not None else PATHS[:1]
    n_confirm = max(int(confirm_evals), 0)
    search_tol = max(tol_deg, SEARCH_TOL_DEG) if n_confirm > 0 else tol_deg
    total = 1 + len(HIGH_EDGE) + (len(PLATE_EDGE) if end_max > 0 else 0) + len(paths) * max_evals + n_confirm
    twin_kw = {"drum": drum, "recipe": recipe, "seed": seed, "window_s": window_s, "mixer": mixer, "engine": engine,
               "spin_up_s": default_spin_up_s(rpm) if spin_up_s is None else spin_up_s, **sim_kwargs}
    runs = _Runs(rpm, twin_kw, progress, total)
    ends = _range_ends(runs, rpm, end_max)
    lo_b, hi_b = ends.range_deg
    if not (lo_b - RANGE_TOL_DEG <= target_mag <= hi_b + RANGE_TOL_DEG):
        raise _out_of_range(target_mag, ends, rpm, end_max)
    if ends.top is not ends.plane_top and target_mag > ends.plane_top[3]:  # beyond the plane: the plates
        legs = [(PLATES, ends.plane_top, ends.top)]
    else:
        legs = [(p, ends.low, ends.plane_top) for p in paths]
    searched = {p: _search(runs, ends, p, lo, hi, target_mag, search_tol, max_evals) for p, lo, hi in legs}
    path, found = _choose([(p, _nearest(leg, target_mag)) for p, leg in searched.items()], target_mag, search_tol,
                          target_curvature, runs.curv)
    (f, r, e, s), se, n = found, math.nan, 0
    if n_confirm > 0:
        meas = measure if measure is not None else twin_measure(rpm, twin_kw, confirm_run or CONFIRM_RUN)
        (f, r, e, s), se, n = _confirm_leg(runs, ends, path, searched[path], meas, target_mag, tol_deg, n_confirm,
                                           found)
    return Calibration(
        friction=float(f), rolling=float(r), twin_slope_deg=float(sign * s),
        residual_deg=float(sign * (s - target_mag)),
        target_slope_deg=target, rpm=rpm, evaluations=len(runs.history), history=tuple(runs.history),
        range_deg=(float(lo_b), float(hi_b)), twin_curvature=float(runs.curv[found]),
        target_curvature=None if target_curvature is None else float(target_curvature), path=path,
        end_friction=float(e), end_friction_max=float(end_max), slope_se_deg=float(se), confirmations=n,
    )


def _confirm_leg(runs: _Runs, ends: _Ends, path: str, leg: Leg, measure: Measure, target: float, tol_deg: float,
                 max_evals: int, found: Run) -> tuple[Run, float, int]:
    """The confirming runs along ``path`` from its search runs ``leg`` (``sim.calibrate_confirm``), each kept
    in the history: the one nearest ``target`` with its standard error and how many ran (``found``, the
    search's answer, when none measured a slope)."""
    done = confirm(measure, lambda u: ends.leg_point(u, path), [u for u, _ in leg], [h[3] for _, h in leg], target,
                   tol_deg, max_evals)
    kept = [(runs.record(*c.point, c.slope_deg), c.measured.se_deg) for c in done]
    kept = [k for k in kept if math.isfinite(k[0][3])]
    if not kept:
        return found, math.nan, len(done)
    run, se = min(kept, key=lambda k: abs(k[0][3] - target))
    return run, se, len(done)


def _choose(candidates: list[tuple[str, Run]], target: float, tol_deg: float, target_curvature: float | None,
            curv: dict[Run, float]) -> tuple[str, Run]:
    """The slope decides first: only points within the tolerance (or the best slope found) compete;
    with a measured curvature the surface shape then picks among them."""
    def err(c: tuple[str, Run]) -> float:
        return abs(c[1][3] - target)

    best_err = min(err(c) for c in candidates)
    fits = [c for c in candidates if err(c) <= max(tol_deg, best_err)]
    if target_curvature is None:
        return min(fits, key=err)
    return min(fits, key=lambda c: abs(curv[c[1]] - float(target_curvature)))

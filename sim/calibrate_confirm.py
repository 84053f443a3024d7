"""The calibration's last step: the point its search found, confirmed by a long measurement.

A search run (one seed, a few seconds) is good to 2-4 deg on a monolayer, so the search's single
closest run is as likely chance as fit. Instead:

1. **The fit.** The slope along the search's path rises with friction; the search's runs, fitted by
   a non-decreasing curve (``monotone_fit``: pooled adjacent violators, so one noisy run cannot bend
   it backwards), give where the curve crosses the target (``fit_crossing``) and how steep it is there.
2. **The confirmation.** That point is measured by a confirming run (``sim.calibrate_slope.SlopeRun``:
   several seeds, long windows, its noise known from the seeds); while it is off the target by more
   than the tolerance, a secant step (through the confirmed points once they bracket the target, else
   along the fit's gradient) moves it, at most ``max_evals`` confirming runs in all.
3. **The answer** is the confirmed point nearest the target, with its measured slope and standard
   error: the residual a caller sees is a confirming run's, never a search run's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.calibrate_slope import Measure, Measured

Point = tuple[float, float, "float | None"]  # (sliding, rolling, end-plate friction or None: the twin's own)


def monotone_fit(y: Sequence[float]) -> np.ndarray:
    """The least-squares non-decreasing fit of ``y`` (in order; pooled adjacent violators)."""
    blocks: list[list[float]] = []  # [sum, count]
    for v in y:
        blocks.append([float(v), 1.0])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] > blocks[-1][0] / blocks[-1][1]:
            s, n = blocks.pop()
            blocks[-1][0] += s
            blocks[-1][1] += n
    return np.concatenate([np.full(int(n), s / n) for s, n in blocks]) if blocks else np.zeros(0)


def fit_crossing(us: Sequence[float], slopes: Sequence[float], target: float) -> tuple[float, float]:
    """(u, gradient): where the monotone fit of ``slopes`` against ``us`` crosses ``target`` (linear
    between the fitted levels; the nearer end when it does not cross) and the fit's gradient there
    (deg per unit u: the rise that brackets it, within a third and three times the whole fit's mean
    rise; NaN when the fit is flat)."""
    pts = sorted((float(u), float(s)) for u, s in zip(us, slopes, strict=True) if math.isfinite(s))
    if not pts:
        return math.nan, math.nan
    y = monotone_fit([p[1] for p in pts])
    lv_u: list[list[float]] = []  # the fit's levels: the u's of each run of equal fitted slopes
    lv_y: list[float] = []
    for (ui, _), yi in zip(pts, y, strict=True):
        if lv_y and yi == lv_y[-1]:
            lv_u[-1].append(ui)
        else:
            lv_u.append([ui])
            lv_y.append(float(yi))
    lu, ly = np.array([float(np.mean(g)) for g in lv_u]), np.array(lv_y)
    if ly.size < 2:
        return float(lu[0]), math.nan
    k = int(np.clip(np.searchsorted(ly, target), 1, ly.size - 1))  # the rise from level k-1 to k brackets it
    rise = (ly[-1] - ly[0]) / (lu[-1] - lu[0]) if lu[-1] > lu[0] else math.nan
    g = (ly[k] - ly[k - 1]) / (lu[k] - lu[k - 1]) if lu[k] > lu[k - 1] else rise
    g = min(max(g, rise / 3.0), rise * 3.0)  # two noisy runs close together: no wilder than the whole leg's
    return float(np.interp(target, ly, lu)), float(g)


@dataclass(frozen=True)
class Confirmed:
    """A confirming run at ``u`` on the path: the point and what it measured."""

    u: float
    point: Point
    measured: Measured

    @property
    def slope_deg(self) -> float:
        return self.measured.slope_deg


def _next_u(done: list[Confirmed], target: float, gradient: float) -> float:
    """The next point to confirm: the secant through the confirmed points once they bracket the target,
    else a step from the last along the secant of the last two (within a third and three times
    ``gradient``, the fit's) or, after one, along ``gradient``."""
    below = [c for c in done if c.slope_deg < target]
    above = [c for c in done if c.slope_deg > target]
    if below and above:
        lo = max(below, key=lambda c: c.u)
        hi = min(above, key=lambda c: c.u)
        if lo.u < hi.u:
            return lo.u + (target - lo.slope_deg) * (hi.u - lo.u) / (hi.slope_deg - lo.slope_deg)
    last, g = done[-1], gradient
    if len(done) > 1 and done[-2].u != last.u:
        sec = (last.slope_deg - done[-2].slope_deg) / (last.u - done[-2].u)
        g = min(max(sec, gradient / 3.0), gradient * 3.0) if math.isfinite(sec) else gradient
    return last.u - (last.slope_deg - target) / g


def confirm(measure: Measure, leg_point: Callable[[float], Point], us: Sequence[float], slopes: Sequence[float],
            target: float, tol_deg: float, max_evals: int) -> list[Confirmed]:
    """The confirming runs along one path (``leg_point(u)``, u in [0, 1]) from the search's runs there
    (``us``, ``slopes``; slope magnitudes, deg) to ``target`` (see the module doc). The list is in the
    order run; the caller takes the nearest."""
    u, g = fit_crossing(us, slopes, target)
    if not math.isfinite(u):
        return []
    if not (math.isfinite(g) and g > 0):
        g = max(abs(max(slopes) - min(slopes)), 1.0)  # a flat or noisy fit: the leg's span over its length
    done: list[Confirmed] = []
    for _ in range(max_evals):
        p = leg_point(u)
        done.append(Confirmed(u, p, measure(*p)))
        s = done[-1].slope_deg
        if not math.isfinite(s) or abs(s - target) <= tol_deg:
            break
        nxt = min(max(_next_u(done, target, g), 0.0), 1.0)
        if any(abs(nxt - c.u) < 1e-4 for c in done):  # pinned at an end, or no way on
            break
        u = nxt
    return done


__all__ = ["Confirmed", "Point", "confirm", "fit_crossing", "monotone_fit"]

"""The rig's history as a run sees it, and its golden batch beside the live MI (pure).

A run reads, at its start, its rig's recent runs and golden batch from the run catalogue
(``twin.catalogue.history``, on a thread of its own); this module is what it makes of them:

* :class:`GoldenCurve`: the golden batch's trend MI against run time, decimated, aligned with
  this run at run time 0 (both count from their workers' start), with the rig's usual spread
  at each of its times;
* :func:`usual_spread`, **the one rule of "the rig's usual spread"**: at each run time, the
  sample sd of the trend MI of the rig's recent runs there, where at least ``SPREAD_MIN_RUNS``
  runs reached that time; never below ``floor`` (the run's endpoint ``exit_band``: the MI drop
  its own endpoint detector takes for real, not noise), and the floor alone with fewer runs (an
  sd of one or two runs says nothing of the rig). In MI, at the same run time, because that is
  what the operator sees: the live curve against the golden one;
* :class:`BehindGolden`: a run more than the spread behind the golden batch, for a dwell, is a
  ``slower_than_golden`` record, once per episode (hysteresis: the episode ends when the run is
  back within half the spread for a dwell). An event, not a fault or an alarm: a slow batch is
  no danger;
* :class:`GoldenWatch`: the run bus's subscriber that feeds it each frame's trend MI.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin.records import FrameReading, Record, SlowerThanGolden

SPREAD_MIN_RUNS = 3
"""Runs that must have reached a run time for their sd to be the spread there."""
CLEAR_FRACTION = 0.5
"""An episode ends once the run is back within this fraction of the spread (hysteresis)."""


@dataclass(frozen=True)
class PastRun:
    """One of the rig's earlier runs, as the history panel lists it (unix s; MI 0..1)."""

    id: str
    started_s: float
    mode: str
    mixing_time_s: float | None  # None: the batch did not reach its endpoint
    final_mi: float | None
    golden: bool = False


@dataclass(frozen=True, eq=False)
class GoldenCurve:
    """The golden batch's trend MI at run times ``t_s`` (increasing), and the rig's usual
    spread at each (:func:`usual_spread`, from ``runs`` runs)."""

    run_id: str
    started_s: float
    t_s: np.ndarray
    mi: np.ndarray
    spread: np.ndarray
    runs: int = 0

    def mi_at(self, t_s: np.ndarray) -> np.ndarray:
        """The golden MI at each of ``t_s`` (NaN before its first or after its last time)."""
        t = np.asarray(t_s, dtype=float)
        out = np.full(t.shape, math.nan)
        if self.t_s.size:
            inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
            out[inside] = np.interp(t[inside], self.t_s, self.mi)
        return out

    def at(self, t_s: float) -> tuple[float, float] | None:
        """(golden MI, spread) at run time ``t_s``; None outside the golden batch's run."""
        if not self.t_s.size or not self.t_s[0] <= t_s <= self.t_s[-1]:
            return None
        return float(np.interp(t_s, self.t_s, self.mi)), float(np.interp(t_s, self.t_s, self.spread))


def curve_at(t_s: np.ndarray, curve_t_s: np.ndarray, curve_mi: np.ndarray) -> np.ndarray:
    """A run's trend MI (``curve_t_s``, ``curve_mi``: any order, NaN allowed) at ``t_s``: NaN
    outside the times it covers."""
    ct, cm = np.asarray(curve_t_s, dtype=float), np.asarray(curve_mi, dtype=float)
    ok = np.isfinite(ct) & np.isfinite(cm)
    ct, cm = ct[ok], cm[ok]
    t = np.asarray(t_s, dtype=float)
    out = np.full(t.shape, math.nan)
    if ct.size:
        order = np.argsort(ct, kind="stable")
        ct, cm = ct[order], cm[order]
        inside = (t >= ct[0]) & (t <= ct[-1])
        out[inside] = np.interp(t[inside], ct, cm)
    return out


def usual_spread(t_s: np.ndarray, curves: Sequence[tuple[np.ndarray, np.ndarray]], floor: float,
                 min_runs: int = SPREAD_MIN_RUNS) -> np.ndarray:
    """The rig's usual spread of trend MI at each run time of ``t_s`` (module doc): the sample sd
    across ``curves`` (each run's ``(t_s, trend MI)``) where at least ``min_runs`` of them
    reached that time, never below ``floor``; ``floor`` where fewer did."""
    t = np.asarray(t_s, dtype=float)
    if not curves:
        return np.full(t.shape, float(floor))
    vals = np.stack([curve_at(t, ct, cm) for ct, cm in curves])
    ok = np.isfinite(vals)
    n = ok.sum(axis=0)
    mean = np.where(ok, vals, 0.0).sum(axis=0) / np.maximum(n, 1)
    sq = np.where(ok, (vals - mean) ** 2, 0.0).sum(axis=0)
    sd = np.sqrt(sq / np.maximum(n - 1, 1))
    return np.where(n >= max(2, min_runs), np.maximum(sd, floor), float(floor))


@dataclass(frozen=True)
class Deviation:
    """This run against the golden batch at one run time (MI)."""

    t_s: float
    mi: float
    golden_mi: float
    spread: float

    @property
    def deviation(self) -> float:
        """mi - golden_mi: negative is behind (less mixed than the golden batch was then)."""
        return self.mi - self.golden_mi

    @property
    def behind(self) -> bool:
        """More than the usual spread behind."""
        return self.deviation < -self.spread


def deviation(golden: GoldenCurve | None, t_s: float | None, mi: float | None) -> Deviation | None:
    """This run's trend MI ``mi`` at ``t_s`` against ``golden`` (None: nothing to compare)."""
    if golden is None or t_s is None or mi is None or not (math.isfinite(t_s) and math.isfinite(mi)):
        return None
    at = golden.at(t_s)
    return None if at is None else Deviation(t_s, mi, at[0], at[1])


@dataclass(frozen=True, eq=False)
class RigHistory:
    """What the dashboard's history panel shows: ``state`` "none" (no catalogue read: a
    dashboard outside a run), "loading", "ready" or "unavailable" (``message`` says why);
    the rig's recent runs, newest first, and its golden batch (None: none marked)."""

    state: str = "none"
    rig: str | None = None
    runs: tuple[PastRun, ...] = ()
    golden: GoldenCurve | None = None
    message: str = ""


class BehindGolden:
    """Episodes of a run behind its golden batch (module doc): :meth:`update` with each trend
    MI; a ``SlowerThanGolden`` record when an episode starts (None otherwise)."""

    def __init__(self, golden: GoldenCurve, dwell_s: float, clear_fraction: float = CLEAR_FRACTION) -> None:
        self.golden = golden
        self.dwell_s = float(dwell_s)
        self.clear_fraction = float(clear_fraction)
        self.behind = False  # in an episode
        self._since: float | None = None  # when the condition to change state started to hold

    def update(self, t_s: float, mi: float | None) -> SlowerThanGolden | None:
        d = deviation(self.golden, t_s, mi)
        if d is None:  # nothing to compare (an invalid frame, past the golden batch's end)
            self._since = None
            return None
        change = d.behind if not self.behind else d.deviation > -self.clear_fraction * d.spread
        if not change:
            self._since = None
            return None
        self._since = t_s if self._since is None else self._since
        if t_s - self._since < self.dwell_s:
            return None
        self._since = None
        self.behind = not self.behind
        if not self.behind:
            return None
        return SlowerThanGolden(t_s=t_s, golden_run=self.golden.run_id, mi=d.mi, golden_mi=d.golden_mi,
                                deviation=d.deviation, spread=d.spread)


class GoldenWatch:
    """The run bus's subscriber (``record``) that compares each frame's trend MI with the golden
    batch, once :meth:`set_golden` has given one (from the history thread: the reference is
    swapped whole, never changed in place), and publishes what :class:`BehindGolden` finds."""

    def __init__(self, publish: Callable[[Record], None], dwell_s: float) -> None:
        self.publish = publish
        self.dwell_s = dwell_s
        self._watch: BehindGolden | None = None

    def set_golden(self, golden: GoldenCurve | None) -> None:
        self._watch = None if golden is None else BehindGolden(golden, self.dwell_s)

    def record(self, rec: Record) -> None:
        watch = self._watch
        if watch is None or not isinstance(rec, FrameReading) or not rec.valid:
            return
        found = watch.update(rec.t_s, rec.trend_mi)
        if found is not None:
            self.publish(found)

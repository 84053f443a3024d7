"""A run's view of its rig's history, read from the catalogue at the run's start.

:class:`HistoryJob` runs once on a thread of the run (``LiveLoop.run_beside``), never on the
dashboard's: it lists the rig's recent runs, reads the golden batch's trend MI and that of the
rig's recent runs (only up to the golden batch's end; each decimated as it streams, so a long
log costs time, not memory), and hands the result to the dashboard's state and to the run's
``GoldenWatch`` (``twin.live.golden``). It is read once: a run compares itself with the
reference it started with, even if another drum's run ends or another batch is marked golden
meanwhile (the next run sees them). A catalogue that cannot be read is a sentence in the panel
(the run's start already logged a ``catalogue_unavailable`` record), never the run's end.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from twin import runread
from twin.catalogue.store import Catalogue, RunFilter
from twin.catalogue.summary import RunSummary
from twin.live.golden import GoldenCurve, PastRun, RigHistory, usual_spread
from twin.report.decimate import MinMax
from twin.report.frames import finite, numbers

log = logging.getLogger("drumtwin.catalogue")

HISTORY_ROWS = 10
"""Recent runs the panel lists."""
SPREAD_RUNS = 10
"""Recent runs of the rig whose trend MI gives its usual spread (``twin.live.golden.usual_spread``)."""
CURVE_BUCKETS = 500
"""Min/max buckets of a curve read (at most ~2,000 points: a plot's width)."""


def trend_curve(run_dir: Path | str, until_s: float | None = None, buckets: int = CURVE_BUCKETS,
                stop: threading.Event | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A run's trend MI against run time from its ``frames.csv`` (finite rows only), decimated
    (``twin.report.decimate.MinMax``); read up to ``until_s`` of run time (None: all)."""
    run = runread.open_run(run_dir)
    curve = MinMax(buckets)
    for header, rows in runread.frame_batches(run):
        if "trend_mi" not in header:
            break
        it, im = header.index("t_s"), header.index("trend_mi")
        t, _ = numbers([r[it] for r in rows])
        mi, _ = numbers([r[im] for r in rows])
        ok = finite(t) & np.isfinite(mi)
        t, mi = t[ok], mi[ok]
        past = np.flatnonzero(t > until_s) if until_s is not None else np.zeros(0, dtype=np.int64)
        if past.size:  # the first row past it is the last one read
            t, mi = t[: past[0] + 1], mi[: past[0] + 1]
        curve.add(t, mi)
        if past.size or (stop is not None and stop.is_set()):
            break
    t, mi = curve.points()
    order = np.argsort(t, kind="stable")
    return t[order], mi[order]


def past_run(s: RunSummary) -> PastRun:
    return PastRun(id=s.id, started_s=s.started_s, mode=s.mode, mixing_time_s=s.mixing_time_s if s.mixed else None,
                   final_mi=s.final_mi, golden=s.golden)


def load_history(url: str | None, runs_root: Path | str, rig: str, this_run: str | None, floor_mi: float,
                 stop: threading.Event | None = None) -> RigHistory:
    """The rig's history as ``this_run`` (its id; left out) sees it (module doc)."""
    with Catalogue.open(url, runs_root) as cat:
        recent = [s for s in cat.list(RunFilter(rig=rig, last=max(HISTORY_ROWS, SPREAD_RUNS) + 1))
                  if s.id != this_run]
        golden = cat.golden_of(rig)
    if golden is not None and golden.id == this_run:
        golden = None
    runs = tuple(past_run(s) for s in recent[:HISTORY_ROWS])
    if golden is None:
        return RigHistory("ready", rig, runs)
    g_t, g_mi = trend_curve(golden.path, stop=stop)
    if g_t.size < 2:
        return RigHistory("ready", rig, runs, message=f"the golden batch {golden.id[:8]} logged no trend MI")
    pool = [s for s in recent if s.ended != "running"][:SPREAD_RUNS]
    curves = [(g_t, g_mi) if s.id == golden.id else trend_curve(s.path, float(g_t[-1]), stop=stop) for s in pool]
    spread = usual_spread(g_t, curves, floor_mi)
    curve = GoldenCurve(golden.id, golden.started_s, g_t, g_mi, spread, runs=len(curves))
    return RigHistory("ready", rig, runs, curve)


class HistoryJob:
    """Reads the rig's history once (``run``, on the run's ``drumtwin-history`` thread) and hands it
    to ``show`` (the dashboard's state) and ``use_golden`` (the run's ``GoldenWatch``).
    ``this_run``: the run's id once it is registered (None: not registered)."""

    def __init__(self, url: str | None, runs_root: Path | str, rig: str, this_run: Callable[[], str | None],
                 floor_mi: float, show: Callable[[RigHistory], None],
                 use_golden: Callable[[GoldenCurve | None], None]) -> None:
        self.url, self.runs_root, self.rig = url, Path(runs_root), rig
        self.this_run, self.floor_mi = this_run, floor_mi
        self.show, self.use_golden = show, use_golden

    def run(self, stop: threading.Event) -> None:
        self.show(RigHistory("loading", self.rig))
        try:
            history = load_history(self.url, self.runs_root, self.rig, self.this_run(), self.floor_mi, stop)
        except Exception as exc:  # the history is a convenience: nothing it meets may end the run
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            log.warning("the rig's history could not be read from the run catalogue: %s", first)
            log.debug("history failure", exc_info=True)
            self.show(RigHistory("unavailable", self.rig, message=first))
            return
        if not stop.is_set():
            self.use_golden(history.golden)
            self.show(history)

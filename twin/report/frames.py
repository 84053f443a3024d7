"""What the report keeps of a run's frames: one streaming pass over ``frames.csv``, bounded
whatever its length.

Per batch of rows (``twin.runread.frame_batches``): the columns it needs parsed as numbers
(``numbers``), a row whose ``t_s`` is not a finite number within ``PLOT_LIMIT`` dropped (and
counted), a cell that is not a number, infinite or beyond ``PLOT_LIMIT`` blanked (and counted);
then each plotted column decimated (``twin.report.decimate.MinMax``), the drive energy
integrated, the endpoint's changes read from the live detector's ``mixed`` column (or, for a
log of a release without it, the detector replayed on the raw MI: at most ``REPLAY_MAX_ROWS``
rows), and the first row at which the mill reached each AUTO move's rpm (``twin.report.ttm``).
Rows are taken in file order, which is time order in a log the run wrote.
"""

from __future__ import annotations

import math

import numpy as np

from twin.report.decimate import MinMax
from twin.report.events import PLOT_LIMIT, Changes, Move
from twin.runread import FRAMES_FILE, Skips

PLOTS: dict[str, tuple[tuple[str, str], ...]] = {
    "mi": (("mi", "raw MI"), ("trend_mi", "Kalman trend"), ("twin_mi", "twin")),
    "rpm": (("rpm_setpoint", "set"), ("rpm_actual", "actual")),
    "slope": (("slope_deg", "camera"), ("twin_slope_deg", "twin")),
}
"""The report's line plots: section -> (column, legend) of each line (x: ``t_s``)."""
PLOTTED = tuple(name for lines in PLOTS.values() for name, _ in lines)
REPLAY_MAX_ROWS = 36_000
"""Rows of raw MI the endpoint detector is replayed on, for a log without the ``mixed`` column
(one hour at 10 fps; ~100 us a row: a Kalman step and the detector)."""


def numbers(cells: list[str]) -> tuple[np.ndarray, np.ndarray | None]:
    """The cells as floats (an empty cell: NaN) and a mask of the cells that are not numbers
    (None: every cell is one)."""
    try:
        return np.array(cells, dtype=float), None
    except ValueError:
        pass
    try:
        return np.array([c or "nan" for c in cells], dtype=float), None
    except ValueError:
        pass
    out, bad = np.full(len(cells), math.nan), np.zeros(len(cells), dtype=bool)
    for i, c in enumerate(cells):
        if c:
            try:
                out[i] = float(c)
            except ValueError:
                bad[i] = True
    return out, bad


def finite(v: np.ndarray) -> np.ndarray:
    """Finite and within ``PLOT_LIMIT``: what a plot can place."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(v) & (np.abs(v) <= PLOT_LIMIT)


class FrameScan:
    """The streaming pass (module doc): ``add(header, rows)`` per batch, then read the fields."""

    def __init__(self, skips: Skips, *, replay: bool = False, moves: list[Move] | None = None) -> None:
        self.skips = skips
        self.n = 0
        self.t_max: float | None = None
        self.mode: str | None = None
        self.last_trend: tuple[float, float, float | None] | None = None  # t, trend MI, rpm actual
        self.series: dict[str, MinMax] = {}
        self.energy: Energy | None = None
        self.changes: Changes | None = None
        self._mixed: bool | None = None
        self.replay = Replay() if replay else None
        self.reach = Reach(moves or [])

    def _column(self, header: tuple[str, ...], rows: list[list[str]], name: str) -> np.ndarray | None:
        """One column as floats; a cell that is not a finite number within PLOT_LIMIT is NaN, counted."""
        if name not in header:
            return None
        i = header.index(name)
        y, bad = numbers([r[i] for r in rows])
        if bad is not None:
            self.skips.add(FRAMES_FILE, f"{name} not a number", int(bad.sum()), what="cell")
        with np.errstate(invalid="ignore"):
            huge = np.isinf(y) | (np.abs(y) > PLOT_LIMIT)
        if huge.any():
            self.skips.add(FRAMES_FILE, f"{name} infinite or beyond ±{PLOT_LIMIT:g}", int(huge.sum()), what="cell")
            y[huge] = math.nan
        return y

    def _times(self, header: tuple[str, ...], rows: list[list[str]]) -> tuple[np.ndarray, list[list[str]]]:
        """``t_s`` of the rows and the rows, those without a usable time dropped and counted."""
        i = header.index("t_s")
        t, bad = numbers([r[i] for r in rows])
        ok = finite(t)
        if ok.all():
            return t, rows
        n_bad = 0 if bad is None else int(bad.sum())
        empty = sum(1 for r in rows if r[i] == "")
        self.skips.add(FRAMES_FILE, "t_s not a number", n_bad)
        self.skips.add(FRAMES_FILE, "t_s empty", empty)
        self.skips.add(FRAMES_FILE, f"t_s not a finite number within ±{PLOT_LIMIT:g}", int((~ok).sum()) - n_bad - empty)
        keep = np.flatnonzero(ok)
        return t[keep], [rows[k] for k in keep]

    def add(self, header: tuple[str, ...], rows: list[list[str]]) -> None:
        t, rows = self._times(header, rows)
        if not rows:
            return
        self.n += len(rows)
        self.t_max = float(t.max()) if self.t_max is None else max(self.t_max, float(t.max()))
        cols = {c: self._column(header, rows, c) for c in (*PLOTTED, "power_w", "mixed")}
        for c in PLOTTED:
            y = cols[c]
            if y is not None:
                self.series.setdefault(c, MinMax()).add(t, y)
        if "mode" in header:
            k = header.index("mode")
            self.mode = next((r[k][:20] for r in reversed(rows) if r[k]), self.mode)
        self._last_trend(t, cols["trend_mi"], cols["rpm_actual"])
        if cols["power_w"] is not None:
            self.energy = self.energy or Energy()
            self.energy.add(t, cols["power_w"])
        if cols["mixed"] is not None:
            self._endpoint(t, cols["mixed"], header, rows)
        if self.replay is not None and cols["mi"] is not None:
            self.replay.add(t, cols["mi"])
        if cols["rpm_actual"] is not None:
            self.reach.add(t, cols["rpm_actual"])

    def _last_trend(self, t: np.ndarray, trend: np.ndarray | None, rpm: np.ndarray | None) -> None:
        if trend is None:
            return
        ok = np.flatnonzero(np.isfinite(trend))
        if ok.size:
            k = int(ok[-1])
            r = None if rpm is None or not math.isfinite(rpm[k]) else float(rpm[k])
            self.last_trend = (float(t[k]), float(trend[k]), r)

    def _endpoint(self, t: np.ndarray, mixed: np.ndarray, header: tuple[str, ...], rows: list[list[str]]) -> None:
        """The live detector's state in each row: a change of it is a change of the endpoint (the
        row's ``mixing_time_s`` read only there)."""
        self.changes = self.changes or Changes()
        ok = np.flatnonzero(np.isfinite(mixed))
        state = mixed[ok] >= 0.5
        prev = np.r_[self._mixed if self._mixed is not None else False, state[:-1]]
        i_mt = header.index("mixing_time_s") if "mixing_time_s" in header else -1
        for k in ok[np.flatnonzero(state != prev)]:
            on = bool(mixed[k] >= 0.5)
            mt = float(numbers([rows[k][i_mt]])[0][0]) if on and i_mt >= 0 else math.nan
            self.changes.add(float(t[k]), "mixed" if on else "unmixed", mt if abs(mt) <= PLOT_LIMIT else None,
                             "the live detector (frames.csv's mixed column)")
        if ok.size:
            self._mixed = bool(state[-1])


class Energy:
    """Drive energy used: ``power_w`` integrated over run time (trapezoids between consecutive
    rows with a power), streamed; its running total decimated for the plot."""

    def __init__(self) -> None:
        self.used_j = 0.0
        self.n = 0
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.sum_w = 0.0
        self._last: tuple[float, float] | None = None
        self.curve = MinMax()

    def add(self, t: np.ndarray, p: np.ndarray) -> None:
        ok = np.isfinite(p)
        tt, pp = t[ok], p[ok]
        if tt.size == 0:
            return
        if self._last is not None:
            tt, pp = np.r_[self._last[0], tt], np.r_[self._last[1], pp]
        steps = np.r_[0.0, 0.5 * (pp[1:] + pp[:-1]) * np.diff(tt)]
        cum = self.used_j + np.cumsum(steps)
        if self._last is not None:
            tt, pp, cum = tt[1:], pp[1:], cum[1:]
        self.used_j = float(cum[-1])
        self.t_first = float(tt[0]) if self.t_first is None else self.t_first
        self.t_last, self._last = float(tt[-1]), (float(tt[-1]), float(pp[-1]))
        self.n += tt.size
        self.sum_w += float(pp.sum())
        with np.errstate(invalid="ignore"):
            self.curve.add(tt, np.where(np.abs(cum) <= PLOT_LIMIT, cum, math.nan))


class Replay:
    """The endpoint detector replayed on the raw MI of a log without the live detector's
    ``mixed`` column (at most ``REPLAY_MAX_ROWS`` rows)."""

    def __init__(self) -> None:
        from control.endpoint import EndpointDetector
        from control.trend import MITrend
        from twin.run.settings import endpoint_config, trend_config

        self.trend, self.detector = MITrend(trend_config()), EndpointDetector(endpoint_config())
        self.changes = Changes()
        self.n = 0
        self.skipped = 0

    def add(self, t: np.ndarray, mi: np.ndarray) -> None:
        room = max(0, REPLAY_MAX_ROWS - self.n)
        self.skipped += max(0, t.size - room)
        for ti, mi_i in zip(t[:room].tolist(), mi[:room].tolist(), strict=True):
            est = self.trend.update(ti, mi_i, 0.0)
            st = self.detector.update(ti, mi_i, est.level, bool(est.valid and est.settled))
            if st.changed:
                self.changes.add(st.t_s, st.changed, st.mixing_time_s, st.reason, st.plateau_mi)
        self.n += min(room, t.size)

    @property
    def plateau_mi(self) -> float | None:
        return self.detector.plateau_mi if self.detector.mixed else None


class Reach:
    """For each AUTO move (``twin.report.ttm``): the first row, between the move and the next,
    at which the mill's actual rpm is within 1 rpm of the move's."""

    def __init__(self, moves: list[Move]) -> None:
        self.moves = sorted(moves, key=lambda m: m.t_s)
        self.starts = np.array([m.t_s for m in self.moves], dtype=float)
        self.ends = np.array([m.end_s for m in self.moves], dtype=float)
        self.rpms = np.array([m.rpm for m in self.moves], dtype=float)
        self.reached = np.full(len(self.moves), math.nan)

    def add(self, t: np.ndarray, rpm: np.ndarray) -> None:
        if not self.moves:
            return
        k = np.searchsorted(self.starts, t, side="right") - 1
        kk = np.clip(k, 0, None)
        with np.errstate(invalid="ignore"):
            hit = (k >= 0) & (t < self.ends[kk]) & (np.abs(rpm - self.rpms[kk]) <= 1.0)
        idx, first = np.unique(kk[hit], return_index=True)
        new = np.isnan(self.reached[idx])
        self.reached[idx[new]] = t[hit][first[new]]

    def first(self) -> tuple[Move, float] | None:
        """The first move (in time) whose rpm the mill reached, and when."""
        done = np.flatnonzero(np.isfinite(self.reached))
        return None if done.size == 0 else (self.moves[int(done[0])], float(self.reached[done[0]]))

"""The golden batch beside the live MI (issue 40): the one rule of the rig's usual spread, the
``slower_than_golden`` episodes (hysteresis, once per episode, no fault), the rig's history read
from a real catalogue of run folders, and the dashboard's history panel text."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from tests.catalogue_runs import RunSpec, frame, make_run, stamp
from tests.cli import cli
from twin.catalogue.history import HistoryJob, load_history, trend_curve
from twin.dashboard.history import NO_HISTORY, golden_column, history_markdown
from twin.live.golden import BehindGolden, GoldenCurve, GoldenWatch, PastRun, RigHistory, deviation, usual_spread
from twin.records import FrameReading, Record, SlowerThanGolden
from twin.runlog import RunLog
from twin.state import Panel

FLOOR = 0.05


def flat(t_end: float, mi: float, step: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, t_end + 1e-9, step)
    return t, np.full(t.size, mi)


def test_the_usual_spread_is_the_runs_sd_at_that_time_never_below_the_floor() -> None:
    t = np.array([0.0, 10.0, 20.0, 30.0])
    levels = [0.80, 0.90, 1.00, 0.70]
    curves = [flat(30.0, mi) for mi in levels]
    s = usual_spread(t, curves, FLOOR)
    assert s == pytest.approx(np.full(4, np.std(levels, ddof=1)))  # sample sd: 0.129
    assert usual_spread(t, [flat(30.0, 0.9 + 0.001 * i) for i in range(5)], FLOOR) == pytest.approx(np.full(4, FLOOR))
    # two runs say nothing of the rig: the floor, however far apart they are
    assert usual_spread(t, [flat(30.0, 0.2), flat(30.0, 0.9)], FLOOR) == pytest.approx(np.full(4, FLOOR))
    assert usual_spread(t, [], FLOOR) == pytest.approx(np.full(4, FLOOR))
    # a time only two of four runs reached: the floor there; a curve given backwards, with a gap, reads the same
    short = [flat(12.0, 0.5), flat(12.0, 0.95)]
    back = (curves[0][0][::-1].copy(), curves[0][1][::-1].copy())
    back[1][3] = math.nan
    s = usual_spread(t, [back, curves[1], *short], FLOOR)
    assert s[0] == pytest.approx(np.std([0.8, 0.9, 0.5, 0.95], ddof=1)) and s[1] == pytest.approx(s[0])
    assert s[2:] == pytest.approx([FLOOR, FLOOR])


def golden(mi: float = 0.9, t_end: float = 100.0, spread: float = 0.04) -> GoldenCurve:
    t, g = flat(t_end, mi, 1.0)
    return GoldenCurve("g" * 36, 1.7e9, t, g, np.full(t.size, spread), runs=4)


def test_a_run_behind_the_golden_batch_is_one_event_per_episode_with_hysteresis() -> None:
    w = BehindGolden(golden(0.9, spread=0.04), dwell_s=5.0)
    events: list[tuple[float, SlowerThanGolden]] = []

    def feed(t0: float, t1: float, mi: float) -> None:
        for t in np.arange(t0, t1, 0.5):
            if (e := w.update(float(t), mi)) is not None:
                events.append((float(t), e))

    feed(0, 10, 0.88)  # within the spread
    feed(10, 14, 0.80)  # behind, for less than the dwell
    feed(14, 16, 0.89)
    assert events == []
    feed(16, 30, 0.80)  # behind for 14 s: one event, after the dwell
    assert [t for t, _ in events] == [21.0]
    e = events[0][1]
    assert (e.golden_run, e.mi, e.golden_mi, e.spread) == ("g" * 36, 0.80, 0.9, 0.04)
    assert e.deviation == pytest.approx(-0.10) and e.kind == "slower_than_golden"
    feed(30, 50, 0.875)  # back within the spread, but not within half of it: still the same episode
    feed(50, 53, 0.80)
    assert len(events) == 1 and w.behind
    feed(53, 60, 0.89)  # within half the spread for the dwell: the episode is over
    assert not w.behind
    feed(60, 70, 0.70)  # a second episode
    assert [t for t, _ in events] == [21.0, 65.0]
    feed(70, 130, 0.5)  # past the golden batch's end (100 s): nothing to compare, no event
    assert len(events) == 2 and w.update(5.0, math.nan) is None


def test_the_watch_publishes_from_the_frames_it_sees_once_it_has_a_golden_batch() -> None:
    got: list[Record] = []
    watch = GoldenWatch(got.append, dwell_s=2.0)

    def frames(t0: float, t1: float, mi: float, valid: bool = True) -> None:
        for t in np.arange(t0, t1, 0.5):
            f = frame(float(t), mi, 5.0)
            watch.record(f if valid else FrameReading(**{**f.as_dict(), "valid": False}))

    frames(0, 10, 0.5)  # no golden batch yet: nothing to compare with
    watch.set_golden(golden(0.9))
    frames(10, 20, 0.5, valid=False)  # invalid frames are not compared
    assert got == []
    frames(20, 30, 0.5)
    assert [type(r) for r in got] == [SlowerThanGolden] and got[0].t_s == 22.0
    watch.set_golden(None)
    frames(30, 40, 0.5)
    assert len(got) == 1


def test_deviation_and_the_golden_column_are_nan_or_none_outside_the_golden_batch() -> None:
    g = golden(0.9, t_end=50.0)
    d = deviation(g, 10.0, 0.82)
    assert d is not None and d.deviation == pytest.approx(-0.08) and d.behind and d.spread == 0.04
    assert deviation(g, 60.0, 0.82) is None and deviation(None, 10.0, 0.8) is None
    assert deviation(g, None, 0.8) is None and deviation(g, 10.0, math.nan) is None
    col = golden_column(RigHistory("ready", "pmma", (), g), np.array([-1.0, 0.0, 25.0, 50.0, 51.0]))
    assert np.isnan(col[[0, 4]]).all() and col[1:4] == pytest.approx([0.9] * 3)
    assert np.isnan(golden_column(RigHistory("ready", "pmma"), np.arange(3.0))).all()


def test_the_history_panel_says_what_there_is() -> None:
    assert NO_HISTORY in history_markdown(RigHistory("ready", "demo"), Panel())
    runs = (PastRun("a" * 36, time.mktime((2026, 3, 4, 10, 30, 0, 0, 0, -1)), "auto", 41.25, 0.912, golden=True),
            PastRun("b" * 36, time.mktime((2026, 3, 3, 9, 5, 0, 0, 0, -1)), "off", None, 0.774))
    md = history_markdown(RigHistory("ready", "pmma", runs), Panel())
    assert "| 2026-03-04 10:30 ★ | auto | 41.2 | 0.912 |" in md and "| 2026-03-03 09:05 | off | – | 0.774 |" in md
    assert "No golden batch" in md and NO_HISTORY not in md
    md = history_markdown(RigHistory("ready", "pmma", runs, golden(0.9)), Panel(t_s=30.0, trend_mi=0.8))
    assert "Deviation now: **-0.100**" in md and "behind the golden batch" in md
    md = history_markdown(RigHistory("ready", "pmma", runs, golden(0.9)), Panel(t_s=30.0, trend_mi=0.88))
    assert "**-0.020**" in md and "within the rig's usual spread" in md
    md = history_markdown(RigHistory("ready", "pmma", runs, golden(0.9)), Panel(t_s=30.0, trend_mi=0.95))
    assert "**+0.050**" in md and "ahead of the golden batch" in md
    down = RigHistory("unavailable", "x", message="disk on fire")
    assert "could not be read (disk on fire)" in history_markdown(down, Panel())


def _curve_run(d: Path, mi: float, t_end: float, start_s: float) -> Path:
    """A run folder of the demo rig whose trend MI is ``mi`` from 0 to ``t_end`` s."""
    make_run(d, RunSpec(rig="demo", final_mi=mi, frames=int(t_end / 0.5) + 1, mixing_time_s=20.0))
    stamp(d, start_s)
    return d


def test_the_history_is_read_from_the_catalogue_with_the_golden_curve_and_the_spread(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    t0 = time.time() - 86400
    levels = {"r0": 0.96, "r1": 0.84, "r2": 0.93, "r3": 0.80}
    for i, (name, mi) in enumerate(levels.items()):
        _curve_run(runs / name, mi, 30.0 if name != "r3" else 10.0, t0 + 600 * i)
    make_run(runs / "other", RunSpec(rig="glass"))
    assert cli("runs", "list", "--runs-dir", runs).code == 0
    ids = {Path(s.path).name: s.id for s in _list(runs)}
    assert cli("runs", "golden", ids["r0"], "--runs-dir", runs).code == 0
    h = load_history(None, runs, "demo", this_run=ids["r2"], floor_mi=FLOOR)
    assert h.state == "ready" and [r.id for r in h.runs] == [ids["r3"], ids["r1"], ids["r0"]]  # newest first, not r2
    assert [r.golden for r in h.runs] == [False, False, True]
    g = h.golden
    assert g is not None and g.run_id == ids["r0"] and g.runs == 3
    assert g.t_s[0] == 0.0 and g.t_s[-1] == 30.0 and np.all(g.mi == 0.96)
    early, late = g.at(5.0), g.at(20.0)
    assert early == pytest.approx((0.96, np.std([0.96, 0.84, 0.80], ddof=1)))  # r3 ran 10 s: 3 runs at 5 s
    assert late == pytest.approx((0.96, FLOOR))  # two runs at 20 s: the floor
    assert load_history(None, runs, "glass", None, FLOOR).golden is None
    assert load_history(None, runs, "steel", None, FLOOR).runs == ()
    t, mi = trend_curve(runs / "r1", until_s=5.0)
    assert t[0] == 0.0 and 5.0 < t[-1] <= 6.0 and np.all(mi == 0.84)  # read until past 5 s, no further


def _list(runs: Path):
    from twin.catalogue.store import Catalogue

    with Catalogue.open(None, runs) as cat:
        return cat.list()


def test_a_catalogue_that_cannot_be_read_is_a_sentence_never_an_exception(tmp_path: Path) -> None:
    import threading

    bad = tmp_path / "catalogue.sqlite"
    bad.write_bytes(b"\x13" * 4096)
    shown: list[RigHistory] = []
    used: list[object] = []
    HistoryJob(str(bad), tmp_path, "demo", lambda: None, FLOOR, shown.append, used.append).run(threading.Event())
    assert [h.state for h in shown] == ["loading", "unavailable"] and "runs rebuild" in shown[-1].message
    assert used == []  # no golden batch handed to the watch


def test_a_run_log_of_a_golden_episode_holds_one_event_and_no_fault(tmp_path: Path) -> None:
    """The watch on a real run's bus: the record goes to events.jsonl as an event, not a fault."""
    from twin.live.events import RunEvents
    from twin.runlog import read_events
    from twin.state import LiveState

    state = LiveState()
    with RunLog(tmp_path / "run") as log:
        events = RunEvents(log, state)
        watch = GoldenWatch(events.publish, dwell_s=2.0)
        events.bus.subscribe(watch.record)
        watch.set_golden(golden(0.95))
        for t in np.arange(0.0, 20.0, 0.5):
            events.publish(frame(float(t), 0.7, 5.0))
    kinds = [e["kind"] for e in read_events(tmp_path / "run")]
    assert kinds == ["slower_than_golden"] and events.n_faults == 0 and state.alarms == ()

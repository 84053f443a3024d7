"""The live loop's workers with fakes: supervisor worker, process worker, what-if worker,
the run view and the root's controls (milliseconds; no threads, no sim, no serial)."""

from __future__ import annotations

import math
import queue
import threading
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from control.decision import Mode, PredictionRequest, PredictionResult
from control.protocol import MillStatus
from control.supervisor import Supervisor
from control.trend import MITrend, TrendEstimate
from tests.control.supervisor_values import worked_config
from tests.twin.test_mill_worker import FakeLink, Sink
from twin.live.camera import CameraReading, CameraWorker, ProcessWorker, put_dropping_oldest
from twin.live.commands import Recalibrate, Reseed, RunStudy, SetManualRpm, SetMode, SetRpm, StopMill
from twin.live.snapshots import CameraInfo, FrameInfo, Latest, MillSnapshot, RunView, TwinInfo
from twin.live.supervise import SupervisorWorker
from twin.live.whatif import WhatIfWorker
from twin.state import FRAME_ROW_COLUMNS, SERIES, FrameRow, LiveState


class Wall:
    """A settable monotonic clock (s)."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Boxes:
    def __init__(self, mode: str = "auto") -> None:
        self.camera: Latest[CameraInfo] = Latest(CameraInfo())
        self.frames: Latest[FrameInfo] = Latest(FrameInfo())
        self.mill: Latest[MillSnapshot] = Latest(MillSnapshot())
        self.twin: Latest[TwinInfo] = Latest(TwinInfo())
        self.mode: Latest[str] = Latest(mode)
        self.wall = Wall()
        self.view = RunView(1.0, self.camera, self.frames, self.mill, self.twin, self.mode,
                            clock_now=lambda: 0.0, monotonic=self.wall)

    def frame(self, t_s: float, level: float = 0.9, valid: bool = True) -> None:
        """A frame at run time t_s arriving now (wall), with a trend at ``level``."""
        est = TrendEstimate(t_s, level, 0.0, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=True)
        prev = self.frames.get()
        self.camera.set(CameraInfo(t_s, self.wall.t, None, None, prev.n_frames + 1, False))
        self.frames.set(FrameInfo(t_s, prev.n_frames + 1, t_s if valid else prev.last_valid_t_s, None, est))

    def mill_at(self, rpm: float, running: bool = True, epoch: int = 1, connected: bool = True) -> None:
        self.mill.set(MillSnapshot(MillStatus(rpm, rpm if running else 0.0, running, None), connected, epoch, True))


class FakePredictions:
    def __init__(self) -> None:
        self.requests: list[PredictionRequest] = []
        self.results: list[PredictionResult] = []

    def request(self, req: PredictionRequest) -> None:
        self.requests.append(req)

    def poll(self) -> PredictionResult | None:
        return self.results.pop(0) if self.results else None


def sup_worker(b: Boxes, mode: Mode, preds: FakePredictions | None = None, **cfg):
    base = dict(detect_dwell_s=2.0, min_change_interval_s=10.0, max_rate_rpm_per_s=100.0, vision_timeout_s=3.0,
                seg_level=0.5, clear_level=0.6, prediction_wait_s=0.0, min_rpm=2.0, max_rpm=40.0)
    sent: list = []
    sink = Sink()
    w = SupervisorWorker(Supervisor(worked_config(**{**base, **cfg}), mode=mode), b.view, sink, sent.append,
                         preds, b.mode)
    return w, sink, sent


def advance(b: Boxes, w: SupervisorWorker, t0: float, t1: float, level: float = 0.9, frames: bool = True) -> None:
    """Frames (optional) and a supervisor tick every 0.5 s of run time from t0 to t1."""
    t = t0
    while t < t1 - 1e-9:
        b.wall.t += 0.5
        if frames:
            b.frame(t, level)
        w.tick(b.view.now_s())
        t += 0.5


def test_off_is_hands_off_whatever_it_sees() -> None:
    b = Boxes("off")
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.OFF)
    advance(b, w, 0, 30, level=0.1)  # badly segregated
    b.mill_at(5.0, connected=False)
    advance(b, w, 30, 40, frames=False)  # link and vision lost
    assert sent == [] and sink.kinds("decision") == []


def test_nothing_is_decided_before_the_mill_was_read() -> None:
    b = Boxes()
    w, sink, sent = sup_worker(b, Mode.MANUAL)
    w.supervisor.set_manual_rpm(20.0)
    advance(b, w, 0, 5)
    assert sent == [] and sink.events == []


def test_vision_lost_alarm_and_safe_state_come_together() -> None:
    """Defect 4: the loop alarmed at 3 s, the supervisor went safe at 5 s and moved in between."""
    b = Boxes()
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.AUTO)
    advance(b, w, 0, 10)
    for _ in range(12):  # no frames: run time still passes
        b.wall.t += 0.5
        w.tick(b.view.now_s())
        if "vision_lost" in sink.faults:
            break
    assert "vision_lost" in sink.faults and "camera_stopped" in sink.faults
    assert w.safe  # the same tick
    i_alarm = next(i for i, (k, d) in enumerate(sink.events) if k == "fault" and d["fault"] == "vision_lost")
    i_safe = next(i for i, (k, d) in enumerate(sink.events) if k == "decision" and d["safe"])
    assert i_safe > i_alarm and i_safe - i_alarm <= 3 and sent == []


def test_a_twin_that_never_runs_is_stale_for_the_loops_auto() -> None:
    """The twin worker died (or hung) before its first step: the supervisor saw no twin time
    at all and never called it stale, so AUTO went on without it. With the loop's settings a
    twin that has not run within the twin timeout is stale: safe state."""
    from twin.run.settings import supervisor_config

    b = Boxes()
    b.mill_at(5.0)
    cfg = supervisor_config()
    assert cfg.twin_timeout_s is not None
    w = SupervisorWorker(Supervisor(cfg, mode=Mode.AUTO), b.view, Sink(), [].append, None, b.mode)
    advance(b, w, 0, cfg.twin_timeout_s - 1.0)
    assert not w.safe
    advance(b, w, cfg.twin_timeout_s - 1.0, cfg.twin_timeout_s + 2.0)
    assert w.safe and "twin stale" in w.supervisor.safe_reason


def test_camera_end_means_safe_at_once() -> None:
    b = Boxes()
    b.mill_at(5.0)
    w, sink, _sent = sup_worker(b, Mode.AUTO)
    advance(b, w, 0, 4)
    b.camera.set(replace(b.camera.get(), ended=True))
    w.tick(b.view.now_s())
    assert w.safe and "camera_ended" in sink.faults


def test_moving_the_rpm_slider_never_clears_camera_alarms() -> None:
    """Defect 8: set_manual_rpm supervised at the last frame's time and logged a recovery."""
    b = Boxes("manual")
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.MANUAL)
    advance(b, w, 0, 5)
    b.wall.t += 10.0  # the camera stalls for 10 s
    w.tick(b.view.now_s())
    assert "camera_stopped" in sink.faults
    for rpm in (8.0, 12.0, 9.0):
        b.wall.t += 1.0  # the ramp interval: each one goes out at once
        w.handle(SetManualRpm(rpm))
    assert "camera_stopped" in sink.faults and sink.kinds("recovered") == []
    assert [c.rpm for c in sent] == [8.0, 12.0, 9.0]  # MANUAL acts at once, vision or not


def test_decisions_carry_the_mill_epoch_they_were_made_on() -> None:
    b = Boxes("manual")
    b.mill_at(5.0, epoch=3)
    w, _sink, sent = sup_worker(b, Mode.MANUAL)
    advance(b, w, 0, 1)
    w.handle(SetManualRpm(15.0))
    assert sent == [SetRpm(15.0, 3)]


def test_requests_go_to_the_application_and_results_come_back() -> None:
    b = Boxes()
    b.mill_at(5.0)
    preds = FakePredictions()
    w, sink, sent = sup_worker(b, Mode.AUTO, preds, prediction_wait_s=30.0)
    advance(b, w, 0, 5, level=0.2)
    assert len(preds.requests) == 1 and sent == []
    req = preds.requests[0]
    preds.results.append(PredictionResult(req.t_s, req.horizon_s, {5.0: 0.3, 25.0: 0.9}))
    advance(b, w, 5, 6, level=0.2)
    assert sent == [SetRpm(25.0, 1)]
    moves = [d for d in sink.kinds("decision") if d["decision"] == "move"]
    assert moves and "twin predicts" in moves[0]["reason"]


def test_mode_commands_and_bad_ones() -> None:
    b = Boxes("off")
    b.mill_at(5.0)
    w, sink, _sent = sup_worker(b, Mode.OFF)
    w.handle(SetMode("manual"))
    assert b.mode.get() == "manual" and sink.kinds("decision")[0]["decision"] == "mode"
    w.handle(SetMode("turbo"))
    w.handle(SetManualRpm(math.nan))
    assert b.mode.get() == "manual" and len(sink.kinds("operator_rejected")) == 2


def test_run_view_time_passes_without_frames_and_never_goes_back() -> None:
    b = Boxes()
    assert b.view.now_s() == 0.0  # before any frame: the run clock
    b.frame(10.0)
    assert b.view.now_s() == pytest.approx(10.0)
    b.wall.t += 2.0
    assert b.view.now_s() == pytest.approx(12.0)
    b.frame(11.0)  # a late frame: run time does not go back
    assert b.view.now_s() == pytest.approx(12.0)


def test_frame_row_defines_the_csv_columns_and_plot_series() -> None:
    from twin.records import FRAME_COLUMNS, FrameReading
    from twin.runlog import FRAME_COLUMNS as RUNLOG_COLUMNS

    names = [f.name for f in fields(FrameRow)]
    assert FrameRow is FrameReading and FRAME_ROW_COLUMNS is FRAME_COLUMNS is RUNLOG_COLUMNS
    assert list(FRAME_COLUMNS) == [names[0], "wall_s", *names[1:]] and set(SERIES) <= set(names)


def _reading(mi: float, valid: bool = True, slope: float = 30.0):
    from vision.meter import Reading

    return Reading(mi=mi, mi_sigmoid=mi, mi_linear=mi, d_px=1.0, dsigma_px=1.0, slope_deg=slope,
                   concentration=0.5, valid=valid, flags=() if valid else ("few_pixels:red",), classes=(), roi=None)


def test_process_worker_rows_trend_moving_average_and_slopes() -> None:
    b = Boxes("auto")
    b.mill_at(5.0)
    slopes: queue.SimpleQueue = queue.SimpleQueue()
    state = LiveState()
    sink = Sink(state)
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink, slopes, ma_window=2)
    pw.process(CameraReading(0.0, 0, _reading(0.8)))
    pw.process(CameraReading(0.1, 1, _reading(0.6)))
    pw.process(CameraReading(0.2, 2, _reading(math.nan, valid=False)))
    f = b.frames.get()
    rows = sink.rows()
    assert f.n_frames == 3 and f.last_valid_t_s == 0.1 and f.t_s == 0.2
    assert [r["ma_mi"] for r in rows] == pytest.approx([0.8, 0.7, 0.7])  # the NaN frame is skipped
    assert rows[0]["rpm_actual"] == 5.0 and rows[0]["mode"] == "auto" and rows[0]["twin_mi"] is None
    assert slopes.qsize() == 2
    assert list(rows[0]) == [c for c in FRAME_ROW_COLUMNS if c != "wall_s"]
    assert state.snapshot().history["mi"].size == 3


@pytest.mark.parametrize("bad_mi", [math.nan, math.inf, -math.inf, 1.5, -0.2])
def test_a_reading_flagged_valid_with_an_impossible_mi_is_not_vision(bad_mi: float) -> None:
    """A reading that says valid but carries NaN, inf or an MI outside [0, 1] kept the vision
    timeout fed (AUTO never went safe) or dragged the trend; and an invalid reading's MI
    reached the trend. Now both count as no valid MI: AUTO goes safe with the vision alarm."""
    b = Boxes("auto")
    b.mill_at(5.0)
    slopes: queue.SimpleQueue = queue.SimpleQueue()
    frames_sink = Sink()
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, frames_sink, slopes)
    w, sink, _sent = sup_worker(b, Mode.AUTO)
    t = 0.0
    for i in range(40):  # 4 s of good frames, then 10 s of impossible ones
        b.camera.set(CameraInfo(t, b.wall.t, None, None, i + 1, False))
        pw.process(CameraReading(t, i, _reading(0.9)))
        w.tick(b.view.now_s())
        t, b.wall.t = t + 0.1, b.wall.t + 0.1
    for i in range(40, 140):
        b.camera.set(CameraInfo(t, b.wall.t, None, None, i + 1, False))
        pw.process(CameraReading(t, i, _reading(bad_mi)))
        pw.process(CameraReading(t + 0.05, i, _reading(0.1, valid=False)))
        w.tick(b.view.now_s())
        t, b.wall.t = t + 0.1, b.wall.t + 0.1
    f = b.frames.get()
    assert f.last_valid_t_s == pytest.approx(3.9) and f.estimate.level == pytest.approx(0.9, abs=0.02)
    rows = frames_sink.rows()
    assert slopes.qsize() == 40 and rows[-1]["valid"] is False and rows[-2]["valid"] is False
    assert "vision_lost" in sink.faults and w.safe


def test_a_frame_time_that_goes_back_or_is_not_a_number_is_dropped_with_a_fault() -> None:
    """A camera clock that jumps back (or a NaN frame time) raised in the Kalman trend and
    killed the process thread: no more rows, no more trend. Now the frame is dropped with a
    ``camera_clock`` fault, cleared when frames come in order again."""
    b = Boxes("manual")
    b.mill_at(5.0)
    sink = Sink()
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink)
    for i, t in enumerate((1.0, 1.1, 1.2)):
        pw.process(CameraReading(t, i, _reading(0.9)))
    assert pw.process(CameraReading(0.5, 3, _reading(0.9))) is None  # back in time
    assert pw.process(CameraReading(math.nan, 4, _reading(0.9))) is None
    assert len(sink.rows()) == 3 and b.frames.get().t_s == 1.2 and b.frames.get().n_frames == 3
    assert "camera_clock" in sink.faults
    pw.process(CameraReading(1.2, 5, _reading(0.8)))  # in order again (the same time is fine)
    pw.process(CameraReading(1.3, 6, _reading(0.8)))
    assert len(sink.rows()) == 5 and b.frames.get().t_s == 1.3 and "camera_clock" not in sink.faults


def test_a_camera_clock_that_jumps_back_is_lost_vision_for_auto() -> None:
    """The camera's frame times jump 10 s back. Run time used to stand still until they
    caught up again (the view never goes back) while every frame was refused: AUTO saw
    neither a stopped camera nor lost vision. Now frames from the past do not count as
    frames: run time goes on, the vision alarm and the safe state come."""
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return _reading(0.9)

    b = Boxes("auto")
    b.mill_at(5.0)
    q: queue.Queue = queue.Queue()
    sink = Sink()
    pw = ProcessWorker(q, MITrend(), b.frames, b.view, sink)
    w, _sink, sent = sup_worker(b, Mode.AUTO)
    w.sink = sink
    img = np.zeros((4, 4, 3), np.uint8)
    seen: list[float] = []

    def frames():
        t = 0.0
        for i in range(200):
            if i == 100:
                t -= 10.0  # the camera's clock jumps back
            b.wall.t += 0.1
            yield Frame(index=i, t_s=t, image=img)
            t += 0.1
            while not q.empty():
                pw.process(q.get_nowait())
            seen.append(b.view.now_s())
            w.tick(seen[-1])

    CameraWorker(frames(), Meter(), q, b.camera, LiveState(), monotonic=b.wall).run(threading.Event())
    assert seen[-1] == pytest.approx(19.9, abs=0.05)  # run time went on through the jump
    assert {"camera_clock", "vision_lost", "camera_stopped"} <= sink.faults and w.safe and sent == []


def test_camera_worker_never_blocks_and_marks_the_end() -> None:
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return _reading(0.9)

    q: queue.Queue = queue.Queue(maxsize=3)
    box: Latest[CameraInfo] = Latest(CameraInfo())
    frames = [Frame(index=i, t_s=i * 0.1, image=np.zeros((4, 4, 3), np.uint8)) for i in range(10)]
    cw = CameraWorker(frames, Meter(), q, box, LiveState())
    cw.run(threading.Event())
    assert box.get().ended and box.get().n_frames == 10 and box.get().t_s == pytest.approx(0.9)
    assert [q.get_nowait().frame for _ in range(3)] == [7, 8, 9]  # the oldest were dropped
    put_dropping_oldest(q, 1)
    assert q.qsize() == 1


def test_readings_the_camera_drops_are_counted_in_the_frame_rows() -> None:
    """The camera drops the oldest readings when the process worker is behind (a bounded queue:
    memory stays flat on a loaded machine); they were dropped silently, now every one is counted
    in the ``frames_dropped:N`` flag of the next row."""
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return _reading(0.9)

    q: queue.Queue = queue.Queue(maxsize=3)
    b = Boxes("auto")
    b.mill_at(5.0)
    frames = [Frame(index=i, t_s=i * 0.1, image=np.zeros((4, 4, 3), np.uint8)) for i in range(10)]
    cw = CameraWorker(frames, Meter(), q, b.camera, LiveState())
    cw.run(threading.Event())
    assert cw.dropped == 7 and q.qsize() == 3
    sink = Sink(LiveState())
    pw = ProcessWorker(q, MITrend(), b.frames, b.view, sink)
    while not q.empty():
        pw.process(q.get_nowait())
    flags = [row["flags"] for row in sink.rows()]
    counts = [int(f.split(":")[1]) for fl in flags for f in fl if f.startswith("frames_dropped:")]
    assert sum(counts) == 7 and len(flags) == 3
    pw.process(CameraReading(1.0, 10, _reading(0.9), dropped_total=7))  # nothing new dropped: no flag
    assert not any(f.startswith("frames_dropped") for f in sink.rows()[-1]["flags"])


class _Result:
    def __init__(self, rpm: float) -> None:
        self.plateau_mi = rpm / 100.0
        self.t_s = [0.0, 1.0]
        self.mi = [0.5, rpm / 100.0]
        self.regime = "cascading"


def test_whatif_worker_answers_requests_once_the_twin_runs() -> None:
    b = Boxes()
    jobs_seen: list = []

    def study(jobs):
        jobs_seen.append([j.rpm for j in jobs])
        return [_Result(j.rpm) for j in jobs]

    state = LiveState()
    w = WhatIfWorker(b.view, Sink(), state, study=study)
    w.request(PredictionRequest(1.0, (5.0, 25.0), 40.0))
    assert not w.serve_once() and w.poll() is None  # no twin yet: the request waits
    b.twin.set(TwinInfo(updated_s=1.0, state=object()))
    w.request(PredictionRequest(2.0, (5.0, 45.0), 40.0))  # supersedes the waiting one
    assert w.serve_once()
    res = w.poll()
    assert res is not None and res.t_s == 2.0 and res.predictions == {5.0: 0.05, 45.0: 0.45}
    assert w.poll() is None and jobs_seen == [[5.0, 45.0]]
    assert w.submit(RunStudy((10.0,), 20.0)) and not w.submit(RunStudy((12.0,), 20.0))  # one at a time
    assert w.serve_once() and state.snapshot().whatif.rpms == (10.0,)


def test_root_controls_become_typed_commands(tmp_path) -> None:
    """The dashboard's Controls put commands on the workers' queues; nothing runs."""
    from twin.config import RunConfig
    from twin.run.loop import LiveLoop
    from twin.runlog import RunLog, read_events

    class Link(FakeLink):
        def __init__(self) -> None:
            super().__init__(MillStatus(5.0, 5.0, True, None))

    cfg = RunConfig(dashboard=False, mode="off", log_dir=tmp_path / "run").resolved()
    with RunLog(tmp_path / "run") as log:
        loop = LiveLoop(cfg, iter(()), Link(), log)
        loop.controls.set_mode("manual")
        loop.controls.set_manual_rpm(12.0)
        loop.controls.emergency_stop()
        assert loop.supervisor._inbox.get_nowait() == SetMode("manual")
        assert loop.supervisor._inbox.get_nowait() == SetManualRpm(12.0)
        assert loop.supervisor._inbox.get_nowait() == SetMode("off")
        assert loop.mill._inbox.get_nowait() == StopMill(source="emergency_stop", urgent=True)
        assert "emergency_stop" in loop.events.active()
        loop.controls.recalibrate()
        loop.controls.reseed_twin()
        assert loop.twin._requests.get_nowait() == Recalibrate()
        assert loop.twin._requests.get_nowait() == Reseed()
        loop.controls.run_whatif([5.0], math.nan)  # refused with an event, never an exception
        loop.controls.run_whatif([5.0, 25.0], 10.0)
        loop.controls.run_whatif([5.0], 10.0)  # one study at a time: refused
        ev = [e for e in read_events(tmp_path / "run") if e["kind"] in ("operator", "operator_rejected")]
        assert [e["kind"] for e in ev if e.get("action") == "whatif"] == [
            "operator_rejected", "operator", "operator", "operator_rejected",
        ]
        assert loop._threads == []  # only start() starts threads


@pytest.mark.timeout(120)
def test_the_whatif_pool_starts_under_a_long_tmpdir(tmp_path) -> None:
    """With a long ``$TMPDIR`` the fork server's socket path was too long (``OSError: AF_UNIX path
    too long``): every AUTO study and calibration of the run failed. The pool now makes its private
    temp directory under a short base itself (``short_pool_tempdir``)."""
    import os
    import subprocess
    import sys

    long_tmp = tmp_path / ("t" * 60) / ("u" * 60)
    long_tmp.mkdir(parents=True)
    code = (
        "import tempfile\n"
        "from tests.twin.test_workers import Boxes\n"
        "from tests.twin.test_mill_worker import Sink\n"
        "from twin.live.whatif import WhatIfWorker\n"
        "from twin.state import LiveState\n"
        "from sim.whatif import froude\n"
        "w = WhatIfWorker(Boxes('auto').view, Sink(), LiveState())\n"
        "try:\n"
        "    print(len(tempfile.gettempdir()), round(w._get_pool().submit(froude, 5.0).result(timeout=90), 6))\n"
        "finally:\n"
        "    w.close()\n"
    )
    env = {**os.environ, "TMPDIR": str(long_tmp)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=110, env=env,
                       cwd=Path(__file__).resolve().parents[2])
    assert p.returncode == 0, p.stderr[-1500:]
    n, fr = p.stdout.split()
    assert int(n) > 110  # the temp directory really was long
    from sim.recipe import PAPER_DRUM
    from sim.whatif import froude

    assert float(fr) == pytest.approx(froude(5.0, PAPER_DRUM), abs=1e-6)
    assert list(long_tmp.iterdir()) == []  # nothing left behind


def test_an_auto_study_from_the_bed_waits_for_the_twin_seeded_from_the_camera(monkeypatch) -> None:
    """``PredictionRequest.from_bed`` (objective time/energy): the what-if worker asks the twin to
    seed itself from the camera's bed and starts the study from that new state, not from the
    running twin's (which may have drifted from the plant); a plain request does not re-seed,
    and a twin that never seeds itself leaves the study to the running twin's state."""
    import twin.live.whatif as whatif_mod

    b = Boxes()
    drifted, from_bed = object(), object()
    b.twin.set(TwinInfo(updated_s=1.0, state=drifted, seeds=1))
    asked: list[int] = []
    states: list = []

    def reseed() -> None:
        asked.append(1)
        b.twin.set(TwinInfo(updated_s=1.0, state=from_bed, seeds=2))

    def study(jobs):
        states.append({id(j.start) for j in jobs})
        return [_Result(j.rpm) for j in jobs]

    w = WhatIfWorker(b.view, Sink(), LiveState(), study=study, reseed_twin=reseed)
    w.request(PredictionRequest(1.0, (5.0, 25.0), 40.0))
    assert w.serve_once() and asked == [] and states[-1] == {id(drifted)}
    w.request(PredictionRequest(2.0, (5.0, 25.0), 40.0, 0.9, from_bed=True))
    assert w.serve_once() and asked == [1] and states[-1] == {id(from_bed)}
    monkeypatch.setattr(whatif_mod, "RESEED_WAIT_S", 0.2)
    mute = WhatIfWorker(b.view, Sink(), LiveState(), study=study, reseed_twin=lambda: asked.append(2))
    w2_state = b.twin.get().state
    mute.request(PredictionRequest(3.0, (5.0,), 40.0, 0.9, from_bed=True))
    assert mute.serve_once() and asked == [1, 2] and states[-1] == {id(w2_state)} and mute.poll() is not None

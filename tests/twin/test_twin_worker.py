"""The twin worker's calibration start (``TwinWorker._tend_calibration`` / ``_rpm_now``): it
calibrates only a turning, steady drum, at the rpm the mill measured, and says why it waits.

Defect (a run calibrated at 0.19 rpm): the worker calibrated at the board's actual rpm
whatever it was, and at the run's start rpm when the drum stood still. The calibration
process is replaced by a pool that records what it was given (the calibration itself is
tested in tests/sim); everything else is the worker with the run's own records."""

from __future__ import annotations

import queue
from concurrent.futures import Executor, Future
from typing import Any

import pytest

from control.limits import Limits
from control.protocol import MillStatus
from tests.twin.test_mill_worker import Sink
from twin.live.commands import Reseed
from twin.live.snapshots import CameraInfo, FrameInfo, Latest, MillSnapshot, RunView, TwinInfo
from twin.live.twin import CALIBRATION_STEADY_S, CALIBRATION_WINDOW_S, TwinSettings, TwinWorker
from twin.state import LiveState


class RecordingPool(Executor):
    """Takes calibration jobs and keeps them pending (what the worker decided to run)."""

    def __init__(self) -> None:
        self.jobs: list[tuple[Any, ...]] = []

    def submit(self, fn, /, *args, **kwargs) -> Future:  # type: ignore[override]
        self.jobs.append(args)
        return Future()


class Rig:
    """A TwinWorker on the run's records, stepped at 0.1 s of run time."""

    def __init__(self, limits: Limits | None = None) -> None:
        self.frames: Latest[FrameInfo] = Latest(FrameInfo())
        self.mill: Latest[MillSnapshot] = Latest(MillSnapshot())
        view = RunView(1.0, Latest(CameraInfo()), self.frames, self.mill, Latest(TwinInfo()), Latest("auto"),
                       clock_now=lambda: 0.0)
        self.sink = Sink()
        self.slopes: queue.SimpleQueue[tuple[float, float]] = queue.SimpleQueue()
        self.worker = TwinWorker(TwinSettings(start_rpm=5.0, limits=limits or Limits()), view, self.sink,
                                 LiveState(), Latest(TwinInfo()), self.slopes)
        self.pool = RecordingPool()
        self.worker._pool = self.pool
        self.t = 0.0

    def run(self, seconds: float, rpm: float | None, slope_deg: float = -30.0, running: bool = True) -> None:
        """``seconds`` of run time with the mill at ``rpm`` (None: the link is lost) and the
        camera seeing ``slope_deg``."""
        for _ in range(round(seconds / 0.1)):
            self.t = round(self.t + 0.1, 6)
            status = None if rpm is None else MillStatus(rpm, rpm, running, None)
            self.mill.set(MillSnapshot(status, connected=rpm is not None, polled=True))
            self.frames.set(FrameInfo(t_s=self.t))
            self.slopes.put((self.t, slope_deg))
            self.worker._drain_slopes()
            self.worker._tend_calibration()

    def waiting(self) -> list[str]:
        return [d["reason"].split(":", 1)[0] for d in self.sink.kinds("calibration_waiting")]


def test_the_twin_calibrates_only_a_turning_steady_drum_at_its_measured_rpm() -> None:
    r = Rig(Limits(min_rpm=2.0))  # worked out on a 2 rpm minimum (a run's is 5): the ramp from 2.5 rpm turns
    r.run(CALIBRATION_WINDOW_S + 1.0, 0.19)  # the camera's slope window is full; the drum creeps
    assert r.pool.jobs == [] and r.sink.kinds("calibration_started") == []
    assert r.waiting() == ["not turning"]
    assert r.sink.faults == set()  # waiting is an event, not a fault
    r.run(2.0, 0.0, running=False)  # stopped: not calibrated at the run's start rpm either
    r.run(1.0, None)  # the link is lost: the rpm is unknown
    assert r.pool.jobs == []
    for k in range(10):  # the drum ramps up: turning, not steady
        r.run(0.5, 2.5 + 1.5 * k)
    assert r.pool.jobs == []
    assert r.waiting() == ["not turning", "unknown", "not steady yet", "not steady"]
    r.run(0.5, 12.0)  # reached 12 rpm: steady only once it has held for the whole window
    assert r.pool.jobs == []
    for k in range(round(CALIBRATION_STEADY_S / 0.1)):  # +-0.1 rpm of jitter is steady
        r.run(0.1, 12.0 + 0.1 * ((k % 3) - 1))
        if r.pool.jobs:
            break
    assert len(r.pool.jobs) == 1
    target, rpm, _ = r.pool.jobs[0]
    assert rpm == pytest.approx(12.0, abs=0.05)  # the measured rpm, not start_rpm (5) nor a ramp value
    assert target == -30.0
    started = r.sink.kinds("calibration_started")
    assert len(started) == 1 and started[0]["rpm"] == rpm
    r.run(5.0, 12.0)  # one calibration per request
    assert len(r.pool.jobs) == 1


def test_the_minimum_is_the_limits_lowest_rpm() -> None:
    lo = Limits().min_rpm  # without a run's limits (a worker on its own)
    below, above = Rig(), Rig()
    below.run(CALIBRATION_WINDOW_S + CALIBRATION_STEADY_S + 1.0, 0.9 * lo)
    above.run(CALIBRATION_WINDOW_S + CALIBRATION_STEADY_S + 1.0, 1.1 * lo)
    assert below.pool.jobs == [] and below.waiting() == ["not turning"]
    assert [job[1] for job in above.pool.jobs] == [pytest.approx(1.1 * lo)]


def test_the_live_calibrations_minimum_is_the_runs_supervisor_minimum(tmp_path) -> None:
    """The run's supervisor ran the drum at 5 rpm and above, but the twin calibrated at anything
    from ``Limits()``' 2 rpm on: a drum creeping at 3 rpm, a speed the run never commands, was
    taken as a calibration speed. ``Limits``' defaults are now the run's; this run's minimum is
    set above them (7 rpm) to show the twin takes the run's limits, not the defaults."""
    from tests.twin.test_mill_worker import FakeLink
    from twin.config import RunConfig
    from twin.run.loop import LiveLoop
    from twin.run.settings import Seams
    from twin.runlog import RunLog

    cfg = RunConfig(dashboard=False, mode="auto", log_dir=tmp_path / "run").resolved()
    log = RunLog(tmp_path / "run")
    try:  # the loop hands its twin the supervisor's limits (not started: no thread)
        loop = LiveLoop(cfg, iter(()), FakeLink(MillStatus(0.0, 0.0, False, None)), log,
                        seams=Seams(limits={"min_rpm": 7.0}))
        run_limits = loop.twin.settings.limits
        assert run_limits == loop.limits == loop.supervisor.supervisor.config.limits and run_limits.min_rpm == 7.0
    finally:
        log.close()
    assert run_limits.min_rpm > Limits().min_rpm
    creeping, turning = Rig(run_limits), Rig(run_limits)
    creeping.run(CALIBRATION_WINDOW_S + CALIBRATION_STEADY_S + 1.0, 6.0)
    turning.run(CALIBRATION_WINDOW_S + CALIBRATION_STEADY_S + 1.0, 7.5)
    assert creeping.pool.jobs == [] and creeping.waiting() == ["not turning"]
    assert "below the run's 7 rpm minimum" in creeping.sink.kinds("calibration_waiting")[0]["reason"]
    assert [job[1] for job in turning.pool.jobs] == [pytest.approx(7.5)]


def test_the_twins_age_is_its_simulated_time_since_seeding_not_run_time() -> None:
    """``TwinInfo.age_s`` (what the twin-versus-camera check waits on for the bed's spin-up):
    the real worker thread, seeded at run time 0, falls 20 s behind and skips ahead (run time
    jumps, its bed has not run), steps 3 s, and is seeded again: age 0 -> ~0 -> ~3 -> ~0."""
    import threading

    from tests.waiting import wait_until
    from twin.live.twin import MAX_LAG_S
    from vision.colours import DEFAULT_CLASSES

    camera: Latest[CameraInfo] = Latest(CameraInfo())
    frames: Latest[FrameInfo] = Latest(FrameInfo(t_s=0.0))
    mill: Latest[MillSnapshot] = Latest(MillSnapshot(MillStatus(5.0, 5.0, True, None), connected=True, polled=True))
    box: Latest[TwinInfo] = Latest(TwinInfo())
    view = RunView(1.0, camera, frames, mill, box, Latest("auto"), clock_now=lambda: 0.0)
    sink = Sink()
    settings = TwinSettings(start_rpm=5.0, classes=DEFAULT_CLASSES)
    worker = TwinWorker(settings, view, sink, LiveState(), box, queue.SimpleQueue())
    worker._cal_wanted = False  # no calibration process: this is about the clock
    stop = threading.Event()
    thread = threading.Thread(target=worker.run, args=(stop,), daemon=True)

    def until(cond, what: str) -> TwinInfo:
        wait_until(lambda: cond(box.get()), 60, f"the twin to have {what}", poll_s=0.01)
        return box.get()  # (it waits for the next frame: the state that met cond)

    from sim.drum import DrumSim
    from sim.render import Renderer

    bed = DrumSim(case="C", seed=0, rpm=5.0)
    renderer = Renderer(bed.drum, 240)
    camera.set(CameraInfo(0.0, 0.0, renderer.render(bed.particles()), renderer.roi, 1))
    thread.start()
    try:
        first = until(lambda i: i.updated_s is not None, "published")
        assert first.seeds == 1 and first.age_s == 0.0
        jump = 4.0 * MAX_LAG_S
        frames.set(FrameInfo(t_s=jump))  # the run is far ahead: the twin skips, its bed does not run
        skipped = until(lambda i: i.updated_s >= jump - 1e-6, "caught up")
        assert sink.kinds("twin_lag") and skipped.updated_s == pytest.approx(jump) and skipped.age_s < 0.05
        for k in range(1, 31):  # 3 s more of run time, in 0.1 s frames
            frames.set(FrameInfo(t_s=jump + 0.1 * k))
            until(lambda i, k=k: i.updated_s >= jump + 0.1 * k - 1e-6, "kept up")
        ran = box.get()
        assert ran.updated_s == pytest.approx(jump + 3.0) and ran.age_s == pytest.approx(3.0, abs=0.05)
        worker.request(Reseed())
        again = until(lambda i: i.seeds == 2, "been seeded again")
        assert again.updated_s >= jump + 3.0 - 1e-6 and again.age_s < 0.2
    finally:
        stop.set()
        thread.join(30)

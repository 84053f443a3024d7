"""The live loop's threads on a fake mill and no camera: when the run can no longer keep its
rules (the run log cannot be written, the supervisor or the mill worker crashed) it ends,
stops the mill on the way out, and says why (seconds; no sim, no serial)."""

from __future__ import annotations

import errno
import threading
from pathlib import Path

import pytest

from control.protocol import MillStatus
from tests.twin.test_mill_worker import FakeLink
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.live.faults import NO_FAULTS, FaultHooks
from twin.run.loop import LiveLoop
from twin.run.settings import Seams
from twin.runlog import RunLog, read_events


class FullDisk(RunLog):
    """A run log on a disk that fills up when ``full`` is set (ENOSPC on every write)."""

    full = False

    def _write(self, fh, text: str) -> None:
        if self.full:
            raise OSError(errno.ENOSPC, "No space left on device")
        super()._write(fh, text)


@pytest.fixture
def thread_errors(monkeypatch) -> list[BaseException | None]:
    """Exceptions that escape a thread (each printed a traceback on the run's stderr)."""
    seen: list[BaseException | None] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(args.exc_value))
    return seen


class Armed:
    """A fault hook (``twin.live.faults``) that does nothing until the test arms it, then runs ``fault``."""

    def __init__(self, fault) -> None:
        self.fault = fault
        self.armed = threading.Event()

    def __call__(self, now_s: float) -> None:
        if self.armed.is_set():
            self.fault()


def _loop(tmp_path: Path, log: RunLog, faults: FaultHooks = NO_FAULTS) -> tuple[LiveLoop, FakeLink]:
    link = FakeLink(MillStatus(12.0, 12.0, True, None))  # a running board
    cfg = RunConfig(dashboard=False, mode="manual", log_dir=tmp_path / "run").resolved()
    loop = LiveLoop(cfg, iter(()), link, log, seams=Seams(faults=faults)).start()
    wait_until(lambda: loop.mill_box.get().connected, 5.0, "the mill worker's first read of the board")
    return loop, link


@pytest.mark.timeout(30)
def test_a_full_disk_ends_the_run_and_stops_the_mill(tmp_path: Path, thread_errors) -> None:
    """ENOSPC on the run log: the supervisor thread died on its next event (a traceback), the
    guard's own fault event failed too, and the mill worker fed the board's watchdog on:
    the mill ran unsupervised and unlogged. Now the run ends and the mill is stopped."""
    log = FullDisk(tmp_path / "run")
    loop, link = _loop(tmp_path, log)
    try:
        log.full = True
        loop.controls.set_manual_rpm(20.0)  # the operator's event cannot be written
        wait_until(loop.stop_event.is_set, 5.0, "the run to end without its log")
    finally:
        loop.stop()
        log.close()
    assert loop.failure is not None and "No space left on device" in loop.failure
    assert link.sent[-1] == ("stop", None) and not link.board.running
    assert thread_errors == []
    assert any("cannot write the run log" in a for a in loop.state.alarms)


@pytest.mark.timeout(30)
@pytest.mark.parametrize("worker", ["supervisor", "mill"])
def test_a_crashed_supervisor_or_mill_worker_ends_the_run_and_stops_the_mill(
    tmp_path: Path, worker: str
) -> None:
    """A crashed supervisor left the mill worker feeding the watchdog of a running mill with
    nobody deciding; a crashed mill worker left a snapshot that still said 'connected'.
    Either way the run now ends, logs why, and stops the mill."""
    log = RunLog(tmp_path / "run")

    def boom() -> None:
        raise RuntimeError("bug")

    bug = Armed(boom)
    loop, link = _loop(tmp_path, log, FaultHooks(supervisor_tick=bug) if worker == "supervisor"
                       else FaultHooks(mill_cycle=bug))
    try:
        bug.armed.set()
        if worker == "supervisor":
            loop.controls.set_manual_rpm(20.0)  # its next tick, at once
        # the mill: its next poll, within 0.1 s
        wait_until(loop.stop_event.is_set, 5.0, "the run to end without its worker")
    finally:
        loop.stop()
        log.close()
    assert loop.failure is not None and f"{worker} worker crashed" in loop.failure
    assert link.sent[-1] == ("stop", None) and not link.board.running
    events = read_events(tmp_path / "run")
    assert any(e["kind"] == "fault" and e["fault"] == "worker_crashed" and e["worker"] == worker for e in events)
    assert any(e["kind"] == "mill_command" and e["command"] == "stop" and e["source"] == "run_failed"
               for e in events)
    assert events[-1]["kind"] == "stop" and f"{worker} worker crashed" in events[-1]["failure"]


@pytest.mark.timeout(30)
def test_a_hung_supervisor_ends_the_run_and_stops_the_mill(tmp_path: Path, monkeypatch) -> None:
    """A supervisor that hangs (no crash for the guard to see) left the mill worker feeding
    the watchdog of a running mill with nobody deciding. The loop's watch now ends the run
    once the supervisor has not passed through its loop for the stall time."""
    import twin.run.loop

    monkeypatch.setattr(twin.run.loop, "SUPERVISOR_STALL_S", 1.0)
    log = RunLog(tmp_path / "run")
    release = threading.Event()
    hang = Armed(lambda: release.wait(20.0))
    loop, link = _loop(tmp_path, log, FaultHooks(supervisor_tick=hang))
    try:
        # real time: the stall watch measures the wall clock, and a healthy supervisor must pass
        # through its loop for longer than the (patched) 1 s stall time without ending the run
        assert not loop.stop_event.wait(1.5), "a healthy supervisor is not a stall"
        hang.armed.set()
        loop.controls.set_manual_rpm(20.0)  # its next pass hangs in tick
        # 15 s: the stop comes ~1 s after the hang (the stall time) on a quiet machine; a loaded
        # one (a 5 s wait failed once at load 5-8) may take longer. Still under the hang's 20 s,
        # so a loop without the watch fails here
        wait_until(loop.stop_event.is_set, 15.0, "the run to end with a hung supervisor")
    finally:
        release.set()
        loop.stop()
        log.close()
    assert loop.failure is not None and "supervisor worker has not run" in loop.failure
    assert link.sent[-1] == ("stop", None) and not link.board.running
    events = read_events(tmp_path / "run")
    assert any(e["kind"] == "fault" and e["fault"] == "supervisor_stalled" for e in events)


@pytest.mark.timeout(30)
def test_the_run_start_record_carries_the_config_the_versions_and_the_mixer(tmp_path: Path) -> None:
    """The ``start`` record had the mode and the mill URL only: a run log read on its own
    (``read_events``) could not say what was run, with what, on which drum."""
    log = RunLog(tmp_path / "run")
    loop, _ = _loop(tmp_path, log)
    loop.stop()
    log.close()
    start = next(e for e in read_events(tmp_path / "run") if e["kind"] == "start")
    assert start["config"]["mode"] == "manual" and start["config"]["log_dir"] == str(tmp_path / "run")
    assert {"drumtwin", "python", "numpy", "opencv-python-headless", "pymunk", "viser"} <= set(start["versions"])
    assert start["mixer"]["drum_diameter_mm"] == pytest.approx(300.0)  # the demo's twin: the paper's drum
    assert start["config"]["control_token"] is None


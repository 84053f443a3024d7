"""A worker that crashes (a bug: an exception that is not bad input) in any of the live
loop's threads ends the run in the safe state: the mill, started by this run's operator, is
sent a stop over a real pty by the real serial driver; ``events.jsonl`` holds a
``worker_crashed`` fault with the exception in one line (its traceback beside it); the
command prints one ``error:`` line and exits 3 (``twin.errors.EXIT_WORKER_CRASHED``).

The old loop printed a traceback; a crashed camera, twin or what-if worker only raised a
``thread_<name>`` fault and the run went on to its end and exited 0 (mill, process and
supervisor ended it with exit 2)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import cv2
import pytest

from control.device import DeviceConfig
from control.emulator import MillEmulator
from tests.cli import cli
from tests.waiting import wait_until
from twin.errors import EXIT_WORKER_CRASHED
from twin.live.faults import FaultHooks, Hook
from twin.run import main as run_main
from twin.run.loop import WORKERS, LiveLoop, crash_summary
from twin.run.settings import Seams
from twin.runlog import read_events
from vision.synthetic import drum_frame

LIVE = pytest.mark.xdist_group("live")
CRASH_AT_S = 1.5  # run time (the video's paced time); the operator's start is logged at 0.00-0.02 s
POINTS: dict[str, Callable[[Hook], FaultHooks]] = {  # each worker's per-pass point (twin.live.faults)
    "camera": lambda h: FaultHooks(camera_frame=h),  # its next frame
    "process": lambda h: FaultHooks(process_reading=h),  # its next reading
    "mill": lambda h: FaultHooks(mill_cycle=h),  # its next cycle
    "twin": lambda h: FaultHooks(twin_pass=h),
    "whatif": lambda h: FaultHooks(whatif_pass=h),
    "supervisor": lambda h: FaultHooks(supervisor_tick=h),
}


def _crash_from(at_s: float, message: str) -> Hook:
    """A bug: from run time ``at_s`` on, the worker's next pass raises ``RuntimeError(message)``."""

    def crash(now_s: float) -> None:
        if now_s >= at_s:
            raise RuntimeError(message)

    return crash


def _video(path: Path, n: int) -> Path:
    """``n`` frames at 10 fps of a drum the meter's default classes see."""
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (160, 120))
    for i in range(n):
        vw.write(drum_frame((160, 120), seed=i))
    vw.release()
    return path


def _start_mill(loop: LiveLoop, plant: object, dash: object) -> None:
    """The operator presses Start once the board has been read (the run then controls it)."""
    wait_until(lambda: loop.mill_box.get().connected, 20.0, "the board to be read")
    loop.controls.start_mill()


@pytest.fixture(scope="module")
def drum_video(tmp_path_factory) -> Path:
    """30 s of drum (the run ends by the crash, not by the video), written once for the module:
    each run only reads it."""
    return _video(tmp_path_factory.mktemp("crash") / "drum.avi", n=300)


@LIVE
@pytest.mark.timeout(120)
@pytest.mark.parametrize("worker", WORKERS)
def test_a_crashed_worker_stops_the_mill_logs_it_and_exits_3(tmp_path: Path, worker: str, monkeypatch,
                                                             drum_video: Path) -> None:
    emu = MillEmulator(DeviceConfig(watchdog_s=2.0), seed=1)
    url = emu.open_pty()
    emu.set_motor(setpoint_rpm=10.0, actual_rpm=0.0, running=False)
    video = drum_video
    real = run_main.run_live  # what `drumtwin run` calls, with the crash and the operator's start
    seams = Seams(faults=POINTS[worker](_crash_from(CRASH_AT_S, f"bug in {worker}\nsecond line")),
                  on_started=_start_mill)
    monkeypatch.setattr(run_main, "run_live", lambda cfg, seams_=None, **kw: real(cfg, seams, **kw))
    try:
        t0 = time.monotonic()
        r = cli("run", "--video", video, "--mill", url, "--no-dashboard", "--mode", "manual", "--duration", "60",
                "--log", tmp_path / "run")
        took = time.monotonic() - t0
        applied = [a.cmd for a in emu.applied]
        running = emu.motor.running
    finally:
        emu.close()
    assert r.code == EXIT_WORKER_CRASHED, (r.code, r.err[-2000:])
    assert "Traceback" not in r.err and "Traceback" not in r.out, r.err
    lines = [ln for ln in r.err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.err
    assert f"the {worker} worker crashed: RuntimeError: bug in {worker}" in lines[0]
    assert "second line" not in lines[0]
    assert took < 55.0, "the run went on to its duration"
    # the safe state: the run's own start went through, and the stop on the way out
    assert "RUN" in applied and applied[-1] == "STP", applied
    assert not running
    events = read_events(tmp_path / "run")
    crashed = [e for e in events if e["kind"] == "fault" and e["fault"] == "worker_crashed"]
    assert len(crashed) == 1, [e for e in events if e["kind"] == "fault"]
    assert crashed[0]["worker"] == worker and crashed[0]["error"] == f"RuntimeError: bug in {worker}"
    assert ", in crash\n" in crashed[0]["traceback"]  # where the bug was raised, on the worker's thread
    # the camera's hook sees its frame's paced time, the record the run clock: they agree within a frame
    assert crashed[0]["t_s"] >= CRASH_AT_S - 0.1
    assert any(e["kind"] == "mill_command" and e["command"] == "stop" and e["source"] == "run_failed"
               for e in events)
    assert events[-1]["kind"] == "stop" and f"the {worker} worker crashed" in events[-1]["failure"]


def test_crash_summary_is_one_line_with_the_type() -> None:
    assert crash_summary(ValueError("bad\nmore")) == "ValueError: bad"
    assert crash_summary(KeyError()) == "KeyError"


def test_every_worker_has_a_fault_point_and_a_misspelt_point_is_an_error() -> None:
    assert set(POINTS) == set(WORKERS)
    with pytest.raises(TypeError, match="camra_frame"):
        FaultHooks(camra_frame=_crash_from(0.0, "never"))  # type: ignore[call-arg]

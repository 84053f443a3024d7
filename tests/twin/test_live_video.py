"""A run of a recorded video against the mill emulator on TCP: it never starts a mill it did not command,
a full disk or a video without a drum is a one-line error and a stopped mill, a camera warming up
without a drum is flagged; bad run options are one-line errors."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli import assert_one_line_error, cli
from tests.twin.live_helpers import LIVE, synthetic_video
from twin.config import RunConfig
from twin.run.main import run_live
from twin.runlog import read_events, read_frames
from vision.synthetic import drum_frame


@LIVE
@pytest.mark.timeout(60)
@pytest.mark.parametrize("mode", ["off", "auto"])
def test_run_never_starts_a_mill_it_did_not_command(tcp_mill, tmp_path: Path, mode: str) -> None:
    """Defect 1: `run --video V --mill URL --mode off` started a stopped mill on connecting."""
    emu, url = tcp_mill
    video = synthetic_video(tmp_path / "v.avi")
    cfg = RunConfig(video=video, mill=url, dashboard=False, duration_s=3.0, mode=mode,
                    log_dir=tmp_path / "run").resolved()
    run_live(cfg)
    left = [t.name for t in threading.enumerate() if t.name.startswith(("drumtwin-", "mill-heartbeat"))]
    assert left == []  # the root joined every worker; the mill client has no thread of its own
    m = emu.motor
    assert not m.running and m.fault == "WDOG" and m.setpoint_rpm == 13.0
    assert not any(a.cmd in ("RUN", "SET") for a in emu.applied)
    events = read_events(tmp_path / "run")
    assert any(e["kind"] == "mill_synced" and e["running"] is False for e in events)
    assert not any(e["kind"] in ("mill_restart", "mill_command") for e in events)
    if mode == "auto":  # no valid MI and then the video ends: safe at once, nothing sent
        assert any(e["kind"] == "decision" and e["safe"] for e in events)


@LIVE
@pytest.mark.timeout(60)
def test_a_full_disk_mid_run_is_a_one_line_error_and_a_stopped_mill(tcp_mill, tmp_path: Path, monkeypatch) -> None:
    """The disk fills up after a few frame rows: the run ends at once, the mill (running, by
    the operator's start) is stopped, and the command says so in one line, exit 2 (it
    printed worker tracebacks and ran on unsupervised, unlogged)."""
    import errno

    from twin import runlog as runlog_mod

    class FillingDisk(runlog_mod.RunLog):
        def frame(self, row) -> None:
            if self.n_frames >= 5:
                raise OSError(errno.ENOSPC, "No space left on device")
            super().frame(row)

    emu, url = tcp_mill
    emu.set_motor(setpoint_rpm=13.0, actual_rpm=13.0, running=True)  # started at the front panel
    monkeypatch.setattr(runlog_mod, "RunLog", FillingDisk)

    video = tmp_path / "drum.avi"  # a drum the meter finds (red and blue: its default classes)
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (160, 120))
    for i in range(100):
        vw.write(drum_frame((160, 120), seed=i))
    vw.release()
    r = cli("run", "--video", video, "--mill", url, "--no-dashboard", "--mode", "manual", "--duration", "60",
            "--log", tmp_path / "run")
    assert_one_line_error(r, "the run stopped", "No space left on device", str(tmp_path / "run"))
    assert [a.cmd for a in emu.applied] == ["STP"] and not emu.motor.running
    events = read_events(tmp_path / "run")
    assert events[-1]["kind"] == "stop" and "No space left" in events[-1]["failure"]
    assert len(read_frames(tmp_path / "run")) == 5


@LIVE
@pytest.mark.timeout(60)
@pytest.mark.parametrize("n_frames", [100, 15])
def test_a_video_without_a_drum_is_a_one_line_error(tcp_mill, tmp_path: Path, n_frames: int) -> None:
    """Bad input: the meter cannot find the drum in the video. The camera and twin threads
    printed a traceback each, and the run went on to its end and exited 0. Now: one line,
    exit 2, and the run is over once the camera's grace for a first drum is over (10 s of
    video) or the video ends without one (1.5 s); the mill is sent a stop on the way out."""
    emu, url = tcp_mill
    video = synthetic_video(tmp_path / "noise.avi", n=n_frames, drum=False)
    t0 = time.monotonic()
    r = cli("run", "--video", video, "--mill", url, "--no-dashboard", "--mode", "off", "--duration", "30",
            "--log", tmp_path / "run")
    assert_one_line_error(r, "could not find the drum circle", "--roi")
    assert time.monotonic() - t0 < 20.0  # not the whole 30 s
    assert any(e["kind"] == "stop" and e["failure"] for e in read_events(tmp_path / "run"))
    assert [a.cmd for a in emu.applied] == ["STP"]  # nothing but the stop on the way out


@LIVE
@pytest.mark.timeout(60)
def test_a_camera_warming_up_without_a_drum_is_flagged_not_the_end_of_the_run(tcp_mill, tmp_path: Path) -> None:
    """A webcam's first frames are often black: the first frame (a new size) had no drum to
    find and ended the run. Frames without a drum in the first seconds are flagged rows
    (``no_drum:``); once the drum shows, the run measures it and ends normally."""
    emu, url = tcp_mill
    video = tmp_path / "warmup.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (160, 120))
    for i in range(50):  # 2 s of black, then 3 s of a drum the default classes see
        vw.write(np.zeros((120, 160, 3), np.uint8) if i < 20 else drum_frame((160, 120), seed=i))
    vw.release()
    r = cli("run", "--video", video, "--mill", url, "--no-dashboard", "--mode", "off", "--duration", "4.5",
            "--log", tmp_path / "run")
    assert r.code == 0, r.err
    rows = read_frames(tmp_path / "run")
    early = [row for row in rows if float(row["t_s"]) < 1.9]
    late = [row for row in rows if float(row["t_s"]) > 2.1]
    assert early and all("no_drum" in row["flags"] for row in early)
    assert late and any(float(row["valid"]) == 1 for row in late)
    assert emu.applied == []  # OFF: nothing sent, not even on the way out


def test_bad_run_options_are_one_line_errors(tmp_path: Path) -> None:
    video = synthetic_video(tmp_path / "v.avi", n=2)
    for args, needle in (
        (("--seed", -1), "--seed"),
        (("--speed", "nan"), "--speed"),
        (("--speed", "inf"), "--speed"),
        (("--speed", 0), "--speed"),
        (("--duration", "inf"), "--duration"),
        (("--duration", -5), "--duration"),
        (("--port", 0), "--port"),
        (("--port", 70000), "--port"),
        (("--mode", "turbo"), "--mode"),
        (("--case", "Z"), "--case"),
    ):
        assert_one_line_error(cli("run", "--no-dashboard", *args), needle)
    for args, needle in ((("--warmup", "nan"), "--warmup"), (("--seconds", "inf"), "--seconds"),
                         (("--port", 99999), "--port")):
        assert_one_line_error(cli("bench", "dashboard", *args), needle)
    log = tmp_path / "never"
    r = cli("run", "--video", video, "--mill", "/dev/nonexistent-mill", "--no-dashboard", "--log", log)
    assert_one_line_error(r, "/dev/nonexistent-mill")
    assert not log.exists()  # refused at start, before any log or thread

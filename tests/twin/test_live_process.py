"""``drumtwin run`` as a process: pure JSON on stdout with the dashboard on, Ctrl-C to the process group
ends the run without a traceback, and the run's CSV survives kill -9."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.twin.live_helpers import DRUMTWIN, LIVE, free_port, synthetic_video
from tests.waiting import wait_until
from twin.runlog import read_events, read_frames


@LIVE
@pytest.mark.timeout(60)
def test_json_stdout_is_pure_json_with_the_dashboard_on(tcp_mill, tmp_path: Path) -> None:
    _, url = tcp_mill
    video = synthetic_video(tmp_path / "v.avi", n=20)
    p = subprocess.run(
        [*DRUMTWIN, "run", "--video", str(video), "--mill", url, "--duration", "2", "--mode", "off",
         "--port", str(free_port()), "--json", "--log", str(tmp_path / "run")],
        capture_output=True, text=True, timeout=50,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    assert "dashboard on" in p.stderr  # the banner went to stderr
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 1, p.stdout
    assert json.loads(lines[0])["log_dir"] == str(tmp_path / "run")


# a run started with SIGINT ignored, as everything started with `&` by a shell without job control is
# (a script, a CI step, a service): `trap "" INT` sets that disposition and exec keeps it
IGNORING_SIGINT = ["sh", "-c", 'trap "" INT; exec "$0" "$@"']


@LIVE
@pytest.mark.timeout(120)
@pytest.mark.parametrize(("presses", "started"), [(1, "terminal"), (2, "terminal"), (1, "sigint ignored")])
def test_ctrl_c_to_the_process_group_ends_the_run_without_a_traceback(tmp_path: Path, presses: int,
                                                                      started: str) -> None:
    """Ctrl-C in a terminal signals the whole process group, the calibration and what-if
    worker processes included: the run stops cleanly and nobody prints a traceback; a second
    Ctrl-C while it stops does not cut the stop short (it ended with 130, no "run ended" and
    no stop record). A run that inherited SIGINT ignored stops on it all the same (it ran on
    until killed: Python keeps an inherited SIG_IGN)."""
    wrap = IGNORING_SIGINT if started == "sigint ignored" else []
    proc = subprocess.Popen(
        [*wrap, *DRUMTWIN, "run", "--no-dashboard", "--mode", "auto", "--speed", "2", "--log", str(tmp_path / "run")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    try:
        csv = tmp_path / "run" / "frames.csv"
        wait_until(lambda: csv.exists() and len(read_frames(csv)) > 30, 60, "frames in the run log")
        os.killpg(proc.pid, signal.SIGINT)
        if presses == 2:  # an impatient second press while the run stops (a press after the process has
            # ended its run lands in the interpreter's exit, where Python's own default handling is back)
            time.sleep(0.05)  # real time: the operator's second press, 50 ms after the first
            os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err[-2000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-2000:]
    assert "run ended" in err
    assert any(e["kind"] == "stop" for e in read_events(tmp_path / "run"))


@LIVE
@pytest.mark.timeout(120)
def test_run_csv_survives_kill_9(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [*DRUMTWIN, "run", "--no-dashboard", "--speed", "2", "--mode", "off", "--log", str(tmp_path / "run")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        csv = tmp_path / "run" / "frames.csv"
        wait_until(lambda: csv.exists() and len(read_frames(csv)) > 40, 60, "40 rows in the run log")
        kill_wall = time.time()  # while the run writes on: the kill lands between rows or in one
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    rows = read_frames(tmp_path / "run")
    assert len(rows) > 40
    frames = [int(r["frame"]) for r in rows]
    assert frames == sorted(frames) and all(math.isfinite(r["t_s"]) for r in rows)
    assert kill_wall - rows[-1]["wall_s"] < 1.0

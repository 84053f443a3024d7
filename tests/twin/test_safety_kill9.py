"""Issue 26 item 11 with real runs: ten ``drumtwin run`` processes (the embedded demo),
each killed with SIGKILL at a different moment, from the middle of its imports to well
into the run. Each killed run's log parses up to the kill; the pty directories the kills
leave behind are gone after the next run starts, and that run leaves nothing behind in
the temp directory either (no ``drumtwin-*``, no ``pymp-*``, nothing) and no process."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from control.emulator import OWNER_FILE, PTY_DIR_PREFIX, owner_pid
from tests.cli import cli
from tests.waiting import wait_until
from twin.runlog import EVENTS_FILE, FRAMES_FILE, read_events, read_frames

DRUMTWIN = Path(sys.executable).with_name("drumtwin")

# When each run is killed: (milestone, then this much more), the milestone one of
# "spawn" (the process exists: it is importing), "pty" (its mill emulator's pty directory
# exists), "frames N" (its frames.csv has N rows), "event KIND" (events.jsonl has KIND).
MOMENTS: list[tuple[str, float]] = [
    ("spawn", 0.3), ("spawn", 1.5), ("pty", 0.0), ("pty", 0.3), ("frames 1", 0.0),
    ("frames 3", 0.1), ("frames 8", 0.0), ("event calibration_started", 0.2), ("frames 20", 0.37), ("frames 40", 0.0),
]


def _reached(milestone: str, tmp: Path, log: Path, pid: int) -> bool:
    """Whether run ``pid`` (logging to ``log``) has reached ``milestone``; its "pty" is the pty
    directory whose owner file names ``pid``, not a killed run's leftover in the same temp dir."""
    if milestone == "spawn":
        return True
    if milestone == "pty":
        return any(_owner_pid(d) == pid for d in tmp.glob(PTY_DIR_PREFIX + "*"))
    what, arg = milestone.split()
    if what == "frames":
        return (log / FRAMES_FILE).exists() and len(read_frames(log)) >= int(arg)
    return (log / EVENTS_FILE).exists() and any(e["kind"] == arg for e in read_events(log))


def _owner_pid(d: Path) -> int | None:
    """The pid in a pty directory's owner file (None while it is not written yet)."""
    try:
        return owner_pid((d / OWNER_FILE).read_text(encoding="ascii"))
    except OSError:
        return None


def _ours(marker: str) -> list[int]:
    """Processes whose environment carries ``marker`` (the runs' and their children)."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit() and int(d) != os.getpid():
            try:
                if marker.encode() in Path(f"/proc/{d}/environ").read_bytes():
                    pids.append(int(d))
            except OSError:
                pass
    return pids


def _env(tmp: Path, marker: str) -> dict[str, str]:
    env = {**os.environ, "TMPDIR": str(tmp), "DRUMTWIN_KILL9_TEST": marker, "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": os.environ.get("PYTHONPATH", os.getcwd())}
    env.pop("DRUMTWIN_DEBUG", None)
    return env


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_kill_9_of_ten_runs_leaves_readable_logs_and_no_temp_dirs_after_the_next_start(tmp_path, request) -> None:
    # the runs' temp directory: short, since multiprocessing's fork server puts an AF_UNIX
    # socket there (108 bytes at most: pytest's tmp_path is too long for one)
    tmp = Path(tempfile.mkdtemp(prefix="k9-", dir="/tmp"))
    request.addfinalizer(lambda: shutil.rmtree(tmp, ignore_errors=True))
    marker = f"kill9-{os.getpid()}-{time.time_ns()}"
    env = _env(tmp, marker)
    argv = [str(DRUMTWIN), "run", "--no-dashboard", "--speed", "4", "--mode", "auto", "--duration", "3600"]
    killed: list[tuple[Path, float, str]] = []  # (log dir, wall time of the kill, moment)

    def start(i: int) -> tuple[subprocess.Popen, Path]:
        log = tmp_path / f"run{i}"
        with open(tmp_path / f"run{i}.err", "wb") as err:  # read back when a run ends by itself
            proc = subprocess.Popen([*argv, "--log", str(log)], env=env, stdout=subprocess.DEVNULL, stderr=err)
        return proc, log

    # two at a time (a two-core machine): the pair's two moments are checked independently
    for pair in range(0, len(MOMENTS), 2):
        runs = [(i, *start(i)) for i in range(pair, pair + 2)]
        for i, proc, log in runs:
            milestone, extra = MOMENTS[i]
            wait_until(lambda p=proc, m=milestone, d=log: p.poll() is not None or _reached(m, tmp, d, p.pid), 150,
                       f"run {i} to reach {milestone}")
            assert proc.poll() is None, (f"run {i} ended by itself (code {proc.returncode}) before {milestone}: "
                                       f"{(tmp_path / f'run{i}.err').read_text(errors='replace')[-800:]}")
            assert _reached(milestone, tmp, log, proc.pid), f"run {i} never reached {milestone}"
            time.sleep(extra)  # real time: the kill lands this long after the milestone (the race under test)
            proc.send_signal(signal.SIGKILL)
            killed.append((log, time.time(), f"{milestone} + {extra:g} s"))
            proc.wait(10)
    wait_until(lambda: not _ours(marker), 20.0, "the killed runs' child processes to end with them")

    # each start already removed the leftovers of the runs killed before it; the last pair's
    # (killed well after their pty existed) are still there: the kills do leave them
    left = sorted(p.name for p in tmp.iterdir())
    assert sum(n.startswith(PTY_DIR_PREFIX) for n in left) >= 2, left

    for log, t_kill, moment in killed:
        if not log.exists():
            assert moment.startswith(("spawn", "pty")), (moment, "no log dir")
            continue
        rows = read_frames(log) if (log / FRAMES_FILE).exists() else []
        events = read_events(log) if (log / EVENTS_FILE).exists() else []
        if moment.startswith(("frames", "event")):
            want = int(moment.split()[1]) if moment.startswith("frames") else 1
            assert len(rows) >= want, (moment, len(rows))
            assert events, moment
        frames = [int(r["frame"]) for r in rows]
        assert frames == sorted(frames), moment  # every row parses, in order, up to the kill
        assert all(r["wall_s"] <= t_kill + 0.5 for r in rows), moment
        assert all(isinstance(e, dict) and "kind" in e and "t_s" in e for e in events), moment

    # the next start: a normal run in the same temp directory, stopped once its calibration's pool is up
    nxt = tmp_path / "next"
    stderr = _next_run_stopped_at_its_pool(argv, env, tmp, nxt, tmp_path / "next.err")

    # issue 40: the catalogue beside the runs lists each killed run as ended without a stop,
    # with what its log holds, and the next run as a clean one
    listed = cli("runs", "list", "--runs-dir", tmp_path, "--json")  # in-process: it starts nothing
    assert listed.code == 0, listed.err[-2000:]
    rows = {Path(r["path"]).name: r for r in json.loads(listed.out)}
    assert rows["next"]["ended"] == "clean" and rows["next"]["frames"] > 0
    for log, _t, moment in killed:
        if (log / EVENTS_FILE).exists() or (log / FRAMES_FILE).exists():
            row = rows[log.name]
            assert row["ended"] == "killed" and "without a stop" in row["failure"], (moment, row)
            assert (row["frames"] or 0) == len(read_frames(log)), moment
    assert "Traceback" not in stderr
    wait_until(lambda: not _ours(marker), 20.0, "the next run's processes to end")
    assert sorted(p.name for p in tmp.iterdir()) == [], "left in the temp directory after the next run"


def _next_run_stopped_at_its_pool(argv: list[str], env: dict[str, str], tmp: Path, log: Path, err_file: Path) -> str:
    """A normal run in the same temp directory ``tmp``, stopped (SIGTERM: the operator's stop, the same
    shutdown as the end of its duration) once its calibration's pool is up: its fork server's own pymp-*
    directory (not a killed run's leftover) is there to be left behind. Waiting on that event, not on 20 s
    of run time, cuts ~10 s of CPU and cannot stop before the pool exists. Its stderr; exit 0 asserted."""
    before = {d.name for d in tmp.glob("pymp-*")}
    with open(err_file, "w+b") as err:
        proc = subprocess.Popen([*argv, "--log", str(log)], env=env, stdout=subprocess.DEVNULL, stderr=err)
        try:
            wait_until(lambda: proc.poll() is not None or (
                _reached("event calibration_started", tmp, log, proc.pid)
                and any(d.name not in before for d in tmp.glob("pymp-*"))), 240,
                "the next run's calibration pool to start")
            assert proc.poll() is None, "the next run ended by itself before its calibration pool started"
            proc.send_signal(signal.SIGTERM)
            code = proc.wait(120)
        finally:
            if proc.poll() is None:
                proc.kill()
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    assert code == 0, stderr[-2000:]
    return stderr

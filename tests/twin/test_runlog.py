"""Run log: rows, events and metadata round-trip; the CSV survives kill -9."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, cli
from twin.config import RunConfig
from twin.errors import TwinError
from twin.runlog import (
    FRAME_COLUMNS,
    RunLog,
    default_run_dir,
    make_run_dir,
    read_events,
    read_frames,
    read_metadata,
)


def test_rows_events_metadata_round_trip(tmp_path: Path) -> None:
    with RunLog(tmp_path / "run") as log:
        log.frame({"t_s": 0.5, "mi": 0.81, "valid": True, "flags": ("few_red",), "mode": "auto"})
        log.frame({"t_s": 1.0, "mi": float("nan"), "valid": False})
        ev = log.event("decision", 1.0, rpm=20.0, reason="segregating", extra=float("nan"))
        log.set_metadata(config=RunConfig(seed=3).to_metadata(), versions={"numpy": "x"})
        log.set_metadata(calibration={"friction": 0.4})
    rows = read_frames(tmp_path / "run")
    assert [r["t_s"] for r in rows] == [0.5, 1.0]
    assert rows[0]["mi"] == pytest.approx(0.81) and rows[0]["valid"] == 1.0
    assert rows[0]["flags"] == "few_red" and rows[0]["mode"] == "auto"
    assert math.isnan(rows[1]["mi"]) and rows[1]["trend_mi"] is None
    events = read_events(tmp_path / "run")
    assert events == [ev] and events[0]["extra"] is None and events[0]["kind"] == "decision"
    meta = read_metadata(tmp_path / "run")
    assert meta["config"]["seed"] == 3 and meta["calibration"]["friction"] == 0.4
    header = (tmp_path / "run" / "frames.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == (*FRAME_COLUMNS, "run_uid")  # the run uid last (twin.runlog)


def test_reader_drops_a_cut_off_last_line(tmp_path: Path) -> None:
    with RunLog(tmp_path) as log:
        log.frame({"t_s": 1.0, "mi": 0.5})
    with open(tmp_path / "frames.csv", "a") as fh:
        fh.write("2.0,17")  # a crash mid-line
    with open(tmp_path / "events.jsonl", "a") as fh:
        fh.write('{"t_s": 2')
    assert [r["t_s"] for r in read_frames(tmp_path)] == [1.0]
    assert read_events(tmp_path) == []


_WRITER = textwrap.dedent(
    """
    import sys, time
    from twin.runlog import RunLog
    log = RunLog(sys.argv[1])
    log.event("start", 0.0)
    i = 0
    print("ready", flush=True)
    while True:
        log.frame({"t_s": i * 0.01, "frame": i, "mi": 0.5})
        i += 1
        time.sleep(0.01)
    """
)


@pytest.mark.timeout(60)
def test_csv_survives_kill_9(tmp_path: Path) -> None:
    """A writer killed with SIGKILL leaves a readable CSV whose last row is < 1 s old."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        time.sleep(2.0)
        kill_wall = time.time()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    rows = read_frames(tmp_path)
    assert len(rows) > 50
    assert [r["frame"] for r in rows] == list(range(len(rows)))  # no gaps, no torn rows
    # at most the last second is missing: the newest row was written < 1 s before the kill
    assert kill_wall - rows[-1]["wall_s"] < 1.0
    events = read_events(tmp_path)
    assert events and events[0]["kind"] == "start"


def test_config_validation() -> None:
    cfg = RunConfig().resolved()
    assert cfg.demo and cfg.mode == "auto" and cfg.log_dir is not None
    with pytest.raises(TwinError, match="mode"):
        RunConfig(mode="fast").resolved()
    with pytest.raises(TwinError, match="case"):
        RunConfig(case="D").resolved()
    with pytest.raises(TwinError, match="token"):
        RunConfig(host="0.0.0.0").resolved()
    assert RunConfig(host="0.0.0.0", control_token="s3cret").resolved().remote
    with pytest.raises(FileNotFoundError):
        RunConfig(video=Path("/nonexistent.mp4"), mill="loop://").resolved()
    assert RunConfig(control_token="s3cret").to_metadata()["control_token"] == "***"


def test_an_existing_run_is_never_overwritten(tmp_path: Path) -> None:
    with RunLog(tmp_path / "run") as log:
        log.frame({"t_s": 0.5, "mi": 0.81})
    before = (tmp_path / "run" / "frames.csv").read_bytes()
    with pytest.raises(TwinError, match="already holds"):
        RunLog(tmp_path / "run")
    assert (tmp_path / "run" / "frames.csv").read_bytes() == before
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("mine")
    with pytest.raises(TwinError, match="already holds"):
        RunLog(tmp_path / "notes")
    (tmp_path / "afile").write_text("x")
    with pytest.raises(TwinError, match="not a directory"):
        RunLog(tmp_path / "afile")
    (tmp_path / "empty").mkdir()
    with RunLog(tmp_path / "empty") as log:  # an empty directory is fine
        log.event("start", 0.0)
    assert read_events(tmp_path / "empty")[0]["kind"] == "start"


def test_writers_racing_for_one_directory_exactly_one_wins(tmp_path: Path) -> None:
    """The directory is claimed by an exclusive create: every loser gets a TwinError."""
    barrier = threading.Barrier(8)
    won: list[RunLog] = []
    lost: list[Exception] = []

    def claim() -> None:
        barrier.wait()
        try:
            won.append(RunLog(tmp_path / "run"))
        except TwinError as exc:
            lost.append(exc)

    threads = [threading.Thread(target=claim) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert len(won) == 1 and len(lost) == 7
    won[0].close()


def test_default_run_dirs_are_unique_within_one_second(tmp_path: Path) -> None:
    names = {default_run_dir(tmp_path, now_s=1.7e9) for _ in range(200)}
    assert len(names) == 200 and all(str(os.getpid()) in n.name for n in names)
    made = [make_run_dir(tmp_path / "runs") for _ in range(20)]
    assert len(set(made)) == 20 and all(d.is_dir() and not any(d.iterdir()) for d in made)


def test_cli_refuses_an_existing_log_dir(tmp_path: Path) -> None:
    with RunLog(tmp_path / "run") as log:
        log.frame({"t_s": 0.5})
    r = cli("run", "--log", tmp_path / "run", "--no-dashboard", "--duration", "1")
    assert_one_line_error(r, "--log", "already holds")
    assert len(read_frames(tmp_path / "run")) == 1


_STUDY = textwrap.dedent(
    """
    import time
    from multiprocessing import forkserver, util
    from sim.whatif import WhatIfJob, make_pool, run_study
    pool = make_pool(2)
    # the pool starts workers on demand: two overlapping tasks make it start both
    # (quick tasks may all go to the first before a second is needed)
    assert [f.result() for f in [pool.submit(time.sleep, 0.5) for _ in range(2)]] == [None, None]
    pids = list(pool._processes) + [forkserver._forkserver._forkserver_pid]
    print(" ".join(map(str, pids)), util.get_temp_dir(), flush=True)
    run_study([WhatIfJob(rpm=5.0 + i, duration_s=600.0, sample_s=1.0) for i in range(2)], pool=pool)
    """
)


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")  # a zombie is dead
    except (FileNotFoundError, ProcessLookupError):  # gone before, or while, its stat was read
        return True


@pytest.mark.timeout(60)
def test_whatif_workers_die_with_a_killed_parent_and_leave_no_temp_files() -> None:
    proc = subprocess.Popen([sys.executable, "-c", _STUDY], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        *pids, tmp = proc.stdout.readline().split()
        workers = [int(p) for p in pids]
        assert len(workers) == 3 and Path(tmp).is_dir()  # two workers and the fork server
        time.sleep(0.5)  # the study is running
        assert not any(_gone(p) for p in workers)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        end = time.monotonic() + 10
        while time.monotonic() < end and not (all(_gone(p) for p in workers) and not Path(tmp).exists()):
            time.sleep(0.1)
        assert [p for p in workers if not _gone(p)] == []
        assert not Path(tmp).exists()  # the fork server's socket directory is removed
    finally:
        if proc.poll() is None:
            proc.kill()

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
from dataclasses import fields
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, cli
from tests.waiting import wait_until
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
    import sys
    from twin.runlog import RunLog
    log = RunLog(sys.argv[1])
    log.event("start", 0.0)
    i = 0
    print("ready", flush=True)
    while True:  # flat out: the kill lands anywhere in a row's write
        log.frame({"t_s": i * 0.01, "frame": i, "mi": 0.5})
        i += 1
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
        csv_path = tmp_path / "frames.csv"
        wait_until(lambda: csv_path.read_bytes().count(b"\n") > 60, 30, "the writer's first 60 rows")
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


def _cpu_ticks(pid: int) -> int:
    """User + system CPU of process ``pid`` in clock ticks (-1 once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields_ = fh.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return -1
    return int(fields_[11]) + int(fields_[12])


@pytest.mark.timeout(60)
def test_whatif_workers_die_with_a_killed_parent_and_leave_no_temp_files() -> None:
    proc = subprocess.Popen([sys.executable, "-c", _STUDY], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        *pids, tmp = proc.stdout.readline().split()
        workers = [int(p) for p in pids]
        assert len(workers) == 3 and Path(tmp).is_dir()  # two workers and the fork server
        start = [_cpu_ticks(p) for p in workers[:2]]
        wait_until(lambda: all(_cpu_ticks(p) > t0 + 2 for p, t0 in zip(workers[:2], start, strict=True)), 30,
                   "both workers computing the study")
        assert not any(_gone(p) for p in workers)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        wait_until(lambda: all(_gone(p) for p in workers) and not Path(tmp).exists(), 10,
                   "the workers and the fork server's directory to go with their parent")
        assert not Path(tmp).exists()  # the fork server's socket directory is removed
    finally:
        if proc.poll() is None:
            proc.kill()


def test_every_file_carries_the_run_uid_and_metadata_describes_every_column(tmp_path: Path) -> None:
    """Issue 41 item 6: the uid in the three files; metadata.json's descriptors (dtype, shape,
    units, source) of every frames.csv column, in the header's order, and of each event kind."""
    import csv
    import json

    from twin.records import FrameReading, OperatorAction

    with RunLog(tmp_path / "run", run_uid="a-uid") as log:
        log.frame({"t_s": 0.5, "mi": 0.8, "flags": ("few_red", "glare"), "valid": True})
        log.frame({"t_s": 0.6, "mi": 0.81})
        log.record(OperatorAction(t_s=1.0, action="whatif", rpms=(5.0, 10.0)))
        assert read_metadata(tmp_path / "run")["run_uid"] == "a-uid"  # from the start, before any set_metadata
    d = tmp_path / "run"
    with open(d / "frames.csv", newline="") as fh:  # a plain CSV reader reads it
        rows = list(csv.DictReader(fh))
    assert [r["run_uid"] for r in rows] == ["a-uid", "a-uid"] and rows[0]["flags"] == "few_red;glare"
    lines = [json.loads(ln) for ln in (d / "events.jsonl").read_text().splitlines()]
    assert [ln["run_uid"] for ln in lines] == ["a-uid"]
    meta = json.loads((d / "metadata.json").read_text())
    keys = meta["descriptors"]["frame"]["data_keys"]
    assert list(keys) == list(rows[0]) == [*FRAME_COLUMNS, "run_uid"]
    for f in fields(FrameReading):  # derived from the declarations: the same units, the producer's source
        assert keys[f.name]["units"] == f.metadata["unit"] and keys[f.name]["source"] == f.metadata["source"]
    assert (keys["mi"]["dtype"], keys["frame"]["dtype"], keys["valid"]["dtype"]) == ("number", "integer", "boolean")
    assert keys["flags"]["dtype"] == keys["mode"]["dtype"] == "string" and keys["t_s"]["shape"] == []
    assert keys["wall_s"]["units"] == "s" and keys["run_uid"]["dtype"] == "string"
    op = meta["descriptors"]["operator"]
    assert op["file"] == "events.jsonl" and op["data_keys"]["rpms"] == {
        "dtype": "array", "shape": [None], "units": "rpm", "source": "operator", "doc": "what-if speeds",
        "optional": True}
    assert meta["descriptors"]["decision"]["data_keys"]["predictions"]["dtype"] == "object"
    assert "camera_rate" not in meta["descriptors"]  # a dashboard-only record is not in the log
    assert read_events(d) == [{k: v for k, v in lines[0].items() if k != "run_uid"}]  # the reader checks it, drops it


def test_lines_of_another_run_are_skipped_and_counted(tmp_path: Path) -> None:
    """Two runs' files put together: the uid of the majority of the files is the run's; a line or a
    metadata.json of the other run is a note, never data."""
    from twin.runlog import Skips

    for name in ("a", "b"):
        with RunLog(tmp_path / name, run_uid=f"uid-{name}") as log:
            log.frame({"t_s": 1.0, "mi": 0.5})
            log.event("start", 0.0)
    a, b = tmp_path / "a", tmp_path / "b"
    with open(a / "frames.csv", "a") as fh:  # b's rows appended to a's
        fh.writelines((b / "frames.csv").read_text().splitlines(keepends=True)[1:] * 3)
    with open(a / "events.jsonl", "a") as fh:
        fh.write((b / "events.jsonl").read_text())
    skips = Skips()
    assert [r["t_s"] for r in read_frames(a, skips)] == [1.0] and len(read_events(a, skips)) == 1
    assert skips.notes() == ["3 lines of frames.csv skipped: of another run (this run's run_uid is uid-a...)",
                             "1 line of events.jsonl skipped: of another run (this run's run_uid is uid-a...)"]
    (b / "metadata.json").write_bytes((a / "metadata.json").read_bytes())  # a's metadata in b's folder
    skips = Skips()
    assert read_metadata(b, skips) == {} and len(read_frames(b, skips)) == 1
    assert skips.notes() == ["metadata.json not used: of another run (run_uid uid-a..., frames.csv and "
                             "events.jsonl say uid-b...)"]


def test_a_log_of_the_previous_release_reads_as_a_plain_csv_reader_reads_it() -> None:
    """tests/data/runlog-previous (no uid anywhere): read_frames gives what the csv module and
    float() give (empty cell: None), read_events every line, and nothing is noted."""
    import csv
    import json

    from twin.runlog import Skips

    prev = Path(__file__).resolve().parents[1] / "data" / "runlog-previous"

    def plain(v: str) -> object:
        try:
            return None if v == "" else float(v)
        except ValueError:
            return v

    with open(prev / "frames.csv", newline="") as fh:
        want = [{k: plain(v) for k, v in r.items()} for r in csv.DictReader(fh)]
    skips = Skips()
    got = read_frames(prev, skips)
    assert len(got) == len(want) == 120
    for g, w in zip(got, want, strict=True):
        assert g.keys() == w.keys()
        assert all(g[k] == w[k] or (g[k] != g[k] and w[k] != w[k]) for k in w)  # NaN == NaN here
    lines = [json.loads(ln) for ln in (prev / "events.jsonl").read_text().splitlines()]
    assert read_events(prev, skips) == lines and skips.notes() == []

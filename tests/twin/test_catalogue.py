"""The run catalogue (issue 40): run folders indexed, filtered, annotated and rebuilt; a
catalogue that is corrupt, foreign or newer is one line naming what to do."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
import sqlalchemy as sa

from tests.catalogue_runs import RunSpec, make_run, stamp
from tests.cli import assert_one_line_error, cli
from tests.waiting import wait_until
from twin.catalogue import schema
from twin.catalogue.store import Catalogue, RunFilter


def listed(runs: Path, *args: object) -> list[dict]:
    r = cli("runs", "list", "--runs-dir", runs, "--json", *args)
    assert r.code == 0, r.err
    return json.loads(r.out)


def test_a_run_folder_is_summarised_from_what_its_log_holds(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a", RunSpec(rig="pmma", start_rpm=5, rpms=(12.0, 20.0), mixing_time_s=31.5, final_mi=0.93))
    [row] = listed(runs)
    assert row["rig"] == "pmma" and row["mode"] == "auto" and row["objective"] == "time"
    assert (row["rpm_start"], row["rpm_min"], row["rpm_max"], row["rpm_final"]) == (5, 5, 20, 20)
    assert row["mixed"] is True and row["mixing_time_s"] == 31.5 and row["plateau_mi"] == pytest.approx(0.93)
    assert row["final_mi"] == pytest.approx(0.93) and row["frames"] == 5
    assert row["ended"] == "clean" and row["failure"] is None and row["path"] == str((runs / "a").resolve())


def test_a_failed_run_and_an_unmixed_one_say_so(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a", RunSpec(failure="mill link lost", mixing_time_s=None))
    [row] = listed(runs)
    assert row["ended"] == "failed" and row["failure"] == "mill link lost"
    assert row["mixed"] is False and row["mixing_time_s"] is None


def _writer(run_dir: Path) -> subprocess.Popen[bytes]:
    """A process that writes a run's start and then hangs, as a run killed mid-write would."""
    code = ("import signal, sys; from pathlib import Path; from tests.catalogue_runs import RunSpec, make_run;"
            "from twin.runlog import RunLog;"
            "make_run(Path(sys.argv[1]), RunSpec(stopped=False, mixing_time_s=None));"
            "open(Path(sys.argv[1]) / 'ready', 'w').close(); signal.pause()")
    return subprocess.Popen([sys.executable, "-c", code, str(run_dir)], cwd=Path(__file__).parents[2])


def test_a_run_killed_without_a_stop_is_listed_as_killed_with_what_its_log_holds(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    proc = _writer(runs / "k")
    try:
        wait_until(lambda: (runs / "k" / "ready").exists(), 30, "the writer's run")
        [row] = listed(runs)
        assert row["ended"] == "running"  # its process is alive
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        [row] = listed(runs)
        assert row["ended"] == "killed" and "without a stop" in row["failure"]
        assert row["frames"] == 5 and row["rpm_final"] == 20.0  # what its log holds
    finally:
        proc.kill()


def test_filters_select_by_rig_mode_tag_date_endpoint_rpm_and_count(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    day = 86400.0
    t0 = time.mktime((2026, 11, 2, 12, 0, 0, 0, 0, -1))
    specs = {
        "a": RunSpec(rig="pmma", mode="auto", rpms=(20.0,)),
        "b": RunSpec(rig="pmma", mode="off", rpms=(), mixing_time_s=None),
        "c": RunSpec(rig="glass", mode="auto", rpms=(40.0,)),
        "d": RunSpec(rig="pmma", mode="manual", start_rpm=10.0, rpms=(12.0,)),
    }
    for i, (name, spec) in enumerate(specs.items()):
        stamp(make_run(runs / name, spec), t0 + i * day)
    by_path = {Path(r["path"]).name: r for r in listed(runs)}
    assert [Path(r["path"]).name for r in listed(runs)] == ["d", "c", "b", "a"]  # newest first
    ids = {k: v["id"] for k, v in by_path.items()}
    assert cli("runs", "tag", ids["a"], "operator=ana", "--runs-dir", runs).code == 0

    def names(*args: object) -> list[str]:
        return sorted(Path(r["path"]).name for r in listed(runs, *args))

    assert names("--rig", "pmma") == ["a", "b", "d"]
    assert names("--mode", "auto") == ["a", "c"]
    assert names("--tag", "operator=ana") == ["a"] and names("--tag", "operator=bo") == []
    assert names("--tag", "operator") == ["a"]
    assert names("--since", "2026-11-03", "--until", "2026-11-05") == ["b", "c"]
    assert names("--not-mixed") == ["b"] and names("--mixed") == ["a", "c", "d"]
    assert names("--rpm", "15:30") == ["a", "c"]  # c ramped through it to 40
    assert names("--rpm", "25:") == ["c"] and names("--rpm", ":9") == ["a", "b", "c"]
    assert names("--last", "2") == ["c", "d"]
    assert names("--ended", "clean", "--rig", "glass") == ["c"]


@pytest.mark.parametrize("bad", [("--rpm", "fast"), ("--since", "yesterday"), ("--ended", "maybe"),
                                 ("--tag", "=x")])
def test_bad_filters_are_one_line(tmp_path: Path, bad: tuple[str, str]) -> None:
    assert_one_line_error(cli("runs", "list", "--runs-dir", tmp_path, *bad), bad[0])


def test_tags_notes_and_the_golden_mark_live_in_the_folders_and_survive_a_rebuild(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    for name in "abc":
        make_run(runs / name, RunSpec(rig="glass" if name == "c" else "pmma"))
    ids = {Path(r["path"]).name: r["id"] for r in listed(runs)}
    for args in (("tag", ids["a"], "batch=17", "operator=ana"), ("note", ids["a"], "lid left open"),
                 ("golden", ids["a"]), ("golden", ids["c"]), ("golden", ids["b"]), ("tag", ids["a"], "operator=")):
        r = cli("runs", *args, "--runs-dir", runs)
        assert r.code == 0, r.err
    (runs / "catalogue.sqlite").unlink()
    for side in ("-wal", "-shm"):
        (runs / f"catalogue.sqlite{side}").unlink(missing_ok=True)
    assert cli("runs", "rebuild", "--runs-dir", runs).code == 0
    rows = {Path(r["path"]).name: r for r in listed(runs)}
    assert rows["a"]["tags"] == {"batch": "17"} and rows["a"]["note"] == "lid left open"
    assert sorted(n for n, r in rows.items() if r["golden"]) == ["b", "c"]  # one golden per rig: the latest mark


def test_show_prints_the_summary_and_the_events_that_matter(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a", RunSpec(mixing_time_s=42.0))
    run_id = listed(runs)[0]["id"]
    r = cli("runs", "show", run_id[:6], "--runs-dir", runs, "--json")
    assert r.code == 0, r.err
    shown = json.loads(r.out)
    assert shown["summary"]["id"] == run_id
    assert [e["kind"] for e in shown["events"]] == ["start", "mixed", "stop"]
    assert_one_line_error(cli("runs", "show", "nope", "--runs-dir", runs), "no run", "runs list")


def test_a_run_folder_the_catalogue_missed_is_indexed_at_the_next_list(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a")
    assert len(listed(runs)) == 1
    make_run(runs / "b")  # written while the catalogue was not reachable
    assert sorted(Path(r["path"]).name for r in listed(runs)) == ["a", "b"]


@pytest.mark.parametrize("damage", ["truncated", "random", "empty-header"])
def test_a_corrupt_catalogue_is_one_line_naming_rebuild_and_rebuild_restores_every_run(
        tmp_path: Path, damage: str) -> None:
    runs = tmp_path / "runs"
    for name in "abc":
        make_run(runs / name)
    assert len(listed(runs)) == 3
    db = runs / "catalogue.sqlite"
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = db.read_bytes()
    db.write_bytes({"truncated": data[: len(data) // 3], "random": os.urandom(len(data)),
                    "empty-header": b"\0" * 100 + data[100:]}[damage])
    for side in ("-wal", "-shm"):
        (runs / f"catalogue.sqlite{side}").unlink(missing_ok=True)
    assert_one_line_error(cli("runs", "list", "--runs-dir", runs), "runs rebuild")
    r = cli("runs", "rebuild", "--runs-dir", runs)
    assert r.code == 0, r.err
    assert len(listed(runs)) == 3
    assert list(runs.glob("catalogue.sqlite.unreadable-*")), "the unreadable file is kept aside"


def test_a_foreign_database_is_refused_and_kept_aside_by_rebuild(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a")
    with sqlite3.connect(runs / "catalogue.sqlite") as conn:
        conn.execute("CREATE TABLE invoices (n INTEGER)")
        conn.execute("INSERT INTO invoices VALUES (7)")
    assert_one_line_error(cli("runs", "list", "--runs-dir", runs), "not a drumtwin catalogue", "runs rebuild")
    assert cli("runs", "rebuild", "--runs-dir", runs).code == 0
    [aside] = runs.glob("catalogue.sqlite.unreadable-*")
    with sqlite3.connect(aside) as conn:
        assert conn.execute("SELECT n FROM invoices").fetchall() == [(7,)]
    assert len(listed(runs)) == 1


def test_a_catalogue_of_a_newer_schema_is_refused_not_rewritten(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a")
    assert len(listed(runs)) == 1
    with sqlite3.connect(runs / "catalogue.sqlite") as conn:
        conn.execute(f"UPDATE {schema.SCHEMA_TABLE} SET version = {schema.SCHEMA_VERSION + 1}")
    assert_one_line_error(cli("runs", "list", "--runs-dir", runs), "newer", "upgrade drumtwin")
    assert_one_line_error(cli("runs", "rebuild", "--runs-dir", runs), "newer")


def test_migrations_run_in_order_from_the_version_a_catalogue_holds(tmp_path: Path) -> None:
    engine = sa.create_engine(f"sqlite:///{tmp_path / 'c.sqlite'}")
    seen: list[int] = []
    steps = ((1, lambda c: seen.append(1)), (2, lambda c: seen.append(2)), (3, lambda c: seen.append(3)))
    with engine.begin() as conn:
        assert schema.migrate(conn, None, steps[:2]) == 2
    with engine.begin() as conn:
        assert schema.read_version(conn) == 2
        assert schema.migrate(conn, 2, steps) == 3
    assert seen == [1, 2, 3]


def _index_many(url: str, root: Path, names: list[str]) -> subprocess.Popen[bytes]:
    code = ("import sys; from pathlib import Path; from twin.catalogue.store import Catalogue;"
            "cat = Catalogue.open(sys.argv[1], sys.argv[2]);"
            "[cat.index_folder(Path(sys.argv[2]) / n) for n in sys.argv[3:]]")
    return subprocess.Popen([sys.executable, "-c", code, url, str(root), *names], cwd=Path(__file__).parents[2],
                            stderr=subprocess.PIPE)


def test_two_runs_writing_at_once_both_land(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    names = [f"r{i:03d}" for i in range(60)]
    for n in names:
        make_run(runs / n)
    url = str(runs / "catalogue.sqlite")
    Catalogue.open(url, runs).close()
    procs = [_index_many(url, runs, names[0::2]), _index_many(url, runs, names[1::2])]
    for p in procs:
        _out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err.decode()[-2000:]
    with Catalogue.open(url, runs) as cat:
        assert cat.count() == 60
        assert {Path(s.path).name for s in cat.list(RunFilter())} == set(names)


def _on_a_full_disk(tmp_path: Path, args: list[str]) -> subprocess.CompletedProcess[str]:
    """``drumtwin ARGS`` with ``{full}`` a 1 MB tmpfs filled to the last byte (root: a private mount
    namespace; not root: ``unshare -r`` maps us to root in a user namespace)."""
    full = tmp_path / "full"
    full.mkdir()
    argv = [a.replace("{full}", str(full)) for a in args]
    script = (f'mount -t tmpfs -o size=1m tmpfs "{full}" && (cat /dev/zero > "{full}/filler" 2>/dev/null; true) '
              '&& exec "$@"')
    env = {**os.environ, "COLUMNS": "400"}
    env.pop("DRUMTWIN_DEBUG", None)
    cmd = ["unshare", "-rm", "sh", "-c", script, "sh", str(Path(sys.executable).with_name("drumtwin")), *argv]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=Path(__file__).parents[2])


def test_a_catalogue_on_a_full_disk_is_one_line_and_loses_no_run_folder(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    make_run(runs / "a")
    p = _on_a_full_disk(tmp_path, ["runs", "list", "--runs-dir", str(runs), "--catalogue", "{full}/c.sqlite"])
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "full" in lines[0], p.stderr
    assert sorted(f.name for f in (runs / "a").iterdir()) == ["events.jsonl", "frames.csv", "metadata.json"]
    assert len(listed(runs)) == 1  # the folder is intact and indexes elsewhere


def test_rebuild_never_moves_a_directory_or_a_file_it_does_not_own_by_mistake(tmp_path: Path) -> None:
    """Only a catalogue FILE that cannot be read is kept aside by rebuild: a directory given as
    the catalogue is refused in one line and left where it is (a sweep once lost its fixture
    folder to this)."""
    runs = tmp_path / "runs"
    make_run(runs / "a")
    folder = tmp_path / "important"
    (folder / "keep").mkdir(parents=True)
    assert_one_line_error(cli("runs", "rebuild", "--runs-dir", runs, "--catalogue", folder), "is a directory")
    assert (folder / "keep").is_dir() and not list(tmp_path.glob("important.unreadable-*"))

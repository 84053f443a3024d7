"""Issue 40 with real runs: ``drumtwin run`` registers itself in the catalogue at its start and
completes at its stop; two runs at once share one catalogue (SQLite beside the runs, and a real
PostgreSQL server); a catalogue that cannot be written costs the run nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli import cli
from tests.pg import fresh_database, postgres_url  # noqa: F401 -- the session's server
from twin.runlog import read_events

DRUMTWIN = Path(sys.executable).with_name("drumtwin")
LIVE = pytest.mark.xdist_group("live")


def _runs(*argv: str) -> list[subprocess.Popen[str]]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("DRUMTWIN_DEBUG", None)
    env.pop("DRUMTWIN_CATALOGUE", None)
    # 12 s of run time (3 s of wall at --speed 4): four runs starting at once on two cores can take a
    # second or more of wall time (4+ s of run time) before the demo plant's first frame
    return [subprocess.Popen([str(DRUMTWIN), "run", "--no-dashboard", "--speed", "4", "--duration", "12", *a.split()],
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for a in argv]


def _finish(procs: list[subprocess.Popen[str]]) -> list[str]:
    errs = []
    for p in procs:
        _out, err = p.communicate(timeout=240)
        assert p.returncode == 0, err[-2000:]
        errs.append(err)
    return errs


def _listed(*args: object) -> dict[str, dict]:
    r = cli("runs", "list", "--json", *args)
    assert r.code == 0, r.err
    return {Path(row["path"]).name: row for row in json.loads(r.out)}


@LIVE
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_two_runs_at_once_land_in_one_catalogue_beside_them_and_on_a_server(
        tmp_path: Path, postgres_url: str) -> None:  # noqa: F811
    url = fresh_database(postgres_url, "runs_live")
    runs = tmp_path / "runs"
    procs = _runs(f"--log {runs / 'a'} --seed 1", f"--log {runs / 'b'} --seed 2 --mode off",
                  f"--log {runs / 'c'} --catalogue {url}", f"--log {runs / 'd'} --catalogue {url} --mode off")
    _finish(procs)
    beside = _listed("--runs-dir", runs, "--catalogue", runs / "catalogue.sqlite")
    (tmp_path / "elsewhere").mkdir()
    on_server = _listed("--runs-dir", tmp_path / "elsewhere", "--catalogue", url)  # the server alone
    assert set(on_server) == {"c", "d"}
    assert {"a", "b"} <= set(beside)
    for name, row in {**{k: beside[k] for k in "ab"}, **on_server}.items():
        assert row["ended"] == "clean" and row["frames"] > 0 and row["rig"] == "demo", (name, row)
        assert row["mode"] == ("off" if name in "bd" else "auto"), (name, row)
        assert row["final_mi"] is not None and row["energy_j"] is not None and row["energy_j"] > 0, (name, row)
    assert beside["a"]["id"] != beside["b"]["id"]


@LIVE
@pytest.mark.timeout(200)
def test_a_catalogue_that_cannot_be_written_costs_the_run_nothing(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    bad = tmp_path / "catalogue.sqlite"
    bad.write_bytes(os.urandom(8192))  # corrupt
    [err] = _finish(_runs(f"--log {runs / 'a'} --catalogue {bad}"))
    assert "run catalogue not updated" in err
    kinds = [e["kind"] for e in read_events(runs / "a")]
    assert kinds.count("catalogue_unavailable") == 2 and "stop" in kinds  # at its start and at its stop
    assert _listed("--runs-dir", runs)["a"]["ended"] == "clean"  # indexed later, beside the runs

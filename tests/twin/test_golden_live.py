"""A real demo run against its rig's golden batch (issue 40): the run reads the rig's history
from the catalogue beside its folder at its start (on a thread of its own), and a batch behind
the golden one is one ``slower_than_golden`` event in its log, not a fault or an alarm."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.catalogue_runs import RunSpec, make_run, stamp
from tests.cli import cli
from twin.config import RunConfig
from twin.run.main import run_live
from twin.run.settings import Seams
from twin.runlog import read_events

pytestmark = [pytest.mark.xdist_group("live"), pytest.mark.slow]


@pytest.mark.timeout(240)
def test_a_demo_run_behind_its_golden_batch_logs_one_event_and_no_alarm(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    t0 = time.time() - 86400
    for i, mi in enumerate((1.0, 0.99, 0.98)):  # the demo's bed starts at MI ~0.97 and segregates at 5 rpm
        stamp(make_run(runs / f"r{i}", RunSpec(rig="demo", final_mi=mi, frames=121)), t0 + 600 * i)
    assert cli("runs", "list", "--runs-dir", runs).code == 0
    assert cli("runs", "golden", "r0", "--runs-dir", runs).code == 0
    seen: dict = {}
    # a tight band (0.01 MI for 2 s, the endpoint's exit band and dwell: the floor of the spread and the
    # episode's dwell) so that the demo is behind from its first seconds and the run stays short
    seams = Seams(endpoint={"exit_band": 0.01, "exit_dwell_s": 2.0},
                  on_started=lambda loop, plant, dash: seen.update(loop=loop))
    cfg = RunConfig(dashboard=False, duration_s=8.0, speed=4.0, case="C", seed=0, mode="off",
                    log_dir=runs / "now").resolved()
    run_live(cfg, seams)
    events = read_events(runs / "now")
    slower = [e for e in events if e["kind"] == "slower_than_golden"]
    golden_id = next(s["id"] for s in _rows(runs) if s["path"].endswith("/r0"))
    assert len(slower) == 1 and slower[0]["golden_run"] == golden_id, [e["kind"] for e in events]
    e = slower[0]
    assert e["golden_mi"] == 1.0 and e["deviation"] == pytest.approx(e["mi"] - 1.0) and e["deviation"] < -e["spread"]
    assert e["spread"] == pytest.approx(0.01)  # the sd of 1.0, 0.99 and 0.98 is the floor: 0.01
    assert not any(ev["kind"] == "fault" for ev in events)
    snap = seen["loop"].state.snapshot()
    h = snap.rig_history
    assert h.state == "ready" and h.golden is not None and h.golden.run_id == golden_id
    assert [Path(p).name for p in _paths(runs, [r.id for r in h.runs])] == ["r2", "r1", "r0"]  # not this run
    assert snap.alarms == ()


def _rows(runs: Path) -> list[dict]:
    import json

    r = cli("runs", "list", "--runs-dir", runs, "--json")
    assert r.code == 0, r.err
    return json.loads(r.out)


def _paths(runs: Path, ids: list[str]) -> list[str]:
    by_id = {s["id"]: s["path"] for s in _rows(runs)}
    return [by_id[i] for i in ids]

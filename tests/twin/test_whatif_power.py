"""The live what-if carries the twin's time to target, drive power and energy (issue 24 items 2-3) to the
dashboard's table and the run's events: a real study (sim.whatif.run_study, in this process) from a real
twin state."""

from __future__ import annotations

import math

from sim.drum import DrumSim
from sim.whatif import run_study
from tests.twin.test_mill_worker import Sink
from tests.twin.workers_fakes import Boxes
from twin.dashboard.layout import whatif_table_md
from twin.live.commands import RunStudy
from twin.live.snapshots import TwinInfo
from twin.live.whatif import WhatIfWorker
from twin.state import LiveState, WhatIfView


def test_the_live_whatif_reports_time_power_and_energy_to_the_configs_target():
    sim = DrumSim(case="A", seed=0, rpm=5.0, settle_s=0.5)
    seen: list = []

    def study(jobs):
        seen.extend(jobs)
        return run_study(jobs, workers=1)

    b = Boxes()
    b.twin.set(TwinInfo(updated_s=1.0, state=sim.snapshot()))
    state, sink = LiveState(), Sink()
    w = WhatIfWorker(b.view, sink, state, study=study, target_mi=0.2)
    assert w.submit(RunStudy((5.0, 30.0), 3.0)) and w.serve_once()
    assert [j.target_mi for j in seen] == [0.2, 0.2]  # the worker's target reaches every job
    v = state.snapshot().whatif
    assert v.target_mi == 0.2 and v.rpms == (5.0, 30.0)
    assert all(p > 0 for p in v.power_w)
    assert v.power_w[1] > v.power_w[0]  # six times the speed: more power
    assert len(v.time_to_target_s) == len(v.energy_to_target_j) == 2
    for t, e in zip(v.time_to_target_s, v.energy_to_target_j, strict=True):
        assert math.isnan(t) == math.isnan(e)
    (ev,) = [d for k, d in sink.events if k == "whatif"]
    assert ev["target_mi"] == 0.2 and set(ev["power_w"]) == {"5.0", "30.0"}
    table = whatif_table_md(v)
    assert "time to MI 0.2 (s)" in table and "power (W)" in table and "energy (J)" in table
    row30 = next(ln for ln in table.splitlines() if ln.startswith("| 30 |"))
    assert f"{v.power_w[1]:.2f}" in row30


def test_the_table_of_a_study_without_the_new_columns_shows_dashes():
    v = WhatIfView(status="done", rpms=(5.0,), plateau_mi=(0.7,), regime=("rolling",), seq=1)
    table = whatif_table_md(v)
    assert "| 5 | 0.700 | rolling | – | – | – |" in table and "time to target" in table

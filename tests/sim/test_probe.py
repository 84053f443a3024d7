"""The one probe (sim/probe.py, issue 25 item 5): what-if, calibration, validation and ``drumtwin sim``
advance the twin only through it, and it samples on the grid it promises."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.errors import SimError
from sim.measure import free_surface, particle_mi
from sim.probe import probe
from sim.twin_base import FixedStepTwin
from tests.cli import cli

PROBE_FILE = str(Path(__file__).resolve().parents[2] / "sim" / "probe.py")


@pytest.fixture()
def advance_callers(monkeypatch):
    """The source files from which a twin's ``advance`` is called while the fixture is active."""
    callers: list[str] = []
    real = FixedStepTwin.advance

    def spy(self, duration_s):
        callers.append(sys._getframe(1).f_code.co_filename)
        return real(self, duration_s)

    monkeypatch.setattr(FixedStepTwin, "advance", spy)
    return callers


def _only_the_probe(callers: list[str]) -> None:
    assert callers, "the twin was not advanced at all"
    assert {str(Path(c).resolve()) for c in callers} == {PROBE_FILE}, set(callers)


def test_whatif_advances_the_twin_only_through_the_probe(advance_callers):
    from sim.whatif import WhatIfJob, run_job

    r = run_job(WhatIfJob(rpm=5.0, duration_s=0.5, sample_s=0.25))
    assert r.t_s.size == 3
    _only_the_probe(advance_callers)


def test_calibration_advances_the_twin_only_through_the_probe(advance_callers):
    from sim.calibrate import twin_surface

    slope, _ = twin_surface(0.25, 0.1, 10.0, spin_up_s=0.2, window_s=0.4, sample_s=0.2)
    assert math.isfinite(slope)
    _only_the_probe(advance_callers)


def test_validation_advances_the_twin_only_through_the_probe(advance_callers):
    from sim.validation import case_curves, slope_run

    row = slope_run(10.0, 0, duration_s=0.4, spin_up_s=0.2)
    assert math.isfinite(row["slope_deg"])
    curves = case_curves("A", 0, 0.5, every_s=0.25)
    assert curves["t"].size == 3
    _only_the_probe(advance_callers)


def test_the_sim_command_advances_the_twin_only_through_the_probe(advance_callers):
    r = cli("sim", "--duration", 0.5, "--fps", 4, "--size", 96, "--json")
    assert r.code == 0, r.err
    assert json.loads(r.out)["frames"] == 3
    _only_the_probe(advance_callers)


def test_the_probe_samples_on_its_grid_after_the_spin_up():
    sim = DrumSim(case="C", seed=0, rpm=10.0, settle_s=0.2)
    twin = DrumSim.from_state(sim.snapshot())
    samples = list(probe(sim, 1.0, 0.25, spin_up_s=0.5))
    assert [round(s.t_s, 9) for s in samples] == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert samples[0].sim_t_s == pytest.approx(0.5)
    assert math.isnan(samples[0].bed_torque_nm) and all(s.bed_torque_nm < 0 for s in samples[1:])
    # the same as advancing by hand and measuring with sim.measure (bit for bit)
    twin.advance(0.5)
    for s in samples[1:]:
        twin.advance(0.25)
        p = twin.particles()
        np.testing.assert_array_equal(s.particles.x_m, p.x_m)
        assert s.mi.mi == particle_mi(p, twin.drum).mi
        assert s.surface.slope_deg == free_surface(p, twin.drum).slope_deg
    assert len(list(probe(sim, 1.0, 0.25, include_start=False))) == 4
    with pytest.raises(SimError, match="duration"):
        list(probe(sim, 0.0, 0.25))
    with pytest.raises(SimError, match="sample"):
        list(probe(sim, 1.0, -1.0))

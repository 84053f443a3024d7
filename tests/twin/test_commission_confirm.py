"""Commissioning's calibration is confirmed by the twin check's own runs (``twin_check.CheckRuns``), and
the check takes the answer's run as it is: one measurement, one statistic, no second run that could
land elsewhere. The twin is replaced by a fake ``run_twin`` that counts its runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.commission.twin_check as tc
from sim.calibrate import Calibration
from sim.mixer import Friction
from twin.commission import steps
from twin.commission.measure import FrameMeasure, summarize
from twin.commission.twin_check import CheckRuns, TwinFrames


@pytest.fixture
def runs(monkeypatch) -> list[Friction | None]:
    asked: list[Friction | None] = []

    def fake(mixer, rpm, cfg, r_px, diameter_px, *, engine=None, run=tc.TWIN_RUN, **kw) -> TwinFrames:
        asked.append(mixer.friction)
        per = run.per_seed
        # seed k's frames read -(30 + k) deg, one avalanche frame each at -60: the pooled median 32
        slopes = [-(60.0 if i == 0 else 30.0 + k) for k in range(len(run.seeds)) for i in range(per)]
        ms = tuple(FrameMeasure(s, 0.9, (), 0.4, (1.0, 1.0), 0.0) for s in slopes)
        return TwinFrames(ms, np.zeros((4, 4, 3), np.uint8), None)  # type: ignore[arg-type]

    monkeypatch.setattr(tc, "run_twin", fake)
    return asked


def test_a_confirming_measurement_is_the_checks_run_its_median_and_its_seeds_noise(runs) -> None:
    from sim.mixer import paper_mixer

    check = CheckRuns(paper_mixer(), 5.0, None, 300.0, 20.0)  # type: ignore[arg-type]
    m = check(0.2, 0.5, 0.01)
    assert runs == [Friction(sliding=0.2, rolling=0.5, end_plates=0.01)]
    assert m.slope_deg == summarize(list(check.runs[runs[0]].measures)).slope_deg * -1  # the check's statistic
    assert m.slope_deg == 32.0 and m.se_deg == pytest.approx(np.std([30, 31, 32, 33], ddof=1) / 2)
    assert check.frames(Friction(sliding=0.2, rolling=0.5, end_plates=0.01)) is check.runs[runs[0]]
    assert len(runs) == 1  # the check takes the answer's run: not run again
    check.frames(Friction(sliding=0.2, rolling=0.5, end_plates=0.02))
    assert len(runs) == 2  # another friction is another run


@pytest.mark.parametrize(("end_max", "e_asked", "plates"), [(0.05, 0.0, 0.0), (0.0, None, None)])
def test_the_calibrations_friction_is_the_key_of_its_confirming_run(monkeypatch, end_max, e_asked, plates) -> None:
    """A monolayer's plates (searched: the plane's 0) and a deep drum's (the twin's own, the wall's 0.2:
    None) come back as the mixer's friction that names the run the calibration confirmed."""
    import sim.calibrate as cal_mod

    def fake_calibrate(target, rpm, *, measure, **kw) -> Calibration:
        measure(0.2, 0.5, e_asked)
        return Calibration(friction=0.2, rolling=0.5, twin_slope_deg=-31.5, residual_deg=0.0, target_slope_deg=target,
                           rpm=rpm, evaluations=1, history=(), end_friction=0.2 if plates is None else 0.0,
                           end_friction_max=end_max, confirmations=1, slope_se_deg=0.1)

    monkeypatch.setattr(cal_mod, "calibrate", fake_calibrate)
    asked: list[tuple] = []
    measure = lambda f, r, e: asked.append((f, r, e))  # noqa: E731
    cal, friction, err = steps.calibrate_twin(None, -31.5, 5.0, None, measure)  # type: ignore[arg-type]
    assert err is None and friction == Friction(sliding=0.2, rolling=0.5, end_plates=plates)
    assert friction == Friction(sliding=asked[0][0], rolling=asked[0][1], end_plates=asked[0][2])
    assert not math.isnan(cal.slope_se_deg)

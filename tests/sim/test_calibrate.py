"""Calibration by slope angle recovers a known friction (through the vision meter's slope)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.calibrate import calibrate, twin_slope_deg
from sim.drum import DrumSim
from sim.errors import SimError
from sim.measure import twin_meter
from sim.render import Renderer


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_calibration_recovers_a_known_friction_from_rendered_frames():
    true_friction = 0.15
    plant = DrumSim(case="C", seed=7, rpm=5.0, friction=true_friction)
    renderer = Renderer(plant, 360)
    meter = twin_meter(renderer)
    plant.advance(4.0)
    slopes = []
    for _ in range(40):
        plant.advance(0.2)
        slopes.append(meter.measure(renderer.render(plant.particles())).slope_deg)
    target = float(np.nanmean(slopes))
    cal = calibrate(target, 5.0, seed=0)
    assert abs(cal.twin_slope_deg - target) <= 1.5
    assert abs(cal.residual_deg) <= 1.5
    assert 0.5 * true_friction <= cal.friction <= 2.0 * true_friction
    assert cal.evaluations <= 9


def test_slope_grows_with_friction():
    lo = twin_slope_deg(0.05, 0.0, 5.0, spin_up_s=3.0, window_s=3.0)
    hi = twin_slope_deg(0.5, 0.0, 5.0, spin_up_s=3.0, window_s=3.0)
    assert hi > lo + 5.0


def test_bad_calibration_input():
    with pytest.raises(SimError):
        calibrate(95.0, 5.0)
    with pytest.raises(SimError, match="critical"):
        calibrate(25.0, 90.0)
    with pytest.raises(SimError):
        calibrate(25.0, 0.0)

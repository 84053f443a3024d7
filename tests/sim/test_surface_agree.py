"""The twin's free surface (sim.measure.free_surface: the disks' exact upper boundary) and the camera's
(vision.slope via the Meter, on occupancy cells of a frame) are one fit (vision.slope.fit_surface_points)
on two sets of surface points (exact disk tops in columns; a fill threshold in partly filled cells of
pixels); calibration is only valid while they agree, so this test holds the points together on the
twin's own frames."""

from __future__ import annotations

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.measure import free_surface, twin_meter
from sim.probe import probe
from sim.render import Renderer


@pytest.mark.parametrize("rpm", [5.0, 20.0])
def test_the_twins_and_the_cameras_slope_fits_agree_on_twin_frames(rpm):
    """Where calibration works (a rolling or cascading bed) the means agree within 2 deg and single frames
    within 8 deg. A cataracting bed (40 rpm) is left out on purpose: there the fits part frame by frame
    (sd 11 deg, docs/validation.md), flying disks above the surface being cut off by different rules."""
    sim = DrumSim(case="C", seed=0, rpm=rpm)
    renderer = Renderer(sim, 480)
    meter = twin_meter(renderer)
    diffs, slopes = [], []
    for s in probe(sim, 3.0, 0.25, spin_up_s=2.0, include_start=False):
        reading = meter.measure(renderer.render(s.particles))
        particle = free_surface(s.particles, sim.drum).slope_deg
        assert np.isfinite(reading.slope_deg) and np.isfinite(particle)
        diffs.append(reading.slope_deg - particle)
        slopes.append(particle)
    d = np.asarray(diffs)
    assert abs(float(np.mean(d))) < 2.0  # the calibration target: the means agree within 2 deg
    assert float(np.max(np.abs(d))) < 8.0
    assert float(np.std(slopes)) > 0.5  # the bed moves: the agreement is not of one frozen frame

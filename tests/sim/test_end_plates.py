"""A calibrated end-plate friction reaches both engines and the config (issue 39 item 3).

The calibration's ``end_friction`` is applied the way the live loop applies a calibration
(``set_friction(**cal.twin_kwargs())``), seeds a twin (``make_twin``, ``from_placement``) and is
written to and read from the mixer's ``[drum]`` table. Tiny beds, short runs.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace

import numpy as np
import pytest

from sim.calibrate import Calibration
from sim.engine import from_placement, make_twin
from sim.errors import SimError
from sim.mixer import Friction, Mixer, ParticleKind, Shape, mixer_to_toml, parse_mixer
from sim.recipe import DrumSpec

MONO = Mixer(DrumSpec(0.08, 0.003), (ParticleKind("red", Shape("disc", 0.010), count=12, thickness_m=0.003),
                                     ParticleKind("blue", Shape("disc", 0.010), count=12, thickness_m=0.003)),
             fill=0.4, monolayer=True)
CUT = replace(MONO, particles=(MONO.particles[0], replace(MONO.particles[1], shape=Shape("cut_disc", 0.010,
                                                                                       wedge_deg=90.0))))


def _cal(end: float) -> Calibration:
    return Calibration(friction=0.3, rolling=0.2, twin_slope_deg=30.0, residual_deg=0.0, target_slope_deg=30.0,
                       rpm=5.0, evaluations=1, history=(), end_friction=end, end_friction_max=0.048)


@pytest.mark.parametrize("mixer", [MONO, CUT], ids=["dem", "pymunk"])
def test_a_calibration_applied_at_run_time_sets_the_plates_of_either_engine(mixer):
    sim = make_twin(mixer, seed=0, rpm=5.0, settle_s=0.05)
    assert sim.params.end_mu == pytest.approx(sim.params.friction)  # uncalibrated: the wall's friction
    sim.set_friction(**_cal(0.012).twin_kwargs())
    assert (sim.params.friction, sim.params.rolling, sim.params.end_mu) == (0.3, 0.2, 0.012)
    sim.advance(0.05)  # the new plates in the running engine's step
    sim.set_friction(0.4)  # sliding friction alone keeps the calibrated plates
    assert sim.params.end_mu == 0.012
    with pytest.raises(SimError, match="end-plate friction"):
        sim.set_friction(0.4, end_friction=-1.0)


def _slip_m2_s2(state) -> float:
    """Mean square velocity of the discs relative to the plates (which turn with the drum as a rigid body)."""
    w = state.rpm_actual * 2.0 * np.pi / 60.0  # the DEM's sign: counter-clockwise +
    rigid = np.column_stack([-w * state.pos_m[:, 1], w * state.pos_m[:, 0]])
    return float(np.mean(np.sum((state.vel_m_s - rigid) ** 2, axis=1)))


def test_the_plates_set_at_run_time_brake_the_dem_beds_motion_relative_to_them():
    # the same bed from one snapshot, with and without plate friction set at run time
    sim = make_twin(MONO, seed=1, rpm=10.0, settle_s=0.1, end_friction=0.0)
    sim.advance(0.5)
    state = sim.snapshot()
    slips = []
    for end in (0.0, 0.05):
        twin = type(sim).from_state(state)
        twin.set_friction(twin.params.friction, twin.params.rolling, end_friction=end)
        samples = []
        for _ in range(10):
            twin.advance(0.05)
            samples.append(_slip_m2_s2(twin.snapshot()))
        slips.append(float(np.mean(samples)))
    assert slips[1] < 0.7 * slips[0], slips


@pytest.mark.parametrize("mixer", [MONO, CUT], ids=["dem", "pymunk"])
def test_a_twin_seeded_from_a_placement_takes_the_calibrated_plates(mixer):
    pos = np.array([[-0.02, -0.02], [0.02, -0.02]])
    twin = from_placement(mixer, pos, np.array([0, 1]), np.zeros(2), 5.0, settle_s=0.01, end_friction=0.007)
    assert twin.params.end_mu == 0.007
    carried = from_placement(replace(mixer, friction=Friction(end_plates=0.009)), pos, np.array([0, 1]),
                             np.zeros(2), 5.0, settle_s=0.01)
    assert carried.params.end_mu == 0.009  # the mixer's, when none is given


def test_the_mixers_end_friction_is_its_twins_default_and_round_trips_through_the_toml():
    table = tomllib.loads(mixer_to_toml(replace(MONO, friction=Friction(end_plates=0.012))))
    assert table["drum"]["friction"] == {"end_plates": 0.012}
    back = parse_mixer(table, ["red", "blue"])
    assert back.end_friction == 0.012
    assert make_twin(back, seed=0, rpm=5.0, settle_s=0.01).params.end_mu == 0.012
    assert make_twin(back, seed=0, rpm=5.0, settle_s=0.01, end_friction=0.0).params.end_mu == 0.0  # the caller's
    assert "friction" not in tomllib.loads(mixer_to_toml(MONO))["drum"]  # not set: not written
    table["drum"]["friction"]["end_plates"] = -0.1
    with pytest.raises(SimError, match=r"\[drum.friction\]: end_plates must be a number in \[0, 5\]"):
        parse_mixer(table, ["red", "blue"])

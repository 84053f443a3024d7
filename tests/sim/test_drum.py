"""The physics twin: reproducibility, snapshot/restore, containment, rpm ramp, initial cases."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.errors import SimError
from sim.measure import particle_mi
from sim.recipe import PAPER_DRUM


def _arrays(sim):
    p = sim.particles()
    return np.column_stack([p.x_m, p.y_m, p.angle_rad])


def test_same_seed_same_result_and_other_seed_differs():
    a = DrumSim(case="C", seed=3, rpm=10.0)
    b = DrumSim(case="C", seed=3, rpm=10.0)
    c = DrumSim(case="C", seed=4, rpm=10.0)
    for s in (a, b, c):
        s.advance(0.5)
    assert np.array_equal(_arrays(a), _arrays(b))
    assert not np.allclose(_arrays(a), _arrays(c))


def test_snapshot_restore_is_repeatable_and_branches_from_now():
    sim = DrumSim(case="A", seed=1, rpm=5.0)
    sim.advance(0.5)
    sim.advance(0.3 * sim.substep_s())  # leave part of a step in the accumulator: the snapshot carries it
    state = pickle.loads(pickle.dumps(sim.snapshot()))  # what-if workers get it pickled
    assert len(state.extra["springs"][1]) > 100  # the contacts' tangential springs travel with it
    sim.advance(0.5)
    first = _arrays(sim)
    t_first = sim.t_s
    sim.restore(state)
    assert sim.t_s == pytest.approx(0.5 + 0.3 * sim.substep_s())
    assert np.array_equal(_arrays(sim)[:, :2], state.pos_m)
    sim.advance(0.5)
    assert sim.t_s == pytest.approx(t_first)
    second = _arrays(sim)
    branch = DrumSim.from_state(state)
    branch.advance(0.5)
    assert np.array_equal(second, _arrays(branch))  # restore and from_state agree exactly
    # the snapshot's own future is the same as any branch from it
    assert np.array_equal(first, second)


def test_set_rpm_is_acceleration_limited_and_reaches_the_setpoint():
    sim = DrumSim(rpm=5.0, accel_rpm_s=20.0, settle_s=0.2)
    sim.set_rpm(25.0)
    sim.advance(0.5)
    assert sim.rpm_actual == pytest.approx(15.0, abs=0.3)
    assert sim.rpm_target == 25.0
    sim.advance(1.0)
    assert sim.rpm_actual == pytest.approx(25.0)


@pytest.mark.parametrize("rpm", [15.0, 70.0])
def test_no_disk_sinks_into_the_wall_up_to_0_9_of_critical_speed(rpm):
    sim = DrumSim(case="C", seed=2, rpm=rpm)
    st = sim.stats()
    assert st.steps == 0 and st.wall_max_mm == 0.0
    sim.advance(0.5)  # the drum starts at full speed: the bed's start-up transient
    start = sim.stats()
    assert start.steps == int(0.5 / sim.substep_s())  # 0.5 s of fixed steps
    assert 0.0 < start.wall_max_mm <= 2.0  # the deepest any disk got into the wall, every step
    sim.reset_stats()
    sim.advance(1.0)
    p = sim.particles()
    assert np.all(np.isfinite(p.x_m)) and np.all(np.isfinite(p.y_m))
    assert float(np.max(np.hypot(p.x_m, p.y_m) + p.r_m)) < PAPER_DRUM.radius_m + 0.002
    st = sim.stats()
    assert 0.0 < st.wall_max_mm <= 2.0
    assert st.overlap_p99_r <= 0.05 and st.contacts > 0


def test_advance_runs_the_same_fixed_steps_however_the_caller_slices_time():
    a = DrumSim(case="C", seed=5, rpm=10.0, settle_s=0.2)
    b = DrumSim(case="C", seed=5, rpm=10.0, settle_s=0.2)
    for _ in range(10):
        a.advance(0.1)  # --fps 10
    for _ in range(60):
        b.advance(1 / 60)  # --fps 60
    assert a.n_steps == b.n_steps == int(1.0 / a.substep_s())
    assert a.t_s == pytest.approx(b.t_s)
    assert np.array_equal(_arrays(a), _arrays(b))
    # a call shorter than one step runs no step, and the remainder is kept, not lost
    c = DrumSim(case="C", seed=5, rpm=10.0, settle_s=0.2)
    h = c.substep_s()
    for _ in range(7):
        c.advance(0.4 * h)
    assert c.n_steps == 2 and c.t_s == pytest.approx(2.8 * h)


def test_initial_cases_match_the_paper():
    mis = {case: particle_mi(DrumSim(case=case, seed=0).particles(), PAPER_DRUM) for case in "ABC"}
    assert mis["A"].mi < 0.3 and mis["B"].mi < 0.3
    assert mis["C"].mi > 0.85
    # case A is split left-right, case B top-bottom
    pa = DrumSim(case="A", seed=0).particles()
    assert pa.x_m[pa.cls == 0].mean() < pa.x_m[pa.cls == 1].mean()
    pb = DrumSim(case="B", seed=0).particles()
    assert pb.y_m[pb.cls == 0].mean() > pb.y_m[pb.cls == 1].mean()


def test_set_friction_changes_the_contacts_and_defaults_are_the_papers():
    sim = DrumSim(settle_s=0.1)
    assert (sim.params.friction, sim.params.rolling, sim.params.restitution) == (0.25, 0.1, 0.5)
    sim.set_friction(0.3, 0.05)
    assert sim.params.friction == 0.3 and sim.params.rolling == 0.05
    assert sim.snapshot().params.friction == 0.3


def test_a_step_too_long_for_the_contacts_is_an_error():
    with pytest.raises(SimError, match="too long for this bed's contacts"):
        DrumSim(dt_s=0.002, settle_s=0.0)
    assert DrumSim(dt_s=0.0001, settle_s=0.0).substep_s() == 0.0001


def test_another_recipe_gets_its_own_step_and_stays_contained():
    from sim.recipe import DrumSpec, ParticleSpec, Recipe

    drum = DrumSpec(diameter_m=0.2, depth_m=0.05)
    recipe = Recipe((ParticleSpec("big", 0.012, 60), ParticleSpec("small", 0.006, 480)), fill=0.4)
    sim = DrumSim(drum, recipe, case="C", seed=1, rpm=30.0, settle_s=0.3)
    assert sim.substep_s() < DrumSim(settle_s=0.0).substep_s()  # lighter disks, shorter contacts
    sim.advance(1.0)
    p = sim.particles()
    assert np.all(np.hypot(p.x_m, p.y_m) + p.r_m < drum.radius_m + 0.002)
    st = sim.stats()
    assert st.overlap_p99_r <= 0.05 and st.wall_max_mm <= 2.0

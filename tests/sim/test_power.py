"""Drive torque, power and time to mix from the twin (issue 24 items 2-3): the hand calculation of a
rigid bed, the torque's sign and its scaling with the drum's depth, time and energy to a target MI."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.errors import SimError
from sim.mixer import paper_mixer
from sim.power import (
    class_masses_kg,
    depth_scale,
    drive_power_w,
    gravity_torque_nm,
    rigid_bed_torque_nm,
    segment_centroid_m,
)
from sim.probe import probe
from sim.recipe import PAPER_RECIPE
from sim.whatif import TARGET_DWELL_S, WhatIfJob, energy_to, run_job, run_study, summarize, time_to_target


def _tilted(state, beta_deg: float) -> DrumSim:
    """A twin of ``state`` with the whole bed turned by ``beta_deg`` about the axis (counter-clockwise)."""
    b = math.radians(beta_deg)
    rot = np.array([[math.cos(b), math.sin(b)], [-math.sin(b), math.cos(b)]])
    return DrumSim.from_state(replace(state, pos_m=state.pos_m @ rot))


def test_a_rigid_bed_held_at_its_slope_loads_the_drum_with_its_weight_times_its_centroid_lever_arm():
    """The hand calculation: a bed at rest, tilted and held by very high friction (sliding and rolling 5,
    the drum still), puts the torque M g x_c on the drum (x_c: its centroid's horizontal lever arm).
    A torque that missed the wall's tangential forces, took the wrong lever or the wrong sign fails."""
    sim = DrumSim(case="C", seed=0, rpm=0.0, friction=5.0, rolling=5.0, settle_s=2.0)
    state = sim.snapshot()
    out = []
    for beta in (15.0, 25.0):
        twin = _tilted(state, beta)
        twin.advance(1.0)  # the contacts take the new load
        twin.drum_torque_nm()
        before = twin.particles()
        twin.advance(0.5)
        tq = twin.drum_torque_nm()
        after = twin.particles()
        moved = np.hypot(after.x_m - before.x_m, after.y_m - before.y_m)
        assert np.median(moved) < 2.5e-3  # held: it creeps < half a small radius in 0.5 s (a flow: ~40 mm)
        mass = class_masses_kg(twin)[0][after.cls]
        hand = gravity_torque_nm(after, mass)
        x_c = float(np.dot(mass, after.x_m) / mass.sum())
        assert hand == pytest.approx(-float(mass.sum()) * 9.81 * x_c)
        assert x_c > 0.01  # tilted counter-clockwise: the centroid is well right of the axis
        assert tq == pytest.approx(hand, rel=0.02)  # within 2 % (the issue asks 5 %)
        out.append(tq)
    assert out[1] < out[0] < 0  # steeper: more torque against the counter-clockwise turn


def test_the_segment_model_of_a_half_full_drum():
    """A half-full drum's segment is a half disc: centroid 4R / (3 pi) from the axis; its torque at 30 deg
    is M g 4R/(3 pi) / 2."""
    assert segment_centroid_m(0.5, 0.15) == pytest.approx(4 * 0.15 / (3 * math.pi), rel=1e-9)
    assert rigid_bed_torque_nm(2.0, 0.5, 0.15, 30.0) == pytest.approx(2.0 * 9.81 * 4 * 0.15 / (3 * math.pi) * 0.5)
    assert segment_centroid_m(0.2, 0.15) > segment_centroid_m(0.5, 0.15)  # a thinner bed lies further out


@pytest.mark.parametrize("direction", [1, -1])
def test_the_bed_resists_the_rotation_whichever_way_the_drum_turns(direction):
    """At positive rpm the bed's torque on the drum is against the turn (negative in the mixer's sense)
    and the drive's power positive, for a counter-clockwise and a clockwise mixer; the bed climbs the
    wall the drum turns towards (its centroid right of the axis for ccw, left for cw)."""
    mixer = replace(paper_mixer(), direction=direction)
    sim = DrumSim(mixer=mixer, case="C", seed=1, rpm=10.0)
    mass = class_masses_kg(sim)[0][sim.particles().cls]
    samples = list(probe(sim, 3.0, 0.05, spin_up_s=2.0, include_start=False))
    tq = float(np.mean([s.bed_torque_nm for s in samples]))
    assert tq < 0
    assert float(drive_power_w(tq, 10.0)) > 0
    assert all(direction * float(np.dot(mass, s.particles.x_m)) > 0 for s in samples)
    # the flowing bed in the mean: its own weight moment (angular momentum balance), within 3 %
    weight_moment = float(np.mean([gravity_torque_nm(s.particles, mass, direction) for s in samples]))
    assert tq == pytest.approx(weight_moment, rel=0.03)
    assert math.isnan(sim.drum_torque_nm())  # the mean restarts at each call: no step since


def test_power_scales_with_the_drums_depth_and_the_slice_with_the_3d_beds_mass():
    """Without end plates the slice's physics does not depend on the depth: twice as deep a drum needs
    exactly twice the power. The paper's slice stands for its 250 + 2000 balls (their mass / the
    discs' mass, within 2 %)."""
    mixer = paper_mixer()
    deep = replace(mixer, drum=replace(mixer.drum, depth_m=2 * mixer.drum.depth_m))
    kw = {"end_friction": 0.0}
    a = run_job(WhatIfJob(rpm=20.0, duration_s=2.0, mixer=mixer, sample_s=0.5, sim_kwargs=kw))
    b = run_job(WhatIfJob(rpm=20.0, duration_s=2.0, mixer=deep, sample_s=0.5, sim_kwargs=kw))
    np.testing.assert_allclose(b.mi, a.mi)
    assert a.summary()["power_w"] > 0
    assert b.summary()["power_w"] == pytest.approx(2 * a.summary()["power_w"], rel=1e-9)
    assert b.summary()["torque_nm"] == pytest.approx(2 * a.summary()["torque_nm"], rel=1e-9)
    sim = DrumSim(case="C", seed=0, rpm=5.0, settle_s=0.2)
    balls_kg = sum(q.count * q.density_kg_m3 * math.pi / 6 * q.diameter_m**3 for q in PAPER_RECIPE.particles)
    discs_kg = float(class_masses_kg(sim)[0][sim.particles().cls].sum())
    assert depth_scale(sim) == pytest.approx(balls_kg / discs_kg, rel=0.02)
    mono = replace(mixer, monolayer=True, drum=replace(mixer.drum, depth_m=0.02))
    assert depth_scale(DrumSim(mixer=mono, case="C", seed=0, rpm=5.0, settle_s=0.2)) == 1.0


def test_time_to_target_on_synthetic_curves():
    t = np.arange(0.0, 20.01, 0.5)
    ramp = np.clip(t / 10.0, 0, 1)  # reaches 0.5 at 5 s
    assert time_to_target(t, ramp, 0.5) == pytest.approx(5.0, abs=0.3)
    assert time_to_target(t, ramp, 0.0) == 0.0  # already there at the start
    assert math.isnan(time_to_target(t, ramp, 1.01))  # never
    assert math.isnan(time_to_target(t, ramp, None))  # no target
    noisy = ramp.copy()
    noisy[4] = 0.9  # one outlier at 2 s does not count as reaching 0.5
    assert time_to_target(t, noisy, 0.5) > 3.0
    touch = ramp.copy()
    touch[6:10] = 0.8  # 2 s above 0.7 at 3-4.5 s, then back below: not there (the dwell); there at 7 s
    assert time_to_target(t, touch, 0.7) == pytest.approx(7.0, abs=0.3)
    assert math.isnan(time_to_target(t[t <= 8.0], ramp[t <= 8.0], 0.5))  # crossed at 5 s, the run ends before the dwell
    dip = ramp.copy()
    dip[(t >= 12.0) & (t < 14.0)] = 0.3  # there at 5 s, then 2 s below: "there" only from the last dip on
    assert time_to_target(t, dip, 0.5) == pytest.approx(13.75, abs=0.3)  # the 2 s mean past the dip
    assert math.isnan(time_to_target(t[t <= 17.0], dip[t <= 17.0], 0.5))  # after the dip, < 5 s to the end
    assert energy_to(t, np.full(t.size, 2.0), 5.0) == pytest.approx(10.0)
    assert energy_to(t, np.full(t.size, 2.0), 5.25) == pytest.approx(10.5)
    assert math.isnan(energy_to(t, np.full(t.size, 2.0), math.nan))


def test_time_and_energy_to_target_from_the_twin_with_the_spread_of_three_seeds():
    """A segregated bed (case A) at 30 rpm reaches MI 0.3 (and stays there for the dwell) within 6 s in each
    of three seeds (time > 0,
    energy ~ power x time); nobody reaches 0.999 (NaN time and energy). The per-rpm row carries the
    seed mean and sd of each."""
    jobs = [WhatIfJob(rpm=30.0, duration_s=6.0 + TARGET_DWELL_S, case="A", seed=s, sample_s=0.25, target_mi=0.3)
            for s in range(3)]
    res = run_study(jobs, workers=1)
    for r in res:
        s = r.summary()
        assert 0.0 < s["time_to_target_s"] < 6.0
        assert s["mi_start"] < 0.3
        assert s["power_w"] > 0
        mean_p = float(np.mean(r.power_w[1:][r.t_s[1:] <= s["time_to_target_s"] + 0.25]))
        assert s["energy_to_target_j"] == pytest.approx(mean_p * s["time_to_target_s"], rel=0.2)
        assert s["torque_nm"] == pytest.approx(s["power_w"] / (30.0 * 2 * math.pi / 60), rel=0.05)
    row = summarize(res)[0]
    assert row["time_to_target_reached"] == 3
    times = [r.time_to_target_s for r in res]
    assert row["time_to_target_s"] == pytest.approx(np.mean(times))
    assert row["time_to_target_sd_s"] == pytest.approx(np.std(times, ddof=1))
    assert row["power_sd_w"] > 0 and math.isfinite(row["energy_to_target_sd_j"])
    never = run_job(replace(jobs[0], target_mi=0.999)).summary()
    assert math.isnan(never["time_to_target_s"]) and math.isnan(never["energy_to_target_j"])
    assert never["power_w"] == pytest.approx(res[0].summary()["power_w"])  # the same run otherwise


def test_pymunk_reads_the_drums_contact_impulses_as_a_torque():
    """The pymunk engine's torque (the wall's contact impulses of the last step and the reactions of
    rolling and end-plate friction): a settled bed in a still drum gives its weight moment (within
    2 %: the paper drum's end plates hold about 12 % of it, so leaving them out fails), and a turning
    drum a torque against the turn."""
    from sim.pymunk_twin import PymunkDrumSim

    still = PymunkDrumSim(paper_mixer(), case="C", seed=0, rpm=0.0, dt_s=0.002)  # accounting, at any step
    assert math.isnan(still.drum_torque_nm())  # no step yet
    still.advance(2.5)  # at rest
    tq, hand = [], []
    mass = class_masses_kg(still)[0]
    for _ in range(10):
        still.advance(0.02)
        p = still.particles()
        tq.append(still.drum_torque_nm())
        hand.append(gravity_torque_nm(p, mass[p.cls]))
    assert abs(np.mean(hand)) > 1e-3
    assert np.mean(tq) == pytest.approx(np.mean(hand), rel=0.02)
    turning = PymunkDrumSim(paper_mixer(), case="C", seed=0, rpm=10.0, dt_s=0.002)
    turning.advance(1.5)
    vals = []
    for _ in range(20):
        turning.advance(0.05)
        vals.append(turning.drum_torque_nm())
    assert np.mean(vals) < 0


def test_the_whatif_command_reports_power_and_time_to_the_target_and_refuses_a_bad_target():
    from tests.cli import assert_one_line_error, cli

    r = cli("whatif", "--rpm", "30", "--duration", 11, "--case", "A", "--seeds", 2, "--sample-s", 0.25,
            "--workers", 1, "--target-mi", 0.3, "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    (row,) = out["rpm"]
    assert out["target_mi"] == 0.3 and row["power_w"] > 0 and row["power_sd_w"] is not None
    assert row["time_to_target_reached"] == 2 and 0 < row["time_to_target_s"] < 6
    never = json.loads(cli("whatif", "--rpm", "30", "--duration", 1, "--workers", 1, "--target-mi", 1.0,
                           "--json").out)["rpm"][0]
    assert never["time_to_target_s"] is None and never["energy_to_target_j"] is None  # NaN -> null
    assert_one_line_error(cli("whatif", "--rpm", "30", "--duration", 1, "--target-mi", 1.5), "--target-mi")


def test_the_flowing_beds_mean_torque_is_its_mean_weight_moment_within_half_a_percent():
    """Angular momentum balance: over 10 s of a cascading bed (20 rpm, end plates on) the drum's mean
    torque equals the mean moment of the bed's weight. Slices of 353 steps (0.1 s) are not a multiple of
    the end plates' sampling (every 16 steps): a sampled share weighted per sample instead of per step
    read 1.7 % high here."""
    twin = DrumSim(case="A", seed=0, rpm=20.0)
    mass = class_masses_kg(twin)[0][twin.particles().cls]
    samples = list(probe(twin, 10.0, 0.1, spin_up_s=5.0, include_start=False))
    tq = np.mean([s.bed_torque_nm for s in samples])
    wm = np.mean([gravity_torque_nm(s.particles, mass) for s in samples])
    assert tq == pytest.approx(wm, rel=0.005)


def test_the_pymunk_flowing_beds_mean_torque_is_its_mean_weight_moment():
    """Angular momentum balance on the pymunk engine: over 10 s of the paper bed at 20 rpm (end plates
    and rolling friction on, both applied outside Chipmunk's solver) the mean of the one-step torque
    samples is the mean moment of the bed's weight within 4 % (their standard error: about 1.2 %).
    Without the two frictions' reactions on the drum it read 0.57."""
    from sim.pymunk_twin import PymunkDrumSim

    twin = PymunkDrumSim(paper_mixer(), case="C", seed=0, rpm=20.0, dt_s=0.002)  # accounting, at any step
    twin.advance(3.0)
    mass = class_masses_kg(twin)[0]
    tq, wm = [], []
    for _ in range(200):
        twin.advance(0.05)
        p = twin.particles()
        tq.append(twin.drum_torque_nm())
        wm.append(gravity_torque_nm(p, mass[p.cls]))
    assert np.mean(tq) == pytest.approx(np.mean(wm), rel=0.04)


@pytest.mark.parametrize("engine", ["dem", "pymunk"])
def test_a_whatif_from_a_state_ramps_the_drum_at_the_supervisors_rate(engine):
    """AUTO's studies carry the supervisor's rate limit: from a bed at 5 rpm the twin's drum reaches 25 rpm
    at 4 rpm/s (5 s), as the mill will, not at the twin's own 20 rpm/s (1 s); the start state is not
    changed (its own limit is kept for the next study)."""
    from sim.engine import make_twin

    step = {"dt_s": 0.002} if engine == "pymunk" else {}  # the ramp, at any step (pymunk's disc-bed default: 0.5 ms)
    twin = make_twin(paper_mixer(), engine, case="C", seed=0, rpm=5.0, **step)
    twin.advance(0.3)
    state = twin.snapshot()
    fast = run_job(WhatIfJob(rpm=25.0, duration_s=2.0, start=state, sample_s=0.5))  # its own ramp: there by 1.5 s
    slow = run_job(WhatIfJob(rpm=25.0, duration_s=6.0, start=state, sample_s=0.5, ramp_rpm_s=4.0))
    at = {round(float(t), 1): float(r) for t, r in zip(slow.t_s - slow.t_s[0], slow.rpm_actual, strict=True)}
    assert abs(at[2.5]) == pytest.approx(5.0 + 4.0 * 2.5, abs=1.0)
    assert abs(at[5.5]) == pytest.approx(25.0, abs=0.5)
    assert abs(fast.rpm_actual[fast.t_s - fast.t_s[0] >= 1.5][0]) == pytest.approx(25.0, abs=0.5)
    assert state.params.accel_rpm_s == 20.0
    with pytest.raises(SimError, match="ramp"):
        run_study([WhatIfJob(rpm=25.0, duration_s=1.0, start=state, ramp_rpm_s=0.0)], workers=1)


def test_energy_and_time_part_on_a_real_study_of_a_segregated_bed():
    """The twin's own power curve decides: from a segregated bed (case A) to MI 0.65, 45 rpm gets there
    first (about 4 s against 10 s at 20 rpm) and each objective picks the rpm its own column favours, with
    the other's choice in its reason when they part. (Until the converged step of issue 39, t_c/8, 20 rpm
    reached MI 0.8 with less energy than 45 rpm; at the converged step it mixes the split more slowly and
    takes more: 16.8 against 15.7 J to 0.65 with seed 0.) To MI 0.9 20 rpm does not stay there and both
    objectives pick 45 rpm. The rows are the study's summary, as AUTO gets them."""
    from control.objective import RpmPrediction, choose

    jobs = [WhatIfJob(rpm=r, duration_s=16.0, case="A", seed=0, sample_s=0.5, mixer=paper_mixer(), target_mi=0.65)
            for r in (20.0, 45.0)]
    res = run_study(jobs, workers=1)

    def rows(results) -> list[RpmPrediction]:
        return [RpmPrediction(e["rpm"], e["plateau_mi"], e["time_to_target_s"], e["energy_to_target_j"], e["power_w"])
                for e in summarize(results)]

    by = {r.job.rpm: r for r in res}
    assert by[45.0].time_to_target_s < 0.6 * by[20.0].time_to_target_s
    assert all(math.isfinite(r.energy_to_target_j) and r.energy_to_target_j > 0 for r in res)
    cheaper = min(res, key=lambda r: r.energy_to_target_j).job.rpm
    tm = choose(rows(res), "time", 5.0, (5.0, 45.0), 0.65)
    en = choose(rows(res), "energy", 5.0, (5.0, 45.0), 0.65)
    assert (tm.rpm, en.rpm) == (45.0, cheaper)
    if cheaper != 45.0:
        assert f"energy would pick {cheaper:g} rpm" in tm.reason and "time would pick 45 rpm" in en.reason
    hi = [replace(r, target_mi=0.9) for r in jobs]
    res9 = [replace(x, time_to_target_s=time_to_target(x.t_s, x.mi, 0.9)) for x in res]
    res9 = [replace(x, job=j, energy_to_target_j=energy_to(x.t_s, x.power_w, x.time_to_target_s))
            for x, j in zip(res9, hi, strict=True)]
    assert math.isnan(res9[0].time_to_target_s) or res9[0].time_to_target_s > res9[1].time_to_target_s
    assert choose(rows(res9), "energy", 5.0, (5.0, 45.0), 0.9).rpm == 45.0

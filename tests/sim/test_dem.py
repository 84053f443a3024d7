"""The compiled DEM step (``sim.dem``): restitution, rolling friction, free flight, contact statistics."""

from __future__ import annotations

import numpy as np
import pytest

from sim import dem, dem_contact, dem_neighbours
from sim.drum import DEFAULT_DT_S, STEPS_PER_CONTACT, DrumSim
from sim.params import DEFAULT_STIFFNESS_N_M

R_SMALL = 0.005
M_SMALL = 9.75e-4  # kg, a 10 mm disk of the paper bed
G = 9.81
BIG = 100.0  # m: the radius of a drum whose bottom is flat for a small disk
ON_BOTTOM = (0.0, -BIG + R_SMALL - M_SMALL * G / (2 * DEFAULT_STIFFNESS_N_M))
"""A small disk resting on the bottom of that drum (m; the wall's stiffness is twice its pair's)."""


def _run(pos, vel, omg, n_steps, *, r=R_SMALL, m=M_SMALL, drum_r=1.0, mu=0.25, mu_r=0.1, e=0.5, g=0.0,
         dt=DEFAULT_DT_S, k=DEFAULT_STIFFNESS_N_M, skin=0.4 * R_SMALL, end=0.0):
    """Run the kernel on a few equal disks; returns (pos, vel, omg, hist, acc, ncont) after ``n_steps``
    (``skin``: the smallest Verlet skin, m; ``end``: end-plate friction over the drum's depth, 1/m)."""
    pos = np.array(pos, float).reshape(-1, 2)
    vel = np.array(vel, float).reshape(-1, 2)
    omg = np.array(omg, float)
    n = pos.shape[0]
    prm = np.zeros(dem.P_N)
    prm[[dem.P_DT, dem.P_MU, dem.P_MU_W, dem.P_MU_R, dem.P_G, dem.P_R, dem.P_SKIN,
         dem.P_ACCEL, dem.P_RMIN, dem.P_END]] = [dt, mu, mu, mu_r, g, drum_r, skin, 20.0, r, end]
    rad = np.full(n, r)
    kk = dem_neighbours.neighbour_slots(r, r, max(skin, dem_neighbours.SKIN_MAX_R * r))
    hist = np.zeros(1001, dtype=np.int64)
    acc = np.zeros(dem.ACC_N)
    ncont = np.zeros(n, dtype=np.int64)
    pair, wall = dem_contact.contact_tables(np.array([m]), np.array([r]), k, e)
    done = dem.run(n_steps, prm, np.zeros(3), pos, vel, np.zeros(n), omg, rad, np.zeros(n, dtype=np.int64),
            np.full(n, 1 / m), 1 / (0.4 * m * rad**2), pair,
            wall, np.zeros(n + 1, dtype=np.int64), np.zeros(n * kk, dtype=np.int64),
            np.zeros(n * kk), np.zeros(n), np.zeros((n, 2)), True, hist, acc, ncont)
    assert done == n_steps
    return pos, vel, omg, hist, acc, ncont


@pytest.mark.parametrize("e", [0.2, 0.5, 0.9])
def test_a_head_on_collision_at_the_default_step_has_the_set_restitution(e):
    # the twin's step for restitution e: the contact time (every pair's) / STEPS_PER_CONTACT;
    # averaged over where in a step the contact starts (32 onsets over one whole step): at four
    # steps per contact one collision's restitution depends on that phase (0.41-0.63 at e = 0.5),
    # its mean does not much: 0.167 / 0.489 / 0.903 for e = 0.2 / 0.5 / 0.9 (the step's error,
    # largest for strong damping; docs/validation.md, section 3)
    t_c = dem_contact.contact_time_s(DEFAULT_STIFFNESS_N_M, M_SMALL / 2, e)
    dt = t_c / STEPS_PER_CONTACT
    out = []
    for gap in np.arange(32) / 32 * 0.5 * dt:  # v = 0.5 m/s: onsets over one whole step
        _, vel, _, _, _, _ = _run([[-R_SMALL - gap / 2, 0], [R_SMALL + gap / 2, 0]], [[0.25, 0], [-0.25, 0]],
                                  [0, 0], 3 * STEPS_PER_CONTACT + 2, e=e, dt=dt)
        out.append((vel[1, 0] - vel[0, 0]) / 0.5)
    assert np.mean(out) == pytest.approx(e, abs=0.04)
    assert np.ptp(out) > 0.02  # (the onsets did span the step)


def _rolling_speed(mu_r: float) -> tuple[np.ndarray, np.ndarray]:
    """A disk rolling without slip along the bottom of a 200 m drum (locally flat), drum at rest."""
    dt = DEFAULT_DT_S
    state = ([ON_BOTTOM], [[0.3, 0.0]], [-0.3 / R_SMALL])
    ts, vs = [], []
    for i in range(20):
        pos, vel, omg, _, _, _ = _run(*state, int(0.01 / dt), drum_r=BIG, mu_r=mu_r, g=G)
        state = (pos, vel, omg)
        ts.append((i + 1) * int(0.01 / dt) * dt)
        vs.append(vel[0, 0])
        assert vel[0, 0] == pytest.approx(-omg[0] * R_SMALL, rel=0.02)  # still rolling, not sliding
    return np.array(ts), np.array(vs)


def test_rolling_friction_decelerates_a_rolling_disk_at_the_rate_mu_r_predicts():
    t, v = _rolling_speed(0.1)
    a = np.polyfit(t, v, 1)[0]
    # torque mu_r r m g against the rolling, I = 2/5 m r^2: a = -mu_r g / (1 + 2/5) = -5/7 mu_r g
    assert a == pytest.approx(-5 / 7 * 0.1 * G, rel=0.05)
    t0, v0 = _rolling_speed(0.0)
    assert abs(np.polyfit(t0, v0, 1)[0]) < 0.02 * abs(a)  # no rolling friction: it keeps rolling


def test_every_disk_pair_and_a_disk_at_the_wall_have_the_same_contact_time():
    # MercuryDPM's collision-time parametrisation: the lightest pair has the set stiffness, the others
    # a stiffness in proportion to their effective mass (the paper bed: 10 mm and 20 mm disks)
    from sim.drum import _slab_m
    from sim.recipe import PAPER_DRUM, PAPER_RECIPE, slice_2d

    classes = slice_2d(PAPER_RECIPE, PAPER_DRUM)
    m = np.array([c.mass_kg(_slab_m(classes)) for c in classes])
    r = np.array([c.radius_m for c in classes])
    pair, wall = dem_contact.contact_tables(m, r, 3000.0, 0.5)
    m_pair = m[:, None] * m[None, :] / (m[:, None] + m[None, :])
    t_c = dem_contact.contact_time_s(3000.0, m_pair.min(), 0.5)
    assert pair[..., 3].min() == pytest.approx(3000.0)  # the lightest pair keeps the set stiffness
    assert pair[..., 3].max() == pytest.approx(3000.0 * 4)  # two 20 mm disks (4x the mass per disk)
    for a in range(2):
        assert dem_contact.contact_time_s(wall[a, 1], m[a], 0.5) == pytest.approx(t_c)
        assert wall[a, 2] == pytest.approx(2 / 7 * wall[a, 1]) and wall[a, 3] == pytest.approx(1 / wall[a, 2])
        for b in range(2):
            assert dem_contact.contact_time_s(pair[a, b, 3], m_pair[a, b], 0.5) == pytest.approx(t_c)
            # the damping gives every pair the same restitution: c_n = 2 zeta sqrt(m* k_n)
            zeta = dem_contact.damping_ratio(0.5)
            assert pair[a, b, 0] == pytest.approx(2 * zeta * np.sqrt(m_pair[a, b] * pair[a, b, 3]))


def test_end_plates_decelerate_a_sliding_disk_at_mu_end_g_r_over_the_depth():
    # a disk sliding without spin on the frictionless bottom of a 200 m drum at rest: the two end plates
    # 0.1 m apart (friction 0.25) take mu_end r sum(F_n) / depth, with sum(F_n) = m g; the same run
    # without end plates takes out the drum's curvature (it climbs 0.6 mm/m along the path)
    depth, mu_end = 0.1, 0.25
    n = int(0.02 / DEFAULT_DT_S)
    rates = []
    for end in (mu_end / depth, 0.0):
        state = ([ON_BOTTOM], [[0.3, 0.0]], [0.0])
        ts, vs = [], []
        for i in range(20):
            pos, vel, omg, _, _, _ = _run(*state, n, drum_r=BIG, mu=0.0, mu_r=0.0, g=G, end=end)
            state = (pos, vel, omg)
            ts.append((i + 1) * n * DEFAULT_DT_S)
            vs.append(vel[0, 0])
        assert omg[0] == 0.0  # it slides: no friction turns it
        rates.append(np.polyfit(ts[2:], vs[2:], 1)[0])  # (after the first contact's settling)
    assert abs(rates[1]) < 0.1 * abs(rates[0])
    assert rates[0] - rates[1] == pytest.approx(-mu_end * G * R_SMALL / depth, rel=0.03)


def test_end_plate_friction_stops_a_slow_disk_without_reversing_it_and_spares_one_turning_with_the_drum():
    _, vel, _, _, _, _ = _run([ON_BOTTOM], [[1e-4, 0.0]], [0.0], int(0.1 / DEFAULT_DT_S), drum_r=BIG, mu=0.0, mu_r=0.0,
                              g=G, end=2.5)
    assert abs(vel[0, 0]) < 1e-12  # stopped within 0.1 s, not pushed back
    # a disk pressed on a wall that moves with it: no relative velocity to the end plates, no force
    pos, vel, _, _, _, _ = _run([[0.0, 0.5]], [[0.0, 0.0]], [0.0], 200, drum_r=1.0, mu=0.0, mu_r=0.0, end=2.5)
    assert vel[0, 1] == 0.0 and pos[0, 1] == 0.5


def test_rolling_friction_never_reverses_the_rotation():
    # a spinning disk resting on the flat bottom with huge rolling friction stops spinning, then stays still
    _, vel, omg, _, _, _ = _run([ON_BOTTOM], [[0.0, 0.0]], [5.0], int(0.3 / DEFAULT_DT_S),
                                drum_r=BIG, mu_r=5.0, mu=0.0, g=G)
    assert abs(omg[0]) < 1e-9 and abs(vel[0, 0]) < 1e-9


def test_contact_statistics_overlaps_wall_depth_and_airborne():
    # disk 0 and 1 overlap by 0.5 mm; disk 2 is 1.2 mm into the wall of a 0.1 m drum; disk 3 floats
    r = R_SMALL
    pos = [[-0.03, 0.0], [-0.03 + 2 * r - 0.0005, 0.0], [0.1 - r + 0.0012, 0.0], [0.0, 0.05]]
    _, _, _, hist, acc, ncont = _run(pos, np.zeros((4, 2)), np.zeros(4), 1, drum_r=0.1)
    assert acc[dem.ACC_CONTACTS] == 1
    assert acc[dem.ACC_OVERLAP_MAX] == pytest.approx(0.1)  # 0.5 mm of a 5 mm small radius
    assert acc[dem.ACC_WALL_MAX] == pytest.approx(0.0012)
    assert list(ncont) == [1, 1, 1, 0]
    assert acc[dem.ACC_AIRBORNE] == pytest.approx(1 / 4)
    assert hist.sum() == 1 and hist[49:51].sum() == 1  # bins of 0.002 small radii


def test_a_disk_in_free_flight_keeps_its_spin():
    sim = DrumSim(case="C", seed=0, rpm=5.0, settle_s=0.1)
    st = sim.snapshot()
    st.pos_m[0] = (0.0, 0.12)  # near the top of the drum, far above the bed
    st.vel_m_s[0] = (0.0, 0.0)
    st.omega_rad_s[0] = 7.0
    sim = DrumSim.from_state(st)
    sim.advance(0.02)  # still far from the bed
    assert sim.contact_counts()[0] == 0
    assert sim.snapshot().omega_rad_s[0] == 7.0
    assert sim.particles().y_m[0] == pytest.approx(0.12 - 0.5 * G * 0.02**2, abs=2e-4)  # it falls freely


def test_the_verlet_skin_changes_only_the_cost_not_a_single_bit():
    # 42 disks thrown around a 6 cm drum under gravity: many collisions, fast then settling disks;
    # a fixed wide skin, the default and a skin chosen from the speed alone give the same bits
    rng = np.random.default_rng(7)
    xy = np.array([(x, y) for x in np.arange(-0.035, 0.036, 0.011) for y in np.arange(-0.03, 0.031, 0.011)])
    vel0 = rng.normal(0.0, 0.6, xy.shape)
    runs = [_run(xy, vel0, np.zeros(len(xy)), 3000, drum_r=0.06, g=G, skin=s * R_SMALL) for s in (0.02, 0.4, 1.5)]
    assert runs[0][4][dem.ACC_CONTACTS] > 3000  # the disks did collide
    for pos, vel, omg, hist, acc, _ in runs[1:]:
        assert np.array_equal(pos, runs[0][0]) and np.array_equal(vel, runs[0][1]) and np.array_equal(omg, runs[0][2])
        assert np.array_equal(hist, runs[0][3]) and np.array_equal(acc, runs[0][4])


def test_the_neighbour_list_holds_every_pair_within_reach_once_in_sorted_rows_with_its_spring():
    # 600 disks of two sizes in a 0.3 m drum (many per cell, some outside the box's cells), against
    # all pairs by brute force; a spring of the old list survives only for a pair still listed
    rng = np.random.default_rng(3)
    n, skin = 600, 0.004
    rad = np.where(rng.random(n) < 0.3, 0.01, 0.005)
    pos = rng.uniform(-0.15, 0.15, (n, 2))
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    want = [(i, j) for i in range(n) for j in range(i + 1, n) if d[i, j] < rad[i] + rad[j] + skin]
    cap = 40 * n
    nb_start, nb_j, nb_xi = np.zeros(n + 1, dtype=np.int64), np.zeros(cap, dtype=np.int64), np.zeros(cap)
    # an old list: disk 0 with springs for its first two partners and for one pair that is gone
    old = sorted({*[j for i, j in want if i == 0][:2], n - 1})
    nb_start[1:] = len(old)
    nb_j[: len(old)] = old
    nb_xi[: len(old)] = np.arange(1, len(old) + 1) * 1e-4
    ref = np.zeros((n, 2))
    ok = dem_neighbours.rebuild_list(pos, rad, nb_start, nb_j, nb_xi, np.empty(cap, dtype=np.int64), np.empty(cap),
                                     ref, skin, 0.15, 0.01)
    assert ok and len(want) > 2 * n
    got = [(i, int(j)) for i in range(n) for j in nb_j[nb_start[i]:nb_start[i + 1]]]
    assert got == want  # every pair once, rows by i, sorted by j
    kept = {(0, j): x for j, x in zip(old, np.arange(1, len(old) + 1) * 1e-4, strict=True) if (0, j) in want}
    for k, (i, j) in enumerate(got):
        assert nb_xi[k] == kept.get((i, j), 0.0)
    assert np.array_equal(ref, pos)
    assert not dem_neighbours.rebuild_list(pos, rad, nb_start, nb_j[: len(want) - 1], nb_xi[: len(want) - 1],
                            np.empty(len(want) - 1, dtype=np.int64), np.empty(len(want) - 1), ref, skin, 0.15, 0.01)


def test_the_list_skin_lasts_the_set_steps_at_the_fastest_speed_within_its_bounds():
    dt, r = 2e-4, R_SMALL
    vel = np.array([[0.1, 0.0], [0.0, -0.2]])
    assert dem_neighbours.list_skin(vel, dt, 0.1 * r, r) == pytest.approx(2 * dem_neighbours.SKIN_STEPS * 0.2 * dt)
    assert dem_neighbours.list_skin(vel * 0.01, dt, 0.1 * r, r) == 0.1 * r  # slow: the smallest skin
    widest = dem_neighbours.SKIN_MAX_R * r
    assert dem_neighbours.list_skin(vel * 100, dt, 0.1 * r, r) == pytest.approx(widest)  # fast: the widest

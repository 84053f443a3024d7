"""The pymunk twin (sim.pymunk_twin): interface, shapes, fixed step, snapshots, friction laws."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.errors import SimError
from sim.measure import radial_spread_m
from sim.mixer import Baffles, Mixer, ParticleKind, Shape, shape_area_m2
from sim.pymunk_shapes import convex_pieces
from sim.pymunk_twin import PymunkDrumSim
from sim.recipe import DrumSpec
from sim.twin_base import ContactStats
from vision.shapes import polygon_area


def _small_rig(cut: bool = True, n: int = 30, baffles: Baffles | None = None, drum_mm: float = 120.0) -> Mixer:
    disc = ParticleKind("blue", Shape("disc", 0.010), 1190.0, count=n, thickness_m=0.005, colour_bgr=(220, 60, 0))
    other = ParticleKind("white", Shape("cut_disc", 0.010, wedge_deg=90.0) if cut else Shape("disc", 0.010),
                         1190.0, count=n, thickness_m=0.005, colour_bgr=(255, 255, 255))
    return Mixer(DrumSpec(drum_mm / 1e3, 0.005), (disc, other), fill=0.4, monolayer=True, baffles=baffles)


@pytest.fixture(scope="module")
def running() -> PymunkDrumSim:
    sim = PymunkDrumSim(_small_rig(), seed=3, rpm=10.0, settle_s=0.3)
    sim.advance(0.3)
    return sim


@pytest.mark.parametrize("shape", [
    Shape("cut_disc", 0.010, wedge_deg=90.0),
    Shape("notched_disc", 0.010, notch_deg=90.0, notch_depth=0.4),  # issue 39's shallow notch
    Shape("notched_disc", 0.010, notch_deg=30.0, notch_depth=0.1),  # a slit: the apex sees nearly a full turn
    Shape("notched_disc", 0.010, notch_deg=170.0, notch_depth=0.9),
], ids=["cut", "notch-90-0.4", "slit", "wide-deep"])
def test_cut_and_notched_disc_pieces_are_convex_and_cover_the_shape(shape: Shape) -> None:
    pieces = convex_pieces(shape)
    assert len(pieces) >= 2  # non-convex: more than one piece
    for p in pieces:
        d = np.roll(p, -1, axis=0) - p
        cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
        assert np.all(cross >= -1e-12)  # counter-clockwise and convex
    covered = sum(polygon_area(p) for p in pieces)
    assert covered == pytest.approx(shape_area_m2(shape), rel=0.05)  # the wedge is out, the rest in


def test_vertices_shape_is_decomposed() -> None:
    # an L (non-convex)
    v = ((0.0, 0.0), (0.01, 0.0), (0.01, 0.004), (0.004, 0.004), (0.004, 0.01), (0.0, 0.01))
    shape = Shape("vertices", 0.014, vertices_m=v)
    pieces = convex_pieces(shape)
    assert len(pieces) >= 2
    assert sum(polygon_area(p) for p in pieces) == pytest.approx(shape_area_m2(shape), rel=1e-6)


def test_interface_and_particles(running: PymunkDrumSim) -> None:
    p = running.particles()
    assert len(p) == 60
    assert set(np.unique(p.cls)) == {0, 1}
    assert p.class_names == ("blue", "white")
    assert p.class_outline_m[0] is None and p.class_outline_m[1] is not None
    r = np.hypot(p.x_m, p.y_m)
    assert np.all(r + 0.5 * p.r_m < running.drum.radius_m + 1e-3)  # contained in the drum
    assert running.rpm_actual == pytest.approx(10.0)
    assert running.critical_rpm == pytest.approx(42.3 / math.sqrt(0.12))
    st = running.stats()
    assert isinstance(st, ContactStats) and st.steps > 0 and st.contacts > 0
    assert 0.0 <= st.airborne < 0.5


def test_bed_settles_at_the_bottom_and_the_bed_turns(running: PymunkDrumSim) -> None:
    p = running.particles()
    assert np.mean(p.y_m) < -0.2 * running.drum.radius_m  # gravity: the bed lies in the lower half


def test_fixed_step_independent_of_slicing() -> None:
    a = PymunkDrumSim(_small_rig(n=12), seed=1, rpm=8.0, settle_s=0.1)
    b = PymunkDrumSim.from_state(a.snapshot())
    a.advance(0.1)
    for _ in range(37):
        b.advance(0.1 / 37)
    assert a.n_steps == b.n_steps
    pa, pb = a.particles(), b.particles()
    np.testing.assert_array_equal(pa.x_m, pb.x_m)
    np.testing.assert_array_equal(pa.angle_rad, pb.angle_rad)


def test_twins_built_at_other_addresses_run_bit_identically() -> None:
    """Same seed, same calls, whatever else the process holds: the post-step pass puts a pair's contacts
    with equal normals (a cut disc's two pieces on one wall segment) in an order of their own, not in
    Chipmunk's, which follows memory layout. Ordering them by the normal alone let two such twins part
    by 2e-17 m within 0.5 s in about half of the cases (end-plate sums added in another order)."""
    ref = PymunkDrumSim(_small_rig(), seed=1, rpm=10.0, settle_s=0.1)
    ref.advance(0.5)
    for k in range(4):
        _others = [PymunkDrumSim(_small_rig(), seed=2, rpm=10.0, settle_s=0.02) for _ in range(k + 1)]
        twin = PymunkDrumSim(_small_rig(), seed=1, rpm=10.0, settle_s=0.1)
        twin.advance(0.5)
        np.testing.assert_array_equal(twin.particles().x_m, ref.particles().x_m)
        del _others


def test_snapshot_restore_is_bit_exact() -> None:
    sim = PymunkDrumSim(_small_rig(n=15), seed=2, rpm=12.0, settle_s=0.1)
    sim.advance(0.2)
    state = sim.snapshot()
    branch = PymunkDrumSim.from_state(state)
    sim.advance(0.3)
    branch.advance(0.3)
    np.testing.assert_array_equal(sim.particles().x_m, branch.particles().x_m)
    np.testing.assert_array_equal(sim.particles().y_m, branch.particles().y_m)
    # restore goes back in time on the same object, and a pickled state travels (what-if workers)
    import pickle

    sim.restore(pickle.loads(pickle.dumps(state)))
    assert sim.t_s == pytest.approx(state.t_s)
    sim.advance(0.3)
    np.testing.assert_array_equal(sim.particles().x_m, branch.particles().x_m)


def test_same_seed_same_run_and_seeds_differ() -> None:
    a = PymunkDrumSim(_small_rig(n=10), seed=5, rpm=6.0, settle_s=0.1)
    b = PymunkDrumSim(_small_rig(n=10), seed=5, rpm=6.0, settle_s=0.1)
    c = PymunkDrumSim(_small_rig(n=10), seed=6, rpm=6.0, settle_s=0.1)
    np.testing.assert_array_equal(a.particles().x_m, b.particles().x_m)
    assert not np.array_equal(a.particles().x_m, c.particles().x_m)


def test_set_rpm_is_acceleration_limited() -> None:
    sim = PymunkDrumSim(_small_rig(n=10), seed=0, rpm=5.0, settle_s=0.1, accel_rpm_s=20.0)
    sim.set_rpm(25.0)
    sim.advance(0.5)
    assert sim.rpm_actual == pytest.approx(15.0, abs=0.1)  # 5 + 20 rpm/s * 0.5 s
    assert sim.rpm_target == 25.0
    sim.advance(1.0)
    assert sim.rpm_actual == pytest.approx(25.0)
    with pytest.raises(SimError, match="critical"):
        sim.set_rpm(sim.critical_rpm + 1.0)


def test_direction_turns_the_drum_the_other_way() -> None:
    ccw = PymunkDrumSim(_small_rig(n=10), seed=0, rpm=10.0, settle_s=0.1)
    m = _small_rig(n=10)
    cw = PymunkDrumSim(Mixer(m.drum, m.particles, m.fill, -1, m.monolayer), seed=0, rpm=10.0, settle_s=0.1)
    ccw.advance(0.1)
    cw.advance(0.1)
    assert ccw._drum.angle > 0 > cw._drum.angle


def test_end_plates_brake_the_flow() -> None:
    """With strong end-plate friction the particles move with the drum more (less relative motion)."""
    def rel_speed(end: float) -> float:
        sim = PymunkDrumSim(_small_rig(cut=False, n=20), seed=0, rpm=15.0, settle_s=0.2, end_friction=end)
        sim.advance(0.5)
        w = sim._drum.angular_velocity
        u = [math.hypot(b.velocity.x + w * b.position.y, b.velocity.y - w * b.position.x) for b in sim._bodies]
        return float(np.mean(u))

    assert rel_speed(3.0) < 0.7 * rel_speed(0.0)


def test_rolling_friction_slows_a_rolling_disc() -> None:
    """A lone disc on the turning drum's wall: rolling friction changes its spin relative to the wall."""
    def spin(mu_r: float) -> float:
        m = Mixer(DrumSpec(0.12, 0.005), (ParticleKind("blue", Shape("disc", 0.01), 1190.0, count=1,
                                                        thickness_m=0.005),), fill=0.1, monolayer=True)
        sim = PymunkDrumSim(m, seed=0, rpm=0.0, settle_s=0.2, rolling=mu_r, end_friction=0.0)
        b = sim._bodies[0]
        b.position = (0.03, -0.05)
        b.velocity = (0.3, 0.0)
        sim.advance(0.3)
        return abs(b.angular_velocity) + abs(b.velocity.x)

    assert spin(0.5) < 0.8 * spin(0.0)


def _lone_disc(mu_r: float, dt_s: float, rpm: float = 0.0, direction: int = 1) -> PymunkDrumSim:
    m = Mixer(DrumSpec(0.12, 0.005), (ParticleKind("blue", Shape("disc", 0.01), 1190.0, count=1,
                                                    thickness_m=0.005),), fill=0.1, direction=direction,
              monolayer=True)
    return PymunkDrumSim(m, seed=0, rpm=rpm, settle_s=0.2, rolling=mu_r, end_friction=0.0, dt_s=dt_s)


def _polar_deg(sim: PymunkDrumSim) -> float:
    """The lone disc's angle about the axis from straight down (deg, positive: x > 0)."""
    b = sim._bodies[0]
    return math.degrees(math.atan2(b.position.x, -b.position.y))


@pytest.mark.parametrize("dt_s", [0.0005, 0.002])
def test_rolling_friction_holds_a_disc_below_its_angle_without_creep_and_rolls_it_above(dt_s: float) -> None:
    """A lone disc at rest on the still drum's wall where the wall is tilted by theta: the couple
    mu_r r F_n holds it for tan(theta) < mu_r (torque balance about the contact) and not above, at
    any step. The rolling friction stops the rolling mode (spin and the translation that rolls with
    it), so a held disc does not creep: a couple on the spin alone let it creep down at a speed
    proportional to the step (0.1 deg in 0.5 s at 0.5 ms, 0.5 deg at 2 ms, at 3 deg)."""
    mu_r = 0.1  # holds up to 5.71 deg
    for tilt, held in ((3.0, True), (5.0, True), (8.0, False)):
        sim = _lone_disc(mu_r, dt_s)
        r_c = sim.drum.radius_m - 0.005
        b = sim._bodies[0]
        b.position = (r_c * math.sin(math.radians(tilt)), -r_c * math.cos(math.radians(tilt)))
        b.velocity, b.angular_velocity = (0.0, 0.0), 0.0
        sim.advance(0.05)
        start = _polar_deg(sim)
        sim.advance(0.5)
        moved = start - _polar_deg(sim)
        if held:
            assert abs(moved) < 0.02, (tilt, dt_s, moved)
        else:
            assert moved > 1.0, (tilt, dt_s, moved)


@pytest.mark.parametrize("direction", [1, -1])
def test_a_lone_disc_rides_the_turning_wall_up_to_the_rolling_friction_angle(direction: int) -> None:
    """In the turning drum a lone disc rolls in place where gravity's moment about the contact equals the
    rolling couple: tan(phi) = mu_r, on the side the wall rises (ccw: x > 0). The wall is a static ring
    whose surface moves with the drum (``surface_velocity``): a wrong sign puts the disc on the other side."""
    for mu_r in (0.2, 0.4):
        for dt_s in (0.0005, 0.002):
            sim = _lone_disc(mu_r, dt_s, rpm=10.0, direction=direction)
            sim.advance(1.0)
            phis = []
            for _ in range(20):
                sim.advance(0.1)
                phis.append(_polar_deg(sim))
            want = direction * math.degrees(math.atan(mu_r))
            assert abs(float(np.mean(phis)) - want) < 1.0, (mu_r, dt_s, direction, np.mean(phis), want)


def test_baffles_turn_with_the_drum() -> None:
    m = _small_rig(n=10, baffles=Baffles(4, 0.015, 0.004))
    sim = PymunkDrumSim(m, seed=0, rpm=10.0, settle_s=0.1)
    b0 = sim.particles().baffles_m
    assert len(b0) == 4
    sim.advance(0.5)
    b1 = sim.particles().baffles_m
    turned = math.atan2(b1[0][:, 1].mean(), b1[0][:, 0].mean()) - math.atan2(b0[0][:, 1].mean(), b0[0][:, 0].mean())
    assert turned == pytest.approx(10 * 2 * math.pi / 60 * 0.5, abs=0.05)


def test_bad_input_is_a_sim_error() -> None:
    with pytest.raises(SimError, match="case"):
        PymunkDrumSim(_small_rig(n=5), case="D")
    with pytest.raises(SimError, match="friction"):
        PymunkDrumSim(_small_rig(n=5), friction=-1.0)
    with pytest.raises(SimError, match="time step"):
        PymunkDrumSim(_small_rig(n=5), dt_s=0.5)
    with pytest.raises(SimError, match="critical"):
        PymunkDrumSim(_small_rig(n=5), rpm=500.0)
    with pytest.raises(SimError, match="does not fit"):
        PymunkDrumSim(_small_rig(n=400))
    sim = PymunkDrumSim(_small_rig(n=5), settle_s=0.05)
    with pytest.raises(SimError):
        sim.advance(-1.0)


def test_radial_spread() -> None:
    from sim.twin_base import Particles

    p = Particles(x_m=np.array([1.0, -1.0, 2.0, -2.0]), y_m=np.zeros(4), r_m=np.ones(4), cls=np.array([0, 0, 1, 1]))
    assert radial_spread_m(p) == pytest.approx((1.0, 2.0))


def test_render_draws_the_shapes_and_the_baffles() -> None:
    from sim.mixer import shape_outline_m
    from sim.render import RIM_BGR, Renderer
    from sim.twin_base import Particles

    drum = DrumSpec(0.1, 0.005)
    cut = Shape("cut_disc", 0.02, wedge_deg=90.0)
    base = dict(x_m=np.array([-0.02, 0.02]), y_m=np.zeros(2), r_m=np.full(2, 0.01), cls=np.array([0, 1]),
                angle_rad=np.zeros(2), class_bgr=((0, 0, 220), (220, 60, 0)))
    r = Renderer(drum, 400)
    discs = r.render(Particles(**base))
    shaped = r.render(Particles(**base, class_outline_m=(None, shape_outline_m(cut))))
    assert discs is not None and shaped is not None

    def count(img: np.ndarray, bgr: tuple[int, int, int]) -> int:
        return int(np.all(img == np.array(bgr, np.uint8), axis=2).sum())

    assert count(shaped, (0, 0, 220)) == count(discs, (0, 0, 220))  # the disc class unchanged
    assert count(shaped, (220, 60, 0)) / count(discs, (220, 60, 0)) == pytest.approx(0.75, abs=0.04)  # wedge cut
    box = np.array([[0.03, -0.002], [0.05, -0.002], [0.05, 0.002], [0.03, 0.002]])
    baffled = r.render(Particles(**base, baffles_m=(box,)))
    assert baffled is not None and count(baffled, RIM_BGR) > count(discs, RIM_BGR) + 50



def test_from_placement_starts_from_the_given_bed() -> None:
    m = _small_rig(n=20)
    from sim.pymunk_twin import PymunkDrumSim as P

    # two clusters: class 0 in a column on the left, class 1 on the right, well inside the drum
    ys = np.linspace(-0.036, 0.0, 5)
    left = np.array([(x, y) for x in (-0.007, -0.017, -0.027, -0.037) for y in ys])
    pos = np.vstack([left, left * np.array([-1.0, 1.0])])
    cls = np.repeat([0, 1], 20)
    sim = P.from_placement(m, pos, cls, np.zeros(40), rpm=10.0, settle_s=0.2, seed=1)
    p = sim.particles()
    assert sim.case == "image" and sim.t_s == 0.0 and sim.rpm_actual == pytest.approx(10.0)
    assert np.array_equal(p.cls, cls)
    assert p.x_m[cls == 0].mean() < -0.01 and p.x_m[cls == 1].mean() > 0.01  # settled, not re-placed by a case
    assert np.mean(p.x_m[cls == 0] < 0.0) > 0.8 and np.mean(p.x_m[cls == 1] > 0.0) > 0.8
    r = np.hypot(p.x_m, p.y_m)
    assert np.all(r < m.drum.radius_m)
    # inflated to full size: no deep overlaps left between neighbours
    assert sim.stats().overlap_p99_r < 0.1
    sim.advance(0.1)
    assert sim.n_steps == round(0.1 / sim.substep_s())  # runs on its fixed step
    # the same placement gives the same twin, bit for bit
    again = P.from_placement(m, pos, cls, np.zeros(40), rpm=10.0, settle_s=0.2, seed=1)
    again.advance(0.1)
    assert np.array_equal(again.particles().x_m, sim.particles().x_m)


def test_from_placement_rejects_a_bad_placement_in_one_line() -> None:
    m = _small_rig(n=2)
    pos = np.array([[0.0, -0.03], [0.01, -0.03]])
    for bad in (
        dict(pos_m=pos[:1], classes=np.array([0, 1]), angle_rad=np.zeros(2)),  # shapes differ
        dict(pos_m=pos, classes=np.array([0, 2]), angle_rad=np.zeros(2)),  # no class 2
        dict(pos_m=pos * 10, classes=np.array([0, 1]), angle_rad=np.zeros(2)),  # outside the drum
        dict(pos_m=pos, classes=np.array([0, 1]), angle_rad=np.array([0.0, np.nan])),
    ):
        with pytest.raises(SimError) as exc:
            PymunkDrumSim.from_placement(m, rpm=5.0, **bad)
        assert "\n" not in str(exc.value)


def test_post_step_contact_order_is_the_stable_sort_by_particle_pair() -> None:
    """The post-step pass orders contacts by (a, b) with two counting-sort passes: the same order
    as a stable sort of a * (n + 1) + b (the canonical order bit-exact branches rely on)."""
    from sim.pymunk_contacts import _counting_sort

    rng = np.random.default_rng(0)
    for _ in range(200):
        n, m = int(rng.integers(1, 300)), int(rng.integers(0, 800))
        a, b = rng.integers(0, n + 1, m), rng.integers(0, n + 1, m)
        order = _counting_sort(a, _counting_sort(b, np.arange(m), n), n)
        assert np.array_equal(order, np.argsort(a * (n + 1) + b, kind="mergesort"))

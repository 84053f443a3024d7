"""The trend's arithmetic against filterpy's ``KalmanFilter``, and its rules by known answers
(issue 27's mutation tests of control/trend.py; issue 41: one filter, not two).

``FilterpyKalman`` runs filterpy's own class behind the trend's engine interface; a trend on it
must give every field of every estimate the trend on ``control.trend.Kalman`` gives, at every step
of sequences made to pass every branch, under three configurations. The rules around the
arithmetic (the model's matrices, the projection, the noise pairs, the gate and the window) are
checked by hand-computed answers here and in test_trend_rules.py.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from control.errors import ControlError
from control.trend import Z95, Kalman, MITrend, TrendConfig, project, transition, turning


class FilterpyKalman:
    """filterpy's ``KalmanFilter`` (dim 5, one measurement) behind :class:`control.trend.Kalman`'s methods."""

    def __init__(self, x: np.ndarray, P: np.ndarray) -> None:
        self.f = KalmanFilter(dim_x=len(x), dim_z=1)
        self.f.x = np.array(x, dtype=float).reshape(-1, 1)
        self.f.P = np.array(P, dtype=float)

    @property
    def x(self) -> np.ndarray:
        return self.f.x[:, 0]  # a view: the trend's projection writes through it

    @property
    def P(self) -> np.ndarray:
        return self.f.P

    def predict(self, F: np.ndarray, Q: np.ndarray) -> None:
        self.f.predict(F=F, Q=Q)

    def innovation(self, z: float, h: np.ndarray, r: float) -> tuple[float, float]:
        probe = copy.deepcopy(self.f)
        probe.update(np.array([[z]]), R=r, H=h.reshape(1, -1))
        return float(probe.y[0, 0]), float(probe.S[0, 0])

    def update(self, z: float, h: np.ndarray, r: float) -> None:
        self.f.update(np.array([[z]]), R=r, H=h.reshape(1, -1))


class OnFilterpy(MITrend):
    engine = FilterpyKalman  # type: ignore[assignment]


def sequence(seed: int) -> list[tuple[float, float, float]]:
    """(t_s, MI, rpm) at 30 fps through every branch: NaN before the first sample, ripple at 10 rpm, a ramp,
    NaN frames, single glitches, a
    burst that unsettles but does not re-initialise, a step that does, ramps into both bounds and into
    the rate bound, the drum at rest, a negative and a NaN rpm, a repeated time, a 2 s gap (no noise
    learnt across it) and a 40 s gap (re-initialised)."""
    rng = np.random.default_rng(seed)
    out: list[tuple[float, float, float]] = []
    t = 0.0

    def add(n: int, mi, rpm, noise: float = 0.01) -> None:
        nonlocal t
        for _ in range(n):
            v = mi(t) if callable(mi) else mi
            out.append((t, v + rng.normal(0.0, noise) if math.isfinite(v) else v, rpm))
            t = round(t + 1 / 30, 9)

    w = 2 * math.pi * 10 / 60
    add(3, math.nan, 10.0)  # nothing valid yet: the all-NaN estimate
    add(90, lambda s: 0.4 + 0.05 * math.cos(w * s), 10.0)
    e = 0.0
    for _ in range(90):  # a correlated wander (AR(1), lag-1 correlation 0.9): the coloured noise state
        e = 0.9 * e + rng.normal(0.0, 0.02)
        out.append((t, 0.4 + 0.05 * math.cos(w * t) + e, 10.0))
        t = round(t + 1 / 30, 9)
    t_ramp = t  # a turning drum's ramp at 0.5 MI/s: the rate bound of "tight" (0.3) with ripple covariances
    add(30, lambda s: 0.4 + 0.5 * (s - t_ramp) + 0.05 * math.cos(w * s), 10.0, 0.002)
    add(30, lambda s: 0.4 + 0.05 * math.cos(w * s), 10.0)
    add(3, math.nan, 10.0)
    add(1, 0.95, 10.0, 0.0)  # a glitch
    add(60, lambda s: 0.4 + 0.05 * math.cos(w * s), 10.0)
    add(6, 0.9, 10.0, 0.005)  # a burst: unsettles, does not re-initialise
    add(30, 0.4, 10.0)
    add(25, 0.8, 10.0, 0.005)  # a step: re-initialises on the share
    add(40, 0.8, 0.0)
    add(30, lambda s: min(1.2, 0.8 + 2.0 * (s - out[-1][0])), 0.0, 0.002)  # into the top and the rate bound
    add(30, 1.1, -5.0, 0.0)
    add(30, lambda s: max(-0.2, 1.0 - 3.0 * (s - out[-1][0])), math.nan, 0.002)
    add(30, -0.1, 0.0, 0.0)
    out.append((out[-1][0], 0.05, 0.0))  # the same time again
    add(20, 0.05, 0.0)
    t += 2.0
    add(20, 0.3, 20.0, 0.02)
    t += 40.0
    add(2, math.nan, 20.0)  # after a gap longer than max_dt_s: not initialised until a valid sample
    add(40, 0.6, 20.0, 0.02)
    return out


CONFIGS = {
    "default": TrendConfig(),
    "tight": TrendConfig(meas_sd=0.02, min_meas_sd=0.005, noise_tau_s=2.0, rate_q=1e-3, ripple_q=4e-5,
                         ripple_harmonic=2.0, gate_d2=6.0, reinit_window_s=0.4, reinit_share=0.5, reinit_min=4,
                         unsettle_share=0.25, max_rate_per_s=0.3, init_rate_sd=0.05, init_ripple_sd=0.02,
                         max_dt_s=10.0, settle_s=0.3, settle_band=0.04, settle_band_max=0.08, noise_lag_s=0.5),
    "loose": TrendConfig(meas_sd=0.1, noise_tau_s=200.0, rate_q=1e-4, ripple_q=0.0, gate_d2=16.0,
                         reinit_window_s=1.0, reinit_share=0.8, reinit_min=12, unsettle_share=0.5,
                         max_rate_per_s=2.0, init_rate_sd=0.01, init_ripple_sd=0.1, max_dt_s=60.0,
                         settle_s=0.0, settle_band=0.06, settle_band_max=0.5, noise_lag_s=2.0),
}
FIELDS = ("level", "rate", "level_sd", "rate_sd", "lo95", "hi95", "ripple", "nis", "meas_sd")


@pytest.mark.parametrize("seed", range(6))
def test_the_kalman_sums_are_filterpys(seed):
    """Random states, covariances, models and measurements: predict, innovation and update agree
    with filterpy's class to rounding."""
    rng = np.random.default_rng(seed)
    n = 5
    a = rng.normal(size=(n, n))
    P = a @ a.T + 0.1 * np.eye(n)
    b = rng.normal(size=(n, n))
    Q = 0.01 * (b @ b.T)
    F = np.eye(n) + 0.2 * rng.normal(size=(n, n))
    x, h, r, z = rng.normal(size=n), rng.normal(size=n), float(rng.uniform(0.01, 1.0)), float(rng.normal())
    ours, theirs = Kalman(x, P), FilterpyKalman(x, P)
    for kf in (ours, theirs):
        kf.predict(F, Q)
    np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-12, atol=1e-14)
    assert ours.innovation(z, h, r) == pytest.approx(theirs.innovation(z, h, r), rel=1e-12)
    for kf in (ours, theirs):
        kf.update(z, h, r)
    np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.P, ours.P.T, rtol=1e-12, atol=1e-14)  # the Joseph form stays symmetric




@pytest.mark.parametrize(("name", "seed"), [("default", 0), ("tight", 1), ("loose", 0)])
def test_every_estimate_is_the_one_on_filterpys_kalman_filter(name, seed):
    c = CONFIGS[name]
    tr, ref = MITrend(c), OnFilterpy(c)
    seen = {"reinit": 0, "rejected": 0, "settled": 0, "widened": 0, "coloured": 0}
    for i, (t, mi, rpm) in enumerate(sequence(seed)):
        got, want = tr.update(t, mi, rpm), ref.update(t, mi, rpm)
        where = f"{name} seed {seed} step {i} t={t:.3f}"
        assert (got.t_s, got.accepted, got.reinit, got.rejections, got.n_since_init, got.settled) == (
            want.t_s, want.accepted, want.reinit, want.rejections, want.n_since_init, want.settled), where
        for f in FIELDS:
            assert getattr(got, f) == pytest.approx(getattr(want, f), rel=1e-9, abs=1e-12, nan_ok=True), (where, f)
        seen["reinit"] += want.reinit
        seen["rejected"] += math.isfinite(want.nis) and not want.accepted
        seen["settled"] += want.settled
        seen["widened"] += want.valid and want.hi95 - want.lo95 > 2 * Z95 * want.level_sd + 1e-9
        seen["coloured"] += tr.noise_tau_e_s > 0
    assert tr.n_reinit == ref.n_reinit
    # the sequence passed through the branches it is made for
    # ("loose": its noise, learnt up to sd 0.17 on the ramps' 2 s pairs, opens the 4-sigma gate before 80 %
    # of a 1 s window is rejected: it re-initialises at the start and after the 40 s gap only)
    assert seen["reinit"] >= (2 if name == "loose" else 3), seen
    assert seen["rejected"] >= 5 and seen["settled"] >= 10 and seen["widened"] >= 1, seen
    assert seen["coloured"] >= 30, seen


def test_the_transition_by_hand():
    """rpm 15 at harmonic 2, dt 0.5 s: the pair turns by 2 pi 15 / 60 * 2 * 0.5 = pi / 2; tau_e = dt / ln 2
    gives phi = 1/2, so e's innovation variance is var (1 - 1/4); k scales both densities."""
    c = TrendConfig(rate_q=0.02, ripple_q=0.004, ripple_harmonic=2.0)
    F, Q = transition(0.5, 15.0, c, 0.5 / math.log(2.0), 0.01, 3.0)
    want_F = np.array([[1, 0.5, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 0, 1, 0], [0, 0, -1, 0, 0], [0, 0, 0, 0, 0.5]])
    np.testing.assert_allclose(F, want_F, rtol=0, atol=1e-15)
    q, qr = 0.06, 0.012
    want_Q = np.diag([q * 0.125 / 3, q * 0.5, qr * 0.5, qr * 0.5, 0.01 * 0.75])
    want_Q[0, 1] = want_Q[1, 0] = q * 0.25 / 2
    np.testing.assert_allclose(Q, want_Q, rtol=1e-12, atol=0)
    for rpm in (0.0, -5.0, math.nan, math.inf):  # at rest: the pair does not turn
        F0, _ = transition(0.5, rpm, c, 0.0, 0.01, 1.0)
        assert turning(rpm) == 0.0 and (F0[2:4, 2:4] == np.eye(2)).all() and F0[4, 4] == 0.0  # white: phi 0


def test_the_projection_by_hand():
    """Level 1.3 -> 1, -0.2 -> 0; a rate past its bound keeps its sign at the bound and loses its
    covariance with the other states (its own variance and the rest stay)."""
    P = np.arange(25, dtype=float).reshape(5, 5)
    P = P + P.T
    kf = Kalman(np.array([1.3, -0.7, 0.1, 0.2, 0.3]), P)
    project(kf, 0.5)
    assert list(kf.x) == [1.0, -0.5, 0.1, 0.2, 0.3]
    want = P.copy()
    for j in (0, 2, 3, 4):
        want[1, j] = want[j, 1] = 0.0
    assert (kf.P == want).all() and kf.P[1, 1] == P[1, 1]
    kf = Kalman(np.array([-0.2, 0.5, 0.0, 0.0, 0.0]), P)
    project(kf, 0.5)  # exactly at the bound: not projected
    assert list(kf.x) == [0.0, 0.5, 0.0, 0.0, 0.0] and (kf.P == P).all()


def test_the_comparison_tells_a_trend_with_another_model_apart():
    """The comparison above agrees with the trend, not with anything: a trend whose ripple does not
    rotate, or whose gate is one sigma wider, leaves it."""
    seq = sequence(0)
    for other in (TrendConfig(ripple_harmonic=0.0), TrendConfig(gate_d2=16.0)):
        ref, tr = OnFilterpy(TrendConfig()), MITrend(other)
        worst = np.nanmax([abs(tr.update(*s).level - ref.update(*s).level) for s in seq])
        assert worst > 1e-3, other


def test_a_drum_speed_that_is_not_a_number_stops_the_ripple_where_it_is():
    """NaN or infinite rpm (a status the mill could not read): the drum counts as at rest -- the
    ripple pair, learnt while it turned, neither rotates nor enters the measurement, exactly as at
    rpm 0."""
    w = 2 * math.pi * 10 / 60
    turning_seq = [(i / 30, 0.5 + 0.06 * math.cos(w * i / 30), 10.0) for i in range(150)]
    rest = [(5.0 + i / 30, 0.5 + 0.01 * (i % 3)) for i in range(30)]
    odd, zero = MITrend(), MITrend()
    for t, mi, rpm in turning_seq:
        odd.update(t, mi, rpm)
        zero.update(t, mi, rpm)
    for i, (t, mi) in enumerate(rest):
        a, b = odd.update(t, mi, math.nan if i < 15 else math.inf), zero.update(t, mi, 0.0)
        for f in FIELDS:
            assert getattr(a, f) == getattr(b, f) or (math.isnan(getattr(a, f)) and math.isnan(getattr(b, f))), (t, f)
    held = [odd.update(6.0 + i / 30, math.nan, math.nan).ripple for i in range(3)]
    assert abs(held[0]) > 0.01 and held[0] == held[1] == held[2]  # a ripple was learnt, and it holds still


def test_a_slowly_turning_drum_has_its_ripple_in_the_measurement():
    """0.5 rpm (a turn in 2 min) is turning: the ripple pair enters the measurement (so the level
    shares the wave with it and is known less well) where a drum at rest leaves the pair out."""
    w = 2 * math.pi * 0.5 / 60
    seq = [(i / 30, 0.5 + 0.05 * math.cos(w * i / 30) + 0.01 * math.sin(i)) for i in range(200)]
    slow, rest = MITrend(), MITrend()
    for t, mi in seq:
        a, b = slow.update(t, mi, 0.5), rest.update(t, mi, 0.0)
    assert b.ripple == 0.0 and a.ripple != 0.0 and a.level != b.level and a.level_sd > 5 * b.level_sd


def test_the_correlation_time_by_hand_on_uneven_frame_gaps():
    """Frames at 0, 0.02 and 0.08 s (gaps 0.02 and 0.06), MI 0.5, 0.51, 0.5, noise_tau_s long: the
    frame variance is the running mean (0.05^2 + 5e-5) / 2, then (2 that + 5e-5) / 3; the mean gap
    the first gap, then (2 * 0.02 + 0.06) / 3; no pair 1 s apart yet, so the variance in use is
    0.05^2, rho = 1 - D1 / 0.05^2 and tau_e = -gap / ln(rho)."""
    tr = MITrend(TrendConfig(noise_tau_s=1e9))
    for t, mi in ((0.0, 0.5), (0.02, 0.51), (0.08, 0.5)):
        assert tr.update(t, mi, 0.0).accepted
    d1 = (2 * (0.05**2 + 5e-5) / 2 + 5e-5) / 3
    assert tr.frame_sd**2 == pytest.approx(d1, rel=1e-12)
    assert tr.noise_tau_e_s == pytest.approx(-((2 * 0.02 + 0.06) / 3) / math.log(1 - d1 / 0.05**2), rel=1e-9)
    tr.update(0.1, 0.5, 0.0)  # a pair exactly like the first: the correlation time is capped at noise_lag_s
    assert 0.0 < tr.noise_tau_e_s <= tr.config.noise_lag_s


def test_the_measurement_variance_is_capped_at_a_quarter():
    """One frame a second alternating 0 and 3 (an open gate): each pair 1 s apart has half its
    squared difference 4.5, the running mean (0.25 + 4.5) / 2 and more: the estimate stops at 0.25
    (sd 0.5, MI's whole range)."""
    tr = MITrend(TrendConfig(meas_sd=0.5, gate_d2=1e9))
    out = [tr.update(float(i), 3.0 * (i % 2), 0.0) for i in range(5)]
    assert all(e.accepted for e in out) and out[0].meas_sd == 0.5
    assert [e.meas_sd for e in out[1:]] == [0.5] * 4 and tr.frame_sd > 1.0


def test_without_an_rpm_the_drum_is_at_rest():
    seq = [(t, mi) for t, mi, _ in sequence(0)[:200]]
    default, at_rest, turning = MITrend(), MITrend(), MITrend()
    for t, mi in seq:
        a, b, c = default.update(t, mi), at_rest.update(t, mi, 0.0), turning.update(t, mi, 1.0)
        for f in FIELDS:
            assert getattr(a, f) == pytest.approx(getattr(b, f), rel=0, abs=0, nan_ok=True), (t, f)
    assert c.level != b.level  # a turning drum's ripple enters the measurement: the test can tell


def test_update_edges_by_hand():
    tr = MITrend()
    assert not tr.update(0.0, None).valid  # None is a missing frame, like NaN
    assert tr.update(0.5, 0.4).reinit
    assert not tr.estimate(0.5).accepted and not tr.estimate(0.5).reinit  # a look, not a sample
    with pytest.raises(ControlError) as exc:
        tr.update(0.25, 0.4)
    assert str(exc.value) == "trend time went backwards (0.25 < 0.5)"
    # a gap of exactly max_dt_s is predicted over, not restarted
    tr2 = MITrend(TrendConfig(max_dt_s=30.0))
    tr2.update(0.0, 0.4)
    assert not tr2.update(30.0, 0.41).reinit
    assert tr2.update(60.0 + 2**-10, 0.41).reinit
    # the gate at exactly gate_d2 accepts: y = 1, S = P_level + P_e + floor = 1/16 + 1/16 + 1/64 = 9/64
    # (binary fractions), NIS = 64/9 (both correctly rounded from the same quotient)
    tr3 = MITrend(TrendConfig(meas_sd=0.25, min_meas_sd=0.125, gate_d2=64 / 9))
    tr3.update(0.0, 0.0)
    e = tr3.update(0.0, 1.0)
    assert e.nis == 64 / 9 and e.accepted


def test_a_band_exactly_as_wide_as_settle_band_is_settled():
    """A band clipped to the whole of [0, 1] is exactly 1.0 wide: settled at settle_band 1.0."""
    cfg = TrendConfig(meas_sd=0.5, settle_s=0.0, reinit_min=1, settle_band=1.0, settle_band_max=1.0)
    e = MITrend(cfg).update(0.0, 0.5)
    assert (e.lo95, e.hi95) == (0.0, 1.0) and e.settled


def test_a_pair_exactly_noise_lag_s_plus_1_s_apart_is_still_a_pair():
    """The gap rule drops a pair only past ``noise_lag_s + 1`` s: two samples exactly 2.0 s apart
    (binary-exact, an open gate) are a pair, R = (meas_sd^2 + 0.2^2 / 2) / 2; 2 s is past the
    consecutive pairs' ``noise_lag_s``, so D1 keeps its prior."""
    tr = MITrend(TrendConfig(gate_d2=1e9))
    tr.update(0.0, 0.5)
    e = tr.update(2.0, 0.7)
    assert e.accepted and tr.frame_sd == 0.05
    assert e.meas_sd**2 == pytest.approx((0.05**2 + 0.2**2 / 2) / 2, rel=1e-9)


def test_the_engine_holds_its_own_float_copies():
    """Made from integer lists or a caller's array, the engine neither truncates what the trend
    writes into it (the projection) nor shares the caller's memory."""
    x0 = np.array([2, 1, 0, 0, 0])
    kf = Kalman(x0, np.eye(5, dtype=int))
    project(kf, 0.5)
    assert list(kf.x) == [1.0, 0.5, 0.0, 0.0, 0.0] and list(x0) == [2, 1, 0, 0, 0]


def test_the_reported_ripple_is_the_measured_component_of_the_pair():
    """A drum at 10 rpm whose MI swings 0.06 cos(omega t) about 0.5: the reported ripple follows that
    swing (the pair's first component, the one in the measurement), not the quarter-turn-late other."""
    w = 2 * math.pi * 10 / 60
    rng = np.random.default_rng(8)
    tr = MITrend()
    out = [tr.update(i / 30, 0.5 + 0.06 * math.cos(w * i / 30) + rng.normal(0, 0.005), 10.0) for i in range(900)]
    late = out[600:]
    swing = np.array([0.06 * math.cos(w * e.t_s) for e in late])
    assert np.corrcoef([e.ripple for e in late], swing)[0, 1] > 0.9
    assert max(abs(e.level - 0.5) for e in late) < 0.02


def test_the_first_update_by_hand():
    """At rest, the second sample 1/30 s after the first: the prediction gives P00' = R + dt^2 init_rate_sd^2
    + rate_q dt^3 / 3 and (white noise, no pair yet) P44' = R; the measurement sees level + e + v, so the
    gain on the level is P00' / (P00' + P44' + min_meas_sd^2) and the level moves by that times the
    innovation. One accepted sample more counts once."""
    c = TrendConfig()
    tr = MITrend(c)
    e0 = tr.update(0.0, 0.5, 0.0)
    assert (e0.t_s, e0.level, e0.n_since_init, e0.accepted, e0.reinit) == (0.0, 0.5, 1, True, True)
    dt, r = 1 / 30, c.meas_sd**2
    e1 = tr.update(dt, 0.56, 0.0)
    p00 = r + dt**2 * c.init_rate_sd**2 + c.rate_q * dt**3 / 3
    assert e1.level == pytest.approx(0.5 + p00 / (p00 + r + c.min_meas_sd**2) * 0.06, rel=1e-12)
    assert e1.accepted and not e1.reinit and e1.n_since_init == 2


@pytest.mark.parametrize("z", [1.3, -0.2])
def test_a_first_sample_outside_0_1_starts_the_level_at_the_bound(z):
    e = MITrend().update(0.0, z, 0.0)
    assert e.level == min(1.0, max(0.0, z)) and e.lo95 >= 0.0 and e.hi95 <= 1.0


def test_before_the_first_valid_sample_the_estimate_is_empty_but_timed():
    e = MITrend().update(2.5, math.nan, 5.0)
    assert e.t_s == 2.5 and e.accepted is False and e.reinit is False and not e.valid and not e.settled


def test_consecutive_rejections_are_counted():
    tr = MITrend()
    for i in range(60):
        tr.update(i / 30, 0.5 + 0.01 * (i % 3 - 1), 0.0)
    out = [tr.update(2.0 + k / 30, 0.95, 0.0) for k in range(3)]
    assert [e.rejections for e in out] == [1, 2, 3] and not any(e.accepted for e in out)


def test_the_reinit_share_is_reached_at_exactly_that_share():
    """reinit_min 4, share 0.5, one frame a second (the 0.6 s window holds one: the last 4 count):
    after a step the 2nd rejected sample makes 2 of 4, exactly the share: re-initialised there."""
    cfg = TrendConfig(reinit_min=4, reinit_share=0.5, unsettle_share=0.5, gate_d2=9.0)
    tr = MITrend(cfg)
    for i in range(30):
        assert tr.update(float(i), 0.5 + 0.01 * (i % 3 - 1), 0.0).accepted
    step = [tr.update(30.0 + k, 0.95, 0.0) for k in range(3)]
    assert [e.reinit for e in step] == [False, True, False] and step[1].level == 0.95


def test_rejections_are_still_counted_when_a_gap_restarts_the_trend():
    """Two rejected samples, then 40 s without a valid one (past max_dt_s): the trend is empty again but
    the count of consecutive rejections is what it was until a valid sample comes."""
    tr = MITrend()
    for i in range(60):
        tr.update(i / 30, 0.5, 0.0)
    tr.update(2.0, 0.95, 0.0)
    tr.update(2.1, 0.95, 0.0)
    e = tr.update(42.0, math.nan, 0.0)
    assert not e.valid and e.rejections == 2 and math.isnan(e.nis) and math.isnan(e.ripple)

"""The Kalman trend against a reference model written from control/trend.py's module docstring
(issue 27's mutation tests of control/trend.py).

``Reference`` is the documented filter in plain numpy, without filterpy: state
``[level, rate, ripple_c, ripple_s, e]``, the constant-velocity transition with a ripple pair rotated
by ``omega dt`` (``omega = 2 pi rpm / 60 * harmonic``, rpm < 0 or NaN: no rotation) and the AR(1)
noise ``e`` decaying by ``phi = exp(-dt / tau_e)`` with ``var(w) = R (1 - phi^2)``, the white-noise
densities scaled by the frame-to-frame variance over ``meas_sd^2``, ``MI = level + ripple_c + e`` (+ the
white floor ``min_meas_sd^2``) while the drum turns, the gate on ``y^2 / S``, the windowed share of
rejections (never fewer than ``reinit_min`` samples) and the median re-initialisation that keeps the
learnt noise, the stationary variance from pairs ``noise_lag_s`` apart ending on an accepted sample and
the frame-to-frame one from consecutive valid samples (each pair capped at ``gate_d2`` times the variance
in use, ``max`` of the two), the projection into ``[0, 1]`` and ``+-max_rate_per_s``, the band
widened by the rejections' median and the settle rule (seconds of accepted data, the settle width
and its hysteresis). Every field of every ``TrendEstimate`` must agree with it, step by step, on
sequences made to pass every branch.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.errors import ControlError
from control.trend import SETTLE_HYSTERESIS, Z95, MITrend, TrendConfig, TrendEstimate


class Reference:
    """The documented filter (module docstring of control.trend), one method per rule."""

    def __init__(self, c: TrendConfig) -> None:
        self.c = c
        self.t: float | None = None
        self.on = False
        self.rejections = 0
        self.n_reinit = 0
        self.r, self.d1, self.dt1, self.n_lag, self.n_one = c.meas_sd**2, c.meas_sd**2, 0.0, 0, 0
        self.valid: list[tuple[float, float, bool]] = []  # valid samples since (re)init
        self.acc: list[tuple[float, float]] = []  # valid samples since (re)init or a gap
        self.n = 0
        self.acc_s = 0.0
        self.settled = False
        self.x = np.zeros(5)
        self.P = np.zeros((5, 5))

    def var(self) -> float:
        return float(np.clip(max(self.r, self.d1), self.c.min_meas_sd**2, 0.25))

    def tau_e(self) -> float:
        if self.n_one == 0 or self.dt1 <= 0:
            return 0.0
        rho = 1.0 - self.d1 / self.var()
        return 0.0 if rho <= 0 else min(self.c.noise_lag_s, -self.dt1 / math.log(min(rho, 1.0 - 1e-12)))

    def k(self) -> float:
        c = self.c
        return min(self.var(), max(c.min_meas_sd**2, self.d1)) / c.meas_sd**2

    def start(self, z: float) -> None:
        c, v, k = self.c, self.var(), self.k()
        self.x = np.array([float(np.clip(z, 0.0, 1.0)), 0.0, 0.0, 0.0, 0.0])
        self.P = np.diag([v, k * c.init_rate_sd**2, k * c.init_ripple_sd**2, k * c.init_ripple_sd**2, v])
        self.on, self.rejections, self.valid, self.n, self.acc_s = True, 0, [], 1, 0.0
        self.acc = [] if self.t is None else [(self.t, z)]
        self.n_reinit += 1

    def project(self) -> None:
        m = self.c.max_rate_per_s
        self.x[0] = float(np.clip(self.x[0], 0.0, 1.0))
        if abs(self.x[1]) > m:
            self.x[1] = m if self.x[1] > 0 else -m
            for j in (0, 2, 3, 4):
                self.P[1, j] = self.P[j, 1] = 0.0

    def predict(self, dt: float, rpm: float) -> None:
        c = self.c
        turning = rpm if math.isfinite(rpm) and rpm > 0 else 0.0
        a = 2.0 * math.pi * turning / 60.0 * c.ripple_harmonic * dt
        tau = self.tau_e()
        phi = math.exp(-dt / tau) if tau > 0 else 0.0
        F = np.eye(5)
        F[0, 1] = dt
        F[2:4, 2:4] = [[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]]
        F[4, 4] = phi
        k = self.k()
        q, qr = c.rate_q * k, c.ripple_q * k
        Q = np.zeros((5, 5))
        Q[:2, :2] = [[q * dt**3 / 3.0, q * dt**2 / 2.0], [q * dt**2 / 2.0, q * dt]]
        Q[2, 2] = Q[3, 3] = qr * dt
        Q[4, 4] = self.var() * (1.0 - phi * phi)
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q
        self.project()

    def learn(self, t: float, z: float, accepted: bool) -> None:
        c = self.c
        lag = c.noise_lag_s
        cap = c.gate_d2 * self.var()
        prev = self.acc[-1] if self.acc else None
        if prev is not None and 0.0 < t - prev[0] <= lag:
            dt = t - prev[0]
            self.n_one += 1
            a = max(min(1.0, dt / c.noise_tau_s), 1.0 / (self.n_one + 1))
            self.d1 = (1 - a) * self.d1 + a * min((z - prev[1]) ** 2 / 2, cap)
            self.dt1 = dt if self.n_one == 1 else (1 - a) * self.dt1 + a * dt
        partners = [p for p in self.acc if t - p[0] >= lag]  # the newest is the pair's partner
        if partners and t - partners[-1][0] > lag + 1.0:
            self.acc = [(t, z)]  # a gap: no pair across it, this sample starts the next one
            return
        if partners and prev is not None and accepted:
            self.n_lag += 1
            a = max(min(1.0, (t - prev[0]) / c.noise_tau_s), 1.0 / (self.n_lag + 1))
            self.r = (1 - a) * self.r + a * min((z - partners[-1][1]) ** 2 / 2, cap)
        self.acc.append((t, z))

    def in_window(self, t: float) -> tuple[int, list[float]]:
        c = self.c
        inside = sum(1 for w in self.valid if w[0] >= t - c.reinit_window_s)
        w = self.valid[-max(inside, min(c.reinit_min, len(self.valid))):] if self.valid else []
        return len(w), [v[1] for v in w if v[2]]

    def width(self) -> float:
        c = self.c
        return min(c.settle_band_max, max(c.settle_band, 2 * Z95 * math.sqrt(self.var())))

    def update(self, t: float, mi: float, rpm: float) -> TrendEstimate:
        c = self.c
        z = math.nan if mi is None else float(mi)
        accepted = reinit = False
        nis = math.nan
        dt = 0.0
        if self.on and self.t is not None:
            dt = t - self.t
            if dt > c.max_dt_s:
                self.on = False
            elif dt > 0:
                self.predict(dt, rpm)
        self.t = t
        if math.isfinite(z):
            if not self.on:
                self.start(z)
                accepted = reinit = True
            else:
                h = np.array([1.0, 0.0, 1.0 if math.isfinite(rpm) and rpm > 0 else 0.0, 0.0, 1.0])
                y = z - h @ self.x
                rw = c.min_meas_sd**2
                nis = y * y / (h @ self.P @ h + rw)
                rejected = nis > c.gate_d2
                self.valid.append((t, z, rejected))
                n, rej = self.in_window(t)
                self.learn(t, z, not rejected)  # every valid sample: D1 from all, R from pairs ending accepted
                if not rejected:
                    s = h @ self.P @ h + rw
                    gain = self.P @ h / s
                    self.x = self.x + gain * y
                    ikh = np.eye(5) - np.outer(gain, h)
                    self.P = ikh @ self.P @ ikh.T + rw * np.outer(gain, gain)
                    self.project()
                    accepted, self.rejections = True, 0
                    self.n += 1
                    self.acc_s += dt
                else:
                    self.rejections += 1
                    if n >= c.reinit_min and len(rej) >= c.reinit_share * n:
                        self.start(float(np.median(rej)))
                        accepted = reinit = True
        e = self.estimate(t, accepted, reinit, nis)
        self.settled = e.settled
        return e

    def estimate(self, t: float, accepted: bool, reinit: bool, nis: float) -> TrendEstimate:
        c = self.c
        if not self.on:
            nan = math.nan
            return TrendEstimate(t, nan, nan, nan, nan, nan, nan, accepted, reinit, nan, nis, self.rejections)
        lsd, rsd = math.sqrt(max(self.P[0, 0], 0.0)), math.sqrt(max(self.P[1, 1], 0.0))
        lo, hi = self.x[0] - Z95 * lsd, self.x[0] + Z95 * lsd
        n, rej = self.in_window(t)
        if n >= c.reinit_min and len(rej) >= c.unsettle_share * n:
            med = float(np.median(rej))
            lo, hi = min(lo, med), max(hi, med)
        lo, hi = max(lo, 0.0), min(hi, 1.0)
        widest = min(SETTLE_HYSTERESIS * self.width(), c.settle_band_max) if self.settled else self.width()
        settled = self.acc_s >= c.settle_s and self.n >= c.reinit_min and hi - lo <= widest
        return TrendEstimate(t, float(self.x[0]), float(self.x[1]), lsd, rsd, float(lo), float(hi), accepted, reinit,
                             float(self.x[2]), nis, self.rejections, self.n, math.sqrt(self.var()), settled)


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


@pytest.mark.parametrize(("name", "seed"), [("default", 0), ("tight", 1), ("loose", 0)])
def test_every_estimate_is_the_reference_models(name, seed):
    c = CONFIGS[name]
    tr, ref = MITrend(c), Reference(c)
    seen = {"reinit": 0, "rejected": 0, "settled": 0, "unsettled_after": 0, "widened": 0, "coloured": 0}
    for i, (t, mi, rpm) in enumerate(sequence(seed)):
        got, want = tr.update(t, mi, rpm), ref.update(t, mi, rpm)
        where = f"{name} seed {seed} step {i} t={t:.3f}"
        assert (got.t_s, got.accepted, got.reinit, got.rejections, got.n_since_init, got.settled) == (
            want.t_s, want.accepted, want.reinit, want.rejections, want.n_since_init, want.settled), where
        for f in FIELDS:
            a, b = getattr(got, f), getattr(want, f)
            assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-9, abs=1e-12), (where, f, a, b)
        assert tr.n_reinit == ref.n_reinit and tr.rejections == ref.rejections, where
        seen["reinit"] += want.reinit
        seen["rejected"] += math.isfinite(want.nis) and not want.accepted
        seen["settled"] += want.settled
        seen["widened"] += want.valid and want.hi95 - want.lo95 > 2 * Z95 * want.level_sd + 1e-9
        seen["coloured"] += ref.tau_e() > 0
    # the sequence passed through the branches it is made for
    # ("loose": its noise, learnt up to sd 0.17 on the ramps' 2 s pairs, opens the 4-sigma gate before 80 %
    # of a 1 s window is rejected: it re-initialises at the start and after the 40 s gap only)
    assert seen["reinit"] >= (2 if name == "loose" else 3), seen
    assert seen["rejected"] >= 5 and seen["settled"] >= 10 and seen["widened"] >= 1, seen
    assert seen["coloured"] >= 30, seen  # the AR(1) stretch made the noise coloured


def test_the_comparison_tells_a_trend_with_another_model_apart():
    """The reference agrees with the trend above, not with anything: a trend whose ripple does not
    rotate, or whose gate is one sigma wider, leaves it."""
    seq = sequence(0)
    for other in (TrendConfig(ripple_harmonic=0.0), TrendConfig(gate_d2=16.0)):
        ref, tr = Reference(TrendConfig()), MITrend(other)
        worst = np.nanmax([abs(tr.update(*s).level - ref.update(*s).level) for s in seq])
        assert worst > 1e-3, other


def test_the_measurement_variance_is_capped_at_a_quarter():
    """One frame a second alternating 0 and 3 (an open gate): each pair 1 s apart has half its
    squared difference 4.5, the running mean (0.25 + 4.5) / 2 and more: the estimate stops at 0.25
    (sd 0.5, MI's whole range)."""
    tr = MITrend(TrendConfig(meas_sd=0.5, gate_d2=1e9))
    out = [tr.update(float(i), 3.0 * (i % 2), 0.0) for i in range(5)]
    assert all(e.accepted for e in out) and out[0].meas_sd == 0.5
    assert [e.meas_sd for e in out[1:]] == [0.5] * 4 and tr.frame_sd > 1.0


def test_a_drum_speed_that_is_not_a_number_stops_the_ripple_where_it_is():
    """NaN or infinite rpm (a status the mill could not read): the drum counts as at rest -- the
    ripple pair, learnt while it turned, neither rotates nor enters the measurement."""
    w = 2 * math.pi * 10 / 60
    seq = [(i / 30, 0.5 + 0.06 * math.cos(w * i / 30), 10.0) for i in range(150)]
    seq += [(5.0 + i / 30, 0.5, rpm) for i, rpm in enumerate([math.nan] * 15 + [math.inf] * 15)]
    tr, ref = MITrend(), Reference(TrendConfig())
    for t, mi, rpm in seq:
        got, want = tr.update(t, mi, rpm), ref.update(t, mi, rpm)
        for f in FIELDS:
            assert getattr(got, f) == pytest.approx(getattr(want, f), rel=1e-9, abs=1e-12, nan_ok=True), (t, rpm, f)
    held = [tr.update(6.0 + i / 30, math.nan, math.nan).ripple for i in range(3)]
    assert abs(held[0]) > 0.01 and held[0] == held[1] == held[2]  # a ripple was learnt, and it holds still


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


def test_a_slowly_turning_drum_has_its_ripple_in_the_measurement():
    w = 2 * math.pi * 0.5 / 60
    seq = [(i / 30, 0.5 + 0.05 * math.cos(w * i / 30) + 0.01 * math.sin(i), 0.5) for i in range(200)]
    tr, ref = MITrend(), Reference(TrendConfig())
    for t, mi, rpm in seq:
        got, want = tr.update(t, mi, rpm), ref.update(t, mi, rpm)
        for f in FIELDS:
            assert getattr(got, f) == pytest.approx(getattr(want, f), rel=1e-9, abs=1e-12, nan_ok=True), (t, f)


def test_a_band_exactly_as_wide_as_settle_band_is_settled():
    """A band clipped to the whole of [0, 1] is exactly 1.0 wide: settled at settle_band 1.0."""
    cfg = TrendConfig(meas_sd=0.5, settle_s=0.0, reinit_min=1, settle_band=1.0, settle_band_max=1.0)
    e = MITrend(cfg).update(0.0, 0.5)
    assert (e.lo95, e.hi95) == (0.0, 1.0) and e.settled


def test_the_correlation_time_is_the_reference_models_on_uneven_frame_gaps():
    """An AR(1) wander sampled at jittered times (0.02-0.06 s, the first two different): the mean
    frame gap ``dt1`` is the
    pairs' running mean (the first pair's gap, then weights 1 / (pairs + 1)), so the correlation
    time ``tau_e`` of every step is the reference model's."""
    rng = np.random.default_rng(5)
    tr, ref = MITrend(), Reference(TrendConfig())
    t, e, coloured = 0.0, 0.0, 0
    for i in range(200):
        e = 0.9 * e + rng.normal(0.0, 0.02)
        t = round(t + (0.02, 0.06)[i] if i < 2 else t + float(rng.choice([0.02, 0.04, 0.06])), 9)  # two gaps differ
        tr.update(t, 0.6 + e, 5.0)
        ref.update(t, 0.6 + e, 5.0)
        assert tr.noise_tau_e_s == pytest.approx(ref.tau_e(), rel=1e-9, abs=1e-12), t
        coloured += ref.tau_e() > 0
    assert coloured >= 50


def test_a_pair_exactly_noise_lag_s_plus_1_s_apart_is_still_a_pair():
    """The gap rule drops a pair only past ``noise_lag_s + 1`` s: two samples exactly 2.0 s apart
    (binary-exact, an open gate) are a pair, R = (meas_sd^2 + 0.2^2 / 2) / 2; 2 s is past the
    consecutive pairs' ``noise_lag_s``, so D1 keeps its prior."""
    tr = MITrend(TrendConfig(gate_d2=1e9))
    tr.update(0.0, 0.5)
    e = tr.update(2.0, 0.7)
    assert e.accepted and tr.frame_sd == 0.05
    assert e.meas_sd**2 == pytest.approx((0.05**2 + 0.2**2 / 2) / 2, rel=1e-9)

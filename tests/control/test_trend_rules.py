"""The trend's rules at their edges (issue 27, mutation testing of control/trend.py): inputs ->
outputs only, known answers computed by hand from the documented definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.errors import ControlError
from control.trend import MITrend, MovingAverage, TrendConfig, config_from_window, estimate_meas_sd, moving_average

SQRT2_Z75 = 0.6744897501960817 * math.sqrt(2.0)  # MAD of the difference of two N(0, 1) draws


def test_meas_sd_known_answer_on_a_ramp_with_alternating_steps():
    """Steps 0.19, 0.20, 0.21, ... : median step 0.2 (the ramp, removed), |step - 0.2| 0.01 for
    two steps in three: MAD 0.01."""
    x = np.cumsum([0.19, 0.2, 0.21] * 11)
    assert estimate_meas_sd(x) == pytest.approx(0.01 / SQRT2_Z75, rel=1e-9)
    assert estimate_meas_sd(np.full(20, 0.4)) == 1e-4  # the floor


def test_meas_sd_needs_ten_valid_samples_and_ignores_missing_ones():
    x = list(np.cumsum([0.19, 0.2, 0.21] * 3 + [0.2]))  # 10 samples, 9 steps: MAD 0.01
    with_gaps = [math.nan, None, *x[:5], math.nan, *x[5:], None]
    assert estimate_meas_sd(with_gaps) == estimate_meas_sd(x) == pytest.approx(0.01 / SQRT2_Z75, rel=1e-9)
    with pytest.raises(ControlError, match=r"at least 10 valid MI samples.*got 9"):
        estimate_meas_sd([*x[:9], math.nan, None])


def test_meas_sd_of_an_integer_array_is_that_of_its_values():
    """8-bit counts (0..255) must not wrap round in the differences."""
    x = np.array([10, 12, 11, 9, 10, 14] * 4, dtype=np.uint8)  # steps 2, -1, -2, 1, 4, -4, 2, ...
    assert estimate_meas_sd(x) == estimate_meas_sd(x.astype(float)) == pytest.approx(2.0 / SQRT2_Z75)


def test_config_from_window_scales_both_noise_densities_by_the_variance_ratio():
    base = TrendConfig(meas_sd=0.05, rate_q=4e-4, ripple_q=2e-5)
    x = np.cumsum([0.19, 0.2, 0.21] * 11)
    cfg = config_from_window(x, base)
    sd = 0.01 / SQRT2_Z75
    k = (sd / 0.05) ** 2
    assert cfg.meas_sd == pytest.approx(sd, rel=1e-9)
    assert cfg.rate_q == pytest.approx(4e-4 * k, rel=1e-9) and cfg.ripple_q == pytest.approx(2e-5 * k, rel=1e-9)
    assert cfg.gate_d2 == base.gate_d2 and cfg.settle_band == base.settle_band  # the rest is the base's
    assert config_from_window(x).rate_q == pytest.approx(TrendConfig().rate_q * (sd / 0.05) ** 2, rel=1e-9)


@pytest.mark.parametrize(
    ("kw", "match"),
    [({"meas_sd": 0.0}, "positive"), ({"min_meas_sd": 0.0}, "positive"), ({"rate_q": 0.0}, "positive"),
     ({"ripple_q": -1e-9}, "positive"), ({"gate_d2": 0.0}, "positive"), ({"noise_tau_s": 0.0}, "positive"),
     ({"max_rate_per_s": 0.0}, "positive"), ({"reinit_window_s": 0.0}, "reinit_window_s"),
     ({"unsettle_share": 0.0}, "unsettle_share"), ({"unsettle_share": 0.7, "reinit_share": 0.6}, "unsettle_share"),
     ({"reinit_share": 1.01}, "reinit_share"), ({"reinit_min": 0}, "reinit_min"),
     ({"settle_s": -0.1}, "settle_s"), ({"settle_band": 0.0}, "settle_band"), ({"settle_s": math.nan}, "settle_s"),
     ({"noise_lag_s": 0.0}, "noise_lag_s"), ({"noise_lag_s": 10.5}, "noise_lag_s"),
     ({"meas_sd": math.nan}, "positive"), ({"settle_band": math.nan}, "settle_band")],
)
def test_trend_config_refuses_each_bad_value(kw, match):
    with pytest.raises(ControlError, match=match) as exc:
        TrendConfig(**kw)
    full = {"positive": "trend noise levels must be positive (meas_sd, min_meas_sd, rate_q, gate_d2, "
                        "noise_tau_s, max_rate_per_s)",
            "reinit_window_s": "trend re-init needs reinit_window_s > 0 and 0 < unsettle_share <= reinit_share <= 1",
            "reinit_min": "reinit_min must be >= 1, settle_s >= 0 and settle_band > 0",
            "noise_lag_s": f"trend noise_lag_s must be in (0, 10] s, got {kw.get('noise_lag_s')}"}
    full["unsettle_share"] = full["reinit_share"] = full["reinit_window_s"]
    full["settle_s"] = full["settle_band"] = full["reinit_min"]
    assert str(exc.value) == full[match]


@pytest.mark.parametrize(
    "kw",
    [{"ripple_q": 0.0}, {"unsettle_share": 0.6, "reinit_share": 0.6}, {"reinit_share": 1.0, "unsettle_share": 1.0},
     {"reinit_min": 1}, {"settle_s": 0.0}, {"noise_lag_s": 10.0}, {"min_meas_sd": 1e-9, "meas_sd": 1e-9},
     {"gate_d2": 0.5},
     {"noise_tau_s": 0.5}, {"max_rate_per_s": 0.5}, {"reinit_window_s": 0.1}],
)
def test_trend_config_accepts_the_edges(kw):
    TrendConfig(**kw)


def test_a_constant_bed_brings_the_noise_estimate_down_to_its_floor_exactly():
    tr = MITrend(TrendConfig(min_meas_sd=0.002))
    est = [tr.update(float(i), 0.5, 0.0) for i in range(400)]  # one sample a second, all equal
    assert all(e.accepted for e in est)
    assert est[-1].meas_sd == pytest.approx(0.002, rel=1e-12)
    assert est[-1].level == 0.5


def test_a_rate_at_its_bound_keeps_its_sign():
    """A falling bed at rest (rpm 0: no ripple): the rate stops at -max_rate_per_s, never above 0."""
    cfg = TrendConfig(max_rate_per_s=0.01, meas_sd=0.01, min_meas_sd=0.01)
    tr = MITrend(cfg)
    est = [tr.update(i / 10, 0.9 - 0.02 * i / 10, 0.0) for i in range(300)]
    late = [e.rate for e in est[100:]]
    assert min(late) == -0.01 and max(late) <= 0.0
    assert all(abs(e.rate) <= 0.01 for e in est)


def test_moving_average_default_window_is_the_papers_150():
    assert MovingAverage().window == 150
    x = np.arange(300, dtype=float)
    assert moving_average(x)[-1] == pytest.approx(np.mean(x[-150:]))
    ma = MovingAverage()
    for v in x:
        last = ma.update(v)
    assert last == pytest.approx(np.mean(x[-150:]))


@pytest.mark.parametrize("window", [0, -1])
def test_moving_average_window_below_one_is_refused(window):
    with pytest.raises(ControlError, match=rf"window must be >= 1, got {window}"):
        MovingAverage(window)
    with pytest.raises(ControlError, match=rf"window must be >= 1, got {window}"):
        moving_average([0.1, 0.2], window)


def test_a_window_of_one_is_the_last_finite_sample():
    ma = MovingAverage(1)
    assert [ma.update(v) for v in (0.2, 0.7, math.nan, 0.4)] == [0.2, 0.7, 0.7, 0.4]
    assert list(moving_average([0.2, 0.7, math.nan, 0.4], 1)) == pytest.approx([0.2, 0.7, 0.7, 0.4], rel=1e-12)


@pytest.mark.parametrize("window", [2, 3, 5])
def test_the_streaming_average_slides_exactly(window):
    """The mean of the last ``window`` finite samples, at every step, exact to rounding."""
    rng = np.random.default_rng(window)
    x = rng.uniform(0.0, 1.0, 40)
    x[[3, 10, 11]] = math.nan
    ma = MovingAverage(window)
    finite: list[float] = []
    for v in x:
        got = ma.update(v)
        if math.isfinite(v):
            finite.append(float(v))
        assert got == pytest.approx(math.fsum(finite[-window:]) / len(finite[-window:]), rel=1e-12, abs=0)


def test_the_full_window_is_summed_again_exactly():
    """A huge sample leaving the window must not leave its rounding behind: 1e16 + 1 is 1e16
    in doubles, so a running sum alone says 0.5 where the mean of (1, 1) is 1."""
    ma = MovingAverage(2)
    assert [ma.update(v) for v in (1e16, 1.0, 1.0)][-1] == 1.0


def test_reset_starts_from_nothing():
    ma = MovingAverage(3)
    for v in (0.9, 0.8, 0.7, 0.6):
        ma.update(v)
    ma.reset()
    assert math.isnan(ma.value)
    assert ma.update(0.25) == 0.25
    assert ma.update(0.75) == 0.5


def test_missing_samples_may_be_none():
    """Missing frames arrive as NaN or None (as ``MITrend.update`` takes them): both are skipped."""
    got = moving_average([0.2, None, 0.6, math.nan, 1.0], 2)
    assert list(got) == pytest.approx([0.2, 0.2, 0.4, 0.4, 0.8])


def test_a_rate_at_its_bound_loses_its_covariance_with_the_level_once():
    """At rest (rpm 0) level and rate are a constant-velocity pair: predicting ``dt`` gives
    P00' = P00 + 2 dt P01 + dt^2 P11 + q dt^3 / 3, P01' = P01 + dt P11 + q dt^2 / 2, P11' = P11 + q dt.
    The update that pushes the rate past its bound projects it back and zeroes P01, so the first
    prediction after it has no 2 dt P01 term; the rate, now exactly at the bound, is not projected
    again, so the second has it."""
    # R fixed at its floor 4e-4 (the ramp's pairs 1 s apart differ by 0.02: half the square is 2e-4): q = rate_q
    cfg = TrendConfig(max_rate_per_s=0.01, meas_sd=0.02, min_meas_sd=0.02)
    tr = MITrend(cfg)
    est = [tr.update(i / 10, 0.9 - 0.02 * i / 10, 0.0) for i in range(200)]
    e0 = est[-1]
    assert e0.rate == -0.01 and e0.meas_sd == pytest.approx(0.02, rel=1e-12)
    dt, q = 0.1, cfg.rate_q
    e1 = tr.update(e0.t_s + dt, math.nan, 0.0)
    e2 = tr.update(e0.t_s + 2 * dt, math.nan, 0.0)
    p00, p11 = e0.level_sd**2, e0.rate_sd**2
    p00_1 = p00 + dt**2 * p11 + q * dt**3 / 3
    p01_1, p11_1 = dt * p11 + q * dt**2 / 2, p11 + q * dt
    assert e1.level_sd**2 == pytest.approx(p00_1, rel=1e-9)
    assert e1.rate_sd**2 == pytest.approx(p11_1, rel=1e-9) and e1.rate_sd > 0
    assert e2.level_sd**2 == pytest.approx(p00_1 + 2 * dt * p01_1 + dt**2 * p11_1 + q * dt**3 / 3, rel=1e-9)
    assert e1.rate == e2.rate == -0.01


def test_reset_forgets_everything():
    """After ``reset`` the next valid MI starts the filter as at first: time may start again,
    the noise estimate is the configured one, and a trend that had settled is judged afresh
    (with ``settle_s = 0`` and ``reinit_min = 1`` the first band, 2 * 1.96 * 0.05 = 0.196, is too
    wide for a settle band of 0.14 capped at 0.14; a stale 'settled' would allow 1.5 * 0.14 = 0.21)."""
    cfg = TrendConfig(settle_s=0.0, reinit_min=1, settle_band=0.14, settle_band_max=0.14)
    tr = MITrend(cfg)
    rng = np.random.default_rng(3)
    est = [tr.update(i / 30, 0.6 + rng.normal(0, 0.01), 10.0) for i in range(300)]
    tr.update(10.0, 0.99, 10.0)  # one rejected glitch
    assert est[-1].settled and tr.rejections == 1
    tr.reset()
    e = tr.update(1.0, 0.3, 10.0)  # (time started again: no error)
    assert e.reinit and e.accepted and e.level == 0.3 and e.n_since_init == 1
    assert e.meas_sd == 0.05 and e.rejections == 0 and e.hi95 - e.lo95 == pytest.approx(2 * 1.96 * 0.05, rel=1e-3)
    assert not e.settled


def test_after_reset_missing_frames_report_nothing():
    tr = MITrend()
    tr.update(0.0, 0.5, 10.0)
    tr.update(0.1, 0.99, 10.0)  # rejected
    tr.reset()
    e = tr.update(0.0, math.nan, 10.0)
    assert not e.valid and e.rejections == 0 and not e.settled


def _noisy_bed(tr: MITrend, n: int = 96) -> float:
    """0.48, 0.5, 0.52 repeated at 32 frames/s (binary-exact times; 32 frames is no multiple of the
    period, so the pairs 1 s apart see the spread too); returns the last time."""
    for i in range(n):
        e = tr.update(i / 32, 0.5 + 0.02 * (i % 3 - 1), 0.0)
        assert e.accepted
    return (n - 1) / 32


@pytest.mark.parametrize(("gap_s", "learns"), [(0.0, False), (1.0, True), (1.5, False), (3.0, False)])
def test_the_frame_noise_is_learned_only_from_accepted_pairs_at_most_noise_lag_s_apart(gap_s, learns):
    """Consecutive accepted samples feed the frame-to-frame estimate when 0 < dt <= noise_lag_s (1 s):
    a pair at the same time or across a longer gap (NaN frames in between) says nothing about it."""
    tr = MITrend()
    t = _noisy_bed(tr)
    before = tr.frame_sd
    for k in range(1, 4):
        if k / 4 * gap_s > 0 and k / 4 * gap_s < gap_s:
            assert not tr.update(t + k / 4 * gap_s, math.nan, 0.0).accepted
    e = tr.update(t + gap_s, 0.52, 0.0)
    assert e.accepted
    assert (tr.frame_sd != before) is learns, (tr.frame_sd, before)


def test_both_noise_estimates_are_running_means_at_first():
    """With a long time constant the weight of each new pair is 1 / (pairs + 1), the configured
    meas_sd^2 counting once. Alternating +-0.01 at 32 frames/s: after k consecutive pairs the
    frame variance is (meas_sd^2 + k 0.02^2 / 2) / (k + 1); the pairs 1 s (32 frames, an even
    number) apart differ by 0, so after j of them the pairs' variance is meas_sd^2 / (j + 1); the one in
    use is the larger of the two."""
    tr = MITrend(TrendConfig(noise_tau_s=1e9))
    for i in range(80):
        e = tr.update(i / 32, 0.5 + (0.01 if i % 2 else -0.01), 0.0)
        assert e.accepted
        assert tr.frame_sd**2 == pytest.approx((0.05**2 + i * 0.02**2 / 2) / (i + 1), rel=1e-9)
        j = max(0, i - 31)
        d1 = (0.05**2 + i * 0.02**2 / 2) / (i + 1)
        assert e.meas_sd**2 == pytest.approx(max(0.05**2 / (j + 1), d1, 0.002**2), rel=1e-9)  # never below D1


def test_a_time_constant_shorter_than_the_frame_gap_keeps_only_the_last_pairs():
    """``noise_tau_s`` 0.25 s, frames 0.5 s apart: the weight is capped at 1, so the frame variance is
    half the last consecutive pair's squared difference and the pairs' one half that of the last
    pair 1 s (two frames) apart, whatever came before; the variance in use is the larger."""
    tr = MITrend(TrendConfig(noise_tau_s=0.25))
    z = [0.5 + 0.01 * (i % 3) for i in range(30)]  # steps +0.01, +0.01, -0.02
    for i, v in enumerate(z):
        e = tr.update(i / 2, v, 0.0)
        assert e.accepted
        if i:
            assert tr.frame_sd == pytest.approx(abs(v - z[i - 1]) / math.sqrt(2.0), rel=1e-9)
        if i >= 2:
            want = max(abs(v - z[i - 2]), abs(v - z[i - 1])) / math.sqrt(2.0)  # max(R, D1)
            assert e.meas_sd == pytest.approx(max(want, 0.002), rel=1e-9)


def test_a_fresh_trend_has_no_rejections_and_counts_its_initialisations():
    tr = MITrend()
    assert tr.n_reinit == 0 and tr.rejections == 0
    e = tr.update(0.0, math.nan, 10.0)
    assert e.rejections == 0 and not e.valid
    tr.update(0.1, 0.4, 10.0)
    assert tr.n_reinit == 1  # the first valid sample initialises
    for i in range(60):  # a real step: rejected until the share re-initialises the level
        tr.update(0.2 + i / 30, 0.9, 10.0)
    assert tr.n_reinit == 2 and tr.estimate(2.2).level == pytest.approx(0.9, abs=0.02)


def test_a_fresh_trend_is_judged_by_the_settle_band_itself():
    """(As after ``reset``:) the first band, 0.196, is too wide for a settle band of 0.14; only a
    trend that had settled may keep 1.5 times it."""
    e = MITrend(TrendConfig(settle_s=0.0, reinit_min=1, settle_band=0.14, settle_band_max=0.14)).update(0.0, 0.3, 10.0)
    assert e.hi95 - e.lo95 == pytest.approx(0.196, abs=1e-3) and not e.settled


def test_the_first_prediction_uses_the_documented_initial_uncertainty():
    """At the first sample P = diag(R, init_rate_sd^2, init_ripple_sd^2, init_ripple_sd^2, R) (R = meas_sd^2,
    the last the coloured noise e); the ripple pair is isotropic, so turning it by w dt leaves its
    variance. No consecutive pair yet: e is white (phi 0), its prediction is the stationary R. The
    second sample's squared Mahalanobis distance is then y^2 / (P00' + P22' + R + min_meas_sd^2) with
    P00' = R + dt^2 init_rate_sd^2 + rate_q dt^3 / 3 and P22' = init_ripple_sd^2 + ripple_q dt."""
    cfg = TrendConfig()
    tr = MITrend(cfg)
    e0 = tr.update(0.0, 0.5, 15.0)
    r = cfg.meas_sd**2
    assert e0.level_sd == pytest.approx(cfg.meas_sd, rel=1e-12) and e0.rate_sd == pytest.approx(cfg.init_rate_sd,
                                                                                                rel=1e-12)
    dt = 1 / 30
    e1 = tr.update(dt, 0.6, 15.0)
    p00 = r + dt**2 * cfg.init_rate_sd**2 + cfg.rate_q * dt**3 / 3
    p22 = cfg.init_ripple_sd**2 + cfg.ripple_q * dt
    assert e1.nis == pytest.approx(0.1**2 / (p00 + p22 + r + cfg.min_meas_sd**2), rel=1e-9)


def test_the_reinit_window_holds_the_samples_at_its_start():
    """Window 0.5 s at 32 frames/s (binary-exact times): 17 valid samples, both ends included.
    After a step every new sample is rejected; the share 0.6 is reached at the 11th
    (11 >= 0.6 * 17 = 10.2; a window without its first sample would re-init at the 10th)."""
    tr = MITrend(TrendConfig(reinit_window_s=0.5))
    t = _noisy_bed(tr, 64)
    step = [tr.update(t + k / 32, 0.9, 0.0) for k in range(1, 20)]
    first = next(k for k, e in enumerate(step, start=1) if e.reinit)
    assert first == 11 and not any(e.accepted for e in step[:10])


def test_at_10_fps_the_reinit_window_holds_reinit_min_samples():
    """0.6 s at 10 fps holds 6 valid samples < reinit_min = 11: the window is the last 11, so after
    a step the 7th rejected sample re-initialises (7 >= 0.6 * 11 = 6.6) and a burst of 6 never can
    (issue 38: a dark object over the bed for 6 frames). (A window of 0.6 s only could never reach
    reinit_min samples: the old trend never re-initialised at 10 fps; with reinit_min 8 the 5th did,
    and a 6-frame burst re-initialised the trend onto it.)"""
    tr = MITrend()
    for i in range(100):
        assert tr.update(i / 10, 0.5 + 0.01 * (i % 3 - 1), 5.0).accepted
    step = [tr.update(10.0 + k / 10, 0.9, 5.0) for k in range(10)]
    first = next(k for k, e in enumerate(step, start=1) if e.reinit)
    assert first == 7 and not any(e.accepted for e in step[:6])
    assert step[6].level == 0.9


def test_a_reinit_keeps_the_learnt_noise():
    """The noise belongs to the camera and the bed, not to the level: after a step to a constant
    0.9 (a MAD of 0, as the old re-init took it) the trend keeps the bed's noise (sd ~0.01)."""
    tr = MITrend()
    rng = np.random.default_rng(2)
    for i in range(300):
        tr.update(i / 30, 0.5 + rng.normal(0, 0.01), 5.0)
    before = tr.estimate(10.0).meas_sd
    assert 0.007 < before < 0.014
    step = [tr.update(10.0 + k / 30, 0.9, 5.0) for k in range(30)]
    re = next(e for e in step if e.reinit)
    assert re.meas_sd == pytest.approx(before, rel=0.25) and re.level == 0.9


def test_gated_samples_feed_the_frame_noise_so_its_gate_cannot_trap_it():
    """The real frames' drift pool (0.359, 0.414, 0.422, 0.453, drawn i.i.d.) after 10 s of its two
    middle values: learnt from accepted samples only, the noise stayed at the quiet part's 0.005,
    the gate rejected 0.359 and 0.453 for good (accepted 48 % of the last 10 s, 65 re-inits onto
    them, never settled). Consecutive valid pairs, gated or not (each capped at the gate), see the
    pool's spread (sd 0.034) within the noise time constant: the last 10 s of 40 all accepted,
    settled, the level within 0.035 of the pool's mean 0.412."""
    rng = np.random.default_rng(4)
    tr = MITrend()
    quiet = rng.choice([0.414, 0.422], 300)
    pool = rng.choice([0.359, 0.414, 0.422, 0.453], 1200)
    out = [tr.update(i / 30, float(v), 5.0) for i, v in enumerate(np.concatenate([quiet, pool]))]
    late = out[-300:]
    assert late[-1].meas_sd > 0.028
    assert np.mean([e.accepted for e in late]) >= 0.95 and all(e.settled for e in late)
    assert max(abs(e.level - 0.412) for e in late) <= 0.035
    assert tr.n_reinit <= 3


def test_a_pair_farther_apart_than_the_gate_counts_as_at_the_gate():
    """noise_tau_s 0.25 s and frames 0.5 s apart: each pair's weight is 1, so after a glitch the
    frame variance is exactly gate_d2 times the variance in use before it, not the glitch's."""
    tr = MITrend(TrendConfig(noise_tau_s=0.25))
    z = [0.5 + 0.01 * (i % 3) for i in range(20)]
    for i, v in enumerate(z):
        tr.update(i / 2, v, 0.0)
    var = tr.estimate(9.5).meas_sd ** 2
    e = tr.update(10.0, 0.99, 0.0)
    assert not e.accepted
    assert tr.frame_sd**2 == pytest.approx(9.0 * var, rel=1e-12)
    assert 9.0 * var < 0.5 * (0.99 - z[-1]) ** 2  # the glitch's own half square is larger


def test_the_pairs_partner_is_the_newest_sample_at_least_noise_lag_s_old():
    """noise_lag_s 0.5 s, frames 0.75 s apart (too far apart for the frame-to-frame pairs): at 1.5 s
    the partner is the frame of 0.75 s (the newest at least 0.5 s old), not that of 0 s (1.5 s old,
    still within noise_lag_s + 1). MI 0.5, 0.6, 0.5: both pairs differ by 0.1, so R is the running
    mean (0.05^2 + 0.005) / 2, then (2 that + 0.005) / 3 (the frame of 0 s would have added 0)."""
    tr = MITrend(TrendConfig(noise_lag_s=0.5, gate_d2=1e9))
    for t, mi in ((0.0, 0.5), (0.75, 0.6), (1.5, 0.5)):
        e = tr.update(t, mi, 0.0)
    r = (2 * (0.05**2 + 0.005) / 2 + 0.005) / 3
    assert e.accepted and tr.frame_sd == 0.05  # no consecutive pair within 0.5 s: D1 keeps its prior
    assert e.meas_sd**2 == pytest.approx(r, rel=1e-12)


def test_a_pair_more_than_noise_lag_s_plus_1_s_apart_is_no_pair():
    """Two samples 2.5 s apart (noise_lag_s 1 s): a gap, not a pair -- R keeps its prior."""
    tr = MITrend(TrendConfig(gate_d2=1e9))
    tr.update(0.0, 0.5)
    e = tr.update(2.5, 0.7)
    assert e.accepted and e.meas_sd == 0.05 and tr.frame_sd == 0.05


def test_a_rejected_frame_is_no_partner_of_a_pair():
    """The stationary variance is learned from pairs the gate accepted at both ends (a burst's frames
    are no samples of the bed). Frames 0.5 s apart, noise_tau_s 0.25 s (each pair replaces the
    estimates): the pairs 1 s apart of the quiet bed leave R at 0 (0.51 and 0.51); a glitch 1 s before
    an accepted frame leaves it there, so the variance in use is the last consecutive pair's."""
    tr = MITrend(TrendConfig(noise_tau_s=0.25))
    for i in range(20):
        tr.update(i / 2, 0.5 + 0.01 * (i % 3), 0.0)
    glitch = tr.update(10.0, 0.99, 0.0)
    assert not glitch.accepted
    tr.update(10.5, 0.51, 0.0)
    e = tr.update(11.0, 0.5, 0.0)  # its partner, 1 s back, is the glitch
    assert e.accepted and e.meas_sd == pytest.approx(0.01 / math.sqrt(2.0), rel=1e-9)  # |0.5 - 0.51| / sqrt 2


@pytest.mark.parametrize("bed", ["quiet", "slow wave"])
def test_the_rate_and_ripple_densities_scale_with_the_frame_to_frame_variance(bed):
    """Over a missing frame at rest the rate's variance grows by ``k rate_q dt`` with ``k`` the
    frame-to-frame variance (at least ``min_meas_sd^2``, at most the one in use) over ``meas_sd^2``.
    A quiet bed learned below the configured 0.05 widens its rate less; a bed that swings between
    0.4 and 0.6 every second (frames alike, pairs 1 s apart not) is scaled by its frame-to-frame
    variance, not by the larger one in use."""
    cfg = TrendConfig(noise_tau_s=0.5)
    tr = MITrend(cfg)
    for i in range(200):
        wave = 0.006 * ((i // 7) % 2) if bed == "quiet" else 0.2 * ((i // 10) % 2)
        tr.update(i / 10, 0.4 + 0.004 * (i % 3 - 1) + wave, 0.0)
    e0 = tr.estimate(19.9)
    e1 = tr.update(20.0, math.nan, 0.0)
    k = min(e0.meas_sd**2, max(cfg.min_meas_sd**2, tr.frame_sd**2)) / cfg.meas_sd**2
    assert tr.frame_sd < e0.meas_sd  # the case: D1 below R
    if bed == "slow wave":
        assert tr.frame_sd**2 < 0.004 < e0.meas_sd**2
    assert e1.rate_sd**2 - e0.rate_sd**2 == pytest.approx(k * cfg.rate_q * 0.1, rel=1e-6)


def test_the_stationary_variance_is_an_exponential_mean_with_the_frame_gap_as_weight():
    """A constant bed, frames 0.5 s apart, noise_tau_s 2 s: every pair 1 s apart is 0, so R shrinks by
    (1 - a) per pair, a = max(0.5 / 2, 1 / (pairs + 1)): 1/2, 1/3, then 1/4. The frame-to-frame pairs
    start one frame earlier (one pair more, one factor 3/4 more), so the variance in use is R."""
    tr = MITrend(TrendConfig(noise_tau_s=2.0))
    for i in range(8):  # 0 ... 3.5 s: pairs 1 s apart at 1.0, 1.5, ..., 3.5 s (six)
        e = tr.update(i / 2, 0.5, 0.0)
    assert e.meas_sd**2 == pytest.approx(0.05**2 * (1 / 2) * (2 / 3) * 0.75**4, rel=1e-12)
    assert tr.frame_sd**2 == pytest.approx(e.meas_sd**2 * 0.75, rel=1e-12)


def test_a_fresh_or_reset_trend_has_no_accepted_data():
    tr = MITrend()
    assert tr.accepted_s == 0.0
    for i in range(40):
        tr.update(i / 10, 0.5, 0.0)
    assert tr.accepted_s == pytest.approx(3.9)
    tr.reset()
    assert tr.accepted_s == 0.0


def test_no_pair_shorter_than_noise_lag_s_enters_the_stationary_variance():
    """Half a second of a bed alternating 0.5 / 0.52 at 30 fps (from 10 s on the clock): the
    frame-to-frame variance follows it, but no sample is 1 s old yet, so R keeps its prior 0.05^2 and
    the variance in use is that."""
    tr = MITrend(TrendConfig(gate_d2=1e9))
    out = [tr.update(10.0 + i / 30, 0.5 + 0.02 * (i % 2), 0.0) for i in range(15)]
    assert all(e.meas_sd == 0.05 for e in out) and tr.frame_sd < 0.04


def test_after_a_gap_the_next_frame_pairs_with_the_one_after_the_gap():
    """A gap past noise_lag_s + 1 s is no pair, but the frame after the gap starts the next ones:
    0.5 s later the frame-to-frame variance is the running mean with that pair ((0.05^2 + 0.02^2 / 2) / 2)."""
    tr = MITrend(TrendConfig(gate_d2=1e9, noise_tau_s=1e9))
    tr.update(0.0, 0.5)
    tr.update(2.5, 0.5)  # 2.5 s: no consecutive pair (> noise_lag_s) and no pair 1 s apart (> 2 s)
    assert tr.frame_sd == 0.05
    tr.update(3.0, 0.52)
    assert tr.frame_sd**2 == pytest.approx((0.05**2 + 0.02**2 / 2) / 2, rel=1e-12)

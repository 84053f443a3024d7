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
     ({"settle_frames": -1}, "settle_frames"), ({"settle_band": 0.0}, "settle_band"),
     ({"meas_sd": math.nan}, "positive"), ({"settle_band": math.nan}, "settle_band")],
)
def test_trend_config_refuses_each_bad_value(kw, match):
    with pytest.raises(ControlError, match=match):
        TrendConfig(**kw)


@pytest.mark.parametrize(
    "kw",
    [{"ripple_q": 0.0}, {"unsettle_share": 0.6, "reinit_share": 0.6}, {"reinit_share": 1.0, "unsettle_share": 1.0},
     {"reinit_min": 1}, {"settle_frames": 0}, {"min_meas_sd": 1e-9, "meas_sd": 1e-9}],
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

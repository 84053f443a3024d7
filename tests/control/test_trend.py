"""Kalman MI trend: NaN, gating, re-init, ripple, noise estimation; bench vs moving average."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from control.errors import ControlError
from control.trend import (
    MITrend,
    MovingAverage,
    TrendConfig,
    config_from_window,
    estimate_meas_sd,
    moving_average,
)
from control.trendbench import TrendSequence, run_trend_bench, score_sequence, synthetic_sequence, t63_s


def feed(trend: MITrend, t0: float, n: int, mi, rpm: float = 10.0, fps: float = 30.0):
    out = []
    for i in range(n):
        t = t0 + i / fps
        out.append(trend.update(t, mi(t) if callable(mi) else mi, rpm))
    return out


def test_before_first_valid_sample_everything_is_nan():
    tr = MITrend()
    e = tr.update(0.0, math.nan, 10.0)
    assert not e.valid and math.isnan(e.level) and not e.accepted
    e = tr.update(0.1, 0.4, 10.0)
    assert e.valid and e.reinit and e.level == pytest.approx(0.4)


def test_nan_predicts_only_and_uncertainty_grows():
    rng = np.random.default_rng(0)
    tr = MITrend()
    est = feed(tr, 0.0, 300, lambda t: 0.6 + rng.normal(0, 0.03))
    before = est[-1]
    gap = feed(tr, 10.0, 60, math.nan)
    assert not any(e.accepted for e in gap)
    sds = [e.level_sd for e in gap]
    assert all(b > a for a, b in itertools.pairwise(sds))  # predict only: sd grows monotonically
    assert gap[-1].level == pytest.approx(before.level + before.rate * (gap[-1].t_s - before.t_s), abs=1e-6)
    assert gap[-1].hi95 - gap[-1].lo95 > before.hi95 - before.lo95


def test_outlier_is_gated_and_does_not_move_the_level():
    rng = np.random.default_rng(1)
    tr = MITrend()
    feed(tr, 0.0, 300, lambda t: 0.5 + rng.normal(0, 0.03))
    lvl = tr.estimate(10.0).level
    e = tr.update(10.0, 0.98, 10.0)  # glare
    assert not e.accepted and e.nis > tr.config.gate_d2 and e.rejections == 1
    assert abs(e.level - lvl) < 0.01
    e = tr.update(10.0 + 1 / 30, 0.5, 10.0)
    assert e.accepted and e.rejections == 0


def test_reinit_after_the_rejection_cap():
    rng = np.random.default_rng(2)
    cfg = TrendConfig(max_rejections=5)
    tr = MITrend(cfg)
    feed(tr, 0.0, 300, lambda t: 0.3 + rng.normal(0, 0.01))
    jump = feed(tr, 10.0, 10, lambda t: 0.9 + rng.normal(0, 0.01))
    assert [e.accepted for e in jump[:4]] == [False] * 4
    assert jump[4].reinit and jump[4].accepted and jump[4].level == pytest.approx(0.9, abs=0.05)
    assert all(e.level == pytest.approx(0.9, abs=0.05) for e in jump[5:])


def test_ripple_at_rotation_frequency_is_separated_from_level():
    """Ripple at the rotation frequency, rpm changing mid-run: the level stays flat."""
    rng = np.random.default_rng(3)
    tr = MITrend()
    fps, n = 30.0, 1800
    phase, levels, ripple = 0.0, [], []
    for i in range(n):
        t = i / fps
        rpm = 6.0 if t < 30 else 18.0
        phase += 2 * math.pi * rpm / 60 / fps
        e = tr.update(t, 0.55 + 0.08 * math.sin(phase) + rng.normal(0, 0.02), rpm)
        levels.append(e.level)
        ripple.append(e.ripple)
    lv = np.array(levels[300:])
    assert np.max(np.abs(lv - 0.55)) < 0.04  # a raw 0.08 ripple is mostly removed
    assert np.std(ripple[300:]) > 0.04  # ...because the ripple states carry it
    # without the ripple pair (rpm 0: no rotation) the level wobbles much more
    tr0 = MITrend()
    phase, l0 = 0.0, []
    rng = np.random.default_rng(3)
    for i in range(n):
        t = i / fps
        rpm = 6.0 if t < 30 else 18.0
        phase += 2 * math.pi * rpm / 60 / fps
        l0.append(tr0.update(t, 0.55 + 0.08 * math.sin(phase) + rng.normal(0, 0.02), 0.0).level)
    assert np.std(lv - 0.55) < 0.5 * np.std(np.array(l0[300:]) - 0.55)


def test_band_covers_truth_and_rate_follows_a_ramp():
    rng = np.random.default_rng(4)
    tr = MITrend()
    est = feed(tr, 0.0, 1800, lambda t: 0.2 + 0.01 * t + rng.normal(0, 0.04), rpm=0.0)
    late = est[600:]
    cover = np.mean([e.lo95 <= 0.2 + 0.01 * e.t_s <= e.hi95 for e in late])
    assert cover > 0.8
    assert np.mean([e.rate for e in late]) == pytest.approx(0.01, abs=0.003)


def test_time_must_not_go_backwards():
    tr = MITrend()
    tr.update(1.0, 0.5)
    with pytest.raises(ControlError):
        tr.update(0.5, 0.5)


def test_noise_estimated_from_a_window():
    rng = np.random.default_rng(5)
    t = np.arange(900) / 30
    x = 0.5 + 0.05 * np.sin(2 * math.pi * t / 12) + rng.normal(0, 0.03, t.size)
    x[::50] = 1.0  # outliers
    x[::37] = np.nan
    assert estimate_meas_sd(x) == pytest.approx(0.03, rel=0.15)
    cfg = config_from_window(x)
    assert cfg.meas_sd == pytest.approx(0.03, rel=0.15)
    assert cfg.rate_q / cfg.meas_sd**2 == pytest.approx(TrendConfig().rate_q / TrendConfig().meas_sd**2)
    with pytest.raises(ControlError):
        estimate_meas_sd([0.1, math.nan])


def test_moving_average_reference():
    """The one moving average: the last ``window`` finite samples; NaN skipped, not counted."""
    x = np.array([1.0, 2.0, np.nan, 4.0, 5.0])
    np.testing.assert_allclose(moving_average(x, 2), [1.0, 1.5, 1.5, 3.0, 4.5])
    assert np.isnan(moving_average([np.nan, np.nan], 3)).all()
    np.testing.assert_allclose(moving_average([np.nan, 2.0, np.inf, 4.0], 150), [np.nan, 2.0, 2.0, 3.0])
    with pytest.raises(ControlError):
        moving_average(x, 0)


def test_streaming_and_array_moving_averages_agree():
    rng = np.random.default_rng(1)
    x = rng.random(600)
    x[rng.random(600) < 0.2] = np.nan
    ma = MovingAverage(150)
    stream = np.array([ma.update(v) for v in x])
    np.testing.assert_allclose(stream, moving_average(x, 150), rtol=1e-12)
    assert ma.value == pytest.approx(np.mean(x[np.isfinite(x)][-150:]))
    ma.reset()
    assert math.isnan(ma.value) and ma.update(math.nan) != ma.update(math.nan)  # NaN before any sample
    with pytest.raises(ControlError):
        MovingAverage(0)


def test_t63_and_lag_definition_on_a_known_delay():
    t = np.arange(0, 20, 0.1)
    truth = np.where(t >= 10, 1.0, 0.0)
    delayed = np.where(t >= 12, 1.0, 0.0)
    seq = TrendSequence(t, truth, delayed, np.zeros_like(t), 10.0)
    assert t63_s(t, truth, 10.0, 0.0, 1.0) == pytest.approx(10.0)
    assert t63_s(t, delayed, 10.0, 0.0, 1.0) == pytest.approx(12.0)
    s = score_sequence(seq, ma_window=1, warmup_s=0.0)
    assert s.ma_lag_s == pytest.approx(2.0, abs=1e-9)  # window 1 = the measurement itself


def test_kalman_beats_the_150_sample_moving_average():
    res = run_trend_bench([synthetic_sequence(s) for s in range(3)])
    assert res.kalman_rmse < res.ma_rmse
    assert res.kalman_lag_s < res.ma_lag_s
    assert set(res.as_dict()) == {"kalman_rmse", "ma_rmse", "kalman_lag_s", "ma_lag_s"}


def test_one_moving_average_in_the_project():
    """control.trend holds the only moving average (vision.smoothing disagreed on NaN)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    defs = [
        p.relative_to(root).as_posix()
        for pkg in ("vision", "sim", "control", "twin")
        for p in (root / pkg).rglob("*.py")
        if "class MovingAverage" in p.read_text() or "def moving_average" in p.read_text()
    ]
    assert defs == ["control/trend.py"]

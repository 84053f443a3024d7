"""The trend on MI that wanders like a real bed's: correlated over a few hundred ms.

A drum's camera MI is not white noise about its level: the bed's configuration changes
continuously, so frames a few hundred ms apart have nearly the same MI (the demo's plant
at 10 fps: lag-1 autocorrelation 0.85-0.92, spread 0.05-0.07 about a 3 s mean, zero
correlation after about 1 s). Here an AR(1) wander with lag-1 correlation 0.9 at 10 fps
(correlation time ~0.95 s) and sd 0.06 about a constant level 0.88. With the noise learned
from consecutive frames the trend saw a third of the spread, followed the wander with its
rate and gated the rest out: 0.29-0.82 away from the level (seeds 0, 2, 3). Learned from
pairs 1 s apart, with a re-init window of at least ``reinit_min`` samples: at most 0.195.
"""

from __future__ import annotations

import numpy as np
import pytest

from control.trend import MITrend, TrendConfig

FPS, LEVEL, SD, RHO = 10.0, 0.88, 0.06, 0.9


def wander(seed: int, seconds: float = 120.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = int(seconds * FPS)
    e = np.zeros(n)
    for i in range(1, n):
        e[i] = RHO * e[i - 1] + np.sqrt(1 - RHO**2) * SD * rng.normal()
    return np.clip(LEVEL + e, 0.0, 1.0)


def worst_error(z: np.ndarray, cfg: TrendConfig | None = None) -> float:
    tr = MITrend(cfg)
    lv = np.array([tr.update(i / FPS, float(v), 5.0).level for i, v in enumerate(z)])
    return float(np.max(np.abs(lv[int(10 * FPS):] - LEVEL)))  # after 10 s


@pytest.mark.parametrize("seed", range(4))
def test_a_correlated_wander_does_not_run_the_trend_away(seed):
    assert worst_error(wander(seed)) <= 0.25


def test_the_noise_estimate_sees_the_whole_wander_and_consecutive_pairs_would_not():
    """The learned measurement sd is the wander's (0.06) from pairs 1 s apart; consecutive
    pairs (``noise_lag_s = 0``) see sqrt(1 - 0.9) = 0.32 of it and make the filter trust each
    frame three times too much."""
    for seed in range(4):
        z = wander(seed)
        lagged, lag0 = MITrend(), MITrend(TrendConfig(noise_lag_s=0.0))
        for i, v in enumerate(z):
            e1 = lagged.update(i / FPS, float(v), 5.0)
            e0 = lag0.update(i / FPS, float(v), 5.0)
        assert 0.045 <= e1.meas_sd <= 0.08, (seed, e1.meas_sd)
        assert e0.meas_sd <= 0.035, (seed, e0.meas_sd)

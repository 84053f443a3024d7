"""Kalman trend vs the paper's 150-sample moving average, on MI sequences with a step.

A :class:`TrendSequence` is ``t_s`` (s), ``truth`` (the particle-level MI), ``measured``
(what vision reports: noise, rotation ripple, outliers, NaN dropouts), ``rpm`` (actual
drum speed) and ``step_t_s`` (when the step change starts). Sources are pluggable:
:func:`synthetic_sequence` makes one from a model of the noise; the application can build
``TrendSequence`` objects from the twin (truth = particle MI, measured = vision MI of
the rendered frames) and hand them to :func:`run_trend_bench`.

Metrics (both filters run causally over the same samples):

- RMSE of the estimate against ``truth`` over ``t >= warmup_s`` (default: one MA window,
  so the moving average is never scored on a partial window);
- lag after the step: with ``a`` = mean truth over the 2 s before the step and ``b`` =
  mean truth over the last 2 s, ``t63(s)`` is the first time at or after the step where
  the signal ``s`` has covered 63 % of ``b - a``; ``lag = t63(estimate) - t63(truth)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from control.errors import ControlError
from control.trend import MITrend, TrendConfig, moving_average


@dataclass(frozen=True)
class TrendSequence:
    """One benchmark sequence (arrays of equal length; ``measured`` may hold NaN)."""

    t_s: np.ndarray
    truth: np.ndarray
    measured: np.ndarray
    rpm: np.ndarray
    step_t_s: float
    name: str = "sequence"

    def __post_init__(self) -> None:
        n = len(self.t_s)
        if not (len(self.truth) == len(self.measured) == len(self.rpm) == n) or n < 10:
            raise ControlError("a trend sequence needs t_s, truth, measured and rpm of equal length >= 10")


SequenceSource = Callable[[int], TrendSequence]
"""Makes sequence number ``i`` (a seed) — the pluggable part of the benchmark."""


def synthetic_sequence(
    seed: int = 0,
    *,
    fps: float = 30.0,
    duration_s: float = 60.0,
    step_t_s: float = 30.0,
    mi_before: float = 0.35,
    mi_after: float = 0.8,
    mix_tau_s: float = 1.5,
    rpm_before: float = 5.0,
    rpm_after: float = 20.0,
    noise_sd: float = 0.04,
    ripple_amp: float = 0.05,
    outlier_p: float = 0.01,
    dropout_p: float = 0.02,
) -> TrendSequence:
    """Truth: a level that, after an rpm change at ``step_t_s``, approaches a new level
    exponentially (``mix_tau_s``) with a slow wander; measured: truth + white noise +
    a ripple at the rotation frequency (random phase, amplitude drifting) + glare
    outliers (uniform 0..1) + NaN dropouts."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * fps))
    t = np.arange(n) / fps
    after = t >= step_t_s
    truth = np.where(after, mi_after + (mi_before - mi_after) * np.exp(-(t - step_t_s) / mix_tau_s), mi_before)
    wander = np.cumsum(rng.normal(0, 0.0015, n))
    wander -= np.convolve(wander, np.ones(int(fps * 10)) / int(fps * 10), mode="same")  # keep it slow and small
    truth = np.clip(truth + 0.5 * wander, 0.0, 1.0)
    rpm = np.where(after, rpm_before + (rpm_after - rpm_before) * np.minimum(1.0, (t - step_t_s) / 1.5), rpm_before)
    phase = np.cumsum(2 * math.pi * rpm / 60.0 / fps) + rng.uniform(0, 2 * math.pi)
    amp = ripple_amp * (1.0 + 0.2 * np.sin(2 * math.pi * t / 23.0 + rng.uniform(0, 6)))
    meas = truth + amp * np.sin(phase) + rng.normal(0, noise_sd, n)
    out = rng.random(n) < outlier_p
    meas[out] = rng.uniform(0.0, 1.0, int(out.sum()))
    meas[rng.random(n) < dropout_p] = np.nan
    return TrendSequence(t, truth, meas, rpm, step_t_s, name=f"synthetic-{seed}")


def kalman_trend(seq: TrendSequence, config: TrendConfig | None = None) -> np.ndarray:
    """The Kalman level along ``seq`` (causal)."""
    f = MITrend(config)
    return np.array([f.update(t, m, r).level for t, m, r in zip(seq.t_s, seq.measured, seq.rpm, strict=True)])


def t63_s(t_s: np.ndarray, x: np.ndarray, step_t_s: float, a: float, b: float, frac: float = 0.63) -> float:
    """First time >= ``step_t_s`` at which ``x`` has covered ``frac`` of the step a -> b."""
    thr = a + frac * (b - a)
    after = t_s >= step_t_s
    hit = (x >= thr) if b >= a else (x <= thr)
    idx = np.flatnonzero(after & hit & np.isfinite(x))
    return float(t_s[idx[0]]) if idx.size else math.nan


@dataclass(frozen=True)
class SequenceScore:
    name: str
    kalman_rmse: float
    ma_rmse: float
    kalman_lag_s: float
    ma_lag_s: float


@dataclass(frozen=True)
class TrendBenchResult:
    """Mean scores over the sequences (RMSE in MI, lag in s) and the per-sequence ones."""

    kalman_rmse: float
    ma_rmse: float
    kalman_lag_s: float
    ma_lag_s: float
    ma_window: int
    per_sequence: list[SequenceScore] = field(default_factory=list)

    def as_dict(self) -> dict[str, float]:
        return {
            "kalman_rmse": self.kalman_rmse,
            "ma_rmse": self.ma_rmse,
            "kalman_lag_s": self.kalman_lag_s,
            "ma_lag_s": self.ma_lag_s,
        }


def score_sequence(
    seq: TrendSequence, config: TrendConfig | None = None, ma_window: int = 150, warmup_s: float | None = None
) -> SequenceScore:
    """Score the Kalman trend and the moving average on one sequence."""
    t = seq.t_s
    k = kalman_trend(seq, config)
    ma = moving_average(seq.measured, ma_window)
    if warmup_s is None:
        dt = float(np.median(np.diff(t)))
        warmup_s = ma_window * dt
    m = t >= t[0] + warmup_s
    if m.sum() < 10:
        raise ControlError("trend sequence too short for the warm-up window")

    def rmse(est: np.ndarray) -> float:
        ok = m & np.isfinite(est)
        return float(np.sqrt(np.mean((est[ok] - seq.truth[ok]) ** 2)))

    pre = (t >= seq.step_t_s - 2.0) & (t < seq.step_t_s)
    post = t >= t[-1] - 2.0
    if not pre.any() or not post.any():
        raise ControlError("trend sequence needs >= 2 s before the step and after it")
    a, b = float(np.mean(seq.truth[pre])), float(np.mean(seq.truth[post]))
    t_truth = t63_s(t, seq.truth, seq.step_t_s, a, b)
    lag_k = t63_s(t, k, seq.step_t_s, a, b) - t_truth
    lag_ma = t63_s(t, ma, seq.step_t_s, a, b) - t_truth
    return SequenceScore(seq.name, rmse(k), rmse(ma), lag_k, lag_ma)


def run_trend_bench(
    sequences: Iterable[TrendSequence],
    config: TrendConfig | None = None,
    ma_window: int = 150,
    progress: Callable[[int], None] | None = None,
) -> TrendBenchResult:
    """Score every sequence and average (``progress(i)`` after each one)."""
    scores = []
    for i, seq in enumerate(sequences):
        scores.append(score_sequence(seq, config, ma_window))
        if progress is not None:
            progress(i + 1)
    if not scores:
        raise ControlError("no trend sequences to benchmark")

    def mean(name: str) -> float:
        return float(np.nanmean([getattr(s, name) for s in scores]))

    return TrendBenchResult(
        mean("kalman_rmse"), mean("ma_rmse"), mean("kalman_lag_s"), mean("ma_lag_s"), ma_window, scores
    )

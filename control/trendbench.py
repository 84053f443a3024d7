"""Kalman trend vs the paper's 150-sample moving average, on MI sequences with steps.

A :class:`TrendSequence` is ``t_s`` (s), ``truth`` (the MI to be estimated), ``measured``
(what vision reports, may hold NaN), ``rpm`` (actual drum speed) and its step times. Two
sources, both named (there is no twin-generated source):

- :func:`synthetic_sequence`: a *model* of camera MI (an exponential mixing step, white
  noise, a rotation ripple, uniform outliers, NaN dropouts; truth = the model's level);
- :func:`real_sequences`: sequences composed from the raw MI of the *real* PMMA frames of
  ``tests/data/real-drum-pmma`` (:class:`RealFrameMI`, measured once by the application
  with the project's meter): steps segregated -> mixed and back, periodic single-frame
  glitches, bursts, dropouts of 1-5 s, a slow drift (blends of the segregated and mixed
  frames), the frames looped in file order, and the mixed bed under a dark object over a
  third of the drum for 6 frames every 45 (occluded bursts). Truth is piecewise: each
  segment's median raw MI.

Metrics (both filters run causally over the same samples; scored over ``t >= warmup_s``,
default one MA window, so the moving average is never scored on a partial window):

- RMSE of the estimate against ``truth``;
- per step (a change of the truth by >= 0.2 for real sequences, ``step_t_s`` for
  synthetic ones), with ``a`` = mean truth over the 2 s before the step and ``b`` = mean
  truth over the last 2 s before the next step (or the end): ``lag`` = ``t63(estimate) -
  t63(truth)`` (``t63``: first time at or after the step at which 63 % of ``b - a`` is
  covered), ``lag05`` the same for "within 0.05 of ``b``", ``overshoot`` the largest
  excursion past ``b`` in the step's direction before the next step (MI);
- ``lockout_s``: the longest stretch of scored samples farther than 0.05 from the truth;
- ``coverage`` (Kalman only): the share of scored samples whose 95 % band holds the truth;
- ``min``/``max``: the extreme estimates of the whole sequence (MI is in [0, 1]).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from operator import attrgetter

import numpy as np

from control.errors import ControlError
from control.trend import MITrend, TrendConfig, TrendEstimate, moving_average


@dataclass(frozen=True)
class TrendSequence:
    """One benchmark sequence (arrays of equal length; ``measured`` may hold NaN)."""

    t_s: np.ndarray
    truth: np.ndarray
    measured: np.ndarray
    rpm: np.ndarray
    step_t_s: float
    name: str = "sequence"
    steps_t_s: tuple[float, ...] | None = None  # all step times (None: just ``step_t_s``)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        if not (len(self.truth) == len(self.measured) == len(self.rpm) == n) or n < 10:
            raise ControlError("a trend sequence needs t_s, truth, measured and rpm of equal length >= 10")

    @property
    def steps(self) -> tuple[float, ...]:
        """Step times (s) the lags are measured at."""
        if self.steps_t_s is not None:
            return tuple(self.steps_t_s)
        return (self.step_t_s,) if math.isfinite(self.step_t_s) else ()


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


@dataclass(frozen=True)
class RealFrameMI:
    """Raw MI (eq. 4) of real frames, measured once: the pools the real sequences draw from.

    ``segregated``: the segregated frame and its near-copies (blends with a little of a
    mixed frame); ``mixed``: the mixed frames; ``looped``: every frame in file order (the
    video a user makes by looping the folder); ``drift``: pools from segregated to mixed
    (blends of the segregated frame with mixed frames at increasing mixed share);
    ``occluded``: one pool per position of a dark object over the mixed bed (the mixed
    frames with it drawn in; frames the meter flags are left out: those are dropouts).
    """

    segregated: tuple[float, ...]
    mixed: tuple[float, ...]
    looped: tuple[float, ...]
    drift: tuple[tuple[float, ...], ...]
    occluded: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        pools = (self.segregated, self.mixed, self.looped, *self.drift, *self.occluded)
        if not all(len(p) > 0 and all(math.isfinite(v) and 0.0 <= v <= 1.0 for v in p) for p in pools):
            raise ControlError("real-frame MI pools must be non-empty lists of numbers in [0, 1]")
        if not self.drift or not self.occluded:
            raise ControlError("real-frame MI needs at least one drift level and one occluded position")


OCCLUSION_FRAMES = 6
OCCLUSION_EVERY = 45
"""The occluded bursts: a dark object over the bed for 6 frames in every 45 (issue 38)."""


def compose_sequence(
    name: str, segments: Sequence[np.ndarray], fps: float = 30.0, rpm: float = 5.0, min_step: float = 0.2
) -> TrendSequence:
    """One sequence from consecutive segments of measured MI (NaN allowed); the truth of a
    segment is its median raw MI; a change of the truth by ``min_step`` or more is a step."""
    if not segments or any(len(seg) == 0 or not np.isfinite(seg).any() for seg in segments):
        raise ControlError("every segment needs at least one valid MI sample")
    meas = np.concatenate([np.asarray(seg, dtype=float) for seg in segments])
    truth = np.concatenate([np.full(len(seg), float(np.nanmedian(seg))) for seg in segments])
    t = np.arange(meas.size) / fps
    starts = np.cumsum([0] + [len(seg) for seg in segments])[1:-1]
    steps = tuple(float(t[i]) for i in starts if abs(truth[i] - truth[i - 1]) >= min_step)
    return TrendSequence(t, truth, meas, np.full(meas.size, float(rpm)), steps[0] if steps else math.nan,
                         name=name, steps_t_s=steps)


def real_sequences(frames: RealFrameMI, seed: int = 0, fps: float = 30.0, rpm: float = 5.0) -> list[TrendSequence]:
    """The real-signal bench: 60 s sequences at ``fps`` composed from ``frames`` (see the
    module doc), each frame drawn at random from its pool (``seed``)."""
    rng = np.random.default_rng(seed)
    seg, mix = np.asarray(frames.segregated), np.asarray(frames.mixed)
    n = int(round(fps))

    def draw(pool: np.ndarray, seconds: float) -> np.ndarray:
        return rng.choice(pool, int(round(seconds * fps)))

    def glitched(base: np.ndarray, other: np.ndarray, every: int) -> np.ndarray:
        out = base.copy()
        out[every // 2 :: every] = rng.choice(other, out[every // 2 :: every].size)
        return out

    def bursts(base: np.ndarray, other: np.ndarray) -> np.ndarray:
        out, i = base.copy(), int(rng.integers(n, 2 * n))
        while i < out.size:
            k = int(rng.integers(3, 9))  # 3-8 frames: 0.1-0.27 s at 30 fps
            out[i : i + k] = rng.choice(other, min(k, out.size - i))
            i += k + int(rng.integers(2 * n, 4 * n))
        return out

    def occluded(base: np.ndarray) -> np.ndarray:  # one object position per burst (it is held, not waved)
        out, i = base.copy(), int(rng.integers(n, 2 * n))
        while i < out.size:
            pool = np.asarray(frames.occluded[int(rng.integers(len(frames.occluded)))])
            out[i : i + OCCLUSION_FRAMES] = rng.choice(pool, min(OCCLUSION_FRAMES, out.size - i))
            i += OCCLUSION_EVERY
        return out

    def dropouts(base: np.ndarray) -> np.ndarray:
        out, i = base.copy(), int(rng.integers(n, 3 * n))
        while i < out.size - n:
            k = int(rng.integers(n, 5 * n + 1))  # 1-5 s
            out[i : i + k] = np.nan
            i += k + int(rng.integers(3 * n, 6 * n))
        return out

    looped = np.resize(np.asarray(frames.looped), 60 * n)
    drift = [draw(np.asarray(p), 60.0 / len(frames.drift)) for p in frames.drift]  # 60 s from seg to mixed
    return [
        compose_sequence("real-step-up", [draw(seg, 20), draw(mix, 40)], fps, rpm),
        compose_sequence("real-step-down", [draw(mix, 20), draw(seg, 40)], fps, rpm),
        compose_sequence("real-glitches", [glitched(draw(mix, 30), seg, 15), glitched(draw(seg, 30), mix, 15)],
                         fps, rpm),
        compose_sequence("real-bursts", [bursts(draw(mix, 30), seg), bursts(draw(seg, 30), mix)], fps, rpm),
        compose_sequence("real-dropouts", [dropouts(draw(mix, 30)), dropouts(draw(seg, 30))], fps, rpm),
        compose_sequence("real-drift", [draw(seg, 10), *drift, draw(mix, 20)], fps, rpm),
        compose_sequence("real-looped", [looped], fps, rpm),
        compose_sequence("real-occluded", [occluded(draw(mix, 60))], fps, rpm),
    ]


def kalman_estimates(seq: TrendSequence, config: TrendConfig | None = None) -> list[TrendEstimate]:
    """The Kalman estimates along ``seq`` (causal)."""
    f = MITrend(config)
    return [f.update(t, m, r) for t, m, r in zip(seq.t_s, seq.measured, seq.rpm, strict=True)]


def kalman_trend(seq: TrendSequence, config: TrendConfig | None = None) -> np.ndarray:
    """The Kalman level along ``seq`` (causal)."""
    return np.array([e.level for e in kalman_estimates(seq, config)])


def t63_s(t_s: np.ndarray, x: np.ndarray, step_t_s: float, a: float, b: float, frac: float = 0.63) -> float:
    """First time >= ``step_t_s`` at which ``x`` has covered ``frac`` of the step a -> b."""
    thr = a + frac * (b - a)
    after = t_s >= step_t_s
    hit = (x >= thr) if b >= a else (x <= thr)
    idx = np.flatnonzero(after & hit & np.isfinite(x))
    return float(t_s[idx[0]]) if idx.size else math.nan


def t_within_s(t_s: np.ndarray, x: np.ndarray, step_t_s: float, b: float, tol: float = 0.05) -> float:
    """First time >= ``step_t_s`` at which ``x`` is within ``tol`` of ``b``."""
    idx = np.flatnonzero((t_s >= step_t_s) & (np.abs(x - b) <= tol))
    return float(t_s[idx[0]]) if idx.size else math.nan


def longest_run_s(bad: np.ndarray, dt_s: float) -> float:
    """Duration (s) of the longest run of True in ``bad`` (samples ``dt_s`` apart)."""
    best = run = 0
    for v in bad:
        run = run + 1 if v else 0
        best = max(best, run)
    return best * dt_s


@dataclass(frozen=True)
class FilterScore:
    """One filter on one sequence (MI, s; ``coverage`` NaN for a filter without a band)."""

    rmse: float
    lag_s: float
    lag05_s: float
    overshoot: float
    lockout_s: float
    min: float
    max: float
    coverage: float = math.nan


class _Headline:
    """The headline numbers of a score with a ``kalman`` and an ``ma`` :class:`FilterScore`, read
    through to them (``kalman_rmse`` is ``kalman.rmse``; ``as_dict`` names every metric so)."""

    kalman: FilterScore
    ma: FilterScore

    kalman_rmse = property(attrgetter("kalman.rmse"))
    ma_rmse = property(attrgetter("ma.rmse"))
    kalman_lag_s = property(attrgetter("kalman.lag_s"))
    ma_lag_s = property(attrgetter("ma.lag_s"))


@dataclass(frozen=True)
class SequenceScore(_Headline):
    name: str
    kalman: FilterScore
    ma: FilterScore


METRICS = ("rmse", "lag_s", "lag05_s", "overshoot", "lockout_s", "min", "max", "coverage")
"""Per-filter metrics of a bench result; over the sequences ``rmse``, the lags and
``coverage`` are means, ``overshoot``, ``lockout_s`` and ``max`` maxima, ``min`` a minimum."""


@dataclass(frozen=True)
class TrendBenchResult(_Headline):
    """Scores over the sequences (see :data:`METRICS`) and the per-sequence ones."""

    kalman: FilterScore
    ma: FilterScore
    ma_window: int
    per_sequence: list[SequenceScore] = field(default_factory=list)
    name: str = "synthetic"

    def as_dict(self) -> dict[str, float]:
        """``kalman_<metric>`` and ``ma_<metric>`` (MA coverage left out: it has no band)."""
        d = {f"kalman_{m}": float(getattr(self.kalman, m)) for m in METRICS}
        d.update({f"ma_{m}": float(getattr(self.ma, m)) for m in METRICS if m != "coverage"})
        return d


def _score(
    seq: TrendSequence, est: np.ndarray, scored: np.ndarray, dt: float, lo: np.ndarray | None = None,
    hi: np.ndarray | None = None,
) -> FilterScore:
    t, truth = seq.t_s, seq.truth
    ok = scored & np.isfinite(est)
    rmse = float(np.sqrt(np.mean((est[ok] - truth[ok]) ** 2))) if ok.any() else math.nan
    lags, lags05, overs = [], [], []
    steps = seq.steps
    for i, s in enumerate(steps):
        nxt = steps[i + 1] if i + 1 < len(steps) else float(t[-1]) + dt
        pre = (t >= s - 2.0) & (t < s)
        post = (t >= nxt - 2.0) & (t < nxt)
        if not pre.any() or not post.any():
            raise ControlError("trend sequence needs >= 2 s before each step and after it")
        a, b = float(np.mean(truth[pre])), float(np.mean(truth[post]))
        seg = t < nxt
        xs, ts = np.where(seg, est, np.nan), np.where(seg, truth, np.nan)
        lags.append(t63_s(t, xs, s, a, b) - t63_s(t, ts, s, a, b))
        lags05.append(t_within_s(t, xs, s, b) - t_within_s(t, ts, s, b))
        inside = (t >= s) & seg & np.isfinite(est)
        sgn = 1.0 if b >= a else -1.0
        overs.append(max(0.0, float(np.max(sgn * (est[inside] - b)))) if inside.any() else math.nan)
    fin = est[np.isfinite(est)]
    cover = math.nan
    if lo is not None and hi is not None:
        cover = float(np.mean((lo[scored] <= truth[scored]) & (truth[scored] <= hi[scored])))
    off = ~(np.abs(est - truth) <= 0.05)  # NaN (no estimate yet) counts as off
    return FilterScore(
        rmse,
        float(np.nanmean(lags)) if lags and np.isfinite(lags).any() else math.nan,
        float(np.nanmean(lags05)) if lags05 and np.isfinite(lags05).any() else math.nan,
        float(np.nanmax(overs)) if overs and np.isfinite(overs).any() else math.nan,
        longest_run_s(off[scored], dt),
        float(fin.min()) if fin.size else math.nan,
        float(fin.max()) if fin.size else math.nan,
        cover,
    )


def score_sequence(
    seq: TrendSequence, config: TrendConfig | None = None, ma_window: int = 150, warmup_s: float | None = None
) -> SequenceScore:
    """Score the Kalman trend and the moving average on one sequence."""
    t = seq.t_s
    dt = float(np.median(np.diff(t)))
    ests = kalman_estimates(seq, config)
    k = np.array([e.level for e in ests])
    lo, hi = np.array([e.lo95 for e in ests]), np.array([e.hi95 for e in ests])
    ma = moving_average(seq.measured, ma_window)
    if warmup_s is None:
        warmup_s = ma_window * dt
    m = t >= t[0] + warmup_s
    if m.sum() < 10:
        raise ControlError("trend sequence too short for the warm-up window")
    return SequenceScore(seq.name, _score(seq, k, m, dt, lo, hi), _score(seq, ma, m, dt))


def _combine(scores: list[FilterScore]) -> FilterScore:
    def agg(name: str, how: Callable[[np.ndarray], float]) -> float:
        v = np.array([getattr(s, name) for s in scores], dtype=float)
        return float(how(v[np.isfinite(v)])) if np.isfinite(v).any() else math.nan

    return FilterScore(
        agg("rmse", np.mean), agg("lag_s", np.mean), agg("lag05_s", np.mean), agg("overshoot", np.max),
        agg("lockout_s", np.max), agg("min", np.min), agg("max", np.max), agg("coverage", np.mean),
    )


def run_trend_bench(
    sequences: Iterable[TrendSequence],
    config: TrendConfig | None = None,
    ma_window: int = 150,
    progress: Callable[[int], None] | None = None,
    name: str = "synthetic",
) -> TrendBenchResult:
    """Score every sequence and combine (``progress(i)`` after each one)."""
    scores = []
    for i, seq in enumerate(sequences):
        scores.append(score_sequence(seq, config, ma_window))
        if progress is not None:
            progress(i + 1)
    if not scores:
        raise ControlError("no trend sequences to benchmark")
    return TrendBenchResult(
        _combine([s.kalman for s in scores]), _combine([s.ma for s in scores]), ma_window, scores, name
    )

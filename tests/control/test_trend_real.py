"""The trend on sequences of the real PMMA frames (tests/data/real-drum-pmma, issue 21).

Each frame is measured once (classes learned from the frames, as ``classes suggest``
does); the sequences are composed from those raw MI values at 30 fps. The two issue
reproductions run with the live loop's own trend settings (``twin.run.settings.trend_config``).
"""

from __future__ import annotations

import numpy as np
import pytest

from control.trend import MITrend, TrendEstimate
from control.trendbench import RealFrameMI, real_sequences, run_trend_bench
from tests.learned import memoised_learning
from twin.cli.control_cmds import real_frame_mi
from twin.run.settings import trend_config

FPS = 30.0


@pytest.fixture(scope="module")
def frames_mi(real_drum_dir) -> RealFrameMI:
    with memoised_learning():  # the classes of the 27 frames, learned once per code version (tests/learned.py)
        return real_frame_mi(real_drum_dir / "images")


def run_loop_trend(mi: np.ndarray, rpm: float = 5.0) -> list[TrendEstimate]:
    tr = MITrend(trend_config())  # what `drumtwin run` uses
    return [tr.update(i / FPS, float(v), rpm) for i, v in enumerate(mi)]


def test_the_real_frames_are_what_the_issue_describes(frames_mi):
    """0002 segregated (MI ~0.38), the mixed frames 0.94-0.99, 27 frames in the loop."""
    assert len(frames_mi.looped) == 27 and len(frames_mi.mixed) >= 20
    assert frames_mi.looped[0] == min(frames_mi.looped) < 0.45
    assert 0.93 < min(frames_mi.mixed) and max(frames_mi.mixed) < 0.99


def test_looped_real_frames_do_not_lock_the_trend_out(frames_mi):
    """Issue 21, "locked out": the 27 frames looped for 60 s (0002 first). The old trend
    stayed at 0.42-0.44 for the whole minute (raw median 0.971)."""
    mi = np.resize(np.asarray(frames_mi.looped), int(60 * FPS))
    est = run_loop_trend(mi)
    med = float(np.median(mi))
    late = [e for e in est if e.t_s >= 3.0]
    assert max(abs(e.level - med) for e in late) <= 0.05
    assert all(e.settled for e in late)  # and decisions may be made on it
    assert max(abs(e.rate) for e in est) < 0.5  # the old rate swung to +-6 MI/s


def test_real_step_reaches_the_new_level_within_2_s_and_stays_inside_0_1(frames_mi):
    """Issue 21, "slow, then past the physical bound": 1 s of 0002, then 30 s of mixed
    frames. The old trend re-initialised only after its cap of 60 consecutive rejections
    (2.0 s here; 9 s and an overshoot to 1.07 in the issue's run) and its band went past 1.
    The issue asks for <= 2 s; the share-of-rejections re-init takes ~0.4 s, so 1 s is the
    bound that catches a regression to a rejection count."""
    rng = np.random.default_rng(0)
    seg = frames_mi.looped[0]
    mixed = rng.choice(frames_mi.mixed, int(30 * FPS))
    mi = np.concatenate([np.full(int(FPS), seg), mixed])
    est = run_loop_trend(mi)
    new = float(np.median(mixed))
    after = [e for e in est if e.t_s >= 1.0]
    first = next(e.t_s for e in after if abs(e.level - new) <= 0.05)
    assert first - 1.0 <= 1.0
    assert all(abs(e.level - new) <= 0.05 for e in after if e.t_s >= first)
    assert all(0.0 <= e.lo95 <= e.level <= e.hi95 <= 1.0 for e in est)


@pytest.fixture(scope="module")
def real_bench(frames_mi):
    return run_trend_bench([s for seed in range(2) for s in real_sequences(frames_mi, seed)], name="real")


def test_real_bench_kalman_beats_the_moving_average_on_every_sequence(real_bench):
    names = {s.name for s in real_bench.per_sequence}
    assert names == {"real-step-up", "real-step-down", "real-glitches", "real-bursts", "real-dropouts",
                     "real-drift", "real-looped", "real-occluded"}
    for s in real_bench.per_sequence:
        assert s.kalman.rmse < s.ma.rmse, s.name
        assert s.kalman.lockout_s <= 2.0, s.name
        assert 0.0 <= s.kalman.min <= s.kalman.max <= 1.0, s.name
    k, ma = real_bench.kalman, real_bench.ma
    assert k.lag05_s <= 2.0 < ma.lag05_s  # steps: within 0.05 of the new level in <= 2 s
    assert k.overshoot < 0.05


def test_the_occluded_pools_are_a_dark_object_over_the_mixed_bed(frames_mi):
    """Some positions of the object leave a valid reading that is off the mixed bed's MI by
    more than its own spread (the frames the meter flags are dropouts, not in the pools)."""
    clean = float(np.median(frames_mi.mixed))
    assert frames_mi.occluded and all(len(p) > 0 for p in frames_mi.occluded)
    assert min(min(p) for p in frames_mi.occluded) < clean - 0.1  # a burst the gate must catch


@pytest.mark.parametrize("fps", [10.0, 15.0, 30.0])
def test_occluded_bursts_keep_the_trend_within_0_05_of_the_clean_bed(frames_mi, fps):
    """Issue 38, item 4: the mixed bed under a dark object over a third of the drum for 6 frames
    every 45 (the bench's ``real-occluded``, 10 draws; 4 at 30 fps). The trend stays within 0.05 of the clean
    bed's median after the bench's warm-up (150 frames) and never re-initialises onto a burst.
    With reinit_min 8 a 6-frame burst reached the re-init share at 10 and 15 fps (the window's
    8-10 samples): 0.10-0.13 off in 3 of the 20 draws there; at 30 fps 0.022."""
    clean = float(np.median(frames_mi.mixed))
    for seed in range(10 if fps < 20 else 4):
        seq = next(s for s in real_sequences(frames_mi, seed, fps=fps) if s.name == "real-occluded")
        tr = MITrend(trend_config())
        est = [tr.update(t, m, r) for t, m, r in zip(seq.t_s, seq.measured, seq.rpm, strict=True)]
        assert np.isnan(seq.measured).sum() == 0 and (seq.measured < clean - 0.05).sum() >= 10  # bursts there
        worst = max(abs(e.level - clean) for e in est[150:])
        assert worst <= 0.05 and tr.n_reinit == 1, (seed, worst, tr.n_reinit)


def coverage_ok(res) -> bool:
    """The bench's band criterion: the 95 % band holds the truth 90-99 % of the time."""
    return 0.90 <= res.kalman.coverage <= 0.99


def test_real_bench_band_is_honest_and_the_check_can_fail(real_bench, frames_mi, monkeypatch):
    """Coverage measured on the real bench; a band shrunk to 30 % or inflated x3 fails it."""
    assert coverage_ok(real_bench), real_bench.kalman.coverage
    import control.trend as trend_mod

    seqs = [s for seed in range(2) for s in real_sequences(frames_mi, seed)]
    for factor in (0.3, 3.0):
        monkeypatch.setattr(trend_mod, "Z95", trend_mod.Z95 * factor)
        assert not coverage_ok(run_trend_bench(seqs)), factor
        monkeypatch.undo()


def correlated_real_mi(frames: RealFrameMI, seed: int, fps: float, duration_s: float = 120.0) -> np.ndarray:
    """The real mixed frames' MI (drawn at random, one per frame) plus an AR(1) wander of sd 0.06
    with lag-1 correlation 0.9 at 10 fps (0.9 ** (10 / fps) per frame: the same correlation time,
    ~0.95 s, at any rate), clipped to [0, 1]: a bed's MI as the demo's camera reads it (lag-1
    0.80-0.89, sd 0.05-0.07, about uncorrelated after 1 s), on the real frames' values."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * fps)
    phi = 0.9 ** (10.0 / fps)
    w = rng.normal(0.0, 0.06 * np.sqrt(1.0 - phi * phi), n)
    e = np.empty(n)
    e[0] = rng.normal(0.0, 0.06)
    for i in range(1, n):
        e[i] = phi * e[i - 1] + w[i]
    return np.clip(rng.choice(np.asarray(frames.mixed), n) + e, 0.0, 1.0)


def lag1(x: np.ndarray) -> float:
    d = x - x.mean()
    return float(np.dot(d[1:], d[:-1]) / np.dot(d, d))


def longest_run_s(far: np.ndarray, fps: float) -> float:
    """The longest stretch of consecutive True samples (s)."""
    best = cur = 0
    for f in far:
        cur = cur + 1 if f else 0
        best = max(best, cur)
    return best / fps


@pytest.mark.parametrize("seed", range(4))
def test_the_trend_holds_on_correlated_real_mi_at_10_fps(frames_mi, seed):
    """The demo's trend runaway, on real frames: at 10 fps the old trend learnt its noise from
    consecutive frames (a third of the wander's spread), gated the wander and followed it with
    its rate state: max error 0.21-0.95, up to 17.7 s farther than 0.1 from the level (seeds 0-3);
    and 0.6 s held 6 < reinit_min samples, so it could never re-initialise. The truth is the
    sequence's own mean (the wander has mean 0; clipping at 1 moves it). After the first 10 s:
    within 0.15 of it, RMSE <= 0.05, never more than 2 s farther than 0.1 (no lock-out), settled
    >= 90 % of the time (this trend: max 0.09-0.12, RMSE 0.025-0.034, settled 98-100 %)."""
    fps = 10.0
    mi = correlated_real_mi(frames_mi, seed, fps)
    assert 0.82 <= lag1(mi) <= 0.92  # as correlated as the demo's camera MI
    tr = MITrend(trend_config())
    est = [tr.update(i / fps, float(v), 5.0) for i, v in enumerate(mi)]
    truth = float(mi.mean())
    late = [e for e in est if e.t_s >= 10.0]
    err = np.array([abs(e.level - truth) for e in late])
    assert err.max() <= 0.15 and float(np.sqrt(np.mean(err**2))) <= 0.05, (err.max(), np.sqrt(np.mean(err**2)))
    assert longest_run_s(err > 0.1, fps) <= 2.0
    assert np.mean([e.settled for e in late]) >= 0.9
    assert est[-1].meas_sd > 0.03  # the wander's spread (0.06 less the clipping), not a third of it


@pytest.mark.parametrize("seed", range(4))
def test_the_trend_holds_on_correlated_real_mi_at_30_fps(frames_mi, seed):
    """The same wander at 30 fps (lag-1 correlation 0.92-0.94): the old trend re-initialised 43-55
    times in 2 minutes (each re-init restarted its 30-frame settle count and its noise from a
    0.6 s MAD) and was settled 51-62 % of the time, max error 0.12-0.20. After the first 10 s:
    within 0.15 of the level, at most 3 initialisations, settled >= 90 % (this trend: max
    0.07-0.11, one initialisation, settled 100 %)."""
    fps = 30.0
    mi = correlated_real_mi(frames_mi, seed, fps)
    assert 0.9 <= lag1(mi) <= 0.96
    tr = MITrend(trend_config())
    est = [tr.update(i / fps, float(v), 5.0) for i, v in enumerate(mi)]
    truth = float(mi.mean())
    late = [e for e in est if e.t_s >= 10.0]
    err = np.array([abs(e.level - truth) for e in late])
    assert err.max() <= 0.15 and longest_run_s(err > 0.1, fps) <= 2.0, err.max()
    assert tr.n_reinit <= 3, tr.n_reinit
    assert np.mean([e.settled for e in late]) >= 0.9

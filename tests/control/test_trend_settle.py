"""Decisions wait for a settled trend (issue 21, item 3): the pure supervisor; when the trend is
settled, and its band while rejections pile up."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.decision import Action, Mode, SupervisorInputs
from control.supervisor import Supervisor
from control.trend import Z95, MITrend, TrendConfig, TrendEstimate
from tests.control.supervisor_values import worked_config

CFG = worked_config(detect_dwell_s=5.0, min_change_interval_s=30.0, prediction_wait_s=0.0,
                       max_rate_rpm_per_s=100.0)


def est(t: float, level: float, settled: bool) -> TrendEstimate:
    return TrendEstimate(t, level, 0.0, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=settled)


def drive(sup: Supervisor, t0: float, t1: float, level: float, settled: bool):
    """Step every 0.5 s; return (decisions, prediction requests)."""
    decisions, requests = [], []
    t = t0
    while t < t1 - 1e-9:
        inp = SupervisorInputs(trend=est(t, level, settled), setpoint_rpm=5.0, actual_rpm=5.0,
                               mill_running=True, last_valid_mi_s=t, twin_updated_s=t)
        d, req = sup.step(t, inp)
        decisions += [d] if d is not None else []
        requests += [req] if req is not None else []
        t = round(t + 0.5, 6)
    return decisions, requests


def test_an_unsettled_trend_is_never_called_segregated():
    sup = Supervisor(CFG, mode=Mode.AUTO)
    decisions, requests = drive(sup, 0.0, 60.0, level=0.2, settled=False)  # looks badly segregated
    assert decisions == [] and requests == [] and not sup.detector.segregated and not sup.detector.suspect
    decisions, requests = drive(sup, 60.0, 70.0, level=0.2, settled=True)
    assert sup.detector.segregated  # once settled: the dwell runs from the first settled step
    # detected at 65.0 (5 s of settled bad), the request unanswered: the fallback move one step later
    assert [d.action for d in decisions] == [Action.SET_RPM] and decisions[0].t_s == 65.5


def test_auto_neither_asks_nor_moves_while_the_trend_is_unsettled():
    sup = Supervisor(CFG, mode=Mode.AUTO)
    drive(sup, 0.0, 4.0, level=0.2, settled=True)  # bad, dwell running
    decisions, requests = drive(sup, 4.0, 40.0, level=0.2, settled=False)  # re-initialised, say
    assert decisions == [] and requests == []
    decisions, _ = drive(sup, 40.0, 50.0, level=0.2, settled=True)
    assert decisions and decisions[0].t_s == 45.5  # a fresh 5 s dwell on the settled trend, then the fallback


def test_auto_waits_when_the_trend_unsettles_after_detection():
    cfg = worked_config(detect_dwell_s=5.0, min_change_interval_s=30.0, prediction_wait_s=10.0)
    sup = Supervisor(cfg, mode=Mode.AUTO)
    _, requests = drive(sup, 0.0, 5.5, level=0.2, settled=True)
    assert sup.detector.segregated and len(requests) == 1
    decisions, requests = drive(sup, 5.5, 60.0, level=0.2, settled=False)  # no fallback move either
    assert decisions == [] and requests == []


def test_the_real_trend_starts_unsettled_and_settles_within_five_seconds_of_frames():
    """At least settle_s (1 s: 30 frames at 30 fps) of accepted frames, then a band no wider than
    the settle width (settle_band, or one reading's 95 % spread when wider; at the start the ripple
    pair's prior and the configured noise keep the band wide until the noise is learned)."""
    tr = MITrend()
    rng = np.random.default_rng(0)
    out = [tr.update(i / 30, 0.9 + rng.normal(0, 0.01), 5.0) for i in range(300)]
    assert not any(e.settled for e in out[:30])
    first = next(i for i, e in enumerate(out) if e.settled)
    assert first < 150 and all(e.settled for e in out[first:])  # 4.3 s: the 1 s noise pairs start after 1 s
    c = tr.config
    width = [min(c.settle_band_max, max(c.settle_band, 2 * 1.96 * e.meas_sd)) for e in out]
    assert out[first].hi95 - out[first].lo95 <= width[first]
    assert first == 30 or out[first - 1].hi95 - out[first - 1].lo95 > width[first - 1] * (1 + 1e-4)
    assert out[-1].hi95 - out[-1].lo95 <= c.settle_band  # a camera this quiet settles on settle_band itself


def test_a_decision_records_whether_the_trend_was_settled():
    sup = Supervisor(CFG, mode=Mode.AUTO)
    decisions, _ = drive(sup, 0.0, 10.0, level=0.2, settled=True)
    assert decisions and decisions[0].as_dict()["inputs"]["trend_settled"] is True


@pytest.mark.parametrize(("band", "band_max", "limit"), [(0.1, 0.35, 0.15), (0.3, 0.35, 0.35)])
def test_a_settled_trend_unsettles_only_past_1_5_times_its_settle_width(band, band_max, limit):
    """Hysteresis: settled at the first sample (settle_s 0, reinit_min 1, a band of 0.078), the trend
    stays settled while missing frames widen its band up to ``SETTLE_HYSTERESIS`` (1.5) times the
    settle width, never past ``settle_band_max``, and unsettles on the first band wider than that."""
    cfg = TrendConfig(meas_sd=0.02, min_meas_sd=0.02, settle_s=0.0, reinit_min=1, settle_band=band,
                      settle_band_max=band_max)
    tr = MITrend(cfg)
    first = tr.update(0.0, 0.5, 0.0)
    assert first.settled and first.hi95 - first.lo95 < band
    out = [tr.update(0.1 * i, math.nan, 0.0) for i in range(1, 400)]
    widths = [e.hi95 - e.lo95 for e in out]
    k = next(i for i, e in enumerate(out) if not e.settled)
    assert widths[k] > limit >= widths[k - 1] and max(widths[:k]) > band  # settled on a band wider than settle_band
    assert not any(e.settled for e in out[k:])  # and not again while only missing frames come


def test_the_band_takes_in_the_rejected_median_from_unsettle_share_of_a_full_window():
    """reinit_min 4, unsettle_share 0.5 (re-init at 0.75), one frame a second: the window is the last
    4 samples. A rejection in a window not yet full (3 samples after the start) leaves the band alone;
    in a full one, 1 of 4 leaves it alone, 2 of 4 (exactly the share) take the rejected median in."""
    cfg = TrendConfig(reinit_min=4, unsettle_share=0.5, reinit_share=0.75, meas_sd=0.01, min_meas_sd=0.01)
    tr = MITrend(cfg)

    def plain(e) -> bool:  # the band is the level's own 95 % band
        return e.hi95 - e.lo95 == pytest.approx(2 * Z95 * e.level_sd, rel=1e-9)

    tr.update(0.0, 0.5, 0.0)
    tr.update(1.0, 0.5, 0.0)
    early = tr.update(2.0, 0.9, 0.0)  # rejected, 1 of 3
    assert not early.accepted and plain(early)
    for i in range(3, 30):
        assert tr.update(float(i), 0.5, 0.0).accepted
    one = tr.update(30.0, 0.9, 0.0)
    two = tr.update(31.0, 0.9, 0.0)
    assert not one.accepted and plain(one)
    assert not two.accepted and not two.reinit and two.hi95 == 0.9 and two.lo95 < 0.5


@pytest.mark.parametrize("fps", [10.0, 30.0])
def test_a_trend_settles_after_settle_s_of_accepted_frames_at_any_frame_rate(fps):
    """With the band criterion out of the way (settle_band 1) a trend settles on the first sample
    that completes settle_s = 1 s of accepted frames (and reinit_min = 8 of them), at 10 fps as at
    30 fps. (A count of 30 frames, as before, was 2.9 s at 10 fps and 0.97 s at 30 fps.)"""
    tr = MITrend(TrendConfig(settle_band=1.0, settle_band_max=1.0))
    out = [tr.update(i / fps, 0.6 + 0.01 * (i % 3), 5.0) for i in range(int(3 * fps))]
    assert all(e.accepted for e in out)
    first = next(e.t_s for e in out if e.settled)
    assert 1.0 - 1e-9 <= first <= 1.0 + 1 / fps + 1e-9, first
    assert all(e.settled for e in out if e.t_s >= first)


def test_a_trend_needs_reinit_min_accepted_samples_to_settle():
    """One sample, then one more 2 s later: 2 s of data, but 2 < reinit_min samples: not settled."""
    tr = MITrend(TrendConfig(settle_band=1.0, settle_band_max=1.0))
    tr.update(0.0, 0.5)
    e = tr.update(2.0, 0.5)
    assert e.accepted and tr.accepted_s == 2.0 and not e.settled

"""Decisions wait for a settled trend (issue 21, item 3): the pure supervisor."""

from __future__ import annotations

import numpy as np

from control.decision import Action, Mode, SupervisorInputs
from control.supervisor import Supervisor
from control.trend import MITrend, TrendEstimate
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

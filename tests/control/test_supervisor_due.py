"""When the supervisor's AUTO decision is due (settled trend, segregation, intervals), the age of
predictions, and the fallback rule when none come.

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records with values worked out by hand from the rules in control/supervisor.py's docstring
(issue 27's mutation tests; the helpers are tests/control/supervisor_steps.py).
"""

from __future__ import annotations

import math

from control.decision import Action, Decision, Mode, PredictionRequest, PredictionResult
from control.objective import RpmPrediction
from control.supervisor import Supervisor
from tests.control.supervisor_steps import RAMP, WHY, cfg, due, est, inp


# -- when a decision is due, and the fallback rule ----------------------------------------------------
def test_an_unanswered_request_waits_then_falls_back_one_step_up():
    sup, _ = due(cfg(prediction_wait_s=20.0))
    for t in (0.5, 19.5):
        d, req = sup.step(t, inp(t=t))
        assert d is None and req is None  # asked once, waiting
    i = inp(t=20.0)
    d, _ = sup.step(20.0, i)
    assert d == Decision(20.0, Mode.AUTO, Action.SET_RPM, "move",
                         f"segregation ({WHY}); no predictions -> fallback rule 10 -> 15 rpm", rpm=15.0,
                         target_rpm=15.0, inputs=i)


def test_the_fallback_at_the_upper_limit_steps_down():
    sup, i = due(cfg(prediction_wait_s=0.0), inp(rpm=45.0))
    d, _ = sup.step(0.0, i)
    assert d is not None and (d.rpm, d.target_rpm) == (40.0, 40.0)
    assert d.reason.endswith("fallback rule 45 -> 40 rpm")


def test_with_nothing_known_of_the_mill_the_fallback_starts_from_the_safe_rpm_and_jumps():
    sup = Supervisor(cfg(prediction_wait_s=0.0, max_rate_rpm_per_s=1.0), Mode.AUTO)
    i = inp(rpm=None, mill_running=None)
    assert sup.step(0.0, i) == (None, PredictionRequest(0.0, sup.config.candidates(5.0), 60.0, None, 1.0))
    d, _ = sup.step(0.0, i)
    assert d is not None and (d.action, d.rpm, d.target_rpm) == (Action.SET_RPM, 10.0, 10.0)
    assert d.reason.endswith("fallback rule 5 -> 10 rpm") and sup.commanded_rpm == 10.0


def test_a_reported_actual_rpm_is_the_start_when_nothing_was_commanded():
    sup = Supervisor(cfg(prediction_wait_s=0.0), Mode.AUTO)
    i = inp(rpm=None, actual_rpm=math.nan, mill_running=None)  # a NaN board reading: no resync
    sup.step(0.0, i)
    i2 = inp(rpm=None, mill_running=None, mill_epoch=0, actual_rpm=None)
    d, _ = sup.step(0.0, i2)
    assert d is not None and d.reason.endswith("fallback rule 5 -> 10 rpm")
    sup = Supervisor(cfg(prediction_wait_s=0.0), Mode.AUTO)
    i = inp(rpm=None, actual_rpm=60.0, mill_running=None, mill_connected=False)  # no resync while unlinked
    sup.step(0.0, i)  # safe: the link is down
    assert sup.commanded_rpm is None


def test_evaluations_are_min_change_interval_apart():
    c = cfg(prediction_wait_s=0.0, min_change_interval_s=30.0)
    sup, i = due(c)
    d, _ = sup.step(0.0, i)
    assert d is not None and d.rpm == 15.0
    assert sup.step(29.5, inp(rpm=15.0, t=29.5)) == (None, None)
    _, req = sup.step(30.0, inp(rpm=15.0, t=30.0))
    assert req == PredictionRequest(30.0, c.candidates(15.0), 60.0, None, RAMP)


def test_old_predictions_are_not_used_and_older_ones_never_replace_newer():
    c = cfg(prediction_max_age_s=30.0)
    sup, i = due(c)
    sup.step(0.0, i, PredictionResult(0.0, 60.0, {10.0: 0.3, 30.0: 0.31}))  # a hold at t = 0
    assert sup.fresh_predictions(30.0) is not None and sup.fresh_predictions(30.0 + 1e-9) is None
    newer = PredictionResult(5.0, 60.0, {30.0: 0.9})
    sup.step(1.0, inp(t=1.0), newer)
    sup.step(2.0, inp(t=2.0), PredictionResult(4.0, 60.0, {30.0: 0.1}))
    assert sup.fresh_predictions(6.0) is newer
    same_time = PredictionResult(5.0, 60.0, {30.0: 0.5})
    sup.step(3.0, inp(t=3.0), same_time)
    assert sup.fresh_predictions(6.0) is same_time


def test_no_request_while_the_trend_is_unsettled_or_the_bed_mixed():
    sup = Supervisor(cfg(), Mode.AUTO)
    assert sup.step(0.0, inp(level=0.8)) == (None, None)
    sup.step(1.0, inp(t=1.0))  # segregated, asks
    sup2 = Supervisor(cfg(), Mode.AUTO)
    sup2.step(0.0, inp())
    i = inp(trend=est(0.3, settled=False))
    assert sup2.step(1.0, i) == (None, None)


# -- when AUTO decides -----------------------------------------------------------------------------------------
def test_plateau_with_a_target_mi_never_decides_below_it():
    # plateau (the default) with the endpoint's target_mi: only segregation makes a decision due
    sup = Supervisor(cfg(target_mi=0.9), Mode.AUTO)
    assert sup.step(0.0, inp(level=0.7)) == (None, None)


def test_time_at_exactly_the_target_is_not_below_it():
    sup = Supervisor(cfg(objective="time", target_mi=0.875), Mode.AUTO)
    assert sup.step(0.0, inp(level=0.875)) == (None, None)
    _, req = sup.step(1.0, inp(level=0.874, t=1.0))
    assert req is not None


def test_no_request_on_an_unsettled_trend_after_segregation_was_detected():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0), Mode.AUTO)
    d, req = sup.step(0.0, inp(rpm=46.0))  # a board above the limits: the ramp to 45 comes first
    assert d is not None and d.kind == "ramp" and req is None and sup.detector.segregated
    unsettled = inp(rpm=45.0, t=1.0, trend=est(0.3, settled=False, t=1.0), mill_epoch=0)
    assert sup.step(1.0, unsettled) == (None, None)
    assert sup.step(2.0, inp(rpm=45.0, t=2.0))[1] is not None


def test_plateau_predictions_with_rows_are_scored_as_plateau():
    sup, i = due()
    rows = {10.0: RpmPrediction(10.0, 0.3, 100.0, 10.0), 30.0: RpmPrediction(30.0, 0.6, 50.0, 10.0)}
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, {10.0: 0.3, 30.0: 0.6}, rows=rows))
    assert d is not None and d.reason.startswith(f"segregation ({WHY}); twin predicts MI 0.600 at 30 rpm")


def test_the_fallback_below_the_upper_limit_steps_up_to_it():
    sup, i = due(cfg(prediction_wait_s=0.0), inp(rpm=44.5))
    d, _ = sup.step(0.0, i)
    assert d is not None and d.target_rpm == 45.0 and d.reason.endswith("fallback rule 44.5 -> 45 rpm")


def test_a_fallback_step_of_exactly_a_micro_rpm_is_a_step():
    c = cfg(min_rpm=0.0, max_rpm=1e-6, prediction_wait_s=0.0)
    sup = Supervisor(c, Mode.AUTO)
    i = inp(rpm=0.0, mill_running=False)
    sup.step(0.0, i)
    d, _ = sup.step(0.0, i)
    assert d is not None and d.target_rpm == 1e-6

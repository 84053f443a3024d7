"""The supervisor's step, decision by decision (issue 27's mutation tests of control/supervisor.py).

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records -- time, mode, action, kind, the logged reason, rpm, target, safe flag, inputs,
predictions and scores -- with values worked out by hand from the rules in the module docstring.
"""

from __future__ import annotations

import math

import pytest

from control.decision import Action, Decision, Mode, PredictionRequest, PredictionResult, SupervisorInputs
from control.errors import ControlError
from control.objective import RpmPrediction, choose
from control.supervisor import Supervisor
from control.supervisor_config import SafeAction, SupervisorConfig
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config


def est(level: float, rate: float = 0.0, settled: bool = True, t: float = 0.0) -> TrendEstimate:
    return TrendEstimate(t, level, rate, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=settled)


def inp(level: float = 0.3, rpm: float | None = 10.0, t: float = 0.0, **kw) -> SupervisorInputs:
    base: dict = dict(trend=est(level, t=t), actual_rpm=rpm, setpoint_rpm=rpm, mill_running=True,
                      last_valid_mi_s=t, twin_updated_s=t)
    base.update(kw)
    return SupervisorInputs(**base)


def cfg(**kw) -> SupervisorConfig:
    base: dict = dict(detect_dwell_s=0.0, max_rate_rpm_per_s=100.0, prediction_wait_s=20.0)
    base.update(kw)
    return worked_config(**base)


def due(
    config: SupervisorConfig | None = None, i: SupervisorInputs | None = None
) -> tuple[Supervisor, SupervisorInputs]:
    """An AUTO supervisor on a segregated bed (MI 0.3) at 10 rpm that has just asked for predictions."""
    sup = Supervisor(config or cfg(), Mode.AUTO)
    i = i or inp()
    d, req = sup.step(0.0, i)
    assert d is None and req == PredictionRequest(0.0, sup.config.candidates(i.actual_rpm), 60.0, None, RAMP)
    return sup, i


def answer(preds: dict, config: SupervisorConfig | None = None, i: SupervisorInputs | None = None,
           t: float = 0.0) -> tuple[Supervisor, Decision | None, SupervisorInputs]:
    sup, i = due(config, i)
    d, req = sup.step(t, i, PredictionResult(0.0, 60.0, preds))
    assert req is None
    return sup, d, i


WHY = "MI 0.300 < 0.5"
RAMP = 100.0  # cfg()'s max_rate_rpm_per_s: the twin ramps as the mill will (PredictionRequest.ramp_rpm_s)


# -- the plateau choice ---------------------------------------------------------------------------
def test_a_move_to_the_best_score_names_the_prediction_the_score_and_staying():
    preds = {5.0: 0.5, 10.0: 0.4, 20.0: 0.6}
    sup, d, i = answer(preds)
    scores = {5.0: 0.5 - 0.002 * 5, 10.0: 0.4, 20.0: 0.6 - 0.002 * 10}
    reason = f"segregation ({WHY}); twin predicts MI 0.600 at 20 rpm (score 0.580 vs 0.400 staying at 10)"
    assert d == Decision(0.0, Mode.AUTO, Action.SET_RPM, "move", reason, rpm=20.0, target_rpm=20.0, inputs=i,
                         predictions=preds, scores=scores)
    assert list(sup.events)[-1] is d and sup.commanded_rpm == 20.0 and sup.target_rpm == 20.0


def test_a_gain_below_min_gain_holds_with_the_numbers():
    preds = {10.0: 0.40, 20.0: 0.435}
    sup, d, i = answer(preds)
    reason = f"segregation ({WHY}); best 20 rpm gains +0.015 < 0.02 -> stay at 10"
    assert d == Decision(0.0, Mode.AUTO, Action.NONE, "hold", reason, inputs=i, predictions=preds,
                         scores={10.0: 0.40, 20.0: pytest.approx(0.415)})
    assert sup.commanded_rpm == 10.0 and sup.target_rpm == 10.0


def test_a_gain_of_exactly_min_gain_moves():
    _, d, _ = answer({10.0: 0.25, 20.0: 0.25 + 0.02 + 0.002 * 10 + 1e-12}, cfg(min_gain=0.02))
    assert d is not None and d.kind == "move" and d.rpm == 20.0
    _, d, _ = answer({10.0: 0.25, 20.0: 0.25 + 0.02 + 0.002 * 10 - 1e-6}, cfg(min_gain=0.02))
    assert d is not None and d.kind == "hold"


def test_the_best_at_the_current_rpm_holds():
    preds = {10.0: 0.9, 20.0: 0.5}
    _, d, _ = answer(preds)
    assert d is not None and (d.kind, d.action, d.rpm) == ("hold", Action.NONE, None)
    assert d.reason == f"segregation ({WHY}); best 10 rpm gains +0.000 < 0.02 -> stay at 10"


def test_staying_is_scored_at_the_nearest_candidate_within_half_an_rpm():
    # 10.5 is the current rpm's candidate (<= 0.5 rpm away), 10.4 is nearer still; 10.6 would not be
    preds = {10.5: 0.45, 10.4: 0.40, 30.0: 0.48}
    _, d, _ = answer(preds, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.kind == "move" and "vs 0.400 staying at 10" in d.reason
    _, d, _ = answer({10.5: 0.40, 30.0: 0.43}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.kind == "move" and "vs 0.400 staying at 10" in d.reason
    # nothing within 0.5 rpm: staying is worth the trend's level (0.3)
    _, d, _ = answer({10.6: 0.40, 30.0: 0.33}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.kind == "move" and d.rpm == 10.6 and "vs 0.300 staying at 10" in d.reason


def test_staying_is_the_nearest_candidates_score_not_the_lowest_rpms():
    # 9.6 and 10.1 are both within 0.5 rpm of 10: staying is 10.1's score (nearer), not 9.6's
    _, d, _ = answer({9.6: 0.10, 10.1: 0.42, 30.0: 0.43}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.kind == "hold" and "gains +0.010" in d.reason
    _, d, _ = answer({9.6: 0.42, 10.1: 0.10, 30.0: 0.43}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.kind == "move" and "vs 0.100 staying at 10" in d.reason


def test_a_gain_of_exactly_min_gain_in_binary_fractions_moves():
    _, d, _ = answer({10.0: 0.25, 20.0: 0.5}, cfg(move_penalty_per_rpm=0.0, min_gain=0.25))
    assert d is not None and d.kind == "move" and d.rpm == 20.0


def test_the_best_at_the_current_rpm_holds_even_when_any_gain_would_do():
    for min_gain in (0.0, -1.0):
        _, d, _ = answer({10.0: 0.9, 20.0: 0.5}, cfg(min_gain=min_gain))
        assert d is not None and d.kind == "hold", min_gain


def test_a_best_a_micro_rpm_from_the_current_one_is_a_move():
    # a stopped board (0 rpm) with a 0..45 rpm range: 1e-6 rpm is exactly 1e-6 away, not "the same rpm"
    c = cfg(min_rpm=0.0, move_penalty_per_rpm=0.0)
    i = inp(rpm=0.0, actual_rpm=0.0, setpoint_rpm=0.0, mill_running=False)
    sup = Supervisor(c, Mode.AUTO)
    sup.step(0.0, i)
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, {0.0: 0.5, 1e-6: 0.6}))
    assert d is not None and d.kind == "move" and d.target_rpm == 1e-6


def test_candidates_exactly_at_the_limits_slack_are_scored():
    lo, hi = worked_config().limits.rpm_range
    _, d, _ = answer({lo - 1e-9: 0.3, hi + 1e-9: 0.3, 10.0: 0.3})
    assert d is not None and d.scores is not None and set(d.scores) == {lo - 1e-9, hi + 1e-9, 10.0}


def test_without_a_candidate_near_and_a_level_staying_is_worth_nothing():
    # segregated, then the trend loses its level (a settled record without a valid level)
    sup = Supervisor(cfg(), Mode.AUTO)
    sup.step(0.0, inp())
    i = inp(trend=TrendEstimate(0.0, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False, False,
                                settled=True))
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, {30.0: 0.05}))
    assert d is not None and d.kind == "move" and d.rpm == 30.0 and "vs -inf staying at 10" in d.reason


def test_candidates_outside_the_limits_or_without_a_number_are_not_scored():
    lo, hi = worked_config().limits.rpm_range
    preds = {lo - 1e-8: 0.9, hi + 1e-8: 0.9, lo - 1e-10: 0.31, hi + 1e-10: 0.5, 20.0: math.nan, 10.0: 0.3}
    _, d, _ = answer(preds)
    assert d is not None and d.scores is not None
    assert set(d.scores) == {lo - 1e-10, hi + 1e-10, 10.0}
    assert d.scores[hi + 1e-10] == pytest.approx(0.5 - 0.002 * (hi - 10.0))
    assert d.scores[lo - 1e-10] == pytest.approx(0.31 - 0.002 * (10.0 - lo))


def test_predictions_all_outside_the_limits_hold_with_the_reason():
    preds = {100.0: 0.9, 1.0: 0.8}
    _, d, i = answer(preds)
    assert d == Decision(0.0, Mode.AUTO, Action.NONE, "hold",
                         f"segregation ({WHY}); predictions empty or out of limits", inputs=i, predictions=preds)


def test_equal_scores_go_to_the_nearer_rpm():
    _, d, _ = answer({14.0: 0.6, 6.0: 0.5, 20.0: 0.6}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.rpm == 14.0
    _, d, _ = answer({20.0: 0.6, 3.0: 0.6, 14.0: 0.6}, cfg(move_penalty_per_rpm=0.0))
    assert d is not None and d.rpm == 14.0


def test_a_plateau_choice_under_another_objective_says_it_had_no_rows():
    c = cfg(objective="time", target_mi=0.9)
    sup = Supervisor(c, Mode.AUTO)
    i = inp()
    _, req = sup.step(0.0, i)
    assert req == PredictionRequest(0.0, c.candidates(10.0), 60.0, 0.9, RAMP, from_bed=True)
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, {10.0: 0.3, 30.0: 0.6}))
    assert d is not None and d.reason == (
        f"segregation (objective time: no time/energy rows -> plateau; {WHY}); twin predicts MI 0.600 at 30 rpm "
        "(score 0.560 vs 0.300 staying at 10)")


def test_below_the_target_without_segregation_the_reason_says_so():
    c = cfg(objective="time", target_mi=0.9)
    sup = Supervisor(c, Mode.AUTO)
    i = inp(level=0.7)  # not segregated (>= 0.5), below the target 0.9
    _, req = sup.step(0.0, i)
    assert req is not None
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, {10.0: 0.7, 30.0: 0.95}))
    assert d is not None and d.reason.startswith(
        "segregation (objective time: no time/energy rows -> plateau; below target MI 0.9); twin predicts")


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


# -- ramps -------------------------------------------------------------------------------------------
def test_a_move_ramps_at_the_rate_limit_once_per_interval_with_its_reason():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0, ramp_interval_s=1.0, prediction_wait_s=0.0), Mode.AUTO)
    i = inp()
    sup.step(0.0, i)
    d, _ = sup.step(0.0, i)
    assert d is not None and (d.kind, d.rpm, d.target_rpm) == ("move", 12.0, 15.0)
    assert sup.step(1.0 - 2e-9, i) == (None, None)  # within the interval (1e-9 of slack only)
    d, _ = sup.step(1.0 - 5e-10, i)
    assert d == Decision(1.0 - 5e-10, Mode.AUTO, Action.SET_RPM, "ramp", "ramp 14 rpm toward 15 (<= 2 rpm/s)",
                         rpm=14.0, target_rpm=15.0, inputs=i)
    d, _ = sup.step(2.0, i)
    assert d is not None and (d.rpm, d.reason) == (15.0, "ramp 15 rpm toward 15 (<= 2 rpm/s)")
    assert sup.step(3.0, i) == (None, None)


def test_a_ramp_lands_on_its_target_within_a_hundredth_and_rounds_to_two_decimals():
    sup = Supervisor(cfg(max_rate_rpm_per_s=0.333, ramp_interval_s=1.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(10.675)
    got = [sup.step(float(t), inp(rpm=10.0))[0] for t in range(1, 4)]
    assert [g.rpm for g in got if g is not None] == [10.33, 10.66, 10.675]


def test_a_rate_of_zero_means_no_rate_limit():
    sup = Supervisor(cfg(max_rate_rpm_per_s=0.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(40.0)
    d, _ = sup.step(1.0, inp(rpm=10.0))
    assert d is not None and (d.kind, d.rpm, d.target_rpm) == ("manual", 40.0, 40.0)
    assert d.reason == "operator rpm 40"


def test_a_ramp_down_keeps_its_sign():
    sup = Supervisor(cfg(max_rate_rpm_per_s=3.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=20.0))
    sup.set_manual_rpm(10.0)
    rpms = [d.rpm for t in range(1, 6) if (d := sup.step(float(t), inp(rpm=20.0))[0]) is not None]
    assert rpms == [17.0, 14.0, 11.0, 10.0]


def test_manual_without_an_operator_rpm_only_brings_a_board_above_the_limits_down():
    sup = Supervisor(cfg(max_rate_rpm_per_s=0.0), Mode.MANUAL)
    board_above = inp(rpm=60.0)
    d, _ = sup.step(0.0, board_above)  # a board above the limits: no operator rpm taken, brought down to 45
    assert sup.manual_rpm is None and sup.target_rpm == 45.0
    assert d is not None and (d.kind, d.action, d.rpm) == ("ramp", Action.SET_RPM, 45.0)
    assert sup.step(1.0, inp(rpm=45.0)) == (None, None)  # inside now, and still no operator rpm: nothing
    sup.set_manual_rpm(20.0)
    d, _ = sup.step(2.0, inp(rpm=45.0))
    assert d is not None and (d.kind, d.rpm) == ("manual", 20.0)
    assert sup.step(3.0, inp(rpm=20.0)) == (None, None)



# -- board resync -------------------------------------------------------------------------------------
def test_resync_takes_the_actual_rpm_of_a_running_board_and_the_setpoint_of_a_stopped_one():
    sup = Supervisor(cfg(), Mode.OFF)
    sup.step(0.0, inp(actual_rpm=12.345, setpoint_rpm=20.0, mill_running=True))
    assert (sup.commanded_rpm, sup.target_rpm) == (12.35, 12.35)  # rounded to the wire's 2 decimals
    sup.step(1.0, inp(actual_rpm=0.0, setpoint_rpm=20.0, mill_running=False, mill_epoch=1))
    assert sup.commanded_rpm == 20.0
    sup.step(2.0, inp(actual_rpm=7.0, setpoint_rpm=None, mill_running=False, mill_epoch=2))
    assert sup.commanded_rpm == 7.0  # no setpoint: the actual rpm
    sup.step(3.0, inp(actual_rpm=None, setpoint_rpm=9.0, mill_running=True, mill_epoch=3))
    assert sup.commanded_rpm == 9.0  # running but no actual: the setpoint
    sup.step(4.0, inp(actual_rpm=30.0, setpoint_rpm=30.0, mill_running=True, mill_epoch=3))
    assert sup.commanded_rpm == 9.0  # same epoch: no resync
    sup.step(5.0, inp(actual_rpm=31.0, setpoint_rpm=31.0, mill_epoch=4, mill_connected=False))
    assert sup.commanded_rpm == 9.0  # unlinked: nothing read
    sup.step(6.0, inp(actual_rpm=math.inf, setpoint_rpm=math.inf, mill_epoch=5))
    assert sup.commanded_rpm == 9.0  # not a number: ignored, and the epoch not taken
    sup.step(7.0, inp(actual_rpm=11.0, setpoint_rpm=11.0, mill_epoch=5))
    assert sup.commanded_rpm == 11.0


def test_resync_during_a_ramp_keeps_the_target_and_in_off_a_board_above_stays_untouched():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(20.0)
    sup.step(1.0, inp(rpm=10.0))  # ramping 10 -> 12 ... -> 20
    sup.step(1.5, inp(actual_rpm=11.0, setpoint_rpm=12.0, mill_epoch=1))
    assert (sup.commanded_rpm, sup.target_rpm) == (11.0, 20.0)
    off = Supervisor(cfg(), Mode.OFF)
    off.step(0.0, inp(rpm=60.0))
    assert (off.commanded_rpm, off.target_rpm) == (60.0, 60.0)


def test_a_mode_change_takes_the_commanded_rpm_as_the_operators_only_inside_the_limits():
    sup = Supervisor(cfg(), Mode.OFF)
    sup.step(0.0, inp(rpm=20.0))
    d = sup.set_mode(Mode.MANUAL, 1.0)
    assert d == Decision(1.0, Mode.MANUAL, Action.NONE, "mode", "mode off -> manual (operator)",
                         inputs=inp(rpm=20.0))
    assert sup.manual_rpm == 20.0 and sup.target_rpm == 20.0
    sup2 = Supervisor(cfg(), Mode.OFF)
    sup2.step(0.0, inp(rpm=45.0))
    sup2.set_mode("manual", 1.0, reason="test")
    assert sup2.manual_rpm == 45.0 and sup2.events[-1].reason == "mode off -> manual (test)"
    sup3 = Supervisor(cfg(), Mode.OFF)
    sup3.step(0.0, inp(rpm=2.0))
    sup3.set_mode(Mode.MANUAL, 1.0)
    assert sup3.manual_rpm == 2.0
    for outside in (1.9, 45.1):
        s = Supervisor(cfg(), Mode.OFF)
        s.step(0.0, inp(rpm=outside))
        s.set_mode(Mode.MANUAL, 1.0)
        assert s.manual_rpm is None
    s = Supervisor(cfg(), Mode.OFF)
    s.step(0.0, inp(rpm=20.0))
    s.set_mode(Mode.AUTO, 1.0)
    assert s.manual_rpm is None


def test_a_resync_in_manual_adopts_the_board_rpm_only_inside_the_limits():
    sup = Supervisor(cfg(), Mode.MANUAL)
    sup.step(0.0, inp(rpm=2.0))
    assert sup.manual_rpm == 2.0
    sup = Supervisor(cfg(), Mode.MANUAL)
    sup.step(0.0, inp(rpm=1.0))
    assert sup.manual_rpm is None
    sup = Supervisor(cfg(), Mode.AUTO)
    sup.step(0.0, inp(rpm=20.0, trend=est(0.9)))
    assert sup.manual_rpm is None


# -- safe state -----------------------------------------------------------------------------------------
def test_safe_hold_names_the_rpm_and_recovers_after_recover_s_with_the_old_reason():
    sup = Supervisor(cfg(recover_s=5.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    lost = inp(rpm=10.0, mill_connected=False)
    d, _ = sup.step(1.0, lost)
    assert d == Decision(1.0, Mode.MANUAL, Action.NONE, "safe", "safe hold at 10.0 rpm: mill link lost",
                         safe=True, inputs=lost)
    assert sup.safe and sup.safe_reason == "mill link lost"
    assert sup.step(2.0, lost) == (None, None)  # still in fault: nothing new
    back = inp(rpm=10.0)
    assert sup.step(3.0, back) == (None, None)
    assert sup.step(7.5, back) == (None, None)
    d, _ = sup.step(8.0, back)
    assert d == Decision(8.0, Mode.MANUAL, Action.NONE, "recover",
                         "faults cleared for 5 s (was: mill link lost)", inputs=back)
    assert not sup.safe and sup.safe_reason == ""


def test_a_fault_during_recovery_restarts_its_clock():
    sup = Supervisor(cfg(recover_s=5.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.step(1.0, inp(rpm=10.0, mill_connected=False))
    sup.step(2.0, inp(rpm=10.0))
    sup.step(4.0, inp(rpm=10.0, mill_connected=False))
    assert sup.step(5.0, inp(rpm=10.0)) == (None, None)
    assert sup.step(9.5, inp(rpm=10.0)) == (None, None)
    d, _ = sup.step(10.0, inp(rpm=10.0))
    assert d is not None and d.kind == "recover"


def test_safe_ramp_goes_to_the_clamped_safe_rpm_at_the_rate_limit():
    c = cfg(safe_action=SafeAction.RAMP, safe_rpm=1.0, max_rate_rpm_per_s=3.0, recover_s=100.0)
    sup = Supervisor(c, Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    lost = inp(rpm=10.0, mill_connected=False)
    d, _ = sup.step(1.0, lost)
    assert d == Decision(1.0, Mode.MANUAL, Action.SET_RPM, "safe", "safe ramp to 2 rpm: mill link lost",
                         rpm=7.0, target_rpm=2.0, safe=True, inputs=lost)
    d, _ = sup.step(2.0, lost)
    assert d == Decision(2.0, Mode.MANUAL, Action.SET_RPM, "safe", "ramp 4 rpm toward 2 (<= 3 rpm/s)",
                         rpm=4.0, target_rpm=2.0, safe=True, inputs=lost)
    d, _ = sup.step(3.0, inp(rpm=4.0))  # faults gone, recovering: the ramp goes on
    assert d is not None and (d.kind, d.rpm) == ("safe", 2.0)


def test_safe_ramp_right_after_a_command_waits_for_its_interval():
    c = cfg(safe_action=SafeAction.RAMP, safe_rpm=5.0, max_rate_rpm_per_s=2.0)
    sup = Supervisor(c, Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(12.0)
    sup.step(0.0, inp(rpm=10.0))  # 10 -> 12 sent at t = 0
    lost = inp(rpm=12.0, mill_connected=False)
    d, _ = sup.step(0.5, lost)
    assert d is not None and (d.action, d.rpm, d.target_rpm) == (Action.NONE, None, 5.0)
    assert d.reason == "safe ramp to 5 rpm: mill link lost"


def test_safe_ramp_with_nothing_known_of_the_mill_holds():
    sup = Supervisor(cfg(safe_action=SafeAction.RAMP), Mode.MANUAL)
    lost = inp(rpm=None, mill_connected=False)
    d, _ = sup.step(0.0, lost)
    assert d == Decision(0.0, Mode.MANUAL, Action.NONE, "safe", "safe hold at None rpm: mill link lost",
                         safe=True, inputs=lost)


def test_safe_stop_is_latched_until_a_mode_is_set():
    sup = Supervisor(cfg(safe_action=SafeAction.STOP, recover_s=1.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    lost = inp(rpm=10.0, mill_connected=False)
    d, _ = sup.step(1.0, lost)
    assert d == Decision(1.0, Mode.MANUAL, Action.STOP, "safe", "safe stop: mill link lost", safe=True, inputs=lost)
    assert sup.target_rpm == 10.0
    for t in (2.0, 5.0, 50.0):
        assert sup.step(t, inp(rpm=10.0)) == (None, None)
    sup.set_manual_rpm(20.0)
    assert sup.step(60.0, inp(rpm=10.0)) == (None, None) and sup.safe
    sup.set_mode(Mode.MANUAL, 61.0)
    assert not sup.safe and sup.safe_reason == ""
    d, _ = sup.step(62.0, inp(rpm=10.0))
    assert d is not None and (d.kind, d.rpm) == ("manual", 20.0)


def test_a_refused_command_is_a_fault_for_the_step_it_grew_on():
    sup = Supervisor(cfg(recover_s=2.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    refused = inp(rpm=10.0, mill_refused=1)
    d, _ = sup.step(1.0, refused)
    assert d is not None and d.reason == "safe hold at 10.0 rpm: the mill refused a command"
    assert sup.step(2.0, refused) == (None, None)  # the same count: no new fault, recovering
    assert sup.step(3.5, refused) == (None, None)
    d, _ = sup.step(4.0, refused)
    assert d is not None and d.kind == "recover"
    both = inp(rpm=10.0, mill_refused=2, mill_connected=False)
    d, _ = sup.step(5.0, both)
    assert d is not None and d.reason == "safe hold at 10.0 rpm: mill link lost; the mill refused a command"


def test_auto_faults_join_into_one_reason_and_the_safe_state_drops_a_pending_request():
    sup = Supervisor(cfg(), Mode.AUTO)
    i = inp(twin_updated_s=0.0)
    _, req = sup.step(0.0, i)
    assert req is not None
    bad = inp(t=100.0, last_valid_mi_s=0.0, twin_updated_s=0.0, twin_doubt="disagrees", camera_ended=False)
    d, _ = sup.step(100.0, bad)
    assert d is not None and d.reason == ("safe hold at 10.0 rpm: no valid MI for 100.0 s; twin stale for 100.0 s; "
                                          "twin stale: disagrees")
    d, _ = sup.step(200.0, inp(t=200.0))
    assert d is None
    d, _ = sup.step(205.0, inp(t=205.0))
    assert d is not None and d.kind == "recover"
    _, req = sup.step(205.0, inp(t=205.0))
    assert req == PredictionRequest(205.0, sup.config.candidates(10.0), 60.0, None, RAMP)


def test_recovery_resets_the_detector_and_retargets_at_the_commanded_rpm():
    sup = Supervisor(cfg(recover_s=1.0), Mode.AUTO)
    sup.step(0.0, inp())
    assert sup.detector.segregated
    sup.step(1.0, inp(t=1.0, mill_connected=False))
    sup.step(2.0, inp(t=2.0, trend=est(0.9)))
    d, _ = sup.step(3.0, inp(t=3.0, trend=est(0.9)))
    assert d is not None and d.kind == "recover" and not sup.detector.segregated
    assert sup.target_rpm == sup.commanded_rpm == 10.0


def test_off_steps_do_nothing_but_follow_the_board():
    sup = Supervisor(cfg(), Mode.OFF)
    assert sup.step(0.0, inp(mill_connected=False, mill_refused=3)) == (None, None)
    assert not sup.safe and sup.events == type(sup.events)(maxlen=10000)
    sup.set_mode(Mode.MANUAL, 1.0)
    sup.set_manual_rpm(20.0)
    d, _ = sup.step(2.0, inp(mill_refused=3))  # the refusals seen in OFF are not a fault later
    assert d is not None and d.kind == "manual"


def test_events_keep_at_most_max_events():
    sup = Supervisor(cfg(), Mode.OFF, max_events=2)
    for t in range(4):
        sup.set_mode(Mode.OFF, float(t))
    assert [d.t_s for d in sup.events] == [2.0, 3.0]


# -- the run log's record -----------------------------------------------------------------------------------
def test_a_decision_as_a_log_record_has_every_input():
    tr = TrendEstimate(1.0, 0.42, -0.01, 0.02, 0.003, 0.38, 0.46, True, False, settled=True)
    i = SupervisorInputs(trend=tr, actual_rpm=9.5, setpoint_rpm=10.0, mill_connected=True, mill_running=True,
                         mill_epoch=3, mill_refused=1, radial_factor=0.7, last_valid_mi_s=0.9, camera_ended=False,
                         twin_updated_s=0.5, twin_doubt="", mixed=True, mixing_time_s=42.0)
    d = Decision(1.0, Mode.AUTO, Action.SET_RPM, "move", "why", rpm=12.0, target_rpm=15.0, safe=False, inputs=i,
                 predictions={5.0: 0.3, 12.0: 0.6})
    assert d.as_dict() == {
        "t_s": 1.0, "mode": "auto", "action": "set_rpm", "kind": "move", "reason": "why", "rpm": 12.0,
        "target_rpm": 15.0, "safe": False, "level": 0.42, "rate": -0.01, "predictions": {"5.0": 0.3, "12.0": 0.6},
        "predicted_time_to_target_s": None, "predicted_energy_j": None, "prediction_t_s": None,
        "inputs": {
            "level": 0.42, "rate": -0.01, "level_sd": 0.02, "trend_settled": True, "actual_rpm": 9.5,
            "setpoint_rpm": 10.0, "mill_connected": True, "mill_running": True, "mill_epoch": 3, "mill_refused": 1,
            "camera_ended": False, "radial_factor": 0.7, "last_valid_mi_s": 0.9, "twin_updated_s": 0.5,
            "twin_doubt": "", "mixed": True, "mixing_time_s": 42.0,
        },
    }
    i2 = SupervisorInputs(mill_connected=False, camera_ended=True, twin_doubt="why not")
    rec = Decision(2.0, Mode.OFF, Action.NONE, "mode", "x", safe=True, inputs=i2).as_dict()
    assert rec["level"] is None and rec["rate"] is None and rec["predictions"] is None and rec["safe"] is True
    assert rec["inputs"] == {
        "level": None, "rate": None, "level_sd": None, "trend_settled": None, "actual_rpm": None,
        "setpoint_rpm": None, "mill_connected": False, "mill_running": None, "mill_epoch": 0, "mill_refused": 0,
        "camera_ended": True, "radial_factor": None, "last_valid_mi_s": None, "twin_updated_s": None,
        "twin_doubt": "why not", "mixed": False, "mixing_time_s": None,
    }
    rec = Decision(3.0, Mode.MANUAL, Action.STOP, "safe", "y").as_dict()
    assert rec["inputs"] is None and rec["level"] is None and rec["mode"] == "manual" and rec["action"] == "stop"


# -- the "time" / "energy" objectives and the endpoint ------------------------------------------------------
ROWS = {  # as in test_objective_supervisor.py: sooner when faster, the power grows as rpm^2
    5.0: RpmPrediction(5.0, 0.95, 300.0, 0.5 * 300.0, 0.5),
    25.0: RpmPrediction(25.0, 0.95, 60.0, 12.5 * 60.0, 12.5),
    45.0: RpmPrediction(45.0, 0.95, 70.0, 40.5 * 70.0, 40.5),
}


def objective_decision(objective: str, rows: dict, **kw) -> tuple[Supervisor, Decision | None, SupervisorInputs]:
    c = cfg(objective=objective, target_mi=0.9, min_rpm=5.0, **kw)
    sup = Supervisor(c, Mode.AUTO)
    i = inp(rpm=15.0)
    _, req = sup.step(0.0, i)
    assert req == PredictionRequest(0.0, c.candidates(15.0), 60.0, 0.9, RAMP, from_bed=objective != "plateau")
    preds = {r: v.plateau_mi for r, v in rows.items()}
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, preds, rows=rows))
    return sup, d, i


@pytest.mark.parametrize("objective", ["time", "energy"])
def test_an_objective_move_is_the_choice_of_control_objective_with_the_supervisors_limits(objective):
    sup, d, i = objective_decision(objective, ROWS)
    ch = choose(ROWS.values(), objective, 15.0, (5.0, 45.0), 0.9, min_rel_gain=0.1)
    assert ch.move and ch.rpm is not None
    assert d == Decision(0.0, Mode.AUTO, Action.SET_RPM, "move", f"{WHY}; {ch.reason}", rpm=ch.rpm,
                         target_rpm=ch.rpm, inputs=i, predictions={5.0: 0.95, 25.0: 0.95, 45.0: 0.95},
                         scores={r: -v for r, v in ch.values.items()}, chosen=ROWS[ch.rpm], prediction_t_s=0.0)
    assert sup.step(1.0, inp(rpm=15.0, t=1.0)) == (None, None)  # evaluated: the next one 30 s on


def test_an_objective_hold_uses_the_configured_relative_gain():
    rows = {15.0: RpmPrediction(15.0, 0.95, 100.0, 100.0 * 4.5, 4.5), 25.0: ROWS[25.0]}  # 40 % sooner at 25
    _, d, _ = objective_decision("time", rows)
    assert d is not None and d.kind == "move" and d.rpm == 25.0
    _, d, i = objective_decision("time", rows, objective_min_rel_gain=0.5)
    ch = choose(rows.values(), "time", 15.0, (5.0, 45.0), 0.9, min_rel_gain=0.5)
    assert not ch.move
    assert d == Decision(0.0, Mode.AUTO, Action.NONE, "hold", f"{WHY}; {ch.reason}", inputs=i,
                         predictions={15.0: 0.95, 25.0: 0.95}, scores={r: -v for r, v in ch.values.items()},
                         chosen=None if ch.rpm is None else rows[ch.rpm], prediction_t_s=0.0)


def test_an_objective_with_no_row_inside_the_limits_holds():
    rows = {60.0: RpmPrediction(60.0, 0.95, 10.0, 10.0, 1.0)}
    sup, d, i = objective_decision("time", rows)
    assert d == Decision(0.0, Mode.AUTO, Action.NONE, "hold",
                         f"{WHY}; objective time: no prediction inside 5..45 rpm", inputs=i,
                         predictions={60.0: 0.95}, scores={}, prediction_t_s=0.0)
    assert sup.step(1.0, inp(rpm=15.0, t=1.0)) == (None, None)


def test_the_endpoint_stop_names_the_mixing_time_and_the_level_it_has():
    def stop(**kw) -> Decision:
        sup = Supervisor(cfg(stop_at_endpoint=True), Mode.AUTO)
        sup.step(0.0, inp(trend=est(0.9)))
        d, _ = sup.step(1.0, inp(t=1.0, mixed=True, **kw))
        assert d is not None
        return d

    d = stop(trend=est(0.95), mixing_time_s=12.34)
    assert (d.action, d.kind, d.rpm) == (Action.STOP, "endpoint", None)
    assert d.reason == "batch mixed (mixing time 12.3 s), trend MI 0.950: stop at endpoint"
    assert stop(trend=est(0.95)).reason == "batch mixed, trend MI 0.950: stop at endpoint"
    assert stop(trend=None, mixing_time_s=3.0).reason == "batch mixed (mixing time 3.0 s): stop at endpoint"
    invalid = TrendEstimate(1.0, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False, False)
    assert stop(trend=invalid).reason == "batch mixed: stop at endpoint"


def test_the_endpoint_stop_ends_a_ramp_where_the_mill_is():
    sup = Supervisor(cfg(stop_at_endpoint=True, max_rate_rpm_per_s=1.0, prediction_wait_s=0.0), Mode.AUTO)
    sup.step(0.0, inp())
    d, _ = sup.step(0.0, inp())
    assert d is not None and (d.rpm, d.target_rpm) == (11.0, 15.0)  # ramping 10 -> 15
    d, _ = sup.step(0.5, inp(t=0.5, mixed=True))
    assert d is not None and d.kind == "endpoint" and sup.target_rpm == sup.commanded_rpm == 11.0
    assert sup.step(1.5, inp(t=1.5, mixed=True)) == (None, None)


# -- set_mode ----------------------------------------------------------------------------------------------------
def test_an_unknown_mode_is_refused_by_name():
    with pytest.raises(ControlError) as exc:
        Supervisor(cfg()).set_mode("sideways", 0.0)
    assert str(exc.value) == "unknown mode 'sideways' (use off, manual, auto)"


def test_after_set_mode_a_hold_recovers_by_itself():
    sup = Supervisor(cfg(recover_s=1.0), Mode.OFF)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_mode(Mode.MANUAL, 0.5)
    sup.step(1.0, inp(rpm=10.0, mill_connected=False))
    assert sup.safe
    sup.step(2.0, inp(rpm=10.0))
    d, _ = sup.step(3.0, inp(rpm=10.0))
    assert d is not None and d.kind == "recover" and not sup.safe


def test_set_mode_auto_on_a_segregated_bed_asks_for_predictions_at_the_next_step():
    sup = Supervisor(cfg(), Mode.OFF)
    sup.step(0.0, inp())
    sup.set_mode(Mode.AUTO, 0.5)
    assert sup.step(1.0, inp(t=1.0)) == (None, PredictionRequest(1.0, sup.config.candidates(10.0), 60.0, None, RAMP))


def test_an_operator_rpm_within_a_micro_rpm_of_the_target_is_the_same_rpm():
    sup = Supervisor(cfg(min_rpm=0.0), Mode.MANUAL)
    stopped = inp(rpm=0.0, mill_running=False)
    sup.step(0.0, stopped)
    assert sup.manual_rpm == 0.0 and sup.target_rpm == 0.0
    sup.set_manual_rpm(1e-6)
    assert sup.step(1.0, stopped) == (None, None)


def test_manual_ramp_steps_are_ramp_decisions():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(14.0)
    kinds = [(d.kind, d.rpm) for t in range(1, 5) if (d := sup.step(float(t), inp(rpm=10.0))[0]) is not None]
    assert kinds == [("manual", 12.0), ("ramp", 14.0)]


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


# -- moves, ramps and resyncs at their edges -----------------------------------------------------------------------
def test_a_move_with_nothing_known_of_the_mill_jumps_with_its_whole_record():
    sup = Supervisor(cfg(), Mode.AUTO)
    i = inp(rpm=None, mill_running=None)
    _, req = sup.step(0.0, i)
    assert req is not None and sup.commanded_rpm is None
    preds = {5.0: 0.3, 20.0: 0.6}
    d, _ = sup.step(0.0, i, PredictionResult(0.0, 60.0, preds))
    scores = {5.0: 0.3, 20.0: pytest.approx(0.6 - 0.002 * 15)}
    reason = f"segregation ({WHY}); twin predicts MI 0.600 at 20 rpm (score 0.570 vs 0.300 staying at 5)"
    assert d == Decision(0.0, Mode.AUTO, Action.SET_RPM, "move", reason, rpm=20.0, target_rpm=20.0, inputs=i,
                         predictions=preds, scores=scores)


def test_a_move_right_after_a_ramp_step_sends_nothing_yet():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0), Mode.AUTO)
    d, _ = sup.step(0.0, inp(rpm=46.0))  # ramp 46 -> 45 sent at t = 0
    assert d is not None and d.rpm == 45.0
    i = inp(rpm=45.0, t=0.5)
    _, req = sup.step(0.5, i)
    assert req is not None
    d, _ = sup.step(0.5, i, PredictionResult(0.5, 60.0, {45.0: 0.3, 30.0: 0.7}))
    assert d is not None and (d.kind, d.action, d.rpm, d.target_rpm) == ("move", Action.NONE, None, 30.0)


def test_a_resync_during_a_manual_ramp_sends_nothing_before_the_interval():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(20.0)
    sup.step(1.0, inp(rpm=10.0))  # 10 -> 12
    assert sup.step(1.5, inp(actual_rpm=11.0, setpoint_rpm=12.0, mill_epoch=1)) == (None, None)
    d, _ = sup.step(2.0, inp(actual_rpm=11.0, setpoint_rpm=12.0, mill_epoch=1))
    assert d is not None and (d.kind, d.rpm) == ("ramp", 13.0)  # on from the board's 11 rpm


def test_manual_adopts_a_board_at_exactly_the_upper_limit():
    sup = Supervisor(cfg(), Mode.MANUAL)
    sup.step(0.0, inp(rpm=45.0))
    assert sup.manual_rpm == 45.0


def test_a_hold_keeps_the_commanded_rpm_as_its_target():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(20.0)
    sup.step(1.0, inp(rpm=10.0))  # ramping 10 -> 11 -> ... 20
    sup.step(2.0, inp(rpm=11.0, mill_connected=False))
    assert sup.safe and sup.target_rpm == sup.commanded_rpm == 11.0


def test_a_ramp_step_is_due_at_exactly_the_interval_less_its_slack():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(12.0)
    sup.step(0.0, inp(rpm=10.0))  # 10 -> 11 at t = 0
    d, _ = sup.step(1.0 - 1e-9, inp(rpm=10.0))
    assert d is not None and d.rpm == 12.0


def test_the_rate_limit_is_per_second_whatever_the_ramp_interval():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0, ramp_interval_s=0.5), Mode.MANUAL)
    sup.step(0.0, inp(rpm=10.0))
    sup.set_manual_rpm(14.0)
    rpms = [d.rpm for t in (0.0, 0.5, 1.0, 1.5) if (d := sup.step(t, inp(rpm=10.0))[0]) is not None]
    assert rpms == [11.0, 12.0, 13.0, 14.0]  # 1 rpm per 0.5 s step


def test_a_ramp_a_hundredth_short_does_not_snap_to_its_target():
    sup = Supervisor(cfg(min_rpm=0.0, max_rate_rpm_per_s=0.01), Mode.MANUAL)
    stopped = inp(rpm=0.0, mill_running=False)
    sup.step(0.0, stopped)
    sup.set_manual_rpm(0.02)
    d, _ = sup.step(1.0, stopped)
    assert d is not None and d.rpm == 0.01


# -- a fresh supervisor and its config ------------------------------------------------------------------------------
def test_a_fresh_supervisor_knows_nothing_and_is_not_safe():
    sup = Supervisor()
    assert (sup.mode, sup.safe, sup.safe_reason, sup.commanded_rpm, sup.target_rpm, sup.manual_rpm) == (
        Mode.OFF, False, "", None, None, None)
    assert sup.events.maxlen == 10000 and len(sup.events) == 0
    d = sup.set_mode(Mode.MANUAL, 0.0)  # before any step: the record has no inputs
    assert d.inputs is None and d.as_dict()["inputs"] is None


def test_manual_from_the_start_with_nothing_known_of_the_mill_jumps_to_the_operators_rpm():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0), Mode.MANUAL)
    sup.set_manual_rpm(20.0)
    d, _ = sup.step(0.0, inp(rpm=None, mill_running=None))
    assert d is not None and (d.kind, d.action, d.rpm, d.target_rpm) == ("manual", Action.SET_RPM, 20.0, 20.0)


def test_a_refusal_reported_at_the_first_step_is_a_fault():
    sup = Supervisor(cfg(), Mode.MANUAL)
    d, _ = sup.step(0.0, inp(rpm=10.0, mill_refused=1))
    assert d is not None and d.reason == "safe hold at 10.0 rpm: the mill refused a command"


@pytest.mark.parametrize("bad", [1.5, -0.25, 1.0 + 1e-9, math.inf, math.nan])
def test_target_mi_outside_zero_to_one_is_refused_with_its_value(bad):
    with pytest.raises(ControlError) as exc:
        worked_config(target_mi=bad)
    assert str(exc.value) == f"target_mi must be in [0, 1], got {bad}"


def test_target_mi_at_both_ends_is_allowed():
    assert worked_config(target_mi=0.0).target_mi == 0.0
    assert worked_config(objective="time", target_mi=1.0).target_mi == 1.0

"""The supervisor's plateau choice: which rpm AUTO moves to, or why it holds, with its numbers.

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records with values worked out by hand from the rules in control/supervisor.py's docstring
(issue 27's mutation tests; the helpers are tests/control/supervisor_steps.py).
"""

from __future__ import annotations

import math

import pytest

from control.decision import Action, Decision, Mode, PredictionRequest, PredictionResult
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_steps import RAMP, WHY, answer, cfg, inp
from tests.control.supervisor_values import worked_config


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

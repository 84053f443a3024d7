"""AUTO's objective (control/objective.py) rule by rule: the limits' edges, which row counts as
reaching the target, each tie-break, the stay/move rule at its edges, and the reason a run's log
shows (pure, hand-made prediction rows)."""

from __future__ import annotations

import math

import pytest

from control.errors import ControlError
from control.objective import Choice, RpmPrediction, check_objective, choose, stale_start

LIMITS = (5.0, 45.0)


def row(rpm: float, t: float | None, e: float | None = None, w: float | None = None, mi: float = 0.95) -> RpmPrediction:
    return RpmPrediction(rpm, mi, t, e, w)


def test_value_is_minus_the_plateau_for_plateau_and_inf_when_unknown() -> None:
    assert RpmPrediction(10.0, 0.9).value("plateau") == -0.9
    assert RpmPrediction(10.0, math.nan).value("plateau") == math.inf
    assert row(10.0, 30.0, 40.0).value("time") == 30.0 and row(10.0, 30.0, 40.0).value("energy") == 40.0
    assert row(10.0, -1.0).value("time") == math.inf and row(10.0, None).value("time") == math.inf


def test_the_errors_name_the_objectives() -> None:
    with pytest.raises(ControlError) as e:
        check_objective("cheapest")
    assert str(e.value) == "objective must be one of plateau, time, energy, got 'cheapest'"
    with pytest.raises(ControlError, match=r"^objective plateau is the supervisor's own scoring \(control\.supervisor\)"
                                           r", not choose\(\)$"):
        choose([row(10.0, 1.0)], "plateau", 10.0, LIMITS)


def test_rows_count_inside_the_limits_up_to_a_float_rounding_and_not_half_an_rpm_beyond() -> None:
    lo, hi = LIMITS
    for rpm in (lo, hi, lo - 1e-9, hi + 1e-9):  # the edges, and a limit computed elsewhere off by a rounding
        assert choose([row(rpm, 10.0)], "time", 20.0, LIMITS).rpm == rpm, rpm
    for rpm in (lo - 0.5, hi + 0.5):
        assert choose([row(rpm, 10.0)], "time", 20.0, LIMITS) == Choice(
            "time", None, False, {}, "objective time: no prediction inside 5..45 rpm")


def test_a_plateau_exactly_at_the_target_reaches_it() -> None:
    ch = choose([row(10.0, 60.0, mi=0.9), row(20.0, None, mi=0.95)], "time", 20.0, LIMITS, 0.9)
    assert ch.rpm == 10.0 and ch.move is True


def test_nobody_reaching_the_target_picks_the_highest_plateau_and_of_equal_ones_the_nearest() -> None:
    rows = [row(10.0, None, mi=0.8), row(30.0, None, mi=0.8), row(20.0, None, mi=0.7)]
    ch = choose(rows, "energy", 28.0, LIMITS, 0.9)
    assert (ch.objective, ch.rpm, ch.move) == ("energy", 30.0, True)
    assert ch.values == {10.0: math.inf, 30.0: math.inf, 20.0: math.inf}
    assert ch.reason == ("objective energy: no rpm reaches the target to MI 0.9 within the study; highest plateau"
                         " MI 0.800 at 30 rpm")
    # already there: no move; half an rpm away: a move
    assert choose(rows, "energy", 30.0, LIMITS, 0.9).move is False
    assert choose(rows, "energy", 29.5, LIMITS, 0.9).move is True
    assert "reaches the target within the study" in choose(rows, "energy", 30.0, LIMITS).reason  # no target named


def test_energy_ties_go_to_the_faster_row_and_full_ties_to_the_nearest_rpm() -> None:
    rows = [row(10.0, 50.0, 100.0), row(20.0, 30.0, 101.0)]  # 1 % apart: a tie on energy, time decides
    assert choose(rows, "energy", 40.0, LIMITS).rpm == 20.0
    same = [row(10.0, 30.0, 100.0, 2.0), row(30.0, 30.0, 100.0, 2.0)]  # equal in everything but the rpm
    assert choose(same, "time", 28.0, LIMITS).rpm == 30.0
    assert choose(same, "time", 12.0, LIMITS).rpm == 10.0


def test_staying_compares_with_the_prediction_nearest_the_current_rpm_within_half_an_rpm() -> None:
    rows = [row(10.0, 100.0), row(10.4, 60.0), row(20.0, 57.0)]
    ch = choose(rows, "time", 10.3, LIMITS)  # 10.4 rpm's 60 s is the current one: 57 s is a 5 % gain
    assert (ch.objective, ch.rpm, ch.move) == ("time", 20.0, False)
    assert ch.values == {10.0: 100.0, 10.4: 60.0, 20.0: 57.0}
    assert ch.reason.startswith("objective time: best 20 rpm 57 s vs 60 s staying at 10.3 rpm (gain < 10%) -> stay"
                                " (10 rpm 100 s, 10.4 rpm 60 s, 20 rpm 57 s); ")
    # exactly half an rpm away still counts as the current rpm's prediction ...
    assert choose([row(10.0, 60.0), row(20.0, 57.0)], "time", 10.5, LIMITS).move is False
    # ... one rpm away does not: the current rpm has no prediction, so the best is a move
    ch = choose([row(10.0, 60.0), row(20.0, 57.0)], "time", 11.0, LIMITS, 0.9)
    assert (ch.objective, ch.rpm, ch.move) == ("time", 20.0, True)
    assert ch.reason.startswith("objective time to MI 0.9: 20 rpm 57 s vs never at 11 rpm (10 rpm 60 s, 20 rpm 57 s);")


def test_a_gain_of_exactly_min_rel_gain_moves_and_a_best_at_the_current_rpm_never_does() -> None:
    rows = [row(10.0, 100.0), row(20.0, 50.0)]
    ch = choose(rows, "time", 10.0, LIMITS, min_rel_gain=0.5)
    assert ch.move is True  # 50 % better: "at least"
    assert ch.reason.startswith("objective time: 20 rpm 50 s vs 100 s at 10 rpm (10 rpm 100 s, 20 rpm 50 s); ")
    assert choose(rows, "time", 10.0, LIMITS, min_rel_gain=0.51).move is False
    at_once = [row(10.0, 0.0, 0.0, 1.0), row(20.0, 40.0, 9.0, 1.0)]  # staying costs 0 s: no move, not a zero gain
    assert choose(at_once, "time", 10.0, LIMITS).move is False
    near = [row(10.0, 100.0), row(10.5, 50.0)]  # the better prediction half an rpm up is a move
    assert choose(near, "time", 10.0, LIMITS).move is True


def test_the_rpm_tolerances_are_a_millionth_of_an_rpm() -> None:
    """Where a row reaches the target, a best 1e-6 rpm from the current rpm is another rpm (a
    move when it gains enough, the other objective's pick named apart); where none does, a
    highest plateau up to 1e-6 rpm away is the current rpm (no move)."""
    rows = [row(0.0, 100.0, 1.0), row(1e-6, 50.0, 2.0)]
    ch = choose(rows, "time", 0.0, (0.0, 45.0))
    assert (ch.rpm, ch.move) == (1e-6, True)
    assert "energy would pick 0 rpm" in ch.reason
    nobody = [row(0.0, None, mi=0.5), row(1e-6, None, mi=0.6)]
    assert choose(nobody, "time", 0.0, (0.0, 45.0), 0.9).move is False


def test_the_listing_shows_the_power_only_where_it_is_known() -> None:
    ch = choose([row(10.0, 60.0, 120.0, 2.0), row(20.0, 30.0)], "time", 10.0, LIMITS)
    assert "(10 rpm 60 s at 2.00 W, 20 rpm 30 s);" in ch.reason


def test_the_other_objective_is_compared_only_where_it_has_values() -> None:
    rows = [row(10.0, None, 100.0), row(20.0, None, 50.0)]  # energies without times
    ch = choose(rows, "energy", 10.0, LIMITS)
    assert ch.rpm == 20.0 and ch.reason.endswith("; time: no finite values to compare")
    # of two equal alternatives the one nearer the current rpm is named
    rows = [row(10.0, 60.0, 10.0), row(30.0, 60.0, 10.0), row(20.0, 61.0, 5.0)]
    assert choose(rows, "energy", 28.0, LIMITS).reason.endswith(
        "; time would pick 30 rpm (60 s vs 61 s at 20 rpm; 10.0 J there)")
    # half an rpm from the pick is another rpm
    rows = [row(20.0, 61.0, 5.0), row(20.5, 60.0, 10.0)]
    assert "time would pick 20.5 rpm" in choose(rows, "energy", 5.0, LIMITS).reason


def test_a_trend_exactly_at_the_target_is_not_below_it() -> None:
    at_once = [RpmPrediction(25.0, 0.91, 0.0)]
    assert stale_start(at_once, 0.9, 0.9) == ""
    assert stale_start(at_once, 0.8999, 0.9) != ""

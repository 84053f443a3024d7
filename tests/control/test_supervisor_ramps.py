"""The supervisor's ramps at the rate limit and its resync to the board, down to their edges.

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records with values worked out by hand from the rules in control/supervisor.py's docstring
(issue 27's mutation tests; the helpers are tests/control/supervisor_steps.py).
"""

from __future__ import annotations

import math

import pytest

from control.decision import Action, Decision, Mode, PredictionResult
from control.supervisor import Supervisor
from tests.control.supervisor_steps import WHY, cfg, est, inp


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

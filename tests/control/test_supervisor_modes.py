"""The supervisor's "time"/"energy" objectives and endpoint, set_mode, a fresh supervisor and its config.

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records with values worked out by hand from the rules in control/supervisor.py's docstring
(issue 27's mutation tests; the helpers are tests/control/supervisor_steps.py).
"""

from __future__ import annotations

import math

import pytest

from control.decision import Action, Decision, Mode, PredictionRequest, PredictionResult, SupervisorInputs
from control.errors import ControlError
from control.objective import RpmPrediction, choose
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_steps import RAMP, WHY, cfg, est, inp
from tests.control.supervisor_values import worked_config

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

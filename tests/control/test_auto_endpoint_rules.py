"""AUTO's records after an endpoint stop and around a stale "time" study, and the twin's ramp
when the mill's is unlimited (control/supervisor.py; the survivors of the issue-41 mutation
run): what each logged decision carries, not only its reason."""

from __future__ import annotations

from dataclasses import replace

from control.decision import Action, Mode, PredictionResult, SupervisorInputs
from control.objective import RpmPrediction
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config


def est(t: float, level: float) -> TrendEstimate:
    return TrendEstimate(t, level, 0.0, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=True)


def inputs(t: float, level: float, **kw: object) -> SupervisorInputs:
    base: dict = dict(trend=est(t, level), actual_rpm=15.0, setpoint_rpm=15.0, mill_running=True,
                      last_valid_mi_s=t, twin_updated_s=t)
    base.update(kw)
    return SupervisorInputs(**base)


def test_two_faults_after_the_endpoint_stop_are_one_safe_decision_naming_both_at_its_time() -> None:
    sup = Supervisor(worked_config(stop_at_endpoint=True, vision_timeout_s=2.0), mode=Mode.AUTO)
    d, _ = sup.step(10.0, inputs(10.0, 0.95, mixed=True))
    assert d is not None and d.action is Action.STOP and d.kind == "endpoint"
    # the link goes down and the camera's last valid MI was at 10 s: both at 13 s
    d, _ = sup.step(13.0, inputs(13.0, 0.95, mixed=True, mill_connected=False, last_valid_mi_s=10.0))
    assert d is not None and (d.t_s, d.kind, d.action, d.safe) == (13.0, "safe", Action.NONE, True)
    assert d.reason == "safe (stopped at the endpoint): mill link lost; no valid MI for 3.0 s"
    assert sup.safe_reason == "mill link lost; no valid MI for 3.0 s"


ROWS = {5.0: RpmPrediction(5.0, 0.95, 300.0, 150.0, 0.5), 25.0: RpmPrediction(25.0, 0.95, 0.0, 0.0, 12.5),
        45.0: RpmPrediction(45.0, 0.95, 70.0, 2835.0, 40.5)}  # 25 rpm: the twin's bed at the target at once


def test_a_stale_study_is_asked_again_for_the_same_rpms_and_the_hold_carries_its_predictions() -> None:
    sup = Supervisor(worked_config(objective="time", target_mi=0.9, min_rpm=5.0, max_rpm=45.0, critical_rpm=None,
                                   max_critical_frac=1.0, max_rate_rpm_per_s=3.0, detect_dwell_s=0.0),
                     mode=Mode.AUTO)
    d, first = sup.step(1.0, inputs(1.0, 0.80))
    assert d is None and first is not None and 15.0 in first.rpms  # the current rpm is a candidate
    preds = PredictionResult(first.t_s, first.horizon_s, {r: v.plateau_mi for r, v in ROWS.items()}, rows=ROWS)
    hold, again = sup.step(2.0, inputs(2.0, 0.80), preds)
    assert hold is not None and hold.kind == "hold" and "asking the twin again" in hold.reason
    assert (hold.t_s, hold.action, hold.predictions) == (2.0, Action.NONE, preds.predictions)
    assert again is not None and again == replace(first, t_s=2.0)  # the same candidates, the current rpm too


def test_a_mill_without_a_rate_limit_asks_the_twin_for_no_ramp() -> None:
    """``max_rate_rpm_per_s`` 0: the setpoint jumps, so the twin jumps too (``ramp_rpm_s`` None, not 0)."""
    sup = Supervisor(worked_config(max_rate_rpm_per_s=0.0, detect_dwell_s=0.0), mode=Mode.AUTO)
    _, req = sup.step(0.0, inputs(0.0, 0.3))
    assert req is not None and req.ramp_rpm_s is None
    sup = Supervisor(worked_config(max_rate_rpm_per_s=2.0, detect_dwell_s=0.0), mode=Mode.AUTO)
    _, req = sup.step(0.0, inputs(0.0, 0.3))
    assert req is not None and req.ramp_rpm_s == 2.0

"""``stop_at_endpoint``: AUTO stops the mill once the batch is mixed (a logged decision);
OFF and MANUAL never act on the endpoint (issue 24)."""

from __future__ import annotations

from control.decision import Action, Mode, SupervisorInputs
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config


def est(t: float, level: float) -> TrendEstimate:
    return TrendEstimate(t, level, 0.0, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=True)


def inputs(t: float, mixed: bool, level: float = 0.95) -> SupervisorInputs:
    return SupervisorInputs(trend=est(t, level), actual_rpm=20.0, setpoint_rpm=20.0, mill_running=True,
                            last_valid_mi_s=t, twin_updated_s=t, mixed=mixed, mixing_time_s=12.5 if mixed else None)


def run(sup: Supervisor, t0: float, t1: float, mixed_from: float) -> list:
    out = []
    t = t0
    while t < t1:
        d, _ = sup.step(t, inputs(t, mixed=t >= mixed_from))
        if d is not None:
            out.append(d)
        t += 0.5
    return out


def test_auto_stops_the_mill_once_at_the_endpoint_with_its_reason():
    sup = Supervisor(worked_config(stop_at_endpoint=True), mode=Mode.AUTO)
    ds = run(sup, 0.0, 60.0, mixed_from=20.0)
    stops = [d for d in ds if d.action is Action.STOP]
    assert len(stops) == 1
    d = stops[0]
    assert d.kind == "endpoint" and d.t_s == 20.0 and d.mode is Mode.AUTO
    assert "mixing time 12.5 s" in d.reason and "stop at endpoint" in d.reason and "0.950" in d.reason
    rec = d.as_dict()
    assert rec["inputs"]["mixed"] is True and rec["inputs"]["mixing_time_s"] == 12.5
    assert not [d for d in ds if d.t_s > 20.0]  # hands off afterwards: no rpm command on a stopped mill


def test_auto_after_the_endpoint_stop_rearms_on_a_mode_change():
    sup = Supervisor(worked_config(stop_at_endpoint=True), mode=Mode.AUTO)
    run(sup, 0.0, 30.0, mixed_from=5.0)
    sup.set_mode("auto", 30.0)
    ds = run(sup, 30.0, 40.0, mixed_from=35.0)
    assert [d.t_s for d in ds if d.action is Action.STOP] == [35.0]


def test_auto_without_stop_at_endpoint_does_not_stop():
    sup = Supervisor(worked_config(), mode=Mode.AUTO)
    assert not [d for d in run(sup, 0.0, 60.0, mixed_from=10.0) if d.action is Action.STOP]


def test_manual_only_reports_the_endpoint():
    sup = Supervisor(worked_config(stop_at_endpoint=True), mode=Mode.MANUAL)
    sup.set_manual_rpm(20.0)
    ds = run(sup, 0.0, 60.0, mixed_from=10.0)
    assert not [d for d in ds if d.action is Action.STOP or d.kind == "endpoint"]


def test_off_only_reports_the_endpoint():
    sup = Supervisor(worked_config(stop_at_endpoint=True), mode=Mode.OFF)
    assert run(sup, 0.0, 60.0, mixed_from=10.0) == []


def test_after_the_endpoint_stop_auto_still_logs_its_safe_state():
    """After the endpoint stop AUTO returned before its fault checks: a mill link lost, vision
    lost or a stale twin afterwards gave no safe-state decision (nothing logged, ``safe`` False).
    Now the first fault is one ``safe`` decision that sends nothing (the mill is stopped)."""
    sup = Supervisor(worked_config(stop_at_endpoint=True), mode=Mode.AUTO)
    ds = run(sup, 0.0, 30.0, mixed_from=20.0)
    assert [d.kind for d in ds if d.t_s >= 20.0] == ["endpoint"] and not sup.safe
    out = []
    for k in range(20):  # the link goes down after the stop
        t = 30.0 + 0.5 * k
        lost = SupervisorInputs(trend=est(t, 0.95), actual_rpm=None, setpoint_rpm=None, mill_running=False,
                                mill_connected=False, last_valid_mi_s=t, twin_updated_s=t, mixed=True,
                                mixing_time_s=12.5)
        d, _ = sup.step(t, lost)
        if d is not None:
            out.append(d)
    assert len(out) == 1 and out[0].kind == "safe" and out[0].action is Action.NONE
    assert "mill link lost" in out[0].reason and sup.safe

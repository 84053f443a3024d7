"""An AUTO supervisor's steps for the supervisor's decision-by-decision tests (issue 27's mutation
tests of control/supervisor.py, test_supervisor_{choice,due,ramps,safe,modes}.py): a trend estimate,
step inputs and settings on the worked values (supervisor_values.py), a supervisor that has just asked
for predictions, and one that got them."""

from __future__ import annotations

from control.decision import Decision, Mode, PredictionRequest, PredictionResult, SupervisorInputs
from control.supervisor import Supervisor
from control.supervisor_config import SupervisorConfig
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

"""Supervisor logic on scripted trend sequences (no I/O)."""

from __future__ import annotations

import json
import math
import threading

import pytest

from control.errors import ControlError
from control.supervisor import (
    Action,
    AsyncPredictor,
    Mode,
    PredictionResult,
    SafeAction,
    Supervisor,
    SupervisorConfig,
    SupervisorInputs,
)
from control.trend import TrendEstimate

DT = 0.5


def est(t: float, level: float, rate: float = 0.0) -> TrendEstimate:
    return TrendEstimate(t, level, rate, 0.01, 0.001, level - 0.02, level + 0.02, True, False)


def run(sup: Supervisor, t0: float, t1: float, level, rate=0.0, radial=None, **inp):
    """Step the supervisor from t0 to t1 on a scripted trend; return its decisions."""
    out = []
    t = t0
    while t < t1 - 1e-9:
        lv = level(t) if callable(level) else level
        rt = rate(t) if callable(rate) else rate
        kw = dict(setpoint_rpm=5.0, actual_rpm=5.0, last_valid_mi_s=t, twin_updated_s=t)
        kw.update(inp)
        d = sup.step(t, SupervisorInputs(trend=est(t, lv, rt), radial_factor=radial, **kw))
        if d is not None:
            out.append(d)
        t = round(t + DT, 6)
    return out


def cfg(**kw) -> SupervisorConfig:
    base = dict(detect_dwell_s=5.0, clear_dwell_s=5.0, min_change_interval_s=30.0, max_rate_rpm_per_s=100.0)
    base.update(kw)
    return SupervisorConfig(**base)


def test_limits_include_critical_speed():
    c = SupervisorConfig(min_rpm=2, max_rpm=100, drum_diameter_m=0.3, max_critical_frac=0.5)
    assert c.critical_rpm == pytest.approx(42.3 / math.sqrt(0.3))
    assert c.rpm_limits == (2, pytest.approx(0.5 * 42.3 / math.sqrt(0.3)))
    assert c.clamp(500) == c.rpm_limits[1] and c.clamp(0) == 2
    with pytest.raises(ControlError):
        SupervisorConfig(seg_level=0.6, clear_level=0.5)


def test_no_action_when_well_mixed():
    sup = Supervisor(cfg(), predictor=lambda r, h: {x: 0.9 for x in r}, mode=Mode.AUTO)
    ds = run(sup, 0, 300, level=lambda t: 0.8 + 0.05 * math.sin(t), radial=0.9)
    assert ds == [] and not sup.detector.segregated


def test_short_bad_stretch_does_not_trigger():
    sup = Supervisor(cfg(), mode=Mode.AUTO)
    ds = run(sup, 0, 120, level=lambda t: 0.4 if 50 <= t < 54 else 0.8)  # 4 s < 5 s dwell
    assert ds == []


def test_one_move_with_predictions_then_dwell():
    calls = []

    def predictor(rpms, horizon_s):
        calls.append((tuple(rpms), horizon_s))
        return {r: 0.5 + 0.01 * min(r, 20) for r in rpms}  # best around 20 rpm

    sup = Supervisor(cfg(move_penalty_per_rpm=0.001), predictor=predictor, mode=Mode.AUTO)
    ds = run(sup, 0, 40, level=lambda t: 0.8 if t < 20 else 0.4)
    moves = [d for d in ds if d.kind == "move"]
    assert len(moves) == 1 and len(ds) == 1
    m = moves[0]
    assert m.t_s == pytest.approx(25.0)  # bad from 20 s, dwell 5 s
    assert m.action is Action.SET_RPM and m.rpm == m.target_rpm
    assert "twin predicts" in m.reason and m.inputs.trend.level == 0.4
    assert m.rpm == max(m.scores, key=m.scores.get)  # best score on the candidate grid
    # the penalty matters: the best raw prediction (flat above 20 rpm) is not the furthest move
    assert 20 <= m.rpm < sup.config.rpm_limits[1]
    assert calls and calls[0][1] == sup.config.horizon_s
    # still segregated: nothing more before the minimum dwell between changes
    ds2 = run(sup, 40, 55, level=0.4)
    assert ds2 == []
    ds3 = run(sup, 55, 60, level=0.4)
    assert len(ds3) == 1 and ds3[0].t_s == pytest.approx(55.0)  # next evaluation: exactly at +30 s
    assert ds3[0].kind == "hold"  # already at the best rpm


def test_falling_rate_and_low_radial_factor_also_detect():
    sup = Supervisor(cfg(), mode=Mode.AUTO)
    ds = run(sup, 0, 20, level=0.8, rate=lambda t: -0.05 if t >= 5 else 0.0)
    assert [d.kind for d in ds] == ["move"] and "falling" in ds[0].reason
    sup = Supervisor(cfg(), mode=Mode.AUTO)
    ds = run(sup, 0, 20, level=0.8, radial=0.3)
    assert [d.kind for d in ds] == ["move"] and "radial" in ds[0].reason


def test_fallback_rule_without_predictions():
    sup = Supervisor(cfg(fallback_step_rpm=5.0, max_rpm=12.0), mode=Mode.AUTO)
    ds = run(sup, 0, 10, level=0.3)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 10.0)]
    assert "fallback" in ds[0].reason
    ds = run(sup, 40, 45, level=0.3, setpoint_rpm=10.0)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 12.0)]  # clipped to the limit
    ds = run(sup, 75, 80, level=0.3, setpoint_rpm=12.0)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 7.0)]  # at the limit: step down


def test_hysteresis_clears_only_above_clear_level():
    sup = Supervisor(cfg(), mode=Mode.AUTO)
    run(sup, 0, 10, level=0.4)
    assert sup.detector.segregated
    run(sup, 10, 30, level=0.55)  # above seg_level, below clear_level: still segregated
    assert sup.detector.segregated
    run(sup, 30, 36, level=0.7)
    assert not sup.detector.segregated


def test_rate_limit_ramps_the_setpoint():
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0, ramp_interval_s=1.0), predictor=lambda r, h: {x: x / 100 for x in r}, mode=Mode.AUTO)
    ds = run(sup, 0, 40, level=0.3)
    assert ds[0].kind == "move" and ds[0].rpm == 7.0 and ds[0].target_rpm == sup.config.rpm_limits[1]
    ramps = [d for d in ds if d.kind == "ramp"]
    rpms = [ds[0].rpm] + [d.rpm for d in ramps]
    times = [ds[0].t_s] + [d.t_s for d in ramps]
    assert all(b - a <= 2.0 + 1e-9 for a, b in zip(rpms, rpms[1:]))
    assert all(tb - ta >= 1.0 - 1e-9 for ta, tb in zip(times, times[1:]))
    assert rpms[-1] == sup.config.rpm_limits[1]


def test_async_predictions_are_used_without_blocking():
    gate = threading.Event()

    def slow(rpms, horizon_s):
        gate.wait(5)
        return {r: (0.95 if r == 15.0 else 0.5) for r in list(rpms) + [15.0]}

    ap = AsyncPredictor(slow)
    sup = Supervisor(cfg(prediction_wait_s=20.0), predictor=ap, mode=Mode.AUTO)
    ds = run(sup, 0, 10, level=0.3)
    assert ds == [] and ap.busy  # decision due, predictor running, step did not block
    gate.set()
    ap.join(2)
    ds = run(sup, 10, 11, level=0.3)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 15.0)]


def test_async_predictor_timeout_falls_back():
    never = threading.Event()
    ap = AsyncPredictor(lambda r, h: never.wait(3) or {})
    sup = Supervisor(cfg(prediction_wait_s=4.0), predictor=ap, mode=Mode.AUTO)
    ds = run(sup, 0, 12, level=0.3)
    assert [d.kind for d in ds] == ["move"] and ds[0].t_s == pytest.approx(9.0) and "fallback" in ds[0].reason
    never.set()


def test_offered_predictions_and_staleness():
    sup = Supervisor(cfg(prediction_max_age_s=10.0), mode=Mode.AUTO)
    run(sup, 0, 3, level=0.3)
    req = sup.prediction_request(3.0)
    assert req is not None and req.horizon_s == sup.config.horizon_s and 5.0 in req.rpms
    sup.offer_predictions(PredictionResult(3.0, req.horizon_s, {5.0: 0.3, 25.0: 0.9}))
    assert sup.prediction_request(3.5) is None
    ds = run(sup, 3, 6, level=0.3)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 25.0)]
    # stale predictions are ignored -> fallback
    sup2 = Supervisor(cfg(prediction_max_age_s=1.0), mode=Mode.AUTO)
    sup2.offer_predictions(PredictionResult(0.0, 60.0, {25.0: 0.9}))
    ds = run(sup2, 0, 6, level=0.3)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 10.0)]


@pytest.mark.parametrize(
    "fault, inputs, reason",
    [
        ("link", dict(mill_connected=False), "mill link lost"),
        ("vision", dict(last_valid_mi_s=0.0), "no valid MI"),
        ("twin", dict(twin_updated_s=0.0), "twin stale"),
    ],
)
@pytest.mark.parametrize("action", list(SafeAction))
def test_safe_state_on_each_fault(fault, inputs, reason, action):
    c = cfg(safe_action=action, safe_rpm=3.0, vision_timeout_s=5.0, twin_timeout_s=10.0, recover_s=5.0,
            max_rate_rpm_per_s=1.0, ramp_interval_s=1.0)
    sup = Supervisor(c, mode=Mode.AUTO)
    assert run(sup, 0, 20, level=0.8) == []
    ds = run(sup, 20, 40, level=0.8, **{k: (20.0 if k != "mill_connected" else v) for k, v in inputs.items()})
    safe = [d for d in ds if d.kind == "safe"]
    assert safe and safe[0].safe and reason in safe[0].reason and sup.safe
    first = safe[0]
    delay = {"link": 0.0, "vision": 5.0, "twin": 10.0}[fault]
    assert first.t_s == pytest.approx(20.0 + delay + (DT if fault != "link" else 0.0))
    if action is SafeAction.STOP:
        assert first.action is Action.STOP and len(ds) == 1
    elif action is SafeAction.HOLD:
        assert first.action is Action.NONE and len(ds) == 1
    else:
        assert first.target_rpm == 3.0
        rpms = [d.rpm for d in safe if d.rpm is not None]
        assert rpms[0] == 4.0 and rpms[-1] == 3.0  # ramped at <= 1 rpm/s
    # faults clear: HOLD/RAMP recover after recover_s, STOP stays latched
    ds = run(sup, 40, 60, level=0.8)
    kinds = [d.kind for d in ds]
    if action is SafeAction.STOP:
        assert kinds == [] and sup.safe
        d = sup.set_mode(Mode.AUTO, 60.0)
        assert d.kind == "mode" and not sup.safe
    else:
        assert kinds == ["recover"] and not sup.safe and ds[0].t_s == pytest.approx(45.0)


def test_manual_follows_operator_and_ignores_vision():
    sup = Supervisor(cfg(max_rate_rpm_per_s=100.0), mode=Mode.MANUAL)
    assert sup.set_manual_rpm(500) == sup.config.rpm_limits[1]
    sup.set_manual_rpm(12.0)
    ds = run(sup, 0, 30, level=0.2, last_valid_mi_s=0.0)  # no vision, segregated: manual does not care
    assert [(d.kind, d.rpm) for d in ds] == [("manual", 12.0)]
    ds = run(sup, 30, 32, level=0.2, mill_connected=False)
    assert [d.kind for d in ds] == ["safe"]


def test_off_does_nothing_and_modes_are_logged():
    sup = Supervisor(cfg())
    assert run(sup, 0, 30, level=0.1, mill_connected=False) == []
    d = sup.set_mode("auto", 30.0)
    assert d.mode is Mode.AUTO and "off -> auto" in d.reason and sup.events[-1] is d
    with pytest.raises(ControlError):
        sup.set_mode("turbo", 31.0)
    assert set(d.as_dict()) >= {"t_s", "mode", "action", "reason", "rpm", "inputs"}
    ds = run(sup, 31, 40, level=0.2, radial=0.4)
    rec = json.loads(json.dumps(ds[0].as_dict()))  # run-log ready
    assert rec["kind"] == "move" and rec["inputs"]["level"] == 0.2 and rec["inputs"]["radial_factor"] == 0.4


def test_manual_retargets_a_ramp_in_progress():
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0, ramp_interval_s=1.0), mode=Mode.MANUAL)
    sup.set_manual_rpm(15.0)
    ds = run(sup, 0, 3, level=0.8)  # 5 -> 6 -> 7 -> 8
    assert [d.rpm for d in ds] == [6.0, 7.0, 8.0] and ds[0].kind == "manual"
    sup.set_manual_rpm(6.0)  # operator changes their mind mid-ramp
    ds = run(sup, 3, 6, level=0.8)
    assert ds[0].kind == "manual" and ds[0].target_rpm == 6.0
    assert [d.rpm for d in ds if d.rpm is not None] == [7.0, 6.0]  # straight back, still rate-limited

"""Supervisor logic on scripted trend sequences (no I/O)."""

from __future__ import annotations

import itertools
import json
import math
from typing import Any

import pytest

from control.decision import Action, Mode, PredictionRequest, PredictionResult, SupervisorInputs
from control.errors import ControlError
from control.supervisor import Supervisor
from control.supervisor_config import SafeAction, SupervisorConfig
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config

DT = 0.5


def est(t: float, level: float, rate: float = 0.0) -> TrendEstimate:
    return TrendEstimate(t, level, rate, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=True)


def run(sup: Supervisor, t0: float, t1: float, level, rate=0.0, radial=None, predictor=None, requests=None, **inp):
    """Step the supervisor from t0 to t1 on a scripted trend; return its decisions.

    ``predictor(rpms, horizon_s)``: serves each prediction request at once (the step is
    repeated at the same time with the result); ``requests``: a list the requests go to.
    """
    out = []
    t = t0
    while t < t1 - 1e-9:
        lv = level(t) if callable(level) else level
        rt = rate(t) if callable(rate) else rate
        kw: dict[str, Any] = dict(setpoint_rpm=5.0, actual_rpm=5.0, last_valid_mi_s=t, twin_updated_s=t)
        kw.update(inp)
        inputs = SupervisorInputs(trend=est(t, lv, rt), radial_factor=radial, **kw)
        d, req = sup.step(t, inputs)
        if req is not None:
            if requests is not None:
                requests.append(req)
            if predictor is not None:
                res = PredictionResult(req.t_s, req.horizon_s, dict(predictor(req.rpms, req.horizon_s)))
                d2, req2 = sup.step(t, inputs, res)
                assert req2 is None  # answered: nothing more wanted
                d = d2 if d is None else d
        if d is not None:
            out.append(d)
        t = round(t + DT, 6)
    return out


def cfg(**kw) -> SupervisorConfig:
    base: dict[str, Any] = dict(
        detect_dwell_s=5.0, clear_dwell_s=5.0, min_change_interval_s=30.0, max_rate_rpm_per_s=100.0,
        prediction_wait_s=0.0,  # no answer to a request: fall back at once
    )
    base.update(kw)
    return worked_config(**base)


def test_limits_include_the_critical_speed_it_is_given():
    c = worked_config(min_rpm=2, max_rpm=100, critical_rpm=80.0, max_critical_frac=0.5)
    assert c.limits.rpm_range == (2, 40.0)
    assert c.limits.clamp(500) == 40.0 and c.limits.clamp(0) == 2
    assert worked_config(min_rpm=2, max_rpm=30).limits.rpm_range == (2, 30)  # no drum given: max_rpm only
    for bad in (dict(seg_level=0.6, clear_level=0.5), dict(critical_rpm=0.0), dict(critical_rpm=math.nan),
                dict(vision_timeout_s=math.inf)):
        with pytest.raises(ControlError):
            worked_config(**bad)


def test_a_runs_supervisor_caps_rpm_at_the_share_of_its_drums_critical_speed():
    """One critical-speed function (``sim.recipe.DrumSpec.critical_rpm``): the run's supervisor
    (``twin.run.settings.supervisor_config``, the one path from a drum to control's limits) caps
    MANUAL and AUTO at ``max_critical_frac`` of the critical speed of the drum it is given, for a
    small, the paper's and a large drum. A supervisor that kept the paper's drum's cap, or a
    second formula on the way (another constant, another rounding), fails here."""
    from sim.recipe import DrumSpec
    from twin.run.settings import Seams, supervisor_config

    caps = []
    for d_m in (0.1, 0.3, 1.0):
        crit = DrumSpec(diameter_m=d_m).critical_rpm
        cfg = supervisor_config(Seams(limits={"max_rpm": 500.0}), crit)
        cap = cfg.limits.max_critical_frac * crit
        assert cfg.limits.rpm_range == (cfg.limits.min_rpm, cap), d_m
        assert Supervisor(cfg).set_manual_rpm(1000.0) == cap
        caps.append(cap)
    assert caps[0] > caps[1] > caps[2]  # a smaller drum turns faster


def test_no_action_when_well_mixed():
    sup = Supervisor(cfg(), mode=Mode.AUTO)
    ds = run(sup, 0, 300, level=lambda t: 0.8 + 0.05 * math.sin(t), radial=0.9,
             predictor=lambda r, h: dict.fromkeys(r, 0.9))
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

    sup = Supervisor(cfg(move_penalty_per_rpm=0.001, critical_rpm=77.0), mode=Mode.AUTO)
    ds = run(sup, 0, 40, level=lambda t: 0.8 if t < 20 else 0.4, predictor=predictor)
    moves = [d for d in ds if d.kind == "move"]
    assert len(moves) == 1 and len(ds) == 1
    m = moves[0]
    assert m.t_s == pytest.approx(25.0)  # bad from 20 s, dwell 5 s
    assert m.action is Action.SET_RPM and m.rpm == m.target_rpm
    assert "twin predicts" in m.reason and m.inputs.trend.level == 0.4
    assert m.rpm == max(m.scores, key=m.scores.get)  # best score on the candidate grid
    # the penalty matters: the best raw prediction (flat above 20 rpm) is not the furthest move
    assert 20 <= m.rpm < sup.config.limits.rpm_range[1]
    assert calls and calls[0][1] == sup.config.horizon_s
    # still segregated: nothing more before the minimum dwell between changes
    ds2 = run(sup, 40, 55, level=0.4, predictor=predictor)
    assert ds2 == []
    ds3 = run(sup, 55, 60, level=0.4, predictor=predictor)
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
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0, ramp_interval_s=1.0), mode=Mode.AUTO)
    ds = run(sup, 0, 40, level=0.3, predictor=lambda r, h: {x: x / 100 for x in r})
    assert ds[0].kind == "move" and ds[0].rpm == 7.0 and ds[0].target_rpm == sup.config.limits.rpm_range[1]
    ramps = [d for d in ds if d.kind == "ramp"]
    rpms = [ds[0].rpm] + [d.rpm for d in ramps]
    times = [ds[0].t_s] + [d.t_s for d in ramps]
    assert all(b - a <= 2.0 + 1e-9 for a, b in itertools.pairwise(rpms))
    assert all(tb - ta >= 1.0 - 1e-9 for ta, tb in itertools.pairwise(times))
    assert rpms[-1] == sup.config.limits.rpm_range[1]


def test_predictions_are_asked_once_and_used_when_they_arrive():
    """step never blocks: it asks (a request) and goes on; results come in on a later step."""
    sup = Supervisor(cfg(prediction_wait_s=20.0), mode=Mode.AUTO)
    reqs: list[PredictionRequest] = []
    ds = run(sup, 0, 10, level=0.3, requests=reqs)
    assert ds == [] and len(reqs) == 1  # decision due at 5 s: asked once, waiting
    req = reqs[0]
    assert req.t_s == pytest.approx(5.0) and req.horizon_s == sup.config.horizon_s and 5.0 in req.rpms
    inp = SupervisorInputs(trend=est(10.0, 0.3), setpoint_rpm=5.0, actual_rpm=5.0, last_valid_mi_s=10.0)
    d, again = sup.step(10.0, inp, PredictionResult(req.t_s, req.horizon_s, {5.0: 0.5, 15.0: 0.95}))
    assert again is None and d is not None and (d.kind, d.rpm) == ("move", 15.0)
    assert d.predictions == {5.0: 0.5, 15.0: 0.95}


def test_unanswered_request_falls_back_after_the_wait():
    sup = Supervisor(cfg(prediction_wait_s=4.0), mode=Mode.AUTO)
    reqs: list[PredictionRequest] = []
    ds = run(sup, 0, 12, level=0.3, requests=reqs)
    assert [d.kind for d in ds] == ["move"] and ds[0].t_s == pytest.approx(9.0) and "fallback" in ds[0].reason
    assert len(reqs) == 1


def test_stale_predictions_are_ignored():
    sup = Supervisor(cfg(prediction_max_age_s=10.0, prediction_wait_s=0.0), mode=Mode.AUTO)
    inp = SupervisorInputs(trend=est(0.0, 0.3), setpoint_rpm=5.0, actual_rpm=5.0, last_valid_mi_s=0.0)
    sup.step(0.0, inp, PredictionResult(-20.0, 60.0, {25.0: 0.9}))  # 20 s old at hand-in: too old at 5 s
    ds = run(sup, 0.5, 6, level=0.3)
    assert [(d.kind, d.rpm) for d in ds] == [("move", 10.0)] and "fallback" in ds[0].reason


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
    assert sup.set_manual_rpm(500) == sup.config.limits.rpm_range[1]
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


def test_after_a_link_loss_it_resyncs_to_the_board_and_ramps_from_its_actual_rpm():
    """Defect 5: the board was at 17 rpm while the supervisor believed 25; its next command
    must come from 17 (within the rate limit), not jump 17 -> 29."""
    sup = Supervisor(cfg(max_rate_rpm_per_s=4.0, ramp_interval_s=1.0), mode=Mode.MANUAL)
    sup.set_manual_rpm(45.0)
    ds = run(sup, 0, 5, level=0.9, setpoint_rpm=5.0, actual_rpm=5.0, mill_running=True, mill_epoch=1)
    assert [d.rpm for d in ds] == [9.0, 13.0, 17.0, 21.0, 25.0]
    assert sup.commanded_rpm == 25.0
    ds = run(sup, 5, 7, level=0.9, mill_connected=False, mill_epoch=1)
    assert [d.kind for d in ds] == ["safe"] and ds[0].action is Action.NONE  # hold: nothing sent
    # the link is back; the board (read again: epoch 2) runs at 17 rpm
    ds = run(sup, 7, 20, level=0.9, setpoint_rpm=17.0, actual_rpm=17.0, mill_running=True, mill_epoch=2)
    rpms = [d.rpm for d in ds if d.rpm is not None]
    assert sup.commanded_rpm is not None
    assert rpms and rpms[0] <= 17.0 + 4.0  # from the board's actual, inside the rate limit
    assert all(b - a <= 4.0 + 1e-9 for a, b in zip([17.0, *rpms], rpms, strict=False))


def test_resync_takes_the_setpoint_of_a_stopped_board_and_works_in_off_too():
    sup = Supervisor(cfg())
    sup.step(0.0, SupervisorInputs(setpoint_rpm=12.0, actual_rpm=0.0, mill_running=False, mill_epoch=1))
    assert sup.commanded_rpm == 12.0
    sup.step(1.0, SupervisorInputs(setpoint_rpm=12.0, actual_rpm=30.0, mill_running=True, mill_epoch=1))
    assert sup.commanded_rpm == 12.0  # same epoch: no resync
    sup.step(2.0, SupervisorInputs(setpoint_rpm=12.0, actual_rpm=8.0, mill_running=True, mill_epoch=2))
    assert sup.commanded_rpm == 8.0


def test_camera_end_is_a_safe_state_at_once_and_no_rpm_moves_follow():
    """Defect 4: at the end of a video AUTO went on ramping; now it holds at once."""
    sup = Supervisor(cfg(max_rate_rpm_per_s=2.0, ramp_interval_s=1.0), mode=Mode.AUTO)
    ds = run(sup, 0, 8, level=0.3, predictor=lambda r, h: {x: x / 100 for x in r})
    assert ds[0].kind == "move" and sup.target_rpm > sup.commanded_rpm  # a ramp in progress
    ds = run(sup, 8, 20, level=0.3, camera_ended=True, last_valid_mi_s=7.5)
    assert ds[0].kind == "safe" and ds[0].t_s == 8.0 and "camera ended" in ds[0].reason
    assert all(d.action is Action.NONE for d in ds)


def test_one_vision_timeout_for_alarm_and_safe_state():
    c = cfg(vision_timeout_s=3.0)
    assert not c.vision_lost(13.0, 10.0) and c.vision_lost(13.01, 10.0) and not c.vision_lost(99.0, None)
    sup = Supervisor(c, mode=Mode.AUTO)
    run(sup, 0, 10, level=0.9)
    ds = run(sup, 10, 16, level=0.9, last_valid_mi_s=10.0)
    first = next(d for d in ds if d.kind == "safe")
    assert first.t_s == pytest.approx(13.5)  # first step at which c.vision_lost(t, 10) holds


@pytest.mark.parametrize("action", list(SafeAction))
def test_a_refused_command_is_a_fault_of_its_own(action):
    """A refusal (``mill_refused`` grows) enters the safe state once; HOLD/RAMP recover after
    ``recover_s`` without another one, STOP stays latched. In OFF a refusal changes nothing."""
    c = cfg(safe_action=action, safe_rpm=3.0, recover_s=5.0, max_rate_rpm_per_s=1.0, ramp_interval_s=1.0)
    sup = Supervisor(c, mode=Mode.AUTO)
    assert run(sup, 0, 10, level=0.8) == []
    ds = run(sup, 10, 10.5, level=0.8, mill_refused=1)
    assert [d.kind for d in ds] == ["safe"] and "refused" in ds[0].reason and sup.safe
    assert ds[0].action is {SafeAction.STOP: Action.STOP, SafeAction.HOLD: Action.NONE,
                            SafeAction.RAMP: Action.SET_RPM}[action]
    ds = run(sup, 10.5, 30, level=0.8, mill_refused=1)  # the same count: no new refusal
    if action is SafeAction.STOP:
        assert ds == [] and sup.safe
    else:
        assert "recover" in [d.kind for d in ds] and not sup.safe
    off = Supervisor(c, mode=Mode.OFF)
    assert run(off, 0, 5, level=0.8, mill_refused=3) == [] and not off.safe


@pytest.mark.parametrize("board_rpm", [60.0, 0.5])
def test_a_ramp_from_a_board_outside_the_limits_commands_only_rpm_inside_them(board_rpm):
    """The board runs outside [min_rpm, max_rpm] when the run starts (front panel): one above
    them is brought down to the upper limit at once, one below is held until the operator
    asks for an rpm; the ramp then starts inside the limits (a step towards them), never at
    an intermediate rpm outside them."""
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0, ramp_interval_s=1.0), mode=Mode.MANUAL)
    lo, hi = sup.config.limits.rpm_range
    ds = run(sup, 0, 1, level=0.9, setpoint_rpm=board_rpm, actual_rpm=board_rpm, mill_running=True, mill_epoch=1)
    assert [d.rpm for d in ds if d.rpm is not None] == ([hi] if board_rpm > hi else [])
    sup.set_manual_rpm(20.0)
    ds += run(sup, 1, 10, level=0.9, setpoint_rpm=board_rpm, actual_rpm=board_rpm, mill_running=True, mill_epoch=1)
    rpms = [d.rpm for d in ds if d.rpm is not None]
    assert rpms and all(lo <= r <= hi for r in rpms), rpms
    assert rpms[0] == (hi if board_rpm > hi else lo)
    assert all(abs(b - a) <= 1.0 + 1e-9 for a, b in itertools.pairwise(rpms))  # then rate-limited


def test_manual_does_not_adopt_a_board_rpm_outside_the_limits():
    """MANUAL takes a board found inside the limits as the operator's rpm; one outside them
    is not the operator's: above them it is brought down to the upper limit (again after the
    board is read again), below them it is held as it is until the operator gives an rpm."""
    sup = Supervisor(cfg(max_rate_rpm_per_s=1.0, ramp_interval_s=1.0), mode=Mode.MANUAL)
    ds = run(sup, 0, 3, level=0.9, setpoint_rpm=60.0, actual_rpm=60.0, mill_running=True, mill_epoch=1)
    ds += run(sup, 3, 8, level=0.9, setpoint_rpm=55.0, actual_rpm=55.0, mill_running=True, mill_epoch=2)
    hi = sup.config.limits.rpm_range[1]
    assert sup.manual_rpm is None and [(d.kind, d.rpm) for d in ds if d.rpm is not None] == [("ramp", hi)] * 2
    below = Supervisor(cfg(max_rate_rpm_per_s=1.0, ramp_interval_s=1.0), mode=Mode.MANUAL)
    ds = run(below, 0, 5, level=0.9, setpoint_rpm=0.5, actual_rpm=0.5, mill_running=True, mill_epoch=1)
    assert below.manual_rpm is None and [d.rpm for d in ds if d.rpm is not None] == []
    inside = Supervisor(cfg(), mode=Mode.MANUAL)
    run(inside, 0, 1, level=0.9, setpoint_rpm=12.0, actual_rpm=12.0, mill_running=True, mill_epoch=1)
    assert inside.manual_rpm == 12.0


def test_a_running_board_that_reports_no_actual_speed_is_resynced_from_its_setpoint() -> None:
    """A board read back running with a NaN actual speed and a known setpoint: the supervisor
    takes the setpoint as its state at that epoch, so a later read of the same epoch does
    not resync again and a manual ramp goes on from what it commanded (found by the
    property test: it used to skip the NaN read and resync from a later setpoint)."""
    sup = Supervisor(worked_config(min_rpm=5.0, max_rpm=10.0, max_rate_rpm_per_s=1.0), Mode.MANUAL)

    def step(t: float, **inp: Any) -> Any:
        kw: dict[str, Any] = dict(last_valid_mi_s=t, twin_updated_s=t, mill_connected=True)
        kw.update(inp)
        d, _ = sup.step(t, SupervisorInputs(trend=est(t, 0.0), **kw))
        return d

    step(0.9, actual_rpm=math.nan, setpoint_rpm=4.0, mill_running=True, mill_epoch=1)
    assert sup.commanded_rpm == 4.0
    sup.set_manual_rpm(7.0)
    d = step(1.0, actual_rpm=None, setpoint_rpm=None, mill_epoch=1)
    assert d is not None and d.rpm == 5.0  # one rate step above the board's 4 rpm, not a jump to 7
    d = step(2.0, actual_rpm=None, setpoint_rpm=6.5, mill_epoch=1)  # same epoch: no new resync
    assert d is not None and d.rpm == 6.0

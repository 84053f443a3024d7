"""The supervisor's safe state (hold, ramp, stop), its faults and recovery, and a decision's log record.

Each test drives the public API (``step``, ``set_mode``, ``set_manual_rpm``) and compares whole
``Decision`` records with values worked out by hand from the rules in control/supervisor.py's docstring
(issue 27's mutation tests; the helpers are tests/control/supervisor_steps.py).
"""

from __future__ import annotations

from control.decision import Action, Decision, Mode, PredictionRequest, SupervisorInputs
from control.supervisor import Supervisor
from control.supervisor_config import SafeAction
from control.trend import TrendEstimate
from tests.control.supervisor_steps import RAMP, cfg, est, inp


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

"""The supervisor's rules at their edges (issue 27): inputs -> outputs of the public API only
(limits, candidates, the operator's rpm, segregation detection with its dwell and hysteresis,
the safe-state faults), so they hold whatever the prediction path's objective becomes."""

from __future__ import annotations

import math

import pytest

from control.decision import Mode, SupervisorInputs
from control.errors import ControlError
from control.segregation import SegregationDetector
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config


def est(level: float, rate: float = 0.0, settled: bool = True, t: float = 0.0) -> TrendEstimate:
    return TrendEstimate(t, level, rate, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=settled)


def test_candidates_are_evenly_spaced_over_the_limits_plus_the_current_rpm():
    c = worked_config()  # 2..45 rpm, 7 candidates
    assert c.candidates() == (2.0, 9.2, 16.3, 23.5, 30.7, 37.8, 45.0)
    assert c.candidates(12.34) == (2.0, 9.2, 12.3, 16.3, 23.5, 30.7, 37.8, 45.0)
    assert c.candidates(100.0) == c.candidates() and c.candidates(0.0) == c.candidates()  # clamped first
    assert worked_config(n_candidates=1).candidates() == (2.0, 45.0)  # at least both ends
    crit = worked_config(critical_rpm=50.0)  # 0.6 of the critical speed: 30 rpm
    assert crit.limits.rpm_range == (2.0, 30.0) and max(crit.candidates(40.0)) == 30.0


def test_vision_is_lost_strictly_after_the_timeout_and_never_before_the_first_mi():
    c = worked_config(vision_timeout_s=5.0)
    assert not c.vision_lost(10.0, 5.0) and c.vision_lost(10.0 + 1e-9, 5.0)
    assert not c.vision_lost(1e9, None)
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ControlError, match="vision_timeout_s"):
            worked_config(vision_timeout_s=bad)
    with pytest.raises(ControlError, match="clear_level"):
        worked_config(seg_level=0.6, clear_level=0.59)
    worked_config(seg_level=0.6, clear_level=0.6)  # no hysteresis is allowed


def test_the_operators_rpm_is_clamped_into_the_limits_and_a_non_number_refused():
    sup = Supervisor(worked_config(min_rpm=2.0, max_rpm=45.0))
    assert sup.set_manual_rpm(100.0) == 45.0 and sup.manual_rpm == 45.0
    assert sup.set_manual_rpm(0.5) == 2.0 and sup.manual_rpm == 2.0
    assert sup.set_manual_rpm("12.5") == 12.5  # type: ignore[arg-type]  # (a number as the dashboard sends it)
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ControlError, match=r"manual rpm must be a number, got (nan|inf|-inf)"):
            sup.set_manual_rpm(bad)
    assert sup.manual_rpm == 12.5  # a refused value changes nothing


def test_bad_conditions_and_their_strict_thresholds():
    d = SegregationDetector(worked_config(seg_level=0.5, seg_rate_per_s=-0.01, radial_min=0.5))
    assert d.bad_reasons(est(0.5), None) == []  # at the threshold: not below it
    assert d.bad_reasons(est(0.4999), None) == ["MI 0.500 < 0.5"]
    assert d.bad_reasons(est(0.8, -0.01), None) == []
    assert d.bad_reasons(est(0.8, -0.0125), None) == ["MI falling -0.0125/s < -0.01/s"]
    assert d.bad_reasons(est(0.8), 0.5) == [] and d.bad_reasons(est(0.8), math.nan) == []
    assert d.bad_reasons(est(0.8), 0.25) == ["radial factor 0.250 < 0.5"]
    assert len(d.bad_reasons(est(0.3, -0.02), 0.1)) == 3


def test_good_conditions_need_all_of_level_rate_and_radial_strictly():
    d = SegregationDetector(worked_config(clear_level=0.6, seg_rate_per_s=-0.01, radial_clear=0.6))
    assert d.is_good(est(0.61), None) and not d.is_good(est(0.6), None)
    assert not d.is_good(est(0.7, -0.005), None) and d.is_good(est(0.7, -0.004), None)  # rate above half seg_rate
    assert not d.is_good(est(0.7), 0.6) and d.is_good(est(0.7), 0.61) and d.is_good(est(0.7), math.nan)


def test_detection_and_clearing_wait_their_dwell_and_restart_on_an_interruption():
    d = SegregationDetector(worked_config(detect_dwell_s=5.0, clear_dwell_s=3.0))
    assert not d.update(0.0, est(0.3), None) and d.suspect and not d.segregated
    assert not d.update(4.5, est(0.3), None) and d.suspect
    assert d.update(5.0, est(0.3), None) and d.segregated and not d.suspect  # at the dwell exactly
    assert d.why == "MI 0.300 < 0.5"
    assert not d.update(6.0, est(0.9), None) and not d.suspect  # good: the clear dwell starts ('suspect' is
    assert not d.update(7.0, est(0.55), None) and d.segregated  # only before a detection); neither: restarts
    assert not d.update(8.0, est(0.9), None)
    assert not d.update(10.9, est(0.9), None) and d.segregated
    assert d.update(11.0, est(0.9), None) and not d.segregated and d.why == "" and not d.suspect
    # an unsettled or missing trend decides nothing and restarts the dwell
    assert not d.update(12.0, est(0.3), None) and d.suspect
    assert not d.update(13.0, est(0.3, settled=False), None) and not d.suspect
    assert not d.update(14.0, None, None) and not d.suspect
    assert not d.update(18.9, est(0.3), None)
    assert not d.update(23.8, est(0.3), None) and d.update(23.9, est(0.3), None)
    d.reset()
    assert not d.segregated and not d.suspect and d.why == ""


def test_the_safe_state_faults_of_each_mode():
    cfg = worked_config(vision_timeout_s=5.0, twin_timeout_s=60.0)
    lost = SupervisorInputs(mill_connected=False)
    for mode in Mode:
        sup = Supervisor(cfg, mode=mode)
        assert sup.faults(0.0, lost)[:1] == ["mill link lost"]
    man = Supervisor(cfg, mode=Mode.MANUAL)
    assert man.faults(100.0, SupervisorInputs(camera_ended=True, twin_doubt="disagrees", last_valid_mi_s=0.0)) == []
    auto = Supervisor(cfg, mode=Mode.AUTO)
    ok = SupervisorInputs(last_valid_mi_s=10.0, twin_updated_s=10.0)
    assert auto.faults(15.0, ok) == []
    assert auto.faults(15.5, ok) == ["no valid MI for 5.5 s"]
    assert auto.faults(11.0, SupervisorInputs(last_valid_mi_s=10.0, camera_ended=True)) == [
        "camera ended: no valid MI"]
    assert auto.faults(70.5, SupervisorInputs(last_valid_mi_s=70.0, twin_updated_s=10.0)) == ["twin stale for 60.5 s"]
    assert auto.faults(70.5, SupervisorInputs(last_valid_mi_s=70.0)) == []  # no twin, none required
    assert auto.faults(12.0, SupervisorInputs(last_valid_mi_s=12.0, twin_updated_s=12.0,
                                              twin_doubt="twin_mismatch: slope")) == [
        "twin stale: twin_mismatch: slope"]
    needs = Supervisor(worked_config(require_twin=True, twin_timeout_s=60.0), mode=Mode.AUTO)
    needs.step(0.0, SupervisorInputs(last_valid_mi_s=0.0))  # the run starts at 0: the twin is due from there
    assert needs.faults(60.0, SupervisorInputs(last_valid_mi_s=60.0)) == []
    assert needs.faults(61.0, SupervisorInputs(last_valid_mi_s=61.0)) == ["twin stale for 61.0 s"]
    assert Supervisor(worked_config(twin_timeout_s=None), mode=Mode.AUTO).faults(
        1e6, SupervisorInputs(last_valid_mi_s=1e6, twin_updated_s=0.0)) == []


def test_a_twin_in_doubt_puts_auto_in_the_safe_state_with_the_reason():
    sup = Supervisor(worked_config(), mode=Mode.AUTO)
    inp = dict(trend=est(0.9), actual_rpm=5.0, setpoint_rpm=5.0, mill_running=True, last_valid_mi_s=0.0,
               twin_updated_s=0.0)
    sup.step(0.0, SupervisorInputs(**inp))  # type: ignore[arg-type]
    assert not sup.safe
    d, _ = sup.step(0.5, SupervisorInputs(**{**inp, "last_valid_mi_s": 0.5, "twin_doubt": "what-if failed"}))  # type: ignore[arg-type]
    assert sup.safe and "twin stale: what-if failed" in sup.safe_reason
    assert d is not None and "what-if failed" in d.reason


def test_config_edges_and_messages():
    worked_config(vision_timeout_s=0.5)
    with pytest.raises(ControlError) as exc:
        worked_config(seg_level=0.6, clear_level=0.5)
    assert str(exc.value) == "clear_level must be >= seg_level (hysteresis)"


def test_a_fresh_or_reset_detector_is_clear_and_says_why_when_it_detects():
    cfg = worked_config(detect_dwell_s=1.0, clear_dwell_s=1.0, radial_clear=0.6)
    d = SegregationDetector(cfg)
    assert d.segregated is False and d.why == "" and not d.suspect
    assert d.update(0.0, est(0.9), None) is False  # good, not segregated: no change
    assert d.update(0.5, est(0.3, settled=False), None) is False
    assert not d.update(1.0, est(0.3, -0.02), None) and d.update(2.0, est(0.3, -0.02), None)
    assert d.why == "MI 0.300 < 0.5; MI falling -0.0200/s < -0.01/s"
    # clearing needs the radial factor too: a good level with a radial factor below radial_clear stays
    for t in (3.0, 4.0, 5.0, 6.0):
        assert not d.update(t, est(0.9), 0.55) and d.segregated
    d.reset()
    assert d.segregated is False and d.why == ""


def test_the_time_without_mi_or_twin_counts_from_the_first_step():
    auto = Supervisor(worked_config(vision_timeout_s=5.0, require_twin=True, twin_timeout_s=60.0), mode=Mode.AUTO)
    assert auto.faults(5.0, SupervisorInputs()) == []  # before any step: counted from now
    auto.step(0.0, SupervisorInputs())
    assert auto.faults(5.5, SupervisorInputs(twin_updated_s=5.0)) == ["no valid MI for 5.5 s"]

"""The motor model (control/motor.py) at its edges: no time is no change, the speed lands exactly
on its target once within the board's last digit, and strictly below 0.005 rpm (pure)."""

from __future__ import annotations

from control.motor import MotorConfig, MotorModel, MotorState


def test_the_state_is_a_snapshot_of_all_four() -> None:
    m = MotorModel(MotorConfig(max_rpm=60.0, accel_rpm_per_s=10.0, tau_s=0.5))
    m.setpoint_rpm, m.running, m.fault = 12.0, True, "WDOG"
    m.step(0.25)
    assert m.state() == MotorState(12.0, m.actual_rpm, True, "WDOG") and m.actual_rpm == 2.5


def test_no_time_is_no_change_even_within_the_snap() -> None:
    m = MotorModel()
    m.setpoint_rpm, m.running, m.actual_rpm = 10.0, True, 9.996
    assert m.step(0.0) == 9.996 and m.actual_rpm == 9.996


def test_the_speed_lands_exactly_on_its_target() -> None:
    m = MotorModel(MotorConfig(max_rpm=60.0, accel_rpm_per_s=10.0, tau_s=0.5))
    m.setpoint_rpm, m.running = 10.0, True
    for _ in range(100):  # 10 s: the first-order approach alone would stay a hair below
        m.step(0.1)
    assert m.actual_rpm == 10.0


def test_the_snap_is_strictly_below_0_005_rpm() -> None:
    m = MotorModel()
    m.setpoint_rpm, m.running = 0.005, True
    m.step(1e-300)  # moves nothing (1 - exp(-dt/tau) is 0 in doubles): 0.005 rpm off, exactly
    assert m.actual_rpm == 0.0

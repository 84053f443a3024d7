"""Board firmware logic (pure) and the motor model."""

from __future__ import annotations

import random

import pytest

from control import protocol as p
from control.device import DeviceConfig, MillDevice
from control.motor import MotorConfig, MotorModel


def replies(data: bytes) -> list[p.Frame]:
    return [f for f in p.FrameDecoder().feed(data) if isinstance(f, p.Frame)]


def test_motor_respects_acceleration_lag_and_max():
    m = MotorModel(MotorConfig(max_rpm=30.0, accel_rpm_per_s=10.0, tau_s=0.5))
    m.setpoint_rpm, m.running = 100.0, True
    m.step(0.5)
    assert m.actual_rpm == pytest.approx(5.0)  # accel-limited: 10 rpm/s * 0.5 s
    for _ in range(200):
        m.step(0.05)
    assert m.actual_rpm == pytest.approx(30.0)  # capped at max_rpm
    m.setpoint_rpm = 20.0
    prev = m.actual_rpm
    m.step(0.01)
    assert prev - m.actual_rpm <= 10.0 * 0.01 + 1e-9
    # lag: close to the target, the approach is exponential (not the accel ramp)
    m2 = MotorModel(MotorConfig(max_rpm=60, accel_rpm_per_s=1000, tau_s=1.0))
    m2.setpoint_rpm, m2.running = 10.0, True
    m2.step(1.0)
    assert m2.actual_rpm == pytest.approx(10.0 * (1 - 2.718281828 ** -1), rel=1e-3)
    m2.running = False
    for _ in range(100):
        m2.step(0.1)
    assert m2.actual_rpm == 0.0


def test_set_run_stop_status():
    d = MillDevice(DeviceConfig(watchdog_s=10.0))
    r = replies(d.receive(p.encode_frame(1, p.SET, 12.0), 0.0))
    assert r == [p.Frame(1, p.ACK)]
    r = replies(d.receive(p.encode_frame(2, p.RUN), 0.1))
    assert r[0].cmd == p.ACK and d.motor.running
    d.tick(5.0)
    r = replies(d.receive(p.encode_frame(3, p.STA), 5.0))
    st = p.parse_status(r[0].args)
    assert st.setpoint_rpm == 12.0 and st.running and st.actual_rpm > 11.0 and st.fault is None
    replies(d.receive(p.encode_frame(4, p.STP), 5.0))
    assert not d.motor.running
    assert [a.cmd for a in d.applied] == [p.SET, p.RUN, p.STP]


def test_resend_is_answered_but_not_applied_twice():
    d = MillDevice()
    f = p.encode_frame(10, p.SET, 7.0)
    a = d.receive(f, 0.0)
    b = d.receive(f, 0.01)
    assert a == b and len(d.applied) == 1 and d.counters["resends"] == 1
    # the same seq with another payload is a new request (e.g. host restarted)
    d.receive(p.encode_frame(10, p.SET, 8.0), 0.02)
    assert len(d.applied) == 2 and d.motor.setpoint_rpm == 8.0


def test_naks():
    d = MillDevice(DeviceConfig(motor=MotorConfig(max_rpm=50.0)))
    cases = [
        (p.encode_frame(1, "FOO"), p.NAK_CMD),
        (p.encode_frame(2, p.SET, 80.0), p.NAK_RANGE),
        (p.encode_frame(3, p.SET, "abc"), p.NAK_ARG),
        (p.encode_frame(4, p.SET), p.NAK_ARG),
        (p.encode_frame(5, p.RUN, 1), p.NAK_ARG),
        (p.encode_frame(6, p.ACK), p.NAK_CMD),
    ]
    for i, (frame, reason) in enumerate(cases):
        r = replies(d.receive(frame, 0.0))
        assert r == [p.Frame(i + 1, p.NAK, (reason,))]
    bad = bytearray(p.encode_frame(9, p.RUN))
    bad[-2] = ord("0") if bad[-2] != ord("0") else ord("1")  # wrong checksum digit
    assert replies(d.receive(bytes(bad), 0.0)) == [p.Frame(9, p.NAK, (p.NAK_CRC,))]
    assert d.applied == [] and not d.motor.running and d.motor.setpoint_rpm == 0.0


def test_watchdog_stops_motor_when_host_goes_quiet():
    d = MillDevice(DeviceConfig(watchdog_s=0.5))
    d.receive(p.encode_frame(1, p.SET, 20.0) + p.encode_frame(2, p.RUN), 0.0)
    for k in range(1, 20):  # heartbeats every 0.2 s keep it running
        d.receive(p.encode_frame(2 + k, p.HB), 0.2 * k)
    assert d.motor.running and d.motor.fault is None
    d.tick(3.8 + 0.49)
    assert d.motor.running
    d.tick(3.8 + 0.51)
    assert not d.motor.running and d.motor.fault == p.FAULT_WATCHDOG
    rpm = d.motor.actual_rpm
    d.tick(6.0)
    assert d.motor.actual_rpm < rpm
    d.receive(p.encode_frame(50, p.RUN), 6.0)  # an explicit start clears the fault
    assert d.motor.running and d.motor.fault is None


def test_garbage_never_moves_the_motor():
    rng = random.Random(3)
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    junk = [bytes(rng.randrange(256) for _ in range(rng.randint(1, 400))) for _ in range(300)]
    junk += [b"$1,SET," + b"5" * 200 + b"\n", b"$" * 100, b"\n" * 50, b"$2,RUN*0000\n", b"$3,SET,20*FFFF\n"]
    junk += [p.encode_frame(4, "XYZ"), p.encode_frame(5, p.SET, "-5"), p.encode_frame(6, p.SET, "nan")]
    junk += [p.encode_frame(7, p.SET, 1000.0), p.encode_frame(8, p.STP, "x")]
    for j in junk:
        d.receive(j, 0.0)
    assert d.applied == [] and not d.motor.running and d.motor.setpoint_rpm == 0.0 and d.motor.actual_rpm == 0.0
    # and it still works afterwards
    r = replies(d.receive(b"\n" + p.encode_frame(100, p.SET, 3.0), 0.0))
    assert r == [p.Frame(100, p.ACK)] and d.motor.setpoint_rpm == 3.0


def test_only_the_controlling_hosts_commands_feed_the_watchdog():
    """A status poller (STA) does not keep the motor running; HB, SET, STP do feed."""
    d = MillDevice(DeviceConfig(watchdog_s=0.5))
    d.receive(p.encode_frame(1, p.SET, 20.0) + p.encode_frame(2, p.RUN), 0.0)
    for k in range(1, 10):  # a monitor polls the status every 0.1 s
        r = replies(d.receive(p.encode_frame(100 + k, p.STA), 0.1 * k))
        assert r[0].cmd == p.ACK
    d.tick(0.95)
    assert not d.motor.running and d.motor.fault == p.FAULT_WATCHDOG
    assert d.counters["watchdog_trips"] == 1
    # every controlling command feeds it: SET, HB and a refused SET (the host is alive)
    d.receive(p.encode_frame(20, p.RUN), 1.0)
    feeds = [p.encode_frame(21, p.SET, 10.0), p.encode_frame(22, p.HB), p.encode_frame(23, p.SET, 999.0)]
    for i, frame in enumerate(feeds):
        d.receive(frame, 1.4 + 0.4 * i)
    d.tick(2.2 + 0.45)
    assert d.motor.running and d.motor.fault is None
    assert p.WATCHDOG_COMMANDS == {p.SET, p.RUN, p.STP, p.HB}


def test_status_is_never_answered_from_the_resend_cache():
    """Two hosts (or two CLI calls) asking STA under the same seq get the status of now."""
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    first = p.parse_status(replies(d.receive(p.encode_frame(1, p.STA), 0.0))[0].args)
    assert first == p.MillStatus(0.0, 0.0, False, None)
    d.motor.setpoint_rpm, d.motor.running = 9.0, True  # front panel: no frame, cache untouched
    d.tick(5.0)
    again = p.parse_status(replies(d.receive(p.encode_frame(1, p.STA), 5.0))[0].args)
    assert again.setpoint_rpm == 9.0 and again.running and again.actual_rpm > 8.0
    hb = p.parse_status(replies(d.receive(p.encode_frame(1, p.HB), 5.0))[0].args)
    assert hb.running and d.counters["resends"] == 0
    # a status between a SET and its resend does not break the resend detection
    d.receive(p.encode_frame(2, p.SET, 4.0), 5.1)
    d.receive(p.encode_frame(3, p.STA), 5.1)
    d.receive(p.encode_frame(2, p.SET, 4.0), 5.2)
    assert [a.cmd for a in d.applied] == [p.SET] and d.counters["resends"] == 1

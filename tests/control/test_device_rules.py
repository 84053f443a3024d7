"""The motor board's written rules (docs/mill-protocol.md, control/device.py), each at its edge (issue 27).

Times are chosen as binary-exact floats (0.25, 0.5, 1.5, ...) so "exactly the watchdog time" is exact.
"""

from __future__ import annotations

import pytest

from control import protocol as p
from control.device import Applied, DeviceConfig, MillDevice
from control.motor import MotorConfig


def frames(data: bytes) -> list[p.Frame | p.BadFrame]:
    return p.FrameDecoder().feed(data)


def running_device(watchdog_s: float = 0.5, t: float = 0.0, rpm: float = 10.0) -> MillDevice:
    d = MillDevice(DeviceConfig(watchdog_s=watchdog_s), now_s=t)
    assert frames(d.receive(p.encode_frame(1, p.SET, rpm) + p.encode_frame(2, p.RUN), t)) == [
        p.Frame(1, p.ACK), p.Frame(2, p.ACK)]
    return d


def test_defaults_are_the_documented_ones():
    """watchdog 1 s; the drive model's defaults are those of the doc's motor model (60 rpm, 10 rpm/s, 0.5 s)."""
    c = DeviceConfig()
    assert c.watchdog_s == 1.0 and c.motor == MotorConfig(60.0, 10.0, 0.5)
    d = MillDevice()
    assert d.config == c and d.applied == [] and d.status() == p.MillStatus(0.0, 0.0, False, None)
    assert d.counters == {"frames": 0, "resends": 0, "nak": 0, "bad_crc": 0, "bad_other": 0, "watchdog_trips": 0}


# --- the watchdog ------------------------------------------------------------------------------


def test_the_watchdog_trips_only_strictly_after_watchdog_s():
    d = running_device(watchdog_s=0.5)
    d.receive(p.encode_frame(3, p.HB), 0.25)
    d.tick(0.75)  # exactly 0.5 s of silence: not yet
    assert d.motor.running and d.motor.fault is None and d.counters["watchdog_trips"] == 0
    d.tick(0.75 + 2**-20)
    assert not d.motor.running and d.motor.fault == p.FAULT_WATCHDOG and d.counters["watchdog_trips"] == 1
    d.tick(5.0)  # a stopped motor does not trip again
    assert d.counters["watchdog_trips"] == 1 and d.motor.fault == p.FAULT_WATCHDOG


def test_watchdog_zero_disables_it():
    d = running_device(watchdog_s=0.0)
    d.tick(1000.0)
    assert d.motor.running and d.motor.fault is None and d.counters["watchdog_trips"] == 0


def test_a_stopped_motor_never_trips_the_watchdog():
    d = MillDevice(DeviceConfig(watchdog_s=0.5))
    d.receive(p.encode_frame(1, p.SET, 10.0), 0.0)
    d.tick(100.0)
    assert d.motor.fault is None and d.counters["watchdog_trips"] == 0


def test_the_watchdog_counts_from_the_boards_start_time():
    """Before any frame, the watchdog time runs from ``now_s`` of the board's construction."""
    d = MillDevice(DeviceConfig(watchdog_s=0.5), now_s=10.0)
    d.motor.running, d.motor.setpoint_rpm = True, 5.0  # front panel start: no frame
    d.tick(10.5)
    assert d.motor.running
    d.tick(10.75)
    assert d.motor.fault == p.FAULT_WATCHDOG


def test_a_frame_arriving_after_the_watchdog_time_comes_too_late():
    """receive() advances time first: an HB 0.75 s after the last feed (watchdog 0.5 s) finds the motor
    already stopped with WDOG, and its status says so."""
    d = running_device(watchdog_s=0.5)
    (reply,) = frames(d.receive(p.encode_frame(3, p.HB), 0.75))
    st = p.parse_status(reply.args)
    assert not st.running and st.fault == p.FAULT_WATCHDOG and d.counters["watchdog_trips"] == 1


@pytest.mark.parametrize(
    "frame",
    [p.encode_frame(3, p.HB), p.encode_frame(3, p.SET, 12.0), p.encode_frame(3, p.SET, 999.0),
     p.encode_frame(3, p.SET, "x"), p.encode_frame(3, p.STP), p.encode_frame(3, p.RUN),
     p.encode_frame(3, p.HB, 1)],
)
def test_every_controlling_command_feeds_the_watchdog_acked_or_nakked(frame):
    d = running_device(watchdog_s=0.5)
    d.receive(frame, 0.25)
    was_running = d.motor.running
    d.tick(0.75)  # 0.5 s after the feed: still inside
    assert d.motor.fault is None and d.motor.running == was_running
    d.tick(0.75 + 2**-20)
    assert d.motor.fault == (p.FAULT_WATCHDOG if was_running else None)


@pytest.mark.parametrize(
    "data",
    [p.encode_frame(3, p.STA), p.encode_frame(3, "FOO"), p.encode_frame(3, p.ACK),
     b"$3,HB*0000\n", b"garbage\n", b"$3,HB\n"],
)
def test_status_polls_unknown_commands_and_bad_lines_do_not_feed_the_watchdog(data):
    d = running_device(watchdog_s=0.5)
    d.receive(data, 0.25)
    d.tick(0.5 + 2**-20)
    assert not d.motor.running and d.motor.fault == p.FAULT_WATCHDOG


def test_a_resend_feeds_the_watchdog_too():
    d = running_device(watchdog_s=0.5)
    d.receive(p.encode_frame(2, p.RUN), 0.25)  # the RUN's resend (same seq and payload)
    assert d.counters["resends"] == 1
    d.tick(0.75)
    assert d.motor.running


def test_feed_watchdog_restarts_the_watchdog_time():
    d = running_device(watchdog_s=0.5)
    d.feed_watchdog(0.25)
    d.tick(0.75)
    assert d.motor.running
    d.tick(0.75 + 2**-20)
    assert d.motor.fault == p.FAULT_WATCHDOG


def test_only_run_clears_a_watchdog_fault():
    d = running_device(watchdog_s=0.5)
    d.tick(1.0)
    assert d.motor.fault == p.FAULT_WATCHDOG
    for k, frame in enumerate([p.encode_frame(10, p.SET, 5.0), p.encode_frame(11, p.HB), p.encode_frame(12, p.STP)]):
        d.receive(frame, 1.0 + 0.125 * k)
        assert d.motor.fault == p.FAULT_WATCHDOG and not d.motor.running
    assert frames(d.receive(p.encode_frame(13, p.RUN), 1.5)) == [p.Frame(13, p.ACK)]
    assert d.motor.fault is None and d.motor.running


def test_a_drive_fault_refuses_run_and_is_not_cleared_by_it():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    d.motor.fault = p.FAULT_DRIVE
    assert frames(d.receive(p.encode_frame(4, p.RUN), 0.0)) == [p.Frame(4, p.NAK, (p.NAK_FAULT,))]
    assert not d.motor.running and d.motor.fault == p.FAULT_DRIVE and d.applied == []
    assert d.counters["nak"] == 1


# --- commands and their arguments --------------------------------------------------------------


def test_set_accepts_exactly_max_rpm_and_refuses_above():
    d = MillDevice(DeviceConfig(motor=MotorConfig(max_rpm=50.0)))
    assert frames(d.receive(p.encode_frame(1, p.SET, "50"), 0.0)) == [p.Frame(1, p.ACK)]
    assert d.motor.setpoint_rpm == 50.0
    assert frames(d.receive(p.encode_frame(2, p.SET, "50.001"), 0.0)) == [p.Frame(2, p.NAK, (p.NAK_RANGE,))]
    assert frames(d.receive(p.encode_frame(3, p.SET, "0"), 0.0)) == [p.Frame(3, p.ACK)]
    assert d.motor.setpoint_rpm == 0.0


@pytest.mark.parametrize(
    ("args", "reason"),
    [((), p.NAK_ARG), (("1", "2"), p.NAK_ARG), (("-1",),  p.NAK_ARG), (("1e1",), p.NAK_ARG), (("abc",), p.NAK_ARG)],
)
def test_set_with_a_bad_argument_is_refused_and_changes_nothing(args, reason):
    d = MillDevice()
    d.receive(p.encode_frame(1, p.SET, 7.0), 0.0)
    assert frames(d.receive(p.encode_frame(2, p.SET, *args), 0.0)) == [p.Frame(2, p.NAK, (reason,))]
    assert d.motor.setpoint_rpm == 7.0 and len(d.applied) == 1


@pytest.mark.parametrize("cmd", [p.RUN, p.STP, p.STA, p.HB])
def test_commands_without_arguments_refuse_an_argument(cmd):
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    assert frames(d.receive(p.encode_frame(5, cmd, 1), 0.0)) == [p.Frame(5, p.NAK, (p.NAK_ARG,))]
    assert d.applied == [] and not d.motor.running and d.counters["nak"] == 1


@pytest.mark.parametrize("cmd", ["FOO", p.ACK, p.NAK, "SE"])
def test_an_unknown_command_is_nakked_cmd(cmd):
    d = MillDevice()
    assert frames(d.receive(p.encode_frame(6, cmd), 0.0)) == [p.Frame(6, p.NAK, (p.NAK_CMD,))]
    assert d.applied == [] and d.counters == {**d.counters, "frames": 1, "nak": 1}


def test_status_and_heartbeat_answer_the_status_rounded_to_the_reported_two_decimals():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    d.receive(p.encode_frame(1, p.SET, "12.125"), 0.0)
    d.receive(p.encode_frame(2, p.RUN), 0.0)
    d.tick(0.25)  # accel-limited: 2.5 rpm
    for cmd in (p.STA, p.HB):
        (reply,) = frames(d.receive(p.encode_frame(3, cmd), 0.25))
        assert reply == p.Frame(3, p.ACK, ("12.12", "2.50", "1", "OK"))
    assert d.motor.setpoint_rpm == 12.125
    assert d.status() == p.MillStatus(12.12, 2.5, True, None)
    assert [a.cmd for a in d.applied] == [p.SET, p.RUN]  # status requests are not applied commands


def test_applied_records_time_seq_command_and_args():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    d.receive(p.encode_frame(7, p.SET, 3.0), 1.25)
    d.receive(p.encode_frame(8, p.RUN), 1.5)
    d.receive(p.encode_frame(9, p.STP), 2.0)
    assert d.applied == [Applied(1.25, 7, p.SET, ("3.00",)), Applied(1.5, 8, p.RUN, ()), Applied(2.0, 9, p.STP, ())]
    assert not d.motor.running and d.motor.setpoint_rpm == 3.0


# --- bad lines -----------------------------------------------------------------------------------


def test_a_bad_checksum_with_a_readable_seq_gets_nak_crc_and_is_counted():
    d = MillDevice()
    body = b"41,SET,9.00"
    bad = b"$" + body + f"*{p.crc16(body) ^ 0x10:04X}\n".encode()
    assert d.receive(bad, 0.0) == p.encode_frame(41, p.NAK, p.NAK_CRC)
    assert d.counters == {**d.counters, "bad_crc": 1, "nak": 1, "bad_other": 0, "frames": 0}
    assert d.motor.setpoint_rpm == 0.0


@pytest.mark.parametrize(
    "line",
    [b"$x,SET*0000\n", b"$1,SET,9.00\n", b"$1,set,9*12\n", b"$1,SET,\x019\n", b"$" + b"1" * 80 + b"\n"],
)
def test_other_bad_lines_get_no_answer_and_are_counted(line):
    d = MillDevice()
    assert d.receive(line, 0.0) == b""
    assert d.counters == {**d.counters, "bad_other": 1, "bad_crc": 0, "nak": 0, "frames": 0}


def test_several_frames_in_one_read_are_all_answered_in_order():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    body = b"3,STA"
    bad_crc = b"$" + body + f"*{p.crc16(body) ^ 1:04X}\n".encode()
    out = frames(d.receive(p.encode_frame(1, p.SET, 2.0) + b"junk\n" + bad_crc + p.encode_frame(2, p.RUN), 0.0))
    assert out == [p.Frame(1, p.ACK), p.Frame(3, p.NAK, (p.NAK_CRC,)), p.Frame(2, p.ACK)]
    assert d.counters["frames"] == 2 and d.counters["bad_crc"] == 1


# --- the resend cache -----------------------------------------------------------------------------


def test_a_resend_of_a_refused_set_gets_the_cached_nak_and_is_not_executed_again():
    d = MillDevice(DeviceConfig(motor=MotorConfig(max_rpm=50.0)))
    f = p.encode_frame(5, p.SET, 80.0)
    first = d.receive(f, 0.0)
    assert frames(first) == [p.Frame(5, p.NAK, (p.NAK_RANGE,))]
    assert d.receive(f, 0.1) == first
    assert d.counters["nak"] == 1 and d.counters["resends"] == 1 and d.counters["frames"] == 2


def test_the_cache_holds_only_the_last_state_changing_request():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    a, b = p.encode_frame(1, p.SET, 4.0), p.encode_frame(2, p.SET, 6.0)
    d.receive(a, 0.0)
    d.receive(b, 0.0)
    d.receive(a, 0.0)  # not the last request any more: a new request (setpoints are absolute)
    assert d.motor.setpoint_rpm == 4.0 and len(d.applied) == 3 and d.counters["resends"] == 0
    d.receive(p.encode_frame(2, p.SET, 4.0), 0.0)  # same seq, another payload: new
    d.receive(p.encode_frame(3, p.SET, 4.0), 0.0)  # same payload, another seq: new
    assert len(d.applied) == 5 and d.counters["resends"] == 0


def test_a_status_never_replaces_the_cached_request():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    run = p.encode_frame(9, p.RUN)
    d.receive(run, 0.0)
    d.receive(p.encode_frame(9, p.STA), 0.0)  # the same seq as the RUN
    d.receive(p.encode_frame(9, p.HB), 0.0)
    assert d.receive(run, 0.0) == p.encode_frame(9, p.ACK)
    assert d.counters["resends"] == 1 and [a.cmd for a in d.applied] == [p.RUN]


# --- time --------------------------------------------------------------------------------------


def test_time_going_backwards_does_not_move_the_motor_or_rewind_it():
    d = MillDevice(DeviceConfig(watchdog_s=0.0), now_s=10.0)
    d.receive(p.encode_frame(1, p.SET, 30.0) + p.encode_frame(2, p.RUN), 10.0)
    d.tick(9.0)  # a clock step back: nothing happens
    assert d.motor.actual_rpm == 0.0
    d.tick(10.25)  # 0.25 s after the board's last time (not 1.25 s after 9.0): 10 rpm/s -> 2.5 rpm
    assert d.motor.actual_rpm == pytest.approx(2.5)


def test_the_motor_advances_from_the_boards_start_time():
    d = MillDevice(DeviceConfig(watchdog_s=0.0), now_s=100.0)
    d.receive(p.encode_frame(1, p.SET, 30.0) + p.encode_frame(2, p.RUN), 100.0)
    d.tick(100.5)
    assert d.motor.actual_rpm == pytest.approx(5.0)


def test_the_counters_count_every_event():
    """The audit counters add up: two of each kind give 2, not 1."""
    d = MillDevice(DeviceConfig(watchdog_s=0.5, motor=MotorConfig(max_rpm=50.0)))
    body = b"7,STA"
    bad_crc = b"$" + body + f"*{p.crc16(body) ^ 1:04X}\n".encode()
    d.receive(bad_crc + bad_crc + b"$1,SET\n" + b"$2,SET\n", 0.0)  # two NAK,CRC; two silent drops
    d.receive(p.encode_frame(3, p.SET, 80.0) + p.encode_frame(4, "FOO"), 0.0)  # two NAKs by _execute
    set5 = p.encode_frame(5, p.SET, 5.0)
    d.receive(set5 + set5 + set5, 0.0)  # one SET and two resends
    for k in range(2):  # two watchdog trips
        d.receive(p.encode_frame(10 + k, p.RUN), 1.0 + k)
        d.tick(1.75 + k)
    assert d.counters == {"frames": 7, "resends": 2, "nak": 4, "bad_crc": 2, "bad_other": 2, "watchdog_trips": 2}


def test_the_status_says_running_false_not_just_falsy():
    """``MillStatus.running`` is a bool (the CLI's --json prints it): false after STP and after a trip."""
    d = running_device(watchdog_s=0.5)
    d.receive(p.encode_frame(3, p.STP), 0.25)
    assert d.status().running is False and d.status().as_dict()["running"] is False
    d = running_device(watchdog_s=0.5)
    d.tick(1.0)
    assert d.status().running is False and d.status().fault == p.FAULT_WATCHDOG


def test_the_status_rounds_the_actual_speed_to_two_decimals():
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    d.receive(p.encode_frame(1, p.SET, 30.0) + p.encode_frame(2, p.RUN), 0.0)
    d.tick(0.0625)  # 10 rpm/s for 1/16 s: 0.625 rpm exactly
    assert d.motor.actual_rpm == 0.625
    assert d.status().actual_rpm == 0.62  # round half to even, as the 2-decimal wire field


def test_a_resent_stop_that_stops_a_front_panel_start_is_recorded_and_reads_false():
    """A ``STP`` resend (same seq and payload) that finds the motor running again stops it and
    records that stop as applied now, with its own seq; the status then says running ``False``."""
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    stp = p.encode_frame(7, p.STP)
    d.receive(stp, 0.0)
    d.motor.running = True  # the front panel
    assert frames(d.receive(stp, 0.5)) == [p.Frame(7, p.ACK)]
    assert d.applied == [Applied(0.0, 7, p.STP, ()), Applied(0.5, 7, p.STP, ())]
    assert d.status().running is False and d.status().as_dict()["running"] is False

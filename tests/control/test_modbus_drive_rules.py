"""The drive model (control/modbus/drive.py) rule by rule, pure and on its own clock: what it
serves and counts, what feeds its comm-loss trip and what does not, the trip's edges and
actions, the fault reset's edge, the status word it packs, and commissioning, on the shipped
profiles and on profiles changed in one field (a user's own profile is an input too)."""

from __future__ import annotations

from dataclasses import replace

from control.modbus.drive import ILLEGAL_ADDRESS, ILLEGAL_VALUE, DriveModel, DriveWrite
from control.modbus.profile import load_profile

DELTA = load_profile("delta-ms300")  # time + action registers; 100 counts/Hz; 6 Hz/s; reset bit 0x2 at 0x2002
E3 = load_profile("invertek-e3")  # one packed comm-loss code (P-36, bits 15-8); fault code in the status word
ABB = load_profile("abb-acs")  # tripped bit 0x8 in the status word, fault code at 400
RUN, STOP, RESET = 0x0012, 0x0001, 0x0002  # Delta's words


def _running(comm_loss_s: float = 1.0, **kw: float) -> DriveModel:
    m = DriveModel(DELTA, comm_loss_s=comm_loss_s, **kw)
    assert m.write(0x2000, [RUN, 1000], 0.0) is None  # run + 10 Hz in one write (fc 16)
    return m


def test_a_fresh_drive_serves_zeros_counts_nothing_and_trips_after_2_s_by_default() -> None:
    m = DriveModel(DELTA)
    assert m.counters == {"reads": 0, "writes": 0, "comm_loss_trips": 0, "comm_loss_ignored": 0}
    assert m.comm_loss_time_s() == 2.0 and m.regs[0x0903] == 20 and m.regs[0x0902] == 1
    assert m.read(0x2100, 4, 0.0) == [0, 0, 0, 0] and m.counters["reads"] == 1


def test_reads_and_writes_are_counted_per_request_and_per_register() -> None:
    m = _running()
    assert m.counters["writes"] == 2 and m.writes == [DriveWrite(0.0, 0x2000, RUN), DriveWrite(0.0, 0x2001, 1000)]
    m.write(0x2001, [500], 0.25)
    assert m.counters["writes"] == 3 and m.writes[-1] == DriveWrite(0.25, 0x2001, 500)
    m.read(0x2100, 4, 0.3)
    m.read(0x2001, 1, 0.3)
    assert m.counters["reads"] == 2


def test_a_read_answers_the_registers_asked_in_order_and_only_those_the_drive_has() -> None:
    m = _running(comm_loss_s=0.0)
    m.tick(5.0)
    assert m.read(0x2100, 4, 5.0) == [0, 0x0003, 1000, 1000]  # fault, status (operating), readback, output Hz x 100
    assert m.read(0x2001, 1, 5.0) == [1000]  # the setpoint as written
    assert m.read(0x2103, 2, 5.0) == ILLEGAL_ADDRESS  # past the status block
    assert m.read(0x0100, 1, 5.0) == ILLEGAL_ADDRESS  # between the blocks a host reads
    assert m.read(0x0005, 1, 5.0) == [0]  # a gap inside a read block reads as 0


def test_the_drive_clock_starts_at_now_s_and_the_motor_ramps_from_there() -> None:
    m = _running()  # now_s 0 by default: one second of ramp at 6 Hz/s by t = 1
    m.tick(1.0)
    assert m.regs[0x2103] == 600
    late = DriveModel(DELTA, comm_loss_s=1.0, now_s=10.0)
    late.motor.running = True  # started at the front panel: no write ever fed the trip
    late.tick(11.0)
    assert late.fault_code == 0  # the silence is counted from power-on (10 s), exactly 1 s: no trip yet
    late.tick(11.125)
    assert late.fault_code == 54 and late.counters["comm_loss_trips"] == 1


def test_the_default_speed_loop_settles_within_a_second_after_the_ramp() -> None:
    m = _running(comm_loss_s=0.0)  # tau 0.2 s: 10 Hz reached to 0.1 Hz by 2.5 s (the ramp ends at 1.67 s)
    m.tick(2.5)
    assert m.regs[0x2103] >= 990


def test_a_write_to_the_command_reset_or_setpoint_feeds_the_trip_and_a_parameter_write_does_not() -> None:
    m = _running(comm_loss_s=1.0)
    m.write(0x2001, [1000], 0.75)  # setpoint: fed at 0.75
    m.tick(1.5)
    assert m.fault_code == 0 and m.motor.running
    m.write(0x0902, [1], 1.625)  # the comm-loss action: a parameter, not a feed
    m.tick(1.75)
    assert m.fault_code == 0
    m.tick(1.8125)  # 1.0625 s after the last feed
    assert m.fault_code == 54 and m.trip_times_s == [1.8125]


def test_the_trip_comes_strictly_after_the_comm_loss_time_and_never_when_disabled() -> None:
    m = _running(comm_loss_s=1.0)
    m.tick(1.0)
    assert m.fault_code == 0 and m.motor.running
    m.tick(1.0 + 2**-10)
    assert m.fault_code == 54
    off = _running(comm_loss_s=0.0)
    off.tick(100.0)
    assert off.motor.running and off.fault_code == 0
    assert off.counters["comm_loss_trips"] == off.counters["comm_loss_ignored"] == 0


def test_each_trip_and_each_ignored_silence_is_counted_once() -> None:
    m = _running(comm_loss_s=1.0)
    m.tick(1.5)
    m.tick(2.0)
    assert m.counters["comm_loss_trips"] == 1
    m.write(0x2002, [RESET], 2.0)
    m.write(0x2000, [RUN], 2.0)
    m.tick(3.5)
    assert m.counters["comm_loss_trips"] == 2 and m.trip_times_s == [1.5, 3.5]
    unsafe = _running(comm_loss_s=1.0)
    unsafe.commission(1.0, safe=False)
    for t in (1.5, 2.0, 2.5):
        unsafe.tick(t)
    assert unsafe.counters["comm_loss_ignored"] == 1 and unsafe.motor.running
    unsafe.write(0x2001, [1000], 3.0)
    unsafe.tick(4.5)
    assert unsafe.counters["comm_loss_ignored"] == 2 and unsafe.counters["comm_loss_trips"] == 0


def test_a_ramp_action_trip_ramps_the_output_down_and_a_coast_action_cuts_it() -> None:
    ramp = _running(comm_loss_s=1.0)  # action 1: fault and ramp to stop
    ramp.tick(1.0)
    ramp.tick(1.125)
    assert ramp.fault_code == 54 and 0 < ramp.regs[0x2103] < 700 and ramp.regs[0x2101] == 0x0001  # decelerating
    coast = _running(comm_loss_s=1.0)
    coast.write(0x0902, [2], 0.0)  # action 2: fault and coast to stop
    coast.tick(1.0)
    coast.tick(1.125)
    assert coast.fault_code == 54 and coast.regs[0x2103] == 0 and coast.regs[0x2101] == 0x0000


def test_a_fault_resets_only_on_a_rising_reset_bit_at_the_reset_register() -> None:
    m = _running(comm_loss_s=1.0)
    m.tick(1.5)
    assert m.fault_code == 54
    m.write(0x2001, [1000], 1.5)  # a setpoint (its old word has no reset bit): no reset
    m.write(0x2002, [0x0000], 1.5)  # the reset register without the bit: no reset
    m.write(0x2000, [RUN], 1.5)
    assert m.fault_code == 54 and not m.motor.running
    m.write(0x2002, [RESET], 1.5)  # the rising edge: reset
    assert m.fault_code == 0
    m.write(0x2000, [RUN], 1.5)
    m.tick(3.0)
    assert m.fault_code == 54
    m.write(0x2002, [RESET], 3.0)  # the bit still set from the last reset: no edge
    assert m.fault_code == 54
    m.write(0x2002, [0x0000], 3.0)
    m.write(0x2002, [RESET], 3.0)
    assert m.fault_code == 0


def test_a_cleared_front_panel_fault_reads_zero() -> None:
    m = _running(comm_loss_s=0.0)
    m.set_fault(7)
    assert m.regs[0x2100] == 7 and not m.motor.running
    m.set_fault(None)
    assert m.fault_code == 0 and m.regs[0x2100] == 0


def test_the_output_still_ramping_below_1_hz_says_decelerating() -> None:
    m = DriveModel(DELTA, comm_loss_s=0.0)
    m.write(0x2000, [RUN, 50], 0.0)  # 0.5 Hz
    m.tick(3.0)
    m.write(0x2000, [STOP], 3.0)
    m.tick(3.01)
    assert 0 < m.motor.actual_rpm < 1 and m.regs[0x2101] == 0x0001


def test_the_tripped_bits_are_set_only_while_faulted() -> None:
    m = DriveModel(ABB, comm_loss_s=0.0)
    m.write(0, [0x047E], 0.0)
    m.write(0, [0x047F, 20000], 0.0)
    assert m.regs[3] == ABB.running_word == 0x0337
    m.set_fault(ABB.drive_fault_code)
    assert m.regs[3] == ABB.stopped_word | 0x0008 == 0x023B and m.regs[400] == 0x2310
    m.set_fault(None)
    assert m.regs[3] == 0x0233


def test_the_e3_packs_state_and_fault_code_into_one_status_word() -> None:
    m = DriveModel(E3, comm_loss_s=0.0)
    m.write(1, [0x0001, 100], 0.0)
    assert m.regs[6] == 0x0100  # running, no fault
    m.set_fault(E3.drive_fault_code)
    assert m.regs[6] == 0x0203  # tripped (high byte 2), code 3 (low byte)
    assert E3.is_tripped(m.regs[6], m.regs[6]) and E3.fault_code(m.regs[6]) == 3


def test_a_fault_code_at_a_shift_reads_back_as_itself() -> None:
    """A user's profile may place the code anywhere in its word: the model packs it where the
    profile decodes it, in a status word (packed) or a register of its own."""
    packed = replace(E3, fault_mask=0x00F0, fault_shift=4, tripped_mask=0x0F00, tripped_value=0x0200)
    m = DriveModel(packed, comm_loss_s=0.0)
    m.set_fault(3)
    assert m.regs[6] == 0x0230 and packed.fault_code(m.regs[6]) == 3
    own = replace(DELTA, fault_mask=0xFF00, fault_shift=8)
    d = DriveModel(own, comm_loss_s=0.0)
    d.set_fault(54)
    assert d.regs[0x2100] == 54 << 8 and own.fault_code(d.regs[0x2100]) == 54


def test_a_valid_comm_loss_code_written_by_a_host_is_taken() -> None:
    m = DriveModel(E3, comm_loss_s=0.0)
    assert m.write(164, [4 << 8], 0.0) is None and m.comm_loss_time_s() == 3.0
    assert m.write(164, [9 << 8], 0.0) == ILLEGAL_VALUE


def test_commissioning_a_packed_code_picks_the_nearest_safe_trip_or_disables_it() -> None:
    for seconds, code, time_s in ((0.0, 0, 0.0), (0.03, 1, 0.03), (0.3, 2, 0.3), (1.0, 3, 1.0), (3.0, 4, 3.0)):
        m = DriveModel(E3, comm_loss_s=seconds)
        assert m.regs[164] == code << 8 and m.comm_loss_time_s() == time_s, seconds
        assert E3.comm_loss_setting(m.regs).safe is (code != 0)
    m = DriveModel(E3, comm_loss_s=1.0)
    m.commission(1.0, safe=False)  # no unsafe timed code on an E3: the trip is disabled
    assert m.regs[164] == 0 and E3.comm_loss_setting(m.regs).time_s == 0.0


def test_commissioning_an_unsafe_action_takes_the_profiles_first_unsafe_one() -> None:
    m = DriveModel(DELTA)
    m.commission(2.0, safe=False)
    assert m.regs[0x0902] == 0 and DELTA.comm_loss_setting(m.regs).action == "warn and keep operating"
    cl = DELTA.comm_loss
    listed = replace(DELTA, comm_loss=replace(cl, actions={1: "fault and ramp", 5: "keep running", 6: "warn"}))
    m = DriveModel(listed)
    m.commission(2.0, safe=False)
    assert listed.comm_loss_setting(m.regs).action == "keep running" and not listed.comm_loss_setting(m.regs).safe
    unlisted = replace(DELTA, comm_loss=replace(cl, actions={}, safe_actions=(1,), recommended_action=1))
    m = DriveModel(unlisted)
    m.commission(2.0, safe=False)  # no actions listed: action 0, which is not a safe one
    assert m.regs[0x0902] == 0 and not unlisted.comm_loss_setting(m.regs).safe

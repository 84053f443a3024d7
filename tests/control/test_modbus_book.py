"""The drive emulator by the book (issue 42), checked by an independent master: Debian's
``mbpoll`` (libmodbus) on the emulator's real pty reads and writes every register each
shipped profile names and gets exception 1, 2 and 3 for an illegal function, address and
value; what mbpoll cannot send (an unknown function, a bad quantity or byte count, fc 22/23,
malformed frames) goes raw over the pty; pymodbus's client sees the same answers; the status
word follows the output after a comm-loss trip. The pure drive model's write rules too."""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
from collections.abc import Iterator

import pytest
import serial

from control.modbus.drive import ILLEGAL_ADDRESS, ILLEGAL_VALUE, DriveModel
from control.modbus.emulator import DriveEmulator
from control.modbus.link import ModbusMill
from control.modbus.profile import SHIPPED, DriveProfile, load_profile, read_blocks
from tests.waiting import wait_until

UNIT = 3
EXC = {1: "Illegal function", 2: "Illegal data address", 3: "Illegal data value"}


@pytest.fixture(scope="module", params=SHIPPED)
def drive(request) -> Iterator[DriveEmulator]:
    with DriveEmulator(load_profile(request.param), unit=UNIT, speed=5.0) as emu:  # fast ramps: the trip test
        emu.open_pty()
        yield emu


def mbpoll(drive: DriveEmulator, *opts: str, values: tuple[int, ...] = ()) -> tuple[int, str]:
    """``mbpoll`` once (RTU, PDU addresses, 8N1: a pty takes no parity) -> (exit code, output)."""
    exe = shutil.which("mbpoll")
    assert exe, "mbpoll is not installed (scripts/bootstrap.sh installs it: apt-get install mbpoll)"
    r = subprocess.run([exe, "-m", "rtu", "-b", "19200", "-P", "none", "-a", str(UNIT), "-0", "-1", "-o", "1",
                        *opts, drive.url, *map(str, values)], capture_output=True, text=True, timeout=30)
    return r.returncode, r.stdout + r.stderr


def mb_read(drive: DriveEmulator, address: int, count: int = 1) -> list[int]:
    code, out = mbpoll(drive, "-t", "4", "-r", str(address), "-c", str(count))
    assert code == 0, out
    got = {int(a): int(v) for a, v in re.findall(r"^\[(\d+)\]:\s+(-?\d+)", out, re.M)}
    return [got[a] & 0xFFFF for a in range(address, address + count)]


def mb_refused(drive: DriveEmulator, exception: int, *opts: str, values: tuple[int, ...] = ()) -> None:
    code, out = mbpoll(drive, *opts, values=values)
    assert code != 0 and EXC[exception] in out, (opts, values, out)


def valid_writes(p: DriveProfile) -> dict[int, int]:
    """A value each writable register takes (a drive left stopped, its trip safe)."""
    cl = p.comm_loss
    w = {p.setpoint_register: p.setpoint.to_counts(10.0), p.reset_register: 0, p.control_register: p.stop_word}
    if cl.time_register is not None:
        w[cl.time_register] = int(2 * cl.time_counts_per_s)
    if cl.action_register is not None:
        w[cl.action_register] = int(cl.recommended_action or 0)
    if cl.code_register is not None:
        w[cl.code_register] = (int(cl.recommended_code or 0) << cl.code_shift) & cl.code_mask
    return w


def test_mbpoll_reads_and_writes_every_register_of_the_profile(drive: DriveEmulator) -> None:
    p = drive.profile
    for start, n in read_blocks(p.all_registers):  # every named register, the gaps between them read as 0
        assert mb_read(drive, start, n) == drive.registers(start, n)
    for address, value in valid_writes(p).items():
        code, out = mbpoll(drive, "-t", "4", "-r", str(address), values=(value,))  # fc 6
        assert code == 0 and "Written 1 references" in out, out
        assert mb_read(drive, address) == [value]
    block = (p.control_register, p.setpoint_register)
    assert block[1] == block[0] + 1  # every shipped profile: one fc 16 writes both
    code, out = mbpoll(drive, "-t", "4", "-r", str(block[0]), values=(p.stop_word, p.setpoint.to_counts(12.5)))
    assert code == 0 and "Written 2 references" in out, out
    assert drive.motor.setpoint_rpm == pytest.approx(12.5, abs=0.05) and not drive.motor.running  # the model took it
    read_only = sorted(set(p.all_registers) - p.writable_registers)
    assert read_only and p.status_register in read_only and p.output_register in read_only
    for address in read_only:  # status, output, fault, readback, identity: exception 2, unchanged
        before = drive.registers(address)
        mb_refused(drive, 2, "-t", "4", "-r", str(address), values=(before[0] ^ 1,))
        assert drive.registers(address) == before


def test_mbpoll_gets_the_exception_for_an_illegal_function_address_and_value(drive: DriveEmulator) -> None:
    p = drive.profile
    for opts, values in ((("-t", "3"), ()), (("-t", "0"), ()), (("-t", "1"), ()), (("-t", "0"), (1,))):
        mb_refused(drive, 1, *opts, "-r", str(p.status_register), values=values)  # fc 4, 1, 2, 5
    top = max(p.all_registers)
    mb_refused(drive, 2, "-t", "4", "-r", str(top + 1))  # no such register
    mb_refused(drive, 2, "-t", "4", "-r", str(top), "-c", "2")  # one past the end
    held = drive.registers(p.setpoint_register)
    for counts in (p.setpoint.to_counts(p.max_hz) + 1, 65535):  # above max_hz (65535 is not -0.01 Hz)
        mb_refused(drive, 3, "-t", "4", "-r", str(p.setpoint_register), values=(counts,))
    assert drive.registers(p.setpoint_register) == held
    cl = p.comm_loss
    if cl.action_register is not None:
        mb_refused(drive, 3, "-t", "4", "-r", str(cl.action_register), values=(max(cl.actions) + 1,))
    if cl.code_register is not None:
        mb_refused(drive, 3, "-t", "4", "-r", str(cl.code_register), values=((max(cl.codes) + 1) << cl.code_shift,))


# -- raw frames over the pty (what mbpoll will not send) ------------------------------------
def _crc(body: bytes) -> bytes:
    from pymodbus.framer import FramerRTU

    return FramerRTU.compute_CRC(body).to_bytes(2, "big")


def frame(*pdu: bytes) -> bytes:
    body = bytes([UNIT]) + b"".join(pdu)
    return body + _crc(body)


def exception_reply(fc: int, code: int) -> bytes:
    return frame(bytes([fc | 0x80, code]))


@pytest.fixture(scope="module")
def line(drive: DriveEmulator) -> Iterator[serial.Serial]:
    port = serial.serial_for_url(drive.url, timeout=1.0)
    try:
        yield port
    finally:
        port.close()


def ask(line: serial.Serial, request: bytes, answer_len: int) -> bytes:
    line.reset_input_buffer()
    line.write(request)
    return line.read(answer_len)


def silent(line: serial.Serial, request: bytes) -> None:
    """No answer to ``request`` within 0.2 s (which is also RTU's silence after it)."""
    line.reset_input_buffer()
    line.write(request)
    line.timeout = 0.2
    try:
        assert line.read(1) == b""
    finally:
        line.timeout = 1.0


def test_raw_requests_get_the_protocols_exceptions(drive: DriveEmulator, line: serial.Serial) -> None:
    p = drive.profile
    assert ask(line, frame(b"\x63\x00\x00\x00\x01"), 5) == exception_reply(0x63, 1)  # unknown function
    for count in (0, 126, 0xFFFF):
        assert ask(line, frame(b"\x03", struct.pack(">HH", p.status_register, count)), 5) == exception_reply(3, 3)
    n = len(drive.writes)
    bad16 = frame(b"\x10", struct.pack(">HHB", p.setpoint_register, 1, 4), struct.pack(">H", 100))
    assert ask(line, bad16, 5) == exception_reply(16, 3)  # byte count 4 for 1 register
    assert ask(line, frame(b"\x16", struct.pack(">HHH", p.setpoint_register, 0, 500)), 5) == exception_reply(22, 1)
    fc23 = frame(b"\x17", struct.pack(">HHHHBH", p.status_register, 1, p.setpoint_register, 1, 2, 700))
    assert ask(line, fc23, 5) == exception_reply(23, 1)
    assert drive.writes[n:] == []  # none of them reached the drive model
    assert ask(line, frame(b"\x03\x00"), 5) == exception_reply(3, 3)  # a CRC-valid fc 3 of the wrong length


@pytest.fixture(scope="module")
def delta() -> Iterator[tuple[DriveEmulator, serial.Serial]]:
    """One profile for the framing (the framer does not know profiles)."""
    emu = DriveEmulator(load_profile("delta-ms300"), unit=UNIT)
    emu.open_pty()
    port = serial.serial_for_url(emu.url, timeout=1.0)
    try:
        yield emu, port
    finally:
        port.close()
        emu.close()


def test_after_a_malformed_frame_the_next_valid_one_is_answered(delta: tuple[DriveEmulator, serial.Serial]) -> None:
    drive, line = delta
    p = drive.profile
    read = frame(b"\x03", struct.pack(">HH", p.status_register, 1))
    answer = frame(b"\x03\x02", struct.pack(">H", drive.registers(p.status_register)[0]))
    assert ask(line, read, 7) == answer
    truncated = read[:5]  # the first bytes of a request, then nothing
    long16 = bytes([UNIT, 0x10]) + struct.pack(">HHB", p.setpoint_register, 100, 200)  # promises 200 bytes more
    for junk in (truncated, long16, b"\xff\x00\x13\x37", read[:-1] + bytes([read[-1] ^ 0xFF])):
        silent(line, junk)  # no answer, and RTU's silence: the next request starts afresh
        assert ask(line, read, 7) == answer, junk.hex(" ")
    for junk in (truncated, b"\x00\xff"):  # no silence in between: the framer hunts past the junk
        assert ask(line, junk + read, 7) == answer, junk.hex(" ")


def test_pymodbus_sees_the_same_answers_and_fc16_reaches_the_drive(drive: DriveEmulator) -> None:
    from pymodbus.client import ModbusSerialClient

    p = drive.profile
    c = ModbusSerialClient(drive.url, baudrate=19200, timeout=1.0, retries=0)
    assert c.connect()
    try:
        assert c.read_input_registers(p.status_register, count=1, device_id=UNIT).exception_code == 1
        assert c.mask_write_register(address=p.setpoint_register, device_id=UNIT).exception_code == 1
        assert c.readwrite_registers(read_address=p.status_register, read_count=1, address=p.setpoint_register,
                                     values=[1], device_id=UNIT).exception_code == 1
        assert c.read_holding_registers(max(p.all_registers) + 1, count=1, device_id=UNIT).exception_code == 2
        assert c.write_register(p.output_register, 1, device_id=UNIT).exception_code == 2
        assert c.write_register(p.setpoint_register, 65535, device_id=UNIT).exception_code == 3
        rr = c.write_registers(p.control_register, [p.stop_word, p.setpoint.to_counts(7.5)], device_id=UNIT)
        assert not rr.isError() and (rr.address, rr.count) == (p.control_register, 2)
        assert drive.motor.setpoint_rpm == pytest.approx(7.5, abs=0.05)
    finally:
        c.close()


def test_the_status_word_follows_the_output_after_a_comm_loss_trip(drive: DriveEmulator) -> None:
    """The audit: the status word said stopped while the output still ramped down. Now it
    says decelerating (Delta's 01, the generic profile's bit 2) while a ramp trip runs down,
    and a coasting trip switches the output off at once."""
    p = drive.profile
    drive.commission(2.0)  # the ramp up under a long comm-loss time: a starved test process polls late
    samples: list[tuple[int, int, bool]] = []  # (status word, output counts, tripped) of one read
    regs = sorted({p.status_register, p.output_register} | (set() if p.tripped_mask else {p.fault_register}))
    assert regs[-1] - regs[0] < 8  # one read, as a host's: the words of one instant

    def sample() -> bool:
        block = drive.registers(regs[0], regs[-1] - regs[0] + 1)
        sw, out = block[p.status_register - regs[0]], block[p.output_register - regs[0]]
        tripped = p.is_tripped(sw, 0 if p.tripped_mask else block[p.fault_register - regs[0]])
        samples.append((sw, out, tripped))
        return tripped and out == 0

    try:
        with ModbusMill(drive.mill_url(), timeout_s=1.0) as mill:
            mill.set_rpm(20.0)
            mill.start()
            wait_until(lambda: mill.heartbeat().actual_rpm >= 10.0, 10, "the ramp up")
        drive.commission(0.3)  # then a short one, with nobody writing: the trip while the motor runs fast
        wait_until(sample, 10, "the comm-loss trip and the motor at 0 Hz", poll_s=0.005)  # nobody writes
    finally:
        drive.commission(2.0)
    tripped = [s for s in samples if s[2]]
    decel = p.decelerating_word
    ramps = p.comm_loss_ramps(drive.model.regs)
    for sw, out, _ in tripped:
        assert not p.is_running(sw)
        if out:  # the output still runs down: the word says so
            assert ramps and decel is not None and (sw & ~p.tripped_mask) == decel, (hex(sw), out)
    assert (tripped[-1][0] & ~p.tripped_mask & ~(p.fault_mask if p.fault_register == p.status_register else 0)
            ) == p.stopped_word
    if ramps:
        assert any(out for _, out, _ in tripped)  # a ramp trip was seen ramping (not coasting)


# -- the drive model's write rules, pure ---------------------------------------------------
def test_the_drive_model_refuses_writes_by_the_book_and_applies_none_of_them() -> None:
    p = load_profile("delta-ms300")
    m = DriveModel(p)
    for address, words in (([0x2100], [1]), ([0x2101], [3]), ([0x2103], [100]), ([0x0001], [5])):
        assert m.write_error(address[0], words) == ILLEGAL_ADDRESS, hex(address[0])
    assert m.write(0x2000, [0x0012, 1000, 0, 0], 0.0) == ILLEGAL_ADDRESS  # runs past 0x2002: nothing applied
    assert not m.motor.running and m.writes == []
    for address, words in ((0x2001, [65535]), (0x2001, [6001]), (0x0902, [7]), (0x2000, [0x12, 6001])):
        assert m.write(address, words, 0.0) == ILLEGAL_VALUE, (hex(address), words)
    assert m.writes == [] and m.regs[0x2000] == 0
    assert m.write(0x2001, [6000], 0.0) is None and m.motor.setpoint_rpm == 60.0  # max_hz itself is taken
    e3 = load_profile("invertek-e3")
    assert DriveModel(e3).write_error(164, [9 << 8]) == ILLEGAL_VALUE  # P-36 code 9: not a code


def test_the_status_word_says_decelerating_and_a_drive_fault_coasts() -> None:
    p = load_profile("delta-ms300")
    m = DriveModel(p, comm_loss_s=0.0, tau_s=0.01)  # no trip: only the commands act
    m.write(p.setpoint_register, [1000], 0.0)
    m.write(p.control_register, [0x0012], 0.0)
    m.tick(5.0)
    assert m.regs[0x2101] == 0x0003 and m.regs[0x2103] == 1000
    m.write(p.control_register, [p.stop_word], 5.0)
    m.tick(5.5)  # 6 Hz/s: 7 Hz left
    assert m.regs[0x2101] == 0x0001 and 0 < m.regs[0x2103] < 1000  # decelerating, not stopped
    m.tick(8.0)
    assert m.regs[0x2101] == 0x0000 and m.regs[0x2103] == 0
    m.write(p.control_register, [0x0012], 8.0)
    m.tick(12.0)
    m.set_fault(p.drive_fault_code)  # the power stage trips: output off at once (coast)
    assert m.regs[0x2103] == 0 and m.regs[0x2101] == 0x0000 and m.regs[0x2100] == p.drive_fault_code


def test_find_request_frames_by_layout_by_crc_and_hunts_past_noise() -> None:
    from control.modbus.server import find_request

    read = frame(b"\x03\x21\x00\x00\x04")
    assert find_request(read) == (0, 8)
    assert find_request(read + b"\x01\x02") == (0, 8)  # what follows a complete frame is not its part
    assert find_request(read[:6]) is None  # still arriving: wait
    assert find_request(b"\x00\xff\x13" + read) == (3, 11)  # noise before it
    assert find_request(read[:5] + read) == (5, 13)  # a broken frame before it, no silence between
    assert find_request(b"\xee" * 4 + read, start=4) == (4, 12)  # bytes before a silence are skipped
    odd = frame(b"\x63\x01")
    assert find_request(odd) == (0, len(odd))  # an unknown function: the frame its CRC closes
    short16 = frame(b"\x10", struct.pack(">HHB", 1, 1, 4), b"\x00\x64")  # byte count 4, 2 bytes follow
    assert find_request(short16) == (0, len(short16))  # closed by its CRC: the decoder answers exception 3
    assert find_request(short16[:-1]) is None

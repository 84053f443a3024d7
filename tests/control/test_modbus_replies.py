"""Every reply checked (issue 42): a drive that answers with another function code, byte
count, echo, unit, exception or CRC than its request asks for is a link fault (TimeoutError:
the loop's safe state), never data. Over a real pty: what pymodbus's own client lets through
beside what the link makes of it; the pure checker on hand-made frames."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator

import pytest

from control.modbus.emulator import DriveEmulator, DriveFaults
from control.modbus.link import ModbusMill
from control.modbus.profile import load_profile
from control.modbus.reply import READ, WRITE, BadReply, Reply, Request, check_reply
from tests.cli import assert_one_line_error, cli
from tests.twin.test_mill_worker import Sink
from twin.live.mill import MillWorker
from twin.live.snapshots import Latest, MillSnapshot

DELTA = load_profile("delta-ms300")
UNIT = 5


def _crc(body: bytes) -> bytes:
    from pymodbus.framer import FramerRTU

    return FramerRTU.compute_CRC(body).to_bytes(2, "big")


def _frame(*parts: int) -> bytes:
    body = bytes(parts)
    return body + _crc(body)


def _reads(f: Callable[[bytes], bytes]) -> Callable[[bytes], bytes]:
    return lambda a: f(a) if a[1] == 3 else a


def _writes(f: Callable[[bytes], bytes]) -> Callable[[bytes], bytes]:
    return lambda a: f(a) if a[1] == 6 else a


# name -> (rewrite of the drive's replies (without CRC), the request it spoils, the link's reason)
WRONG = {
    "fc 0x04 to 0x03": (_reads(lambda a: a[:1] + b"\x04" + a[2:]), READ, "function 0x04 for unit 5 function 0x03"),
    "odd byte count": (_reads(lambda a: a[:2] + bytes([a[2] + 1]) + a[3:] + b"\x00"), READ, "not the 13-byte answer"),
    "short byte count": (_reads(lambda a: a[:2] + bytes([a[2] - 2]) + a[3:-2]), READ, "not the 13-byte answer"),
    "exception of fc 4": (_reads(lambda a: a[:1] + b"\x84\x02"), READ, "function 0x84 for unit 5 function 0x03"),
    "undefined exception": (_reads(lambda a: a[:1] + b"\x83\x63"), READ, "exception code 99"),
    "bytes after it": (_reads(lambda a: a + _crc(a) + b"\x00"), READ, "not the 13-byte answer"),
    "echo value": (_writes(lambda a: a[:4] + bytes([a[4], a[5] ^ 1])), WRITE, "echo (8193, 201) of a write of 200"),
    "echo address": (_writes(lambda a: a[:3] + bytes([a[3] ^ 1]) + a[4:]), WRITE, "echo (8192, 200)"),
}


@pytest.fixture(scope="module")
def drive() -> Iterator[DriveEmulator]:
    with DriveEmulator(DELTA, unit=UNIT) as emu:
        emu.open_pty()
        yield emu


@pytest.fixture
def wrong(drive: DriveEmulator) -> Iterator[Callable[[str], None]]:
    """``wrong(name)``: the drive answers as ``WRONG[name]`` until the test ends."""
    yield lambda name: setattr(drive, "faults", DriveFaults(rewrite=WRONG[name][0]))
    drive.faults = DriveFaults()


def _pymodbus_alone(drive: DriveEmulator, kind: int) -> object:
    """What pymodbus's own client returns for the request the fault spoils (no exception)."""
    from pymodbus.client import ModbusSerialClient

    c = ModbusSerialClient(drive.url, baudrate=19200, timeout=0.3, retries=0)
    assert c.connect()
    try:
        if kind == READ:
            return c.read_holding_registers(DELTA.status_register - 1, count=4, device_id=UNIT)
        return c.write_register(DELTA.setpoint_register, 200, device_id=UNIT)
    finally:
        c.close()


@pytest.mark.parametrize("name", list(WRONG))
def test_a_wrong_reply_is_a_link_fault_that_pymodbus_alone_lets_through(drive, wrong, name: str) -> None:
    _, kind, reason = WRONG[name]
    wrong(name)
    rr = _pymodbus_alone(drive, kind)  # the library believes it: data (or an exception for this request)
    assert getattr(rr, "registers", None) or getattr(rr, "exception_code", None), rr
    with ModbusMill(drive.mill_url(), timeout_s=1.0, retries=0, refuse_unsafe=False) as mill:
        with pytest.raises(TimeoutError, match=re.escape(reason)):
            if kind == READ:
                mill.status()
            else:
                mill.set_rpm(2.0)
        assert not mill.connected and mill.stats["bad_replies"] == 1
        drive.faults = DriveFaults()
        assert mill.status().fault is None and mill.connected  # a good reply is data again


def test_pymodbus_itself_drops_another_units_reply_and_a_bad_crc(drive: DriveEmulator) -> None:
    """What the link leaves to pymodbus (and the emulator's corrupt_p and unit tests in
    test_modbus.py show end to end): a frame from another unit and a bad CRC never decode."""
    for faults in (DriveFaults(rewrite=lambda a: bytes([UNIT + 1]) + a[1:]), DriveFaults(corrupt_p=1.0)):
        drive.faults = faults
        try:
            with ModbusMill(drive.mill_url(), timeout_s=0.25, retries=0, refuse_unsafe=False) as mill:
                with pytest.raises(TimeoutError, match="after 1 tries"):
                    mill.status()
        finally:
            drive.faults = DriveFaults()


@pytest.mark.parametrize("cmd", [("status",), ("check",), ("start",), ("set-rpm", "5"), ("stop",)],
                         ids=["status", "check", "start", "set-rpm", "stop"])
def test_every_mill_command_refuses_a_drive_that_answers_fc_4_to_fc_3(drive, wrong, cmd) -> None:
    """The audit's case: each command succeeded and used the 0x04 reply's data. Now each is
    one line, exit 2; a start is never sent on it (it reads the drive first)."""
    wrong("fc 0x04 to 0x03")
    n = len(drive.writes)
    assert_one_line_error(cli("mill", "--retries", "0", "--timeout", "1", drive.mill_url(), *cmd), "no valid answer",
                          "function 0x04 for unit 5 function 0x03")
    applied = [(w.address, w.value) for w in drive.writes[n:]]
    assert (DELTA.control_register, DELTA.run_words[0]) not in applied
    if cmd == ("stop",):  # the stop itself went (a write, answered right); the status after it did not
        assert applied == [(DELTA.control_register, DELTA.stop_word)]


def test_the_mill_worker_treats_a_wrong_reply_as_a_lost_link(drive, wrong) -> None:
    wrong("fc 0x04 to 0x03")
    with ModbusMill(drive.mill_url(), timeout_s=0.3, retries=0, refuse_unsafe=False) as link:
        sink, box = Sink(), Latest(MillSnapshot())
        snap = MillWorker(link, sink, box, now_s=lambda: 0.0).cycle()
        assert not snap.connected and snap.status is None and "mill_link" in sink.faults


# -- the checker, pure --------------------------------------------------------------------
READ2 = Request(1, READ, 0x2100, count=2)
WRITE1 = Request(1, WRITE, 0x2001, value=500)
OK_READ = _frame(1, 3, 4, 0, 7, 0x12, 0x34)
OK_WRITE = _frame(1, 6, 0x20, 0x01, 0x01, 0xF4)


def test_check_reply_takes_the_exact_answer_after_line_noise() -> None:
    assert check_reply(READ2, OK_READ) == Reply(registers=(7, 0x1234))
    assert check_reply(READ2, b"\x00\xff" + OK_READ) == Reply(registers=(7, 0x1234))  # noise before the frame
    assert check_reply(WRITE1, OK_WRITE) == Reply()
    assert check_reply(READ2, _frame(1, 0x83, 2)) == Reply(exception=2)
    assert check_reply(WRITE1, _frame(1, 0x86, 3)) == Reply(exception=3)


@pytest.mark.parametrize(("req", "raw", "why"), [
    (READ2, _frame(1, 4, 4, 0, 7, 0x12, 0x34), "function 0x04"),
    (READ2, _frame(2, 3, 4, 0, 7, 0x12, 0x34), "unit 2"),
    (READ2, _frame(1, 3, 5, 0, 7, 0x12, 0x34, 0), "9-byte answer"),  # odd byte count, frame consistent
    (READ2, _frame(1, 3, 2, 0, 7), "9-byte answer"),
    (READ2, _frame(1, 3, 6, 0, 7, 0x12, 0x34, 0, 0), "9-byte answer"),
    (READ2, OK_READ[:-1] + bytes([OK_READ[-1] ^ 1]), "9-byte answer"),  # CRC
    (READ2, OK_READ + b"\x00", "9-byte answer"),  # bytes after the frame
    (READ2, _frame(1, 0x84, 2), "function 0x84"),
    (READ2, _frame(1, 0x83, 0), "exception code 0"),
    (READ2, OK_WRITE, "9-byte answer"),  # a late answer to another request
    (WRITE1, _frame(1, 6, 0x20, 0x01, 0x01, 0xF5), "echo (8193, 501)"),
    (WRITE1, _frame(1, 6, 0x20, 0x02, 0x01, 0xF4), "echo (8194, 500)"),
    (WRITE1, OK_READ, "8-byte answer"),
    (WRITE1, b"", "0 bytes"),
])
def test_check_reply_refuses_anything_else(req: Request, raw: bytes, why: str) -> None:
    with pytest.raises(BadReply, match=re.escape(why)):
        check_reply(req, raw)

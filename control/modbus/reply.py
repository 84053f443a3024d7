"""A drive's reply checked against the request it answers, on the raw bytes (pure).

What pymodbus 3.16's client checks before a reply reaches the link: the CRC (a frame with
a bad CRC is never decoded: the client waits on and resends after its timeout) and the unit
id (a frame from another unit is skipped; a mismatch raises). What it lets through, each
reproduced in ``tests/control/test_modbus_replies.py``: any function code it knows (a 0x04
reply to a 0x03 request decodes to a ``ReadInputRegistersResponse`` with ``.registers``), an
exception reply of another function, a byte count that is odd or disagrees with the request's
quantity when the frame is self-consistent (it yields ``byte_count // 2`` registers), bytes
after the frame (swallowed), and a write's echo (never compared).

:func:`check_reply` checks all of it on the bytes pymodbus decoded the reply from (the
client's ``trace_packet`` hands them over): the reply is the frame at their end, after any
line noise (pymodbus hunts past leading bytes as well); it must carry the request's unit and
function (or that function's exception, with a code the protocol defines), the byte count
``2 x quantity`` for a read, the request's own address and value for a write, and a valid CRC.
Anything else raises :class:`BadReply`: the link treats it as no answer (a link fault), never
as data.
"""

from __future__ import annotations

from dataclasses import dataclass

READ = 3
WRITE = 6

EXCEPTIONS = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value", 4: "server device failure",
    5: "acknowledge", 6: "server device busy", 8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}
"""The exception codes of the Modbus application protocol (v1.1b3, section 7)."""


class BadReply(ValueError):
    """A reply that is not the answer to the request (the detail says why)."""


@dataclass(frozen=True)
class Request:
    """What the link asked: ``function`` READ (``count`` registers from ``address``) or WRITE
    (``value`` at ``address``), of drive ``unit``."""

    unit: int
    function: int
    address: int
    count: int = 1
    value: int = 0


@dataclass(frozen=True)
class Reply:
    """A checked answer: the registers read (empty for a write), or the drive's exception code."""

    registers: tuple[int, ...] = ()
    exception: int | None = None


def _crc(frame: bytes) -> int:
    from pymodbus.framer import FramerRTU

    return int(FramerRTU.compute_CRC(frame))


def _frame_at_end(raw: bytes, size: int) -> bytes | None:
    """The last ``size`` bytes of ``raw`` when they are a frame with a valid CRC."""
    if len(raw) < size:
        return None
    frame = raw[len(raw) - size:]
    return frame if _crc(frame[:-2]) == int.from_bytes(frame[-2:], "big") else None


def expected_size(req: Request) -> int:
    """RTU size of the normal answer: unit, function, byte count, 2 x count, CRC for a read;
    the 8-byte echo for a write."""
    return 5 + 2 * req.count if req.function == READ else 8


def check_reply(req: Request, raw: bytes) -> Reply:
    """The reply to ``req`` in ``raw`` (see module doc), or :class:`BadReply`."""
    frame = _frame_at_end(raw, expected_size(req))
    if frame is not None and frame[0] == req.unit and frame[1] == req.function:
        return _normal(req, frame)
    exc = _frame_at_end(raw, 5)
    if exc is not None and exc[0] == req.unit and exc[1] == req.function | 0x80:
        if exc[2] not in EXCEPTIONS:
            raise BadReply(f"exception code {exc[2]} (not one the protocol defines)")
        return Reply(exception=exc[2])
    head = frame or exc
    if head is not None:
        raise BadReply(f"unit {head[0]} function 0x{head[1]:02X} for unit {req.unit} function 0x{req.function:02X}")
    raise BadReply(f"{len(raw)} bytes ({raw[:16].hex(' ')}{' ...' if len(raw) > 16 else ''}) are not"
                   f" the {expected_size(req)}-byte answer to function 0x{req.function:02X} (nor an exception)")


def _normal(req: Request, frame: bytes) -> Reply:
    if req.function == READ:
        if frame[2] != 2 * req.count:
            raise BadReply(f"byte count {frame[2]} for {req.count} registers")
        data = frame[3:-2]
        return Reply(registers=tuple(int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2)))
    echo = (int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big"))
    if echo != (req.address, req.value):
        raise BadReply(f"echo {echo} of a write of {req.value} to {req.address}")
    return Reply()


__all__ = ["EXCEPTIONS", "READ", "WRITE", "BadReply", "Reply", "Request", "check_reply", "expected_size"]

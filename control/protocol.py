"""The mill line protocol: pure framing, no I/O (see ``docs/mill-protocol.md``).

A frame is one line of printable ASCII::

    $<seq>,<CMD>[,<arg>...]*<crc>\\n

- ``seq``: decimal sequence number 0..65535 chosen by the host; a resend of the same
  request reuses it, the device answers with the same number.
- ``CMD``: 2-3 upper-case letters (``SET RUN STP STA HB`` from the host,
  ``ACK NAK`` from the device).
- ``crc``: CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of the bytes between ``$`` and
  ``*`` (exclusive), four upper-case hex digits.
- at most :data:`MAX_LINE` bytes including ``$`` and ``\\n``; ``\\r`` is ignored.

This module is the protocol object of the link (in the spirit of pyserial's
``serial.threaded``): :class:`FrameDecoder` turns bytes into frames, :func:`encode_frame`
turns frames into bytes. The transport (serial port, pty, socket) lives in
``control.driver`` and ``control.emulator``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from control.errors import ControlError

MAX_LINE = 64
"""Longest valid frame in bytes, ``$`` to ``\\n`` inclusive."""

SEQ_MOD = 65536
"""Sequence numbers run 0..65535 and wrap."""

# Host -> device commands.
SET = "SET"  #: ``SET,<rpm>``: absolute speed setpoint in rpm (idempotent).
RUN = "RUN"  #: start the motor (clears a watchdog fault).
STP = "STP"  #: stop the motor (ramps down to 0 rpm).
STA = "STA"  #: read status.
HB = "HB"  #: heartbeat: feeds the watchdog, answered with the status.
HOST_COMMANDS = (SET, RUN, STP, STA, HB)
WATCHDOG_COMMANDS = frozenset({SET, RUN, STP, HB})
"""Commands that feed the device watchdog: only the controlling host sends them. ``STA``
does not, so a status poller cannot keep a motor running whose controller died."""
READ_ONLY_COMMANDS = frozenset({STA, HB})
"""Commands that change nothing on the board: always answered with a fresh status,
never from the resend cache."""

# Device -> host replies.
ACK = "ACK"
NAK = "NAK"

# NAK reasons.
NAK_CRC = "CRC"  #: checksum mismatch (the host should resend at once)
NAK_CMD = "CMD"  #: unknown command
NAK_ARG = "ARG"  #: bad or missing argument
NAK_RANGE = "RANGE"  #: setpoint outside 0..max rpm
NAK_FAULT = "FAULT"  #: the drive is faulted and refuses the command

# Device fault codes (``OK`` on the wire means no fault).
FAULT_NONE = "OK"
FAULT_WATCHDOG = "WDOG"  #: no valid frame for the watchdog time while running
FAULT_DRIVE = "DRIVE"  #: drive/motor fault reported by the power stage

_BODY_RE = re.compile(rb"^(\d{1,5}),([A-Z]{2,3})((?:,[0-9A-Za-z.+\-]{1,16}){0,6})$")
_CRC_RE = re.compile(rb"^[0-9A-F]{4}$")


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


@dataclass(frozen=True)
class Frame:
    """A decoded, checksum-valid frame: sequence number, command and its arguments."""

    seq: int
    cmd: str
    args: tuple[str, ...] = ()

    @property
    def payload(self) -> str:
        """``CMD[,arg...]``: what the device compares to detect a resend."""
        return ",".join((self.cmd, *self.args))


@dataclass(frozen=True)
class BadFrame:
    """A line that is not a valid frame. ``seq`` is set when it could still be read."""

    reason: str  # "crc" | "syntax" | "too_long" | "binary"
    raw: bytes
    seq: int | None = None


@dataclass(frozen=True)
class MillStatus:
    """What the motor board reports: setpoint and actual speed (rpm), running, fault.

    ``fault`` is ``None`` when healthy, else the board's fault code (e.g. ``"WDOG"``).
    """

    setpoint_rpm: float
    actual_rpm: float
    running: bool
    fault: str | None = None

    def as_dict(self) -> dict[str, object]:
        return {
            "setpoint_rpm": self.setpoint_rpm,
            "actual_rpm": self.actual_rpm,
            "running": self.running,
            "fault": self.fault,
        }


def encode_frame(seq: int, cmd: str, *args: object) -> bytes:
    """Frame ``cmd`` with ``args`` under sequence number ``seq`` (bytes ready to write).

    Floats are written with two decimals. Raises :class:`ControlError` when the frame
    would not be valid (bad command, bad argument characters, longer than MAX_LINE).
    """
    if not 0 <= int(seq) < SEQ_MOD:
        raise ControlError(f"sequence number {seq} outside 0..{SEQ_MOD - 1}")
    parts = [str(int(seq)), cmd]
    for a in args:
        if isinstance(a, bool):
            parts.append("1" if a else "0")
        elif isinstance(a, float):
            if not math.isfinite(a):
                raise ControlError(f"cannot send a non-finite number ({a}) to the mill")
            parts.append(f"{a:.2f}")
        else:
            parts.append(str(a))
    body = ",".join(parts).encode("ascii")
    if not _BODY_RE.match(body):
        raise ControlError(f"not a valid mill frame body: {body!r}")
    line = b"$" + body + b"*" + f"{crc16(body):04X}".encode("ascii") + b"\n"
    if len(line) > MAX_LINE:
        raise ControlError(f"mill frame longer than {MAX_LINE} bytes: {line!r}")
    return line


def decode_line(line: bytes) -> Frame | BadFrame:
    """Decode one line (``$`` .. before ``\\n``, ``\\r`` already removed) into a frame."""
    raw = bytes(line)
    if len(raw) + 1 > MAX_LINE:
        return BadFrame("too_long", raw[:MAX_LINE])
    if any(b < 0x20 or b > 0x7E for b in raw):
        return BadFrame("binary", raw)
    if not raw.startswith(b"$") or raw.count(b"*") != 1:
        return BadFrame("syntax", raw)
    body, crc_txt = raw[1:].split(b"*")
    m = _BODY_RE.match(body)
    seq = None
    head = body.split(b",", 1)[0]
    if head.isdigit() and len(head) <= 5 and int(head) < SEQ_MOD:
        seq = int(head)
    if not _CRC_RE.match(crc_txt):
        return BadFrame("syntax", raw, seq)
    if int(crc_txt, 16) != crc16(body):
        return BadFrame("crc", raw, seq)
    if m is None or seq is None:
        return BadFrame("syntax", raw, seq)
    args = tuple(a.decode("ascii") for a in m.group(3).split(b",")[1:]) if m.group(3) else ()
    return Frame(seq, m.group(2).decode("ascii"), args)


class FrameDecoder:
    """Incremental decoder: feed it bytes as they arrive, get frames and bad lines back.

    A ``$`` always starts a new frame (resynchronisation after garbage); bytes outside a
    frame are dropped and counted; a frame longer than :data:`MAX_LINE` is reported once
    as ``too_long`` and discarded up to the next ``$`` or ``\\n``. Never raises on input.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._in_frame = False
        self._overflow = False
        self.junk_bytes = 0

    def feed(self, data: bytes) -> list[Frame | BadFrame]:
        out: list[Frame | BadFrame] = []
        for b in bytes(data):
            if b == 0x24:  # '$'
                if self._in_frame and self._buf and not self._overflow:
                    out.append(BadFrame("syntax", bytes(self._buf)))  # unterminated
                self._buf = bytearray(b"$")
                self._in_frame = True
                self._overflow = False
            elif b == 0x0A:  # '\n'
                if self._in_frame and not self._overflow:
                    out.append(decode_line(bytes(self._buf)))
                self._buf = bytearray()
                self._in_frame = False
                self._overflow = False
            elif b == 0x0D:  # '\r'
                continue
            elif not self._in_frame:
                self.junk_bytes += 1
            elif not self._overflow:
                self._buf.append(b)
                if len(self._buf) + 1 > MAX_LINE:
                    out.append(BadFrame("too_long", bytes(self._buf)))
                    self._overflow = True
                    self._buf = bytearray()
        return out


# --- payload helpers shared by the driver and the device -------------------------------


def status_args(status: MillStatus) -> tuple[str, ...]:
    """Arguments of a status ACK: ``setpoint,actual,running,fault``."""
    return (
        f"{status.setpoint_rpm:.2f}",
        f"{status.actual_rpm:.2f}",
        "1" if status.running else "0",
        status.fault or FAULT_NONE,
    )


def parse_status(args: tuple[str, ...]) -> MillStatus:
    """Inverse of :func:`status_args` (the arguments after ``ACK``). Raises ControlError,
    also for rpm no board can have (NaN, infinite, negative, beyond five digits)."""
    if len(args) != 4 or args[2] not in ("0", "1"):
        raise ControlError(f"malformed mill status {','.join(args)!r}")
    try:
        sp, act = float(args[0]), float(args[1])
    except ValueError:
        raise ControlError(f"malformed mill status {','.join(args)!r}") from None
    if not all(math.isfinite(v) and 0.0 <= v < 1e5 for v in (sp, act)):
        raise ControlError(f"malformed mill status {','.join(args)!r}")
    return MillStatus(sp, act, args[2] == "1", None if args[3] == FAULT_NONE else args[3])


def parse_rpm_arg(text: str) -> float | None:
    """A setpoint argument as a finite float rpm, or None when it is not a plain number."""
    if not re.fullmatch(r"\+?\d{1,5}(\.\d{1,3})?", text):
        return None
    return float(text)


def next_seq(seq: int) -> int:
    """The sequence number after ``seq`` (wraps at 65536, skips 0 so 0 can mean 'none')."""
    n = (seq + 1) % SEQ_MOD
    return n or 1

"""The drive emulator's Modbus server by the book: pymodbus's own server (``ModbusSerialServer``
or ``ModbusTcpServer`` with RTU framing) with a request framer and decoder that answer as the
Modbus application protocol (v1.1b3, section 7) says, where pymodbus 3.16's stock server does not.

What the stock server does, and what this module changes (``docs/drives.md``):

- an unknown function code (e.g. 0x63) got no reply (its framer cannot size the frame and
  hunts past it): here it is exception 1 (illegal function), as is every function a drive
  of ours does not implement (anything but 3, 6 and 16; 22 and 23 were acknowledged and
  ignored);
- fc 3 with a quantity outside 1..125 was ``01 80 01`` (the request failed to decode, so the
  reply carries function 0): here ``0x83`` exception 3 (illegal data value);
- fc 16 whose byte count disagrees with its quantity got no reply (the framer waited for the
  bytes the byte count promised): here a frame is also complete when what arrived ends in a
  valid CRC, and pymodbus's own fc 16 checks answer exception 3;
- after a malformed frame, the next valid one could go unanswered (a CRC failure dropped the
  whole buffer, a partial frame swallowed the next one): here bytes left over from before a
  silence of :data:`GAP_S` are stale (RTU frames are delimited by silence), and a frame
  whose CRC fails is skipped one byte at a time, never with what follows it;
- a write is answered with its own echo (the stock fc 6 reply echoes the register read back).

Register-level answers (illegal address, read-only registers, values out of range) are the
drive model's (``control.modbus.drive``).
"""

from __future__ import annotations

import struct
import time
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)

SUPPORTED_FUNCTIONS = (3, 6, 16)
"""Read holding registers, write single register, write multiple registers: what the drive
profiles' manuals document (every other function is exception 1)."""

GAP_S = 0.05
"""Silence (s) after which bytes not yet framed are stale. RTU's own gap is 3.5 characters
(1.8 ms at 19200 baud); a master writes a request at once and then waits at least its reply
timeout, so this is far below any resend and far above a frame's own byte gaps on a pty."""

MIN_FRAME = 4  # unit, function, CRC (2)
_LAYOUTS = DecodePDU(True)  # pymodbus's request layouts: only to size a frame, never to decode it


def crc_ok(frame: bytes) -> bool:
    """Whether ``frame`` (unit .. CRC) ends in its Modbus CRC."""
    return len(frame) >= MIN_FRAME and FramerRTU.compute_CRC(frame[:-2]) == int.from_bytes(frame[-2:], "big")


def layout_size(buf: bytes) -> int | None:
    """The RTU size of the request starting at ``buf[0]`` by its function's layout; 0 when more
    bytes are needed to tell (a byte count not yet received), None for a function without a
    known layout (unknown, or >= 0x80: no request has it)."""
    if len(buf) < 2 or buf[1] & 0x80:
        return None if len(buf) >= 2 else 0
    try:
        cls = _LAYOUTS.lookupPduClass(buf)
        return None if cls is None else int(cls.calculateRtuFrameSize(buf))
    except (IndexError, struct.error):
        return 0
    except Exception:  # a layout pymodbus cannot size (NotImplementedException)
        return None


def find_request(buf: bytes, start: int = 0) -> tuple[int, int] | None:
    """The first request frame in ``buf[start:]`` as (first byte, end), or None to wait for
    more bytes (pure). At each candidate start: the frame its layout gives, when complete
    with a valid CRC; else everything received when that ends in a valid CRC (an unknown
    function, or a length that disagrees with its own layout: the decoder answers it); else,
    when its layout says more bytes are coming, wait; else (a bad CRC: noise or a broken
    frame) the next byte is the next candidate."""
    s = start
    while len(buf) - s >= MIN_FRAME:
        size = layout_size(buf[s:])
        if size and s + size <= len(buf) and crc_ok(buf[s:s + size]):
            return s, s + size
        if crc_ok(buf[s:]):
            return s, len(buf)
        if size == 0 or (size is not None and s + size > len(buf)):
            return None
        s += 1
    return None


class BookFramer(FramerRTU):
    """pymodbus's RTU framer with :func:`find_request` and the silence rule (see module doc)."""

    def __init__(self, decoder: DecodePDU) -> None:
        super().__init__(decoder)
        self._left = 0  # bytes not framed at the end of the last call
        self._last_s = float("-inf")

    def decode(self, data: bytes) -> tuple[int, int, int, bytes]:
        now = time.monotonic()
        if len(data) < self._left:  # the transport dropped its buffer (an overflow): nothing is left
            self._left = 0
        stale = self._left if now - self._last_s > GAP_S else 0
        self._last_s = now
        found = find_request(data, stale)
        if found is None:
            self._left = len(data) - stale
            return stale, 0, 0, self.EMPTY
        first, end = found
        self._left = len(data) - end
        return end, data[first], 0, data[first + 1:end - 2]


class Refused(ModbusPDU):
    """A request answered with an exception whatever the registers: ``code`` for function ``fc``."""

    def __init__(self, fc: int, code: ExcCodes) -> None:
        super().__init__()
        self.function_code = fc
        self.code = code

    async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
        return ExceptionResponse(self.function_code, self.code)


class BookRead(ReadHoldingRegistersRequest):
    """fc 3 whose quantity is checked when answered (exception 3), not when decoded."""

    def decode(self, data: bytes) -> None:
        self.address, self.count = struct.unpack(">HH", data[:4])

    async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
        if not 1 <= self.count <= self.MAX_COUNT:
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_VALUE)
        if self.address + self.count > 0x10000:
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_ADDRESS)
        return await super().datastore_update(context, device_id)


class BookWriteSingle(WriteSingleRegisterRequest):
    """fc 6 answered with the echo of the request."""

    async def datastore_update(self, context: Any, device_id: int) -> ModbusPDU:
        rc = await context.async_setValues(device_id, self.function_code, self.address, self.registers)
        if rc:
            return ExceptionResponse(self.function_code, rc)
        return WriteSingleRegisterResponse(address=self.address, registers=list(self.registers))


class BookDecoder(DecodePDU):
    """The server's request decoder: a CRC-valid frame always decodes (see module doc)."""

    def __init__(self) -> None:
        super().__init__(True)

    def decode(self, frame: bytes) -> ModbusPDU | None:
        fc, body = frame[0], frame[1:]
        if fc not in SUPPORTED_FUNCTIONS:
            return Refused(fc, ExcCodes.ILLEGAL_FUNCTION)
        if (fc != 16 and len(body) != 4) or (fc == 16 and len(body) < 5):  # not the function's layout
            return Refused(fc, ExcCodes.ILLEGAL_VALUE)
        pdu: ModbusPDU = {3: BookRead, 6: BookWriteSingle, 16: WriteMultipleRegistersRequest}[fc]()
        pdu.decode(body)
        return pdu


def by_the_book(server: Any) -> Any:
    """Give a pymodbus server (before it serves) this module's framer and decoder."""
    server.decoder = BookDecoder()
    server.framer = BookFramer
    return server


__all__ = ["GAP_S", "SUPPORTED_FUNCTIONS", "BookDecoder", "BookFramer", "by_the_book", "crc_ok", "find_request",
           "layout_size"]

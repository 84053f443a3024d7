"""The Modbus mill link: a frequency inverter behind the same interface as
``control.driver.MillClient`` (``set_rpm``, ``start``, ``stop``, ``status``, ``heartbeat``,
``close``, ``url``, ``connected``), on pymodbus's ``ModbusSerialClient`` (RTU framing) over
pyserial ``serial_for_url``: a real port, a pty, ``socket://`` or ``rfc2217://``. The URL is
``control.modbus.url``'s (``modbus:PORT?profile=NAME&unit=N...``).

Rules (as the line protocol's, see ``twin/live/mill.py``):

- **A stop is never gated.** ``stop()`` writes the stop word whatever the drive's comm-loss
  trip says, whatever it can or cannot read, with or without an override; so do a lower
  setpoint, the keep-alive and every read.
- **Only what starts the motor or raises its speed is refused** (``SafetyRefused``, a
  ``MillRefused`` naming the parameter and the value to set) while the drive's comm-loss
  trip is disabled, does not stop the motor, is longer than ``comm_loss_limit`` or cannot be
  read (a Modbus exception, e.g. 2 on an ACS355 that lacks 58.14/58.16), unless the URL says
  ``override=comm-loss`` (logged as ``safety_override``). The trip is read before the first
  such command after each (re)connect, and at construction (``connect=True``), where
  ``refuse_unsafe`` refuses the whole link (``ControlError``): a run is not started on it.
- ``status()`` only reads; ``heartbeat()`` is the keep-alive write (the setpoint register,
  rewritten with the value it holds) the controlling host sends; ``set_rpm`` outside 0..max
  is refused before anything is written.
- **Every reply is checked** against its request (``control.modbus.reply``: unit, function,
  byte count, echo, CRC): a Modbus exception reply is ``MillRefused`` (the link is fine,
  nothing applied); no answer, a CRC error after the retries, or a reply that is not the
  answer is ``TimeoutError`` (a link fault: the loop's safe state), never data; a port that
  cannot be opened is ``ConnectionError``.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from control.driver import WRITE_TIMEOUT_S
from control.errors import ControlError, MillRefused, SafetyRefused, check_number
from control.modbus.profile import CommLossSetting, DriveProfile, load_profile, read_blocks
from control.modbus.reply import EXCEPTIONS, READ, WRITE, BadReply, Request, check_reply
from control.modbus.url import (
    COMM_LOSS_LIMIT_S,
    DRIVE_KEYS,
    ModbusUrl,
    config_mill_url,
    drive_hz_per_rpm,
    is_modbus_url,
    parse_modbus_url,
)
from control.protocol import MillStatus

log = logging.getLogger("drumtwin.modbus")

OVERRIDE_HINT = "(or add override=comm-loss to the URL, logged)"


def comm_loss_problem(profile: DriveProfile, setting: CommLossSetting, limit_s: float) -> str | None:
    """Why the drive's comm-loss trip is not good enough (one line naming the parameter and
    what to set), or None when it trips safely within ``limit_s`` (pure)."""
    cl = profile.comm_loss
    advice = profile.comm_loss_advice(limit_s)
    if setting.time_s <= 0:
        return f"the drive's comm-loss trip is disabled ({cl.time_parameter} = 0): {advice}"
    if not setting.safe:
        return (f"the drive's comm-loss action does not stop the motor ({cl.action_parameter or cl.time_parameter}"
                f" = {setting.action}): {advice}")
    if setting.time_s > limit_s:
        return (f"the drive's comm-loss trip is too slow ({cl.time_parameter} = {setting.time_s:g} s,"
                f" limit {limit_s:g} s): {advice}")
    return None


class ModbusMill:
    """A drive over Modbus RTU, presenting ``MillClient``'s interface (see module doc).
    ``timeout_s`` per attempt, ``retries`` resends; ``connect``: open the port now;
    ``refuse_unsafe`` (with ``connect``): read the comm-loss trip now and refuse a drive whose
    trip is unsafe and not overridden (``ControlError``), as a run does; without it (the
    ``mill`` commands) nothing is read before the first command, and only a start or a faster
    setpoint is refused."""

    def __init__(
        self, url: str, *, timeout_s: float = 0.2, retries: int = 2, connect: bool = True, refuse_unsafe: bool = True
    ) -> None:
        self.url = url
        self.spec: ModbusUrl = parse_modbus_url(url)
        self.profile = load_profile(self.spec.profile)
        self.hz_per_rpm = self.spec.hz_per_rpm or self.profile.hz_per_rpm
        self.max_hz = min(self.spec.max_hz or self.profile.max_hz, self.profile.max_hz)
        self.timeout_s = check_number("timeout_s", timeout_s, above=0.0, at_most=60.0)
        if isinstance(retries, bool) or not isinstance(retries, int) or not 0 <= retries <= 100:
            raise ControlError(f"retries must be an integer in 0..100 (got {retries})")
        self.retries = retries
        self.safety_override: str | None = None  # set when a bad comm-loss trip was overridden
        self.safety_problem: str | None = None  # what is wrong with the drive's comm-loss trip
        self.comm_loss: CommLossSetting | None = None
        self.last_status: MillStatus | None = None
        self.last_error: str | None = None
        self.last_ok_s: float | None = None  # time.monotonic() of the last decoded status
        self.stats = {"requests": 0, "timeouts": 0, "exceptions": 0, "reconnects": 0, "keepalives": 0, "resends": 0,
                      "bad_replies": 0}
        self._lock = threading.RLock()
        self._client: Any = None
        self._checked = False  # the comm-loss trip was read on this connection
        self._connected = False
        self._closed = False
        self._rx = b""  # the bytes the last reply was decoded from (pymodbus's trace_packet)
        self._written: tuple[int, float] | None = None  # (counts, rpm) of this link's last set_rpm
        if connect:
            with self._lock:
                try:
                    self._ensure_open()
                    why = self._unsafe() if refuse_unsafe else None
                except BaseException:
                    self._drop()  # release the port (pyserial locks it)
                    raise
                if why is not None:
                    self._drop()
                    raise ControlError(f"{why} {OVERRIDE_HINT}")

    # -- the MillClient interface ---------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._connected

    def set_rpm(self, rpm: float) -> None:
        """Write the frequency setpoint for ``rpm`` drum rpm (``rpm * hz_per_rpm`` Hz); above
        the drive's present setpoint only when its comm-loss trip is safe (see module doc)."""
        rpm = check_number("rpm", rpm, at_least=0.0, at_most=1e5)
        hz = rpm * self.hz_per_rpm
        what = f"SET {rpm:g}"
        if hz > self.max_hz + 1e-9:
            raise MillRefused(what, f"RANGE ({hz:.2f} Hz > max {self.max_hz:g} Hz)")
        p = self.profile
        counts = p.setpoint.to_counts(hz)
        with self._lock:
            why = self._unsafe()
            if why is not None:
                held_hz = p.setpoint.to_hz(self._read(p.readback_register, 1, "setpoint")[0])
                if hz > held_hz + 0.5 / p.setpoint.counts_per_hz:
                    raise SafetyRefused(what, f"{why}; only a stop or a lower speed (now {max(held_hz, 0.0):.2f} Hz)"
                                              f" is sent {OVERRIDE_HINT}")
            self._write(p.setpoint_register, counts, what)
            self._written = (counts, round(rpm, 2))

    def start(self) -> None:
        """Run forward; a latched comm-loss fault is reset first (as the line protocol's RUN
        clears a watchdog trip); any other drive fault refuses the start, and so does an
        unsafe comm-loss trip (see module doc)."""
        p = self.profile
        with self._lock:
            why = self._unsafe()
            if why is not None:
                raise SafetyRefused("RUN", f"{why} {OVERRIDE_HINT}")
            words = self._read_status_words()
            sw, fw = words[p.status_register], words[p.fault_register]
            if p.is_tripped(sw, fw):
                code = p.fault_code(fw)
                if code != p.comm_loss_fault_code or not p.reset_words:
                    raise MillRefused("RUN", f"FAULT {p.fault_name(code)}")
                for w in p.reset_words:
                    self._write(p.reset_register, w, "RESET")
            for w in p.run_words:
                self._write(p.control_register, w, "RUN")

    def stop(self) -> None:
        """Ramp stop (the profile's stop word): never gated, never preceded by a read."""
        with self._lock:
            self._write(self.profile.control_register, self.profile.stop_word, "STOP")

    def status(self) -> MillStatus:
        """Read setpoint, output (rpm), running and fault; never counts as control."""
        with self._lock:
            return self._decode(self._read_status_words())

    def heartbeat(self) -> MillStatus:
        """The controlling host's keep-alive write (the setpoint register, unchanged), then status."""
        p = self.profile
        with self._lock:
            if self._written is not None:
                counts = self._written[0]
            else:
                counts = self._read_status_words()[p.readback_register]
            self._write(p.setpoint_register, counts, "KEEPALIVE")
            self.stats["keepalives"] += 1
            return self._decode(self._read_status_words())

    def close(self) -> None:
        """Close the port (idempotent); the drive's comm-loss trip takes over."""
        with self._lock:
            self._closed = True
            self._drop()

    def __enter__(self) -> ModbusMill:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- commissioning --------------------------------------------------------------------------
    def read_identity(self) -> dict[str, int]:
        """The profile's identity registers as read from the drive."""
        with self._lock:
            return {name: self._read(addr, 1, f"identity {name}")[0] for name, addr in self.profile.identity.items()}

    def read_comm_loss(self) -> CommLossSetting:
        """The drive's comm-loss parameters as it holds them now."""
        with self._lock:
            values: dict[int, int] = {}
            for start, n in read_blocks(self.profile.comm_loss.registers):
                for i, v in enumerate(self._read(start, n, "comm-loss parameters")):
                    values[start + i] = v
            self.comm_loss = self.profile.comm_loss_setting(values)
            return self.comm_loss

    def comm_loss_check(self) -> str | None:
        """What is wrong with the drive's comm-loss trip as read now (None: it trips safely
        within the limit), an unreadable parameter included (a Modbus exception: the
        profile's register is not the drive's). A link fault raises (TimeoutError,
        ConnectionError)."""
        cl = self.profile.comm_loss
        try:
            return comm_loss_problem(self.profile, self.read_comm_loss(), self.spec.comm_loss_limit_s)
        except MillRefused as exc:
            names = " / ".join(n for n in (cl.time_parameter, cl.action_parameter) if n)
            return (f"the drive's comm-loss parameters cannot be read ({names}: {exc.reason}): this drive may not"
                    f" have the profile's registers; fill them in from its manual (docs/drives.md)")

    # -- internals -----------------------------------------------------------------------------
    def _unsafe(self) -> str | None:
        """Why a start or a faster setpoint is refused now (None: it is not). Reads the trip
        once per connection; an override makes it None (and is logged once)."""
        if not self._checked:
            self._ensure_open()
            why = self.comm_loss_check()
            self._checked = True
            self.safety_problem = why
            self.safety_override = why if why is not None and self.spec.override else None
            if self.safety_override:
                log.warning("safety override: %s", why)
        return None if self.spec.override else self.safety_problem

    def _ensure_open(self) -> None:
        if self._closed:
            raise ControlError("the modbus mill link is closed")
        if self._client is not None:
            return
        from pymodbus.client import ModbusSerialClient
        from pymodbus.framer import FramerType

        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # we report in one line ourselves
        s = self.spec
        client = ModbusSerialClient(
            s.port, framer=FramerType.RTU, baudrate=s.baud, parity=s.parity, stopbits=s.stopbits,
            timeout=self.timeout_s, retries=self.retries, reconnect_delay=0, trace_packet=self._trace,
        )
        if s.port.startswith("rfc2217://"):
            self._open_rfc2217(client)
        if not client.connect():
            self._connected = False
            self.last_error = f"cannot open {s.port}"
            raise ConnectionError(f"cannot open mill link {s.port} (modbus)")
        if client.socket is not None and client.socket.write_timeout is not None:
            client.socket.write_timeout = max(WRITE_TIMEOUT_S, self.timeout_s)  # pymodbus: the reply timeout
        self._client = client
        self._checked = False  # a new connection: the trip is read again before a start
        self.stats["reconnects"] += 1

    def _trace(self, sending: bool, data: bytes) -> bytes:
        """pymodbus's ``trace_packet``: keep the bytes each reply is decoded from."""
        if not sending:
            self._rx = bytes(data)
        return data

    def _open_rfc2217(self, client: Any) -> None:
        """pymodbus opens its port with a ``write_timeout``, which pyserial's RFC 2217 client
        refuses (NotImplementedError): open it here without one, with pymodbus's other
        settings; ``client.connect()`` then finds it open. A server that does not answer
        leaves ``client.socket`` None (ConnectionError, as for any port)."""
        import serial

        s = self.spec
        try:
            port = serial.serial_for_url(s.port, timeout=self.timeout_s, baudrate=s.baud, parity=s.parity,
                                         stopbits=s.stopbits, bytesize=8)
            port.inter_byte_timeout = client.inter_byte_timeout or None
        except (OSError, ValueError, serial.SerialException):
            return
        client.socket = port

    def _drop(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except Exception:
                pass
        self._client = None
        self._connected = False

    def _exchange(self, req: Request, what: str) -> tuple[int, ...]:
        """Send ``req``, check the reply (``control.modbus.reply``); the registers read."""
        from pymodbus.exceptions import ConnectionException, ModbusException

        self._ensure_open()
        self.stats["requests"] += 1
        self._rx = b""
        try:
            if req.function == READ:
                rr = self._client.read_holding_registers(req.address, count=req.count, device_id=req.unit)
            else:
                rr = self._client.write_register(req.address, req.value, device_id=req.unit)
        except ConnectionException as exc:
            self._drop()
            self.last_error = str(exc)
            raise ConnectionError(f"mill link {self.spec.port} down: {what}") from None
        except ModbusException:
            self.stats["timeouts"] += 1
            self._connected = False
            self.last_error = f"no valid answer to {what}"
            raise TimeoutError(
                f"no valid answer from drive unit {self.spec.unit} at {self.spec.port} to {what} "
                f"after {self.retries + 1} tries"
            ) from None
        except OSError as exc:
            self._drop()
            raise ConnectionError(f"mill link {self.spec.port} down: {exc}") from None
        try:
            reply = check_reply(req, self._rx)
        except BadReply as exc:
            raise self._garbled(what, str(exc)) from None
        self._connected = True
        self.last_error = None
        self.stats["resends"] += int(getattr(rr, "retries", 0) or 0)
        if reply.exception is not None:
            self.stats["exceptions"] += 1
            raise MillRefused(what, f"modbus exception {reply.exception} ({EXCEPTIONS[reply.exception]})")
        return reply.registers

    def _read(self, address: int, count: int, what: str) -> list[int]:
        return list(self._exchange(Request(self.spec.unit, READ, address, count=count), what))

    def _write(self, address: int, value: int, what: str) -> None:
        self._exchange(Request(self.spec.unit, WRITE, address, value=int(value) & 0xFFFF), what)

    def _garbled(self, what: str, detail: str) -> TimeoutError:
        self.stats["timeouts"] += 1
        self.stats["bad_replies"] += 1
        self._connected = False
        self.last_error = f"garbled answer to {what}: {detail}"
        where = f"drive unit {self.spec.unit} at {self.spec.port}"
        return TimeoutError(f"no valid answer from {where} to {what} ({detail})")

    def _read_status_words(self) -> dict[int, int]:
        out: dict[int, int] = {}
        for start, n in read_blocks(self.profile.status_registers):
            for i, v in enumerate(self._read(start, n, "STATUS")):
                out[start + i] = v
        return out

    def _decode(self, words: dict[int, int]) -> MillStatus:
        p = self.profile
        sw, fw = words[p.status_register], words[p.fault_register]
        counts = words[p.readback_register]
        if self._written is not None and counts == self._written[0]:
            setpoint = self._written[1]  # what this link wrote, not its rounding to counts
        else:
            setpoint = round(p.setpoint.to_hz(counts) / self.hz_per_rpm, 2)
        st = MillStatus(
            setpoint_rpm=setpoint,
            actual_rpm=round(max(0.0, p.output.to_hz(words[p.output_register])) / self.hz_per_rpm, 2),
            running=p.is_running(sw),
            fault=p.fault_name(p.fault_code(fw)) if p.is_tripped(sw, fw) else None,
        )
        self.last_status = st
        self.last_ok_s = time.monotonic()
        return st


__all__ = ["COMM_LOSS_LIMIT_S", "DRIVE_KEYS", "ModbusMill", "ModbusUrl", "comm_loss_problem", "config_mill_url",
           "drive_hz_per_rpm", "is_modbus_url", "parse_modbus_url"]

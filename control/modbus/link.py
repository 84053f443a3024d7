"""The Modbus mill link: a frequency inverter behind the same interface as
``control.driver.MillClient`` (``set_rpm``, ``start``, ``stop``, ``status``, ``heartbeat``,
``close``, ``url``, ``connected``), on pymodbus's ``ModbusSerialClient`` (RTU framing) over
pyserial ``serial_for_url``: a real port, a pty, ``socket://`` or ``rfc2217://``.

URL (everything after ``?`` belongs to the Modbus layer)::

    modbus:/dev/ttyUSB0?profile=delta-ms300&unit=1&baud=19200&parity=E
    modbus:socket://127.0.0.1:5020?profile=abb-acs&unit=1&hz_per_rpm=12.5

Keys: ``profile`` (shipped name or a .toml path; required), ``unit`` (1..247, default 1),
``baud`` (19200), ``parity`` (N/E/O, default E), ``stopbits`` (1/2), ``hz_per_rpm`` (motor
Hz per drum rpm; default the profile's), ``max_hz`` (highest setpoint this link writes;
default the profile's), ``comm_loss_limit`` (longest comm-loss trip accepted, s; default
:data:`COMM_LOSS_LIMIT_S`), ``override=comm-loss`` (run a drive whose trip is disabled or
too long: logged as ``safety_override``).

Rules (as the line protocol's, see ``twin/live/mill.py``): at connect (and after every
reconnect) the drive's comm-loss time and action are read and a drive without a safe trip
no longer than the limit is refused (``ControlError`` naming the parameter and the value to
set) unless overridden; ``status()`` only reads; ``heartbeat()`` is the keep-alive write
(the setpoint register, rewritten with the value it holds) the controlling host sends;
``set_rpm`` outside 0..max is refused before anything is written; a Modbus exception reply
is ``MillRefused`` (the link is fine, nothing applied); no answer or a garbled one after
the retries is ``TimeoutError``; a port that cannot be opened is ``ConnectionError``.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl

from control.driver import WRITE_TIMEOUT_S
from control.errors import ControlError, MillRefused, check_number
from control.modbus.profile import CommLossSetting, DriveProfile, load_profile, read_blocks
from control.protocol import MillStatus

log = logging.getLogger("drumtwin.modbus")

SCHEME = "modbus:"
COMM_LOSS_LIMIT_S = 5.0
"""Longest comm-loss trip time (s) the link accepts without an override: the loop's own
limit for a mill nobody controls any more (the line protocol's board watchdog is 1 s)."""

_KEYS = ("profile", "unit", "baud", "parity", "stopbits", "hz_per_rpm", "max_hz", "comm_loss_limit", "override")


@dataclass(frozen=True)
class ModbusUrl:
    """A parsed ``modbus:`` mill URL (see module doc)."""

    port: str
    profile: str
    unit: int = 1
    baud: int = 19200
    parity: str = "E"
    stopbits: int = 1
    hz_per_rpm: float | None = None
    max_hz: float | None = None
    comm_loss_limit_s: float = COMM_LOSS_LIMIT_S
    override: bool = False


def is_modbus_url(url: str) -> bool:
    return url.startswith(SCHEME)


def parse_modbus_url(url: str) -> ModbusUrl:
    """Parse a ``modbus:`` URL (pure); one-line ``ControlError`` naming the bad part."""
    if not is_modbus_url(url):
        raise ControlError(f"not a modbus: URL: {url!r}")
    port, _, query = url[len(SCHEME):].partition("?")
    if not port:
        raise ControlError(f"modbus URL {url!r} names no port (modbus:/dev/ttyUSB0?profile=...)")
    q: dict[str, str] = {}
    for k, v in parse_qsl(query, keep_blank_values=True):
        if k not in _KEYS:
            raise ControlError(f"unknown key {k!r} in modbus URL (known: {', '.join(_KEYS)})")
        q[k] = v
    if "profile" not in q:
        raise ControlError("modbus URL needs profile=NAME (delta-ms300, abb-acs, siemens-v20, invertek-e3, generic)")

    def integer(key: str, default: int, lo: int, hi: int) -> int:
        try:
            v = int(q.get(key, default))
        except ValueError:
            v = lo - 1
        if not lo <= v <= hi:
            raise ControlError(f"modbus URL: {key} must be an integer in {lo}..{hi} (got {q.get(key)!r})")
        return v

    def number(key: str, default: float | None, **bounds: float) -> float | None:
        return default if key not in q else check_number(f"modbus URL: {key}", q[key], **bounds)

    parity = q.get("parity", "E").upper()
    if parity not in ("N", "E", "O"):
        raise ControlError(f"modbus URL: parity must be N, E or O (got {q['parity']!r})")
    override = q.get("override", "")
    if override not in ("", "comm-loss"):
        raise ControlError(f"modbus URL: override must be 'comm-loss' (got {override!r})")
    return ModbusUrl(
        port=port,
        profile=q["profile"],
        unit=integer("unit", 1, 1, 247),
        baud=integer("baud", 19200, 300, 4_000_000),
        parity=parity,
        stopbits=integer("stopbits", 1, 1, 2),
        hz_per_rpm=number("hz_per_rpm", None, above=0.0),
        max_hz=number("max_hz", None, above=0.0, at_most=600.0),
        comm_loss_limit_s=number("comm_loss_limit", COMM_LOSS_LIMIT_S, above=0.0) or COMM_LOSS_LIMIT_S,
        override=override == "comm-loss",
    )


DRIVE_KEYS = ("hz_per_rpm",)
"""Keys of a mixer config's ``[drive]`` table (the drive behind a ``modbus:`` mill URL)."""


def drive_hz_per_rpm(table: object, source: str) -> float | None:
    """``hz_per_rpm`` (motor Hz per drum rpm) of a config's ``[drive]`` table, None when the
    table or the key is absent (pure); one-line ``ControlError`` for an unknown key or a bad value."""
    if table is None or table == {}:
        return None
    if not isinstance(table, dict):
        raise ControlError(f"{source}: [drive] must be a table (hz_per_rpm = ...)")
    unknown = sorted(set(table) - set(DRIVE_KEYS))
    if unknown:
        raise ControlError(f"{source}: unknown key(s) {unknown} in [drive] (allowed: {', '.join(DRIVE_KEYS)})")
    if "hz_per_rpm" not in table:
        return None
    v = table["hz_per_rpm"]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ControlError(f"{source}: [drive] hz_per_rpm must be a number (got {v!r})")
    return check_number(f"{source}: [drive] hz_per_rpm", float(v), above=0.0, at_most=1e4)


def config_mill_url(url: str, drive_table: object, source: str) -> str:
    """The mill URL a run (or ``drumtwin mill --config``) opens, given the config's ``[drive]``
    table (pure): its ``hz_per_rpm`` is written into a ``modbus:`` URL, the one place the link
    reads it (the run's ``start`` event shows that URL). A URL that already carries
    ``hz_per_rpm`` must agree (within 1e-6), else one-line ``ControlError`` naming both; a
    line-protocol board's URL refuses it (that board takes rpm, not Hz). No value: the URL unchanged."""
    hz_per_rpm = drive_hz_per_rpm(drive_table, source)
    if hz_per_rpm is None:
        return url
    if not is_modbus_url(url):
        raise ControlError(f"{source}: [drive] hz_per_rpm is for a drive (a modbus: mill URL), not {url!r}")
    given = parse_modbus_url(url).hz_per_rpm
    if given is not None:
        if abs(given - hz_per_rpm) > 1e-6 * max(given, hz_per_rpm):
            raise ControlError(f"hz_per_rpm: the mill URL says {given:g}, {source} [drive] says {hz_per_rpm:g}:"
                               " give it in one place (or make them agree)")
        return url
    return url + ("&" if "?" in url else "?") + f"hz_per_rpm={hz_per_rpm!r}"


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
    ``timeout_s`` per attempt, ``retries`` resends; ``connect``: open and check now;
    ``enforce=False`` (``drumtwin mill URL check`` only: it reads, never controls) records
    an unsafe comm-loss trip in ``safety_problem`` instead of refusing."""

    def __init__(
        self, url: str, *, timeout_s: float = 0.2, retries: int = 2, connect: bool = True, enforce: bool = True
    ) -> None:
        self.url = url
        self.spec = parse_modbus_url(url)
        self.profile = load_profile(self.spec.profile)
        self.hz_per_rpm = self.spec.hz_per_rpm or self.profile.hz_per_rpm
        self.max_hz = min(self.spec.max_hz or self.profile.max_hz, self.profile.max_hz)
        self.timeout_s = check_number("timeout_s", timeout_s, above=0.0, at_most=60.0)
        if isinstance(retries, bool) or not isinstance(retries, int) or not 0 <= retries <= 100:
            raise ControlError(f"retries must be an integer in 0..100 (got {retries})")
        self.retries = retries
        self.enforce = enforce
        self.safety_override: str | None = None  # set when a bad comm-loss trip was overridden
        self.safety_problem: str | None = None  # what is wrong with the drive's comm-loss trip
        self.comm_loss: CommLossSetting | None = None
        self.last_status: MillStatus | None = None
        self.last_error: str | None = None
        self.last_ok_s: float | None = None  # time.monotonic() of the last decoded status
        self.stats = {"requests": 0, "timeouts": 0, "exceptions": 0, "reconnects": 0, "keepalives": 0, "resends": 0}
        self._lock = threading.RLock()
        self._client: Any = None
        self._checked = False
        self._connected = False
        self._closed = False
        self._written: tuple[int, float] | None = None  # (counts, rpm) of this link's last set_rpm
        if connect:
            with self._lock:
                self._ensure_open()

    # -- the MillClient interface ---------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._connected

    def set_rpm(self, rpm: float) -> None:
        """Write the frequency setpoint for ``rpm`` drum rpm (``rpm * hz_per_rpm`` Hz)."""
        rpm = check_number("rpm", rpm, at_least=0.0, at_most=1e5)
        hz = rpm * self.hz_per_rpm
        if hz > self.max_hz + 1e-9:
            raise MillRefused(f"SET {rpm:g}", f"RANGE ({hz:.2f} Hz > max {self.max_hz:g} Hz)")
        counts = self.profile.setpoint.to_counts(hz)
        with self._lock:
            self._write(self.profile.setpoint_register, counts, f"SET {rpm:g}")
            self._written = (counts, round(rpm, 2))

    def start(self) -> None:
        """Run forward; a latched comm-loss fault is reset first (as the line protocol's RUN
        clears a watchdog trip); any other drive fault refuses the start."""
        p = self.profile
        with self._lock:
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
        """Ramp stop (the profile's stop word)."""
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

    # -- internals -----------------------------------------------------------------------------
    def _ensure_open(self) -> None:
        if self._closed:
            raise ControlError("the modbus mill link is closed")
        if self._client is None:
            from pymodbus.client import ModbusSerialClient
            from pymodbus.framer import FramerType

            logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # we report in one line ourselves
            s = self.spec
            client = ModbusSerialClient(
                s.port, framer=FramerType.RTU, baudrate=s.baud, parity=s.parity, stopbits=s.stopbits,
                timeout=self.timeout_s, retries=self.retries, reconnect_delay=0,
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
            self._checked = False
            self.stats["reconnects"] += 1
        if not self._checked:
            self._checked = True  # set first: the check's own reads must not recurse
            try:
                self._check_safety()
            except BaseException:
                self._checked = False
                self._drop()  # release the port (pyserial locks it): the next request opens and checks again
                raise

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

    def _check_safety(self) -> None:
        setting = self.read_comm_loss()
        why = self.safety_problem = comm_loss_problem(self.profile, setting, self.spec.comm_loss_limit_s)
        if why is None:
            self.safety_override = None
            return
        if not self.enforce:
            return
        if not self.spec.override:
            raise ControlError(f"{why} (or add override=comm-loss to the URL, logged)")
        self.safety_override = why
        log.warning("safety override: %s", why)

    def _drop(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except Exception:
                pass
        self._client = None
        self._connected = False

    def _call(self, what: str, fn: str, *args: Any, **kw: Any) -> Any:
        from pymodbus.exceptions import ConnectionException, ModbusException

        self._ensure_open()
        self.stats["requests"] += 1
        try:
            rr = getattr(self._client, fn)(*args, device_id=self.spec.unit, **kw)
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
        if rr.isError():
            self.stats["exceptions"] += 1
            self._connected = True
            code = getattr(rr, "exception_code", "?")
            raise MillRefused(what, f"modbus exception {code}")
        self._connected = True
        self.last_error = None
        self.stats["resends"] += int(getattr(rr, "retries", 0) or 0)
        return rr

    def _read(self, address: int, count: int, what: str) -> list[int]:
        regs = list(self._call(what, "read_holding_registers", address, count=count).registers)
        if len(regs) != count:  # RTU has no transaction id: a late answer to another request
            raise self._garbled(what, f"{len(regs)} registers for {count}")
        return regs

    def _write(self, address: int, value: int, what: str) -> None:
        value = int(value) & 0xFFFF
        rr = self._call(what, "write_register", address, value)
        echo = (getattr(rr, "address", address), list(getattr(rr, "registers", [value]) or [value]))
        if echo != (address, [value]):  # a write is answered with its own echo
            raise self._garbled(what, f"echo {echo} for {(address, [value])}")

    def _garbled(self, what: str, detail: str) -> TimeoutError:
        self.stats["timeouts"] += 1
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

"""The host side of the mill link: a thread-safe client on pyserial ``serial_for_url``.

``url`` is anything pyserial opens: ``/dev/ttyUSB0``, a pty path, ``socket://host:port``,
``rfc2217://host:port``. One request is in flight at a time (a lock): a request is
framed by ``control.protocol`` with a fresh sequence number (each client starts at a
random one, so two hosts or two CLI calls never reuse each other's numbers), written,
and answered by the device with ACK/NAK under the same number. A timeout, a garbled
reply or ``NAK,CRC`` resend the *same* frame (same sequence number, so the device never
applies it twice) up to ``retries`` times; any other ``NAK`` raises
:class:`control.errors.MillRefused` at once (never resent). A broken port is closed and
reopened with exponential back-off. A heartbeat thread (``heartbeat_s``; ``None``: the
caller polls ``heartbeat()`` itself) keeps the device watchdog fed, refreshes
:attr:`MillClient.last_status` and reconnects in the background. Only the host that
controls the motor should send ``HB`` (or SET/RUN/STP): ``status()`` does not feed the
board's watchdog.
"""

from __future__ import annotations

import os
import secrets
import threading
import time
from typing import Any

import serial

from control import protocol as p
from control.errors import ControlError, MillRefused, check_number
from control.protocol import MillStatus

WRITE_TIMEOUT_S = 1.0
"""How long a write to the mill link may take (s) before the link is down: a frame's bytes
at the slowest baud rate, not the reply timeout. pyserial checks its write timer after a
complete ``os.write`` too, so a host that loses the CPU for that long just after writing
would otherwise call a healthy link down (and the run safe)."""

__all__ = ["MillClient", "MillStatus"]

try:  # termios errors are not OSErrors; a closed pty can raise them
    import termios

    _LINK_ERRORS: tuple[type[Exception], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # pragma: no cover - windows
    _LINK_ERRORS = (serial.SerialException, OSError)
_OPEN_ERRORS: tuple[type[Exception], ...] = (*_LINK_ERRORS, ValueError, NotImplementedError)


class MillClient:
    """Drive the mill: ``set_rpm``, ``start``, ``stop``, ``status``; ``connected`` flag.

    Parameters: ``timeout_s`` per attempt; ``retries`` resends after the first attempt;
    ``heartbeat_s`` period of the heartbeat thread (default ``None``: no thread; only a
    caller that controls the motor in this run passes a period, e.g. 0.25 s);
    ``backoff_s``/``backoff_max_s`` first and longest wait between reconnect attempts;
    ``reconnect_wait_s`` longest time one request waits for a lost link to come back
    (so a request blocks at most about ``(retries + 1) * timeout_s + reconnect_wait_s``;
    the heartbeat thread never waits, it just tries to reopen once per period);
    ``connect``: open the port now (raises ``ConnectionError`` when it cannot) or leave
    it to the first request / the heartbeat thread.
    Requests raise ``ConnectionError`` (port cannot be opened), ``TimeoutError`` (no valid
    answer after all retries) or ``MillRefused`` (a ``ControlError``: the device answered
    NAK with a reason; the link is fine and nothing was applied).
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 115200,
        timeout_s: float = 0.2,
        retries: int = 5,
        heartbeat_s: float | None = None,
        backoff_s: float = 0.05,
        backoff_max_s: float = 2.0,
        reconnect_wait_s: float = 1.0,
        connect: bool = True,
    ) -> None:
        if not url:
            raise ControlError("empty mill URL")
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise ControlError(f"retries must be an integer >= 0 (got {retries})")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise ControlError(f"baudrate must be a positive integer (got {baudrate})")
        self.url = url
        self.baudrate = baudrate
        self.timeout_s = check_number("timeout_s", timeout_s, above=0.0, at_most=60.0)
        self.retries = retries
        self.heartbeat_s = None if heartbeat_s is None else check_number("heartbeat_s", heartbeat_s, above=0.0)
        self.backoff_s = check_number("backoff_s", backoff_s, above=0.0)
        self.backoff_max_s = max(self.backoff_s, check_number("backoff_max_s", backoff_max_s, above=0.0))
        self.reconnect_wait_s = check_number("reconnect_wait_s", reconnect_wait_s, at_least=0.0)
        self._poll_s = min(0.02, max(0.002, timeout_s / 5))
        self._lock = threading.RLock()
        self._port: Any = None
        self._decoder = p.FrameDecoder()
        self._seq = secrets.randbelow(p.SEQ_MOD)  # each host starts at a random number
        self._backoff = backoff_s
        self._next_open_s = 0.0
        self._connected = False
        self._closed = False
        self.last_status: MillStatus | None = None
        self.last_ok_s: float | None = None  # time.monotonic() of the last valid answer
        self.last_error: str | None = None
        self.stats: dict[str, int] = {
            "requests": 0,
            "resends": 0,
            "timeouts": 0,
            "naks": 0,
            "bad_frames": 0,
            "reconnects": 0,
            "link_errors": 0,
        }
        self._stop = threading.Event()
        self._hb_thread: threading.Thread | None = None
        if connect:
            with self._lock:
                self._open(force=True)
        if heartbeat_s:
            self._hb_thread = threading.Thread(target=self._heartbeat_loop, name="mill-heartbeat", daemon=True)
            self._hb_thread.start()

    # -- public API ------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """True while the port is open and the last request was answered."""
        return self._connected

    def set_rpm(self, rpm: float) -> None:
        """Set the absolute speed setpoint (rpm); the device ramps to it while running."""
        rpm = float(rpm)
        if not (rpm >= 0.0 and rpm < 1e5):
            raise ControlError(f"rpm must be a number >= 0, got {rpm}")
        self._request(p.SET, round(rpm, 2))

    def start(self) -> None:
        """Start the motor (also clears a watchdog fault)."""
        self._request(p.RUN)

    def stop(self) -> None:
        """Stop the motor (it ramps down to 0 rpm)."""
        self._request(p.STP)

    def status(self) -> MillStatus:
        """Read setpoint, actual rpm, running and fault (does not feed the board's watchdog)."""
        return self._status_of(self._request(p.STA))

    def heartbeat(self, retries: int | None = None, wait_s: float | None = None) -> MillStatus:
        """Feed the device watchdog (controlling host only); returns the status it answers with."""
        return self._status_of(self._request(p.HB, retries=retries, wait_s=wait_s))

    def close(self) -> None:
        """Stop the heartbeat thread and close the port (idempotent)."""
        self._closed = True
        self._stop.set()
        if self._hb_thread is not None and self._hb_thread is not threading.current_thread():
            self._hb_thread.join(2.0)
        with self._lock:
            self._drop_port()

    def __enter__(self) -> MillClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals ---------------------------------------------------------------------------
    def _status_of(self, frame: p.Frame) -> MillStatus:
        st = p.parse_status(frame.args)
        self.last_status = st
        return st

    def _open(self, force: bool = False) -> None:
        """Open the port unless it is open; respects the back-off unless ``force``."""
        if self._port is not None:
            return
        now = time.monotonic()
        if not force and now < self._next_open_s:
            raise ConnectionError(f"mill link {self.url} down (next reconnect in {self._next_open_s - now:.2f} s)")
        try:
            kw = {} if self.url.startswith("rfc2217://") else {"write_timeout": WRITE_TIMEOUT_S}  # rfc2217 has none
            # a fixed short read timeout: changing it per read would re-configure the port
            # (tcsetattr; a whole settings negotiation on rfc2217://)
            port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=self._poll_s, **kw)
        except _OPEN_ERRORS as exc:
            self._next_open_s = now + self._backoff
            self._backoff = min(self.backoff_max_s, self._backoff * 2)
            self._connected = False
            errno = getattr(exc, "errno", None)
            why = os.strerror(errno) if isinstance(errno, int) else str(exc)
            self.last_error = why
            raise ConnectionError(f"cannot open mill link {self.url}: {why}") from None
        self._port = port
        self._decoder = p.FrameDecoder()
        self._backoff = self.backoff_s
        self.stats["reconnects"] += 1

    def _drop_port(self) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except Exception:
                pass
        self._port = None
        self._connected = False

    def _request(self, cmd: str, *args: object, retries: int | None = None, wait_s: float | None = None) -> p.Frame:
        retries = self.retries if retries is None else retries
        with self._lock:
            if self._closed:
                raise ControlError("the mill client is closed")
            self._seq = p.next_seq(self._seq)
            seq = self._seq
            line = p.encode_frame(seq, cmd, *args)
            self.stats["requests"] += 1
            last_problem = "no answer"
            wait_left = self.reconnect_wait_s if wait_s is None else wait_s
            for attempt in range(retries + 1):
                if attempt:
                    self.stats["resends"] += 1
                try:
                    self._open()
                except ConnectionError as exc:
                    last_problem = str(exc)
                    if wait_left <= 0:
                        break
                    wait_left -= self._sleep_backoff(wait_left)
                    continue
                try:
                    reply = self._exchange(line, seq)
                except _LINK_ERRORS as exc:
                    self.stats["link_errors"] += 1
                    self.last_error = last_problem = f"link error: {exc}"
                    self._drop_port()
                    self._next_open_s = time.monotonic() + self._backoff
                    continue
                if reply is None:
                    self.stats["timeouts"] += 1
                    last_problem = "timeout"
                    continue
                if reply.cmd == p.NAK:
                    self.stats["naks"] += 1
                    reason = reply.args[0] if reply.args else "?"
                    if reason == p.NAK_CRC:
                        last_problem = "checksum errors"
                        continue
                    self._mark_ok()
                    raise MillRefused(f"{cmd}{'' if not args else ' ' + str(args[0])}", str(reason))
                self._mark_ok()
                return reply
            self._connected = False
            if self._port is None:
                own = last_problem.startswith(("cannot open", "mill link"))
                raise ConnectionError(last_problem if own else f"mill link {self.url} down: {last_problem}")
            raise TimeoutError(
                f"no valid answer from the mill at {self.url} to {cmd} after {retries + 1} tries ({last_problem})"
            )

    def _mark_ok(self) -> None:
        self._connected = True
        self.last_ok_s = time.monotonic()
        self.last_error = None

    def _sleep_backoff(self, limit_s: float) -> float:
        """Sleep until the next reconnect attempt is due (at most ``limit_s``); returns the time slept."""
        wait = min(max(0.0, self._next_open_s - time.monotonic()), limit_s, self.backoff_max_s)
        if wait > 0:
            self._stop.wait(wait)
        return max(wait, 1e-3)

    def _exchange(self, line: bytes, seq: int) -> p.Frame | None:
        """Write ``line`` and wait up to ``timeout_s`` for the ACK/NAK with ``seq``.

        Returns None on timeout or when a garbled frame that could be our answer arrives
        (resending at once is faster than waiting out the timeout).
        """
        port = self._port
        port.write(line)
        deadline = time.monotonic() + self.timeout_s
        while True:
            if time.monotonic() >= deadline:
                return None
            data = port.read(max(1, port.in_waiting))
            if not data:
                continue
            for item in self._decoder.feed(data):
                if isinstance(item, p.BadFrame):
                    self.stats["bad_frames"] += 1
                    if item.reason == "crc" and item.seq in (seq, None):
                        return None
                    continue
                if item.seq == seq and item.cmd in (p.ACK, p.NAK):
                    return item

    def _heartbeat_loop(self) -> None:
        assert self.heartbeat_s
        while not self._stop.wait(self.heartbeat_s):
            try:
                self.heartbeat(retries=min(self.retries, 2), wait_s=0.0)  # never sleeps on a dead link
            except (ControlError, ConnectionError, TimeoutError):
                pass
            except Exception as exc:
                self.last_error = f"heartbeat: {exc}"

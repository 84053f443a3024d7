"""The motor board's firmware logic, as a pure state machine (no I/O, no clock).

``MillDevice.receive(data, now_s)`` takes the bytes that arrived and returns the bytes to
send back; ``tick(now_s)`` advances the motor and the watchdog. The emulator
(``control.emulator``) wraps it in a pty or TCP transport; the Arduino reference sketch
(``docs/firmware/mill_board.ino``) implements the same rules.

Rules (see ``docs/mill-protocol.md``):

- only the *controlling* host's frames feed the watchdog: ``HB``, ``SET``, ``RUN`` and
  ``STP`` (answered ACK or NAK, resends included); ``STA`` (status) does not, so a status
  poller (a second dashboard, a monitoring script) never keeps the motor running after
  the controlling host died. A frame with a bad checksum whose sequence number can
  still be read gets ``NAK,CRC`` (the host resends at once); anything else that is not
  a frame is dropped silently;
- a state-changing frame (``SET RUN STP``) with the same sequence number *and* payload as
  the previous one is a resend: the cached reply is sent again and nothing is applied a
  second time, except that a ``STP`` resend still stops a motor found running (started
  since from the front panel: a stop is never refused); ``STA``/``HB`` change nothing and
  are always answered with a fresh status (never from the cache, so another host's
  request with the same number can never return a stale status);
- ``STP`` is never refused: not with the watchdog off, not before any heartbeat, not after
  a NAK'd command, not while faulted (only ``STP`` with an argument is not a stop: ``ARG``);
- ``SET`` takes an absolute setpoint in 0..max rpm (idempotent), ``RUN`` starts (and
  clears a watchdog fault), ``STP`` stops, ``STA``/``HB`` answer with the status;
- while running, no watchdog-feeding frame for ``watchdog_s`` stops the motor with fault
  ``WDOG``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from control import protocol as p
from control.motor import MotorConfig, MotorModel


@dataclass(frozen=True)
class DeviceConfig:
    """Board settings: watchdog time (s; 0 disables it, commissioning only) and the drive model."""

    watchdog_s: float = 1.0
    motor: MotorConfig = field(default_factory=MotorConfig)


@dataclass(frozen=True)
class Applied:
    """A state-changing command the board carried out (for audit and tests)."""

    t_s: float
    seq: int
    cmd: str
    args: tuple[str, ...]


class MillDevice:
    """Protocol + motor + watchdog of the board. Not thread-safe (the emulator locks)."""

    def __init__(self, config: DeviceConfig | None = None, now_s: float = 0.0) -> None:
        self.config = config or DeviceConfig()
        self.motor = MotorModel(self.config.motor)
        self.decoder = p.FrameDecoder()
        self.applied: list[Applied] = []
        self.counters: dict[str, int] = {
            "frames": 0,
            "resends": 0,
            "nak": 0,
            "bad_crc": 0,
            "bad_other": 0,
            "watchdog_trips": 0,
        }
        self._last_key: tuple[int, str] | None = None
        self._last_reply = b""
        self._last_valid_s = now_s
        self._t_s = now_s

    # -- input ---------------------------------------------------------------------------
    def receive(self, data: bytes, now_s: float) -> bytes:
        """Consume received bytes; return the reply bytes (possibly empty)."""
        self.tick(now_s)
        out = bytearray()
        for item in self.decoder.feed(data):
            if isinstance(item, p.BadFrame):
                if item.reason == "crc" and item.seq is not None:
                    self.counters["bad_crc"] += 1
                    self.counters["nak"] += 1
                    out += p.encode_frame(item.seq, p.NAK, p.NAK_CRC)
                else:
                    self.counters["bad_other"] += 1
                continue
            out += self._handle(item, now_s)
        return bytes(out)

    def _handle(self, frame: p.Frame, now_s: float) -> bytes:
        self.counters["frames"] += 1
        if frame.cmd in p.WATCHDOG_COMMANDS:
            self._last_valid_s = now_s
        if frame.cmd in p.READ_ONLY_COMMANDS:  # a fresh status, never from or into the cache
            return self._execute(frame, now_s)
        key = (frame.seq, frame.payload)
        if key == self._last_key:
            self.counters["resends"] += 1
            if frame.cmd == p.STP and self.motor.running:  # a stop is never just a cached answer
                self.motor.running = False
                self.applied.append(Applied(now_s, frame.seq, frame.cmd, frame.args))
            return self._last_reply
        reply = self._execute(frame, now_s)
        self._last_key, self._last_reply = key, reply
        return reply

    def _nak(self, seq: int, reason: str) -> bytes:
        self.counters["nak"] += 1
        return p.encode_frame(seq, p.NAK, reason)

    def _execute(self, f: p.Frame, now_s: float) -> bytes:
        m = self.motor
        if f.cmd == p.SET:
            if len(f.args) != 1:
                return self._nak(f.seq, p.NAK_ARG)
            rpm = p.parse_rpm_arg(f.args[0])
            if rpm is None:
                return self._nak(f.seq, p.NAK_ARG)
            if rpm > m.config.max_rpm:
                return self._nak(f.seq, p.NAK_RANGE)
            m.setpoint_rpm = rpm
        elif f.cmd in (p.RUN, p.STP, p.STA, p.HB):
            if f.args:
                return self._nak(f.seq, p.NAK_ARG)
            if f.cmd == p.RUN:
                if m.fault == p.FAULT_DRIVE:
                    return self._nak(f.seq, p.NAK_FAULT)
                m.fault = None
                m.running = True
            elif f.cmd == p.STP:
                m.running = False
            else:
                return p.encode_frame(f.seq, p.ACK, *p.status_args(self.status()))
        else:
            return self._nak(f.seq, p.NAK_CMD)
        self.applied.append(Applied(now_s, f.seq, f.cmd, f.args))
        return p.encode_frame(f.seq, p.ACK)

    # -- time ----------------------------------------------------------------------------
    def tick(self, now_s: float) -> None:
        """Advance the motor to ``now_s`` and trip the watchdog when the host went quiet."""
        dt = now_s - self._t_s
        if dt > 0:
            self.motor.step(dt)
            self._t_s = now_s
        if self.config.watchdog_s > 0 and self.motor.running and now_s - self._last_valid_s > self.config.watchdog_s:
            self.motor.running = False
            self.motor.fault = p.FAULT_WATCHDOG
            self.counters["watchdog_trips"] += 1

    def feed_watchdog(self, now_s: float) -> None:
        """Restart the watchdog time (as a watchdog-feeding frame would)."""
        self._last_valid_s = now_s

    def status(self) -> p.MillStatus:
        m = self.motor
        return p.MillStatus(round(m.setpoint_rpm, 2), round(m.actual_rpm, 2), m.running, m.fault)

"""A frequency inverter's behaviour behind its registers, as a pure state machine (no I/O,
no clock): what the drive emulator serves over pymodbus.

``DriveModel.write(address, words, now_s)`` applies a register write the way the profile's
manual says (run/stop command word, fault reset, frequency setpoint in counts, comm-loss
parameters); ``read(address, count, now_s)`` answers with the live status. The motor is
``control.motor.MotorModel`` in Hz (the drive's acceleration ramp, a short lag).

Comm-loss trip (the drive's own watchdog): while running, no write to the command, reset
or setpoint register for the comm-loss time trips the drive when its action is a safe one
(fault latched, a run command is ignored until a fault reset; the motor ramps to 0 Hz when
the action is one of the profile's ``ramp_actions``, else it coasts: output off at once);
an unsafe action (keep running, warn) only counts the event. Reads never feed it.

Writes by the book (the Modbus application protocol's exception codes): a register the
drive does not have, or one it only reports (status, output, fault, identity, the gaps of
a read block), is exception 2 (illegal data address); a setpoint above ``max_hz`` (the
word read unsigned: 65535 is 655.35 Hz at 100 counts/Hz, not -0.01 Hz) or a comm-loss
action or code the profile does not list is exception 3 (illegal data value); nothing of a
refused write is applied. The status word follows the output: ``decelerating_word`` while
the output ramps down (when the profile has one), the stopped word only at 0 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass

from control.modbus.profile import DriveProfile, read_blocks
from control.motor import MotorConfig, MotorModel

ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3


@dataclass(frozen=True)
class DriveWrite:
    """A register write the drive applied (for audit and tests)."""

    t_s: float
    address: int
    value: int


class DriveModel:
    """Registers + motor (Hz) + comm-loss trip of one drive. Not thread-safe."""

    def __init__(self, profile: DriveProfile, *, comm_loss_s: float = 2.0, tau_s: float = 0.2, now_s: float = 0.0):
        self.profile = profile
        # the motor model in Hz: the drive's ramp (accel_hz_per_s) and a short speed-loop lag
        self.motor = MotorModel(MotorConfig(profile.max_hz, profile.accel_hz_per_s, tau_s))
        # every address of the blocks a host reads in one request (the gaps read as 0)
        self.regs: dict[int, int] = {
            a: 0 for start, n in read_blocks(profile.all_registers) for a in range(start, start + n)
        }
        self.regs.update(profile.emulator_identity)
        self.fault_code = 0
        self.writes: list[DriveWrite] = []
        self.counters = {"reads": 0, "writes": 0, "comm_loss_trips": 0, "comm_loss_ignored": 0}
        self.trip_times_s: list[float] = []  # when (drive clock, s) each comm-loss trip stopped the motor
        self._last_feed_s = now_s
        self._t_s = now_s
        self._lost = False  # the current silence was already acted upon
        self.commission(comm_loss_s)

    # -- commissioning ---------------------------------------------------------------------
    def commission(self, comm_loss_s: float, safe: bool = True) -> None:
        """Set the comm-loss parameters: trip after ``comm_loss_s`` (0: disabled) with a safe
        action (``safe``) or an unsafe one (keep running)."""
        cl = self.profile.comm_loss
        if cl.code_register is not None:
            want = [c for c, (s, _, ok) in cl.codes.items() if ok == safe and s > 0]
            code = 0 if comm_loss_s <= 0 or not want else min(want, key=lambda c: abs(cl.codes[c][0] - comm_loss_s))
            self.regs[cl.code_register] = (code << cl.code_shift) & cl.code_mask
            return
        assert cl.time_register is not None
        self.regs[cl.time_register] = int(round(max(comm_loss_s, 0.0) * cl.time_counts_per_s))
        if cl.action_register is not None:
            unsafe = [a for a in cl.actions if a not in cl.safe_actions]
            action = cl.recommended_action if safe else (unsafe[0] if unsafe else 0)
            self.regs[cl.action_register] = int(action or 0)

    def comm_loss_time_s(self) -> float:
        """The trip time the parameters say now (0: disabled)."""
        s = self.profile.comm_loss_setting(self.regs)
        return s.time_s

    # -- the drive's front panel (tests, demo) ----------------------------------------------
    def set_fault(self, code: int | None) -> None:
        """Raise fault ``code`` (the motor coasts: output off at once) or clear it (None)."""
        if code:
            self.fault_code = int(code)
            self._halt(ramp=False)
        else:
            self.fault_code = 0
        self._refresh()

    def _halt(self, ramp: bool) -> None:
        """Stop the motor: ramp down (a stop command, a ramp trip) or coast (output off at once)."""
        self.motor.running = False
        if not ramp:
            self.motor.actual_rpm = 0.0

    def feed(self, now_s: float) -> None:
        """Restart the comm-loss time (what a write to the command, reset or setpoint does)."""
        self._last_feed_s = now_s
        self._lost = False

    # -- the bus -------------------------------------------------------------------------
    def write(self, address: int, words: list[int], now_s: float) -> int | None:
        """Apply a write of ``words`` from ``address``; a Modbus exception code (nothing
        applied) or None."""
        self.tick(now_s)
        err = self.write_error(address, words)
        if err is not None:
            return err
        p = self.profile
        for i, w in enumerate(words):
            a = address + i
            old = self.regs[a]
            self.regs[a] = w
            self.counters["writes"] += 1
            self.writes.append(DriveWrite(now_s, a, w))
            if a in (p.control_register, p.reset_register, p.setpoint_register):
                self.feed(now_s)
            if a == p.reset_register and p.reset_mask and (w & p.reset_mask) and not (old & p.reset_mask):
                self.fault_code = 0
            if a == p.setpoint_register:
                self.motor.setpoint_rpm = p.setpoint.to_hz(w)
            if a == p.control_register:
                cmd = p.command_of(w)
                if cmd == "run" and not self.fault_code:
                    self.motor.running = True
                elif cmd == "stop":
                    self._halt(ramp=True)
        self._refresh()
        return None

    def write_error(self, address: int, words: list[int]) -> int | None:
        """The exception code a write of ``words`` from ``address`` gets (see module doc),
        None when the drive takes it (pure)."""
        p = self.profile
        cl = p.comm_loss
        writable = p.writable_registers
        if any(address + i not in writable or address + i not in self.regs for i in range(len(words))):
            return ILLEGAL_ADDRESS
        for i, w in enumerate(words):
            a = address + i
            if a == p.setpoint_register and w > p.setpoint.to_counts(p.max_hz):  # unsigned: no reverse
                return ILLEGAL_VALUE
            if a == cl.action_register and cl.actions and w not in cl.actions:
                return ILLEGAL_VALUE
            if a == cl.code_register and ((w & cl.code_mask) >> cl.code_shift) not in cl.codes:
                return ILLEGAL_VALUE
        return None

    def read(self, address: int, count: int, now_s: float) -> list[int] | int:
        """The words at ``address``.. (live status); a Modbus exception code when unmapped."""
        self.tick(now_s)
        self.counters["reads"] += 1
        out = []
        for a in range(address, address + count):
            if a not in self.regs:
                return ILLEGAL_ADDRESS
            out.append(self.regs[a])
        return out

    def tick(self, now_s: float) -> None:
        """Advance the motor and the comm-loss trip to ``now_s``."""
        dt = now_s - self._t_s
        if dt > 0:
            self.motor.step(dt)
            self._t_s = now_s
        setting = self.profile.comm_loss_setting(self.regs)
        if self.motor.running and setting.time_s > 0 and not self._lost and now_s - self._last_feed_s > setting.time_s:
            self._lost = True
            if setting.safe:
                self.counters["comm_loss_trips"] += 1
                self.trip_times_s.append(now_s)
                self.fault_code = self.profile.comm_loss_fault_code
                self._halt(ramp=self.profile.comm_loss_ramps(self.regs))
            else:
                self.counters["comm_loss_ignored"] += 1
        self._refresh()

    def _refresh(self) -> None:
        p = self.profile
        m = self.motor
        if m.running:
            word = p.running_word
        elif m.actual_rpm > 0 and p.decelerating_word is not None:  # the output still ramps down
            word = p.decelerating_word
        else:
            word = p.stopped_word
        if self.fault_code and p.tripped_mask:
            word = (word & ~p.tripped_mask) | p.tripped_value
        regs = self.regs
        if p.fault_register == p.status_register:  # packed (E3): fault code in its own bits
            word = (word & ~p.fault_mask) | ((self.fault_code << p.fault_shift) & p.fault_mask)
        else:
            regs[p.fault_register] = (self.fault_code << p.fault_shift) & p.fault_mask
        regs[p.status_register] = word & 0xFFFF
        regs[p.readback_register] = p.setpoint.to_counts(m.setpoint_rpm) & 0xFFFF
        regs[p.output_register] = p.output.to_counts(m.actual_rpm) & 0xFFFF


__all__ = ["ILLEGAL_ADDRESS", "ILLEGAL_VALUE", "DriveModel", "DriveWrite"]

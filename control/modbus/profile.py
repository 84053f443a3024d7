"""Drive profiles: a drive's Modbus register map as data (TOML), and the pure functions that
turn its words into numbers (no I/O).

A profile names the run/stop command register and its words, the frequency setpoint
register and its scaling (``counts`` per ``hz``), the status word and how to read running
and tripped from it, the output frequency, the fault code register and the codes' meaning,
and the drive's comm-loss trip parameters (time and action, or one packed code). Shipped
profiles live in ``control/modbus/profiles/``; ``load_profile`` takes a shipped name or a
path to a TOML file (see ``generic.toml`` and ``docs/drives.md``). Addresses are Modbus PDU
addresses (0-based: holding register 40001 is address 0).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from control.errors import ControlError, check_number

SHIPPED = ("delta-ms300", "abb-acs", "siemens-v20", "invertek-e3", "generic")
"""The profiles shipped in the package (``control/modbus/profiles/NAME.toml``)."""

READ_GAP = 16
"""Registers closer than this are read in one request (see :func:`read_blocks`)."""


@dataclass(frozen=True)
class Scale:
    """``counts`` register counts mean ``hz`` Hz (e.g. 100 per 1 Hz; 20000 per 50 Hz)."""

    counts: float
    hz: float

    @property
    def counts_per_hz(self) -> float:
        return self.counts / self.hz

    def to_counts(self, hz: float) -> int:
        """Hz -> the nearest register count."""
        return int(round(hz * self.counts_per_hz))

    def to_hz(self, counts: int) -> float:
        """Register count (unsigned 16 bit) -> Hz (counts >= 0x8000 read as negative)."""
        c = counts - 0x10000 if counts >= 0x8000 else counts
        return c / self.counts_per_hz


@dataclass(frozen=True)
class CommLoss:
    """The drive's comm-loss trip: either a time register (``time_counts_per_s``; 0 =
    disabled) plus an optional action register (``safe_actions`` stop the motor), or one
    packed ``code_register`` whose codes map to (seconds, action, safe)."""

    time_parameter: str
    action_parameter: str = ""
    time_register: int | None = None
    time_counts_per_s: float = 1.0
    action_register: int | None = None
    safe_actions: tuple[int, ...] = ()
    recommended_action: int | None = None
    actions: dict[int, str] = field(default_factory=dict)
    code_register: int | None = None
    code_mask: int = 0xFFFF
    code_shift: int = 0
    codes: dict[int, tuple[float, str, bool]] = field(default_factory=dict)
    recommended_code: int | None = None
    ramp_actions: tuple[int, ...] = ()
    """Actions (or codes) whose trip ramps the motor down; any other trip coasts (output off at once)."""

    @property
    def registers(self) -> tuple[int, ...]:
        return tuple(r for r in (self.time_register, self.action_register, self.code_register) if r is not None)


@dataclass(frozen=True)
class CommLossSetting:
    """What the drive's comm-loss parameters say: trip time (s; 0 = disabled), action, safe."""

    time_s: float
    action: str
    safe: bool


@dataclass(frozen=True)
class DriveProfile:
    """One drive family's register map (see module doc and ``docs/drives.md``)."""

    name: str
    title: str
    max_hz: float
    hz_per_rpm: float
    control_register: int
    run_words: tuple[int, ...]
    stop_word: int
    run_mask: int
    run_bits: int
    stop_mask: int
    stop_bits: int
    reset_register: int
    reset_words: tuple[int, ...]
    reset_mask: int
    setpoint_register: int
    setpoint: Scale
    status_register: int
    running_mask: int
    running_value: int
    running_word: int
    stopped_word: int
    readback_register: int
    output_register: int
    output: Scale
    fault_register: int
    fault_mask: int
    fault_shift: int
    fault_codes: dict[int, str]
    drive_fault_code: int
    comm_loss_fault_code: int
    comm_loss: CommLoss
    tripped_mask: int = 0
    tripped_value: int = 0
    decelerating_word: int | None = None  # status word while the output ramps down (None: stopped_word)
    identity: dict[str, int] = field(default_factory=dict)
    emulator_identity: dict[int, int] = field(default_factory=dict)
    accel_hz_per_s: float = 10.0

    # -- pure decoding -------------------------------------------------------------------
    def is_running(self, status_word: int) -> bool:
        return (status_word & self.running_mask) == self.running_value

    def is_tripped(self, status_word: int, fault_word: int) -> bool:
        """Tripped by the status word's trip bits when the profile has them, else by a
        non-zero fault code."""
        if self.tripped_mask:
            return (status_word & self.tripped_mask) == self.tripped_value
        return self.fault_code(fault_word) != 0

    def fault_code(self, fault_word: int) -> int:
        return (fault_word & self.fault_mask) >> self.fault_shift

    def fault_name(self, code: int) -> str:
        """Short name of a fault code (the part before ``:``), ``code N`` when unknown."""
        text = self.fault_codes.get(code)
        return text.split(":", 1)[0].strip() if text else f"code {code}"

    def fault_text(self, code: int) -> str:
        return self.fault_codes.get(code, f"fault code {code} (not in the {self.name} profile)")

    def command_of(self, word: int) -> str | None:
        """``"run"``, ``"stop"`` or None: what a control word written to the drive means."""
        if (word & self.run_mask) == self.run_bits:
            return "run"
        if (word & self.stop_mask) == self.stop_bits:
            return "stop"
        return None

    def comm_loss_setting(self, values: dict[int, int]) -> CommLossSetting:
        """Decode the comm-loss parameters from ``{address: word}`` (as read from the drive)."""
        cl = self.comm_loss
        if cl.code_register is not None:
            code = (values[cl.code_register] & cl.code_mask) >> cl.code_shift
            secs, action, safe = cl.codes.get(code, (0.0, f"unknown code {code}", False))
            return CommLossSetting(secs, action, safe and secs > 0)
        assert cl.time_register is not None
        time_s = values[cl.time_register] / cl.time_counts_per_s
        if cl.action_register is None:
            return CommLossSetting(time_s, "fault (trip)", time_s > 0)
        a = values[cl.action_register]
        return CommLossSetting(time_s, cl.actions.get(a, f"action {a}"), a in cl.safe_actions and time_s > 0)

    def comm_loss_ramps(self, values: dict[int, int]) -> bool:
        """Whether the comm-loss action set in ``values`` ramps the motor down (else it coasts)."""
        cl = self.comm_loss
        if cl.code_register is not None:
            return ((values[cl.code_register] & cl.code_mask) >> cl.code_shift) in cl.ramp_actions
        return cl.action_register is not None and values[cl.action_register] in cl.ramp_actions

    def comm_loss_advice(self, limit_s: float) -> str:
        """What to set on the drive: the parameter(s) and the value(s) for a ``limit_s`` trip."""
        cl = self.comm_loss
        if cl.code_register is not None:
            best = cl.recommended_code
            ok = [c for c, (s, _, safe) in cl.codes.items() if safe and 0 < s <= limit_s]
            if best is None or best not in ok:
                best = max(ok, key=lambda c: cl.codes[c][0]) if ok else None
            if best is None:
                return f"set {cl.time_parameter} to a trip of at most {limit_s:g} s"
            return f"set {cl.time_parameter} to {cl.codes[best][1]} (code {best})"
        t = f"set {cl.time_parameter} to {min(limit_s, 2.0):g} s"
        if cl.action_register is not None and cl.recommended_action is not None:
            act = cl.actions.get(cl.recommended_action, str(cl.recommended_action))
            t += f" and {cl.action_parameter} to {cl.recommended_action} ({act})"
        return t

    @property
    def status_registers(self) -> tuple[int, ...]:
        """Every register one status read needs."""
        return tuple(sorted({self.status_register, self.readback_register, self.output_register, self.fault_register}))

    @property
    def writable_registers(self) -> frozenset[int]:
        """The registers a host may write: command, reset, setpoint and the comm-loss
        parameters; every other register the drive serves is read-only."""
        return frozenset({self.control_register, self.reset_register, self.setpoint_register,
                          *self.comm_loss.registers})

    @property
    def all_registers(self) -> tuple[int, ...]:
        """Every register the profile names (what an emulator must serve)."""
        regs = {self.control_register, self.reset_register, self.setpoint_register, *self.status_registers}
        regs |= set(self.comm_loss.registers) | set(self.identity.values()) | set(self.emulator_identity)
        return tuple(sorted(regs))


def read_blocks(addresses: tuple[int, ...] | list[int], gap: int = READ_GAP) -> list[tuple[int, int]]:
    """Group register addresses into (start, count) blocks: one read each (pure)."""
    out: list[tuple[int, int]] = []
    for a in sorted(set(addresses)):
        if out and a - (out[-1][0] + out[-1][1]) < gap:
            start = out[-1][0]
            out[-1] = (start, a - start + 1)
        else:
            out.append((a, 1))
    return out


def profile_names() -> list[str]:
    """The shipped profile names."""
    return list(SHIPPED)


def load_profile(name_or_path: str) -> DriveProfile:
    """A shipped profile by name, or a TOML file by path; one-line ``ControlError`` when it
    cannot be read or a key is missing or wrong."""
    if name_or_path in SHIPPED:
        text = resources.files("control.modbus").joinpath("profiles", f"{name_or_path}.toml").read_text()
        where = name_or_path
    else:
        p = Path(name_or_path)
        if not p.suffix == ".toml" or not p.is_file():
            raise ControlError(
                f"unknown drive profile {name_or_path!r} (shipped: {', '.join(SHIPPED)}; or a path to a .toml file)"
            )
        try:
            text = p.read_text()
        except OSError as exc:
            raise ControlError(f"cannot read drive profile {p}: {exc.strerror}") from None
        where = str(p)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ControlError(f"drive profile {where}: {exc}") from None
    try:
        return _build(data)
    except KeyError as exc:
        raise ControlError(f"drive profile {where}: missing key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise ControlError(f"drive profile {where}: {exc}") from None


def _reg(v: Any, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 0xFFFF:
        raise ValueError(f"{what} must be a register address or word 0..65535 (got {v!r})")
    return v


def _scale(d: dict[str, Any], what: str) -> Scale:
    return Scale(check_number(f"{what}.counts", d["counts"], above=0.0),
                 check_number(f"{what}.hz", d["hz"], above=0.0))


def _int_keys(d: dict[str, Any]) -> dict[int, Any]:
    return {int(k, 0): v for k, v in d.items()}


def _build(d: dict[str, Any]) -> DriveProfile:
    c, s, st, o, f, cl = d["control"], d["setpoint"], d["status"], d["output"], d["fault"], d["comm_loss"]
    if "code_register" in cl:
        comm = CommLoss(
            time_parameter=str(cl["time_parameter"]),
            action_parameter=str(cl.get("action_parameter", cl["time_parameter"])),
            code_register=_reg(cl["code_register"], "comm_loss.code_register"),
            code_mask=_reg(cl.get("code_mask", 0xFFFF), "comm_loss.code_mask"),
            code_shift=int(cl.get("code_shift", 0)),
            codes={k: (float(v[0]), str(v[1]), bool(v[2])) for k, v in _int_keys(cl["codes"]).items()},
            recommended_code=cl.get("recommended_code"),
            ramp_actions=tuple(int(a) for a in cl.get("ramp_actions", ())),
        )
    else:
        comm = CommLoss(
            time_parameter=str(cl["time_parameter"]),
            action_parameter=str(cl.get("action_parameter", "")),
            time_register=_reg(cl["time_register"], "comm_loss.time_register"),
            time_counts_per_s=check_number("comm_loss.time_counts_per_s", cl.get("time_counts_per_s", 1), above=0.0),
            action_register=(None if "action_register" not in cl
                             else _reg(cl["action_register"], "comm_loss.action_register")),
            safe_actions=tuple(int(a) for a in cl.get("safe_actions", ())),
            recommended_action=cl.get("recommended_action"),
            actions={k: str(v) for k, v in _int_keys(cl.get("actions", {})).items()},
            ramp_actions=tuple(int(a) for a in cl.get("ramp_actions", ())),
        )
    emu = d.get("emulator", {})
    ident = list(emu.get("identity", []))
    if len(ident) % 2:
        raise ValueError("emulator.identity must be address, value pairs")
    run_words = tuple(_reg(w, "control.run_words") for w in c["run_words"])
    if not run_words:
        raise ValueError("control.run_words must not be empty")
    return DriveProfile(
        name=str(d["name"]),
        title=str(d.get("title", d["name"])),
        max_hz=check_number("max_hz", d["max_hz"], above=0.0),
        hz_per_rpm=check_number("hz_per_rpm", d.get("hz_per_rpm", 1.0), above=0.0),
        control_register=_reg(c["register"], "control.register"),
        run_words=run_words,
        stop_word=_reg(c["stop_word"], "control.stop_word"),
        run_mask=_reg(c["run_mask"], "control.run_mask"),
        run_bits=_reg(c["run_bits"], "control.run_bits"),
        stop_mask=_reg(c["stop_mask"], "control.stop_mask"),
        stop_bits=_reg(c["stop_bits"], "control.stop_bits"),
        reset_register=_reg(c.get("reset_register", c["register"]), "control.reset_register"),
        reset_words=tuple(_reg(w, "control.reset_words") for w in c.get("reset_words", ())),
        reset_mask=_reg(c.get("reset_mask", 0), "control.reset_mask"),
        setpoint_register=_reg(s["register"], "setpoint.register"),
        setpoint=_scale(s, "setpoint"),
        status_register=_reg(st["register"], "status.register"),
        running_mask=_reg(st["running_mask"], "status.running_mask"),
        running_value=_reg(st["running_value"], "status.running_value"),
        running_word=_reg(st["running_word"], "status.running_word"),
        stopped_word=_reg(st["stopped_word"], "status.stopped_word"),
        tripped_mask=_reg(st.get("tripped_mask", 0), "status.tripped_mask"),
        tripped_value=_reg(st.get("tripped_value", 0), "status.tripped_value"),
        decelerating_word=None if "decelerating_word" not in st else _reg(st["decelerating_word"],
                                                                          "status.decelerating_word"),
        readback_register=_reg(st.get("readback_register", s["register"]), "status.readback_register"),
        output_register=_reg(o["register"], "output.register"),
        output=_scale(o, "output"),
        fault_register=_reg(f["register"], "fault.register"),
        fault_mask=_reg(f.get("mask", 0xFFFF), "fault.mask"),
        fault_shift=int(f.get("shift", 0)),
        fault_codes={k: str(v) for k, v in _int_keys(f.get("codes", {})).items()},
        drive_fault_code=int(f["drive_fault"]),
        comm_loss_fault_code=int(f["comm_loss"]),
        comm_loss=comm,
        identity={str(k): _reg(v, f"identity.{k}") for k, v in d.get("identity", {}).items()},
        emulator_identity={_reg(ident[i], "emulator.identity"): int(ident[i + 1]) for i in range(0, len(ident), 2)},
        accel_hz_per_s=check_number("emulator.accel_hz_per_s", emu.get("accel_hz_per_s", 10.0), above=0.0),
    )


__all__ = [
    "SHIPPED", "CommLoss", "CommLossSetting", "DriveProfile", "Scale", "load_profile", "profile_names", "read_blocks",
]

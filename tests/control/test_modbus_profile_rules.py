"""Drive profiles (control/modbus/profile.py) rule by rule: every key of a profile TOML reaches
its field, the optional ones get their documented defaults, a bad value is a one-line error
naming its key, and the pure decoding of words and comm-loss parameters at its edges. The
profiles are written by the tests (a user's own profile is the input this module reads)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from control.errors import ControlError
from control.modbus.profile import load_profile


def toml(d: dict[str, Any]) -> str:
    """The TOML text of ``d`` (scalars, lists and nested tables: what a profile holds)."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return json.dumps(v)

    def table(name: str, t: dict[str, Any]) -> list[str]:
        lines = [f"[{name}]"] if name else []
        lines += [f"{json.dumps(k)} = {value(v)}" for k, v in t.items() if not isinstance(v, dict)]
        for k, v in t.items():
            if isinstance(v, dict):
                lines += table(f"{name}.{json.dumps(k)}" if name else json.dumps(k), v)
        return lines

    return "\n".join(table("", d)) + "\n"


MINIMAL: dict[str, Any] = {
    "name": "mini", "max_hz": 50.0,
    "control": {"register": 0x10, "run_words": [0x11], "stop_word": 0x13, "run_mask": 0x14, "run_bits": 0x15,
                "stop_mask": 0x16, "stop_bits": 0x17},
    "setpoint": {"register": 0x20, "counts": 200, "hz": 2.0},
    "status": {"register": 0x30, "running_mask": 0x31, "running_value": 0x32, "running_word": 0x33,
               "stopped_word": 0x34},
    "output": {"register": 0x40, "counts": 300, "hz": 3.0},
    "fault": {"register": 0x50, "drive_fault": 0x52, "comm_loss": 0x53},
    "comm_loss": {"time_parameter": "T", "time_register": 0x60},
}


def load(tmp_path: Path, d: dict[str, Any], name: str = "p.toml"):  # type: ignore[no-untyped-def]
    path = tmp_path / name
    path.write_text(toml(d))
    return load_profile(str(path))


def refused(tmp_path: Path, d: dict[str, Any]) -> str:
    with pytest.raises(ControlError) as e:
        load(tmp_path, d)
    prefix = f"drive profile {tmp_path / 'p.toml'}: "
    assert str(e.value).startswith(prefix), str(e.value)
    return str(e.value)[len(prefix):]


def test_a_bad_comm_loss_action_register_is_named_with_its_table(tmp_path: Path) -> None:
    d = {**MINIMAL, "comm_loss": {**MINIMAL["comm_loss"], "action_register": 70000}}
    assert refused(tmp_path, d) == "comm_loss.action_register must be a register address or word 0..65535 (got 70000)"

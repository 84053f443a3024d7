"""Drive profiles (control/modbus/profile.py) rule by rule: every key of a profile TOML reaches
its field, the optional ones get their documented defaults, a bad value is a one-line error
naming its key, and the pure decoding of words and comm-loss parameters at its edges. The
profiles are written by the tests (a user's own profile is the input this module reads)."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from control.errors import ControlError
from control.modbus.profile import (
    SHIPPED,
    CommLoss,
    CommLossSetting,
    DriveProfile,
    Scale,
    load_profile,
    profile_names,
    read_blocks,
)


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


FULL: dict[str, Any] = {
    "name": "full", "title": "Full drive", "max_hz": 55.0, "hz_per_rpm": 2.5,
    "control": {**MINIMAL["control"], "run_words": [0x11, 0x12], "reset_register": 0x18, "reset_words": [0x19, 0x1A],
                "reset_mask": 0x1B},
    "setpoint": MINIMAL["setpoint"],
    "status": {**MINIMAL["status"], "tripped_mask": 0x35, "tripped_value": 0x36, "decelerating_word": 0x37,
               "readback_register": 0x38},
    "output": MINIMAL["output"],
    "fault": {**MINIMAL["fault"], "mask": 0x51, "shift": 2, "codes": {"0x52": "drv: drive fault", "83": "cl: lost"}},
    "comm_loss": {"time_parameter": "T", "time_register": 0x60, "time_counts_per_s": 100, "action_register": 0x61,
                  "action_parameter": "A", "safe_actions": [1, 2], "recommended_action": 2, "ramp_actions": [2],
                  "actions": {"0": "keep", "1": "coast", "2": "ramp"}},
    "identity": {"id a": 0x70, "id b": 0x71},
    "emulator": {"identity": [0x70, 5, 0x71, 6], "accel_hz_per_s": 7.5},
}
CODES: dict[str, Any] = {"code_register": 0x62, "time_parameter": "P", "codes": {
    "0": [0.0, "off", False], "1": [1.0, "trip", True], "2": [2.0, "ramp", True], "3": [1.5, "warn", False]}}


def _expected(**kw: Any) -> DriveProfile:
    base: dict[str, Any] = dict(
        name="mini", title="mini", max_hz=50.0, hz_per_rpm=1.0, control_register=0x10, run_words=(0x11,),
        stop_word=0x13, run_mask=0x14, run_bits=0x15, stop_mask=0x16, stop_bits=0x17, reset_register=0x10,
        reset_words=(), reset_mask=0, setpoint_register=0x20, setpoint=Scale(200.0, 2.0), status_register=0x30,
        running_mask=0x31, running_value=0x32, running_word=0x33, stopped_word=0x34, readback_register=0x20,
        output_register=0x40, output=Scale(300.0, 3.0), fault_register=0x50, fault_mask=0xFFFF, fault_shift=0,
        fault_codes={}, drive_fault_code=0x52, comm_loss_fault_code=0x53,
        comm_loss=CommLoss(time_parameter="T", time_register=0x60), tripped_mask=0, tripped_value=0,
        decelerating_word=None, identity={}, emulator_identity={}, accel_hz_per_s=10.0)
    base.update(kw)
    return DriveProfile(**base)


def test_a_minimal_profile_gets_the_documented_defaults(tmp_path: Path) -> None:
    p = load(tmp_path, MINIMAL)
    assert p == _expected()
    assert p.comm_loss == CommLoss("T", "", 0x60, 1.0, None, (), None, {}, None, 0xFFFF, 0, {}, None, ())


def test_every_key_of_a_full_profile_reaches_its_field(tmp_path: Path) -> None:
    assert load(tmp_path, FULL) == _expected(
        name="full", title="Full drive", max_hz=55.0, hz_per_rpm=2.5, run_words=(0x11, 0x12), reset_register=0x18,
        reset_words=(0x19, 0x1A), reset_mask=0x1B, tripped_mask=0x35, tripped_value=0x36, decelerating_word=0x37,
        readback_register=0x38, fault_mask=0x51, fault_shift=2, fault_codes={0x52: "drv: drive fault", 83: "cl: lost"},
        comm_loss=CommLoss(time_parameter="T", action_parameter="A", time_register=0x60, time_counts_per_s=100.0,
                           action_register=0x61, safe_actions=(1, 2), recommended_action=2,
                           actions={0: "keep", 1: "coast", 2: "ramp"}, ramp_actions=(2,)),
        identity={"id a": 0x70, "id b": 0x71}, emulator_identity={0x70: 5, 0x71: 6}, accel_hz_per_s=7.5)


def test_a_packed_comm_loss_code_and_its_defaults(tmp_path: Path) -> None:
    codes = {0: (0.0, "off", False), 1: (1.0, "trip", True), 2: (2.0, "ramp", True), 3: (1.5, "warn", False)}
    assert load(tmp_path, {**MINIMAL, "comm_loss": CODES}).comm_loss == CommLoss(
        time_parameter="P", action_parameter="P", code_register=0x62, codes=codes)
    full = {**CODES, "action_parameter": "Q", "code_mask": 0x0F00, "code_shift": 8, "recommended_code": 1,
            "ramp_actions": [2]}
    assert load(tmp_path, {**MINIMAL, "comm_loss": full}).comm_loss == CommLoss(
        time_parameter="P", action_parameter="Q", code_register=0x62, code_mask=0x0F00, code_shift=8, codes=codes,
        recommended_code=1, ramp_actions=(2,))


REGISTER_KEYS = [("control", "register"), ("control", "stop_word"), ("control", "run_mask"), ("control", "run_bits"),
                 ("control", "stop_mask"), ("control", "stop_bits"), ("control", "reset_register"),
                 ("control", "reset_mask"), ("setpoint", "register"), ("status", "register"),
                 ("status", "running_mask"), ("status", "running_value"), ("status", "running_word"),
                 ("status", "stopped_word"), ("status", "tripped_mask"), ("status", "tripped_value"),
                 ("status", "decelerating_word"), ("status", "readback_register"), ("output", "register"),
                 ("fault", "register"), ("fault", "mask"), ("comm_loss", "time_register")]


@pytest.mark.parametrize(("table", "key"), REGISTER_KEYS)
def test_a_register_or_word_out_of_16_bits_is_named(tmp_path: Path, table: str, key: str) -> None:
    for bad, shown in ((70000, "70000"), (65536, "65536"), (-1, "-1"), (True, "True"), ("12", "'12'")):
        d = {**FULL, table: {**FULL[table], key: bad}}
        assert refused(tmp_path, d) == f"{table}.{key} must be a register address or word 0..65535 (got {shown})"
    assert load(tmp_path, {**FULL, table: {**FULL[table], key: 0xFFFF}}).name == "full"


@pytest.mark.parametrize(("d", "message"), [
    ({**FULL, "control": {**FULL["control"], "run_words": [0x11, 70000]}}, "control.run_words must be a register"),
    ({**FULL, "control": {**FULL["control"], "reset_words": [70000]}}, "control.reset_words must be a register"),
    ({**MINIMAL, "comm_loss": {**CODES, "code_register": 70000}}, "comm_loss.code_register must be a register"),
    ({**MINIMAL, "comm_loss": {**CODES, "code_mask": 70000}}, "comm_loss.code_mask must be a register"),
    ({**FULL, "identity": {"id a": 70000}}, "identity.id a must be a register"),
    ({**FULL, "emulator": {"identity": [70000, 1]}}, "emulator.identity must be a register"),
])
def test_registers_in_lists_and_tables_are_named_too(tmp_path: Path, d: dict[str, Any], message: str) -> None:
    assert refused(tmp_path, d).startswith(message + " address or word 0..65535 (got 70000)")


@pytest.mark.parametrize(("path", "name"), [
    ((), "max_hz"), ((), "hz_per_rpm"), (("setpoint",), "counts"), (("setpoint",), "hz"), (("output",), "counts"),
    (("output",), "hz"), (("comm_loss",), "time_counts_per_s"), (("emulator",), "accel_hz_per_s")])
def test_a_scale_or_rate_must_be_positive_and_is_named(tmp_path: Path, path: tuple[str, ...], name: str) -> None:
    def put(v: float) -> dict[str, Any]:
        return {**FULL, name: v} if not path else {**FULL, path[0]: {**FULL[path[0]], name: v}}

    key = ".".join((*path, name))
    assert refused(tmp_path, put(0)) == f"{key} must be a finite number > 0 (got 0)"
    small = load(tmp_path, put(0.5))  # any positive number, not only from 1 up
    assert small.name == "full"


def test_the_shape_rules_of_word_lists(tmp_path: Path) -> None:
    d = {**FULL, "control": {**FULL["control"], "run_words": []}}
    assert refused(tmp_path, d) == "control.run_words must not be empty"
    d = {**FULL, "emulator": {"identity": [0x70, 5, 0x71]}}
    assert refused(tmp_path, d) == "emulator.identity must be address, value pairs"


def test_loading_names_the_profile_and_what_is_wrong(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert profile_names() == list(SHIPPED) == ["delta-ms300", "abb-acs", "siemens-v20", "invertek-e3", "generic"]
    for missing in ("nope", str(tmp_path / "none.toml")):
        with pytest.raises(ControlError) as e:
            load_profile(missing)
        assert str(e.value) == (f"unknown drive profile {missing!r} (shipped: delta-ms300, abb-acs, siemens-v20,"
                                " invertek-e3, generic; or a path to a .toml file)")
    txt = tmp_path / "p.txt"
    txt.write_text(toml(MINIMAL))  # a readable profile, but not a .toml file
    with pytest.raises(ControlError, match=r"^unknown drive profile"):
        load_profile(str(txt))
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(ControlError, match=rf"^drive profile {re.escape(str(bad))}: \S"):  # tomllib's words
        load_profile(str(bad))

    def unreadable(self: Path, *a: object, **k: object) -> str:
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_text", unreadable)
    with pytest.raises(ControlError) as e:
        load_profile(str(bad))
    assert str(e.value) == f"cannot read drive profile {bad}: Permission denied"


def test_a_register_count_at_or_above_0x8000_reads_as_negative() -> None:
    s = Scale(100.0, 1.0)
    assert (s.to_hz(0x7FFF), s.to_hz(0x8000), s.to_hz(0xFFFF), s.to_hz(0)) == (327.67, -327.68, -0.01, 0.0)


def test_status_and_fault_words_decode_by_their_masks() -> None:
    delta, e3 = load_profile("delta-ms300"), load_profile("invertek-e3")
    assert delta.is_running(0x0003) and not delta.is_running(0x0002) and not delta.is_running(0x0001)
    assert delta.is_tripped(0x0003, 0x0136) and not delta.is_tripped(0x0003, 0x0100)  # no trip bits: the code
    assert delta.fault_code(0x0136) == 0x36  # masked to the low byte
    assert e3.is_tripped(0x0203, 0) and not e3.is_tripped(0x0103, 3)  # trip bits: the status word decides
    shifted = replace(delta, fault_mask=0x0FF0, fault_shift=4)
    assert shifted.fault_code(0x1365) == 0x36
    assert delta.fault_name(1) == "ocA" and delta.fault_name(99) == "code 99"
    assert delta.fault_text(1) == "ocA: over-current during acceleration"
    assert delta.fault_text(99) == "fault code 99 (not in the delta-ms300 profile)"


def test_a_fault_name_is_the_text_before_its_first_colon(tmp_path: Path) -> None:
    p = load(tmp_path, {**MINIMAL, "fault": {**MINIMAL["fault"], "codes": {"7": "OC: over-current: phase U"}}})
    assert p.fault_name(7) == "OC" and p.fault_text(7) == "OC: over-current: phase U"


def test_a_packed_comm_loss_code_decodes_through_its_mask_and_shift() -> None:
    e3 = load_profile("invertek-e3")
    assert e3.comm_loss_setting({164: 3 << 8}) == CommLossSetting(1.0, "t 1000 ms: trip", True)
    assert e3.comm_loss_setting({164: (3 << 8) | 0x00FF}) == CommLossSetting(1.0, "t 1000 ms: trip", True)
    assert e3.comm_loss_setting({164: 0}) == CommLossSetting(0.0, "disabled", False)
    assert e3.comm_loss_setting({164: 9 << 8}) == CommLossSetting(0.0, "unknown code 9", False)
    assert e3.comm_loss_ramps({164: 7 << 8}) and e3.comm_loss_ramps({164: (7 << 8) | 0xFF})
    assert not e3.comm_loss_ramps({164: 3 << 8})


def test_a_code_is_safe_only_when_it_trips_after_a_time(tmp_path: Path) -> None:
    codes = {**CODES, "codes": {"1": [0.0, "trip at once?", True], "2": [1.0, "warn", False], "3": [0.5, "trip", True]}}
    p = load(tmp_path, {**MINIMAL, "comm_loss": codes})
    assert p.comm_loss_setting({0x62: 1}) == CommLossSetting(0.0, "trip at once?", False)
    assert p.comm_loss_setting({0x62: 2}) == CommLossSetting(1.0, "warn", False)
    assert p.comm_loss_setting({0x62: 3}) == CommLossSetting(0.5, "trip", True)


def test_a_time_register_decodes_with_or_without_an_action() -> None:
    v20, delta = load_profile("siemens-v20"), load_profile("delta-ms300")
    assert v20.comm_loss_setting({0: 500}) == CommLossSetting(0.5, "fault (trip)", True)  # ms
    assert v20.comm_loss_setting({0: 0}) == CommLossSetting(0.0, "fault (trip)", False)
    assert not v20.comm_loss_ramps({0: 500})  # no action register: a trip coasts
    assert delta.comm_loss_setting({0x903: 20, 0x902: 1}) == CommLossSetting(2.0, "fault and ramp to stop", True)
    assert delta.comm_loss_setting({0x903: 20, 0x902: 7}) == CommLossSetting(2.0, "action 7", False)
    assert delta.comm_loss_setting({0x903: 0, 0x902: 1}) == CommLossSetting(0.0, "fault and ramp to stop", False)
    assert delta.comm_loss_ramps({0x903: 20, 0x902: 1}) and not delta.comm_loss_ramps({0x903: 20, 0x902: 2})


def test_the_advice_names_the_recommended_code_or_the_longest_safe_one_within_the_limit(tmp_path: Path) -> None:
    e3 = load_profile("invertek-e3")
    assert e3.comm_loss_advice(3.0) == "set P-36 (index 3) to t 3000 ms: trip (code 4)"  # the limit itself is ok
    assert e3.comm_loss_advice(2.0) == "set P-36 (index 3) to t 1000 ms: trip (code 3)"
    assert e3.comm_loss_advice(0.01) == "set P-36 (index 3) to a trip of at most 0.01 s"
    rec = load(tmp_path, {**MINIMAL, "comm_loss": {**CODES, "recommended_code": 1}})
    assert rec.comm_loss_advice(5.0) == "set P to trip (code 1)"  # recommended, though 2 s is longer
    odd = {**CODES, "codes": {"1": [0.0, "instant", True], "2": [9.0, "slow", True]}}
    assert load(tmp_path, {**MINIMAL, "comm_loss": odd}).comm_loss_advice(5.0) == "set P to a trip of at most 5 s"


def test_the_advice_names_the_action_only_with_an_action_register(tmp_path: Path) -> None:
    assert load_profile("delta-ms300").comm_loss_advice(5.0) == (
        "set Pr.09-03 to 2 s and Pr.09-02 to 1 (fault and ramp to stop)")
    unnamed = {**FULL["comm_loss"], "actions": {}, "recommended_action": 1}
    assert load(tmp_path, {**FULL, "comm_loss": unnamed}).comm_loss_advice(5.0) == "set T to 2 s and A to 1 (1)"
    no_register = {"time_parameter": "T", "time_register": 0x60, "recommended_action": 1}
    assert load(tmp_path, {**MINIMAL, "comm_loss": no_register}).comm_loss_advice(1.5) == "set T to 1.5 s"


def test_read_blocks_join_registers_closer_than_the_gap() -> None:
    assert read_blocks([0, 16]) == [(0, 17)]  # 15 registers between: one read
    assert read_blocks([0, 17]) == [(0, 1), (17, 1)]  # 16 between: two
    assert read_blocks([0, 10, 25]) == [(0, 26)]  # the gap counts from the block's end, not its start

"""The ``modbus:`` mill URL and the config's ``[drive]`` table, rule by rule (pure, no port):
each key's default, its accepted edges and the first value past them, and the one-line
errors naming what to fix (control/modbus/url.py's module doc is the rule book)."""

from __future__ import annotations

import re

import pytest

from control.errors import ControlError
from control.modbus.profile import SHIPPED
from control.modbus.url import COMM_LOSS_LIMIT_S, config_mill_url, drive_hz_per_rpm, parse_modbus_url

BASE = "modbus:/dev/x?profile=abb-acs"


def _error(url: str) -> str:
    with pytest.raises(ControlError) as e:
        parse_modbus_url(url)
    return str(e.value)


def test_a_url_with_only_port_and_profile_gets_every_documented_default() -> None:
    u = parse_modbus_url(BASE)
    assert (u.port, u.profile, u.unit, u.baud, u.parity, u.stopbits) == ("/dev/x", "abb-acs", 1, 19200, "E", 1)
    assert (u.hz_per_rpm, u.max_hz, u.comm_loss_limit_s, u.override) == (None, None, COMM_LOSS_LIMIT_S, False)
    assert COMM_LOSS_LIMIT_S == 5.0


def test_every_key_given_reaches_its_field() -> None:
    u = parse_modbus_url(BASE + "&unit=17&baud=9600&parity=N&stopbits=2&hz_per_rpm=0.5&max_hz=60"
                                "&comm_loss_limit=3&override=comm-loss")
    assert (u.unit, u.baud, u.parity, u.stopbits) == (17, 9600, "N", 2)
    assert (u.hz_per_rpm, u.max_hz, u.comm_loss_limit_s, u.override) == (0.5, 60.0, 3.0, True)


@pytest.mark.parametrize(("value", "parity"), [("N", "N"), ("E", "E"), ("O", "O"), ("o", "O"), ("n", "N")])
def test_parity_n_e_o_in_either_case(value: str, parity: str) -> None:
    assert parse_modbus_url(f"{BASE}&parity={value}").parity == parity


@pytest.mark.parametrize(("key", "lo", "hi"), [("unit", 1, 247), ("baud", 300, 4_000_000), ("stopbits", 1, 2)])
def test_integer_keys_take_both_ends_of_their_range_and_refuse_one_past(key: str, lo: int, hi: int) -> None:
    for v in (lo, hi):
        assert getattr(parse_modbus_url(f"{BASE}&{key}={v}"), key) == v
    for bad in (lo - 1, hi + 1, "x", "1.5", ""):  # an empty value is an error, not the default
        msg = _error(f"{BASE}&{key}={bad}")
        assert msg == f"modbus URL: {key} must be an integer in {lo}..{hi} (got {str(bad)!r})"


def test_comm_loss_limit_and_hz_per_rpm_take_any_positive_number_and_refuse_zero() -> None:
    assert parse_modbus_url(BASE + "&comm_loss_limit=0.5").comm_loss_limit_s == 0.5
    assert parse_modbus_url(BASE + "&hz_per_rpm=0.25").hz_per_rpm == 0.25
    for key in ("comm_loss_limit", "hz_per_rpm"):
        for bad in ("0", "-1", "nan"):
            assert _error(f"{BASE}&{key}={bad}") == f"modbus URL: {key} must be a finite number > 0 (got {bad})"


def test_a_value_holding_a_question_mark_stays_whole() -> None:
    """Everything after the first ``?`` belongs to the Modbus layer: a profile path may hold one."""
    assert parse_modbus_url("modbus:/dev/x?profile=/tmp/drive?.toml").profile == "/tmp/drive?.toml"


def test_the_errors_name_the_url_the_keys_and_the_profiles() -> None:
    assert _error("/dev/ttyUSB0") == "not a modbus: URL: '/dev/ttyUSB0'"
    msg = _error(BASE + "&speed=3")
    known = re.fullmatch(r"unknown key 'speed' in modbus URL \(known: (.*)\)", msg)
    assert known is not None, msg
    keys = known.group(1).split(", ")
    assert keys == ["profile", "unit", "baud", "parity", "stopbits", "hz_per_rpm", "max_hz", "comm_loss_limit",
                    "override"]
    assert _error("modbus:/dev/x?unit=1") == f"modbus URL needs profile=NAME ({', '.join(SHIPPED)})"
    assert _error(BASE + "&parity=x") == "modbus URL: parity must be N, E or O (got 'x')"


def test_the_drive_tables_hz_per_rpm_is_checked_up_to_1e4() -> None:
    assert drive_hz_per_rpm({"hz_per_rpm": 10_000}, "c") == 10_000.0
    assert drive_hz_per_rpm({"hz_per_rpm": 3}, "c") == 3.0
    assert drive_hz_per_rpm(None, "c") is None and drive_hz_per_rpm({}, "c") is None
    with pytest.raises(ControlError, match=r"^c: \[drive\] hz_per_rpm must be a finite number > 0 and <= 10000 "
                                           r"\(got 10000\.5\)$"):
        drive_hz_per_rpm({"hz_per_rpm": 10_000.5}, "c")


def test_the_config_url_names_the_config_in_its_errors() -> None:
    with pytest.raises(ControlError, match=r"^config c\.toml: \[drive\] hz_per_rpm must be a number \(got 'x'\)$"):
        config_mill_url(BASE, {"hz_per_rpm": "x"}, "config c.toml")


def test_the_url_and_the_table_agree_within_one_part_per_million_of_the_larger() -> None:
    url = BASE + "&hz_per_rpm=100"
    assert config_mill_url(url, {"hz_per_rpm": 100.00005}, "c") == url  # 0.5 ppm apart: the same value
    # exactly 1e-6 x the larger apart (both binary-exact, so is their difference): still agreeing
    exact = BASE + "&hz_per_rpm=976.5625"
    assert config_mill_url(exact, {"hz_per_rpm": 976.5615234375}, "c") == exact
    with pytest.raises(ControlError) as e:
        config_mill_url(BASE + "&hz_per_rpm=100", {"hz_per_rpm": 100.001}, "config c.toml")
    assert str(e.value) == ("hz_per_rpm: the mill URL says 100, config c.toml [drive] says 100.001: give it in one"
                            " place (or make them agree)")

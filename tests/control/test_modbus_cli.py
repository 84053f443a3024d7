"""The commissioning commands on ``modbus:`` URLs, ``mill-emulator --modbus`` as its own
process, and ``bench link`` reporting the Modbus round trip beside the line protocol's."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from control.modbus.emulator import DriveEmulator
from control.modbus.link import ModbusMill
from control.modbus.profile import load_profile
from tests.cli import assert_one_line_error, cli

DRUMTWIN = Path(sys.executable).parent / "drumtwin"


@pytest.fixture
def delta() -> Iterator[DriveEmulator]:
    with DriveEmulator(load_profile("delta-ms300"), unit=3) as emu:
        emu.open_pty()
        yield emu


def test_check_prints_identity_and_safety_parameters(delta: DriveEmulator) -> None:
    r = cli("mill", delta.mill_url(), "check")
    assert r.code == 0, r.err
    assert "identity code (Pr.00-00): 6" in r.out and "firmware version (Pr.00-06): 114" in r.out
    assert "Pr.09-03: 2 s" in r.out and "fault and ramp to stop" in r.out and "ok the drive trips" in r.out
    assert delta.writes == []  # check only reads


def test_check_says_what_to_change_and_exits_2(delta: DriveEmulator) -> None:
    delta.commission(0.0)
    r = cli("mill", delta.mill_url(), "check", "--json")
    assert r.code == 2
    d = json.loads(r.out)
    assert d["safe"] is False and d["comm_loss_s"] == 0 and "set Pr.09-03 to 2 s and Pr.09-02 to 1" in d["change"]


def test_on_a_drive_with_its_trip_disabled_start_and_set_rpm_are_refused_and_status_is_read(
    delta: DriveEmulator,
) -> None:
    delta.commission(0.0)
    for cmd in (("start",), ("set-rpm", "5")):
        assert_one_line_error(cli("mill", delta.mill_url(), *cmd), "refused", "Pr.09-03", "override=comm-loss")
    assert delta.writes == []  # refused before anything was written
    r = cli("mill", delta.mill_url(), "status", "--json")  # reads are never gated (stop: test_stop_never_gated.py)
    assert r.code == 0 and json.loads(r.out)["running"] is False, r.err


def test_mill_commands_on_a_modbus_url(delta: DriveEmulator) -> None:
    url = delta.mill_url()
    r = cli("mill", url, "set-rpm", "12.5", "--json")
    assert r.code == 0, r.err
    assert json.loads(r.out)["setpoint_rpm"] == 12.5
    assert delta.registers(0x2001) == [1250]
    r = cli("mill", url, "start", "--hold", "0.5", "--json")
    assert r.code == 0, r.err
    assert json.loads(r.out)["running"] is True
    r = cli("mill", url, "stop", "--json")
    assert r.code == 0 and json.loads(r.out)["running"] is False
    assert_one_line_error(cli("mill", url, "set-rpm", "70"), "outside the limits 5-45 rpm")  # the run's limits
    r = cli("mill", url, "set-rpm", "70", "--commission")  # past them (warned): the drive's own 60 Hz refuses
    err = [ln for ln in r.err.splitlines() if ln.strip()]
    assert r.code == 2 and len(err) == 2 and "commissioning override" in err[0] and "RANGE" in err[1], r.err
    assert_one_line_error(cli("mill", "modbus:/dev/x?profile=nope", "status"), "unknown drive profile")


def test_mill_config_gives_hz_per_rpm_and_a_url_that_disagrees_is_refused(delta: DriveEmulator, tmp_path: Path) -> None:
    cfg = tmp_path / "mixer.toml"
    cfg.write_text("[drive]\nhz_per_rpm = 2.5  # measured at commissioning\n")
    bare = f"modbus:{delta.url}?profile=delta-ms300&unit=3&parity=N"  # no hz_per_rpm in the URL
    r = cli("mill", "--config", cfg, bare, "set-rpm", "10", "--json")
    assert r.code == 0, r.err
    assert delta.registers(0x2001) == [2500]  # 10 drum rpm x 2.5 Hz/rpm x 100 counts/Hz
    assert json.loads(r.out)["setpoint_rpm"] == 10.0
    n = len(delta.writes)
    assert_one_line_error(cli("mill", "--config", cfg, bare + "&hz_per_rpm=1", "set-rpm", "10"),
                          "the mill URL says 1", "[drive] says 2.5")
    assert len(delta.writes) == n  # refused before the port is opened
    cfg.write_text("[drive]\nhz_per_rpm = -2\n")
    assert_one_line_error(cli("mill", "--config", cfg, bare, "status"), "hz_per_rpm must be a finite number > 0")


@pytest.mark.timeout(60)
def test_mill_emulator_modbus_process_on_tcp() -> None:
    proc = subprocess.Popen(
        [str(DRUMTWIN), "mill-emulator", "--modbus", "invertek-e3", "--tcp", "0", "--unit", "5", "--duration", "30"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        assert url.startswith("modbus:socket://127.0.0.1:") and "profile=invertek-e3" in url and "unit=5" in url
        with ModbusMill(url) as mill:
            mill.set_rpm(20.0)
            mill.start()
            st = mill.heartbeat()
            assert st.setpoint_rpm == 20.0 and st.running
    finally:
        proc.terminate()
        proc.wait(10)
    assert proc.returncode == 0


def test_mill_emulator_modbus_bad_options_are_one_line_errors() -> None:
    assert_one_line_error(cli("mill-emulator", "--modbus", "nope"), "unknown drive profile")
    assert_one_line_error(cli("mill-emulator", "--modbus", "generic", "--unit", "0"), "--unit")
    assert_one_line_error(cli("mill-emulator", "--modbus", "generic", "--faults", "boom=1"), "unknown drive fault")


@pytest.mark.timeout(120)
def test_bench_link_reports_the_modbus_round_trip_beside_the_line_protocol() -> None:
    r = cli("bench", "link", "--json", "--requests", "20")
    assert r.code == 0, r.err
    d = json.loads(r.out)
    for tr in ("pty", "tcp", "modbus_pty", "modbus_tcp"):
        assert 0 < d[f"{tr}_median_ms"] <= d[f"{tr}_p99_ms"], tr
        assert d[f"{tr}_resends"] == 0  # a clean line needs no resend

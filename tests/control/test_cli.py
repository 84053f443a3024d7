"""The control commands through the real CLI entry point."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from control.device import DeviceConfig
from control.driver import MillClient
from control.emulator import MillEmulator
from tests.cli import assert_one_line_error
from tests.cli import cli as run_cli
from tests.conftest import BENCH_TREND_ARGS, BENCHES

DRUMTWIN = Path(sys.executable).with_name("drumtwin")


def cli(capsys, *args: str) -> tuple[int, str, str]:
    r = run_cli(*args)
    return r.code, r.out, r.err


@BENCHES
@pytest.mark.timeout(300)  # a hang guard, not a speed check: it learns classes on 27 real frames
def test_bench_trend_json(cli_once):  # (the 27 frames' classes: tests/learned.py)
    """``bench trend --json --sequences 2 --real-seeds 1``: the session's run (tests/conftest.py,
    shared with the bad-input sweep's base of ``bench trend``)."""
    r = cli_once("bench", "trend", *BENCH_TREND_ARGS)
    code, out = r.code, r.out
    assert code == 0, r.err[-2000:]
    d = json.loads(out)
    assert set(d) == {"synthetic", "real"}  # both benches, each both filters
    for bench in d.values():
        assert {"kalman_rmse", "ma_rmse", "kalman_lag_s", "ma_lag_s", "kalman_lockout_s",
                "kalman_coverage"} <= set(bench)
        assert bench["kalman_rmse"] < bench["ma_rmse"] and bench["kalman_lag_s"] < bench["ma_lag_s"]
    assert 0.0 <= d["real"]["kalman_min"] <= d["real"]["kalman_max"] <= 1.0


@pytest.mark.timeout(60)
def test_bench_link_times_both_transports(capsys):
    code, out, _ = cli(capsys, "bench", "link", "--json", "--requests", "30")
    assert code == 0
    d = json.loads(out)
    for tr in ("pty", "tcp"):
        assert 0 < d[f"{tr}_median_ms"] <= d[f"{tr}_p99_ms"] < 500
        assert d[f"{tr}_resends"] == 0  # a clean line needs no resend


@pytest.mark.timeout(300)
def test_bench_trend_table(capsys):
    code, out, _ = cli(capsys, "bench", "trend", "--sequences", "1", "--real-seeds", "0")
    # (the row labels are cut when rich's console was made at 80 columns: check the title)
    assert code == 0 and "Kalman vs 150-sample moving average" in out and "(real)" not in out
    code, _, err = cli(capsys, "bench", "trend", "--sequences", "1", "--frames", "/nonexistent/frames")
    assert code == 2 and "--frames" in err and "Traceback" not in err


@pytest.mark.timeout(30)
def test_mill_commands_against_emulator(capsys):
    with MillEmulator(DeviceConfig(watchdog_s=0.0)) as emu:
        emu.open_tcp(0)
        code, out, _ = cli(capsys, "mill", emu.url, "status", "--json")
        assert code == 0
        assert json.loads(out) == {"setpoint_rpm": 0.0, "actual_rpm": 0.0, "running": False, "fault": None}
        code, out, _ = cli(capsys, "mill", emu.url, "set-rpm", "14.5", "--json")
        assert code == 0 and json.loads(out)["setpoint_rpm"] == 14.5 and emu.motor.setpoint_rpm == 14.5
        code, out, _ = cli(capsys, "mill", emu.url, "start")
        assert code == 0 and "running" in out and emu.motor.running
        code, out, _ = cli(capsys, "mill", emu.url, "stop", "--json")
        assert code == 0 and json.loads(out)["running"] is False
        code, out, err = cli(capsys, "mill", emu.url, "set-rpm", "500", "--commission")  # past our limits
        assert code == 2 and "RANGE" in err and emu.motor.setpoint_rpm == 14.5  # and the board's


def test_bad_url_and_bad_faults_are_one_line_errors():
    r = run_cli("mill", "/nonexistent/ttyUSB7", "status")
    assert_one_line_error(r, "cannot open mill link")
    assert r.out == ""
    assert_one_line_error(run_cli("mill-emulator", "--faults", "bogus=1", "--duration", "0.1"), "unknown fault")
    assert_one_line_error(run_cli("mill-emulator", "--pty", "--tcp", "0", "--duration", "0.1"), "one of")


NAN, INF = "nan", "inf"
BAD_NUMBERS = [
    (("mill-emulator", "--tcp", "99999"), "--tcp"),
    (("mill-emulator", "--tcp", "-1"), "--tcp"),
    (("mill-emulator", "--watchdog", NAN), "--watchdog"),  # used to disable the watchdog silently
    (("mill-emulator", "--watchdog", "-1"), "--watchdog"),
    (("mill-emulator", "--max-rpm", INF), "--max-rpm"),  # used to accept 5000 rpm
    (("mill-emulator", "--max-rpm", "0"), "--max-rpm"),
    (("mill-emulator", "--accel", NAN), "--accel"),
    (("mill-emulator", "--tau", "-0.5"), "--tau"),
    (("mill-emulator", "--duration", NAN), "--duration"),
    (("mill-emulator", "--duration", "0"), "--duration"),
    (("mill-emulator", "--faults", "delay=nan"), "delay"),
    (("mill", "--timeout", NAN, "socket://127.0.0.1:9", "status"), "--timeout"),  # used to hang
    (("mill", "--timeout", "0", "socket://127.0.0.1:9", "status"), "--timeout"),
    (("mill", "--timeout", INF, "socket://127.0.0.1:9", "status"), "--timeout"),
    (("mill", "--retries", "-1", "socket://127.0.0.1:9", "status"), "--retries"),
    (("mill", "socket://127.0.0.1:9", "set-rpm", NAN), "rpm"),
    (("mill", "socket://127.0.0.1:9", "set-rpm", "--", "-3"), "rpm"),
    (("mill", "socket://127.0.0.1:9", "set-rpm", "5", "--hold", INF), "--hold"),
    (("mill", "socket://127.0.0.1:9", "start", "--hold", NAN), "--hold"),
    (("mill", "socket://127.0.0.1:9", "start", "--hold", "-1"), "--hold"),
    (("bench", "link", "--requests", "0"), "--requests"),
    (("bench", "link", "--requests", "-5"), "--requests"),
    (("bench", "trend", "--fps", NAN), "--fps"),
    (("bench", "trend", "--noise", INF), "--noise"),
    (("bench", "trend", "--ripple", "-1"), "--ripple"),
]


@pytest.mark.timeout(20)
@pytest.mark.parametrize(("args", "needle"), BAD_NUMBERS, ids=[" ".join(a) for a, _ in BAD_NUMBERS])
def test_bad_numbers_are_one_line_errors(args, needle):
    """Refused before any port is opened or any thread started: exit 2, one line, no hang."""
    assert_one_line_error(run_cli(*args), needle)


@pytest.mark.timeout(20)
def test_two_status_calls_see_the_fresh_state():
    """Every CLI call is a new host: its status is never a reply cached for the last one."""
    with MillEmulator(DeviceConfig(watchdog_s=0.0)) as emu:
        emu.open_tcp(0)
        r1 = run_cli("mill", emu.url, "status", "--json")
        assert r1.code == 0 and json.loads(r1.out)["setpoint_rpm"] == 0.0
        emu.set_motor(setpoint_rpm=9.0, actual_rpm=9.0, running=True)  # front panel
        r2 = run_cli("mill", emu.url, "status", "--json")
        assert r2.code == 0 and json.loads(r2.out) == {
            "setpoint_rpm": 9.0, "actual_rpm": 9.0, "running": True, "fault": None
        }


@pytest.mark.timeout(60)
def test_mill_emulator_process_on_a_pty():
    proc = subprocess.Popen(
        [str(DRUMTWIN), "mill-emulator", "--pty", "--duration", "30", "--watchdog", "0.5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = proc.stdout.readline().strip()
        assert url.endswith("/mill")
        with MillClient(url, timeout_s=0.2, heartbeat_s=0.1) as c:
            c.set_rpm(8.0)
            c.start()
            st = c.status()
            assert st.setpoint_rpm == 8.0 and st.running
    finally:
        proc.terminate()
        proc.wait(10)
    assert proc.returncode == 0
    assert not Path(url).exists()  # the pty link is cleaned up


def test_bench_trend_pluggable_source(capsys, monkeypatch):
    import numpy as np

    from control.trendbench import TrendSequence
    from twin.cli import control_cmds

    calls = []

    def step_source(seed: int) -> TrendSequence:
        calls.append(seed)
        t = np.arange(0, 40, 1 / 30)
        truth = np.where(t >= 20, 0.8, 0.3)
        rng = np.random.default_rng(seed)
        return TrendSequence(t, truth, truth + rng.normal(0, 0.03, t.size), np.full(t.size, 10.0), 20.0)

    monkeypatch.setitem(control_cmds.TREND_SOURCES, "step", step_source)
    code, out, _ = cli(capsys, "bench", "trend", "--source", "step", "--sequences", "3", "--json", "--real-seeds", "0")
    assert code == 0 and calls == [0, 1, 2]
    d = json.loads(out)["step"]
    assert d["kalman_lag_s"] < d["ma_lag_s"]
    code, _, err = cli(capsys, "bench", "trend", "--source", "nope")
    assert code == 2 and "unknown trend source" in err

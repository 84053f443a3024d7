"""The live loop end to end against the embedded demo (hidden plant + mill emulator on a
pty + the real serial driver): AUTO acts through the serial link and beats OFF; faults
go to a safe state and recover; the CSV survives kill -9 of ``drumtwin run``."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from twin.cli.run_cmd import run_live
from twin.config import RunConfig
from twin.loop import supervisor_config
from twin.runlog import read_events, read_frames, read_metadata

DRUMTWIN = [str(Path(sys.executable).parent / "drumtwin")]
SPEED = 4.0
DURATION_S = 220.0


def _drumtwin(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [*DRUMTWIN, "run", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def _col(rows: list[dict], name: str) -> np.ndarray:
    return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)


@pytest.fixture(scope="module")
def auto_and_off(tmp_path_factory) -> dict[str, tuple[dict, Path]]:
    """The same Case C demo start (seed 0, 5 rpm) run in AUTO and in OFF, side by side."""
    base = tmp_path_factory.mktemp("auto_vs_off")
    procs = {}
    for mode in ("auto", "off"):
        procs[mode] = _drumtwin(
            "--no-dashboard", "--duration", str(DURATION_S), "--speed", str(SPEED), "--case", "C",
            "--seed", "0", "--mode", mode, "--json", "--log", str(base / mode),
        )
    out = {}
    for mode, p in procs.items():
        stdout, stderr = p.communicate(timeout=400)
        assert p.returncode == 0, stderr[-2000:]
        out[mode] = (json.loads(stdout), base / mode)
    return out


@pytest.mark.slow
@pytest.mark.timeout(500)
def test_auto_detects_segregation_and_moves_the_mill_over_serial(auto_and_off) -> None:
    summary, run_dir = auto_and_off["auto"]
    assert set(summary) >= {"final_trend_mi", "final_rpm", "decisions", "faults", "log_dir"}
    rows, events = read_frames(run_dir), read_events(run_dir)
    meta = read_metadata(run_dir)
    assert meta["config"]["mode"] == "auto" and meta["calibration"]["friction"] > 0
    moves = [e for e in events if e["kind"] == "decision" and e["action"] == "set_rpm"]
    assert moves, f"no rpm decision in {[e['kind'] for e in events]}"
    first = moves[0]
    assert "segregation" in first["reason"] and first["rpm"] > 5.0
    t_dec = first["t_s"]
    t, trend, rpm_act, rpm_set = (_col(rows, c) for c in ("t_s", "trend_mi", "rpm_actual", "rpm_setpoint"))
    # segregation developed before the decision: the trend started mixed and fell
    seg_level = supervisor_config(RunConfig()).seg_level
    assert np.nanmean(trend[t < 5]) > seg_level
    assert np.nanmin(trend[(t > 5) & (t <= t_dec)]) < seg_level
    # the emulator's motor (read back over the pty) follows the decision
    assert np.nanmax(rpm_act[t < t_dec - 1]) < 5.5
    target = max(e["target_rpm"] or e["rpm"] for e in moves)
    assert np.nanmax(rpm_act) > 0.9 * target
    assert np.nanmax(rpm_set) == pytest.approx(target, abs=0.05)
    assert summary["final_rpm"] > 10.0 and summary["decisions"] >= 1


@pytest.mark.slow
@pytest.mark.timeout(500)
def test_auto_ends_clearly_more_mixed_than_off(auto_and_off) -> None:
    (auto, auto_dir), (off, off_dir) = auto_and_off["auto"], auto_and_off["off"]
    assert off["decisions"] == 0 and off["final_rpm"] == pytest.approx(5.0, abs=0.1)
    # compare once the lever has acted: from 30 s after AUTO's first move to the end
    t_move = min(e["t_s"] for e in read_events(auto_dir) if e["kind"] == "decision" and e["decision"] == "move")
    tail = {}
    for name, d in (("auto", auto_dir), ("off", off_dir)):
        rows = read_frames(d)
        t, trend = _col(rows, "t_s"), _col(rows, "trend_mi")
        tail[name] = float(np.nanmean(trend[t > t_move + 30]))
    assert tail["auto"] > tail["off"] + 0.04, tail
    assert auto["final_trend_mi"] > off["final_trend_mi"] + 0.04


@pytest.mark.slow
def test_compare_command_plots_both_runs(auto_and_off, tmp_path: Path) -> None:
    """``drumtwin compare`` makes the README's AUTO-vs-OFF figure from the two run logs."""
    (_, auto_dir), (_, off_dir) = auto_and_off["auto"], auto_and_off["off"]
    png = tmp_path / "auto-vs-off.png"
    p = subprocess.run([*DRUMTWIN, "compare", f"AUTO={auto_dir}", f"OFF={off_dir}", "--plot", str(png)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "AUTO" in p.stdout and "OFF" in p.stdout
    assert png.stat().st_size > 20_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = subprocess.run([*DRUMTWIN, "compare", str(tmp_path), "--plot", str(png)], capture_output=True, text=True)
    assert bad.returncode == 2 and "not a run log dir" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_faults_safe_state_alarm_and_recovery(tmp_path: Path) -> None:
    """Unplug the mill: fault, safe state, recovery on replug. Stop the camera: alarm, no
    controller moves, recovery. Every fault is an event."""
    cfg = RunConfig(dashboard=False, duration_s=400, speed=SPEED, mode="auto", log_dir=tmp_path / "run").resolved()
    report: dict = {}

    def script(loop, plant, dash) -> None:  # noqa: ANN001
        def wait(pred, timeout_s: float, what: str) -> None:
            end = time.monotonic() + timeout_s
            while time.monotonic() < end:
                if pred():
                    return
                time.sleep(0.05)
            raise AssertionError(f"timed out waiting for {what}")

        def run() -> None:
            try:
                wait(lambda: loop.mill_view.connected and loop.n_frames > 20, 30, "a running loop")
                plant.emulator.disconnect()
                wait(lambda: not loop.mill_view.connected, 10, "the loop to see the link down")
                wait(lambda: loop.supervisor.safe, 10, "the supervisor's safe state")
                report["alarm_link"] = list(loop.state.alarms)
                time.sleep(plant.config.watchdog_s + 0.7)  # the board's watchdog stops the drive
                report["motor_after_unplug"] = plant.emulator.motor
                plant.emulator.reconnect()
                wait(lambda: loop.mill_view.connected, 20, "the link to come back")
                wait(lambda: plant.emulator.motor.running, 10, "the drive to restart")
                wait(lambda: not loop.supervisor.safe, 30, "recovery from the safe state")
                decisions_before = loop.n_decisions
                t_pause = loop.now_s()
                plant.camera_paused.set()
                wait(lambda: any("camera" in a for a in loop.state.alarms), 20, "a camera alarm")
                report["alarm_camera"] = list(loop.state.alarms)
                wait(lambda: loop.supervisor.safe, 20, "the safe state without vision")
                time.sleep(2.0)
                report["setpoint_during_pause"] = plant.emulator.motor.setpoint_rpm
                report["pause"] = (t_pause, loop.now_s(), decisions_before)
                plant.camera_paused.clear()
                wait(lambda: not any("camera" in a for a in loop.state.alarms), 20, "the camera alarm to clear")
                wait(lambda: not loop.supervisor.safe, 30, "recovery once frames are back")
            except BaseException as exc:  # noqa: BLE001
                report["error"] = exc
            finally:
                loop.stop_event.set()

        threading.Thread(target=run, daemon=True).start()

    run_live(cfg, progress=False, on_started=script)
    if "error" in report:
        raise report["error"]
    events = read_events(tmp_path / "run")
    faults = {e["fault"] for e in events if e["kind"] == "fault"}
    recovered = {e["fault"] for e in events if e["kind"] == "recovered"}
    assert {"mill_link", "camera_stopped"} <= faults and {"mill_link", "camera_stopped"} <= recovered
    assert any("mill link" in a for a in report["alarm_link"])
    assert any("camera" in a for a in report["alarm_camera"])
    safe = [e for e in events if e["kind"] == "decision" and e["safe"]]
    assert any("mill link lost" in e["reason"] for e in safe)
    assert any("no valid MI" in e["reason"] for e in safe)
    assert sum(e["kind"] == "decision" and e["decision"] == "recover" for e in events) >= 2
    assert report["motor_after_unplug"].fault == "WDOG"  # the board stopped itself
    assert any(e["kind"] == "mill_restart" for e in events)
    # no controller move while the camera was stopped
    t0, t1, _ = report["pause"]
    moves = [e for e in events if e["kind"] == "decision" and e["action"] == "set_rpm" and t0 <= e["t_s"] <= t1]
    assert moves == []
    assert report["setpoint_during_pause"] == pytest.approx(5.0)


@pytest.mark.timeout(120)
def test_run_csv_survives_kill_9(tmp_path: Path) -> None:
    proc = _drumtwin("--no-dashboard", "--speed", "2", "--mode", "off", "--log", str(tmp_path / "run"))
    try:
        csv = tmp_path / "run" / "frames.csv"
        end = time.monotonic() + 60
        while time.monotonic() < end and not (csv.exists() and len(read_frames(csv)) > 40):
            time.sleep(0.2)
        time.sleep(1.0)
        kill_wall = time.time()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    rows = read_frames(tmp_path / "run")
    assert len(rows) > 40
    frames = [int(r["frame"]) for r in rows]
    assert frames == sorted(frames) and all(math.isfinite(r["t_s"]) for r in rows)
    assert kill_wall - rows[-1]["wall_s"] < 1.0


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.browser
@pytest.mark.timeout(300)
def test_browser_sees_live_dashboard_and_drives_the_mill(page, tmp_path: Path) -> None:
    """Chromium opens the live demo's dashboard: camera image and plots update; MANUAL and
    the rpm slider move the emulator's setpoint through the real serial driver."""
    from tests.twin.dashboard_helpers import (
        IMG, choose_mode, drag_slider_to, image_srcs, plot_pixels, slider_enabled, slider_value, wait_until,
    )

    cfg = RunConfig(
        dashboard=True, duration_s=10_000, speed=2.0, mode="auto", port=_free_port(), log_dir=tmp_path / "run"
    ).resolved()
    started: dict = {}
    done = threading.Event()

    def on_started(loop, plant, dash) -> None:  # noqa: ANN001
        started.update(loop=loop, plant=plant, dash=dash)

    def runner() -> None:
        try:
            run_live(cfg, progress=False, on_started=on_started)
        finally:
            done.set()

    th = threading.Thread(target=runner, daemon=True)
    th.start()
    try:
        wait_until(lambda: "dash" in started or done.is_set(), 60, "the demo to start")
        assert not done.is_set(), "the run ended early"
        loop, plant, dash = started["loop"], started["plant"], started["dash"]
        page.goto(dash.url)
        page.wait_for_selector(IMG)
        wait_until(lambda: len(image_srcs(page)) >= 2, 30, "camera and twin images")
        imgs, plots = image_srcs(page), plot_pixels(page)
        wait_until(lambda: image_srcs(page)[0] != imgs[0], 15, "a new camera frame in the browser")
        wait_until(lambda: plot_pixels(page)["Mixing index"] != plots["Mixing index"], 15, "the MI plot to update")
        wait_until(lambda: plot_pixels(page)["Mill rpm"] != plots["Mill rpm"], 15, "the rpm plot to update")
        choose_mode(page, "MANUAL")
        wait_until(lambda: loop.mode_name == "manual", 10, "MANUAL mode in the loop")
        wait_until(lambda: slider_enabled(page), 10, "the rpm slider to enable")
        drag_slider_to(page, 0.35)
        wait_until(lambda: abs(slider_value(page) - 5.0) > 5, 10, "the slider to move")
        wanted = slider_value(page)
        wait_until(
            lambda: abs(plant.emulator.motor.setpoint_rpm - loop.supervisor.config.clamp(wanted)) < 0.05,
            30,
            f"the emulator's setpoint to reach {wanted} rpm",
        )
        wait_until(lambda: plant.emulator.motor.actual_rpm > 10, 30, "the drive to speed up")
        page.screenshot(path=str(tmp_path / "dashboard.png"))
        assert (tmp_path / "dashboard.png").stat().st_size > 10_000
    finally:
        if "loop" in started:
            started["loop"].stop_event.set()
        done.wait(30)
    events = read_events(tmp_path / "run")
    assert any(e["kind"] == "operator" and e.get("action") == "manual_rpm" for e in events)
    assert any(e["kind"] == "decision" and e["decision"] == "manual" for e in events)


@pytest.mark.browser
@pytest.mark.timeout(240)
def test_bench_dashboard_counts_image_updates_in_chromium() -> None:
    """`drumtwin bench dashboard` runs the demo, opens it in chromium and reports rates."""
    p = subprocess.run(
        [*DRUMTWIN, "bench", "dashboard", "--seconds", "4", "--warmup", "10", "--speed", "2",
         "--port", str(_free_port()), "--json"],
        capture_output=True, text=True, timeout=220,
    )
    assert p.returncode == 0, p.stderr[-2000:]
    rate = json.loads(p.stdout)
    assert rate["seconds"] == 4.0
    assert rate["camera_hz"] > 1.0 and rate["twin_hz"] > 1.0  # both images moved while counting
    bad = subprocess.run([*DRUMTWIN, "bench", "dashboard", "--seconds", "0"], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "--seconds" in bad.stderr

"""The whole loop against the drive emulator over a real pty, pymodbus on both ends: AUTO
moves the drive, OFF sends no write, a drive left running by another host is not kept
running, ``kill -9`` of the run stops the drive through its own comm-loss trip, a garbled
or unanswered reply is a logged fault and the safe state, and a drive whose trip is
disabled is refused (exit 2) and runs only with the logged override."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from control.modbus.emulator import DriveEmulator, DriveFaults
from control.modbus.profile import load_profile
from tests.cli import assert_one_line_error, cli
from tests.twin.live_helpers import QUICK_AUTO, SPEED, free_port, synthetic_video
from tests.twin.live_script import run_scripted
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.run.main import run_live
from twin.run.settings import Seams
from twin.runlog import read_events

# the whole-loop tests share one worker, group "live" (see tests/twin/live_helpers.py: two loops at once on two cores
# made their timing flaky in CI); the option check and the worker-on-a-pty test run anywhere
LIVE = pytest.mark.xdist_group("live")

DELTA = load_profile("delta-ms300")


@pytest.fixture
def delta() -> Iterator[DriveEmulator]:
    """A Delta MS300 emulator on a pty, commissioned with a 1 s comm-loss trip."""
    with DriveEmulator(DELTA, unit=1, comm_loss_s=1.0) as emu:
        emu.open_pty()
        yield emu


@LIVE
@pytest.mark.timeout(300)
def test_auto_moves_the_drive_and_a_garbled_or_silent_reply_is_a_fault_and_the_safe_state(tmp_path: Path) -> None:
    """The embedded demo on a Delta drive emulator (`drumtwin run --drive delta-ms300`)."""
    cfg = RunConfig(dashboard=False, duration_s=600, speed=SPEED, mode="auto", case="C", seed=0,
                    log_dir=tmp_path / "run", drive="delta-ms300").resolved()
    report: dict = {}

    def body(loop, plant) -> None:
        mill = loop.mill_box.get
        emu = plant.emulator
        assert isinstance(emu, DriveEmulator)
        wait_until(lambda: mill().connected and mill().setpoint_rpm >= 15.0, 150, "AUTO to set 15 rpm")
        report["setpoint_counts"] = emu.registers(DELTA.setpoint_register)[0]
        wait_until(lambda: emu.output_hz > 10.0, 20, "the drive ramping towards 15 Hz")
        for fault in (DriveFaults(corrupt_p=1.0), DriveFaults(mute=True)):
            emu.faults = fault
            wait_until(lambda: not mill().connected, 10, "the loop to see the link down")
            wait_until(lambda: loop.supervisor.safe, 10, "the supervisor's safe state")
            report.setdefault("alarms", []).append(list(loop.state.alarms))
            emu.faults = DriveFaults()
            wait_until(lambda: mill().connected, 10, "the link back")

    run_scripted(cfg, body, seams=QUICK_AUTO)
    assert report["setpoint_counts"] == 1500  # 15 rpm x 1 Hz/rpm x 100 counts/Hz: the manual's Hz x 100
    events = read_events(tmp_path / "run")
    sent = [e for e in events if e["kind"] == "mill_command" and e["command"] == "set_rpm"]
    assert sent and sent[-1]["rpm"] == 15.0
    lost = [e for e in events if e["kind"] == "fault" and e["fault"] == "mill_link"]
    # (at least) the two injected losses; a loaded machine may add a late reply of its own
    assert len(lost) >= 2 and all("no valid answer" in e["message"] for e in lost)
    assert sum(e["kind"] == "recovered" and e["fault"] == "mill_link" for e in events) >= 2
    assert any(e["kind"] == "decision" and e["safe"] and "mill link lost" in e["reason"] for e in events)
    assert all(any("mill link" in a for a in alarms) for alarms in report["alarms"])


@LIVE
@pytest.mark.timeout(240)
def test_off_sends_no_write_and_a_drive_left_running_is_not_kept_running(delta: DriveEmulator, tmp_path: Path) -> None:
    """Another host starts the drive once the run is up and goes away: the run (OFF) only
    reads, so the drive's own trip stops it while the run keeps polling."""
    video = synthetic_video(tmp_path / "v.avi", n=60)
    cfg = RunConfig(video=video, mill=delta.mill_url(), dashboard=False, duration_s=5.0, mode="off",
                    log_dir=tmp_path / "run").resolved()
    seen: dict = {}

    def another_host(loop, plant, dash) -> None:
        wait_until(lambda: loop.mill_box.get().connected, 10, "the loop to read the drive")
        delta.set_motor(setpoint_rpm=10.0, actual_rpm=10.0, running=True)
        seen["t_s"], seen["reads"] = loop.now_s(), delta.counters["reads"]

    run_live(cfg, Seams(on_started=another_host))
    assert delta.writes == []  # OFF: not one write on the bus
    m = delta.motor
    assert not m.running and m.fault == "CE1" and delta.counters["comm_loss_trips"] == 1
    events = read_events(tmp_path / "run")
    trip = [e for e in events if e["kind"] == "fault" and e["fault"] == "mill_fault" and e["mill_fault"] == "CE1"]
    assert len(trip) == 1 and seen["t_s"] < trip[0]["t_s"] <= seen["t_s"] + 1.0 + 1.0
    assert delta.counters["reads"] - seen["reads"] > 10  # it tripped while the loop kept polling
    assert not any(e["kind"] == "mill_command" for e in events)


@LIVE
@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.timeout(300)
def test_kill_9_of_drumtwin_run_stops_the_drive_through_its_comm_loss_trip(
    delta: DriveEmulator, page, tmp_path: Path
) -> None:
    """`drumtwin run` (the console script in its own process, as a user starts it: AUTO, its
    dashboard) on the Delta emulator over a real pty; the operator presses "Start mill" in
    chromium, the drive runs at the frequency its keypad holds (12 Hz) and the run's
    keep-alive writes hold it; kill -9 of the CLI: nobody writes any more and the drive's own
    comm-loss trip (2 s) stops it within 2 + 1 s of the kill, on the drive's own clock."""
    from tests.twin.dashboard_helpers import button

    set_s = 2.0
    delta.commission(set_s)
    delta.set_motor(setpoint_rpm=12.0)  # the keypad's frequency command; the drive is stopped
    video = synthetic_video(tmp_path / "v.avi", n=1800)
    exe = Path(sys.executable).with_name("drumtwin")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2]), "COLUMNS": "400"}
    cmd = [str(exe), "run", "--video", str(video), "--mill", delta.mill_url(), "--port", str(free_port()),
           "--duration", "170", "--log", str(tmp_path / "run")]  # the default mode: AUTO
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(proc.stderr or []), daemon=True).start()

    def dashboard_url() -> str | None:
        return next((m.group(1) for ln in list(lines) if (m := re.search(r"dashboard on (http://\S+)", ln))), None)

    try:
        wait_until(lambda: dashboard_url() is not None or proc.poll() is not None, 120, "the run's dashboard")
        wait_until(lambda: delta.counters["reads"] > 10 or proc.poll() is not None, 120, "the run to poll the drive")
        assert proc.poll() is None, "".join(lines)[-2000:]
        assert delta.writes == [] and not delta.motor.running  # connected, read only: nothing moved
        page.goto(dashboard_url())
        button(page, "Start mill").click(no_wait_after=True, timeout=60_000)  # the operator's start
        wait_until(lambda: delta.output_hz > 8.0 or proc.poll() is not None, 60, "the run to start the drive")
        assert proc.poll() is None, "".join(lines)[-2000:]
        time.sleep(set_s + 0.5)  # real time: longer than the drive's own 2 s comm-loss timer, which only the run's
        # keep-alive writes (from another process) hold off
        assert delta.motor.running and delta.fault_code == 0 and delta.trip_times_s == []
        kill_s = delta.now_s()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        wait_until(lambda: delta.trip_times_s != [], set_s + 3.0, "the comm-loss trip")
        stop_s = delta.trip_times_s[0] - kill_s
        assert 0.0 < stop_s <= set_s + 1.0, stop_s
        assert delta.fault_code == DELTA.comm_loss_fault_code and not delta.motor.running
        wait_until(lambda: delta.output_hz == 0.0, 5.0, "the ramp to stop")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    writes = delta.writes
    starts = [w for w in writes if w.address == DELTA.control_register and w.value == 0x12]
    assert len(starts) == 1  # the operator's one start
    last_s = max(w.t_s for w in writes)
    assert last_s < kill_s + 0.5  # at most a frame on its way at the kill
    assert delta.trip_times_s[0] - last_s >= set_s  # the trip: set_s of silence after the last write
    events = read_events(tmp_path / "run")  # what the run logged before it was killed
    assert [e["action"] for e in events if e["kind"] == "operator"] == ["start"]
    commanded = {1200} | {round(100 * e["rpm"]) for e in events if e["kind"] == "mill_command"
                          and e["command"] == "set_rpm"}  # the keypad's 12 Hz, or what AUTO set
    keepalive = [w for w in writes if w.address == DELTA.setpoint_register and w.t_s > starts[0].t_s]
    assert len(keepalive) > 10 and {w.value for w in keepalive} <= commanded, (keepalive[-3:], commanded)


@LIVE
@pytest.mark.timeout(240)
def test_a_drive_without_a_comm_loss_trip_is_refused_and_runs_only_with_the_logged_override(
    delta: DriveEmulator, tmp_path: Path
) -> None:
    delta.commission(0.0)
    video = synthetic_video(tmp_path / "v.avi", n=30)
    log = tmp_path / "refused"
    r = cli("run", "--video", video, "--mill", delta.mill_url(), "--no-dashboard", "--mode", "off",
            "--duration", "2", "--log", log)
    assert_one_line_error(r, "Pr.09-03", "disabled", "override=comm-loss")
    assert not log.exists() and delta.writes == []
    r = cli("run", "--video", video, "--mill", delta.mill_url(override="comm-loss"), "--no-dashboard", "--mode", "off",
            "--duration", "2", "--log", tmp_path / "run")
    assert r.code == 0, r.err
    events = read_events(tmp_path / "run")
    over = [e for e in events if e["kind"] == "fault" and e["fault"] == "mill_safety_override"]
    assert len(over) == 1 and "Pr.09-03" in over[0]["message"] and over[0]["t_s"] == 0.0


@pytest.mark.timeout(240)
def test_run_takes_hz_per_rpm_from_the_configs_drive_table(delta: DriveEmulator, tmp_path: Path) -> None:
    """`drumtwin run --config` with `[drive] hz_per_rpm = 2.5`: the link converts with it (the
    drive's keypad holds 10 Hz: the run reads 4 drum rpm) and the start event's URL says so;
    a URL giving another value is refused before anything starts."""
    cfg = tmp_path / "mixer.toml"
    cfg.write_text("[drive]\nhz_per_rpm = 2.5\n")
    delta.set_motor(setpoint_rpm=10.0)  # 10 Hz (the emulator's own hz_per_rpm is 1)
    bare = f"modbus:{delta.url}?profile=delta-ms300&unit=1&parity=N"
    video = synthetic_video(tmp_path / "v.avi", n=30)
    args = ("run", "--video", video, "--config", cfg, "--no-dashboard", "--mode", "off", "--duration", "2")
    r = cli(*args, "--mill", bare + "&hz_per_rpm=1", "--log", tmp_path / "refused")
    assert_one_line_error(r, "the mill URL says 1", "[drive] says 2.5")
    assert not (tmp_path / "refused").exists()
    r = cli(*args, "--mill", bare, "--log", tmp_path / "run")
    assert r.code == 0, r.err
    events = read_events(tmp_path / "run")
    assert events[0]["kind"] == "start" and events[0]["mill"] == bare + "&hz_per_rpm=2.5"
    synced = [e for e in events if e["kind"] == "mill_synced"]
    assert synced and synced[0]["setpoint_rpm"] == 4.0  # 10 Hz / 2.5 Hz per rpm
    assert delta.writes == []


def test_drive_option_is_for_the_demo_only() -> None:
    assert_one_line_error(cli("run", "--drive", "nope", "--no-dashboard"), "unknown drive profile")
    assert_one_line_error(cli("run", "--drive", "abb-acs", "--mill", "/dev/x", "--no-dashboard"), "--drive")


def test_the_mill_workers_rules_hold_on_the_modbus_link_over_a_pty() -> None:
    """The same worker (nothing above the link changes) on ModbusMill and the drive emulator:
    connecting reads only, the operator's start, an out-of-range set-rpm refused (event,
    re-read, nothing written), an unplugged cable: fault, the pending command decided before
    the re-read is dropped, the first exchange after the link is back is a read."""
    from control.modbus.link import ModbusMill
    from tests.twin.test_mill_worker import Sink
    from twin.live.commands import SetRpm, StartMill
    from twin.live.mill import MillWorker
    from twin.live.snapshots import Latest, MillSnapshot

    emu = DriveEmulator(DELTA, unit=1, comm_loss_s=1.0)
    emu.open_pty()
    try:
        emu.set_motor(setpoint_rpm=8.0, actual_rpm=8.0, running=True)
        wait_until(lambda: emu.motor.fault == "CE1", 5, "the comm-loss trip of a drive nobody controls")
        link = ModbusMill(emu.mill_url(), timeout_s=0.3, retries=1)
        sink, box = Sink(), Latest(MillSnapshot())
        w = MillWorker(link, sink, box, now_s=lambda: 0.0)
        for _ in range(5):
            w.cycle()
        assert box.get().connected and box.get().fault == "CE1" and not emu.motor.running
        assert emu.writes == []
        w.submit(StartMill(epoch=box.get().epoch))
        w.cycle()
        assert emu.motor.running and emu.fault_code == 0  # the start reset the latched comm fault
        # reset (bit 1 up and down), run forward, then the poll's keep-alive: the held 8 Hz again
        assert [(x.address, x.value) for x in emu.writes] == [(0x2002, 2), (0x2002, 0), (0x2000, 0x12), (0x2001, 800)]
        n = len(emu.writes)
        w.submit(SetRpm(90.0, epoch=box.get().epoch))  # 90 Hz > the drive's 60 Hz
        snap = w.cycle()
        assert snap.connected and sink.kinds("mill_refused")[0]["reason"].startswith("RANGE")
        assert snap.refused == 1 and [x.address for x in emu.writes[n:]] == [0x2001]  # only the keep-alive
        emu.disconnect()
        old_epoch = box.get().epoch
        for _ in range(3):
            w.cycle()
        assert not box.get().connected and "mill_link" in sink.faults
        w.submit(SetRpm(20.0, epoch=old_epoch))
        emu.reconnect()
        wait_until(lambda: w.cycle().connected, 10, "the link back")
        w.cycle()
        assert box.get().epoch == old_epoch + 1
        assert sink.kinds("mill_command_dropped")[-1]["rpm"] == 20.0
        assert 2000 not in [x.value for x in emu.writes if x.address == 0x2001]  # 20 rpm never written
        link.close()
    finally:
        emu.close()


@LIVE
@pytest.mark.timeout(240)
def test_run_drive_puts_the_embedded_demo_on_a_drive_emulator(tmp_path: Path) -> None:
    """`drumtwin run --drive siemens-v20`: the demo's mill is that drive over Modbus RTU."""
    r = cli("run", "--drive", "siemens-v20", "--no-dashboard", "--mode", "off", "--duration", "3", "--speed", "4",
            "--log", tmp_path / "run", "--json")
    assert r.code == 0, r.err[-2000:]
    events = read_events(tmp_path / "run")
    assert events[0]["kind"] == "start" and events[0]["mill"].startswith("modbus:")
    assert "profile=siemens-v20" in events[0]["mill"]
    synced = [e for e in events if e["kind"] == "mill_synced"]
    assert synced and synced[0]["fault"] is None
    cmds = [(e["command"], e["source"]) for e in events if e["kind"].startswith("mill_command")]
    # the demo's operator; OFF sends nothing else but the stop at the end of a run that had the mill
    assert cmds == [("start", "operator"), ("stop", "run_end")]

"""Issue 25/26 safety of the mill: the CLI enforces the run's limits (from the config's drum), a default
client never feeds the board's watchdog, a killed emulator's pty dirs are cleaned at the next start,
no stale rpm during a link outage, a board found above the limits is an alarm and brought inside."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from control.device import DeviceConfig
from control.emulator import MillEmulator
from control.motor import MotorConfig
from tests.cli import assert_one_line_error, cli
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.run.settings import supervisor_config


@pytest.mark.timeout(30)
def test_mill_set_rpm_refuses_past_the_limits_unless_commissioning() -> None:
    """A board whose own maximum is 200 rpm: the CLI's limit is the run's (5-45 rpm on
    the demo drum, 0.6 x its 77.2 rpm critical speed), not the board's."""
    limits = supervisor_config().limits
    with MillEmulator(DeviceConfig(watchdog_s=0.0, motor=MotorConfig(max_rpm=200.0))) as emu:
        emu.open_tcp(0)
        r = cli("mill", emu.url, "set-rpm", "100")
        assert_one_line_error(r, "100", limits.describe())
        assert emu.motor.setpoint_rpm == 0.0  # nothing reached the board
        assert cli("mill", emu.url, "set-rpm", "30").code == 0 and emu.motor.setpoint_rpm == 30.0
        r = cli("mill", emu.url, "set-rpm", "100", "--commission")
        assert r.code == 0 and emu.motor.setpoint_rpm == 100.0
        assert "commissioning override: set-rpm 100 outside the limits" in r.err  # said, not silent
        assert cli("mill", emu.url, "set-rpm", "0").code == 0  # stopping is always allowed


def _drum_config(path: Path, diameter_mm: float) -> Path:
    """A mixer config with a ``diameter_mm`` drum (two classes of 20 mm discs)."""
    classes = "".join(f'[[classes]]\nname = "{n}"\nhsv = [[[{h}, 90, 50], [{h + 10}, 255, 255]]]\n\n'
                      for n, h in (("red", 0), ("blue", 100)))
    parts = "".join(f'[[particles]]\nname = "{n}"\nshape = "disc"\ndiameter_mm = 20\n'
                    f"density_kg_m3 = 931\nshare = 0.5\n\n" for n in ("red", "blue"))
    path.write_text(f"{classes}[drum]\ndiameter_mm = {diameter_mm}\ndepth_mm = 100\nfill = 0.3\n\n{parts}")
    return path


@pytest.mark.timeout(60)
def test_mill_set_rpm_takes_its_limits_from_the_configs_drum(tmp_path) -> None:
    """``drumtwin mill --config C URL set-rpm R``: the limit is the user's drum's, as the run
    with that config enforces it (0.6 x its critical speed, capped by the supervisor's
    ``max_rpm``), not the demo drum's. A 1 m drum (critical speed 42.3 rpm) refuses the
    30 rpm the demo allows; a 100 mm drum (133.8 rpm) allows what the 400 mm drum (66.9 rpm)
    refuses. Each refusal names the limit and leaves the board untouched."""
    import math

    from twin.config import load_checked_config

    def crit(d_mm: float) -> float:  # n_c = (30 / pi) sqrt(g / R), independently of sim/
        return 30.0 / math.pi * math.sqrt(9.81 / (d_mm / 2000.0))

    big, mid, small = (_drum_config(tmp_path / f"d{d}.toml", d) for d in (1000, 400, 100))
    for cfg, d in ((big, 1000), (mid, 400), (small, 100)):
        assert load_checked_config(cfg).mixer.drum.critical_rpm == pytest.approx(crit(d), rel=1e-3)
        want = RunConfig(meter_config=cfg)
        assert supervisor_config(None, crit(d), want).limits.rpm_range[1] == pytest.approx(min(45.0, 0.6 * crit(d)),
                                                                                      rel=1e-3)
    with MillEmulator(DeviceConfig(watchdog_s=0.0, motor=MotorConfig(max_rpm=200.0))) as emu:
        emu.open_tcp(0)
        assert cli("mill", emu.url, "set-rpm", "30").code == 0 and emu.motor.setpoint_rpm == 30.0  # the demo's
        r = cli("mill", "--config", big, emu.url, "set-rpm", "31")
        assert_one_line_error(r, "31", f"5-{0.6 * crit(1000):.4g} rpm", f"critical speed {crit(1000):.1f} rpm")
        assert emu.motor.setpoint_rpm == 30.0  # refused before the port was opened
        r = cli("mill", "--config", mid, emu.url, "set-rpm", "42")
        assert_one_line_error(r, "42", f"5-{0.6 * crit(400):.4g} rpm", f"critical speed {crit(400):.1f} rpm")
        assert cli("mill", "--config", small, emu.url, "set-rpm", "42").code == 0 and emu.motor.setpoint_rpm == 42.0
        assert_one_line_error(cli("mill", "--config", small, emu.url, "set-rpm", "50"), "outside the limits 5-45 rpm")
        assert_one_line_error(cli("mill", "set-rpm", "45", "--config", big), "")  # usage: the group's option
        assert_one_line_error(cli("mill", "--config", tmp_path / "missing.toml", emu.url, "set-rpm", "10"),
                              "missing.toml")
        assert emu.motor.setpoint_rpm == 42.0


@pytest.mark.timeout(30)
def test_a_default_mill_client_never_feeds_the_watchdog() -> None:
    """Issue 25 item 5: ``MillClient(url)`` starts no heartbeat thread; only a caller that
    controls the motor passes ``heartbeat_s``. A started motor with a silent default
    client is stopped by the board's watchdog (0.3 s here)."""
    import threading

    from control.driver import MillClient

    with MillEmulator(DeviceConfig(watchdog_s=0.3)) as emu:
        emu.open_tcp(0)
        before = {t.name for t in threading.enumerate()}
        with MillClient(emu.url) as c:
            assert c.heartbeat_s is None
            c.set_rpm(10.0)
            c.start()
            assert emu.motor.running
            assert {t.name for t in threading.enumerate()} - before == set()  # no thread of its own
            wait_until(lambda: not emu.motor.running and emu.motor.fault is not None, 10.0,
                       "the watchdog to stop the motor of a silent host")


@pytest.mark.timeout(120)
def test_kill_9_leftovers_are_removed_at_the_next_start(tmp_path, monkeypatch) -> None:
    """Ten emulators on a pty killed with -9 leave ten ``drumtwin-mill-*`` directories
    with a dangling link; the next emulator's start removes them (a live one's stays)."""
    import signal
    import tempfile

    from control.emulator import PTY_DIR_PREFIX

    env = {**os.environ, "TMPDIR": str(tmp_path), "PYTHONPATH": os.environ.get("PYTHONPATH", os.getcwd())}
    code = ("import sys; from control.emulator import MillEmulator; e = MillEmulator(); "
            "print(e.open_pty(), flush=True); sys.stdin.read()")  # lives until killed or its stdin closes
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              env=env) for _ in range(11)]
    links = [Path(p.stdout.readline().strip()) for p in procs]  # type: ignore[union-attr]
    assert all(link.is_symlink() for link in links)
    alive = procs.pop()
    try:
        for p in procs:
            p.send_signal(signal.SIGKILL)
            p.wait(10)
        assert len(list(tmp_path.glob(PTY_DIR_PREFIX + "*"))) == 11
        assert not links[0].exists()  # the pty died with its owner: a dangling link
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with MillEmulator() as emu:
            url = emu.open_pty()
            left = sorted(tmp_path.glob(PTY_DIR_PREFIX + "*"))
            assert left == sorted([links[-1].parent, Path(url).parent])  # the live owner's and ours
    finally:
        alive.kill()
        alive.wait(10)
    assert not Path(url).parent.exists()  # a clean close removes its own


def test_a_pty_dir_whose_owner_file_is_still_being_written_is_left_alone(tmp_path) -> None:
    """Another run's emulator creates its owner file empty, then writes its pid: a start that
    cleans up in between must not take that dir for a dead owner's (it did: two demo runs
    started together, one lost its mill pty and exited 2)."""
    import os
    import time

    from control.emulator import OWNER_FILE, PTY_DIR_PREFIX, remove_stale_pty_dirs

    young = tmp_path / (PTY_DIR_PREFIX + "young")
    young.mkdir()
    (young / OWNER_FILE).write_text("", encoding="ascii")  # created, not written yet
    (young / "mill").symlink_to(tmp_path / "no-such-pty")
    old = tmp_path / (PTY_DIR_PREFIX + "old")
    old.mkdir()
    (old / OWNER_FILE).write_text("", encoding="ascii")
    (old / "mill").symlink_to(tmp_path / "no-such-pty")
    past = time.time() - 120.0
    os.utime(old, (past, past))
    dead = tmp_path / (PTY_DIR_PREFIX + "dead")
    dead.mkdir()
    (dead / OWNER_FILE).write_text("999999999 1", encoding="ascii")  # a pid no process has
    assert sorted(remove_stale_pty_dirs(tmp_path)) == sorted([old, dead])
    assert young.is_dir()


# -- no stale value is a measurement (issue 26 item 7) ------------------------------------
def test_during_a_link_outage_rpm_is_empty_with_a_link_lost_flag() -> None:
    import queue

    from control.trend import MITrend
    from tests.twin.test_mill_worker import RUNNING, Sink, make
    from tests.twin.workers_fakes import Boxes, reading
    from twin.live.camera import CameraReading, ProcessWorker
    from twin.live.supervise import inputs_of

    w, link, _sink, box = make(RUNNING)
    w.cycle()
    b = Boxes("auto")
    b.mill = box
    b.view.mill = box.get  # type: ignore[method-assign]
    sink = Sink()
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink, None)
    pw.process(CameraReading(0.0, 0, reading(0.8)))
    link.up = False  # the outage: the board's last report (5 rpm) is history now
    w.cycle()
    pw.process(CameraReading(0.1, 1, reading(0.8)))
    assert box.get().status is not None and box.get().status.actual_rpm == 5.0  # kept for the resync
    assert inputs_of(b.view, 0.1).actual_rpm is None and inputs_of(b.view, 0.1).setpoint_rpm is None
    link.up = True
    w.cycle()
    pw.process(CameraReading(0.2, 2, reading(0.8)))
    rows = sink.rows()
    assert [(r["rpm_actual"], r["rpm_setpoint"]) for r in rows] == [(5.0, 5.0), (None, None), (5.0, 5.0)]
    assert [r["flags"] for r in rows] == [(), ("link_lost:mill",), ()]


@pytest.mark.timeout(30)
@pytest.mark.parametrize("mode", ["auto", "off"])
def test_a_board_found_above_the_limits_is_an_alarm_and_brought_inside_when_we_control_it(mode) -> None:
    """Another host sets the board to 55 rpm (limits 2-40 here): the mill worker reads it
    again (a new epoch, no stale belief), the supervisor worker alarms; in AUTO the
    supervisor brings it to 40 rpm at once, in OFF it keeps its hands off."""

    from control.decision import Mode
    from control.driver import MillClient
    from tests.twin.workers_fakes import Boxes, advance, sup_worker
    from twin.live.mill import MillWorker

    fast = MotorConfig(max_rpm=200.0, accel_rpm_per_s=200.0, tau_s=0.05)
    with MillEmulator(DeviceConfig(watchdog_s=0.0, motor=fast)) as emu:
        port = emu.open_tcp(0)
        emu.set_motor(setpoint_rpm=30.0, actual_rpm=30.0, running=True)
        link = MillClient(f"socket://127.0.0.1:{port}", heartbeat_s=None, timeout_s=0.5, retries=1)
        try:
            b = Boxes(mode)
            sup, sink, _ = sup_worker(b, Mode(mode))
            mill = MillWorker(link, sink, b.mill, now_s=lambda: 0.0)
            sup.send = mill.submit
            mill.cycle()
            advance(b, sup, 0.0, 2.0)
            assert "mill_above_limits" not in sink.faults
            emu.set_motor(setpoint_rpm=55.0, actual_rpm=55.0, running=True)  # another host
            mill.cycle()
            assert sink.kinds("mill_changed_elsewhere") and b.mill.get().epoch == 2
            advance(b, sup, 2.0, 3.0)
            assert "mill_above_limits" in sink.faults
            mill.cycle()  # the command goes out
            if mode == "auto":
                assert emu.motor.setpoint_rpm == 40.0
                assert any(d["rpm"] == 40.0 for d in sink.kinds("decision"))
                t = [3.0]

                def step() -> bool:  # the motor slows down in real time: read it, tick the supervisor
                    mill.cycle()
                    advance(b, sup, t[0], t[0] + 0.5)
                    t[0] += 0.5
                    return "mill_above_limits" not in sink.faults

                wait_until(step, 20.0, "the fault to clear as the motor slows to 40 rpm")
                assert emu.motor.actual_rpm <= 40.5
            else:
                assert emu.motor.setpoint_rpm == 55.0 and sink.kinds("decision") == []
        finally:
            link.close()

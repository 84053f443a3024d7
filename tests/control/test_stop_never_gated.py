"""A stop is never gated (issue 42): ``drumtwin mill URL stop``, the mill worker's stop (the
dashboard's E-STOP, the supervisor's safe state) and ``link.stop()`` (a failed run's end)
reach a drive whatever its comm-loss trip says or whether it can be read, with or without
``override=comm-loss``; only a start or a faster setpoint is refused, with the reason. The
same for the line protocol's board. Every case runs over a real pty against the emulators
and checks that the stop frame reached the drive and that the drive, running before, stopped."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from control import protocol as p
from control.device import DeviceConfig, MillDevice
from control.driver import MillClient
from control.emulator import MillEmulator
from control.errors import ControlError, MillRefused, SafetyRefused
from control.modbus.emulator import DriveEmulator
from control.modbus.link import ModbusMill
from control.modbus.profile import load_profile
from control.motor import MotorConfig
from tests.cli import assert_one_line_error, cli
from tests.twin.test_mill_worker import Sink
from tests.waiting import wait_until
from twin.live.commands import SetRpm, StartMill, StopMill
from twin.live.mill import MillWorker
from twin.live.snapshots import Latest, MillSnapshot

DELTA = load_profile("delta-ms300")
ABB = load_profile("abb-acs")
ACS355_LIKE = "58.16 / 58.14: modbus exception 2"  # the link reads abb-acs's group 58: this drive has none


@pytest.fixture(scope="module")
def delta() -> Iterator[DriveEmulator]:
    with DriveEmulator(DELTA, unit=1, speed=5.0) as emu:  # ramps 5 x faster: a stopped output in a fraction of a second
        emu.open_pty()
        yield emu


@pytest.fixture(scope="module")
def acs355(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DriveEmulator]:
    """An ABB drive that has the ABB Drives registers but not group 58 (as an ACS355, whose
    comm-fault parameters live elsewhere): a read of 58.14/58.16 is exception 2."""
    from importlib import resources

    text = resources.files("control.modbus").joinpath("profiles", "abb-acs.toml").read_text()
    text = text.replace("time_register = 5815", "time_register = 3018").replace("action_register = 5813",
                                                                                "action_register = 3017")
    path = Path(tmp_path_factory.mktemp("acs355")) / "acs355.toml"
    path.write_text(text.replace('name = "abb-acs"', 'name = "acs355-like"'))
    with DriveEmulator(load_profile(str(path)), unit=2, comm_loss_s=30.0, speed=5.0) as emu:  # its own trip: never here
        emu.open_pty()
        yield emu


def _url(drive: DriveEmulator, override: bool) -> str:
    """The link's URL: the shipped profile (abb-acs for the ACS355-like drive)."""
    url = drive.mill_url(**({"override": "comm-loss"} if override else {}))
    return url.replace("profile=acs355-like", "profile=abb-acs")


def _running(drive: DriveEmulator, rpm: float = 2.0) -> int:
    """Another host left the drive running at ``rpm`` (no fault); the number of writes so far."""
    drive.set_drive_fault(False)
    drive.set_motor(setpoint_rpm=rpm, actual_rpm=rpm, running=True)
    assert drive.motor.running and drive.output_hz > 0 and drive.fault_code == 0
    return len(drive.writes)


def _stopped_by_the_stop_word(drive: DriveEmulator, n_before: int) -> None:
    """The stop word reached the drive's command register (beside it at most the keep-alive's
    setpoint, unchanged), and the drive, not its trip, stopped."""
    prof = drive.profile
    writes = drive.writes[n_before:]
    assert [w.value for w in writes if w.address == prof.control_register] == [prof.stop_word]
    assert {w.address for w in writes} <= {prof.control_register, prof.setpoint_register}
    assert not drive.motor.running and drive.fault_code == 0
    wait_until(lambda: drive.output_hz == 0.0, 5, "the output to ramp down to 0 Hz")


def _unsafe(drive: DriveEmulator, how: str) -> str:
    """Make the drive's comm-loss check fail ``how``; the parameter the refusal names."""
    if how == "disabled":  # the audit's repro: another bus master writes Pr.09-03 = 0 (reference 2308, 1-based)
        drive.commission(2.0)
        exe = shutil.which("mbpoll")
        assert exe, "mbpoll is not installed (scripts/bootstrap.sh installs it: apt-get install mbpoll)"
        subprocess.run([exe, "-m", "rtu", "-b", "19200", "-P", "none", "-a", str(drive.unit), "-t", "4", "-r", "2308",
                        "-1", drive.url, "0"], check=True, capture_output=True, timeout=30)
        assert drive.model.comm_loss_time_s() == 0.0
        return "Pr.09-03 = 0"
    if how == "too long":
        drive.commission(9.0)  # longer than the 5 s the link accepts
        return "too slow"
    return ACS355_LIKE


CASES = [("delta", "disabled"), ("delta", "too long"), ("acs355", "unreadable")]


@pytest.mark.parametrize("override", [False, True], ids=["plain", "override"])
@pytest.mark.parametrize(("which", "how"), CASES)
def test_cli_stop_reaches_a_drive_whose_comm_loss_check_fails(request, which: str, how: str, override: bool) -> None:
    drive: DriveEmulator = request.getfixturevalue(which)
    why = _unsafe(drive, how)
    url = _url(drive, override)
    n = _running(drive)
    r = cli("mill", url, "stop", "--json")
    assert r.code == 0, r.err
    _stopped_by_the_stop_word(drive, n)
    if override:
        return
    n = len(drive.writes)
    line = assert_one_line_error(cli("mill", url, "start"), "refused RUN", why, "override=comm-loss")
    assert drive.writes[n:] == [] and not drive.motor.running, line  # nothing written, nothing started


@pytest.mark.parametrize(("which", "how"), CASES)
def test_only_a_start_or_a_faster_setpoint_is_refused(request, which: str, how: str) -> None:
    drive: DriveEmulator = request.getfixturevalue(which)
    why = _unsafe(drive, how)
    prof = drive.profile
    n = _running(drive, 4.0)
    with ModbusMill(_url(drive, False), timeout_s=0.3, refuse_unsafe=False) as mill:
        with pytest.raises(SafetyRefused, match=why):
            mill.start()
        with pytest.raises(SafetyRefused, match=r"only a stop or a lower speed \(now 4.00 Hz\)"):
            mill.set_rpm(6.0)
        assert drive.writes[n:] == []  # refused before anything was written
        resent = mill.stats["resends"]
        mill.set_rpm(2.0)  # slower: sent
        mill.heartbeat()  # the keep-alive: the setpoint it holds
        sent = [(w.address, w.value) for w in drive.writes[n:]]  # twice; a late answer's request resent is a third
        resent = mill.stats["resends"] - resent
        assert 2 <= len(sent) <= 2 + resent and set(sent) == {(prof.setpoint_register, prof.setpoint.to_counts(2.0))}, \
            (sent, resent)
        assert mill.status().setpoint_rpm == 2.0 and mill.safety_problem is not None
        n = len(drive.writes)
        mill.stop()
    _stopped_by_the_stop_word(drive, n)


def test_the_loops_stops_reach_a_drive_whose_trip_was_disabled_behind_a_reconnect(delta: DriveEmulator) -> None:
    """A run opened on a safe drive; another master disables its trip and the cable is
    replugged: the mill worker's stop (E-STOP, the supervisor's safe state) and ``link.stop()``
    (a failed run's end) still reach it; a start is a ``mill_refused`` event with the reason."""
    delta.commission(2.0)
    with ModbusMill(delta.mill_url(), timeout_s=0.3) as link:  # the run's open: checked and safe
        sink, box = Sink(), Latest(MillSnapshot())
        worker = MillWorker(link, sink, box, now_s=lambda: 0.0)
        worker.cycle()
        assert box.get().connected
        n = _running(delta)
        delta.commission(0.0)
        delta.disconnect()
        with pytest.raises((ConnectionError, TimeoutError)):
            link.status()
        delta.reconnect()
        wait_until(lambda: worker.cycle().connected, 5, "the link back")
        worker.submit(StartMill(box.get().epoch))
        worker.submit(SetRpm(9.0, box.get().epoch))
        worker.cycle()
        refused = sink.kinds("mill_refused")
        assert [e["command"] for e in refused] == ["start"] and "Pr.09-03 = 0" in refused[0]["reason"]
        assert delta.writes[n:] == []
        for source in ("emergency_stop", "supervisor"):
            n = _running(delta)
            worker.submit(StopMill(source=source, urgent=source == "emergency_stop"))
            worker.cycle()
            _stopped_by_the_stop_word(delta, n)
        n = _running(delta)
        link.stop()  # LiveLoop.stop() after a failure: the workers are gone, the link is the loop's
        _stopped_by_the_stop_word(delta, n)
        assert [e["command"] for e in sink.kinds("mill_command") if e["command"] == "stop"] == ["stop", "stop"]


def test_a_run_refuses_an_unreadable_trip_up_front_and_with_the_override_it_runs_logged(
    acs355: DriveEmulator,
) -> None:
    with pytest.raises(ControlError, match=r"cannot be read.*modbus exception 2.*override=comm-loss"):
        ModbusMill(_url(acs355, False), timeout_s=0.3)  # refuse_unsafe: what a run opens
    with ModbusMill(_url(acs355, True), timeout_s=0.3) as mill:
        assert mill.safety_override is not None and ACS355_LIKE in mill.safety_override
        acs355.set_motor(running=False, actual_rpm=0.0)
        mill.set_rpm(3.0)
        mill.start()  # overridden (the run logs mill_safety_override)
        assert acs355.motor.running
        n = len(acs355.writes)
        mill.stop()
    _stopped_by_the_stop_word(acs355, n)


# -- the line protocol's board -------------------------------------------------------------
@pytest.fixture(scope="module")
def board() -> Iterator[MillEmulator]:
    """The board with its watchdog off (commissioning): nothing but a stop stops it."""
    with MillEmulator(DeviceConfig(watchdog_s=0.0, motor=MotorConfig(max_rpm=60.0, accel_rpm_per_s=40.0,
                                                                      tau_s=0.05))) as emu:
        emu.open_pty()
        yield emu


def _board_running(board: MillEmulator) -> int:
    board.set_drive_fault(False)
    board.set_motor(setpoint_rpm=3.0, actual_rpm=3.0, running=True)
    assert board.motor.running
    return len(board.applied)


def _board_stopped(board: MillEmulator, n_before: int) -> None:
    assert [a.cmd for a in board.applied[n_before:]] == [p.STP]
    assert not board.motor.running
    wait_until(lambda: board.motor.actual_rpm == 0.0, 5, "the board's motor to ramp down")


def test_cli_stop_reaches_a_board_with_its_watchdog_off_as_its_first_frame(board: MillEmulator) -> None:
    n = _board_running(board)
    frames = board.counters["frames"]
    r = cli("mill", board.url, "stop", "--json")  # a new host: no heartbeat, no command before it
    assert r.code == 0, r.err
    _board_stopped(board, n)
    assert board.counters["frames"] - frames == 2  # the STP, then the status read (STA)


def test_a_stop_after_a_nakd_command_and_while_faulted_reaches_the_board(board: MillEmulator) -> None:
    with MillClient(board.url, timeout_s=0.3, heartbeat_s=None) as c:
        n = _board_running(board)
        with pytest.raises(MillRefused, match="RANGE"):
            c.set_rpm(99.0)  # above the board's max: NAK
        c.stop()
        _board_stopped(board, n)
        n = _board_running(board)
        board.device.motor.fault = p.FAULT_DRIVE  # the power stage reports a fault, the motor still turns
        c.stop()
        _board_stopped(board, n)


def test_a_resent_stop_still_stops_a_motor_started_from_the_front_panel() -> None:
    """Pure: a ``STP`` with the same sequence number and payload as the last frame is a
    resend (the cached ACK), and it still stops a motor someone started since."""
    d = MillDevice(DeviceConfig(watchdog_s=0.0))
    stp = p.encode_frame(7, p.STP)
    assert d.receive(stp, 0.0) == p.encode_frame(7, p.ACK)
    d.motor.running = True  # the front panel
    assert d.receive(stp, 0.1) == p.encode_frame(7, p.ACK)
    assert not d.motor.running and [a.cmd for a in d.applied] == [p.STP, p.STP]
    assert d.receive(stp, 0.2) == p.encode_frame(7, p.ACK)  # a plain resend: nothing applied again
    assert len(d.applied) == 2 and d.counters["resends"] == 2

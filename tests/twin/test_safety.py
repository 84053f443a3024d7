"""Issue 26: every entry point refuses bad input in one line (exit 2, no traceback), the
mill CLI enforces the run's limits, a dead Dask scheduler is refused at the start."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from control.device import DeviceConfig
from control.emulator import MillEmulator
from control.motor import MotorConfig
from tests.cli import assert_one_line_error, cli
from tests.conftest import BENCH_MEMORY_ARGS, BENCHES
from tests.twin.live_script import run_scripted
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.records import FaultRaised
from twin.run.settings import Seams, supervisor_config

DRUMTWIN = Path(sys.executable).with_name("drumtwin")
REAL = Path(__file__).resolve().parents[1] / "data" / "real-drum-pmma" / "images"


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # nothing listens there once closed


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bad")
    deep = d / "deep.toml"
    deep.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    roi = d / "roi.toml"
    roi.write_text("[meter]\nroi = [1e308, 1e308, 1e308]\n")
    video = d / "v.avi"  # a file that exists (the run refuses before it reads it)
    video.write_bytes(b"not a video")
    return {"deep": deep, "roi": roi, "video": video}


IMG = str(REAL / "0002.jpg")
SWEEP: list[tuple[tuple[str, ...], str]] = [
    # run: every option class bounded (numbers, host, scheduler, files, choices)
    (("run", "--duration", "1e308"), "--duration"),
    (("run", "--duration", "nan"), "--duration"),
    (("run", "--duration", "-1"), "--duration"),
    (("run", "--speed", "1e-9"), "--speed"),
    (("run", "--speed", "inf"), "--speed"),
    (("run", "--speed", "0"), "--speed"),
    (("run", "--host", "999.1.1.1"), "--host"),
    (("run", "--host", "a b"), "--host"),
    (("run", "--host", ""), "--host"),
    (("run", "--port", "0"), "--port"),
    (("run", "--port", "70000"), "--port"),
    (("run", "--seed", "-1"), "--seed"),
    (("run", "--mode", "turbo"), "--mode"),
    (("run", "--case", "Z"), "--case"),
    (("run", "--scheduler", "garbage"), "--scheduler"),
    (("run", "--scheduler", "tcp://127.0.0.1:notaport"), "--scheduler"),
    (("run", "--host", "0.0.0.0"), "control token"),
    (("run", "--config", "{deep}"), "nested too deeply"),
    (("run", "--video", "{video}", "--mill", "socket://127.0.0.1:9", "--config", "{roi}"), "roi"),
    (("run", "--video", "/nonexistent.mp4", "--mill", "socket://127.0.0.1:9"), "not found"),
    # mi: configs, ROI, numbers
    (("mi", IMG, "--config", "{deep}"), "nested too deeply"),
    (("mi", IMG, "--config", "{roi}"), "roi"),
    (("mi", IMG, "--roi", "1e308,1e308,1e308"), "roi"),
    (("mi", IMG, "--roi", "1,2"), "--roi"),
    (("mi", IMG, "--window", "0"), "window"),
    (("mi", IMG, "--fps", "nan"), "fps"),
    # what-if / sim: the same caps as the dashboard's what-if
    (("whatif", "--duration", "1e9"), "what-if duration must be in (0, 3600] s"),
    (("whatif", "--rpm", "10000"), "what-if rpm 10000 outside (0, 77.23] rpm"),
    (("whatif", "--rpm", "5,10", "--seeds", "1001"), "--seeds"),
    (("sim", "--duration", "1e308"), "--duration"),
    # the mill CLI: the run's limits (issue 26 item 5) before any port is opened
    (("mill", "socket://127.0.0.1:9", "set-rpm", "100"), "outside the limits 5-45 rpm"),
    (("mill", "socket://127.0.0.1:9", "set-rpm", "2"), "outside the limits"),
    (("mill-emulator", "--max-rpm", "inf"), "--max-rpm"),
    (("mill-emulator", "--duration", "1e308"), "--duration"),
    (("compare", "/nonexistent-run", "--plot", "x.png"), ""),
]


@pytest.mark.parametrize("rpm", ["0", "-5", "5,-5"])
def test_whatif_refuses_a_zero_or_negative_rpm_with_the_dashboards_check(rpm: str) -> None:
    """``whatif --rpm -5`` ran (sim.drum.check_rpm bounds |rpm|: the drum turned the other way)
    and ``--rpm 0`` simulated a standing drum, where the dashboard's what-if refused both: the
    command now refuses them with the loop's own check (``Limits.check_whatif``), word for word."""
    from control.errors import ControlError
    from twin.run.settings import supervisor_config

    bad = float(rpm.split(",")[-1])
    with pytest.raises(ControlError) as loops:  # what the dashboard's viewer is told (LiveLoop.run_whatif)
        supervisor_config().limits.check_whatif([bad], 1.0)
    line = assert_one_line_error(cli("whatif", "--rpm", rpm, "--duration", "0.5", "--workers", "1"))
    assert str(loops.value) in line and "outside (0, 77.23] rpm" in line


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("args", "needle"), SWEEP, ids=[" ".join(a)[:60] for a, _ in SWEEP])
def test_bad_input_sweep_is_one_line_exit_2(args, needle, bad_files) -> None:
    argv = [a.format(**{k: str(v) for k, v in bad_files.items()}) for a in args]
    assert_one_line_error(cli(*argv), *([needle] if needle else []))


def test_run_refuses_a_dead_scheduler_at_the_start(tmp_path) -> None:
    port = _closed_port()
    r = cli("run", "--no-dashboard", "--duration", "5", "--log", tmp_path / "log",
            "--scheduler", f"tcp://127.0.0.1:{port}")
    assert_one_line_error(r, "--scheduler", "no Dask scheduler answers")
    assert not (tmp_path / "log").exists()  # refused before any log or thread exists


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


def _frames(d: Path) -> Path:
    from vision.synthetic import drum_frame

    d.mkdir()
    for i, mix in enumerate([0.0, 0.5, 1.0]):
        cv2.imwrite(str(d / f"f{i}.png"), drum_frame(mix=mix, seed=i))
    return d


def _in_read_only_dir(tmp_path: Path, args: list[str]) -> subprocess.CompletedProcess:
    """Run ``drumtwin ARGS`` with ``{ro}`` a read-only directory: a read-only tmpfs in a
    private mount namespace when we are root (permission bits do not stop root), else a
    directory without write permission."""
    ro = tmp_path / "ro"
    ro.mkdir()
    argv = [a.replace("{ro}", str(ro)) for a in args]
    env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", os.getcwd()), "COLUMNS": "400"}
    env.pop("DRUMTWIN_DEBUG", None)
    if os.geteuid() == 0:
        unshare = shutil.which("unshare")
        assert unshare, "root without unshare(1): no way to make a read-only directory here"
        cmd = [unshare, "-rm", "sh", "-c", f'mount -t tmpfs -o ro tmpfs "{ro}" && exec "$@"', "sh",
               str(DRUMTWIN), *argv]
    else:
        ro.chmod(0o555)
        cmd = [str(DRUMTWIN), *argv]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)


@pytest.mark.timeout(240)
@pytest.mark.parametrize("what", ["mi --csv", "mi --plot", "mill-emulator --link"])
def test_writing_into_a_read_only_directory_is_one_line(tmp_path, what) -> None:
    frames = str(_frames(tmp_path / "frames")) if what.startswith("mi") else ""
    args = {
        "mi --csv": ["mi", frames, "--csv", "{ro}/mi.csv"],
        "mi --plot": ["mi", frames, "--csv", str(tmp_path / "ok.csv"), "--plot", "{ro}/mi.png"],
        "mill-emulator --link": ["mill-emulator", "--link", "{ro}/mill", "--duration", "0.5"],
    }[what]
    p = _in_read_only_dir(tmp_path, args)
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    assert "Traceback" not in p.stderr
    lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "read-only" in lines[0].lower(), p.stderr


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


# -- twin versus reality (issue 26 item 8) and a failed AUTO study (item 4) -----------------
def test_residual_flags_direction_slope_and_mi() -> None:
    from twin.live.mismatch import MismatchTolerance, residual

    tol = MismatchTolerance(slope_deg=15.0, mi=0.3)
    assert not residual(30.0, 36.0, 0.9, 0.8, tol).bad
    r = residual(-33.8, 53.7, 0.9, 0.9, tol)  # the video: clockwise drum, twin the other way
    assert r.bad and not r.direction_agrees and "rotation direction" in r.reasons[0]
    assert residual(30.0, 50.0, 0.9, 0.9, tol).reasons[0].startswith("slope")
    assert residual(30.0, 30.0, 0.3, 0.9, tol).reasons[0].startswith("MI")
    assert not residual(float("nan"), 30.0, 0.9, 0.9, tol).known  # no camera slope: no verdict


def _mismatch_rig(camera_slope: float, twin_slope: float, tol=None):
    from tests.twin.workers_fakes import Boxes, reading
    from twin.live.mismatch import MismatchMonitor

    b = Boxes("auto")
    b.mill_at(5.0)
    recal: list[float] = []
    from control.decision import Mode
    from control.supervisor import Supervisor
    from tests.control.supervisor_values import worked_config
    from tests.twin.test_mill_worker import Sink
    from twin.live.supervise import SupervisorWorker

    sink = Sink()
    w = SupervisorWorker(Supervisor(worked_config(vision_timeout_s=3.0, recover_s=2.0), mode=Mode.AUTO),
                         b.view, sink, [].append, None, b.mode, mismatch=MismatchMonitor(tol),
                         on_twin_mismatch=lambda: recal.append(b.view.now_s()))

    def run(t0: float, t1: float, twin_slope_deg: float, twin_steps: bool = True, seeded_s: float = 0.0) -> None:
        """Run time ``t0`` to ``t1`` in 0.5 s ticks; the twin was seeded at run time ``seeded_s``."""
        from control.trend import TrendEstimate
        from twin.live.snapshots import CameraInfo, FrameInfo, TwinInfo

        t = t0
        while t < t1 - 1e-9:
            b.wall.t += 0.5
            est = TrendEstimate(t, 0.9, 0.0, 0.01, 0.001, 0.88, 0.92, True, False)
            b.camera.set(CameraInfo(t, b.wall.t, None, None, int(t * 2) + 1, False))
            b.frames.set(FrameInfo(t, int(t * 2) + 1, t, reading(0.9, slope=camera_slope), est))
            if twin_steps:  # False: the twin lags (its newest state stays where it was)
                b.twin.set(TwinInfo(updated_s=t, mi=0.88, slope_deg=twin_slope_deg, age_s=t - seeded_s))
            w.tick(b.view.now_s())
            t += 0.5

    return w, sink, recal, run


@pytest.mark.parametrize(("twin_slope", "what"), [(-31.0, "rotation direction"), (58.0, "slope")])
def test_a_twin_calibrated_wrong_raises_twin_mismatch_within_10_s_and_auto_goes_safe(twin_slope, what) -> None:
    w, sink, recal, run = _mismatch_rig(camera_slope=31.0, twin_slope=twin_slope)
    run(0.0, 20.0, 33.0)  # twin and camera agree: no alarm
    assert "twin_mismatch" not in sink.faults and not w.safe
    run(20.0, 30.0, twin_slope)  # the twin goes wrong at t = 20 s
    raised = [d for k, d in sink.events if k == "fault" and d["fault"] == "twin_mismatch"]
    assert raised and what in raised[0]["message"]
    assert w.safe and "twin stale: twin disagrees with the camera" in w.supervisor.safe_reason
    assert recal and 20.0 < recal[0] <= 30.0  # a recalibration was asked for, within 10 s
    run(30.0, 45.0, 33.0)  # agrees again: cleared, trusted, AUTO recovers
    assert "twin_mismatch" not in sink.faults and w.twin_doubt == "" and not w.safe


def test_a_failed_auto_study_is_an_alarm_and_the_safe_state_until_the_operator_chooses() -> None:
    from control.decision import Mode, PredictionRequest
    from tests.twin.test_mill_worker import Sink
    from tests.twin.workers_fakes import Boxes, advance, sup_worker
    from twin.live.commands import SetMode
    from twin.live.snapshots import TwinInfo
    from twin.live.whatif import WhatIfWorker
    from twin.state import LiveState

    def dead_cluster(jobs):
        raise OSError("no Dask scheduler answers at tcp://127.0.0.1:1")

    b = Boxes("auto")
    b.mill_at(5.0)
    w, sink, _sent = sup_worker(b, Mode.AUTO, twin_timeout_s=None)
    results: list = []
    wi = WhatIfWorker(b.view, Sink(), LiveState(), study=dead_cluster)
    wi.on_auto_result = results.append
    b.twin.set(TwinInfo(updated_s=0.0, state=object()))
    wi.request(PredictionRequest(1.0, (5.0, 25.0), 40.0))
    assert wi.serve_once() and wi.poll() is None
    assert results and results[0] is not None and "no Dask scheduler" in results[0]
    # the loop's wiring (LiveLoop._auto_study_result): fault + doubt
    w.doubt_twin("whatif", f"what-if study failed ({results[0]})")
    sink.publish(FaultRaised(t_s=1.0, fault="whatif_failed", message=results[0]))
    advance(b, w, 0.0, 3.0)
    assert w.safe and "what-if study failed" in w.supervisor.safe_reason
    w.handle(SetMode("auto"))  # the operator chooses again
    advance(b, w, 3.0, 12.0)
    assert not w.safe and "whatif_failed" not in sink.faults


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


@BENCHES
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_bench_memory_measures_the_run_and_its_process_tree(cli_once) -> None:
    """``drumtwin bench memory --seconds 5 --json``: a real run on a 640x640 video; the tree includes
    the what-if and calibration pool processes, so it is at least the run process itself (the
    session's run, tests/conftest.py: shared with the bad-input sweep's base of ``bench memory``)."""
    import json

    r = cli_once("bench", "memory", *BENCH_MEMORY_ARGS)
    assert r.code == 0, r.err
    d = json.loads(r.out)
    assert d["processes"] >= 2 and 50 < d["main_hwm_mb"] < 2000
    assert d["tree_rss_mb"] >= d["tree_pss_mb"] > 0 and d["tree_rss_mb"] >= d["main_hwm_mb"] * 0.8
    per = d["per_process"]  # each process's own peak: their sum bounds the peak of the sum
    assert "run" in per and len(per) >= 2 and sum(per.values()) >= d["tree_pss_mb"] - 0.5
    assert not any(k == "forkserver" for k in per) or any(k.startswith("worker") for k in per)
    assert_one_line_error(cli("bench", "memory", "--seconds", "1e9"), "--seconds")


def test_chunked_colour_table_equals_the_classifier() -> None:
    """The HSV lookup table is now built in 16 chunks (peak memory): every colour still gets
    the class the pixel classifier gives it."""
    import numpy as np

    from vision.colours import DEFAULT_CLASSES, Classifier, class_lut

    lut = class_lut(DEFAULT_CLASSES)
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (64, 4096, 3), dtype=np.uint8)
    img[0, :256] = [[b, 0, 255] for b in range(256)]  # a chunk border (B = 15/16) is in there too
    h, s, v = cv2.split(cv2.cvtColor(img, cv2.COLOR_BGR2HSV))
    masks = Classifier(DEFAULT_CLASSES).class_masks(h, s, v)
    want = np.zeros(img.shape[:2], np.uint8)
    for k in range(len(masks) - 1, -1, -1):
        want[masks[k] != 0] = k + 1
    idx = (img[..., 0].astype(np.int64) << 16) | (img[..., 1].astype(np.int64) << 8) | img[..., 2]
    assert np.array_equal(lut[idx], want) and want.any()


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("wrong", ["direction", "slope"])
def test_demo_twin_gone_wrong_raises_twin_mismatch_within_10_s_and_auto_goes_safe(tmp_path, wrong) -> None:
    """The whole loop (embedded demo, AUTO): from run time ``t_wrong`` on, the twin's
    published bed turns the other way (its slope negated) or 30 deg steeper, as a twin
    calibrated to the wrong direction or slope would; ``twin_mismatch`` follows within
    10 s of run time and the supervisor is safe with the twin stale."""
    import dataclasses
    import math

    from twin.live.faults import FaultHooks
    from twin.live.mismatch import MismatchMonitor, MismatchTolerance
    from twin.runlog import read_events

    cfg = RunConfig(dashboard=False, duration_s=600, speed=4.0, mode="auto", log_dir=tmp_path / "run").resolved()
    report: dict = {}

    def before(loop, plant) -> None:
        report["loop"] = loop

    def wrong_twin(info):  # the twin's state as it is published (twin.live.faults: twin_published)
        if report.get("t_wrong") is not None and math.isfinite(info.slope_deg):
            s = -info.slope_deg if wrong == "direction" else info.slope_deg + 30.0
            info = dataclasses.replace(info, slope_deg=s)
            report.setdefault("t_first_wrong", report["loop"].now_s())  # the twin's first wrong publish
        return info

    def body(loop, plant) -> None:
        # the twin goes wrong once it is evidence (past its spin-up, ``warmup_s`` simulated since
        # it was seeded) and has agreed a whole median window: on a busy machine it seeds late
        settled = MismatchTolerance().warmup_s + MismatchMonitor().window_s
        wait_until(lambda: loop.now_s() > 15.0 and loop.twin_box.get().age_s > settled, 120, "a settled twin")
        report["quiet_before"] = not any("twin" in a for a in loop.state.alarms)
        report["t_wrong"] = loop.now_s()
        wait_until(lambda: loop.supervisor.safe, 120, "the safe state after the twin went wrong")
        report["t_safe"] = loop.now_s()
        report["safe_reason"] = loop.supervisor.supervisor.safe_reason

    run_scripted(cfg, body, before, Seams(faults=FaultHooks(twin_published=wrong_twin)))
    events = read_events(tmp_path / "run")
    raised = [e for e in events if e["kind"] == "fault" and e["fault"] == "twin_mismatch"]
    assert report["quiet_before"] and raised
    t_wrong = report["t_first_wrong"]  # (a busy machine's twin publishes less often: from its first wrong state)
    assert t_wrong < raised[0]["t_s"] <= t_wrong + 10.0
    assert ("rotation direction" if wrong == "direction" else "slope") in raised[0]["message"]
    assert report["t_safe"] <= t_wrong + 10.5 and "twin stale: twin disagrees" in report["safe_reason"]
    assert any(e["kind"] == "decision" and e["safe"] and "twin stale" in e["reason"] for e in events)


def test_the_loops_whatif_has_the_whatif_commands_caps_and_can_be_cancelled(tmp_path) -> None:
    """Issue 26 item 3: 1e9 s or 10,000 rpm values are refused with the limit named (the
    dashboard's callback and a script calling the loop alike); a running study is cancelled."""
    import threading

    from control.limits import WHATIF_MAX_RUNS
    from control.protocol import MillStatus
    from tests.twin.test_mill_worker import FakeLink
    from twin.live.snapshots import TwinInfo
    from twin.run.loop import LiveLoop
    from twin.runlog import RunLog, read_events

    started, release = threading.Event(), threading.Event()

    def slow_study(jobs):
        started.set()
        release.wait(30)
        raise RuntimeError("pool terminated")

    cfg = RunConfig(dashboard=False, mode="off", log_dir=tmp_path / "run").resolved()
    with RunLog(tmp_path / "run") as log:
        loop = LiveLoop(cfg, iter(()), FakeLink(MillStatus(5.0, 5.0, True, None)), log,
                        seams=Seams(whatif_study=slow_study))
        loop.controls.run_whatif([5.0], 1e9)
        loop.controls.run_whatif([5.0 + i * 0.001 for i in range(WHATIF_MAX_RUNS + 1)], 60.0)
        loop.controls.run_whatif([10000.0], 60.0)
        errors = [e["error"] for e in read_events(tmp_path / "run") if e["kind"] == "operator_rejected"]
        assert len(errors) == 3 and "(0, 3600] s" in errors[0] and "at most 2000 runs" in errors[1]
        assert "10000 outside (0, 77.23] rpm" in errors[2]  # the demo drum's critical speed
        assert not loop.controls.cancel_whatif()  # nothing to cancel
        loop.twin_box.set(TwinInfo(updated_s=1.0, state=object()))
        loop.controls.run_whatif([5.0, 25.0], 60.0)
        t = threading.Thread(target=loop.whatif.serve_once)
        t.start()
        assert started.wait(10)
        assert loop.controls.cancel_whatif()  # running: abandoned (the local pool is terminated)
        release.set()
        t.join(10)
        kinds = [e["kind"] for e in read_events(tmp_path / "run")]
        assert "whatif_cancelled" in kinds and "whatif_error" not in kinds
        assert loop.state.snapshot().whatif.status == "cancelled by the operator"
        loop.whatif.close()


def test_a_lagging_or_spinning_up_twin_is_no_evidence_of_a_mismatch() -> None:
    """The demo's OFF run alarmed at 9 s: its twin, lagging, still showed the 4 deg slope of its
    first state (just seeded, not spun up) against the camera's 34 deg. A twin whose newest state
    is older than ``fresh_s`` or younger than ``warmup_s`` is no evidence; a fresh wrong twin is."""
    from twin.live.mismatch import MismatchTolerance, twin_is_evidence

    tol = MismatchTolerance()
    assert not twin_is_evidence(9.0, 1.0, 8.0, tol)  # 8 s old
    assert not twin_is_evidence(4.0, 4.0, 3.9, tol)  # fresh, but 3.9 s into its run
    assert twin_is_evidence(9.0, 8.5, 8.4, tol)
    assert not twin_is_evidence(9.0, None, 8.4, tol)  # no twin yet
    w, sink, recal, run = _mismatch_rig(camera_slope=34.0, twin_slope=4.0)
    run(0.0, 4.5, 4.0)  # spinning up: a wrong slope, but no verdict
    assert "twin_mismatch" not in sink.faults

    run(5.0, 20.0, 4.0, twin_steps=False)  # the twin lags at 4.5 s while the camera goes on
    assert "twin_mismatch" not in sink.faults and not recal
    assert w.view.twin().updated_s == 4.0
    run(20.0, 30.0, 4.0)  # fresh again and past its spin-up, still wrong: raised
    assert "twin_mismatch" in sink.faults and recal


@pytest.mark.parametrize("how", ["late seeding", "reseeded"])
def test_a_twin_that_skipped_ahead_or_was_seeded_again_is_spinning_up_whatever_run_time_says(how) -> None:
    """CI at stop 37: the twin of a busy machine seeded late, published its first state 15 s
    behind and skipped ahead to now; counted from that first state's run time it looked spun up
    at once. Spin-up is the twin's own simulated time since its latest seeding
    (``TwinInfo.age_s``): a wrong bed fresh from seeding is no verdict until it has run
    ``warmup_s``, and then it is."""
    from twin.live.mismatch import MismatchMonitor, MismatchTolerance

    tol = MismatchTolerance(warmup_s=8.0)  # longer than a median window and a raise (a verdict without it)
    warm = tol.warmup_s
    assert warm > MismatchMonitor().window_s + tol.raise_after_s
    _w, sink, recal, run = _mismatch_rig(camera_slope=34.0, twin_slope=4.0, tol=tol)
    if how == "late seeding":
        run(0.0, 0.5, 4.0)  # its first state, published at run time 0 ...
        seeded = 15.0  # ... then 15 s on the twin skipped ahead (only 0.5 s simulated)
    else:
        run(0.0, 10.0, 34.0)  # a right twin, well spun up
        seeded = 10.0  # then seeded again (an operator's reseed): a fresh bed
    run(seeded, seeded + warm - 0.5, 4.0, seeded_s=seeded)
    assert "twin_mismatch" not in sink.faults and not recal
    run(seeded + warm - 0.5, seeded + warm + 5.0, 4.0, seeded_s=seeded)
    assert "twin_mismatch" in sink.faults and recal

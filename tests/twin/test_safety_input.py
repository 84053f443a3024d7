"""Issue 26: every entry point refuses bad input in one line (exit 2, no traceback): the option sweep,
a dead Dask scheduler refused at the start, a read-only output directory, and the loop's what-if caps
(refused with the limit named; a running study can be cancelled)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from tests.cli import assert_one_line_error, cli
from twin.config import RunConfig
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
    """``whatif --rpm -5`` ran (sim.params.check_rpm bounds |rpm|: the drum turned the other way)
    and ``--rpm 0`` simulated a standing drum, where the dashboard's what-if refused both: the
    command now refuses them with the loop's own check (``Limits.check_whatif``), word for word."""
    from control.errors import ControlError

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

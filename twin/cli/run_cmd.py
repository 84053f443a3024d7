"""``drumtwin run``: the live loop (embedded demo by default) with its dashboard."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from twin.cli.app import ENDPOINT_HELP, app, bench_app, console_err, print_json, say
from twin.errors import TwinError

if TYPE_CHECKING:
    from twin.config import RunConfig
    from twin.run.loop import LiveLoop, Summary


@contextlib.contextmanager
def _signals_restored() -> Iterator[None]:
    """Ctrl-C (SIGINT) stops the run even when the process inherited it ignored (started with ``&``
    by a script or a service: Python keeps an inherited SIG_IGN, and the run went on until killed).
    The run's SIGINT and SIGTERM handlers (this and :func:`_wait`) end with the run; after a
    Ctrl-C the process is on its way out: a repeated one stays harmless to the end."""
    main = threading.current_thread() is threading.main_thread()
    saved = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) if main else None
    if main:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if saved is not None:
            signal.signal(signal.SIGTERM, saved[1])
            if signal.getsignal(signal.SIGINT) is not _still_stopping:
                signal.signal(signal.SIGINT, saved[0])


def _run(cfg: RunConfig, progress: bool) -> Summary:
    """``drumtwin run`` for ``cfg`` (a resolved ``RunConfig``): the one composition root
    (``twin.run.main.run_live``) with the CLI's progress bar, Ctrl-C and SIGTERM."""
    from twin.run import main

    with _signals_restored():
        return main.run_live(cfg, wait=lambda loop: _wait(loop, cfg, progress),
                             on_dashboard=lambda url: console_err.print(f"dashboard on [bold]{url}[/]  (Ctrl-C stops)",
                                                                        highlight=False))


def _still_stopping(signum: int, frame: object) -> None:
    """SIGINT after the first Ctrl-C: the run log's stop record and the mill's stop come first."""
    say("still stopping…")


def _wait(loop: LiveLoop, cfg: RunConfig, progress: bool) -> None:
    """Block until the duration is over, Ctrl-C or SIGTERM."""
    stop = loop.stop_event
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        if cfg.duration_s is None or not progress:
            loop.wait(cfg.duration_s)
            return
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        with Progress(
            TextColumn("run"), BarColumn(), TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
            TextColumn("MI {task.fields[mi]}  rpm {task.fields[rpm]}"), TimeRemainingColumn(),
            console=console_err, transient=True,
        ) as bar:
            task = bar.add_task("run", total=cfg.duration_s, mi="–", rpm="–")
            while not stop.is_set() and loop.now_s() < cfg.duration_s:
                est = loop.frames_box.get().estimate
                mi = f"{est.level:.3f}" if est is not None and est.valid else "–"
                rpm = loop.mill_box.get().actual_rpm
                bar.update(task, completed=min(loop.now_s(), cfg.duration_s), mi=mi, rpm=f"{rpm:.1f}")
                stop.wait(0.2)
    except KeyboardInterrupt:
        say("stopping…")
        if threading.current_thread() is threading.main_thread():  # a second Ctrl-C must not cut the
            signal.signal(signal.SIGINT, _still_stopping)  # stop short


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
    """Send everything printed to stdout (by us, viser, workers, child processes) to
    stderr while the block runs, so ``--json`` stdout carries only the JSON."""
    saved_fd = None
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (in-process tests)
        fd = None
    if fd is not None:
        sys.stdout.flush()
        saved_fd = os.dup(fd)
        os.dup2(sys.stderr.fileno(), fd)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        if saved_fd is not None and fd is not None:
            sys.stdout.flush()
            os.dup2(saved_fd, fd)
            os.close(saved_fd)


def _drive_profile(drive: str, *others: object) -> str:
    """``--drive``: a loadable profile, and only for the embedded demo."""
    from control.modbus.profile import load_profile

    if any(o is not None for o in others):
        raise TwinError("--drive only applies to the embedded demo (a real drive: --mill modbus:PORT?profile=...)")
    load_profile(drive)  # a one-line error now for an unknown profile
    return drive


@app.command("run")
def run(
    camera: str = typer.Option(None, "--camera", help="Camera index or stream URL (real hardware)."),
    video: Path = typer.Option(None, "--video", help="Replay a recorded video instead of a camera."),
    mill: str = typer.Option(None, "--mill", help="Mill serial URL: /dev/ttyUSB0, socket://host:port, rfc2217://..."),
    config: Path = typer.Option(None, "--config", help="Meter TOML (colour classes, ROI; the twin's mixer: "
                                "\\[drum], [\\[particles]])."),
    engine: str = typer.Option(None, "--engine", help="Twin engine: dem or pymunk (default: the mixer's)."),
    no_dashboard: bool = typer.Option(False, "--no-dashboard", help="Run without the browser dashboard."),
    duration: float = typer.Option(None, "--duration", help="Stop after this many seconds of run time."),
    log: Path = typer.Option(None, "--log", help="Run log directory (default runs/<timestamp>)."),
    mode: str = typer.Option("auto", "--mode", help="Supervisor mode: off, manual or auto."),
    case: str = typer.Option("C", "--case", help="Demo plant's initial state: A, B or C."),
    speed: float = typer.Option(1.0, "--speed", help="Demo clock speed-up (run seconds per wall second)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the demo plant and twin."),
    port: int = typer.Option(8080, "--port", help="Dashboard port."),
    host: str = typer.Option("127.0.0.1", "--host", help="Dashboard address (beyond loopback needs a control token)."),
    control_token: str = typer.Option(
        None, "--control-token", help="Token that unlocks the controls (or $DRUMTWIN_CONTROL_TOKEN)."
    ),
    scheduler: str = typer.Option(None, "--scheduler", help="Dask scheduler address for what-if studies."),
    estop_needs_token: bool = typer.Option(
        False, "--estop-needs-token", help="EMERGENCY STOP only for viewers with the token (open networks)."
    ),
    json_out: bool = typer.Option(False, "--json", help="Print a JSON summary at the end (stdout)."),
    drive: str = typer.Option(
        None, "--drive", help="Demo only: the mill is this drive profile's emulator over Modbus RTU (e.g. delta-ms300)."
    ),
    objective: str = typer.Option("plateau", "--objective", help="AUTO's objective: plateau, time or energy."),
    target_mi: float = typer.Option(None, "--target-mi", help="Target MI of the endpoint and the objective."),
    stop_at_endpoint: bool = typer.Option(False, "--stop-at-endpoint", help="AUTO stops the mill once mixed."),
    endpoint_band: float = typer.Option(None, "--endpoint-band", help=ENDPOINT_HELP["band"]),
    endpoint_dwell_s: float = typer.Option(None, "--endpoint-dwell-s", help=ENDPOINT_HELP["dwell_s"]),
    endpoint_block_s: float = typer.Option(None, "--endpoint-block-s", help=ENDPOINT_HELP["block_s"]),
    endpoint_block_sd_max: float = typer.Option(None, "--endpoint-block-sd-max", help=ENDPOINT_HELP["block_sd_max"]),
    catalogue: str = typer.Option(None, "--catalogue", help="Run catalogue to index the run in: an SQLite path or "
                                  "postgresql://... (default $DRUMTWIN_CATALOGUE, else catalogue.sqlite beside the run "
                                  "folder)."),
) -> None:
    """Run the live twin: camera -> MI -> trend -> supervisor -> mill, with the twin beside it.

    With no arguments: the embedded demo (hidden plant, emulated mill on a pty, AUTO) and
    the dashboard on http://127.0.0.1:8080.
    """
    from twin.config import RunConfig, check_port_free, endpoint_options

    try:
        cfg = RunConfig(
            camera=camera, video=video, mill=mill, meter_config=config, dashboard=not no_dashboard,
            duration_s=duration, log_dir=log, mode=mode, case=case, speed=speed, seed=seed, port=port,
            host=host, control_token=control_token, scheduler=scheduler, engine=engine,
            estop_needs_token=estop_needs_token, objective=objective, target_mi=target_mi,
            stop_at_endpoint=stop_at_endpoint,
            endpoint=endpoint_options(band=endpoint_band, dwell_s=endpoint_dwell_s, block_s=endpoint_block_s,
                                      block_sd_max=endpoint_block_sd_max),
            drive=None if drive is None else _drive_profile(drive, camera, video, mill),
            catalogue=catalogue,
        ).resolved()
        if cfg.dashboard:  # issue 26: a port in use is refused, not swapped for another
            check_port_free(cfg.host, cfg.port)
        if json_out:
            with stdout_to_stderr():
                summary = _run(cfg, progress=False)
        else:
            summary = _run(cfg, progress=True)
    except OSError as exc:
        if isinstance(exc, (FileNotFoundError, PermissionError, ConnectionError, TimeoutError)):
            raise
        raise TwinError(str(exc)) from None  # one line (twin.cli.main), never wrapped
    _report(summary, json_out)


def _report(summary: Summary, json_out: bool) -> None:
    """The run's end: its summary as JSON (``--json``, stdout) or one line."""
    if json_out:
        print_json({
            "final_trend_mi": summary.final_trend_mi,
            "final_rpm": summary.final_rpm,
            "decisions": summary.decisions,
            "faults": summary.faults,
            "log_dir": summary.log_dir,
            "frames": summary.frames,
            "run_time_s": round(summary.run_time_s, 2),
            "wall_time_s": round(summary.wall_time_s, 2),
            "camera_fps": round(summary.camera_fps, 1),
            "twin_fps": round(summary.twin_fps, 1),
        })
    else:
        say(f"run ended: trend MI {summary.final_trend_mi:.3f}, {summary.final_rpm:.1f} rpm, "
            f"{summary.decisions} decisions, {summary.faults} faults; log in {summary.log_dir}")


@bench_app.command("dashboard")
def bench_dashboard(
    seconds: float = typer.Option(20.0, "--seconds", help="Counting window (s)."),
    warmup: float = typer.Option(15.0, "--warmup", help="Seconds after both images are live before counting."),
    speed: float = typer.Option(1.0, "--speed", help="Demo clock speed."),
    port: int = typer.Option(8079, "--port", help="Dashboard port of the demo started for the bench."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON: camera_hz, twin_hz, seconds."),
) -> None:
    """Image updates/s the dashboard delivers to a real browser while the demo runs.

    Starts `drumtwin run` (the embedded demo) in a subprocess and opens its dashboard in
    headless Debian chromium; needs Playwright (the `test` extra) and /usr/bin/chromium.
    """
    import re
    import subprocess
    import sys
    import tempfile

    from twin.dashboard.ratebench import FIRST_IMAGE_S, LIVE_S, check_bench_args, measure_dashboard_rate

    check_bench_args(seconds, warmup, speed, port)
    budget = warmup + seconds + 2 * FIRST_IMAGE_S + LIVE_S + 30.0  # the demo outlives the browser's waits
    with tempfile.TemporaryDirectory(prefix="drumtwin-bench-dash-") as tmp:
        cmd = [sys.executable, "-c", "from twin.cli import main; main()", "run", "--port", str(port),
               "--speed", str(speed), "--duration", str(budget * speed), "--log", str(Path(tmp) / "run")]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            url = None
            lines: list[str] = []
            with console_err.status("starting the demo ..."):
                assert proc.stderr is not None
                for line in proc.stderr:
                    lines.append(line.strip())
                    m = re.search(r"dashboard on (http://\S+)", line)
                    if m:
                        url = m.group(1)
                        break
            if url is None:
                last = next((s for s in reversed(lines) if s), "no output")
                raise TwinError(f"the demo did not start its dashboard: {last}")
            stderr = proc.stderr
            threading.Thread(target=stderr.read, daemon=True).start()  # keep draining: a full pipe would stall the demo
            with console_err.status(f"counting image updates on {url} ({warmup:g} s warm-up, {seconds:g} s) ..."):
                rate = measure_dashboard_rate(url, seconds=seconds, warmup_s=warmup)
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
    if as_json:
        print_json(rate.as_dict())
    else:
        say(f"dashboard in headless chromium over {rate.seconds:g} s: camera {rate.camera_hz:.1f} updates/s, "
            f"twin {rate.twin_hz:.1f} updates/s (target 10)")


@bench_app.command("memory")
def bench_memory(
    seconds: float = typer.Option(30.0, "--seconds", help="Run time of the measured run (s)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON: main_hwm_mb, tree_rss_mb, tree_pss_mb, ..."),
) -> None:
    """Peak resident memory of `drumtwin run` without the dashboard on a 640x640, 30 fps
    video (the mill emulator on a pty): the run process, and its whole process tree."""
    from rich.table import Table

    from control.errors import check_number
    from twin.cli.app import console
    from twin.membench import measure_run_memory

    check_number("--seconds", seconds, at_least=5.0, at_most=600.0)
    with console_err.status(f"measuring a {seconds:g} s run ..."):
        res = measure_run_memory(seconds)
    if as_json:
        print_json(asdict(res))
        return
    t = Table(title=f"peak memory of `drumtwin run --no-dashboard`, 640x640 video at 30 fps, {seconds:g} s")
    for col in ("run process VmHWM MB", "process tree RSS MB", "process tree PSS MB", "processes"):
        t.add_column(col, justify="right")
    t.add_row(f"{res.main_hwm_mb:.0f}", f"{res.tree_rss_mb:.0f}", f"{res.tree_pss_mb:.0f}", str(res.processes))
    console.print(t)

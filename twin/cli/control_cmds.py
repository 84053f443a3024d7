"""Commands of the control package: ``mill``, ``mill-emulator``, ``bench trend``."""

from __future__ import annotations

import signal
import threading
import time
from typing import TYPE_CHECKING

import typer
from rich.progress import Progress
from rich.table import Table

from control.device import DeviceConfig
from control.driver import MillClient
from control.emulator import Faults, MillEmulator
from control.errors import ControlError, check_number
from control.motor import MotorConfig
from control.protocol import MillStatus
from twin.cli.app import app, bench_app, console, console_err, print_json

if TYPE_CHECKING:  # the trend bench pulls in filterpy (slow import): loaded by its command only
    from control.trendbench import SequenceSource, TrendBenchResult

mill_app = typer.Typer(
    help="Talk to the mill's motor board (commissioning): status, set-rpm, start, stop.",
    no_args_is_help=True,
)
app.add_typer(mill_app, name="mill")

JSON_OPT = typer.Option(False, "--json", help="Print one JSON object on stdout.")


@mill_app.callback()
def _mill(
    ctx: typer.Context,
    url: str = typer.Argument(..., help="Port or URL: /dev/ttyUSB0, a pty path, socket://host:port, rfc2217://host:port."),
    timeout_s: float = typer.Option(0.3, "--timeout", help="Per-attempt reply timeout (s)."),
    retries: int = typer.Option(5, "--retries", help="Resends after the first attempt."),
) -> None:
    check_number("--timeout", timeout_s, above=0.0, at_most=60.0)
    if not 0 <= retries <= 100:
        raise ControlError(f"--retries must be an integer in 0..100 (got {retries})")
    ctx.obj = {"url": url, "timeout_s": timeout_s, "retries": retries}


def _client(ctx: typer.Context) -> MillClient:
    o = ctx.obj
    return MillClient(o["url"], timeout_s=o["timeout_s"], retries=o["retries"], heartbeat_s=None)


HOLD_OPT = typer.Option(
    0.0, "--hold", help="Keep the link alive (heartbeat) this many seconds, printing the status; "
    "afterwards the board's watchdog stops the motor."
)


def _check_hold(hold_s: float) -> float:
    return check_number("--hold", hold_s, at_least=0.0, at_most=86400.0)


def _hold(c: MillClient, hold_s: float, as_json: bool) -> None:
    if hold_s <= 0:
        return
    t_end = time.monotonic() + hold_s
    while time.monotonic() < t_end:
        st = c.heartbeat()
        if not as_json:
            console_err.print(f"actual {st.actual_rpm:6.2f} rpm (setpoint {st.setpoint_rpm:.2f})", highlight=False)
        time.sleep(min(0.25, max(0.0, t_end - time.monotonic())))


def _report(status: MillStatus, as_json: bool, what: str = "") -> None:
    if as_json:
        d = status.as_dict()
        if what:
            d["ok"] = what
        print_json(d)
        return
    if what:
        console.print(f"[green]ok[/] {what}")
    console.print(
        f"setpoint {status.setpoint_rpm:.2f} rpm  actual {status.actual_rpm:.2f} rpm  "
        f"{'running' if status.running else 'stopped'}  fault {status.fault or 'none'}",
        highlight=False,
    )


@mill_app.command("status")
def mill_status(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Read setpoint, actual rpm, running, fault."""
    with _client(ctx) as c:
        _report(c.status(), as_json)


@mill_app.command("set-rpm")
def mill_set_rpm(
    ctx: typer.Context,
    rpm: float = typer.Argument(..., help="Absolute setpoint (rpm)."),
    as_json: bool = JSON_OPT,
    hold_s: float = HOLD_OPT,
    commission: bool = typer.Option(
        False, "--commission", help="Commissioning override: allow an rpm outside the run's limits (logged)."
    ),
) -> None:
    """Set the speed setpoint (rpm), inside the run's limits (the demo drum's: the same
    limits the supervisor enforces) unless --commission is given."""
    from twin.config import RunConfig
    from twin.loop import supervisor_config

    check_number("rpm", rpm, at_least=0.0)
    limits = supervisor_config(RunConfig()).limits  # the one set of limits (control.limits)
    if not commission:
        limits.refuse_rpm(rpm, "set-rpm")  # ControlError: one line naming the limit, exit 2
    elif limits.check_rpm(rpm).clamped and rpm != 0:
        import logging

        msg = f"commissioning override: set-rpm {rpm:g} outside the limits {limits.describe()}"
        logging.getLogger("drumtwin.mill").warning(msg)
        console_err.print(f"[bold yellow]warning:[/] {msg}", highlight=False)
    _check_hold(hold_s)
    with _client(ctx) as c:
        c.set_rpm(rpm)
        _hold(c, hold_s, as_json)
        _report(c.status(), as_json, f"set-rpm {rpm:g}")


@mill_app.command("start")
def mill_start(ctx: typer.Context, as_json: bool = JSON_OPT, hold_s: float = HOLD_OPT) -> None:
    """Start the motor (clears a watchdog fault). Without --hold the board's watchdog
    stops it again once the host is silent (see docs/mill-protocol.md)."""
    _check_hold(hold_s)
    with _client(ctx) as c:
        c.start()
        _hold(c, hold_s, as_json)
        _report(c.status(), as_json, "start")


@mill_app.command("stop")
def mill_stop(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Stop the motor."""
    with _client(ctx) as c:
        c.stop()
        _report(c.status(), as_json, "stop")


@app.command("mill-emulator")
def mill_emulator(
    pty: bool = typer.Option(False, "--pty", help="Serve on a pseudo-terminal (default)."),
    tcp: int | None = typer.Option(None, "--tcp", help="Serve on this TCP port instead (0: any free port)."),
    host: str = typer.Option("127.0.0.1", "--host", help="TCP address to listen on."),
    link: str | None = typer.Option(None, "--link", help="Path of the stable symlink to the pty slave."),
    faults: str = typer.Option("", "--faults", help="e.g. 'corrupt=0.05,drop=0.01,delay=0.02,disconnect=10:1'."),
    watchdog_s: float = typer.Option(
        1.0, "--watchdog", help="Stop the motor after this long without HB/SET/RUN/STP (s; 0 disables it)."
    ),
    max_rpm: float = typer.Option(60.0, "--max-rpm", help="Top speed of the drive (rpm)."),
    accel: float = typer.Option(10.0, "--accel", help="Acceleration limit (rpm/s)."),
    tau_s: float = typer.Option(0.5, "--tau", help="Speed-loop time constant (s)."),
    duration_s: float | None = typer.Option(None, "--duration", help="Exit after this many seconds (default: Ctrl-C)."),
    seed: int | None = typer.Option(None, "--seed", help="Seed of the fault injection."),
) -> None:
    """Run the motor-board emulator on a pty (prints its path) or a TCP port."""
    if pty and tcp is not None:
        raise ControlError("choose one of --pty and --tcp")
    if tcp is not None and not 0 <= tcp <= 65535:
        raise ControlError(f"--tcp must be a port in 0..65535 (0: any free port), got {tcp}")
    check_number("--watchdog", watchdog_s, at_least=0.0, at_most=3600.0)
    check_number("--max-rpm", max_rpm, above=0.0, at_most=1000.0)
    check_number("--accel", accel, above=0.0, at_most=1e4)
    check_number("--tau", tau_s, at_least=0.0, at_most=60.0)
    if duration_s is not None:
        check_number("--duration", duration_s, above=0.0, at_most=30 * 86400.0)  # 1e308 would never end
    cfg = DeviceConfig(watchdog_s=watchdog_s, motor=MotorConfig(max_rpm=max_rpm, accel_rpm_per_s=accel, tau_s=tau_s))
    emu = MillEmulator(cfg, Faults.parse(faults), seed=seed)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())  # before the path is printed: clean exit
    try:
        if tcp is not None:
            emu.open_tcp(tcp, host)
        else:
            emu.open_pty(link)
        print(emu.url, flush=True)
        console_err.print(f"mill emulator on {emu.url} (watchdog {watchdog_s:g} s); Ctrl-C to stop", highlight=False)
        t_end = None if duration_s is None else time.monotonic() + duration_s
        last = None
        try:
            while not done.is_set() and (t_end is None or time.monotonic() < t_end):
                st = emu.status()
                line = (round(st.setpoint_rpm, 1), round(st.actual_rpm, 1), st.running, st.fault)
                if line != last:
                    console_err.print(
                        f"setpoint {st.setpoint_rpm:6.2f}  actual {st.actual_rpm:6.2f} rpm  "
                        f"{'running' if st.running else 'stopped'}  fault {st.fault or 'none'}",
                        highlight=False,
                    )
                    last = line
                done.wait(0.5)
        except KeyboardInterrupt:
            pass
    finally:
        emu.close()


TREND_SOURCES: dict[str, SequenceSource] = {}
"""Extra MI sequence sources for ``bench trend --source NAME`` (seed -> TrendSequence), e.g. a
twin-generated one (truth = particle MI, measured = vision MI of rendered frames).
``synthetic`` is built in (truth + noise + rotation ripple + outliers + dropouts)."""


@bench_app.command("trend")
def bench_trend(
    as_json: bool = JSON_OPT,
    source: str = typer.Option(
        "synthetic", "--source", help="Sequence source: synthetic, or one registered in TREND_SOURCES."
    ),
    sequences: int = typer.Option(8, "--sequences", help="Number of synthetic sequences (seeds 0..N-1)."),
    fps: float = typer.Option(30.0, "--fps", help="Frame rate of the MI stream."),
    noise_sd: float = typer.Option(0.04, "--noise", help="Measurement noise sd (MI)."),
    ripple: float = typer.Option(0.05, "--ripple", help="Rotation ripple amplitude (MI)."),
    window: int = typer.Option(150, "--window", help="Moving-average window (samples; the paper uses 150)."),
) -> None:
    """Kalman MI trend vs the paper's 150-sample moving average: RMSE and step lag."""
    from control.trendbench import run_trend_bench, synthetic_sequence

    if sequences < 1 or window < 1:
        raise ControlError("--sequences and --window must be >= 1")
    check_number("--fps", fps, above=0.0, at_most=10000.0)
    check_number("--noise", noise_sd, at_least=0.0, at_most=1.0)
    check_number("--ripple", ripple, at_least=0.0, at_most=1.0)
    if source == "synthetic":
        make: SequenceSource = lambda i: synthetic_sequence(i, fps=fps, noise_sd=noise_sd, ripple_amp=ripple)  # noqa: E731
    elif source in TREND_SOURCES:
        make = TREND_SOURCES[source]
    else:
        raise ControlError(f"unknown trend source {source!r} (known: {', '.join(['synthetic', *TREND_SOURCES])})")
    with Progress(console=console_err, transient=True) as prog:
        task = prog.add_task(f"trend sequences ({source})", total=sequences)
        res = run_trend_bench(
            (make(i) for i in range(sequences)),
            ma_window=window,
            progress=lambda i: prog.update(task, completed=i),
        )
    print_trend_result(res, as_json)


@bench_app.command("link")
def bench_link(
    as_json: bool = JSON_OPT,
    requests: int = typer.Option(500, "--requests", help="Status requests per transport."),
) -> None:
    """Round trip of the real serial driver to the emulator over a pty and over TCP."""
    from control.linkbench import run_link_bench

    if not 1 <= requests <= 1_000_000:
        raise ControlError(f"--requests must be in 1..1000000 (got {requests})")
    with console_err.status("timing the link ...") as st:
        res = run_link_bench(requests, progress=lambda s: st.update(f"timing the link: {s}"))
    if as_json:
        print_json({f"{r.transport}_{k}": v for r in res
                    for k, v in (("median_ms", r.median_ms), ("p99_ms", r.p99_ms), ("resends", r.resends))})
        return
    t = Table(title=f"serial link: driver <-> emulator, {requests} STATUS requests each")
    for col in ("transport", "median ms", "p99 ms", "max ms", "requests/s", "resends"):
        t.add_column(col, justify="left" if col == "transport" else "right")
    for r in res:
        t.add_row(r.transport, f"{r.median_ms:.3f}", f"{r.p99_ms:.3f}", f"{r.max_ms:.3f}",
                  f"{r.requests_per_s:,.0f}", str(r.resends))
    console.print(t)


def print_trend_result(res: TrendBenchResult, as_json: bool) -> None:
    """Print a trend benchmark result as a table or one JSON object (reused by twin)."""
    if as_json:
        print_json(res.as_dict())
        return
    t = Table(title=f"MI trend: Kalman vs {res.ma_window}-sample moving average ({len(res.per_sequence)} sequences)")
    t.add_column("filter")
    t.add_column("RMSE vs truth (MI)", justify="right")
    t.add_column("lag after step, 63 % (s)", justify="right")
    t.add_row("Kalman", f"{res.kalman_rmse:.4f}", f"{res.kalman_lag_s:.2f}")
    t.add_row(f"moving average ({res.ma_window})", f"{res.ma_rmse:.4f}", f"{res.ma_lag_s:.2f}")
    console.print(t)

"""Commands of the control package: ``mill``, ``bench trend``, ``bench link`` (``mill-emulator``
lives in ``twin.cli.emulator_cmds``, registered from here)."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import typer
from rich.progress import Progress
from rich.table import Table

from control.driver import MillClient
from control.errors import ControlError, check_number
from control.modbus.link import ModbusMill, is_modbus_url, parse_modbus_url
from control.protocol import MillStatus
from twin.cli.app import app, bench_app, console, console_err, print_json, say
from twin.config import load_checked_config

if TYPE_CHECKING:  # the trend bench: loaded by its command only
    from control.limits import Limits
    from control.trendbench import RealFrameMI, SequenceSource, TrendBenchResult

mill_app = typer.Typer(
    help="Talk to the mill's motor board (commissioning): status, set-rpm, start, stop.",
    no_args_is_help=True,
)
app.add_typer(mill_app, name="mill")

JSON_OPT = typer.Option(False, "--json", help="Print one JSON object on stdout.")


@mill_app.callback()
def _mill(
    ctx: typer.Context,
    url: str = typer.Argument(
        ..., help="Port or URL: /dev/ttyUSB0, a pty path, socket://host:port, rfc2217://host:port; "
        "a drive: modbus:PORT?profile=NAME&unit=1 (docs/drives.md)."
    ),
    timeout_s: float = typer.Option(0.3, "--timeout", help="Per-attempt reply timeout (s)."),
    retries: int = typer.Option(5, "--retries", help="Resends after the first attempt."),
    config: Path | None = typer.Option(
        None, "--config", help="The mixer's TOML: set-rpm's limits come from its \\[drum]'s critical speed and a "
        "drive's hz_per_rpm from its \\[drive], as in `drumtwin run --config` (default: the demo's drum)."
    ),
) -> None:
    check_number("--timeout", timeout_s, above=0.0, at_most=60.0)
    if not 0 <= retries <= 100:
        raise ControlError(f"--retries must be an integer in 0..100 (got {retries})")
    limits = None
    if config is not None:  # a given config is read (and refused when bad) whatever the subcommand
        from control.modbus.link import config_mill_url

        checked = load_checked_config(config)
        url = config_mill_url(url, checked.meter.drive_table, f"config {checked.meter.source}")
        limits = mill_limits(checked.mixer.drum.critical_rpm)
    ctx.obj = {"url": url, "timeout_s": timeout_s, "retries": retries, "limits": limits}


def mill_limits(critical_rpm: float | None) -> Limits:
    """The limits ``drumtwin run --config CONFIG`` enforces: the supervisor's rpm range with the
    critical speed of the config's drum (``critical_rpm``; None: the demo's drum)."""
    from twin.run.settings import supervisor_config

    return supervisor_config().limits if critical_rpm is None else supervisor_config(None, critical_rpm).limits


def _client(ctx: typer.Context) -> MillClient | ModbusMill:
    """The link of a ``mill`` command. A drive is not refused as a whole when its comm-loss
    trip is unsafe: ``stop`` and ``status`` always go to it, ``start`` and a faster
    ``set-rpm`` are refused with the reason (``SafetyRefused``, exit 2)."""
    o = ctx.obj
    if is_modbus_url(o["url"]):
        return ModbusMill(o["url"], timeout_s=o["timeout_s"], retries=o["retries"], refuse_unsafe=False)
    return MillClient(o["url"], timeout_s=o["timeout_s"], retries=o["retries"], heartbeat_s=None)


HOLD_OPT = typer.Option(
    0.0, "--hold", help="Keep the link alive (heartbeat) this many seconds, printing the status; "
    "afterwards the board's watchdog stops the motor."
)


def _check_hold(hold_s: float) -> float:
    return check_number("--hold", hold_s, at_least=0.0, at_most=86400.0)


def _hold(c: MillClient | ModbusMill, hold_s: float, as_json: bool) -> None:
    if hold_s <= 0:
        return
    t_end = time.monotonic() + hold_s
    while time.monotonic() < t_end:
        st = c.heartbeat()
        if not as_json:
            say(f"actual {st.actual_rpm:6.2f} rpm (setpoint {st.setpoint_rpm:.2f})")
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
    """Set the speed setpoint (rpm), inside the run's limits (the drum of `mill --config`,
    else the demo's: the limits the supervisor enforces) unless --commission is given."""
    check_number("rpm", rpm, at_least=0.0)
    limits = ctx.obj["limits"] or mill_limits(None)  # the one set of limits (control.limits)
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


@mill_app.command("check")
def mill_check(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """A drive (modbus: URL): print its identity and comm-loss parameters and what to change.
    Exit 2 when its comm-loss trip would refuse a run (reads only: never counts as control)."""
    url = ctx.obj["url"]
    if not is_modbus_url(url):
        raise ControlError("check reads a drive's parameters: give a modbus: URL (modbus:PORT?profile=NAME)")
    spec = parse_modbus_url(url)
    mill = ModbusMill(url, timeout_s=ctx.obj["timeout_s"], retries=ctx.obj["retries"], refuse_unsafe=False)
    with mill:  # reads only: the problem is reported, not refused
        ident = mill.read_identity()
        why = mill.comm_loss_check()
        setting = mill.comm_loss  # None: the parameters could not be read
        st = mill.status()
    p = mill.profile
    if as_json:
        print_json({"profile": p.name, "unit": spec.unit, "identity": ident,
                    "comm_loss_s": setting.time_s if setting else None,
                    "comm_loss_action": setting.action if setting else None, "safe": why is None, "change": why,
                    **st.as_dict()})
    else:
        console.print(f"{p.title} (profile {p.name}), unit {spec.unit}", highlight=False)
        for name, v in ident.items():
            console.print(f"  {name}: {v} (0x{v:04X})", highlight=False)
        cl = p.comm_loss
        if setting is not None:
            console.print(f"  comm-loss trip {cl.time_parameter}: {setting.time_s:g} s; action"
                          f" {cl.action_parameter or '(fixed)'}: {setting.action}", highlight=False)
        console.print(f"  hz_per_rpm {mill.hz_per_rpm:g}, max {mill.max_hz:g} Hz"
                      f" = {mill.max_hz / mill.hz_per_rpm:.2f} drum rpm", highlight=False)
        _report(st, False)
        if why is None:
            console.print(f"[green]ok[/] the drive trips within {spec.comm_loss_limit_s:g} s of comm loss",
                          highlight=False)
        else:
            console.print(f"[bold red]change:[/] {why}", highlight=False)
    if why is not None:
        raise typer.Exit(2)


TREND_SOURCES: dict[str, SequenceSource] = {}
"""Extra MI sequence sources for ``bench trend --source NAME`` (seed -> TrendSequence), for
applications and tests. Built in: ``synthetic`` (control.trendbench.synthetic_sequence: a
noise model -- exponential step, white noise, rotation ripple, outliers, dropouts); the real
bench (sequences of the real frames' MI, control.trendbench.real_sequences) always runs beside it."""

REAL_FRAMES = Path(__file__).resolve().parents[2] / "tests" / "data" / "real-drum-pmma" / "images"
"""The real PMMA frames that ship with the repository (CC BY 4.0, see its README)."""

BLEND_PARTNERS = 4  # mixed frames blended with the segregated one (drift and segregated pools)
SEGREGATED_BLENDS = (0.05, 0.1)  # mixed share of the segregated pool's near-copies
DRIFT_BLENDS = tuple(round(0.15 + 0.05 * i, 2) for i in range(12))  # 0.15 ... 0.7: the drift's levels
OCCLUDER_AT = ((0.0, 0.0), (-0.25, 0.0), (0.25, 0.0), (0.0, -0.25), (0.0, 0.25))
"""Centres of the dark object of the occluded bursts: the bed's centroid plus these offsets (drum radii)."""


def real_frame_mi(images: Path = REAL_FRAMES, config: Path | None = None) -> RealFrameMI:
    """Measure a folder of real frames once (``config``: a meter TOML; None: classes learned
    from the frames, as ``classes suggest`` does) and sort their MI into the real bench's
    pools: the lowest-MI frame is the segregated one, frames more than 0.05 below the median
    are the mix in progress (only in the looped sequence), the rest are mixed; the drift
    and the segregated pool's near-copies are blends (cv2.addWeighted) of the segregated
    frame with the first ``BLEND_PARTNERS`` mixed frames; the occluded pools are the mixed frames
    with a near-black disc of a third of the drum's area over the bed (centred on the bed's
    centroid plus each of ``OCCLUDER_AT``), the frames the meter flags left out."""
    import cv2

    from control.trendbench import RealFrameMI
    from vision.errors import VisionError
    from vision.sources import open_source
    from vision.suggest import suggest_classes

    try:
        frames = {Path(str(fr.name)).stem: fr.image for fr in open_source(images)}
    except (VisionError, OSError) as exc:
        raise ControlError(f"cannot read the real frames in {images}: {exc} (use --frames DIR)") from None
    if len(frames) < 3:
        raise ControlError(f"the real trend bench needs at least 3 frames in {images}, found {len(frames)}")
    cfg = load_checked_config(config).meter if config is not None else suggest_classes(list(frames.values()))
    # the frames are as shot and their blends are no change of light (but mixed colours no gain maps back):
    # the trend bench measures them in the set-up's light, without tracking it
    meter = replace(cfg, light_reference=None, light_reference_classes=None).make_meter()

    def mi(img: np.ndarray, what: str) -> float:
        r = meter.measure(img)
        if not (r.valid and math.isfinite(r.mi)):
            raise ControlError(f"no valid MI in {what} ({', '.join(r.flags)}): not a frame for the trend bench")
        return float(r.mi)

    names = sorted(frames)
    raw = {n: mi(frames[n], f"frame {n}") for n in names}
    seg = min(raw, key=lambda n: raw[n])
    med = float(np.median(list(raw.values())))
    mixed = [n for n in names if n != seg and raw[n] >= med - 0.05]
    partners = [frames[n] for n in mixed[:BLEND_PARTNERS]]

    def blends(alpha: float) -> tuple[float, ...]:
        return tuple(mi(cv2.addWeighted(frames[seg], 1.0 - alpha, p, alpha, 0.0), f"a blend of {seg}")
                     for p in partners)

    def occluded(at: tuple[float, float]) -> tuple[float, ...]:
        out = []
        for n in mixed:
            r = meter.measure(frames[n])
            if r.roi is None:  # (a valid reading, as the mixed frames' are, has its drum)
                continue
            n_px = sum(c.n_px for c in r.classes)
            bed = (sum(c.cx_px * c.n_px for c in r.classes) / n_px, sum(c.cy_px * c.n_px for c in r.classes) / n_px)
            img = frames[n].copy()
            centre = (round(bed[0] + at[0] * r.roi.r_px), round(bed[1] + at[1] * r.roi.r_px))
            cv2.circle(img, centre, round(r.roi.r_px / math.sqrt(3.0)), (20, 20, 20), -1)
            o = meter.measure(img)
            if o.valid and math.isfinite(o.mi):
                out.append(float(o.mi))
        return tuple(out)

    return RealFrameMI(
        segregated=(raw[seg], *(v for a in SEGREGATED_BLENDS for v in blends(a))),
        mixed=tuple(raw[n] for n in mixed),
        looped=tuple(raw[n] for n in names),
        drift=tuple(blends(a) for a in DRIFT_BLENDS),
        occluded=tuple(p for p in (occluded(at) for at in OCCLUDER_AT) if p),
    )


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
    frames: Path = typer.Option(REAL_FRAMES, "--frames", help="Folder of real frames for the real bench."),
    config: Path | None = typer.Option(
        None, "--config", help="Meter TOML for the real frames (default: classes learned from them)."
    ),
    real_seeds: int = typer.Option(2, "--real-seeds", help="Draws of the real sequences (0: no real bench)."),
) -> None:
    """Kalman MI trend vs the paper's 150-sample moving average, on synthetic MI and on
    sequences of the real frames' MI: RMSE, lags, overshoot, lock-out, band coverage."""
    from control.trendbench import real_sequences, run_trend_bench, synthetic_sequence

    if not (1 <= sequences <= 10_000 and 1 <= window <= 100_000):
        raise ControlError(f"--sequences must be in 1..10000 and --window in 1..100000 (got {sequences}, {window})")
    if not 0 <= real_seeds <= 100:
        raise ControlError(f"--real-seeds must be in 0..100 (got {real_seeds})")
    check_number("--fps", fps, above=0.0, at_most=10000.0)
    check_number("--noise", noise_sd, at_least=0.0, at_most=1.0)
    check_number("--ripple", ripple, at_least=0.0, at_most=1.0)
    if config is not None and real_seeds:  # refused now, not after the synthetic sequences
        load_checked_config(config)
    if source == "synthetic":
        make: SequenceSource = lambda i: synthetic_sequence(i, fps=fps, noise_sd=noise_sd, ripple_amp=ripple)  # noqa: E731
    elif source in TREND_SOURCES:
        make = TREND_SOURCES[source]
    else:
        raise ControlError(f"unknown trend source {source!r} (known: {', '.join(['synthetic', *TREND_SOURCES])})")
    results = []
    with Progress(console=console_err, transient=True) as prog:
        task = prog.add_task(f"trend sequences ({source})", total=sequences)
        results.append(run_trend_bench(
            (make(i) for i in range(sequences)),
            ma_window=window,
            progress=lambda i: prog.update(task, completed=i),
            name=source,
        ))
        if real_seeds:
            prog.update(task, description="measuring the real frames")
            mi = real_frame_mi(frames, config)
            real = [s for seed in range(real_seeds) for s in real_sequences(mi, seed, fps=fps)]
            task = prog.add_task("trend sequences (real frames)", total=len(real))
            results.append(run_trend_bench(
                real, ma_window=window, progress=lambda i: prog.update(task, completed=i), name="real"
            ))
    print_trend_results(results, as_json)


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


def print_trend_results(results: list[TrendBenchResult], as_json: bool) -> None:
    """Print trend benchmark results as tables or one JSON object ``{name: metrics}``."""
    if as_json:
        print_json({r.name: r.as_dict() for r in results})
        return
    for res in results:
        t = Table(title=f"MI trend ({res.name}): Kalman vs {res.ma_window}-sample moving average "
                        f"({len(res.per_sequence)} sequences)")
        for col in ("filter", "RMSE (MI)", "lag 63 % (s)", "lag to 0.05 (s)", "overshoot (MI)",
                    "longest lock-out (s)", "min..max", "95 % band covers"):
            t.add_column(col, justify="left" if col == "filter" else "right")
        for label, f in (("Kalman", res.kalman), (f"moving average ({res.ma_window})", res.ma)):
            cover = "-" if math.isnan(f.coverage) else f"{100 * f.coverage:.1f} %"
            t.add_row(label, f"{f.rmse:.4f}", f"{f.lag_s:.2f}", f"{f.lag05_s:.2f}", f"{f.overshoot:.3f}",
                      f"{f.lockout_s:.2f}", f"{f.min:.3f}..{f.max:.3f}", cover)
        console.print(t)
        if res.name == "real":
            p = Table(title="real frames, per sequence (Kalman / moving average)")
            for col in ("sequence", "RMSE", "lock-out (s)", "band covers"):
                p.add_column(col, justify="left" if col == "sequence" else "right")
            for s in res.per_sequence:
                p.add_row(s.name, f"{s.kalman.rmse:.4f} / {s.ma.rmse:.4f}",
                          f"{s.kalman.lockout_s:.2f} / {s.ma.lockout_s:.2f}", f"{100 * s.kalman.coverage:.1f} %")
            console.print(p)


from twin.cli import emulator_cmds  # noqa: E402,F401  (registers mill-emulator after mill, as before)

"""``drumtwin sim``, ``drumtwin calibrate``, ``drumtwin whatif`` and ``drumtwin bench twin``."""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import typer

from control.limits import WHATIF_MAX_S as MAX_SIM_S  # and the longest simulated run of one command, s
from sim.errors import SimError
from twin.cli.app import app, bench_app, check_outputs, console, console_err, print_json, say

SIM_COLUMNS = ("t_s", "rpm", "mi", "mi_sigmoid", "mi_linear", "mi_particles", "mi_sigmoid_particles", "slope_deg",
               "slope_deg_particles", "valid")


def _progress():
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=console_err, transient=True)


def _parse_list(text: str, what: str) -> list[float]:
    try:
        vals = [float(v) for v in str(text).replace(" ", "").split(",")] if str(text).strip() else []
    except ValueError:
        raise SimError(f"{what} must be a comma-separated list of numbers (got {text!r})") from None
    if not vals:
        raise SimError(f"{what} is empty")
    return vals


MAX_SEEDS = 1000
SLOPE_AFTER_S = 5.0  # ``slope_deg`` averages the free surface after this start-up


def _check_seed(seed: int) -> int:
    from sim.errors import check_seed

    return check_seed("--seed", seed)


CONFIG_HELP = "TOML with the colour classes and the mixer (\\[drum], [\\[particles]]; default: the paper's drum)"
ENGINE_HELP = "twin engine: dem (discs in a plain drum) or pymunk (any shape, baffles); default: the mixer's"


@app.command("sim")
def sim_cmd(
    case: str = typer.Option("C", "--case", help="initial state: A (left/right), B (top/bottom), C (random)"),
    rpm: float = typer.Option(5.0, "--rpm", help="drum speed, rpm"),
    duration: float = typer.Option(60.0, "--duration", help=f"simulated seconds (at most {MAX_SIM_S:g})"),
    seed: int = typer.Option(0, "--seed", help="0 <= seed < 2**32"),
    fps: float = typer.Option(10.0, "--fps", help="frames rendered and measured per simulated second"),
    size: int = typer.Option(480, "--size", help="rendered frame size, px"),
    csv_out: Path | None = typer.Option(None, "--csv", help="write the MI curve here"),
    video: Path | None = typer.Option(None, "--video", help="write the rendered frames as MP4"),
    realism: bool = typer.Option(False, "--realism", help="camera noise, blur, glare, drift, JPEG, drops"),
    friction: float | None = typer.Option(None, "--friction", help="sliding friction (paper: 0.25)"),
    rolling: float | None = typer.Option(None, "--rolling", help="rolling friction (paper: 0.1)"),
    end_friction: float | None = typer.Option(None, "--end-friction",
                                              help="friction of the drum's end plates (default: the wall's; 0: none)"),
    dt_ms: float | None = typer.Option(None, "--dt-ms", help="internal time step, ms (default: the converged step)"),
    config: Path | None = typer.Option(None, "--config", help=CONFIG_HELP),
    engine: str | None = typer.Option(None, "--engine", help=ENGINE_HELP),
    as_json: bool = typer.Option(False, "--json", help="print a JSON summary to stdout"),
) -> None:
    """Run the twin and measure MI over time (vision meter on rendered frames + particle level)."""
    from sim.capacity import twin_particles
    from sim.engine import make_twin
    from sim.measure import twin_meter
    from sim.render import Realism, Renderer
    from twin.config import load_checked_config

    kw = _sim_options(duration, fps, size, friction, rolling, dt_ms, end_friction)
    seed = _check_seed(seed)
    checked = load_checked_config(config, engine=engine)
    with _progress() as prog:  # the twin is built (placed and settled) under its own line
        task = prog.add_task(f"sim: building the twin ({twin_particles(checked.mixer)} particles)", total=None)
        sim: Any = make_twin(checked.mixer, engine, case=case, seed=seed, rpm=rpm, **kw)
        renderer = Renderer(sim.drum, size, realism=Realism(seed=seed) if realism else None)
        meter = checked.meter.make_meter(roi=renderer.roi) if checked.has_mixer else twin_meter(renderer)
        rows, curv, air = _sim_rows(sim, renderer, meter, duration, fps, video, lambda n: prog.update(
            task, description="sim", total=n, completed=0), lambda: prog.advance(task))
    if csv_out is not None:
        csv_out.parent.mkdir(parents=True, exist_ok=True)
        with open(csv_out, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=SIM_COLUMNS)
            w.writeheader()
            w.writerows(rows)
    summary = {"case": sim.case, "rpm": rpm, "duration_s": duration, "seed": seed, "frames": len(rows),
               "engine": checked.engine, "config": str(config) if config else None,
               **_sim_summary(sim, rows, curv, air, rpm, duration),
               "csv": str(csv_out) if csv_out else None, "video": str(video) if video else None}
    if as_json:
        print_json(summary)
    else:
        console.print(
            f"case {sim.case} at {rpm:g} rpm for {duration:g} s: MI {summary['mi_start']:.3f} -> "
            f"{summary['mi_end']:.3f} (particles {summary['mi_particles_start']:.3f} -> "
            f"{summary['mi_particles_end']:.3f}), slope {summary['slope_deg']:.1f} deg, "
            f"{summary['regime']} (Fr {summary['froude']:.3f}); step {summary['dt_ms']:g} ms, "
            f"overlap p99 {summary['overlap_p99_r']:.3f} r, wall {summary['wall_max_mm']:.2f} mm"
        )


def _sim_options(duration: float, fps: float, size: int, friction: float | None, rolling: float | None,
                 dt_ms: float | None, end_friction: float | None) -> dict[str, float]:
    """``drumtwin sim``'s numbers checked (one-line ``SimError``s); the twin's keyword arguments."""
    from sim.errors import check_number

    check_number("--duration", duration, 0.0, MAX_SIM_S, lo_open=True)
    check_number("--fps", fps, 0.0, 240.0, lo_open=True)
    check_number("--size", size, 32, 4096, integer=True)
    kw: dict[str, float] = {}
    if friction is not None:
        kw["friction"] = check_number("--friction", friction, 0.0, 5.0)
    if rolling is not None:
        kw["rolling"] = check_number("--rolling", rolling, 0.0, 5.0)
    kw.update(_step_options(dt_ms, end_friction))
    return kw


def _sim_rows(sim: Any, renderer: Any, meter: Any, duration: float, fps: float, video: Path | None,
              start: Callable[[int], None], advance: Callable[[], None]) -> tuple[list[dict], list[float], list[float]]:
    """The twin run for ``duration`` s, rendered and measured ``fps`` times per simulated second (and at
    the start): one ``SIM_COLUMNS`` row per frame, the free surface's curvature and the airborne share
    per frame; the frames written to ``video`` (MP4) when given. ``start(frames)``, ``advance()``: progress."""
    import cv2

    from sim.probe import probe

    writer = None
    if video is not None:
        video.parent.mkdir(parents=True, exist_ok=True)
        writer = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"mp4v"), float(min(fps, 60.0)),
                                 (renderer.width_px, renderer.height_px))
        if not writer.isOpened():
            raise SimError(f"cannot write video {video}")
    n = max(1, int(round(duration * fps)))
    start(n + 1)
    rows, curv, air = [], [], []
    last = None
    nan = float("nan")
    try:
        for i, smp in enumerate(probe(sim, duration, duration / n)):
            frame = renderer.render(smp.particles, smp.sim_t_s)
            curv.append(smp.surface.curvature)
            air.append(smp.airborne if i > 0 else nan)
            rd = meter.measure(frame) if frame is not None else None  # None: a dropped frame
            last = frame if frame is not None else last
            if writer is not None and last is not None:
                writer.write(last)
            rows.append({
                "t_s": round(smp.sim_t_s, 6), "rpm": smp.rpm_actual, "mi": rd.mi if rd else nan,
                "mi_sigmoid": rd.mi_sigmoid if rd else nan, "mi_linear": rd.mi_linear if rd else nan,
                "mi_particles": smp.mi.mi, "mi_sigmoid_particles": smp.mi.mi_sigmoid,
                "slope_deg": rd.slope_deg if rd else nan, "slope_deg_particles": smp.surface.slope_deg,
                "valid": int(bool(rd.valid)) if rd else 0,
            })
            advance()
    finally:
        if writer is not None:
            writer.release()
    return rows, curv, air


def _finite_mean(a: Any) -> float:
    f = np.asarray(a, float)
    f = f[np.isfinite(f)]
    return float(f.mean()) if f.size else float("nan")


def _sim_summary(sim: Any, rows: list[dict], curv: list[float], air: list[float], rpm: float,
                 duration: float) -> dict[str, Any]:
    """``drumtwin sim``'s numbers of a run: MI at the start and the end (the last 10 % of the frames),
    the slope after ``SLOPE_AFTER_S`` (or half the run), the flow regime of its last third, the step and
    the contact statistics."""
    from sim.whatif import flow_regime, froude, froude_regime

    col = {k: np.array([r[k] for r in rows], float) for k in SIM_COLUMNS}
    end = {k: _finite_mean(col[k][-max(1, int(round(0.1 * len(rows)))):]) for k in SIM_COLUMNS}  # the last 10 %
    mi_valid = col["mi"][np.isfinite(col["mi"])]
    third = max(1, len(rows) // 3)
    late = col["t_s"] >= min(SLOPE_AFTER_S, 0.5 * duration)
    st = sim.stats()
    air_m, curv_m = _finite_mean(air[-third:]), _finite_mean(curv[-third:])
    return {
        "dt_ms": sim.substep_s() * 1e3, "default_dt_ms": _default_dt_ms(sim),
        "friction": sim.params.friction, "rolling": sim.params.rolling, "end_friction": sim.params.end_mu,
        "mi_start": float(mi_valid[0]) if mi_valid.size else float("nan"), "mi_end": end["mi"],
        "mi_sigmoid_end": end["mi_sigmoid"], "mi_linear_end": end["mi_linear"],
        "mi_particles_start": float(col["mi_particles"][0]), "mi_particles_end": end["mi_particles"],
        "slope_deg": _finite_mean(col["slope_deg_particles"][late]),
        "slope_deg_vision": _finite_mean(col["slope_deg"][late]),
        "surface_curvature": curv_m,
        "overlap_p99_r": st.overlap_p99_r, "overlap_max_r": st.overlap_max_r, "wall_max_mm": st.wall_max_mm,
        "airborne": air_m, "regime": flow_regime(air_m, curv_m), "froude": froude(rpm, sim.drum),
        "froude_regime": froude_regime(rpm, sim.drum), "n_particles": len(sim.particles()),
    }


def _step_options(dt_ms: float | None, end_friction: float | None) -> dict[str, float]:
    """The twin's keyword arguments of ``--dt-ms`` (ms, 0.01-20; as ``dt_s``) and
    ``--end-friction`` (0-5), range-checked (one-line ``SimError``); the ones not given left out."""
    from sim.errors import check_number

    out: dict[str, float] = {}
    if dt_ms is not None:
        out["dt_s"] = check_number("--dt-ms", dt_ms, 0.01, 20.0) / 1e3
    if end_friction is not None:
        out["end_friction"] = check_number("--end-friction", end_friction, 0.0, 5.0)
    return out


def _default_dt_ms(sim: Any) -> float:
    """The engine's default step for this bed (ms): the DEM's from its contact time, pymunk's from the
    mixer's shapes (``sim.pymunk_twin.default_dt_s``)."""
    from sim.drum import DrumSim, default_dt_s
    from sim.pymunk_twin import PymunkDrumSim
    from sim.pymunk_twin import default_dt_s as pymunk_dt_s

    if isinstance(sim, DrumSim):
        return default_dt_s(sim.classes, sim.params.stiffness_n_m, sim.params.restitution) * 1e3
    assert isinstance(sim, PymunkDrumSim)
    return pymunk_dt_s(sim.mixer) * 1e3


def _measure_source_surface(source: str, max_frames: int, bed: str | None,
                            config: Any) -> tuple[float, float | None, int]:
    """Median free-surface slope (deg), median curvature (None if the meter gives none) and frames used,
    measured with ``config``'s meter (a ``vision.config.MeterConfig``)."""
    from vision.sources import open_source

    meter = config.make_meter(bed=bed)
    vals, curvs = [], []
    n = 0
    for frame in open_source(source, loop=False, reconnect=False):
        n += 1
        if frame.error:  # vision.sources says why a frame cannot be decoded
            raise SimError(f"frame {n} of {source}: {frame.error}")
        rd = meter.measure(frame.image)
        if math.isfinite(rd.slope_deg):
            vals.append(rd.slope_deg)
            c = getattr(rd, "surface_curvature", None)
            if c is not None and math.isfinite(c):
                curvs.append(float(c))
        if n >= max_frames:
            break
    if not vals:
        raise SimError(f"no bed slope could be measured in {n} frame(s) of {source}")
    return float(np.median(vals)), (float(np.median(curvs)) if curvs else None), len(vals)


@app.command("calibrate")
def calibrate_cmd(
    source: str | None = typer.Argument(None, help="frames to measure the slope in (video, folder, image, camera)"),
    rpm: float = typer.Option(..., "--rpm", help="drum speed of the source, rpm"),
    slope_deg: float | None = typer.Option(None, "--slope-deg", help="target slope instead of a source, deg"),
    curvature: float | None = typer.Option(None, "--curvature",
                                           help="target free-surface S-shape (default: measured, if given)"),
    max_frames: int = typer.Option(300, "--max-frames", help="frames of SOURCE to measure"),
    bed: str | None = typer.Option(None, "--bed", help="bed for the slope: color (union of classes) or dark (backlit)"),
    config: Path | None = typer.Option(None, "--config", help=CONFIG_HELP + "; its meter measures SOURCE"),
    engine: str | None = typer.Option(None, "--engine", help=ENGINE_HELP),
    seed: int = typer.Option(0, "--seed", help="0 <= seed < 2**32"),
    max_evals: int = typer.Option(8, "--max-evals", help="twin runs per search path, after the range runs (1..40)"),
    spin_up_s: float | None = typer.Option(None, "--spin-up-s", help="simulated start-up of each twin run, s "
                                                                      "(default: 3 s or a quarter turn if longer)"),
    window_s: float = typer.Option(5.0, "--window-s", help="simulated seconds each run's slope is averaged over"),
    dt_ms: float | None = typer.Option(None, "--dt-ms", help="internal time step of the twin runs, ms"),
    end_friction: float | None = typer.Option(None, "--end-friction",
                                              help="friction of the drum's end plates in the twin runs, kept "
                                                   "fixed (default: the wall's in a deep drum; a monolayer's is "
                                                   "calibrated)"),
    as_json: bool = typer.Option(False, "--json", help="print JSON to stdout"),
) -> None:
    """Fit the twin's sliding and rolling friction (and a monolayer's end-plate friction) to a measured
    free-surface slope (and curvature).

    Prints the slopes the twin can reach at this rpm; a target outside them is an error naming the
    friction that would have to leave its range.
    """
    from sim.calibrate import calibrate
    from sim.errors import check_number
    from sim.params import check_rpm
    from twin.config import load_checked_config

    if (source is None) == (slope_deg is None):
        raise SimError("give either SOURCE or --slope-deg (exactly one)")
    seed = _check_seed(seed)
    checked = load_checked_config(config, engine=engine)
    mixer = checked.mixer
    check_rpm(rpm, mixer.drum)
    check_number("--rpm", rpm, 0.0, mixer.drum.critical_rpm, lo_open=True)
    check_number("--max-evals", max_evals, 1, 40, integer=True)
    if spin_up_s is not None:
        check_number("--spin-up-s", spin_up_s, 0.0, 600.0)
    check_number("--window-s", window_s, 0.0, 600.0, lo_open=True)
    sim_kw: dict[str, Any] = _step_options(dt_ms, end_friction)  # spread into calibrate(...)
    if curvature is not None:
        check_number("--curvature", curvature, -1.0, 1.0)
    n_frames = 0
    target_curv = curvature
    if source is not None:
        check_number("--max-frames", max_frames, 1, 100_000, integer=True)
        target, measured_curv, n_frames = _measure_source_surface(source, max_frames, bed, checked.meter)
        if target_curv is None:
            target_curv = measured_curv
        say(f"measured slope {target:.1f} deg in {n_frames} frame(s)")
    else:
        target = check_number("--slope-deg", slope_deg, -90.0, 90.0)
    with _progress() as prog:
        task = prog.add_task("calibrate", total=None)
        cal = calibrate(target, rpm, target_curvature=target_curv, seed=seed, max_evals=max_evals,
                        spin_up_s=spin_up_s, window_s=window_s, mixer=mixer, engine=engine, **sim_kw,
                        progress=lambda d, t: prog.update(task, completed=d, total=t))
    out = {"slope_deg": target, "twin_slope_deg": cal.twin_slope_deg, "friction": cal.friction,
           "rolling": cal.rolling, "residual_deg": cal.residual_deg, "rpm": rpm,
           "range_deg": list(cal.range_deg), "curvature": target_curv, "twin_curvature": cal.twin_curvature,
           "path": cal.path, "evaluations": cal.evaluations, "frames": n_frames, "source": source,
           "engine": checked.engine, "end_friction": cal.end_friction,
           "end_friction_max": cal.end_friction_max}
    if as_json:
        print_json(out)
    else:
        console.print(
            f"reachable at {rpm:g} rpm: {cal.range_deg[0]:.1f}-{cal.range_deg[1]:.1f} deg; "
            f"target slope {target:.1f} deg -> twin {cal.twin_slope_deg:.1f} deg "
            f"(residual {cal.residual_deg:+.2f}) with friction {cal.friction:.3f}, rolling {cal.rolling:.3f}"
            + (f", end plates {cal.end_friction:.4f}" if cal.end_friction_max > 0 else "")
        )


@app.command("whatif")
def whatif_cmd(
    rpm: str = typer.Option("5,10,20,40", "--rpm", help="comma-separated rpm values"),
    duration: float = typer.Option(60.0, "--duration", help="simulated seconds per run"),
    case: str = typer.Option("C", "--case"),
    seeds: int = typer.Option(1, "--seeds", help=f"seeds per rpm (0..K-1), at most {MAX_SEEDS}"),
    fill: float | None = typer.Option(None, "--fill", help="filling degree (default: the recipe's 0.5)"),
    workers: int | None = typer.Option(None, "--workers", help="local processes (default: all cores)"),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Dask scheduler, tcp://HOST:PORT"),
    sample_s: float = typer.Option(0.5, "--sample-s", help="MI sample interval, s"),
    csv_out: Path | None = typer.Option(None, "--csv", help="write all MI curves here"),
    plot: Path | None = typer.Option(None, "--plot", help="PNG of MI against time per rpm"),
    config: Path | None = typer.Option(None, "--config", help=CONFIG_HELP),
    engine: str | None = typer.Option(None, "--engine", help=ENGINE_HELP),
    target_mi: float | None = typer.Option(None, "--target-mi",
                                           help="MI to reach: time and energy to it per rpm (default: none)"),
    as_json: bool = typer.Option(False, "--json", help="print JSON to stdout"),
) -> None:
    """Run the twin for several rpm values and report the plateau MI and regime of each, the drive power
    (whole drum) and, with --target-mi, the time and energy to reach it (seed mean and sd)."""
    from control.limits import Limits
    from sim.capacity import check_twin
    from sim.errors import check_number
    from sim.whatif import WhatIfJob, run_study, summarize
    from twin.config import load_checked_config

    check_outputs(csv_out, plot)  # before the study: a directory as --plot is no PNG
    checked = load_checked_config(config, engine=engine)
    mixer = checked.mixer
    check_number("--seeds", seeds, 1, MAX_SEEDS, integer=True)
    # the dashboard's and the loop's check (control.limits): rpm in (0, critical], study size, duration
    rpms, duration = Limits(critical_rpm=mixer.drum.critical_rpm).check_whatif(_parse_list(rpm, "--rpm"), duration,
                                                                              seeds)
    check_number("--sample-s", sample_s, 0.0, duration, lo_open=True)
    if fill is not None:
        check_number("--fill", fill, 0.0, 0.85, lo_open=True)
        check_twin(replace(mixer, fill=fill), engine, source=f"--fill {fill:g}")  # shares: more particles
    if target_mi is not None:
        check_number("--target-mi", target_mi, 0.0, 1.0)
    if workers is not None:
        check_number("--workers", workers, 1, 256, integer=True)
    if workers is not None and scheduler:
        raise SimError("give --workers or --scheduler, not both")
    jobs = [WhatIfJob(rpm=r, duration_s=duration, case=case.upper(), seed=s, fill=fill, sample_s=sample_s,
                      mixer=mixer, engine=engine, target_mi=target_mi) for r in rpms for s in range(seeds)]
    t0 = time.perf_counter()
    with _progress() as prog:
        task = prog.add_task("whatif", total=len(jobs))
        results = run_study(jobs, workers=workers, scheduler=scheduler,
                            progress=lambda d, t: prog.update(task, completed=d))
    wall = time.perf_counter() - t0
    if csv_out is not None:
        csv_out.parent.mkdir(parents=True, exist_ok=True)
        with open(csv_out, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["rpm", "case", "seed", "t_s", "mi", "mi_sigmoid", "slope_deg", "rpm_actual"])
            for res in results:
                for i in range(res.t_s.size):
                    w.writerow([res.job.rpm, res.job.case, res.job.seed, f"{res.t_s[i]:.4f}", f"{res.mi[i]:.5f}",
                                f"{res.mi_sigmoid[i]:.5f}", f"{res.slope_deg[i]:.3f}", f"{res.rpm_actual[i]:.3f}"])
    if plot is not None:
        _plot_whatif(results, plot)
    summary = summarize(results)
    out = {"rpm": summary, "duration_s": duration, "case": case.upper(), "seeds": seeds, "wall_s": wall,
           "scheduler": scheduler, "workers": workers, "engine": checked.engine, "target_mi": target_mi}
    if as_json:
        print_json(out)
    else:
        from rich.table import Table

        t = Table("rpm", "regime (flow)", "Fr", "airborne", "plateau MI", "sd", "t plateau (s)", "power (W)",
                  "t to target (s)", "energy (J)")
        for e in summary:
            t.add_row(f"{e['rpm']:g}", e["regime"], f"{e['froude']:.3f}", f"{e['airborne']:.3f}",
                      f"{e['plateau_mi']:.3f}", f"{e['plateau_mi_sd']:.3f}", f"{e['t_plateau_s']:.0f}",
                      _pm(e["power_w"], e["power_sd_w"], ".2f"),
                      _pm(e["time_to_target_s"], e["time_to_target_sd_s"], ".1f"),
                      _pm(e["energy_to_target_j"], e["energy_to_target_sd_j"], ".1f"))
        console.print(t)


def _pm(mean: float, sd: float, fmt: str) -> str:
    """``mean +- sd`` (``-`` for NaN, the sd left out when NaN)."""
    if not math.isfinite(mean):
        return "-"
    return f"{mean:{fmt}}" + (f" +- {sd:{fmt}}" if math.isfinite(sd) else "")


def _plot_whatif(results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 4))
    rpms = sorted({r.job.rpm for r in results})
    cmap = plt.get_cmap("viridis")
    for i, rpm in enumerate(rpms):
        rs = [r for r in results if r.job.rpm == rpm]
        for j, r in enumerate(rs):
            ax.plot(r.t_s, r.mi, color=cmap(i / max(1, len(rpms) - 1)), lw=1.0, alpha=0.8,
                    label=f"{rpm:g} rpm ({r.regime})" if j == 0 else None)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("MI (eq. 4, particles)")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@bench_app.command("twin")
def bench_twin(
    duration: float = typer.Option(10.0, "--duration", help="simulated seconds per measurement"),
    as_json: bool = typer.Option(False, "--json", help="print JSON to stdout"),
) -> None:
    """Real-time factor of the twin on one core: paper bed at 5 and 30 rpm, 4x and 16x particles at 5 rpm
    on the DEM; the paper bed and the cut-disc rig (configs/pmma-cutdisc.toml) on pymunk, each at its
    default step; and the time to place 20,000 and 200,000 discs (``sim.bench``: the beds and the clock).
    """
    from sim.bench import DEM_BEDS, PLACEMENT_BEDS, PYMUNK_BEDS, run_twin_bench
    from sim.errors import check_number

    check_number("--duration", duration, 0.0, 600.0, lo_open=True)
    with _progress() as prog:
        task = prog.add_task("bench twin", total=len(DEM_BEDS))
        out = run_twin_bench(duration, progress=lambda: prog.advance(task))
    if as_json:
        print_json(out)
    else:
        from rich.table import Table

        table = Table(title="twin real-time factor = sim s per wall s (one core)")
        for col in ("bed", "particles", "RTF", "µs/particle/sim-s"):
            table.add_column(col, justify="left" if col == "bed" else "right")
        for name, drum, rpm in DEM_BEDS:
            n, rtf = out[name.replace("rtf_", "n_")], out[name]
            bed = "paper" if name.startswith("rtf_paper") else name[4:] + " particles"
            table.add_row(f"DEM: {bed}, {rpm:g} rpm, D {drum.diameter_m:.1f} m", str(n), f"{rtf:.1f}",
                          f"{1e6 / (rtf * n):.0f}")
        for name, bed in PYMUNK_BEDS:
            n, rtf = out[name.replace("rtf_", "n_")], out[name]
            table.add_row(bed, str(n), f"{rtf:.1f}", f"{1e6 / (rtf * n):.0f}")
        console.print(table)
        console.print("placement (sim.placement): " + ", ".join(
            f"{n:,} discs {out[f'placement_s_{n}']:.2f} s" for n in PLACEMENT_BEDS), highlight=False)

"""``drumtwin commission``: a rig's frames to ``mixer.toml`` and ``report.html``, every set-up step
checked (``twin.commission``), and ``drumtwin bench commission``."""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path

import typer

from twin.cli.app import app, bench_app, print_json, say


def _progress(step: str, message: str) -> None:
    say(f"commission: {step}: {message}")


@app.command("commission")
def commission_cmd(
    source: list[str] = typer.Argument(..., help="Frames of the rig turning: a folder, images or a video."),
    drum_diameter_mm: float = typer.Option(..., "--drum-diameter-mm", help="The drum's inner diameter (mm)."),
    rpm: float = typer.Option(..., "--rpm", help="The drum's speed in the frames (rpm)."),
    out: Path | None = typer.Option(None, "--out", help="A new folder to write mixer.toml and report.html into; "
                                    "default commission-YYYYmmdd-HHMMSS."),
    drum_depth_mm: float | None = typer.Option(None, "--drum-depth-mm", help="The end plates' distance (mm); "
                                               "default a monolayer drum (one particle thick)."),
    rotation: float | None = typer.Option(None, "--camera-rotation-deg", help="How far the camera is turned "
                                          "(deg, counter-clockwise as seen); default: from where the bed lies."),
    roi: str | None = typer.Option(None, "--roi", help="Drum circle cx,cy,r in px (overrides detection)."),
    engine: str | None = typer.Option(None, "--engine", help="The twin's engine: dem (discs) or pymunk (any "
                                      "shape); default the mixer's."),
    frames: int = typer.Option(48, "--frames", help="Frames kept, spread over the source (5..500)."),
    as_json: bool = typer.Option(False, "--json", help="Print the checks and the files as JSON on stdout."),
) -> None:
    """Commission a rig: drum, orientation, colour classes, light, census, calibration, and the
    calibrated twin against the camera; exit 0 when every check passes, 1 when one fails (one line
    each on stderr saying what to do; the files are written), 2 on bad input (nothing written)."""
    from twin.commission.checks import exit_code, failed
    from twin.commission.output import check_out, default_out, write_outputs
    from twin.commission.steps import Given, check_given, commission
    from vision.roi import parse_roi

    given = Given(tuple(source), drum_diameter_mm, rpm, drum_depth_mm, rotation, parse_roi(roi) if roi else None,
                  engine, frames)
    check_given(given)
    target = check_out(out if out is not None else default_out())
    c = commission(given, _progress)
    toml_path, html_path = write_outputs(c, target)
    bad = failed(c.checks)
    for k in bad:
        against = "" if k.target is None else f" against {k.target:.4g}"
        unit = f" {k.unit}" if k.unit else ""
        say(f"check failed: {k.name} = {k.value:.4g}{against} (tolerance {k.tolerance:g}{unit}): {k.advice}")
    say(f"commission: {len(c.checks) - len(bad)} of {len(c.checks)} checks passed; wrote {toml_path} and {html_path} "
        f"({c.wall_s:.0f} s, {c.cpu_s:.0f} s CPU)")
    if as_json:
        print_json({"exit_code": exit_code(c.checks), "mixer_toml": str(toml_path), "report_html": str(html_path),
                    "cpu_s": c.cpu_s, "wall_s": c.wall_s,
                    "checks": [{"step": k.step, "name": k.name, "value": k.value, "target": k.target,
                                "tolerance": k.tolerance, "unit": k.unit, "passed": k.passed, "advice": k.advice}
                               for k in c.checks]})
    code = exit_code(c.checks)
    if code:
        raise typer.Exit(code)


class BenchRig(StrEnum):
    notched = "notched"  # issue 39's rig: 25 discs across, notched and round (pymunk)
    notched_small = "notched-small"  # the same discs in a 150 mm drum (about 60: the tests' rig)
    discs = "discs"  # a small drum of round discs (DEM): a quick run of every step


@bench_app.command("commission")
def bench_commission(
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    rig: BenchRig = typer.Option(BenchRig.notched, "--rig", help="The rendered rig to commission."),
) -> None:
    """CPU time of commissioning a rendered rig of known answer (one core; each step's wall and CPU
    time): issue 39's notched and round discs (pymunk), or a small one. A rig's own frames: run
    ``drumtwin commission``, which prints its time too."""
    import tempfile

    from twin.commission.checks import failed
    from twin.commission.rigs import RigRun, disc_rig, film, notched_rig, write_frames
    from twin.commission.steps import Given, commission

    mixer, run = {BenchRig.notched: (notched_rig(), RigRun()),
                  BenchRig.notched_small: (notched_rig(drum_mm=150.0), RigRun(size_px=640, frames=16)),
                  BenchRig.discs: (disc_rig(), RigRun(size_px=480, frames=12))}[rig]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.process_time()
        write_frames(film(mixer, run), Path(tmp) / "rig")
        filmed_s = time.process_time() - t0
        say(f"bench commission: the {rig.value} rig filmed, {run.frames} frames ({filmed_s:.1f} s CPU)")
        c = commission(Given((str(Path(tmp) / "rig"),), mixer.drum.diameter_m * 1e3, run.rpm), _progress)
    bad = [k.name for k in failed(c.checks)]
    res = {"rig": rig.value, "frames": len(c.frames.images), "cpu_s": c.cpu_s, "wall_s": c.wall_s,
           "filming_cpu_s": filmed_s, "failed": bad, "steps": {t.step: {"wall_s": t.wall_s, "cpu_s": t.cpu_s}
                                                              for t in c.times}}
    if json_out:
        print_json(res)
        return
    say(f"commissioning the {rig.value} rig: {c.cpu_s:.1f} s CPU, {c.wall_s:.1f} s wall; failed checks: "
        f"{', '.join(bad) or 'none'}")

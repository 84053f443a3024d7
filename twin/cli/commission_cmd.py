"""``drumtwin commission``: a rig's frames to ``mixer.toml`` and ``report.html``, every set-up step
checked (``twin.commission``), and ``drumtwin bench commission``."""

from __future__ import annotations

import time
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
    out: Path | None = typer.Option(None, "--out", help="Folder to write mixer.toml and report.html into (new, "
                                    "or empty); default commission-YYYYmmdd-HHMMSS."),
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


@bench_app.command("commission")
def bench_commission(
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    rig: str = typer.Option("notched", "--rig", help="notched (issue 39's shaped rig, pymunk) or a folder of "
                            "frames with --drum-diameter-mm and --rpm."),
    drum_diameter_mm: float = typer.Option(250.0, "--drum-diameter-mm", help="With a folder: its drum (mm)."),
    rpm: float = typer.Option(5.0, "--rpm", help="With a folder: its speed (rpm)."),
) -> None:
    """CPU time of commissioning a rig (one core): issue 39's rendered rig of notched and round discs
    (pymunk), or a folder of frames; each step's wall and CPU time."""
    import tempfile

    from twin.commission.checks import failed
    from twin.commission.rigs import RigRun, film, notched_rig, write_frames
    from twin.commission.steps import Given, commission

    with tempfile.TemporaryDirectory() as tmp:
        if rig == "notched":
            t0 = time.process_time()
            write_frames(film(notched_rig(), RigRun()), Path(tmp) / "rig")
            say(f"bench commission: the rig filmed ({time.process_time() - t0:.1f} s CPU)")
            folder = str(Path(tmp) / "rig")
        else:
            folder = rig
        c = commission(Given((folder,), drum_diameter_mm, rpm), _progress)
    bad = [k.name for k in failed(c.checks)]
    res = {"rig": rig, "frames": len(c.frames.images), "cpu_s": c.cpu_s, "wall_s": c.wall_s, "failed": bad,
           "steps": {t.step: {"wall_s": t.wall_s, "cpu_s": t.cpu_s} for t in c.times}}
    if json_out:
        print_json(res)
        return
    say(f"commissioning {rig}: {res['cpu_s']:.1f} s CPU, {res['wall_s']:.1f} s wall; failed checks: "
        f"{', '.join(bad) or 'none'}")

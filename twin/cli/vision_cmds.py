"""The vision commands: ``drumtwin mi`` (``twin.cli.mi_cmd``), ``drumtwin classes suggest``
(``twin.cli.classes_cmd``; the twin's mixer it measures: ``twin.suggest_mixer``) and
``drumtwin bench vision``."""

from __future__ import annotations

import typer

from twin.cli import classes_cmd, mi_cmd  # noqa: F401  (their commands register on import, in this order)
from twin.cli.app import bench_app, console, print_json, say
from twin.cli.options import check_number

CENSUS_MAX_FRAMES = 24  # frames `classes suggest --drum-diameter-mm` keeps for the mixer's census


@bench_app.command("vision")
def bench_vision(
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    seconds: float = typer.Option(1.5, "--seconds", help="Time per measurement (s)."),
    rigs: bool = typer.Option(False, "--rigs", help="Accuracy on rigs made from the real frames (vision.rigbench)."),
) -> None:
    """Frames/s of the centroid, GLCM and Lacey pipelines on the same frames (one thread)."""
    from vision.bench import run_vision_bench

    check_number("--seconds", seconds, 0.01, 600)
    if rigs:  # the cross-rig bench (issue 38): its own module
        from vision.rigbench import rig_table, run_rig_bench

        res = run_rig_bench(log=say)
        print_json(res) if json_out else console.print("\n".join(rig_table(res)), highlight=False, markup=False)
        return
    res = run_vision_bench(seconds=seconds, log=say)
    if json_out:
        print_json(res)
        return
    from rich.table import Table

    t = Table(title="vision pipelines, one thread, pre-decoded frames")
    t.add_column("pipeline")
    t.add_column("frames/s", justify="right")
    t.add_column("vs centroid", justify="right")
    c = res["centroid_fps"]
    t.add_row("centroid 640x480 (every pixel)", f"{c:,.0f}", "1x")
    t.add_row("centroid 640x480, stride 2 (opt-in decimation)", f"{res['centroid_fps_stride2']:,.0f}", "")
    t.add_row("centroid 640x480, class opening", f"{res['centroid_fps_opening']:,.0f}", "")
    t.add_row("centroid 640x480, three glare spots filled", f"{res['centroid_fps_glare']:,.0f}", "")
    t.add_row("centroid 640x480, tracking on, a full estimate every frame", f"{res['centroid_fps_tracked']:,.0f}",
              f"{res['tracked_ratio']:.2f}x")
    t.add_row("centroid 640x480, tracking on, steady video (default schedule)",
              f"{res['centroid_fps_tracked_steady']:,.0f}", f"{res['tracked_steady_ratio']:.2f}x")
    t.add_row("centroid 640x480, light moving every frame (re-bakes)", f"{res['centroid_fps_light_moved']:,.1f}",
              f"one re-bake {1000 * res['rebake_s']:.0f} ms")
    t.add_row("GLCM 640x480", f"{res['glcm_fps']:,.1f}", f"{c / res['glcm_fps']:.1f}x slower")
    t.add_row("Lacey 640x480", f"{res['lacey_fps']:,.1f}", f"{c / res['lacey_fps']:.1f}x slower")
    t.add_row("centroid 1920x1080 (every pixel)", f"{res['centroid_fps_1080p']:,.0f}", "")
    t.add_row("centroid 1920x1080, stride 2", f"{res['centroid_fps_1080p_stride2']:,.0f}", "")
    t.add_row("per CPU second: centroid / tracked 640x480", f"{res['centroid_cpu_fps']:,.0f} / "
              f"{res['centroid_cpu_fps_tracked']:,.0f}", f"GLCM {res['glcm_cpu_ratio']:.1f}x slower")
    console.print(t)
    console.print("paper (Raspberry Pi 5): 68 fps centroid, 2.8x GLCM, 21.6x Lacey", highlight=False)

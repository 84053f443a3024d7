"""The vision commands: ``drumtwin mi`` (``twin.cli.mi_cmd``), ``drumtwin classes suggest``
(``twin.cli.classes_cmd``; the twin's mixer it measures, :func:`suggest_mixer_toml`, is here) and
``drumtwin bench vision``."""

from __future__ import annotations

import math

import typer

from twin.cli import classes_cmd, mi_cmd  # noqa: F401  (their commands register on import, in this order)
from twin.cli.app import bench_app, console, print_json, say
from twin.cli.options import check_number
from vision.errors import VisionError

SUGGEST_DENSITY_KG_M3 = 1190.0  # PMMA: a camera cannot see density
CENSUS_MAX_FRAMES = 24  # frames `classes suggest --drum-diameter-mm` keeps for the mixer's census
CROPS_PER_FRAME = 4  # single particles per class and frame traced for the class's shape


def suggest_mixer_toml(cfg, frames, rois, drum_diameter_mm: float, drum_depth_mm: float | None) -> str:
    """The twin's ``[drum]`` and ``[[particles]]`` tables measured in ``frames`` (``vision.census``),
    every number commented with where it came from; each class's shape round or the outline traced
    from its single particles in the frames (``sim.mixer.shape_from_crops``)."""
    import cv2
    import numpy as np

    from sim.errors import SimError
    from sim.mixer import MAX_FILL, Mixer, ParticleKind, Shape, mixer_to_toml, shape_from_crops
    from sim.recipe import PACKING_2D, DrumSpec
    from vision.census import (
        SAME_SIZE,
        census,
        circle_census,
        class_size,
        count_particles,
        particle_body,
        run_diameter_px,
        same_size,
        single_particle_crops,
        single_particles,
    )
    from vision.roi import roi_bbox
    from vision.suggest import drum_labels

    counted = [(j + 1, c) for j, c in enumerate(cfg.classes) if not c.reject]
    names = [c.name for _, c in counted]
    labels, grays, bodies, cpx, rpx, runs, slopes = [], [], [], [], [], [], []
    for img, roi in zip(frames, rois, strict=True):
        lab = drum_labels(cfg, img, roi)
        x0, y0, x1, y1 = roi_bbox(roi, img.shape[:2])
        gray = cv2.cvtColor(np.ascontiguousarray(img[y0:y1, x0:x1]), cv2.COLOR_BGR2GRAY)
        body = [particle_body(lab == j, gray) for j, _ in counted]  # each class's particles without its gaps
        labels.append(lab)
        grays.append(gray)
        bodies.append(body)
        rd = cfg.make_meter(roi=roi).measure(img)
        cpx.append([rd.cls(n).n_px for n in names])
        rpx.append(roi.area_px)
        runs.append([run_diameter_px(single_particles(b, run_diameter_px(b))) for b in body])
        slopes.append(rd.slope_deg)
    r_px = float(np.median([r.r_px for r in rois]))
    px_mm = drum_diameter_mm / (2.0 * r_px)
    runs_a = np.asarray(runs, dtype=float).reshape(len(frames), len(counted))
    by_runs = [class_size(np.zeros(0), runs_a[:, i]) for i in range(len(counted))]
    known = [s.diameter_px for s in by_runs if math.isfinite(s.diameter_px)]
    # round particles as circles in the gray frames, up to 1.6x the largest class's runs (a third of the drum)
    circles = (circle_census(grays, labels, len(cfg.classes), [j - 1 for j, _ in counted],
                             min(1.6 * max(known), 2.0 * r_px / 3.0)) if known else [np.zeros(0) for _ in counted])
    own, shapes = [], []
    for i, (_, c) in enumerate(counted):
        # a class's circles are its size when its single particles at that size are round; else its runs
        cand = class_size(circles[i], runs_a[:, i])
        for size in ([cand, by_runs[i]] if cand.source == "circles" else [by_runs[i]]):
            crops = [cr for body in bodies for cr in single_particle_crops(body[i], size.diameter_px, CROPS_PER_FRAME)]
            shape, how = shape_from_crops(crops, size.diameter_px * px_mm * 1e-3, px_mm, f"class {c.name!r}")
            if shape.kind == "disc" or size is by_runs[i]:
                break
        own.append(size)
        shapes.append((shape, how))
    sizes, _ = same_size([s.diameter_px for s in own])
    cnt = [[count_particles(b, sizes[i], PACKING_2D) for i, b in enumerate(body)] for body in bodies]
    cen = census(names, np.asarray(cpx), np.asarray(rpx), own, np.asarray(cnt), slopes, r_px, PACKING_2D)
    if not all(math.isfinite(c.diameter_px) for c in cen.classes):
        missing = next(c.name for c in cen.classes if not math.isfinite(c.diameter_px))
        raise VisionError(f"class {missing!r}: too few particle pixels in the frames to measure a size")
    notes: dict[str, str] = {
        "drum.diameter_mm": f"--drum-diameter-mm (the drum is {2 * r_px:.0f} px across in the frames: "
                            f"{px_mm:.3f} mm/px)",
        "drum.fill": f"{sum(c.count for c in cen.classes):.0f} particles counted (median of {cen.frames} frames) "
                     f"x their area / ({PACKING_2D:g} packing x the drum's area)",
        "drum.rotation": (f"the free surface's median slope {cen.slope_deg:+.1f} deg "
                          f"({'rises to the right' if cen.slope_deg > 0 else 'rises to the left'})"
                          if cen.direction else "the surface is flat in the frames: direction unknown, set it"),
        "drum.density_kg_m3": "acrylic (assumed; not used by the physics)",
    }
    if drum_depth_mm is None:
        notes["drum.monolayer"] = "assumed: one particle between the plates (give --drum-depth-mm otherwise)"
    else:
        notes["drum.depth_mm"] = "--drum-depth-mm"
    kinds = []
    for i, c in enumerate(cen.classes):
        w = f"particles.{c.name}"
        d_mm = c.diameter_px * px_mm
        why = (f"; its own {c.own.diameter_px:.1f} px, the classes within {100 * SAME_SIZE:.0f}%: one size"
               if cen.same_size else "")
        shape, how = shapes[i]
        if shape.kind == "disc":
            shape = Shape("disc", d_mm * 1e-3)
        src = (f"median of {c.own.count} circles in the gray frames" if c.own.source == "circles" else
               f"median horizontal run / 0.91 of its single particles, {cen.frames} frames")
        notes[f"{w}.diameter_mm"] = (f"{c.diameter_px:.1f} px ({src}){why}" if shape.kind == "disc" else
                                     "the traced outline's circumscribed diameter")
        notes[f"{w}.shape"] = how
        notes[f"{w}.share"] = (f"{c.count:.0f} particles per frame x their area; the class's pixel share is "
                               f"{c.pixel_share:.3f}")
        notes[f"{w}.density_kg_m3"] = "PMMA (assumed: a camera cannot see density)"
        thick = None
        if drum_depth_mm is not None and drum_depth_mm < d_mm:  # flat discs: as thick as the drum is deep
            thick = drum_depth_mm * 1e-3
            notes[f"{w}.thickness_mm"] = "assumed: the drum's depth (the discs are wider than the drum is deep)"
        kinds.append(ParticleKind(c.name, shape, SUGGEST_DENSITY_KG_M3,
                                  share=round(c.share, 3), thickness_m=thick,
                                  colour_bgr=next(k.display_bgr for _, k in counted if k.name == c.name)))
    fill = min(max(cen.fill, 0.05), MAX_FILL) if math.isfinite(cen.fill) else 0.5
    depth_m = (drum_depth_mm if drum_depth_mm is not None else max(k.shape.diameter_m * 1e3 for k in kinds)) * 1e-3
    mixer = Mixer(DrumSpec(drum_diameter_mm * 1e-3, depth_m), tuple(kinds), fill=round(fill, 3),
                  direction=-1 if cen.direction < 0 else 1, monolayer=drum_depth_mm is None)
    total = sum(k.share or 0.0 for k in kinds)
    if abs(total - 1.0) > 1e-9:  # rounding: the last class takes the rest
        last = kinds[-1]
        kinds[-1] = ParticleKind(last.name, last.shape, last.density_kg_m3, share=round(float(last.share or 0.0)
                                 + 1.0 - total, 3), thickness_m=last.thickness_m, colour_bgr=last.colour_bgr)
        mixer = Mixer(mixer.drum, tuple(kinds), mixer.fill, mixer.direction, mixer.monolayer)
    try:
        from sim.mixer import check_fits

        check_fits(mixer, "suggested mixer")
    except SimError as exc:
        raise VisionError(str(exc)) from None
    head = ("# The twin's mixer, measured in the same frames by `drumtwin classes suggest --drum-diameter-mm`;\n"
            "# edit what is wrong (shape, density, depth).\n")
    return head + mixer_to_toml(mixer, notes)


@bench_app.command("vision")
def bench_vision(
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    seconds: float = typer.Option(1.5, "--seconds", help="Time per measurement (s)."),
) -> None:
    """Frames/s of the centroid, GLCM and Lacey pipelines on the same frames (one thread)."""
    from vision.bench import run_vision_bench

    check_number("--seconds", seconds, 0.01, 600)
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

"""``drumtwin mi``, ``drumtwin classes suggest`` and ``drumtwin bench vision``."""

from __future__ import annotations

import csv
import math
import sys
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from twin.cli.app import ENDPOINT_HELP, app, bench_app, check_outputs, console, console_err, print_json, say
from vision.errors import VisionError

if TYPE_CHECKING:
    from collections.abc import Iterator

    import numpy as np

    from vision.glcm import GLCMMeter
    from vision.lacey import LaceyMeter

classes_app = typer.Typer(help="Colour classes: suggest a TOML config from a frame.")
app.add_typer(classes_app, name="classes")


class Method(StrEnum):
    centroid = "centroid"
    lacey = "lacey"
    glcm = "glcm"


class Bed(StrEnum):
    color = "color"
    dark = "dark"


BASE_COLUMNS = ("frame", "t_s", "mi", "mi_sigmoid", "mi_linear", "d_px", "dsigma_px", "slope_deg", "valid")
CLASS_COLUMNS = ("cx", "cy", "sigma", "frac")
EXTRA_COLUMNS = ("concentration", "mi_avg", "slope_axis_deg", "surface_curvature", "roi_cx_px", "roi_cy_px",
                 "roi_r_px", "flags", "source")


def csv_columns(class_names: list[str]) -> list[str]:
    """CSV header of ``drumtwin mi``: base columns, per-class columns, extras."""
    cols = list(BASE_COLUMNS)
    for n in class_names:
        cols += [f"{c}_{n}" for c in CLASS_COLUMNS]
    return cols + list(EXTRA_COLUMNS)


def _num(x: float | None, digits: int = 6) -> str:
    return "" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _check_number(option: str, value: float, lo: float, hi: float) -> None:
    """A one-line error naming ``option`` unless ``lo <= value <= hi`` (and finite)."""
    if not (math.isfinite(value) and lo <= value <= hi):
        raise VisionError(f"{option} must be within {lo:g}..{hi:g}, got {value:g}")


def _warn(lines: tuple[str, ...] | list[str]) -> None:
    for ln in lines:
        say(f"warning: {ln}")


def _no_default_pixels_error() -> VisionError:
    return VisionError(
        "no pixels of the default red/blue classes in the drum: these particles need their own colours; run "
        "`drumtwin classes suggest FRAMES... --preview preview.png > mixer.toml` and pass --config mixer.toml"
    )


@app.command("mi")
def mi_cmd(
    source: list[str] = typer.Argument(..., help="Camera index (0), video file, stream URL, image folder or images."),
    config: Path | None = typer.Option(None, "--config", help="TOML config (colour classes, ROI, bed)."),
    method: Method = typer.Option(
        Method.centroid, "--method", help="Mixing index: centroid (paper eq. 4), lacey, glcm."
    ),
    csv_out: Path | None = typer.Option(None, "--csv", help="Write one row per frame here (default: stdout)."),
    plot: Path | None = typer.Option(None, "--plot", help="PNG of MI and its moving average against time."),
    overlay_video: Path | None = typer.Option(None, "--overlay-video", help="MP4 with the monitoring overlay."),
    roi: str | None = typer.Option(None, "--roi", help="Drum circle cx,cy,r in px (overrides detection)."),
    bed: Bed | None = typer.Option(None, "--bed", help="Bed for the slope angle: color (classes) or dark (backlit)."),
    fps: float = typer.Option(30.0, "--fps", help="Frame rate assumed for image sequences (timestamps)."),
    max_frames: int = typer.Option(0, "--max-frames", help="Stop after this many frames (0 = all)."),
    window: int = typer.Option(150, "--window", help="Moving-average window (samples)."),
    endpoint: bool = typer.Option(False, "--endpoint", help="Batch endpoint: the mixing time (docs/endpoint.md)."),
    target_mi: float = typer.Option(None, "--target-mi", help="--endpoint: plateau MI a mixed batch reaches "
                                    "(default: the run's, control.endpoint)."),
    json_out: bool = typer.Option(False, "--json", help="Print a JSON summary on stdout (the CSV only with --csv)."),
    endpoint_band: float = typer.Option(None, "--endpoint-band", help=ENDPOINT_HELP["band"]),
    endpoint_dwell_s: float = typer.Option(None, "--endpoint-dwell-s", help=ENDPOINT_HELP["dwell_s"]),
    endpoint_block_s: float = typer.Option(None, "--endpoint-block-s", help=ENDPOINT_HELP["block_s"]),
    endpoint_block_sd_max: float = typer.Option(None, "--endpoint-block-sd-max", help=ENDPOINT_HELP["block_sd_max"]),
) -> None:
    """Mixing index per frame: CSV row per frame, optional plot and overlay video."""
    import cv2
    import numpy as np

    from control.trend import MovingAverage
    from twin.config import load_checked_config
    from vision.overlay import draw_overlay
    from vision.roi import parse_roi
    from vision.sources import open_source, source_kind

    _check_number("--window", window, 1, 1_000_000)
    _check_number("--fps", fps, 1e-3, 10_000)
    _check_number("--max-frames", max_frames, 0, 10**12)
    if target_mi is not None:
        _check_number("--target-mi", target_mi, 0.0, 1.0)
    from twin.config import endpoint_options

    ep_options = endpoint_options(band=endpoint_band, dwell_s=endpoint_dwell_s, block_s=endpoint_block_s,
                                  block_sd_max=endpoint_block_sd_max)
    cfg = load_checked_config(config).meter
    if cfg.endpoint_table:  # [endpoint] under the --endpoint-* options
        from twin.config import config_endpoint

        ep_options = config_endpoint(cfg.endpoint_table, cfg.source, ep_options)
    _warn(cfg.warnings)
    manual_roi = parse_roi(roi) if roi else None
    meter = cfg.make_meter(roi=manual_roi, bed=bed.value if bed else None)
    baseline: LaceyMeter | GLCMMeter | None = None
    if method is Method.lacey:
        from vision.lacey import LaceyMeter

        baseline = LaceyMeter(cfg.classes, manual_roi or cfg.roi, opening=cfg.opening)
    elif method is Method.glcm:
        from vision.glcm import GLCMMeter

        baseline = GLCMMeter(manual_roi or cfg.roi)
    for out in (csv_out, plot, overlay_video):
        if out is not None and not out.parent.exists():
            raise VisionError(f"output folder does not exist: {out.parent}")
    check_outputs(csv_out, plot, overlay_video)  # a directory as --plot would become DIR.png
    spec = source if len(source) > 1 else source[0]
    kind = source_kind(spec)
    frames = open_source(spec, fps=fps)
    total = None
    if kind in ("folder", "images"):
        from vision.sources import _image_paths

        total = len(_image_paths(spec))
    elif kind == "image":
        total = 1
    if max_frames > 0 and (total is None or total > max_frames):
        total = max_frames

    names = [c.name for c in meter.classes]
    cols = csv_columns(names)
    import io

    fh = open(csv_out, "w", newline="") if csv_out else io.StringIO() if json_out else sys.stdout
    writer = csv.writer(fh)
    header_written = False
    ma = MovingAverage(window)
    ts: list[float] = []
    mis: list[float] = []
    avgs: list[float] = []
    vw = None
    vw_size = None
    n_valid = 0
    n_good = 0
    n = 0
    first_bad: str | None = None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    progress = Progress(TextColumn("mi"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        console=console_err, transient=True)
    try:
        with progress:
            task = progress.add_task("frames", total=total)
            for fr in frames:
                if fr.error:
                    if kind == "image":
                        raise VisionError(fr.error)
                    reading = meter.invalid(f"bad_frame:{fr.error}")
                    first_bad = first_bad or fr.error
                elif fr.image.ndim == 2:
                    why = f"{fr.name or 'the frame'} is a grayscale image; the mixing index needs colour frames"
                    if kind == "image":
                        raise VisionError(why)
                    reading = meter.measure(fr.image)  # a flagged row
                    first_bad = first_bad or why
                else:
                    try:
                        reading = meter.measure(fr.image)
                    except VisionError as exc:  # no drum found in a frame of a new size
                        if n_good == 0:
                            raise VisionError(f"{fr.name or 'the first frame'}: {exc}") from None
                        reading = meter.invalid(f"bad_frame:{exc}")
                    else:
                        n_good += 1
                    if (cfg.is_default and meter.bed == "color" and n_good == 1
                            and any(f.startswith("few_pixels") for f in reading.flags)):
                        raise _no_default_pixels_error()
                if not header_written:
                    writer.writerow(cols)
                    header_written = True
                mi_val = reading.mi
                mi_sig, mi_lin, d, ds = reading.mi_sigmoid, reading.mi_linear, reading.d_px, reading.dsigma_px
                flags = list(reading.flags)
                if baseline is not None:
                    mi_sig = mi_lin = d = ds = float("nan")
                    ok_frame = not fr.error and not any(f.startswith(("bad_frame", "size_changed")) for f in flags)
                    mi_val = baseline.measure(fr.image).m if ok_frame else float("nan")
                valid = math.isfinite(mi_val)
                avg = ma.update(mi_val)
                row = [fr.index, f"{fr.t_s:.4f}", _num(mi_val), _num(mi_sig), _num(mi_lin), _num(d), _num(ds),
                       _num(reading.slope_deg, 5), int(valid)]
                for st in reading.classes:
                    row += [_num(st.cx_px), _num(st.cy_px), _num(st.sigma_px), _num(st.frac)]
                r_roi = reading.roi
                row += [_num(reading.concentration), _num(avg), _num(reading.slope_axis_deg, 5),
                        _num(reading.surface_curvature, 4)]
                row += [_num(r_roi.cx_px, 7), _num(r_roi.cy_px, 7), _num(r_roi.r_px, 7)] if r_roi else ["", "", ""]
                row += [";".join(flags), fr.name]
                writer.writerow(row)
                ts.append(fr.t_s)
                mis.append(mi_val)
                avgs.append(avg)
                n += 1
                n_valid += int(valid)
                if overlay_video is not None:
                    img = fr.image if fr.image.size else None
                    ov = draw_overlay(img if img is not None else np.zeros((480, 640, 3), np.uint8), reading,
                                      cfg.classes, mi_avg=avg)
                    if vw is None:
                        vw_size = (ov.shape[1] // 2 * 2, ov.shape[0] // 2 * 2)
                        vw = cv2.VideoWriter(str(overlay_video), cv2.VideoWriter.fourcc(*"mp4v"), fps, vw_size)
                        if not vw.isOpened():
                            raise VisionError(f"cannot write video {overlay_video}")
                    if (ov.shape[1], ov.shape[0]) != vw_size:
                        ov = cv2.resize(ov, vw_size)
                    vw.write(ov)
                progress.advance(task)
                if max_frames and n >= max_frames:
                    break
    finally:
        if vw is not None:
            vw.release()
        if csv_out:
            fh.close()
        else:
            fh.flush()
    if n == 0:
        raise VisionError("the source gave no frames")
    if n_good == 0:
        raise VisionError(f"none of the {n} frames could be read (corrupt or not images): {first_bad}")
    if plot is not None:
        _plot(plot, ts, mis, avgs, method.value, window)
    say(f"{n} frames, {n_valid} valid" + (f" -> {csv_out}" if csv_out else ""))
    if endpoint or json_out:
        summary = _mi_summary(ts, mis, method.value, endpoint, target_mi, ep_options)
        if json_out:
            print_json(summary)
        elif endpoint:
            mt = summary["mixing_time_s"]
            say("endpoint: " + ("never mixed" if mt is None else f"mixed at {mt:.2f} s "
                f"(plateau MI {summary['plateau_mi']:.3f})"))


def _mi_summary(ts: list[float], mis: list[float], method: str, endpoint: bool, target_mi: float | None,
                ep_options: dict[str, float] | None = None) -> dict:
    """The ``--json`` summary: frames, MI statistics and (``--endpoint``) the mixing time."""
    import numpy as np

    v = np.asarray(mis, float)
    ok = v[np.isfinite(v)]
    stats = {"mi_first": ok[0], "mi_last": ok[-1], "mi_mean": ok.mean(), "mi_median": np.median(ok),
             "mi_min": ok.min(), "mi_max": ok.max()} if ok.size else {}
    out: dict = {"frames": len(mis), "valid": int(ok.size), "method": method,
                 "duration_s": (ts[-1] - ts[0]) if ts else 0.0,
                 **{k: float(stats[k]) if k in stats else None
                    for k in ("mi_first", "mi_last", "mi_mean", "mi_median", "mi_min", "mi_max")}}
    if endpoint:
        from dataclasses import asdict

        from control.endpoint import EndpointConfig, endpoint_of_series
        from twin.config import RunConfig
        from twin.run.settings import endpoint_config, trend_config

        cfg: EndpointConfig = endpoint_config(RunConfig(target_mi=target_mi, endpoint=ep_options or {}))
        res = endpoint_of_series(ts, mis, cfg, trend_config())
        out.update(mixing_time_s=res.mixing_time_s, plateau_mi=res.plateau_mi, endpoint=asdict(cfg),
                   endpoint_changes=[{"t_s": t, "kind": k, "mixing_time_s": m, "reason": why}
                                     for t, k, m, why in res.changes])
    return out


def _plot(path: Path, ts: list[float], mis: list[float], avgs: list[float], method: str, window: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4), dpi=100)
    ax.plot(ts, mis, ".", ms=3, alpha=0.6, label=f"MI ({method}) per frame")
    ax.plot(ts, avgs, "-", lw=2, label=f"moving average ({window})")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("mixing index")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _pick_count(source: list[str], n_frames: int) -> int:
    """How many frames :func:`_pick_frames` will try to give (images: exact; a video: at most)."""
    from vision.sources import _image_paths, source_kind

    spec = source if len(source) > 1 else source[0]
    kind = source_kind(spec)
    if kind == "image":
        return 1
    if kind in ("folder", "images"):
        return max(1, min(n_frames, len(_image_paths(spec))))
    return n_frames


def _pick_frames(source: list[str], n_frames: int) -> Iterator[tuple[str, np.ndarray]]:
    """Up to ``n_frames`` readable frames spread evenly over the source, as (name, image), read
    one at a time (``classes suggest --frames 500`` holds no more than it must)."""
    from vision.sources import _image_paths, open_source, read_image, source_kind

    spec = source if len(source) > 1 else source[0]
    kind = source_kind(spec)
    if kind in ("folder", "images", "image"):
        from pathlib import Path as _P

        paths = [_P(str(spec))] if kind == "image" else _image_paths(spec)
        if kind == "image" and not paths[0].exists():
            raise FileNotFoundError(f"no such file: {paths[0]}")
        m = min(n_frames, len(paths))
        idx = sorted({round(i * (len(paths) - 1) / max(m - 1, 1)) for i in range(m)})
        for i in idx:
            img, err = read_image(paths[i])
            if err:
                if kind == "image":
                    raise VisionError(err)
                continue
            yield paths[i].name, img
        return
    total = 0
    if kind == "video":
        import cv2

        cap = cv2.VideoCapture(str(spec))
        total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        cap.release()
    step = max(1, total // n_frames) if total > 0 else 10
    got = 0
    for fr in open_source(spec, reconnect=False):
        if fr.index % step == 0 and not fr.error:
            yield fr.name or str(fr.index), fr.image
            got += 1
        if got >= n_frames:
            break


_SIDE = ("bottom", "right", "top", "left")  # where gravity's down lies in the image per quarter turn


@classes_app.command("suggest")
def suggest_cmd(
    source: list[str] = typer.Argument(..., help="Frames with both particle kinds: images, a folder, a video."),
    k: int = typer.Option(2, "--k", help="Number of particle classes (2..6)."),
    roi: str | None = typer.Option(None, "--roi", help="Drum circle cx,cy,r in px (overrides detection)."),
    n_frames: int = typer.Option(12, "--frames", help="Frames to learn from, spread over the source (1..500)."),
    preview: Path | None = typer.Option(None, "--preview", help="PNG: a frame beside its class map."),
    drum_diameter_mm: float | None = typer.Option(
        None, "--drum-diameter-mm", help="The drum's inner diameter (mm): also write the twin's mixer (\\[drum], "
        "[\\[particles]]) measured in the frames."),
    drum_depth_mm: float | None = typer.Option(
        None, "--drum-depth-mm", help="With --drum-diameter-mm: the end plates' distance (mm); default a "
        "monolayer drum (one particle thick)."),
    rotation: float | None = typer.Option(
        None, "--camera-rotation-deg",
        help="How far the camera is turned (deg, counter-clockwise as seen); default: from where the bed lies."),
    mirror: bool = typer.Option(False, "--mirror", help="The drum is filmed through a mirror."),
) -> None:
    """Learn the particle colours from the bed over many frames and print a ready TOML config."""
    from vision.config import config_to_toml
    from vision.roi import detect_drum, parse_roi
    from vision.suggest import OPENING_GRID, class_preview, suggest_classes

    _check_number("--k", k, 2, 6)
    _check_number("--frames", n_frames, 1, 500)
    if drum_diameter_mm is not None:
        _check_number("--drum-diameter-mm", drum_diameter_mm, 10.0, 1e4)
    if drum_depth_mm is not None:
        if drum_diameter_mm is None:
            raise VisionError("--drum-depth-mm needs --drum-diameter-mm")
        _check_number("--drum-depth-mm", drum_depth_mm, 0.1, 1e4)
    if rotation is not None:
        _check_number("--camera-rotation-deg", rotation, -360, 360)
    if preview is not None and not preview.parent.exists():
        raise VisionError(f"--preview folder does not exist: {preview.parent}")
    if preview is not None and preview.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise VisionError(f"--preview must be a .png or .jpg file, got {preview.name}")
    manual = parse_roi(roi) if roi else None
    seen: list[str] = []  # names of the frames used (the first frame is kept for the preview)
    rois: list = []
    first: list[np.ndarray] = []
    skipped: list[str] = []
    done: list[bool] = []  # the source read to its end
    census_frames: list[np.ndarray] = []

    def stream() -> Iterator[np.ndarray]:
        """The picked frames, one at a time; frames without a drum are left out (and named)."""
        for name, img in _pick_frames(source, n_frames):
            if img.ndim != 3:
                raise VisionError(f"{name} is a grayscale image; colour classes need colour frames")
            if manual is None:  # find the drum in each frame; leave out (and name) the frames without one
                try:
                    rois.append(detect_drum(img))
                except VisionError as exc:
                    skipped.append(f"{name}: {exc}")
                    continue
            seen.append(name)
            if not first:
                first.append(img)
            if drum_diameter_mm is not None and len(census_frames) < CENSUS_MAX_FRAMES:
                census_frames.append(img)  # the mixer's census measures these again (bounded)
            yield img
        done.append(True)

    try:  # (``rois`` grows as the stream goes: each frame's drum is found before it is handed over)
        cfg = suggest_classes(stream(), manual, k=k, rois=None if manual else rois, camera_rotation_deg=rotation,
                              mirror=mirror, n_frames=_pick_count(source, n_frames))
    except VisionError as exc:
        if seen or not done:  # an error of a frame or of the fit, not an empty source
            raise
        if not skipped:
            raise VisionError("no readable frames in the source") from None
        if len(skipped) == 1:
            raise VisionError(skipped[0]) from None
        _warn([f"{w.split(': ', 1)[0]} left out: {w.split(': ', 1)[1]}" for w in skipped])
        raise VisionError(f"none of the {len(skipped)} frames shows a drum that can be found; "
                          "pass --roi cx,cy,r") from exc
    _warn([f"{w.split(': ', 1)[0]} left out: {w.split(': ', 1)[1]}" for w in skipped])
    picked = [(seen[0], first[0])]
    r0 = manual or rois[0]
    names = ", ".join(c.name for c in cfg.counted)
    comment = (f"suggested by `drumtwin classes suggest` from {len(seen)} frame(s) ({picked[0][0]} ...); "
               f"classes: {names}.\nLearned colour model (CIELAB Gaussians); the first two classes give the MI.\n"
               "The drum is detected per frame size; add roi = [cx, cy, r] under [meter] to fix it.")
    if cfg.opening:
        why = (f"particles about {cfg.stride * OPENING_GRID:.0f} px or more across: opened on a grid of stride "
               f"{cfg.stride}" if cfg.stride > 1 else "it moved a class centroid by more than 1% of R on these frames")
        comment += (f"\nopening = true ({why}): it drops the thin rims and gaps that colour blur gives a class,\n"
                    "and keeps whole particles.")
        say(f"class opening on ({why})")
    if rotation is None and cfg.camera_rotation_deg:
        why = (f"camera_rotation_deg = {cfg.camera_rotation_deg:g}: the bed lies towards the image's "
               f"{_SIDE[int(cfg.camera_rotation_deg) // 90]}, so gravity points there (nearest quarter turn)")
        comment += f"\n{why}"
        say(why)
    comment += "".join(f"\nwarning: {w}" for w in cfg.warnings)
    _warn(cfg.warnings)
    if preview is not None:
        import cv2

        if not cv2.imwrite(str(preview), class_preview(picked[0][1], cfg.classes, r0)):
            raise VisionError(f"cannot write {preview}")
        say(f"preview of {picked[0][0]} -> {preview}")
    text = config_to_toml(cfg, comment)
    if drum_diameter_mm is not None:
        from twin.suggest_mixer import suggest_mixer_toml

        n = len(census_frames)
        text += "\n" + suggest_mixer_toml(cfg, census_frames, rois[:n] if rois else [r0] * n,
                                          float(drum_diameter_mm), drum_depth_mm)
    sys.stdout.write(text)


CENSUS_MAX_FRAMES = 24  # frames `classes suggest --drum-diameter-mm` keeps for the mixer's census


@bench_app.command("vision")
def bench_vision(
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object on stdout."),
    seconds: float = typer.Option(1.5, "--seconds", help="Time per measurement (s)."),
) -> None:
    """Frames/s of the centroid, GLCM and Lacey pipelines on the same frames (one thread)."""
    from vision.bench import run_vision_bench

    _check_number("--seconds", seconds, 0.01, 600)
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

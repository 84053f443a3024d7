"""``drumtwin mi``: the mixing index of every frame of a source, through the one measurement path
(``vision.stream``: frames -> readings with the no-drum policy; ``twin.frame_rows``: readings ->
trend, moving average, endpoint -> ``FrameReading``). The CSV has the columns of a run's
``frames.csv`` (``twin.records.FRAME_COLUMNS``; the twin's, the mill's and the mode's empty), so a
video measured here and replayed by ``drumtwin run --video`` gives the same rows."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import typer

from twin.cli.app import ENDPOINT_HELP, app, check_outputs, console_err, print_json, say
from twin.cli.options import check_number, warn
from vision.errors import VisionError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    import numpy as np

    from control.endpoint import EndpointConfig, EndpointStatus
    from twin.frame_rows import FrameRows, RowStep
    from twin.records import FrameReading
    from vision.config import MeterConfig
    from vision.meter import Reading
    from vision.sources import Frame
    from vision.stream import FrameMeter


class Method(StrEnum):
    centroid = "centroid"
    lacey = "lacey"
    glcm = "glcm"


class Bed(StrEnum):
    color = "color"
    dark = "dark"


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
    """Mixing index per frame: one frames.csv row per frame (as `drumtwin run` logs it), optional plot and
    overlay video."""
    from control.endpoint import EndpointDetector
    from control.trend import MITrend
    from twin.config import load_checked_config
    from twin.frame_rows import FrameRows
    from twin.run.settings import trend_config
    from vision.roi import parse_roi
    from vision.sources import open_source
    from vision.stream import FrameMeter

    check_number("--window", window, 1, 1_000_000)
    check_number("--fps", fps, 1e-3, 10_000)
    check_number("--max-frames", max_frames, 0, 10**12)
    if target_mi is not None:
        check_number("--target-mi", target_mi, 0.0, 1.0)
    cfg = load_checked_config(config).meter
    ep_cfg = _endpoint_config(cfg, target_mi, band=endpoint_band, dwell_s=endpoint_dwell_s,
                              block_s=endpoint_block_s, block_sd_max=endpoint_block_sd_max)
    warn(cfg.warnings)
    manual_roi = parse_roi(roi) if roi else None
    meter = FrameMeter(cfg.make_meter(roi=manual_roi, bed=bed.value if bed else None))
    baseline = _baseline(method, cfg, manual_roi)
    for out in (csv_out, plot, overlay_video):
        if out is not None and not out.parent.exists():
            raise VisionError(f"output folder does not exist: {out.parent}")
    check_outputs(csv_out, plot, overlay_video)  # a directory as --plot would become DIR.png
    spec = source if len(source) > 1 else source[0]
    rows = FrameRows(MITrend(trend_config()), window, EndpointDetector(ep_cfg))
    sink = _Outputs(csv_out, overlay_video, fps, cfg, stdout=not json_out)
    with sink:
        _measure(open_source(spec, fps=fps), meter, rows, baseline, sink, _frame_count(spec, max_frames),
                 max_frames, check_default=cfg.is_default and meter.meter.bed == "color")
    got = sink.got
    if plot is not None:
        _plot(plot, got.t_s, got.mi, got.ma_mi, method.value, window)
    say(f"{len(got.t_s)} frames, {got.valid} valid" + (f" -> {csv_out}" if csv_out else ""))
    if endpoint or json_out:
        summary = _mi_summary(got, method.value, ep_cfg if endpoint else None)
        if json_out:
            print_json(summary)
        elif endpoint:
            mt = summary["mixing_time_s"]
            say("endpoint: " + ("never mixed" if mt is None else f"mixed at {mt:.2f} s "
                f"(plateau MI {summary['plateau_mi']:.3f})"))


def _endpoint_config(cfg: MeterConfig, target_mi: float | None, **options: float | None) -> EndpointConfig:
    """The endpoint's settings as a run with these options and this config would have them."""
    from twin.config import RunConfig, config_endpoint, endpoint_options
    from twin.run.settings import endpoint_config

    ep_options = endpoint_options(**options)
    if cfg.endpoint_table:  # [endpoint] under the --endpoint-* options
        ep_options = config_endpoint(cfg.endpoint_table, cfg.source, ep_options)
    return endpoint_config(RunConfig(target_mi=target_mi, endpoint=ep_options))


def _baseline(method: Method, cfg: MeterConfig, roi: Any) -> Callable[[np.ndarray], float] | None:
    """The baseline index of ``--method`` (None: the centroid MI)."""
    if method is Method.lacey:
        from vision.lacey import LaceyMeter

        lacey = LaceyMeter(cfg.classes, roi or cfg.roi, opening=cfg.opening)
        return lambda img: lacey.measure(img).m
    if method is Method.glcm:
        from vision.glcm import GLCMMeter

        glcm = GLCMMeter(roi or cfg.roi)
        return lambda img: glcm.measure(img).m
    return None


def _frame_count(spec: str | list[str], max_frames: int) -> int | None:
    """How many frames the source holds, for the progress bar (None: unknown)."""
    from vision.sources import _image_paths, source_kind

    kind = source_kind(spec)
    total = len(_image_paths(spec)) if kind in ("folder", "images") else 1 if kind == "image" else None
    return max_frames if max_frames > 0 and (total is None or total > max_frames) else total


def _no_default_pixels_error() -> VisionError:
    return VisionError(
        "no pixels of the default red/blue classes in the drum: these particles need their own colours; run "
        "`drumtwin classes suggest FRAMES... --preview preview.png > mixer.toml` and pass --config mixer.toml"
    )


def _measure(frames: Iterable[Frame], meter: FrameMeter, rows: FrameRows, baseline: Callable[[np.ndarray], float]
             | None, sink: _Outputs, total: int | None, max_frames: int, *, check_default: bool) -> None:
    """Every frame through the path into ``sink``. ``check_default``: the default classes see
    nothing in the first measured frame -> the one-line advice to learn the colours."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from vision.stream import readings, with_index

    progress = Progress(TextColumn("mi"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                        console=console_err, transient=True)
    with progress:
        task = progress.add_task("frames", total=total)
        for frame, reading in readings(frames, meter, max_frames):
            if check_default and meter.measured == 1 and any(f.startswith("few_pixels") for f in reading.flags):
                raise _no_default_pixels_error()
            if baseline is not None:  # frames the meter could not measure give no baseline either
                ok = not any(f.startswith(("bad_frame", "no_drum")) for f in reading.flags)
                reading = with_index(reading, baseline(frame.image) if ok else float("nan"))
            step = rows.step(frame.t_s, frame.index, reading)
            if step is not None:  # (a source's frame times only run forward)
                sink.add(frame, reading, step)
            progress.advance(task)


@dataclass
class _Series:
    """What the plot and the summary read: per frame the time, the MI that counted (NaN when
    not valid), the moving average; the endpoint changes and its last status."""

    t_s: list[float] = field(default_factory=list)
    mi: list[float] = field(default_factory=list)
    ma_mi: list[float] = field(default_factory=list)
    valid: int = 0
    changes: list[dict[str, Any]] = field(default_factory=list)
    last: EndpointStatus | None = None

    def add(self, step: RowStep) -> None:
        row, end = step.row, step.endpoint
        self.t_s.append(row.t_s)
        self.mi.append(row.mi if step.valid else float("nan"))
        self.ma_mi.append(row.ma_mi)
        self.valid += int(step.valid)
        if end.changed:
            self.changes.append({"t_s": end.t_s, "kind": end.changed, "mixing_time_s": end.mixing_time_s,
                                 "reason": end.reason})
        self.last = end


class _Outputs:
    """Where each measured frame goes: the CSV (``--csv`` or ``stdout``; frames.csv's columns, the
    header with the first row), the ``--overlay-video`` and the series (:class:`_Series`)."""

    def __init__(self, csv_out: Path | None, video: Path | None, fps: float, cfg: MeterConfig, *,
                 stdout: bool) -> None:
        self._path = csv_out
        self._video, self._fps, self._classes = video, fps, cfg.classes
        self._fh: TextIO | None = None if csv_out is None and not stdout else sys.stdout
        self._header = False
        self._vw: Any = None
        self._size: tuple[int, int] = (0, 0)
        self.got = _Series()

    def __enter__(self) -> _Outputs:
        if self._path is not None:
            self._fh = open(self._path, "w", newline="")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._vw is not None:
            self._vw.release()
        if self._fh is not None:
            self._fh.close() if self._path is not None else self._fh.flush()

    def add(self, frame: Frame, reading: Reading, step: RowStep) -> None:
        self.got.add(step)
        if self._fh is not None:
            self._row(self._fh, step.row)
        if self._video is not None:
            self._overlay(frame, reading, step.row.ma_mi)

    def _row(self, fh: TextIO, row: FrameReading) -> None:
        """One CSV row, cell for cell as the run log writes it (``wall_s``: now)."""
        import csv

        from twin.records import FRAME_COLUMNS
        from twin.runlog import _cell

        writer = csv.writer(fh, lineterminator="\n")
        if not self._header:  # with the first row: an error before any frame leaves stdout empty
            writer.writerow(FRAME_COLUMNS)
            self._header = True
        cells = {"wall_s": time.time(), **row.as_dict()}
        writer.writerow([_cell(cells[c]) for c in FRAME_COLUMNS])

    def _overlay(self, frame: Frame, reading: Reading, ma_mi: float) -> None:
        import cv2
        import numpy as np

        from vision.overlay import draw_overlay

        img = frame.image if frame.image.size and frame.image.ndim == 3 else np.zeros((480, 640, 3), np.uint8)
        ov = draw_overlay(img, reading, self._classes, mi_avg=ma_mi)
        if self._vw is None:
            self._size = (ov.shape[1] // 2 * 2, ov.shape[0] // 2 * 2)
            self._vw = cv2.VideoWriter(str(self._video), cv2.VideoWriter.fourcc(*"mp4v"), self._fps, self._size)
            if not self._vw.isOpened():
                raise VisionError(f"cannot write video {self._video}")
        if (ov.shape[1], ov.shape[0]) != self._size:
            ov = cv2.resize(ov, self._size)
        self._vw.write(ov)


def _mi_summary(got: _Series, method: str, endpoint: EndpointConfig | None) -> dict:
    """The ``--json`` summary: frames, MI statistics and (``endpoint``: its settings) the mixing
    time, from the same trend and endpoint detector that filled the rows."""
    import numpy as np

    v = np.asarray(got.mi, float)
    ok = v[np.isfinite(v)]
    stats = {"mi_first": ok[0], "mi_last": ok[-1], "mi_mean": ok.mean(), "mi_median": np.median(ok),
             "mi_min": ok.min(), "mi_max": ok.max()} if ok.size else {}
    out: dict = {"frames": len(got.mi), "valid": int(ok.size), "method": method,
                 "duration_s": (got.t_s[-1] - got.t_s[0]) if got.t_s else 0.0,
                 **{k: float(stats[k]) if k in stats else None
                    for k in ("mi_first", "mi_last", "mi_mean", "mi_median", "mi_min", "mi_max")}}
    if endpoint is not None:
        from dataclasses import asdict

        last = got.last
        out.update(mixing_time_s=last.mixing_time_s if last else None, plateau_mi=last.plateau_mi if last else None,
                   endpoint=asdict(endpoint), endpoint_changes=got.changes)
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

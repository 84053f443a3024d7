"""One measurement path (issue 41): ``drumtwin mi`` and ``drumtwin run --video`` measure a video
through the same steps (``vision.stream``: frames -> readings and the no-drum policy;
``twin.frame_rows``: readings -> trend, moving average, endpoint -> ``FrameReading``), so they
write the same row for every frame, cell for cell, where the cell comes from the video.

The video: three black frames (a camera warming up: ``no_drum:`` rows in both), then the 42
real PMMA frames of one mixing run in time order (tests/data/real-drum-pmma and -white,
interleaved by their frame numbers), measured with classes learned from the first real frame
(a light reference: the meter tracks the light, state carried from frame to frame)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from control.device import DeviceConfig
from control.emulator import MillEmulator
from tests.cli import cli
from tests.learned import learn
from twin.records import FRAME_COLUMNS
from vision.config import config_to_toml
from vision.sources import read_image

FPS = 60.0
BLACK = 3  # frames without a drum before the real ones (within vision.stream.NO_DRUM_GRACE_S)

RUN_ONLY = {c for c in FRAME_COLUMNS if c.startswith(("twin_", "rpm_"))} | {"mode"}
"""What only a run knows: the twin's reading, the mill's speeds and the supervisor's mode
(``drumtwin mi`` leaves them empty). ``wall_s`` is when the row was written."""


def _video(path: Path, real_dirs: list[Path]) -> tuple[Path, int]:
    frames = sorted((p for d in real_dirs for p in (d / "images").glob("*.jpg")), key=lambda p: p.stem)
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), FPS, (640, 640))
    assert vw.isOpened()
    for _ in range(BLACK):
        vw.write(np.zeros((640, 640, 3), np.uint8))
    for p in frames:
        vw.write(read_image(p)[0])
    vw.release()
    return path, BLACK + len(frames)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.xdist_group("live")  # (see tests/twin/live_helpers.py)
@pytest.mark.timeout(180)
def test_mi_and_run_write_the_same_row_for_every_frame_of_a_video(real_drum_dir: Path, tmp_path: Path) -> None:
    video, n = _video(tmp_path / "pmma.avi", [real_drum_dir, real_drum_dir.parent / "real-drum-pmma-white"])
    cfg = learn([read_image(real_drum_dir / "images" / "0002.jpg")[0]], per_frame=4000)
    assert cfg.light_reference is not None  # the meter tracks the light: its state runs through the video
    conf = tmp_path / "classes.toml"
    conf.write_text(config_to_toml(cfg))
    r = cli("mi", video, "--config", conf, "--csv", tmp_path / "mi.csv")
    assert r.code == 0, r.err
    emu = MillEmulator(DeviceConfig(watchdog_s=0.0), seed=1)  # stopped: the trend's ripple is off in both
    port = emu.open_tcp(0)
    try:  # the run lasts 2 s past the video's end: every frame is processed by then
        r = cli("run", "--video", video, "--mill", f"socket://127.0.0.1:{port}", "--config", conf, "--mode", "off",
                "--no-dashboard", "--duration", n / FPS + 2.0, "--log", tmp_path / "run")
        assert r.code == 0, r.err[-2000:]
    finally:
        emu.close()
    assert emu.applied == []  # (OFF: the mill was never asked to move)
    mi, run = _rows(tmp_path / "mi.csv"), _rows(tmp_path / "run" / "frames.csv")
    assert [int(row["frame"]) for row in mi] == list(range(n))
    assert [int(row["frame"]) for row in run] == list(range(n))  # every frame, none dropped
    for a, b in zip(mi, run, strict=True):
        same = {c for c in FRAME_COLUMNS if a[c] == b[c]}
        assert set(FRAME_COLUMNS) - same <= RUN_ONLY | {"wall_s"}, (a["frame"], {c: (a[c], b[c]) for c in
                                                                                   set(FRAME_COLUMNS) - same})
        assert all(a[c] == "" for c in RUN_ONLY) and b["mode"] == "off" and b["rpm_actual"] != ""
    # what the rows compared hold: no drum in the black frames, then the run mixing under a settled trend
    assert all(row["flags"].startswith("no_drum:") and row["mi"] == "nan" for row in mi[:BLACK])
    valid = [row for row in mi[BLACK:] if row["valid"] == "1"]
    assert len(valid) >= 0.9 * (n - BLACK)
    assert float(valid[0]["mi"]) < 0.6 < 0.9 < float(valid[-1]["mi"])
    assert 0.0 < float(mi[-1]["trend_mi"]) <= 1.0 and float(mi[-1]["ma_mi"]) > float(valid[0]["mi"])


def test_frame_rows_fold_each_reading_into_its_row_as_the_filters_do() -> None:
    """``FrameRows.step``: the row's measurement cells are the reading's; valid only for an MI in
    [0, 1] flagged valid (1.5 is no vision); trend, moving average and endpoint are what
    ``MITrend``, ``MovingAverage`` and ``EndpointDetector`` give on the MI that counted (NaN
    otherwise); a frame time that goes back or is NaN is refused (None) and folds nothing in."""
    from control.endpoint import EndpointDetector
    from control.trend import MITrend, MovingAverage
    from tests.twin.workers_fakes import reading
    from twin.frame_rows import FrameRows

    rows = FrameRows(MITrend(), ma_window=3)
    trend, ma, end = MITrend(), MovingAverage(3), EndpointDetector()
    mis = [0.5, 0.6, 1.5, math.nan, 0.7, 0.8]
    for i, m in enumerate(mis):
        r = reading(m, valid=math.isfinite(m), slope=20.0 + i)
        step = rows.step(0.1 * i, i, r, rpm=4.0)
        assert step is not None
        counted = m if 0.0 <= m <= 1.0 else math.nan
        est = trend.update(0.1 * i, counted, 4.0)
        e = end.update(0.1 * i, counted, est.level, est.valid and est.settled)
        row = step.row
        assert step.valid is (counted == counted) and row.valid is step.valid
        assert (row.frame, row.t_s, row.slope_deg, row.flags) == (i, 0.1 * i, 20.0 + i, r.flags)
        assert row.mi == m or (math.isnan(m) and math.isnan(row.mi))  # the reading's, valid or not
        assert (row.trend_mi, row.trend_lo95, row.trend_hi95, row.trend_rate) == (est.level, est.lo95, est.hi95,
                                                                                  est.rate)
        assert row.ma_mi == ma.update(counted) and (row.mixed, row.mixing_time_s) == (e.mixed, e.mixing_time_s)
        assert row.twin_mi is None and row.rpm_actual is None and row.mode == ""
    assert rows.step(0.2, 9, reading(0.9)) is None and rows.step(math.nan, 9, reading(0.9)) is None
    assert rows.last_t_s == pytest.approx(0.5) and rows.ma.update(math.nan) == pytest.approx(0.7)  # 0.6, 0.7, 0.8

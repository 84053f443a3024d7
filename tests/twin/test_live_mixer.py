"""``drumtwin run --video`` of the real PMMA frames with the rig's mixer (configs/pmma-rig.toml): the live twin
holds that rig's discs and its MI at the mill's rpm follows the camera's trend; AUTO moves nothing on that bed."""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from control.device import DeviceConfig
from control.emulator import MillEmulator
from tests.cli import cli
from tests.sim.test_mixer_cli import _white_circles
from twin.runlog import read_events, read_frames

pytestmark = [pytest.mark.xdist_group("live"), pytest.mark.slow]  # (see tests/twin/live_helpers.py)

REPO = Path(__file__).resolve().parents[2]
PMMA_RIG = REPO / "configs" / "pmma-rig.toml"


def _col(rows: list[dict], name: str) -> np.ndarray:
    return np.array([float(r[name]) if r[name] not in ("", None) else np.nan for r in rows])


@pytest.mark.timeout(420)
def test_run_video_of_the_pmma_frames_twins_that_rig(real_drum_dir: Path, tmp_path: Path) -> None:
    frames = sorted((real_drum_dir / "images").glob("*.jpg"))[3:]  # the mixed frames (0002-0008: the start)
    video = tmp_path / "pmma.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 30.0, (640, 640))
    images = [cv2.imread(str(f)) for f in frames]
    for _ in range(20):  # 16 s at 30 fps
        for img in images:
            vw.write(img)
    vw.release()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # one label file is empty
        blue = [len(np.loadtxt(real_drum_dir / "labels" / f"{f.stem}.txt", ndmin=2)) for f in frames]
    emu = MillEmulator(DeviceConfig(watchdog_s=300.0), seed=1)  # turning at 10 rpm, started at its front panel
    port = emu.open_tcp(0)
    emu.set_motor(setpoint_rpm=10.0, actual_rpm=10.0, running=True)
    try:
        t0 = time.monotonic()
        r = cli("run", "--video", video, "--mill", f"socket://127.0.0.1:{port}", "--config", PMMA_RIG,
                "--mode", "auto", "--no-dashboard", "--duration", "15", "--log", tmp_path / "run")
        assert r.code == 0, r.err[-2000:]
        assert time.monotonic() - t0 < 400
        assert not any(a.cmd == "SET" for a in emu.applied)  # AUTO changed no rpm on this bed
    finally:
        emu.close()
    events = read_events(tmp_path / "run")
    seeded = [e for e in events if e["kind"] == "twin_seeded"]
    assert seeded and seeded[0]["source"] == "live frame"
    # what the frames show: the labelled blue discs and the white ones counted by Hough circles
    shown = float(np.median(blue)) + float(np.median([_white_circles(img) for img in images[::4]]))
    assert abs(seeded[0]["n_particles"] - shown) <= 0.10 * shown
    rows = read_frames(tmp_path / "run")
    twin, trend = _col(rows, "twin_mi"), _col(rows, "trend_mi")
    late = np.isfinite(twin) & np.isfinite(trend)
    late &= np.cumsum(late) > 0.5 * late.sum()  # the second half of the frames the twin ran beside
    assert late.sum() > 20
    assert abs(float(np.median(twin[late])) - float(np.median(trend[late]))) <= 0.05

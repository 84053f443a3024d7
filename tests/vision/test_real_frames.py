"""The real blue/white PMMA frames (tests/data/real-drum-pmma, CC BY 4.0) against their YOLO labels."""

import math
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.config import load_config
from vision.sources import open_source

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "pmma-blue-white.toml"


def label_centroid(path: Path, w: int, h: int):
    """Centroid of the labelled blue discs (px). All discs are the same size, so each
    disc counts once (the mean of box centres); None for a frame without labels."""
    if os.path.getsize(path) == 0:
        return None
    a = np.loadtxt(path, ndmin=2)
    return float(a[:, 1].mean() * w), float(a[:, 2].mean() * h)


@pytest.fixture(scope="module")
def readings(real_drum_dir):
    cfg = load_config(CONFIG)
    out = {}
    for fr in open_source(real_drum_dir / "images"):
        meter = cfg.make_meter()  # detect the drum on each frame independently
        out[Path(fr.name).stem] = (fr.image.shape, meter.measure(fr.image))
    return out


def test_all_frames_valid_and_drum_found(readings):
    assert len(readings) == 27
    for name, (shape, r) in readings.items():
        assert r.valid, (name, r.flags)
        # the stretched 640x640 drum: centre near the middle, radius ~ 0.49 of the side
        assert abs(r.roi.cx_px - 320) < 8 and abs(r.roi.cy_px - 320) < 8, name
        assert 295 < r.roi.r_px < 322, name


def test_blue_centroid_matches_labels(readings, real_drum_dir):
    checked = 0
    for name, (shape, r) in readings.items():
        lc = label_centroid(real_drum_dir / "labels" / f"{name}.txt", shape[1], shape[0])
        if lc is None:
            continue  # 0069 has no labels
        b = r.cls("blue")
        err = math.hypot(b.cx_px - lc[0], b.cy_px - lc[1])
        assert err < 0.03 * r.roi.r_px, f"{name}: blue centroid {err:.1f} px from the labels"
        checked += 1
    assert checked >= 26


def test_segregated_first_frame_has_clearly_lower_mi(readings):
    first = readings["0002"][1]
    later = [r.mi for name, (_, r) in readings.items() if name >= "0013"]
    assert first.mi < 0.6
    assert first.mi < min(later) - 0.25
    assert np.median(later) > 0.9
    # the bed's free surface rises to the left in these frames (drum turning clockwise)
    assert all(r.slope_deg < -10 for _, (_, r) in readings.items())

"""The real blue/white PMMA frames (tests/data/real-drum-pmma, CC BY 4.0) against their YOLO labels."""

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.learned import learn
from vision.config import load_config
from vision.sources import open_source
from vision.suggest import suggest_classes

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
def frames(real_drum_dir):
    return {Path(fr.name).stem: fr.image for fr in open_source(real_drum_dir / "images")}


@pytest.fixture(scope="module")
def labels(real_drum_dir, frames):
    return {n: label_centroid(real_drum_dir / "labels" / f"{n}.txt", img.shape[1], img.shape[0])
            for n, img in frames.items()}


def measure_all(cfg, frames):
    meter = cfg.make_meter()  # one stream: the drum is detected once per frame size
    return {n: meter.measure(img) for n, img in frames.items()}


def blue_errors(readings, labels):
    """Blue centroid error / R per labelled frame."""
    out = {}
    for n, r in readings.items():
        if labels[n] is None:
            continue  # 0069 has no labels
        b = r.cls("blue")
        out[n] = math.hypot(b.cx_px - labels[n][0], b.cy_px - labels[n][1]) / r.roi.r_px
    return out


def check_mi_order(readings):
    first = readings["0002"].mi
    later = [r.mi for n, r in readings.items() if n >= "0013"]
    assert first < 0.6 and first < min(later) - 0.25
    assert np.median(later) > 0.85


@pytest.fixture(scope="module")
def hand_readings(frames):
    return measure_all(load_config(CONFIG), frames)


def test_all_frames_valid_and_drum_found(hand_readings):
    assert len(hand_readings) == 27
    for name, r in hand_readings.items():
        assert r.valid, (name, r.flags)
        # the stretched 640x640 drum: centre near the middle, radius ~ 0.49 of the side
        assert abs(r.roi.cx_px - 320) < 8 and abs(r.roi.cy_px - 320) < 8, name
        assert 295 < r.roi.r_px < 322, name


def test_hand_config_blue_centroid_and_mi(hand_readings, labels):
    errs = blue_errors(hand_readings, labels)
    assert len(errs) == 26 and max(errs.values()) < 0.03, errs
    check_mi_order(hand_readings)
    # the bed's free surface rises to the left in these frames (drum turning clockwise)
    for r in hand_readings.values():
        assert -60 < r.slope_deg < -15 and -50 < r.slope_axis_deg < -15
    assert abs(np.median([r.slope_deg - r.slope_axis_deg for r in hand_readings.values()])) < 5


def test_classes_learned_from_the_whole_folder(frames, labels):
    cfg = learn(list(frames.values()))  # suggest_classes, learned once per code version (tests/learned.py)
    assert [c.name for c in cfg.counted] == ["blue", "white"]
    readings = measure_all(cfg, frames)
    assert all(r.valid for r in readings.values())
    errs = blue_errors(readings, labels)
    assert len(errs) == 26 and max(errs.values()) < 0.03, errs
    check_mi_order(readings)


@pytest.mark.parametrize("source", ["0002", "0020", "0069", "0097"])
def test_classes_learned_from_any_single_frame(frames, labels, source):
    """The most segregated frame, mixed ones, and the unlabelled one: the same classes in the
    same order, and the blue centroid within 3% of R on every labelled frame."""
    cfg = suggest_classes(frames[source])
    assert [c.name for c in cfg.counted] == ["blue", "white"]
    readings = measure_all(cfg, frames)
    errs = blue_errors(readings, labels)
    assert len(errs) == 26 and max(errs.values()) < 0.03, errs
    check_mi_order(readings)

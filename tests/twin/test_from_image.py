"""Seeding a twin from an observed class map keeps where each class is."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sim.drum import DrumSim
from sim.from_image import pixels_to_drum_m, seed_from_labels
from vision.roi import DrumROI


def label_map_of(sim: DrumSim, roi: DrumROI, size: int) -> np.ndarray:
    """Draw the sim's disks as a label map (1 = class 0 'red', 2 = class 1 'blue')."""
    p = sim.particles()
    lab = np.zeros((size, size), np.uint8)
    s = roi.r_px / sim.drum.radius_m
    for x, y, r, k in zip(p.x_m, p.y_m, p.r_m, p.cls, strict=True):
        cv2.circle(lab, (int(roi.cx_px + x * s), int(roi.cy_px - y * s)), max(1, int(r * s)), int(k) + 1, -1)
    return lab


def test_pixel_mapping() -> None:
    roi = DrumROI(100.0, 100.0, 80.0)
    pts = pixels_to_drum_m(np.array([100.0, 180.0, 100.0]), np.array([100.0, 100.0, 20.0]), roi, DrumSim().drum)
    assert np.allclose(pts, [[0, 0], [0.15, 0], [0, 0.15]])


@pytest.mark.timeout(60)
def test_seeded_twin_keeps_a_left_right_split() -> None:
    plant = DrumSim(case="A", seed=3, rpm=5.0)  # large (red) left, small (blue) right
    roi = DrumROI(120.0, 120.0, 110.0)
    labels = label_map_of(plant, roi, 240)
    twin = seed_from_labels(labels, roi, ["red", "blue"], rpm=5.0, seed=9, friction=0.3)
    p = twin.particles()
    n_plant = plant.particles()
    assert len(p) == len(n_plant)
    assert np.bincount(p.cls).tolist() == np.bincount(n_plant.cls).tolist()
    assert np.all(np.hypot(p.x_m, p.y_m) + p.r_m <= twin.drum.radius_m * 1.05)  # contacts are soft: a little overlap
    red_x, blue_x = p.x_m[p.cls == 0].mean(), p.x_m[p.cls == 1].mean()
    assert red_x < -0.02 and blue_x > 0.02, (red_x, blue_x)
    assert twin.rpm_actual == 5.0 and twin.params.friction == 0.3
    # a mirrored map gives a mirrored twin: the seed follows the image, not the recipe's case
    twin2 = seed_from_labels(labels[:, ::-1].copy(), roi, ["red", "blue"], rpm=5.0, seed=9)
    q = twin2.particles()
    assert q.x_m[q.cls == 0].mean() > 0.02 > q.x_m[q.cls == 1].mean()

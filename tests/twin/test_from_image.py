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


@pytest.mark.timeout(120)
def test_a_seeded_twin_is_as_mixed_as_the_bed_the_camera_sees() -> None:
    """The twin seeded from a rendered frame of a segregating paper bed (case C at 5 rpm, three
    states) has the camera's MI: the first free pixel of a class put a disk on the edge of
    its colour's blob as often as inside it, and the seeded beds came out 0.08-0.13 more
    mixed than the camera's (a what-if "from now" then starts from a better mix than the
    plant's and predicts too short a time to mix)."""
    from sim.render import Renderer
    from vision.colours import classify
    from vision.meter import Meter
    from vision.roi import roi_mask

    errs = []
    for seed, t_s in ((0, 30.0), (1, 10.0), (2, 10.0)):
        plant = DrumSim(case="C", seed=seed, rpm=5.0, friction=0.3, rolling=0.12)
        plant.advance(t_s)
        ren = Renderer(plant.drum, 240)
        img = ren.render(plant.particles())
        cam = Meter(roi=ren.roi)
        labels = classify(img, cam.classes, roi_mask(ren.roi, img.shape[:2]))
        twin = seed_from_labels(labels, ren.roi, [c.name for c in cam.classes], rpm=5.0, seed=seed)
        errs.append(Meter(roi=ren.roi).measure(ren.render(twin.particles())).mi - cam.measure(img).mi)
    assert float(np.mean(np.abs(errs))) < 0.05, errs

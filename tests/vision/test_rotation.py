"""Gravity's direction (issue 22): ``camera_rotation_deg`` and ``mirror`` under ``[meter]``.

A view is made the way a turned camera makes it: gravity's view mirrored left-right (when
mirrored), then turned counter-clockwise on screen (``np.rot90`` for quarter turns,
``cv2.warpAffine`` for any angle). The free surface, its curvature and the principal axis
come out in gravity's frame, within 1 deg of the unturned frame's, with the sign kept
(positive: rising to the right in gravity's frame).
"""

import dataclasses
import math

import cv2
import numpy as np
import pytest

from tests.learned import learn
from tests.vision.helpers import tilted_bed
from vision.config import parse_config
from vision.meter import Meter
from vision.roi import DrumROI
from vision.sources import read_image
from vision.suggest import propose_rotation_deg, suggest_classes
from vision.synthetic import particle_drum

TURNS = [(rot, mirror) for rot in (0, 90, 180, 270) for mirror in (False, True)]


def view(img: np.ndarray, rot: int, mirror: bool) -> np.ndarray:
    out = img[:, ::-1] if mirror else img
    return np.ascontiguousarray(np.rot90(out, rot // 90))  # np.rot90 turns counter-clockwise


def fold(a: float) -> float:
    return (a + 90.0) % 180.0 - 90.0


@pytest.fixture(scope="module")
def particles():
    sc = particle_drum((360, 360), slope_deg=32.0, s_shape=0.12, seed=3, particle_r_frac=0.04)
    cfg = suggest_classes([sc.image], per_frame=2500)
    return sc, cfg


@pytest.mark.parametrize(("rot", "mirror"), TURNS)
def test_quarter_turns_and_mirrors_keep_slope_and_sign(particles, rot, mirror):
    sc, cfg = particles
    ref = cfg.make_meter().measure(sc.image)
    assert ref.slope_deg > 25.0  # rising to the right, as drawn
    r = Meter(cfg.classes, camera_rotation_deg=rot, mirror=mirror).measure(view(sc.image, rot, mirror))
    assert abs(r.slope_deg - ref.slope_deg) < 1.0, (r.slope_deg, ref.slope_deg)
    assert abs(r.slope_axis_deg - ref.slope_axis_deg) < 1.0
    assert abs(r.surface_curvature - ref.surface_curvature) < 0.03
    assert ref.surface_curvature > 0.05  # (the S-shape is there to be kept)
    # the overlay's line: the image angle is gravity's turned back
    want = fold((-r.slope_deg if mirror else r.slope_deg) + rot)
    assert abs(fold(r.surface_image_deg - want)) < 1e-6
    assert math.hypot(r.surface_mid_px[0] - r.roi.cx_px, r.surface_mid_px[1] - r.roi.cy_px) < r.roi.r_px
    assert abs(r.mi - ref.mi) < 0.02  # the MI does not care how the camera is turned


@pytest.mark.parametrize("angle", [10.0, 37.0, 200.0, 333.0])
def test_any_angle(angle):
    img, roi = tilted_bed(30.0, w=480, h=480)
    m = cv2.getRotationMatrix2D((239.5, 239.5), angle, 1.0)  # counter-clockwise on screen
    turned = cv2.warpAffine(img, m, (480, 480), flags=cv2.INTER_NEAREST, borderValue=(15, 15, 15))
    r = Meter(camera_rotation_deg=angle, roi=roi).measure(turned)
    assert abs(r.slope_deg - 30.0) < 1.0, r.slope_deg
    assert abs(r.slope_axis_deg - 30.0) < 1.0


def test_a_turned_camera_without_its_rotation_says_why_there_is_no_slope():
    """The issue's 17 of 52 frames: a sideways camera gave no slope and no flag. Now the
    slope (when the fit finds no surface) comes with a no_surface flag -- and with the
    rotation set, the slope is there."""
    img, _ = tilted_bed(20.0, w=480, h=480)
    side = view(img, 90, False)
    r = Meter().measure(side)
    if math.isnan(r.slope_deg):
        assert any(f.startswith("no_surface:") for f in r.flags), r.flags
    else:  # a surface was found, but in the image's frame: 90 deg off
        assert abs(abs(r.slope_deg) - 70.0) < 2.0
    assert abs(Meter(camera_rotation_deg=90).measure(side).slope_deg - 20.0) < 1.0


REAL_TURNED = ("0002", "0022", "0036", "0064", "0097")
"""Frames 0022, 0036 and 0064 moved by 1.4-2.9 deg under a mirror or a turn before the
stride grid and the occupancy cells were anchored on the drum centre (``vision.meter``)."""


@pytest.fixture(scope="module")
def real(real_drum_dir):
    frames = [read_image(real_drum_dir / "images" / f"{n}.jpg")[0] for n in REAL_TURNED]
    return frames, learn(frames[:1], per_frame=4000)  # suggest_classes, once per code version (tests/learned.py)


def turned_roi(roi: DrumROI, shape_hw: tuple[int, int], rot: int, mirror: bool) -> DrumROI:
    """The drum where ``view`` puts it (``np.rot90``: (x, y) -> (y, W - 1 - x))."""
    h, w = shape_hw
    cx, cy = (w - 1 - roi.cx_px, roi.cy_px) if mirror else (roi.cx_px, roi.cy_px)
    for _ in range(rot // 90):
        cx, cy, w, h = cy, w - 1 - cx, h, w
    return DrumROI(cx, cy, roi.r_px)


@pytest.mark.parametrize(("rot", "mirror"), TURNS[1:])
def test_real_frames_turned_and_mirrored(real, rot, mirror):
    """Within 1 deg (the issue's bound) on the real frames with the config ``classes suggest``
    writes (stride 2, light tracking): with the drum where the turn puts it the meter samples
    the same pixels into the same cells, turned, so the fit is the same one (to rounding). The
    old box-anchored grid gave 1.5 deg on 0036 and 2.9 deg on 0022 (a stride grid of the other
    parity under a flip; cells left unanchored when the drum touches the image's edge)."""
    frames, cfg = real
    assert cfg.stride == 2  # (the case that broke: an even stride)
    for name, img in zip(REAL_TURNED, frames, strict=True):
        ref = cfg.make_meter().measure(img)
        assert math.isfinite(ref.slope_deg) and abs(ref.slope_deg) > 15.0  # (the real drum turns clockwise)
        turned = dataclasses.replace(cfg, camera_rotation_deg=float(rot), mirror=mirror)  # light tracking too
        roi = turned_roi(ref.roi, img.shape[:2], rot, mirror)
        r = turned.make_meter(roi=roi).measure(view(img, rot, mirror))
        assert abs(r.slope_deg - ref.slope_deg) < 1.0, (name, rot, mirror, r.slope_deg, ref.slope_deg)
        assert abs(r.slope_deg - ref.slope_deg) < 1e-6, (name, rot, mirror, r.slope_deg, ref.slope_deg)
        assert abs(r.surface_curvature - ref.surface_curvature) < 1e-6
        assert r.mi == pytest.approx(ref.mi, abs=1e-9)


def test_classes_suggest_proposes_the_quarter_turn(real, particles):
    frames, _ = real
    sc, _ = particles
    for rot in (0, 90, 180, 270):
        for mirror in (False, True):
            turned = [view(f, rot, mirror) for f in frames]
            assert propose_rotation_deg(turned, [Meter().measure(t).roi for t in turned]) == rot
            one = view(sc.image, rot, mirror)
            assert propose_rotation_deg([one], [Meter().measure(one).roi]) == rot


def test_suggest_on_a_turned_camera_learns_the_same_classes_and_writes_the_turn(real):
    frames, cfg0 = real
    turned = [view(f, 270, False) for f in frames[:1]]
    cfg = suggest_classes(turned, per_frame=4000)
    assert cfg.camera_rotation_deg == 270.0
    assert [c.name for c in cfg.counted] == [c.name for c in cfg0.counted]
    r = cfg.make_meter().measure(turned[0])
    ref = cfg0.make_meter().measure(frames[0])
    assert abs(r.slope_deg - ref.slope_deg) < 1.0
    assert abs(r.mi - ref.mi) < 0.03


def test_rotation_config_is_checked():
    base = '[[classes]]\nname = "a"\nhsv = [[[0, 90, 50], [10, 255, 255]]]\n' \
           '[[classes]]\nname = "b"\nhsv = [[[95, 90, 50], [130, 255, 255]]]\n'
    cfg = parse_config("[meter]\ncamera_rotation_deg = 90\nmirror = true\n" + base)
    m = cfg.make_meter()
    assert m.camera_rotation_deg == 90.0 and m.mirror
    from vision.errors import VisionError

    for bad, key in (("camera_rotation_deg = 400", "camera_rotation_deg"),
                     ("camera_rotation_deg = nan", "camera_rotation_deg"), ('mirror = "yes"', "mirror")):
        with pytest.raises(VisionError, match=key):
            parse_config(f"[meter]\n{bad}\n" + base)


def test_the_live_loop_measures_with_the_configs_turn_and_light(tmp_path, particles):
    """``drumtwin run --config``: the live loop's meter is the config's (camera turn, mirror,
    light reference), not a bare one from its classes."""
    from control.protocol import MillStatus
    from tests.twin.test_mill_worker import FakeLink
    from twin.config import RunConfig
    from twin.run.loop import LiveLoop
    from twin.runlog import RunLog

    _, cfg = particles
    turned = dataclasses.replace(cfg, camera_rotation_deg=90.0, mirror=True)
    run = RunConfig(dashboard=False, mode="off", log_dir=tmp_path / "run").resolved()
    with RunLog(tmp_path / "run") as log:
        loop = LiveLoop(run, iter(()), FakeLink(MillStatus(5.0, 5.0, True, None)), log, meter_config=turned)
        m = loop.camera.meter
        assert m.camera_rotation_deg == 90.0 and m.mirror and m._light_ref is not None

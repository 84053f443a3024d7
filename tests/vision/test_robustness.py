"""Robustness of learned classes: suggest from perturbed frames as a user would, then measure.

Synthetic drums of shaded, glossy particles (vision.synthetic.particle_drum) for several
colour pairs, and the real blue/white PMMA frames with their labels, under exposure x0.7
and x1.3, gaussian noise, JPEG quality 30, glare spots, a 10 deg rotation and half
resolution. The known class -- the first colour of a synthetic pair, blue on the real
frames -- must stay within 3% of R of its true centroid on >= 90% of the frames.

Issue 22 adds time and mounting: one meter over a stream whose light drifts (exposure and
colour temperature ramps) and jumps (auto-exposure), classes learned at set-up -- within 3%
on >= 90% of the frames and every other frame flagged ``lighting_changed:`` -- and cameras
turned by quarter turns and mirrored (see also test_lighting.py and test_rotation.py).

The classes come from the tests' memo of ``suggest_classes`` (``tests.learned.learn``: the same
result, learned once per frames, arguments and code version; the upright classes of the turned-
camera test are learned once, not once per turn).
"""

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.learned import learn
from tests.vision.helpers import jpeg, paired_errors
from vision.colours import classify
from vision.sources import read_image
from vision.synthetic import PERTURBATIONS, light_change, particle_drum, perturb

PAIRS = {
    "blue-white": ((200, 70, 10), (235, 235, 235)),
    "paleteal-white": ((205, 210, 160), (235, 235, 235)),  # low saturation
    "darkgreen-lightgreen": ((30, 110, 20), (150, 235, 150)),  # same hue, different lightness
    "red-blue": ((30, 30, 210), (200, 70, 10)),
}
# darkgreen-lightgreen was the last pair to pass: jpeg30 9.8% of R until ``classes suggest``
# learned to turn the class opening on where it moves a centroid (2.9; test_opening.py),
# glare 3.4% until the meter filled glare spots with the class mix around them (1.3;
# test_glare.py): the spots hid a fifth of the dark class in one frame, and their halos
# (dark green blended with white) took the light green's colour.


@pytest.fixture(scope="module")
def scenes():
    """Two frames per pair: segregated and partly mixed, different slopes."""
    return {name: [particle_drum((400, 300), cols, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
                   for i, (m, sl) in enumerate([(0.0, 25.0), (0.4, 35.0)])]
            for name, cols in PAIRS.items()}


@pytest.mark.parametrize("kind", PERTURBATIONS)
@pytest.mark.parametrize("pair", list(PAIRS))
def test_synthetic_pairs_under_perturbations(scenes, pair, kind):
    pert = [perturb(s.image, kind, seed=i) for i, s in enumerate(scenes[pair])]
    cfg = learn([p[0] for p in pert], per_frame=2500)
    assert len(cfg.counted) == 2
    readings = [cfg.make_meter().measure(img) for img, _ in pert]
    truths = [[tuple(a @ np.array([x, y, 1.0])) for x, y in s.centroids]
              for s, (_, a) in zip(scenes[pair], pert, strict=True)]
    errs = paired_errors(readings, truths)
    assert all(np.isfinite(errs)), [r.flags for r in readings]
    ok = sum(e < 0.03 for e in errs)
    assert ok >= 0.9 * len(errs), errs


def test_glare_is_no_class_of_its_own(scenes):
    """Glare spots (small, largely clipped) on a pair without white particles give no
    white class: both classes stay green, and the glare is no class."""
    pert = [perturb(s.image, "glare", seed=i)[0] for i, s in enumerate(scenes["darkgreen-lightgreen"])]
    cfg = learn(pert, per_frame=2500)
    assert [c.name for c in cfg.counted] == ["green-dark", "green-light"]
    for img in pert:
        r = cfg.make_meter().measure(img)
        glare = img.min(axis=2) >= 250  # the glare spots' clipped cores
        assert glare.sum() > 50
        assert (classify(img, cfg.classes)[glare] == 0).mean() > 0.9
        assert r.valid


@pytest.fixture(scope="module")
def real_frames(real_drum_dir):
    out = []
    for name in ("0002", "0097"):
        img, _ = read_image(real_drum_dir / "images" / f"{name}.jpg")
        a = np.loadtxt(real_drum_dir / "labels" / f"{name}.txt", ndmin=2)
        assert os.path.getsize(real_drum_dir / "labels" / f"{name}.txt") > 0
        out.append((img, (float(a[:, 1].mean() * img.shape[1]), float(a[:, 2].mean() * img.shape[0]))))
    return out


@pytest.mark.parametrize("kind", PERTURBATIONS)
def test_real_pmma_frames_under_perturbations(real_frames, kind):
    pert = [(perturb(img, kind, seed=i), lab) for i, (img, lab) in enumerate(real_frames)]
    cfg = learn([p[0][0] for p in pert], per_frame=4000)
    assert cfg.counted[0].name == "blue"
    errs = []
    for (img, a), lab in pert:
        r = cfg.make_meter().measure(img)
        tx, ty = a @ np.array([lab[0], lab[1], 1.0])
        b = r.cls("blue")
        errs.append(math.hypot(b.cx_px - tx, b.cy_px - ty) / r.roi.r_px)
    assert sum(e < 0.03 for e in errs) >= 0.9 * len(errs), errs


def test_perturbations_do_what_they_say():
    sc = particle_drum((240, 180), seed=0, particle_r_frac=0.06)
    img = sc.image
    dark, _ = perturb(img, "exposure0.7")
    bright, _ = perturb(img, "exposure1.3")
    assert dark.mean() < img.mean() < bright.mean()
    half, a = perturb(img, "half")
    assert half.shape == (90, 120, 3) and a[0, 0] == 0.5
    rot, a = perturb(img, "rotate10")
    assert rot.shape == img.shape and abs(math.degrees(math.atan2(-a[1, 0], a[0, 0])) - 10.0) < 1e-6
    glare, _ = perturb(img, "glare")
    assert (glare.max(axis=2) >= 250).sum() > (img.max(axis=2) >= 250).sum() + 50
    with pytest.raises(ValueError):
        perturb(img, "fog")
    assert Path(__file__).exists()


# -- issue 22: the light changes over time after set-up, and cameras are turned --------------

def light_schedule(n: int) -> list[tuple[float, float, float]]:
    """Gains (B, G, R) per frame: a drift (exposure x1 -> x0.75 with the colour temperature
    going 0 -> +1000 K over the first half), then auto-exposure jumps (x1.3, x0.7, x1.0, x1.3)."""
    from vision.synthetic import colour_temperature_gains

    out = []
    half = n // 2
    for i in range(half):
        f = i / max(half - 1, 1)
        ct = colour_temperature_gains(1000.0 * f)
        out.append(tuple((1.0 - 0.25 * f) * g for g in ct))
    jumps = (1.3, 0.7, 1.0, 1.3)
    out += [(jumps[(i // 2) % 4],) * 3 for i in range(n - half)]
    return out


def check_stream(meter, frames, truths, schedule, known):

    res = []
    for img, tru, g in zip(frames, truths, schedule, strict=True):
        r = meter.measure(light_change(img, g))
        st = r.classes[known]
        e = math.hypot(st.cx_px - tru[0], st.cy_px - tru[1]) / r.roi.r_px
        res.append((e, r.valid, any(f.startswith("lighting_changed:") for f in r.flags)))
    silent = [x for x in res if not x[2] and not (x[0] < 0.03 and x[1])]
    assert not silent, res
    assert sum(1 for e, v, f in res if e < 0.03 and v and not f) >= 0.9 * len(res), res


def stream_setup(pair):
    """Four JPEG scenes of ``pair`` (truths and images), the classes learned on the first (mix
    0.4), and the index of the class whose centroid is the scenes' ``centroids[0]``."""
    cols = PAIRS[pair] if pair != "paleteal-white" else ((232, 240, 218), (244, 244, 244))  # near white
    scenes = [particle_drum((400, 300), cols, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
              for i, (m, sl) in enumerate([(0.4, 30.0), (0.1, 28.0), (0.7, 33.0), (1.0, 25.0)])]
    images = [jpeg(s.image) for s in scenes]  # a camera's JPEG, as in test_lighting
    cfg = learn([images[0]], per_frame=2500)
    r0 = cfg.make_meter().measure(images[0])
    c0 = scenes[0].centroids[0]
    known = min((0, 1), key=lambda k: math.hypot(r0.classes[k].cx_px - c0[0], r0.classes[k].cy_px - c0[1]))
    return scenes, images, cfg, known


@pytest.mark.parametrize("pair", ["blue-white", "paleteal-white", "darkgreen-lightgreen", "red-blue"])
def test_synthetic_stream_under_drift_and_auto_exposure_jumps(pair):
    """One meter over a stream (as the live loop runs it): classes learned on one frame at
    set-up, then the light drifts and jumps; each jump is estimated on the frame it happens.
    The stream is started at each of the four scenes in turn, so every light of the schedule
    meets every bed (a bed that shows more of one class than the set-up frame misled the
    drum-wide estimate into a fixed point of mislabelled pixels: blue-white, mix 1.0, x1.3)."""
    scenes, images, cfg, known = stream_setup(pair)
    n = 16
    for track_every in (1, 4):  # every frame estimated, and the meter's default
        for start in range(4):  # each jump and each step of the ramp lands on every scene
            meter = cfg.make_meter()
            meter.track_every = track_every
            check_stream(meter, [images[(i + start) % 4] for i in range(n)],
                         [scenes[(i + start) % 4].centroids[0] for i in range(n)], light_schedule(n), known)


def test_light_estimate_holds_on_a_bed_unlike_the_setup_frame():
    """Blue-white learned on a bed at mix 0.4; the first frame is the fully mixed bed (more
    white in view) at x1.3: the drum-wide quantiles alone read red x1.60, and the per-class
    refinement started from them stayed there (white clipped, blue's labels off). Started also
    from the set-up light, the refinement that fits more channels, then closer, wins: each
    gain within 4% of 1.3, the frame valid and within 3% of R."""
    scenes, images, cfg, known = stream_setup("blue-white")
    meter = cfg.make_meter()
    r = meter.measure(light_change(images[3], 1.3))
    assert meter.light is not None and meter.light.cause is None, meter.light
    assert all(abs(g / 1.3 - 1.0) < 0.04 for g in meter.light.gains_bgr), meter.light
    tru = scenes[3].centroids[0]
    st = r.classes[known]
    assert r.valid and math.hypot(st.cx_px - tru[0], st.cy_px - tru[1]) / r.roi.r_px < 0.03, r.flags


def test_real_stream_under_drift_and_auto_exposure_jumps(real_frames, real_drum_dir):
    from tests.vision.test_real_frames import label_centroid
    from vision.sources import open_source

    frames, truths = [], []
    for fr in open_source(real_drum_dir / "images"):
        lab = label_centroid(real_drum_dir / "labels" / f"{Path(fr.name).stem}.txt", fr.image.shape[1],
                             fr.image.shape[0])
        if lab is not None:
            frames.append(fr.image)
            truths.append(lab)
    cfg = learn(frames[:1], per_frame=4000)
    assert cfg.counted[0].name == "blue"
    check_stream(cfg.make_meter(), frames, truths, light_schedule(len(frames)), 0)


@pytest.mark.parametrize(("rot", "mirror"), [(90, False), (180, True), (270, False)])
def test_turned_cameras_learn_and_measure_as_the_upright_one(scenes, real_frames, rot, mirror):
    """``classes suggest`` on frames of a turned (and mirrored) camera proposes the turn, learns
    the classes and gives each class's centroid within 3% of R and the slope within 1 deg of
    the upright camera's (synthetic pairs) -- the turned bed's top is not taken for the drum's."""
    def turn(img):
        out = img[:, ::-1] if mirror else img
        return np.ascontiguousarray(np.rot90(out, rot // 90))

    for pair in ("blue-white", "paleteal-white"):
        imgs = [s.image for s in scenes[pair]]
        up = learn(imgs, per_frame=2500)
        cfg = learn([turn(i) for i in imgs], per_frame=2500, mirror=mirror)
        assert cfg.camera_rotation_deg == rot
        assert [c.name for c in cfg.counted] == [c.name for c in up.counted]
        for img in imgs:
            a, b = up.make_meter().measure(img), cfg.make_meter().measure(turn(img))
            assert abs(a.slope_deg - b.slope_deg) < 1.0
            assert abs(a.mi - b.mi) < 0.03
    img, lab = real_frames[1]
    cfg = learn([turn(img)], per_frame=4000, mirror=mirror)
    assert cfg.camera_rotation_deg == rot and cfg.counted[0].name == "blue"
    r = cfg.make_meter().measure(turn(img))
    h, w = img.shape[:2]
    x, y = (w - 1 - lab[0], lab[1]) if mirror else lab
    for _ in range(rot // 90):  # np.rot90: (x, y) -> (y, W - 1 - x)
        x, y, w, h = y, w - 1 - x, h, w
    b = r.cls("blue")
    assert math.hypot(b.cx_px - x, b.cy_px - y) / r.roi.r_px < 0.03

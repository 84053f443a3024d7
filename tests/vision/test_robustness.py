"""Robustness of learned classes: suggest from perturbed frames as a user would, then measure.

Synthetic drums of shaded, glossy particles (vision.synthetic.particle_drum) for several
colour pairs, and the real blue/white PMMA frames with their labels, under exposure x0.7
and x1.3, gaussian noise, JPEG quality 30, glare spots, a 10 deg rotation and half
resolution. The known class -- the first colour of a synthetic pair, blue on the real
frames -- must stay within 3% of R of its true centroid on >= 90% of the frames.
"""

import math
import os
from pathlib import Path

import numpy as np
import pytest

from tests.vision.helpers import paired_errors
from vision.colours import classify
from vision.sources import read_image
from vision.suggest import suggest_classes
from vision.synthetic import PERTURBATIONS, particle_drum, perturb

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
    cfg = suggest_classes([p[0] for p in pert], per_frame=2500)
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
    cfg = suggest_classes(pert, per_frame=2500)
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
    cfg = suggest_classes([p[0][0] for p in pert], per_frame=4000)
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

"""Glare: clipped light is its own label, and the meter fills glare spots with the class mix
around them (vision.glare)."""

import math

import numpy as np
import pytest

from vision.glare import HALO, glare_fill, region_moments
from vision.meter import Meter
from vision.moments import class_tables
from vision.suggest import suggest_classes
from vision.synthetic import particle_drum, perturb

DARK_LIGHT_GREEN = ((30, 110, 20), (150, 235, 150))


def _centroid(m: np.ndarray) -> tuple[float, float]:
    return m[1] / m[0], m[2] / m[0]


def test_glare_fill_gives_the_hidden_pixels_the_mix_around_them():
    """A spot on the class-1 half, ringed by a halo of wrong labels (class 2 and none): after
    the fill class 1 has its moments without the spot, class 2 loses the halo pixels."""
    h, w = 60, 90
    truth = np.zeros((h, w), np.uint8)
    truth[:, :45] = 1
    truth[:, 45:] = 2
    labels = truth.copy()
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.hypot(xx - 20, yy - 30)
    labels[(r <= 9) & (r > 6)] = 2  # the halo: dark blended with white looks light
    labels[(r <= 6) & (r > 4)] = 0
    labels[r <= 4] = 3  # the clipped core (glare = n_classes + 1)
    assert HALO * math.sqrt((r <= 4).sum() / math.pi) + 1 > 9  # the disc covers the halo
    inside = np.ones((h, w), bool)
    origin, step = (100.0, 50.0), 2
    delta = glare_fill(labels, inside, 2, origin, step)
    for k in (1, 2):
        seen = region_moments(labels == k, origin, step)
        want = region_moments(truth == k, origin, step)
        got = seen + delta[k - 1]
        assert got[0] == pytest.approx(want[0], abs=1e-9)
        assert _centroid(got) == pytest.approx(_centroid(want), abs=1e-9)
        assert _centroid(seen) != pytest.approx(_centroid(want), abs=0.2)  # the glare did move it


def test_glare_over_the_empty_drum_adds_nothing():
    """A spot ringed by no class (the empty top of the drum): the disc fills with nothing, and
    a class pixel the halo gave a class is taken out."""
    labels = np.zeros((40, 40), np.uint8)
    labels[30:, :] = 1
    labels[10:14, 10:14] = 3
    labels[15, 12] = 1  # a stray halo pixel
    delta = glare_fill(labels, np.ones_like(labels, bool), 2, (0.0, 0.0), 1)
    assert delta[0, 0] == pytest.approx(-1.0)
    assert delta[1].tolist() == [0.0] * 6
    assert glare_fill(np.where(labels == 3, 0, labels).astype(np.uint8), np.ones_like(labels, bool), 2,
                      (0.0, 0.0), 1).tolist() == [[0.0] * 6] * 2  # no glare: no change


def test_clipped_white_is_glare_unless_an_achromatic_class_claims_it():
    def label(cfg, bgr):
        t = class_tables(cfg.classes)
        return int(t.fine[(bgr[0] << 16) | (bgr[1] << 8) | bgr[2]]), len(cfg.counted)

    for cols, white in ((((30, 30, 210), (200, 70, 10)), None), (((200, 70, 10), (235, 235, 235)), "white")):
        scenes = [particle_drum((400, 300), cols, mix=m, seed=i, particle_r_frac=0.045)
                  for i, m in enumerate((0.0, 0.4))]
        imgs = [perturb(s.image, "glare", seed=i)[0] for i, s in enumerate(scenes)]
        cfg = suggest_classes(imgs, per_frame=2500)
        lab, n = label(cfg, (255, 255, 255))
        if white is None:  # red and blue: a blue particle's highlights reach white, but white has no hue
            assert lab == n + 1
        else:
            assert cfg.counted[lab - 1].name == white


def test_the_meter_fills_glare_on_a_same_hue_pair():
    """Dark vs light green under three glare spots that hide part of the dark class: without
    the fill its centroid is off by more than 3% of R, with it by less than 2%."""
    scenes = [particle_drum((400, 300), DARK_LIGHT_GREEN, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
              for i, (m, sl) in enumerate([(0.0, 25.0), (0.4, 35.0)])]
    imgs = [perturb(s.image, "glare", seed=i)[0] for i, s in enumerate(scenes)]
    cfg = suggest_classes(imgs, per_frame=2500)
    dark = min(range(2), key=lambda k: cfg.counted[k].lab[0].mean_lab[0])
    errs = {}
    for fill in (False, True):
        meter = Meter(cfg.classes, stride=cfg.stride, opening=cfg.opening, glare_fill=fill)
        r = meter.measure(imgs[1])
        st = r.classes[dark]
        tx, ty = scenes[1].centroids[0]
        errs[fill] = math.hypot(st.cx_px - tx, st.cy_px - ty) / r.roi.r_px
        assert r.valid
    assert errs[False] > 0.03 and errs[True] < 0.02, errs


def test_a_frame_without_glare_measures_the_same_with_or_without_the_fill():
    sc = particle_drum((400, 300), DARK_LIGHT_GREEN, mix=0.3, seed=4, particle_r_frac=0.045)
    cfg = suggest_classes([sc.image], per_frame=2500)
    a = Meter(cfg.classes, glare_fill=False).measure(sc.image)
    b = Meter(cfg.classes, glare_fill=True).measure(sc.image)
    assert [(c.cx_px, c.cy_px, c.n_px) for c in a.classes] == [(c.cx_px, c.cy_px, c.n_px) for c in b.classes]


def test_many_small_glare_specks_are_filled_each_with_its_own_surroundings():
    """3000 clipped pixels scattered over a red/blue drum (salt noise, tiny highlights): each
    speck is its own spot, filled from its own ring, so the centroids stay those of the
    clean frame (within 0.3% of R)."""
    from vision.synthetic import drum_frame

    img = drum_frame((640, 480), mix=0.2, seed=1)
    salt = img.copy()
    idx = np.random.default_rng(0).integers(0, 640 * 480, 3000)
    salt.reshape(-1, 3)[idx] = 255
    clean, speckled = Meter().measure(img), Meter().measure(salt)
    for a, b in zip(clean.classes, speckled.classes, strict=True):
        assert math.hypot(a.cx_px - b.cx_px, a.cy_px - b.cy_px) / clean.roi.r_px < 0.003

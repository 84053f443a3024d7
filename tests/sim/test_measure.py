"""Particle-level MI/slope against the vision meter on rendered frames; renderer and realism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.drum import DrumSim, Particles
from sim.measure import particle_mi, particle_slope_deg, twin_meter
from sim.recipe import PAPER_DRUM
from sim.render import Realism, Renderer


@pytest.fixture(scope="module")
def running_sim():
    sim = DrumSim(case="A", seed=0, rpm=5.0)
    sim.advance(8.0)
    return sim


def test_particle_mi_and_slope_agree_with_the_vision_meter(running_sim):
    r = Renderer(running_sim, 480)
    meter = twin_meter(r)
    for _ in range(3):
        running_sim.advance(1.0)
        p = running_sim.particles()
        reading = meter.measure(r.render(p))
        pm = particle_mi(p, PAPER_DRUM)
        assert reading.valid
        assert reading.mi == pytest.approx(pm.mi, abs=0.03)
        assert reading.mi_sigmoid == pytest.approx(pm.mi_sigmoid, abs=0.03)
        assert reading.slope_deg == pytest.approx(particle_slope_deg(p, PAPER_DRUM), abs=2.0)
    assert particle_slope_deg(p, PAPER_DRUM) > 10.0  # the bed leans towards the rising wall


def test_radially_segregated_bed_has_low_eq4_but_high_eq3():
    # small disks in a core, large disks on a ring around it: centroids coincide
    ang = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    xs = np.concatenate([0.11 * np.cos(ang), 0.03 * np.cos(ang)])
    ys = np.concatenate([0.11 * np.sin(ang), 0.03 * np.sin(ang)])
    p = Particles(xs, ys, np.r_[np.full(30, 0.01), np.full(30, 0.005)], np.r_[np.zeros(30, int), np.ones(30, int)])
    m = particle_mi(p, PAPER_DRUM)
    assert m.mi_sigmoid > 0.95
    assert m.mi < 0.2


def test_renderer_colours_roi_and_realism(running_sim):
    p = running_sim.particles()
    clean = Renderer(running_sim, (320, 240)).render(p)
    assert clean.shape == (240, 320, 3) and clean.dtype == np.uint8
    r = Renderer(PAPER_DRUM, 400)
    roi = r.roi
    assert roi.cx_px == pytest.approx(199.5) and roi.r_px < 200
    img = r.render(p)
    x, y = r.to_px(p.x_m[p.cls == 0][:1], p.y_m[p.cls == 0][:1])
    assert tuple(img[int(round(y[0])), int(round(x[0]))]) == (0, 0, 220)  # a red disk's centre
    noisy = Renderer(PAPER_DRUM, 400, Realism(drop_prob=0.0, seed=1))
    a = noisy.render(p, 0.0)
    assert a is not None and a.shape == img.shape
    assert float(np.mean(np.abs(a.astype(int) - img.astype(int)))) > 2.0
    rc = twin_meter(r).measure(img)
    assert twin_meter(noisy).measure(a).valid
    # without the keystone warp (which moves pixels on purpose) noise, blur, glare, drift and
    # JPEG leave the measurement close to the clean frame's
    flat = Renderer(PAPER_DRUM, 400, Realism(drop_prob=0.0, perspective=0.0, seed=1))
    ra = twin_meter(flat).measure(flat.render(p, 5.0))
    assert ra.valid
    for name in ("red", "blue"):  # centroids and spreads move by a few px at most (of R = 162 px)
        a, c = ra.cls(name), rc.cls(name)
        assert np.hypot(a.cx_px - c.cx_px, a.cy_px - c.cy_px) < 4.0
        assert abs(a.sigma_px - c.sigma_px) < 4.0
    dropper = Renderer(PAPER_DRUM, 200, Realism(drop_prob=0.5, seed=2))
    frames = [dropper.render(p, i / 30) for i in range(40)]
    assert 5 < sum(f is None for f in frames) < 35
    assert not math.isnan(rc.mi)

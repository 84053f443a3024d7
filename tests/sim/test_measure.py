"""Particle-level MI/slope against the vision meter on rendered frames; renderer and realism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.measure import CHORD_HALF_R, free_surface, particle_axis_deg, particle_mi, particle_slope_deg, twin_meter
from sim.recipe import PAPER_DRUM
from sim.render import Realism, Renderer
from sim.twin_base import Particles


@pytest.fixture(scope="module")
def running_sim():
    sim = DrumSim(case="A", seed=0, rpm=5.0)
    sim.advance(3.0)
    return sim


def test_particle_mi_and_slope_agree_with_the_vision_meter(running_sim):
    r = Renderer(running_sim, 480)
    meter = twin_meter(r)
    twin = []
    for _ in range(3):
        running_sim.advance(1.0)
        p = running_sim.particles()
        reading = meter.measure(r.render(p))
        pm = particle_mi(p, PAPER_DRUM)
        assert reading.valid
        assert reading.mi == pytest.approx(pm.mi, abs=0.03)
        assert reading.mi_sigmoid == pytest.approx(pm.mi_sigmoid, abs=0.03)
        # the principal axis is exact on a frame (the free surface: see test_free_surface_*)
        assert reading.slope_axis_deg == pytest.approx(particle_axis_deg(p, PAPER_DRUM), abs=0.5)
        twin.append(particle_slope_deg(p, PAPER_DRUM))
    assert np.mean(twin) > 15.0  # the bed leans towards the rising wall


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


def _bed(surface, r=0.005, big_r=PAPER_DRUM.radius_m, extra=()):
    """A packed bed of equal disks (hexagonal lattice) below the surface ``y = surface(x)``."""
    xs, ys = [], []
    dy = r * math.sqrt(3.0)
    for j, y in enumerate(np.arange(-big_r, big_r, dy)):
        for x in np.arange(-big_r + (j % 2) * r, big_r, 2 * r):
            if math.hypot(x, y) < big_r - r and y + r <= surface(x):
                xs.append(x)
                ys.append(y)
    for x, y in extra:
        xs.append(x)
        ys.append(y)
    n = len(xs)
    return Particles(np.array(xs), np.array(ys), np.full(n, r), np.zeros(n, dtype=int))


@pytest.mark.parametrize("angle_deg", [-20.0, 10.0, 35.0, 45.0])
def test_free_surface_slope_of_beds_with_known_surfaces(angle_deg):
    t = math.tan(math.radians(angle_deg))
    fs = free_surface(_bed(lambda x: t * x - 0.01), PAPER_DRUM)
    assert fs.slope_deg == pytest.approx(angle_deg, abs=1.5)  # a lattice bed: a jagged surface
    # a straight surface, up to the lattice's steps where it meets the wall: the meter's cubic runs through
    # every surface point (vision.slope.fit_surface_points; an S-shaped bed reads 0.13-2, below)
    assert abs(fs.curvature) < 0.1
    assert fs.n_columns > 40
    assert abs(fs.x_mid_m) < 0.3 * PAPER_DRUM.radius_m


def test_free_surface_sees_the_s_shape_and_ignores_a_flying_disk():
    half = CHORD_HALF_R * PAPER_DRUM.radius_m
    t = math.tan(math.radians(30.0))
    s_shaped = free_surface(_bed(lambda x: t * x - 0.02 * (x / half) ** 3), PAPER_DRUM)
    assert s_shaped.curvature > 0.1  # steeper in the middle, flatter at both ends
    mirrored = free_surface(_bed(lambda x: -t * x + 0.02 * (x / half) ** 3), PAPER_DRUM)
    assert mirrored.slope_deg < -20 and mirrored.curvature > 0.1  # the sign does not depend on the lean
    reverse = free_surface(_bed(lambda x: t * x + 0.01 * (x / half) ** 3), PAPER_DRUM)
    assert reverse.curvature < -0.05
    flat = free_surface(_bed(lambda x: t * x), PAPER_DRUM)
    flying = free_surface(_bed(lambda x: t * x, extra=[(0.0, 0.08)]), PAPER_DRUM)
    assert flying.slope_deg == pytest.approx(flat.slope_deg, abs=0.5)
    # the principal axis of the same bed is a different (flatter) number than its free surface
    assert particle_axis_deg(_bed(lambda x: t * x - 0.02 * (x / half) ** 3), PAPER_DRUM) < s_shaped.slope_deg
    empty = Particles(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=int))
    assert math.isnan(free_surface(empty, PAPER_DRUM).slope_deg)


@pytest.mark.parametrize("angle_deg", [-40.0, 0.0, 25.0])
def test_the_one_surface_fit_reads_exact_surface_points(angle_deg):
    """vision.slope.fit_surface_points, the fit the camera and the twin share: points on a straight line
    (image y down) give its angle and no S-shape, a point far off it does not move the angle, and a
    profile steeper in the middle reads a positive S-shape."""
    from vision.slope import fit_surface_points

    t = math.tan(math.radians(angle_deg))
    x = np.linspace(-0.1, 0.1, 60)
    flat = fit_surface_points(x, -(t * x), 0.15, 1e-4)
    assert flat.slope_deg == pytest.approx(angle_deg, abs=1e-6) and abs(flat.curvature) < 1e-9
    assert flat.n_points == 60 and flat.mid_px[0] == pytest.approx(0.0, abs=1e-12)
    y_out = -(t * x)
    y_out[30] -= 0.05  # one flying particle above the surface
    assert fit_surface_points(x, y_out, 0.15, 1e-4).slope_deg == pytest.approx(angle_deg, abs=0.01)
    s = fit_surface_points(x, -(np.tan(np.radians(30.0)) * x - 0.5 * x ** 3 / 0.15 ** 2), 0.15, 1e-4)
    assert s.curvature > 0.1
    assert math.isnan(fit_surface_points(x[:4], -(t * x[:4]), 0.15, 1e-4).slope_deg)  # too few points

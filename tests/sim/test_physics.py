"""The physics matches the paper qualitatively (seeded short runs; the full runs are in docs/validation.md)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.drum import DrumSim
from sim.measure import particle_mi
from sim.recipe import PAPER_DRUM


def _curve(case: str, seed: int, duration_s: float, rpm: float = 5.0, every_s: float = 1.0):
    sim = DrumSim(case=case, seed=seed, rpm=rpm)
    eq4, eq3 = [], []
    for i in range(int(duration_s / every_s) + 1):
        if i:
            sim.advance(every_s)
        m = particle_mi(sim.particles(), PAPER_DRUM)
        eq4.append(m.mi)
        eq3.append(m.mi_sigmoid)
    return np.array(eq4), np.array(eq3), sim


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_case_c_at_5_rpm_segregates_radially_small_core_large_periphery():
    # two seeds: when the core forms varies from seed to seed (seed 0 of the converged step, t_c/8, still
    # reads 0.93 at 20 s, seed 1 0.76; 8 seeds average 0.81 over the last 20 s of 60, docs/validation.md 4)
    runs = [_curve("C", seed, 20.0) for seed in (0, 1)]
    eq4 = np.mean([r[0] for r in runs], axis=0)
    eq3 = np.mean([r[1] for r in runs], axis=0)
    assert eq4[:2].mean() > 0.85
    assert eq4[-6:].mean() < eq4[:2].mean() - 0.05
    assert eq4[-6:].mean() < eq3[-6:].mean()  # eq. 4 sees what eq. 3 misses
    # radial segregation: small disks sit closer to the bed's centre than large ones
    gaps = []
    for _, _, sim in runs:
        p = sim.particles()
        a = np.pi * p.r_m**2
        cx, cy = np.dot(a, p.x_m) / a.sum(), np.dot(a, p.y_m) / a.sum()
        dist = np.hypot(p.x_m - cx, p.y_m - cy)
        gaps.append(dist[p.cls == 0].mean() - dist[p.cls == 1].mean())
    assert np.mean(gaps) > 0.005

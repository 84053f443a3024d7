"""Rolling friction at contacts (constant directional torque) and the contact statistics."""

from __future__ import annotations

import numpy as np
import pytest

from sim.contacts import STAT_AIRBORNE, STAT_CONTACTS, STAT_OVERLAP_MAX, STAT_WALL_MAX, contact_pass
from sim.drum import DrumSim

R = np.array([0.01, 0.005, 0.005])  # disk radii, m
INERTIA = 0.4 * np.array([1.0, 0.25, 0.25]) * R**2
IDS = np.array([11, 22, 33], dtype=np.uint64)  # body ids of disks 0, 1, 2; 99 = the wall
WALL = np.uint64(99)


def _pass(pairs, jn, w, w_wall=0.0, mu_r=0.1, overlap=None):
    """Run the kernel on contacts ``pairs`` (body ids) with normal impulses ``jn`` along +y."""
    m = len(pairs)
    ids = np.array(pairs, dtype=np.uint64).reshape(m, 2)
    fl = np.zeros((m, 5))
    fl[:, 1] = jn  # total impulse along the normal
    fl[:, 3] = 1.0  # normal +y
    fl[:, 4] = -np.asarray(overlap if overlap is not None else np.zeros(m))
    order = np.argsort(IDS)
    w_space = np.asarray(w, float).copy()
    hist = np.zeros(1001, dtype=np.int64)
    acc = np.zeros(4)
    contact_pass(ids, fl, IDS[order], order.astype(np.int64), R, 1.0 / INERTIA, np.arange(3), w_space,
                 w_wall, mu_r, 0.005, hist, acc)
    return w_space, hist, acc


def test_rolling_torque_opposes_the_relative_rotation_and_scales_with_the_normal_force():
    w0 = [5.0, -3.0, 0.0]
    w, _, _ = _pass([(11, 22)], [1e-4], w0)
    assert w[0] < w0[0] and w[1] > w0[1]  # relative rotation 8 rad/s is braked from both sides
    assert w[2] == 0.0  # no contact, no torque
    # magnitude mu_r * r_i * J_n / I_i on each disk
    assert w0[0] - w[0] == pytest.approx(0.1 * R[0] * 1e-4 / INERTIA[0])
    assert w[1] - w0[1] == pytest.approx(0.1 * R[1] * 1e-4 / INERTIA[1])
    w2, _, _ = _pass([(11, 22)], [2e-4], w0)
    assert w0[0] - w2[0] == pytest.approx(2 * (w0[0] - w[0]))
    # disks rolling together (same spin) feel nothing
    w3, _, _ = _pass([(11, 22)], [1e-4], [2.0, 2.0, 0.0])
    assert list(w3[:2]) == [2.0, 2.0]


def test_rolling_torque_never_reverses_the_relative_rotation():
    w, _, _ = _pass([(11, 22)], [10.0], [0.2, 0.1, 0.0])  # a huge impulse on a small relative spin
    assert w[0] - w[1] == pytest.approx(0.0, abs=1e-12)  # stopped, not reversed
    # against the wall: the disk is braked towards the drum's rate, never past it
    w, _, _ = _pass([(11, WALL)], [10.0], [3.0, 0.0, 0.0], w_wall=0.5)
    assert w[0] == pytest.approx(0.5)
    w, _, _ = _pass([(11, WALL)], [1e-5], [3.0, 0.0, 0.0], w_wall=0.5)
    assert 0.5 < w[0] < 3.0


def test_contact_statistics_overlaps_wall_depth_and_airborne():
    _, hist, acc = _pass([(11, 22), (22, WALL)], [0.0, 0.0], [0, 0, 0], mu_r=0.0, overlap=[0.0005, 0.0012])
    assert acc[STAT_CONTACTS] == 1
    assert acc[STAT_OVERLAP_MAX] == pytest.approx(0.1)  # 0.5 mm of a 5 mm small radius
    assert acc[STAT_WALL_MAX] == pytest.approx(0.0012)
    assert acc[STAT_AIRBORNE] == pytest.approx(1 / 3)  # disk 2 touches nothing
    assert hist.sum() == 1 and hist[50] == 1  # bins of 0.002 small radii


def test_a_disk_in_free_flight_keeps_its_spin():
    sim = DrumSim(case="C", seed=0, rpm=5.0, settle_s=0.1)
    body = sim._bodies[0]
    body.position = (0.0, 0.12)  # near the top of the drum, far above the bed
    body.velocity = (0.0, 0.0)
    body.angular_velocity = 7.0
    sim.advance(0.02)  # 40 steps of falling, still far from the bed
    assert sim.contact_counts()[0] == 0
    assert sim._bodies[0].angular_velocity == pytest.approx(7.0)

"""Known answers for the paper's equations and the baselines (issue 27).

Every expected number here is computed by hand from the paper's definitions
(Byun & Son 2024, eq. 1, 3, 4; DESIGN.md), not by calling the code under test:
``f(x) = 1 - 1/(1 + exp(-10 (x - 1/2)))`` gives f(1/4) = e^2.5 / (1 + e^2.5),
f(1/2) = 1/2, f(3/4) = 1 / (1 + e^2.5), f(0) = e^5 / (1 + e^5).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from vision.glcm import GLCMMeter
from vision.lacey import lacey_from_labels
from vision.mixing import characteristic_distance, mixing_indices, sigmoid_f
from vision.roi import DrumROI

F_QUARTER = 0.9241418199787566  # e^2.5 / (1 + e^2.5)
F_THREE_QUARTERS = 0.07585818002124355  # 1 / (1 + e^2.5)
F_ZERO = 0.9933071490757153  # e^5 / (1 + e^5)
F_ONE = 0.0066928509242848554  # 1 / (1 + e^5)


@pytest.mark.parametrize(
    ("x", "want"), [(0.0, F_ZERO), (0.25, F_QUARTER), (0.5, 0.5), (0.75, F_THREE_QUARTERS), (1.0, F_ONE)]
)
def test_sigmoid_at_hand_computed_points(x, want):
    assert sigmoid_f(x) == pytest.approx(want, abs=1e-12)
    assert float(sigmoid_f(np.array([x]))[0]) == pytest.approx(want, abs=1e-12)


def test_characteristic_distance_is_the_centroid_distance_of_two_half_discs():
    """d_c = 8R/(3 pi): measured on a pixel disc split into halves (left/right and top/bottom)."""
    r = 400.0
    yy, xx = np.mgrid[-450:451, -450:451].astype(np.float64)
    disc = xx**2 + yy**2 <= r * r
    for half in (xx < 0, yy < 0):
        a, b = disc & half, disc & ~half
        d = math.hypot(xx[a].mean() - xx[b].mean(), yy[a].mean() - yy[b].mean())
        assert d == pytest.approx(characteristic_distance(r), rel=2e-3)
    assert characteristic_distance(r) == pytest.approx(8 * r / (3 * math.pi), rel=1e-15)


R_PX = 300.0
DC = 8 * R_PX / (3 * math.pi)


@pytest.mark.parametrize(
    ("c2", "s2", "mi_sig", "mi"),
    [
        ((DC / 2, 0.0), 50.0, 0.5, 0.5 * F_ZERO),  # horizontal d = d_c/2, equal spreads
        ((0.0, DC / 4), 50.0, F_QUARTER, F_QUARTER * F_ZERO),  # vertical d = d_c/4
        ((0.0, -3 * DC / 4), 50.0, F_THREE_QUARTERS, F_THREE_QUARTERS * F_ZERO),  # vertical, other sign
        ((0.0, 0.0), 50.0 + 0.75 * DC / 2, F_ZERO, F_ZERO * F_THREE_QUARTERS),  # dsigma = 3/4 sigma_c
        ((0.6 * DC / 4, 0.8 * DC / 4), 50.0 + DC / 4, F_QUARTER, F_QUARTER * 0.5),  # oblique, dsigma = sigma_c/2
    ],
)
def test_eq3_and_eq4_at_hand_computed_points(c2, s2, mi_sig, mi):
    out = mixing_indices((0.0, 0.0), c2, 50.0, s2, R_PX)
    assert out.mi_sigmoid == pytest.approx(mi_sig, abs=1e-12)
    assert out.mi == pytest.approx(mi, abs=1e-12)
    assert out.d_px == pytest.approx(math.hypot(*c2), abs=1e-9)
    assert out.dsigma_px == pytest.approx(abs(s2 - 50.0), abs=1e-9)


def test_eq1_linear_index_against_the_first_distance():
    out = mixing_indices((10.0, 10.0), (10.0, 35.0), 40.0, 40.0, R_PX, d0=100.0)
    assert out.mi_linear == pytest.approx(0.75, abs=1e-12)  # 1 - 25/100
    assert math.isnan(mixing_indices((0, 0), (1, 0), 1, 1, R_PX).mi_linear)
    assert math.isnan(mixing_indices((0, 0), (1, 0), 1, 1, R_PX, d0=0.0).mi_linear)


# --------------------------------------------------------------------- Lacey


def _lacey(labels: np.ndarray, cell: int = 10):
    inside = np.ones(labels.shape, dtype=bool)
    return lacey_from_labels(labels, inside, cell, np.random.default_rng(0))


def test_lacey_fully_segregated_halves_give_zero():
    labels = np.ones((40, 40), dtype=np.uint8)
    labels[:, 20:] = 2
    res = _lacey(labels)
    assert res.n_cells == 16
    assert res.s0_2 == pytest.approx(0.25, abs=1e-12)  # P (1 - P), P = 1/2
    assert res.s2 == pytest.approx(0.25, abs=1e-12)  # every cell pure
    assert res.m == pytest.approx(0.0, abs=1e-12)


def test_lacey_perfectly_ordered_mix_has_zero_cell_variance():
    labels = np.where((np.add.outer(np.arange(40), np.arange(40)) % 2) == 0, 1, 2).astype(np.uint8)
    res = _lacey(labels)
    assert res.s2 == pytest.approx(0.0, abs=1e-15)  # each 10x10 cell holds 50 + 50
    assert res.s0_2 == pytest.approx(0.25, abs=1e-12)
    assert 0.0 < res.sr_2 < res.s0_2
    assert res.m == pytest.approx(res.s0_2 / (res.s0_2 - res.sr_2), abs=1e-12)
    assert res.m > 1.0  # more even than random


def test_lacey_share_and_weights_of_an_unequal_bed():
    """P = 1/4: cells of share 1 and 0 -> s2 = s0 = P(1-P) = 3/16, m = 0."""
    labels = np.full((40, 40), 2, dtype=np.uint8)
    labels[:10, :40] = 1  # one row of four pure class-1 cells over twelve pure class-2 cells
    res = _lacey(labels)
    assert res.s0_2 == pytest.approx(3 / 16, abs=1e-12)
    assert res.s2 == pytest.approx(3 / 16, abs=1e-12)
    assert res.m == pytest.approx(0.0, abs=1e-12)


# ---------------------------------------------------------------------- GLCM


def _stripes(axis: int, size: int = 200) -> np.ndarray:
    idx = np.arange(size)
    col = np.where(idx % 2 == 0, 0, 255).astype(np.uint8)
    grey = np.broadcast_to(col[None, :] if axis == 1 else col[:, None], (size, size))
    return np.ascontiguousarray(np.repeat(grey[:, :, None], 3, axis=2))


@pytest.mark.parametrize("axis", [0, 1])
def test_glcm_one_pixel_stripes(axis):
    """Alternating 1-px stripes of grey 0 and 255 (levels 1 and 16, 16 levels): at distance 1
    three of the four angles always see the two levels (contrast 15^2), the one along the
    stripes never does -> mean contrast 0.75 * 225; the reference is 2 Var(level)."""
    img = _stripes(axis)
    meter = GLCMMeter(roi=DrumROI(100.0, 100.0, 90.0), levels=16, distances=(1,))
    res = meter.measure(img)
    assert res.contrast == pytest.approx(0.75 * 225.0, rel=1e-9)
    yy, xx = np.mgrid[0:200, 0:200]
    inside = (xx - 100.0) ** 2 + (yy - 100.0) ** 2 <= 90.0**2
    levels = np.where(img[:, :, 0] == 0, 1.0, 16.0)[inside]
    assert res.m == pytest.approx(0.75 * 225.0 / (2.0 * levels.var()), rel=1e-6)
    assert res.m == pytest.approx(1.5, rel=0.01)


def test_glcm_two_halves_is_near_zero_and_below_stripes():
    img = np.zeros((200, 200, 3), dtype=np.uint8)
    img[:, 100:] = 255
    meter = GLCMMeter(roi=DrumROI(100.0, 100.0, 90.0), levels=16, distances=(1,))
    half = meter.measure(img)
    # only the pairs straddling the boundary differ: about 180 rows of ~180 pairs per angle
    assert 0.0 < half.m < 0.03
    assert half.m < GLCMMeter(roi=DrumROI(100.0, 100.0, 90.0), levels=16, distances=(1,)).measure(_stripes(1)).m


@pytest.mark.parametrize("which", range(7))
def test_any_non_finite_input_gives_all_nan_outputs(which):
    """A missing class (any NaN centroid coordinate, spread or radius) gives NaN in every field."""
    args = [0.0, 0.0, 10.0, 0.0, 5.0, 7.0, R_PX]
    args[which] = math.nan
    out = mixing_indices((args[0], args[1]), (args[2], args[3]), args[4], args[5], args[6], d0=50.0)
    assert all(math.isnan(v) for v in (out.mi, out.mi_sigmoid, out.mi_linear, out.d_px, out.dsigma_px))


def test_small_radius_and_reference_are_valid_numbers():
    """Sub-pixel radius and reference distance are legal (a strided grid, a tiny drum): finite outputs."""
    out = mixing_indices((0.0, 0.0), (0.1, 0.0), 0.2, 0.2, 0.5, d0=0.5)
    assert math.isfinite(out.mi) and out.mi_linear == pytest.approx(0.8, abs=1e-12)
    zero_r = mixing_indices((0, 0), (1, 0), 1, 1, 0.0)
    assert math.isnan(zero_r.mi) and math.isnan(zero_r.d_px)


def test_sigmoid_far_tails_are_exact_and_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tails = sigmoid_f(np.array([-1000.0, 1000.0]))
        assert sigmoid_f(-1000.0) == 1.0 and sigmoid_f(1000.0) == pytest.approx(0.0, abs=1e-300)
    assert tails[0] == 1.0 and tails[1] == pytest.approx(0.0, abs=1e-300)
    ints = sigmoid_f(np.array([0, 1]))
    assert ints.dtype == np.float64 and ints[0] == pytest.approx(F_ZERO, abs=1e-12)


def test_sigmoid_computes_in_float64_whatever_the_input_dtype():
    x32 = np.array([0.25, 0.3], dtype=np.float32)
    out = sigmoid_f(x32)
    assert out.dtype == np.float64
    assert out[0] == pytest.approx(F_QUARTER, abs=1e-12)  # float32 arithmetic would be ~1e-8 off
    assert out[1] == sigmoid_f(float(np.float32(0.3)))

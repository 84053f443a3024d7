import math

import numpy as np
import pytest

from vision.mixing import characteristic_distance, mixing_indices, sigmoid_f


def test_sigmoid_shape():
    assert sigmoid_f(0.5) == pytest.approx(0.5)
    assert sigmoid_f(0.0) > 0.99 and sigmoid_f(1.0) < 0.01
    xs = np.linspace(-1, 3, 50)
    ys = sigmoid_f(xs)
    assert np.all(np.diff(ys) < 0)
    assert math.isnan(sigmoid_f(float("nan")))
    assert sigmoid_f(1e6) == pytest.approx(0.0) and sigmoid_f(-1e6) == pytest.approx(1.0)


def test_characteristic_distance_is_half_disc_centroid_gap():
    r = 100.0
    assert characteristic_distance(r) == pytest.approx(2 * 4 * r / (3 * math.pi))


def test_mixing_indices_equations():
    r = 200.0
    dc = characteristic_distance(r)
    m = mixing_indices((0, 0), (dc, 0), 50.0, 50.0 + dc / 2, r, d0=2 * dc)
    assert m.d_px == pytest.approx(dc)
    assert m.dsigma_px == pytest.approx(dc / 2)
    assert m.mi_sigmoid == pytest.approx(sigmoid_f(1.0))
    assert m.mi == pytest.approx(sigmoid_f(1.0) * sigmoid_f(1.0))
    assert m.mi_linear == pytest.approx(0.5)
    assert math.isnan(mixing_indices((0, 0), (1, 0), 1, 1, r).mi_linear)


def test_mixing_indices_nan_safe():
    m = mixing_indices((float("nan"), 0), (1, 0), 1, 1, 100.0)
    assert all(math.isnan(v) for v in (m.mi, m.mi_sigmoid, m.mi_linear, m.d_px, m.dsigma_px))
    assert math.isnan(mixing_indices((0, 0), (1, 0), 1, 1, 0.0).mi)

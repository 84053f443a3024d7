"""Calibration's pure rules (issue 27): the search paths through the friction box and the
arguments refused before any simulation runs. Inputs -> outputs of the public functions only,
so they hold however the slopes are probed."""

from __future__ import annotations

import math

import pytest

from sim.calibrate import FRICTION_RANGE, PATHS, ROLLING_RANGE, calibrate, path_point
from sim.errors import SimError


def test_the_box_and_paths_are_the_documented_ones():
    assert FRICTION_RANGE == (0.05, 1.0) and ROLLING_RANGE == (0.0, 1.0)
    assert PATHS == ("diagonal", "sliding-first", "rolling-first")


@pytest.mark.parametrize("path", PATHS)
def test_every_path_runs_from_the_least_to_the_most_friction_corner(path):
    assert path_point(0.0, path) == (0.05, 0.0)
    assert path_point(1.0, path) == pytest.approx((1.0, 1.0), rel=1e-12)
    assert path_point(-3.0, path) == path_point(0.0, path) and path_point(7.0, path) == path_point(1.0, path)


def test_sliding_friction_is_geometric_and_rolling_linear_on_the_diagonal():
    f, r = path_point(0.5)
    assert f == pytest.approx(math.sqrt(0.05 * 1.0), rel=1e-12) and r == pytest.approx(0.5, rel=1e-12)
    f, r = path_point(0.25)
    assert f == pytest.approx(0.05 * 20.0**0.25, rel=1e-12) and r == pytest.approx(0.25, rel=1e-12)


def test_the_two_legged_paths_change_one_friction_at_a_time():
    assert path_point(0.5, "sliding-first") == pytest.approx((1.0, 0.0), rel=1e-12)
    assert path_point(0.25, "sliding-first") == pytest.approx((math.sqrt(0.05), 0.0), rel=1e-12)
    assert path_point(0.75, "sliding-first") == pytest.approx((1.0, 0.5), rel=1e-12)
    assert path_point(0.5, "rolling-first") == pytest.approx((0.05, 1.0), rel=1e-12)
    assert path_point(0.25, "rolling-first") == pytest.approx((0.05, 0.5), rel=1e-12)
    assert path_point(0.75, "rolling-first") == pytest.approx((math.sqrt(0.05), 1.0), rel=1e-12)


def test_a_path_may_end_at_a_given_high_corner():
    assert path_point(1.0, high=(0.25, 1.0)) == pytest.approx((0.25, 1.0), rel=1e-12)
    assert path_point(0.5, high=(0.2, 0.6)) == pytest.approx((math.sqrt(0.05 * 0.2), 0.3), rel=1e-12)


def test_an_unknown_path_is_refused_by_name():
    with pytest.raises(SimError, match=r"path must be one of diagonal, sliding-first, rolling-first \(got 'zigzag'\)"):
        path_point(0.5, "zigzag")


@pytest.mark.parametrize(
    ("args", "kw", "match"),
    [(("steep", 10.0), {}, r"target slope must be a number of degrees \(got 'steep'\)"),
     ((None, 10.0), {}, "target slope must be a number"),
     ((0.0, 10.0), {}, r"between 0 and 90 degrees \(got 0.0\)"),
     ((90.0, 10.0), {}, r"between 0 and 90 degrees \(got 90.0\)"),
     ((-90.0, 10.0), {}, "between 0 and 90"),
     ((math.nan, 10.0), {}, "between 0 and 90"),
     ((math.inf, 10.0), {}, "between 0 and 90"),
     ((30.0, 0.0), {}, r"turning drum \(rpm > 0\)"),
     ((30.0, math.nan), {}, "rpm must be finite"),
     ((30.0, 10.0), {"target_curvature": math.nan}, "target curvature must be a finite number"),
     ((30.0, 10.0), {"tol_deg": 0.0}, r"tolerance must be > 0 deg \(got 0.0\)"),
     ((30.0, 10.0), {"tol_deg": math.nan}, "tolerance must be > 0 deg"),
     ((30.0, 10.0), {"max_evals": 0}, r"at least 1 search evaluation \(got 0\)")],
)
def test_bad_arguments_are_refused_before_any_simulation(args, kw, match):
    with pytest.raises(SimError, match=match):
        calibrate(*args, **kw)


def test_a_small_target_is_a_valid_angle_refused_only_by_the_range():
    """0.5 deg is a slope (0 < |target| < 90): it passes the argument check and is then refused
    because the twin cannot be that flat at 10 rpm, naming the range."""
    with pytest.raises(SimError, match=r"target slope 0\.5 deg is outside the twin's reachable range"):
        calibrate(0.5, 10.0, spin_up_s=0.5, window_s=0.5)

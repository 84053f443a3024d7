"""Calibration over (sliding, rolling friction): reach, honesty about the range, recovery of a known bed."""

from __future__ import annotations

import pytest

from sim.calibrate import FRICTION_RANGE, HIGH_EDGE, ROLLING_RANGE, calibrate, path_point, twin_slope_deg
from sim.errors import SimError

# short runs: the properties, not the numbers of docs/validation.md
QUICK = {"spin_up_s": 1.0, "window_s": 1.0}


def test_search_paths_span_the_plane_between_the_same_corners():
    for path in ("diagonal", "sliding-first", "rolling-first"):
        assert path_point(0.0, path) == (FRICTION_RANGE[0], ROLLING_RANGE[0])
        assert path_point(1.0, path) == pytest.approx((FRICTION_RANGE[1], ROLLING_RANGE[1]))
    f_s, r_s = path_point(0.5, "sliding-first")
    f_r, r_r = path_point(0.5, "rolling-first")
    assert f_s > f_r and r_s < r_r  # two different points between the corners
    with pytest.raises(SimError, match="path"):
        path_point(0.5, "sideways")
    assert path_point(1.0, "diagonal", high=(0.5, 1.0)) == pytest.approx((0.5, 1.0))  # the top of the range


def test_slope_grows_with_sliding_and_rolling_friction():
    lo = twin_slope_deg(*path_point(0.0), 10.0, **QUICK)
    hi = twin_slope_deg(*path_point(1.0), 10.0, **QUICK)
    assert hi > lo + 10.0


def test_the_end_plates_steepen_the_bed_and_a_narrower_drum_more():
    # Taberlet's side-wall friction: tan(slope) grows by about mu_w h / W; the paper's drum (W = 100 mm)
    # at 5 rpm stands about 5 deg steeper with its end plates (docs/validation.md, section 2)
    from sim.recipe import PAPER_DRUM, DrumSpec

    kw = {"spin_up_s": 2.0, "window_s": 3.0}
    without = twin_slope_deg(0.25, 0.1, 5.0, end_friction=0.0, **kw)
    paper = twin_slope_deg(0.25, 0.1, 5.0, **kw)  # end-plate friction = the wall friction
    narrow = twin_slope_deg(0.25, 0.1, 5.0, drum=DrumSpec(PAPER_DRUM.diameter_m, depth_m=0.05), **kw)
    assert paper > without + 2.5
    assert narrow > paper + 2.5


def test_a_target_outside_the_reachable_range_is_an_error_that_names_the_range():
    with pytest.raises(SimError, match=r"outside the twin's reachable range \d+\.\d-\d+\.\d deg at 10 rpm"):
        calibrate(75.0, 10.0, spin_up_s=0.5, window_s=0.5)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_calibration_reaches_the_slope_of_a_bed_with_other_parameters():
    kw = {"spin_up_s": 1.0, "window_s": 2.0}
    target = twin_slope_deg(0.4, 0.25, 10.0, seed=7, **kw)
    cal = calibrate(target, 10.0, seed=0, tol_deg=0.5, max_evals=6, **kw)
    assert abs(cal.twin_slope_deg - target) <= 1.5 and abs(cal.residual_deg) <= 1.5
    assert cal.range_deg[0] < target < cal.range_deg[1] + 1.0
    assert cal.evaluations <= 1 + len(HIGH_EDGE) + 6  # the range runs, then the search
    assert FRICTION_RANGE[0] <= cal.friction <= FRICTION_RANGE[1]
    assert ROLLING_RANGE[0] <= cal.rolling <= ROLLING_RANGE[1]


def test_bad_calibration_input():
    with pytest.raises(SimError):
        calibrate(95.0, 5.0)
    with pytest.raises(SimError, match="critical"):
        calibrate(25.0, 90.0)
    with pytest.raises(SimError):
        calibrate(25.0, 0.0)
    with pytest.raises(SimError, match="curvature"):
        calibrate(25.0, 5.0, target_curvature=float("nan"))

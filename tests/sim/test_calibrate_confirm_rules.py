"""The confirming runs' rules and the slope statistic by hand (the mutation tests of sim/calibrate_confirm.py
and sim/calibrate_slope.py's pure parts, docs/mutation.md): every answer is worked out from the module docs
on a few numbers, with binary-exact values where an edge (a tolerance, the pinned-run check) is tested. No
twin runs: a confirming measurement is a function of the path's u (``leg_point(u) = (u, 0, None)``).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from sim.calibrate_confirm import Confirmed, _next_u, confirm, fit_crossing, monotone_fit
from sim.calibrate_slope import (
    CONFIRM_RUN,
    SPIN_UP_S,
    Measured,
    SlopeRun,
    default_spin_up_s,
    frames_slope_deg,
    seeds_se_deg,
)


def along(u: float) -> tuple[float, float, None]:
    return u, 0.0, None


def reads(m) -> object:
    """A confirming measurement reading ``m(u)`` deg (se 0.1) at the point ``along(u)``."""
    return lambda f, r, e: Measured(m(f), 0.1)


def us(done: list[Confirmed]) -> list[float]:
    return [c.u for c in done]


def at(u: float, s: float) -> Confirmed:
    return Confirmed(u, along(u), Measured(s, 0.1))


def test_a_pooled_block_is_pooled_again_with_a_higher_one_before_it():
    # 5 and 1 pool to 3 (a block of two), then 4 > 3 pools all three: 10 / 3 each
    assert monotone_fit([4.0, 5.0, 1.0]) == pytest.approx([10.0 / 3.0] * 3)
    assert monotone_fit([]).shape == (0,)


def test_the_crossings_levels_group_each_pooled_run_with_its_own_level():
    # levels (0, 20), (0.5, 30), (0.7 = mean of 0.6 and 0.8, 34: 35 and 33 pooled), (1, 45); 34.5 between the last two
    u, g = fit_crossing([0.0, 0.5, 0.6, 0.8, 1.0], [20.0, 30.0, 35.0, 33.0, 45.0], 34.5)
    assert u == pytest.approx(0.7 + 0.5 / 11.0 * 0.3) and g == pytest.approx(11.0 / 0.3)


def test_the_gradient_is_the_rise_that_brackets_the_target_kept_within_the_whole_fits():
    # levels (0, 20), (0.5, 40), (1, 45): the whole fit rises 25 deg per u, the first half 40, the second 10
    assert fit_crossing([0.0, 0.5, 1.0], [20.0, 40.0, 45.0], 30.0) == pytest.approx((0.25, 40.0))
    # below the fit: its low end, with the first rise
    assert fit_crossing([0.0, 0.5, 1.0], [20.0, 40.0, 45.0], 10.0) == pytest.approx((0.0, 40.0))
    assert fit_crossing([0.0, 0.5, 1.0], [20.0, 40.0, 45.0], 42.0) == pytest.approx((0.7, 10.0))
    # (0, 20), (0.9, 21), (1, 45): the last rise is 240 per u, capped at 3 x 25; the first 1.11, raised to 25 / 3
    assert fit_crossing([0.9, 0.0, 1.0], [21.0, 20.0, 45.0], 30.0) == pytest.approx((0.9375, 75.0))  # any order
    assert fit_crossing([0.0, 0.9, 1.0], [20.0, 21.0, 45.0], 20.5) == pytest.approx((0.45, 25.0 / 3.0))


def test_the_whole_fits_rise_is_over_its_levels_own_span_of_u():
    # the first level pools u 0 and 0.4 (20 and 18 deg): the fit spans u 0.2-1, rising 26 / 0.8 = 32.5 deg per u
    assert fit_crossing([0.0, 0.4, 0.9, 1.0], [20.0, 18.0, 21.0, 45.0], 30.0) == pytest.approx((0.9375, 97.5))
    # two levels at one u (0.5): the whole fit still rises from it to 1, 50 deg per u, the gradient at its start
    assert fit_crossing([0.5, 0.5, 1.0], [20.0, 30.0, 45.0], 25.0) == pytest.approx((0.5, 50.0))
    # ... and the same at its end: 25 deg per u from 0 to 1
    assert fit_crossing([0.0, 1.0, 1.0], [20.0, 30.0, 45.0], 40.0) == pytest.approx((1.0, 25.0))


def test_a_flat_fit_has_no_gradient_and_its_one_level_is_the_crossing():
    u, g = fit_crossing([0.2, 0.6], [35.0, 25.0], 30.0)  # pooled to one level, 30 deg at u 0.4
    assert u == pytest.approx(0.4) and math.isnan(g)
    u, g = fit_crossing([0.5, 0.5], [20.0, 30.0], 25.0)  # two levels at one u: no rise to take
    assert u == 0.5 and math.isnan(g)
    u, g = fit_crossing([0.3, 0.7], [math.nan, 30.0], 25.0)  # a run without a free surface is no level
    assert u == 0.7 and math.isnan(g)
    assert all(math.isnan(x) for x in fit_crossing([0.3], [math.nan], 25.0))
    with pytest.raises(ValueError):
        fit_crossing([0.0, 0.5, 1.0], [20.0, 45.0], 30.0)  # a slope per u


def test_a_run_within_the_tolerance_ends_the_confirmation_and_one_outside_goes_on():
    line = lambda u: 20.0 + 25.0 * u  # noqa: E731
    # the fit's crossing 0.4 reads 30.5 (0.5 off: binary-exact, at the tolerance): done
    assert us(confirm(reads(lambda u: line(u) + 0.5), along, [0.0, 1.0], [20.0, 45.0], 30.0, 0.5, 3)) == [0.4]
    assert len(confirm(reads(lambda u: line(u) + 0.5), along, [0.0, 1.0], [20.0, 45.0], 30.0, 0.25, 3)) == 2
    # a run without a free surface ends it too
    assert us(confirm(reads(lambda u: math.nan), along, [0.0, 1.0], [20.0, 45.0], 30.0, 0.5, 3)) == [0.4]


def test_confirming_runs_bracket_the_target_and_take_the_secant_of_the_nearest_pair():
    curve = lambda u: 20.0 + 25.0 * u * u  # noqa: E731  (convex: 30 deg at u = sqrt(0.4))
    done = confirm(reads(curve), along, [0.0, 1.0], [20.0, 45.0], 30.0, 1e-3, 6)
    u1 = 0.4 - (curve(0.4) - 30.0) / 25.0  # 24 deg: below, a step along the fit's gradient to 0.64 (30.24: above)
    u2 = 0.4 + (30.0 - curve(0.4)) * (u1 - 0.4) / (curve(u1) - curve(0.4))  # the bracket's secant: 29.947, below
    u3 = u2 + (30.0 - curve(u2)) * (u1 - u2) / (curve(u1) - curve(u2))  # the bracket's low end is now u2, not 0.4
    assert us(done) == pytest.approx([0.4, u1, u2, u3], abs=1e-12)
    assert abs(done[-1].slope_deg - 30.0) <= 1e-3 and done[-1].point == along(u3)


def test_the_next_point_without_a_bracket_steps_along_the_secant_kept_near_the_fits_gradient():
    assert _next_u([at(0.4, 24.0)], 30.0, 25.0) == pytest.approx(0.64)  # one run: the fit's gradient
    # both below: the secant 200 deg per u capped at 3 x 25, 5 deg per u raised to 25 / 3
    assert _next_u([at(0.4, 24.0), at(0.42, 28.0)], 30.0, 25.0) == pytest.approx(0.42 + 2.0 / 75.0)
    assert _next_u([at(0.4, 24.0), at(0.6, 25.0)], 30.0, 25.0) == pytest.approx(0.6 + 5.0 / (25.0 / 3.0))
    assert _next_u([at(0.4, 24.0), at(0.5, 26.5)], 30.0, 25.0) == pytest.approx(0.5 + 3.5 / 25.0)  # within: its own
    # a bracket the wrong way round (below at the larger u: noise) is no bracket: the last two's secant
    assert _next_u([at(0.6, 31.0), at(0.7, 29.0)], 30.0, 25.0) == pytest.approx(0.7 + 1.0 / (25.0 / 3.0))


def test_a_secant_through_a_run_that_measured_nothing_is_not_a_step():
    # a NaN slope (the twin's bed unreadable) before the last run: the fit's gradient, not a NaN step
    assert _next_u([at(0.2, math.nan), at(0.5, 27.0)], 30.0, 10.0) == pytest.approx(0.5 + 3.0 / 10.0)


def test_the_bracket_is_the_nearest_confirmed_pair_around_the_target_not_the_last_two():
    # below at 0.2 (25), above at 0.6 (35) and 0.5 (31): the bracket is 0.2-0.5, not the last two (both above)
    assert _next_u([at(0.2, 25.0), at(0.6, 35.0), at(0.5, 31.0)], 30.0, 25.0) == pytest.approx(0.2 + 5.0 * 0.3 / 6.0)
    # below at 0.2 (25) and 0.4 (28), above at 0.6 (35): the bracket is 0.4-0.6
    assert _next_u([at(0.2, 25.0), at(0.6, 35.0), at(0.4, 28.0)], 30.0, 25.0) == pytest.approx(0.4 + 2.0 * 0.2 / 7.0)


def test_a_flat_or_shallow_search_leg_steps_by_its_span_at_least_one_degree_per_u():
    # the search's runs pool to one level (no gradient): a step of the leg's span, 10 deg per u
    done = confirm(reads(lambda u: 32.0), along, [0.2, 0.6], [35.0, 25.0], 30.0, 0.1, 2)
    assert us(done) == pytest.approx([0.4, 0.2])
    # a span of 0.5 deg: at least 1 deg per u
    done = confirm(reads(lambda u: 30.5), along, [0.2, 0.6], [30.5, 30.0], 30.0, 0.1, 2)
    assert us(done) == pytest.approx([0.4, 0.0])
    # a shallow fit (0.5 deg per u) keeps its own gradient
    done = confirm(reads(lambda u: 20.5), along, [0.0, 1.0], [20.0, 20.5], 20.25, 0.1, 2)
    assert us(done) == pytest.approx([0.5, 0.0])


def test_confirming_runs_stop_pinned_at_an_end_of_the_path():
    # reads 20 deg everywhere, the target 30: 0.4, then 0.8, then the path's end 1.0 (once), then no way on
    done = confirm(reads(lambda u: 20.0), along, [0.0, 1.0], [20.0, 45.0], 30.0, 0.1, 6)
    assert us(done) == pytest.approx([0.4, 0.8, 1.0])
    # a next point exactly 1e-4 from a confirmed one is a new point (the pinned check is strict)
    done = confirm(reads(lambda u: 1.0 if u > 0 else 0.0), along, [0.0, 1.0], [0.0, 1.0], 1e-4, 0.0, 5)
    assert us(done) == [1e-4, 0.0]  # then the bracket's secant, 1e-8, is pinned to 0


def test_the_slope_statistic_takes_float32_frames_in_double_and_warns_of_nothing():
    f32 = np.array([0.1, 0.2], dtype=np.float32)  # an image pipeline's frames
    assert frames_slope_deg(f32) == (float(f32[0]) + float(f32[1])) / 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an empty set of frames is NaN, not a numpy warning per call
        assert math.isnan(frames_slope_deg([]))
        assert math.isnan(frames_slope_deg([math.nan, math.nan]))
        assert math.isnan(seeds_se_deg([30.0, 31.0], 2))  # one seed
        assert math.isnan(seeds_se_deg([math.nan, math.nan, 30.0, 31.0], 2))  # one seed with a slope
    # two seeds (medians 30 and 33): sd 3 / sqrt(2) over sqrt(2) = 1.5; float32 frames in double
    assert seeds_se_deg([30.0, 30.0, 33.0, 33.0], 2) == pytest.approx(1.5)
    s32 = np.array([0.1, 0.1, 0.2, 0.2], dtype=np.float32)
    d = float(s32[2]) - float(s32[0])
    assert seeds_se_deg(s32, 2) == pytest.approx(d / math.sqrt(2) / math.sqrt(2), rel=1e-15)


def test_the_spin_up_is_a_quarter_turn_at_least_and_a_drum_at_rest_gets_the_floor():
    assert default_spin_up_s(0.0) == SPIN_UP_S == 3.0
    assert default_spin_up_s(-2.0) == pytest.approx(7.5)
    assert SlopeRun(spin_up_s=5.0).spin_up_at(10.0) == 5.0  # the run's own floor
    assert SlopeRun(spin_up_s=5.0).spin_up_at(-1.0) == pytest.approx(15.0)  # a quarter turn at 1 rpm
    assert CONFIRM_RUN.spin_up_at(10.0) == 3.0

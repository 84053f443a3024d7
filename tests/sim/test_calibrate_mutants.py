"""Calibration's decision path on a known slope field (issue 27's mutation tests of sim/calibrate.py).

``calibrate`` and ``reachable_range`` decide from the twin's slopes: the range, the bracketing
search (regula falsi kept off the ends), the tolerance, the budget, the curvature's choice among
the paths. Here the twin is replaced by a known analytic slope field (``twin_surface`` patched in
``sim.calibrate``), so every decision can be checked against a value computed by hand; the twin
itself is checked in ``test_calibrate.py`` and ``test_calibrate_real.py``. Along the diagonal to the
field's high point ``(0.5, 1.0)`` the field's slope is ``20 + 25 u`` (or ``20 + 25 u^2``).
"""

from __future__ import annotations

import math

import pytest

import sim.calibrate as cal_mod
from sim.calibrate import HIGH_EDGE, RANGE_TOL_DEG, calibrate, path_point, reachable_range
from sim.errors import SimError
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec

LOG10 = math.log(10.0)


def _u_of(f: float) -> float:
    """Position along the geometric sliding-friction axis from 0.05 (0) to 0.5 (1)."""
    return math.log(f / 0.05) / LOG10


def _g(f: float) -> float:
    """0 at sliding friction 0.05, 1 at its peak 0.5, falling above it."""
    us = _u_of(f)
    return us if us <= 1.0 else 1.0 - 1.2 * (us - 1.0)


def linear(f: float, r: float) -> float:
    """20 deg at the least-friction corner, +10 deg per decade of sliding friction up to 0.5 (and
    -12 deg per decade above: the peak of the high edge is at 0.5), +15 deg per unit rolling."""
    return 20.0 + 10.0 * _g(f) + 15.0 * r


class Field:
    """A fake ``twin_surface``: ``slope(f, r)`` (signed by ``sign``) and ``curv(f, r)``, and the calls."""

    def __init__(self, slope=linear, curv=lambda f, r: f - r, sign: float = 1.0) -> None:
        self.slope, self.curv, self.sign = slope, curv, sign
        self.calls: list[tuple[float, float, float, dict]] = []

    def __call__(self, friction: float, rolling: float, rpm: float, **kw) -> tuple[float, float]:
        self.calls.append((friction, rolling, rpm, kw))
        return self.sign * self.slope(friction, rolling), self.curv(friction, rolling)


@pytest.fixture
def field(monkeypatch) -> Field:
    f = Field()
    monkeypatch.setattr(cal_mod, "twin_surface", f)
    return f


HIGH = (0.5, 1.0)


def test_the_fields_diagonal_is_linear_and_its_high_point_is_the_middle_of_the_edge():
    edge = [20 + 10 * _u_of(0.25) + 15, 45.0, 45.0 - 12 * math.log10(2)]
    assert [linear(f, 1.0) for f in HIGH_EDGE] == pytest.approx(edge)
    for u in (0.0, 0.3, 1.0):
        assert linear(*path_point(u, "diagonal", HIGH)) == pytest.approx(20.0 + 25.0 * u, abs=1e-12)


def test_the_reachable_range_is_the_low_corner_and_the_best_high_edge_point(field):
    assert reachable_range(10.0) == pytest.approx((20.0, 45.0), abs=1e-12)
    # the low corner, then the high edge's points in order, each at |rpm| with the given seed
    assert [(c[0], c[1]) for c in field.calls] == [(0.05, 0.0)] + [(f, 1.0) for f in HIGH_EDGE]
    assert all(c[3]["seed"] == 0 for c in field.calls)  # the default seed: calibrate's too
    field.calls.clear()
    field.sign = -1.0  # the other turning direction: the slopes' magnitudes count
    assert reachable_range(-10.0, seed=3, spin_up_s=0.5) == pytest.approx((20.0, 45.0), abs=1e-12)
    assert {c[2] for c in field.calls} == {10.0}
    assert all(c[3]["seed"] == 3 and c[3]["spin_up_s"] == 0.5 for c in field.calls)


def test_a_range_whose_low_corner_is_steeper_is_still_reported_low_to_high(field):
    field.slope = lambda f, r: 40.0 - 10.0 * r - (f == 0.25) * 5.0  # corner 40, edge 30 / 25 / 30
    assert reachable_range(10.0) == (30.0, 40.0)


def test_no_free_surface_at_an_end_is_an_error_that_names_the_rpm(field):
    field.slope = lambda f, r: math.nan if r == 0.0 else 30.0
    with pytest.raises(SimError) as exc:
        reachable_range(12.5)
    assert str(exc.value) == "the twin shows no free surface at 12.5 rpm: it cannot be calibrated by slope there"
    field.slope = lambda f, r: math.nan if r == 1.0 else 30.0
    with pytest.raises(SimError, match="no free surface at 10 rpm"):
        calibrate(30.0, 10.0)


def test_the_high_end_is_the_best_finite_edge_point(field):
    field.slope = lambda f, r: 20.0 if r == 0.0 else {0.25: 30.0, 0.5: math.nan, 1.0: 35.0}[f]
    assert reachable_range(10.0) == (20.0, 35.0)
    cal = calibrate(35.0, 10.0)  # at the high end: no search, the point (1.0, 1.0)
    assert (cal.friction, cal.rolling, cal.evaluations, cal.residual_deg) == (1.0, 1.0, 4, 0.0)


def test_a_linear_path_is_solved_by_the_first_regula_falsi_step(field):
    cal = calibrate(30.0, 10.0, seed=5, spin_up_s=0.5, window_s=0.7)
    f, r = path_point(0.4, "diagonal", HIGH)
    assert (cal.friction, cal.rolling) == pytest.approx((f, r), abs=1e-12)
    assert cal.twin_slope_deg == pytest.approx(30.0, abs=1e-9) and abs(cal.residual_deg) < 1e-9
    assert cal.evaluations == 1 + len(HIGH_EDGE) + 1 and len(cal.history) == 5
    assert cal.history[4] == pytest.approx((f, r, f, 30.0))  # a deep drum's end plates take the wall's friction
    assert cal.end_friction == pytest.approx(f) and cal.end_friction_max == 0.0
    assert cal.range_deg == pytest.approx((20.0, 45.0)) and cal.path == "diagonal"
    assert cal.target_slope_deg == 30.0 and cal.rpm == 10.0 and cal.target_curvature is None
    assert cal.twin_curvature == pytest.approx(f - r)
    # every run of the twin with the calibration's seed, windows and |rpm|
    assert all(c[2] == 10.0 and c[3]["seed"] == 5 and c[3]["spin_up_s"] == 0.5 and c[3]["window_s"] == 0.7
               and c[3]["drum"] is PAPER_DRUM and c[3]["recipe"] is PAPER_RECIPE and c[3]["mixer"] is None
               and c[3]["engine"] is None for c in field.calls)


def test_a_convex_path_is_bracketed_step_by_step_and_kept_off_the_ends(field):
    # along the diagonal: 20 + 25 u^2 (rolling enters squared, sliding friction linear in u)
    field.slope = lambda f, r: 20.0 + 25.0 * r * r if f <= 0.5 else 20.0 + 25.0 * r - 3.0
    cal = calibrate(30.0, 10.0, tol_deg=0.4)
    u1 = 0.4  # (30 - 20) / (45 - 20)
    s1 = 20.0 + 25.0 * u1**2  # 24: below, the bracket's low end moves up
    u2 = u1 + (30.0 - s1) / (45.0 - s1) * (1.0 - u1)
    s2 = 20.0 + 25.0 * u2**2  # 28.16: below again
    w3 = (30.0 - s2) / (45.0 - s2)
    assert w3 < 0.15  # regula falsi would creep: the step is kept 15 % off the bracket's end
    u3 = u2 + 0.15 * (1.0 - u2)
    s3 = 20.0 + 25.0 * u3**2  # 30.10: within 0.4 deg
    assert [h[3] for h in cal.history[4:]] == pytest.approx([s1, s2, s3], abs=1e-9)
    assert cal.history[-1][:2] == pytest.approx(path_point(u3, "diagonal", HIGH), abs=1e-12)
    assert cal.residual_deg == pytest.approx(s3 - 30.0, abs=1e-9) and cal.evaluations == 7


def test_a_target_near_the_top_is_approached_from_below_the_high_end(field):
    cal = calibrate(44.0, 10.0, tol_deg=0.01)
    u1 = 0.85  # (44 - 20) / 25 = 0.96, kept 15 % off the end
    u2 = u1 + (44.0 - (20 + 25 * u1)) / (45.0 - (20 + 25 * u1)) * (1.0 - u1)
    assert [h[3] for h in cal.history[4:]] == pytest.approx([20 + 25 * u1, 20 + 25 * u2], abs=1e-9)
    assert cal.twin_slope_deg == pytest.approx(44.0, abs=1e-9)


def test_a_point_above_the_target_moves_the_brackets_high_end(field):
    # concave along the diagonal: 20 + 25 sqrt(u): the first step overshoots
    field.slope = lambda f, r: 20.0 + 25.0 * math.sqrt(r) if f <= 0.5 else 20.0 + 25.0 * r - 3.0
    cal = calibrate(30.0, 10.0, tol_deg=0.2)
    u1 = 0.4
    s1 = 20.0 + 25.0 * math.sqrt(u1)  # 35.8: above
    w2 = min(max((30.0 - 20.0) / (s1 - 20.0), 0.15), 0.85)
    u2 = 0.0 + w2 * (u1 - 0.0)
    s2 = 20.0 + 25.0 * math.sqrt(u2)
    assert [h[3] for h in cal.history[4:6]] == pytest.approx([s1, s2], abs=1e-9)
    assert abs(cal.residual_deg) <= 0.2


def test_the_search_stops_at_its_budget_with_the_best_point_found(field):
    field.slope = lambda f, r: 20.0 + 25.0 * r**6 if f <= 0.5 else 20.0 + 25.0 * r - 3.0
    cal = calibrate(30.0, 10.0, tol_deg=1e-6, max_evals=3)
    assert cal.evaluations == 4 + 3
    best = min(cal.history, key=lambda h: abs(h[3] - 30.0))
    assert (cal.friction, cal.rolling, cal.end_friction, cal.twin_slope_deg) == best
    assert cal.residual_deg == pytest.approx(best[3] - 30.0) and abs(cal.residual_deg) > 1e-3


def test_a_target_within_the_tolerance_of_an_end_needs_no_search(field):
    cal = calibrate(20.3, 10.0, tol_deg=0.4)
    assert cal.evaluations == 4 and (cal.friction, cal.rolling) == (0.05, 0.0)
    assert cal.residual_deg == pytest.approx(-0.3) and cal.twin_slope_deg == 20.0


def test_a_target_just_outside_the_range_calibrates_to_the_end_within_the_grace(field):
    assert RANGE_TOL_DEG == 1.0
    cal = calibrate(45.0 + 0.9, 10.0)
    assert (cal.friction, cal.rolling, cal.evaluations) == (0.5, 1.0, 4)
    assert cal.residual_deg == pytest.approx(-0.9)
    cal = calibrate(20.0 - 0.9, 10.0)
    assert (cal.friction, cal.rolling, cal.evaluations) == (0.05, 0.0, 4)
    assert cal.residual_deg == pytest.approx(0.9)
    assert calibrate(46.0, 10.0).residual_deg == pytest.approx(-1.0)  # the grace's edges are inside
    assert calibrate(19.0, 10.0).residual_deg == pytest.approx(1.0)


@pytest.mark.parametrize("target", [46.01, 18.99, -46.5, 3.0])
def test_a_target_beyond_the_grace_is_an_error_naming_the_range_and_the_box(field, target):
    need = "sliding friction below 0.05" if abs(target) < 20.0 else "rolling friction above 1"
    msg = (f"target slope {abs(target):.1f} deg is outside the twin's reachable range 20.0-45.0 deg at 10 rpm "
           f"(sliding friction 0.05-1, rolling friction 0-1): it needs {need}")
    with pytest.raises(SimError) as exc:
        calibrate(target, -10.0)
    assert str(exc.value) == msg
    assert len(field.calls) == 4  # the range runs only


def test_a_negative_target_and_rpm_are_fitted_by_magnitude_and_reported_with_the_targets_sign(field):
    field.sign = -1.0
    cal = calibrate(-30.0, -10.0)
    assert cal.twin_slope_deg == pytest.approx(-30.0, abs=1e-9) and cal.target_slope_deg == -30.0
    assert cal.rpm == -10.0 and {c[2] for c in field.calls} == {10.0}
    cal = calibrate(-45.9, 10.0)  # within the grace above the range: the high end, 0.9 deg short
    assert cal.twin_slope_deg == pytest.approx(-45.0) and cal.residual_deg == pytest.approx(0.9)


def test_progress_counts_every_run_against_the_whole_budget(field):
    seen: list[tuple[int, int]] = []
    calibrate(30.0, 10.0, max_evals=5, progress=lambda i, n: seen.append((i, n)))
    assert seen == [(i, 1 + len(HIGH_EDGE) + 5) for i in range(1, 6)]
    seen.clear()
    calibrate(30.0, 10.0, max_evals=2, target_curvature=0.0, progress=lambda i, n: seen.append((i, n)))
    assert seen[0] == (1, 1 + 3 + 3 * 2) and [s[0] for s in seen] == list(range(1, len(seen) + 1))


def test_no_free_surface_mid_search_ends_that_path_with_its_best_point(field):
    field.slope = lambda f, r: math.nan if 0.2 < r < 0.9 else linear(f, r)
    cal = calibrate(30.0, 10.0)
    assert cal.evaluations == 5 and math.isnan(cal.history[4][3])  # one NaN run, then no more
    assert (cal.friction, cal.rolling) == (0.05, 0.0)  # 10 deg off, the best of the ends
    assert cal.residual_deg == pytest.approx(-10.0)


def test_with_a_curvature_each_path_gives_a_point_and_the_nearest_shape_wins(field):
    field.slope = lambda f, r: 20.0 + 12.5 * (_g(f) + r)  # linear on every path to (0.5, 1)
    field.curv = lambda f, r: r - _u_of(f)  # diagonal 0, sliding-first < 0, rolling-first > 0
    want = {}
    for path in ("diagonal", "sliding-first", "rolling-first"):
        u = 0.4
        want[path] = path_point(u, path, HIGH)
    for target_curv, path in ((0.0, "diagonal"), (-0.7, "sliding-first"), (0.7, "rolling-first")):
        field.calls.clear()
        cal = calibrate(30.0, 10.0, target_curvature=target_curv)
        assert cal.path == path and (cal.friction, cal.rolling) == pytest.approx(want[path], abs=1e-12)
        assert cal.target_curvature == target_curv
        assert cal.twin_curvature == pytest.approx(field.curv(*want[path]))
        assert cal.evaluations == 4 + 3  # each path's first regula falsi step hits 30 deg


def test_the_slope_decides_before_the_curvature(field):
    # the rolling-first path's shape matches, but its slope there is 3 deg off: it may not compete
    def slope(f, r):
        s = 20.0 + 12.5 * (_g(f) + r)
        return s + 3.0 if (f < 0.06 and 0.3 < r < 1.0) else s

    field.slope = slope
    field.curv = lambda f, r: r - _u_of(f)
    cal = calibrate(30.0, 10.0, target_curvature=0.8, tol_deg=0.4, max_evals=1)
    assert cal.path == "diagonal"  # nearer to 0.8 than sliding-first's, rolling-first excluded
    assert abs(cal.residual_deg) < 1e-9


def test_when_no_path_is_within_the_tolerance_the_best_slopes_compete(field):
    field.slope = lambda f, r: 20.0 + 25.0 * r**6 if f <= 0.5 else 20.0 + 25.0 * r - 3.0
    field.curv = lambda f, r: f
    # first steps (u = 0.4): diagonal 20.1 deg, sliding-first 20 deg at friction 0.315 (the shape wanted),
    # rolling-first 26.6 deg: the best slope, 3.4 deg off: the only one that competes
    cal = calibrate(30.0, 10.0, tol_deg=1e-6, max_evals=1, target_curvature=0.315)
    assert cal.path == "rolling-first" and (cal.friction, cal.rolling) == pytest.approx((0.05, 0.8), abs=1e-12)
    assert cal.residual_deg == pytest.approx(25.0 * 0.8**6 - 10.0, abs=1e-9)


def test_a_narrower_drum_and_extra_arguments_reach_the_twin(field):
    drum = DrumSpec(PAPER_DRUM.diameter_m, depth_m=0.05)
    calibrate(30.0, 10.0, drum=drum, seed=2, friction_wall=0.3)
    assert all(c[3]["drum"] is drum and c[3]["friction_wall"] == 0.3 for c in field.calls)
    with pytest.raises(SimError, match="critical"):
        calibrate(30.0, drum.critical_rpm + 1.0, drum=drum)


def test_a_mixers_drum_sets_the_critical_speed_and_the_mixer_and_engine_reach_the_twin(field):
    from dataclasses import replace

    from sim.mixer import paper_mixer

    big = replace(paper_mixer(), drum=DrumSpec(1.0, depth_m=0.1))  # critical speed 42.3 rpm
    assert big.drum.critical_rpm < 50.0 < PAPER_DRUM.critical_rpm
    with pytest.raises(SimError, match="critical"):
        calibrate(30.0, 50.0, mixer=big)  # the paper's drum would allow 50 rpm: the mixer's drum decides
    calibrate(30.0, 10.0, mixer=big, engine="pymunk")
    assert field.calls and all(c[3]["mixer"] is big and c[3]["engine"] == "pymunk" and c[3]["drum"] is big.drum
                               for c in field.calls)


def test_a_calibration_as_a_record_has_every_field(field):
    field.curv = lambda f, r: f - r + 0.125
    cal = calibrate(30.0, 10.0, target_curvature=0.25)
    values = (cal.friction, cal.rolling, cal.twin_slope_deg, cal.residual_deg, cal.twin_curvature)
    assert len(set(values)) == len(values)  # a field read from another would show
    assert cal.as_dict() == {
        "friction": cal.friction, "rolling": cal.rolling, "end_friction": cal.friction,
        "twin_slope_deg": cal.twin_slope_deg, "residual_deg": cal.residual_deg, "target_slope_deg": 30.0,
        "rpm": 10.0, "evaluations": cal.evaluations, "range_deg": [20.0, 45.0], "twin_curvature": cal.twin_curvature,
        "target_curvature": 0.25, "path": cal.path, "end_friction_max": 0.0, "slope_se_deg": cal.slope_se_deg,
        "confirmations": 0,
    }
    assert cal.twin_kwargs() == {"friction": cal.friction, "rolling": cal.rolling, "end_friction": cal.friction}
    assert cal.path in ("diagonal", "sliding-first", "rolling-first")
    assert isinstance(cal.as_dict()["range_deg"], list)


def test_the_defaults_are_the_documented_ones(field):
    field.slope = lambda f, r: linear(f, r) + (3.0 if r >= 0.4 else 0.0)  # 31.5 deg is never within 0.4 deg
    cal = calibrate(31.5, 10.0)
    assert cal.evaluations == 1 + len(HIGH_EDGE) + 8  # max_evals 8
    assert all(c[3]["seed"] == 0 and c[3]["spin_up_s"] == 3.0 and c[3]["window_s"] == 5.0 for c in field.calls)
    # tol_deg 0.4: a first step 0.9 deg off goes on searching, one 0.3 deg off stops
    field.slope = linear
    assert calibrate(30.0, 10.0).evaluations == 5  # hits 30.0: within any tolerance
    field.slope = lambda f, r: linear(f, r) + (0.9 if 0.3 < r < 0.5 else 0.0)
    assert calibrate(30.0, 10.0).evaluations > 5
    field.slope = lambda f, r: linear(f, r) + (0.3 if 0.3 < r < 0.5 else 0.0)
    assert calibrate(30.0, 10.0).evaluations == 5


def test_a_drum_at_rest_is_refused_with_its_reason(field):
    with pytest.raises(SimError) as exc:
        calibrate(30.0, 0.0)
    assert str(exc.value) == "calibration needs a turning drum (rpm > 0)" and not field.calls


def test_a_target_under_one_degree_keeps_its_sign(field):
    field.slope = lambda f, r: 0.2 + 0.8 * linear(f, r) / 45.0  # a nearly flat bed: 0.56-1.0 deg
    cal = calibrate(0.8, 10.0)
    assert cal.twin_slope_deg > 0 and cal.twin_slope_deg == pytest.approx(0.8, abs=0.4)
    assert calibrate(-0.8, 10.0).twin_slope_deg < 0


def test_an_infinite_slope_is_no_free_surface_too(field):
    field.slope = lambda f, r: -math.inf if 0.2 < r < 0.9 else linear(f, r)
    cal = calibrate(30.0, 10.0)
    assert cal.evaluations == 5 and math.isnan(cal.history[4][3]) and (cal.friction, cal.rolling) == (0.05, 0.0)


def test_an_end_exactly_the_tolerance_away_needs_no_search(field):
    cal = calibrate(20.5, 10.0, tol_deg=0.5)  # binary fractions: the low corner is exactly 0.5 deg off
    assert cal.evaluations == 4 and cal.residual_deg == -0.5
    assert calibrate(20.5, 10.0, tol_deg=0.25).evaluations > 4  # a tighter tolerance searches


def test_a_given_wall_friction_is_the_end_plates_friction_each_run_records(field):
    cal = calibrate(30.0, 10.0, wall_friction=0.3)  # a deep drum: the plates take the wall's friction
    assert cal.end_friction == 0.3 and {h[2] for h in cal.history} == {0.3}
    assert all(c[3]["wall_friction"] == 0.3 for c in field.calls)

"""Commissioning's checks (``twin.commission.checks``), pure: each check fails its own test when its
quantity is off by more than its tolerance and passes within it; the twin-vs-camera checks are wired
so that a twin off in one quantity fails that check and no other; the mixed frames start at the
plateau; the exit code says whether every check passed."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from twin.commission import checks as ck
from twin.commission.measure import FrameMeasure, summarize
from twin.commission.steps import _twin_checks

T = ck.TOLERANCES


def _frames(n: int, slope: float, mi: float, cover: float, ratios: tuple[float, float],
            seed: int) -> list[FrameMeasure]:
    """``n`` frames scattered about the given medians (the medians exact: symmetric noise about them)."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, 1.0, n // 2)
    e = np.concatenate([e, -e])
    return [FrameMeasure(slope + 3.0 * d, mi + 0.01 * d, (), cover + 0.005 * d,
                         (ratios[0] + 0.02 * d, ratios[1] - 0.02 * d), 20.0) for d in e]


CAMERA = dict(slope=-32.0, mi=0.97, cover=0.41, ratios=(1.02, 0.98))


def _checks(**twin: object) -> list[ck.Check]:
    cam = summarize(_frames(40, **CAMERA, seed=1))  # type: ignore[arg-type]
    tw = summarize(_frames(120, **{**CAMERA, **twin}, seed=2))  # type: ignore[arg-type]
    return _twin_checks(cam, tw, ["blue", "white"], calibrated=True)


def _failed(checks: list[ck.Check]) -> list[str]:
    return [c.name for c in checks if not c.passed]


def test_a_twin_like_the_camera_passes_every_twin_check() -> None:
    checks = _checks(slope=-32.6, cover=0.41 * 1.03, mi=0.95, ratios=(1.07, 0.92))
    assert [c.name for c in checks] == ["free-surface slope", "fill (bed cover)", "plateau MI", "spread ratio blue",
                                        "spread ratio white"]
    assert _failed(checks) == []


@pytest.mark.parametrize(("twin", "fails"), [
    (dict(slope=-33.2), "free-surface slope"),  # 1.2 deg steeper
    (dict(slope=-30.7), "free-surface slope"),  # 1.3 deg flatter
    (dict(cover=0.41 * 1.06), "fill (bed cover)"),  # 6 % more of the drum
    (dict(cover=0.41 * 0.94), "fill (bed cover)"),
    (dict(mi=0.90), "plateau MI"),  # 0.07 below the camera's mixed frames
    (dict(ratios=(1.14, 0.98)), "spread ratio blue"),  # blue at the rim
    (dict(ratios=(1.02, 0.86)), "spread ratio white"),  # white in the core
], ids=["slope-steep", "slope-flat", "fill-more", "fill-less", "mi", "spread-blue", "spread-white"])
def test_each_twin_check_fails_alone_when_its_quantity_is_off(twin: dict, fails: str) -> None:
    checks = _checks(**twin)
    assert _failed(checks) == [fails]
    bad = next(c for c in checks if c.name == fails)
    assert bad.advice and math.isfinite(bad.value) and bad.target is not None
    assert ck.exit_code(checks) == ck.EXIT_FAILED


def test_the_twin_checks_say_when_the_twin_was_not_calibrated() -> None:
    cam = summarize(_frames(40, **CAMERA, seed=1))  # type: ignore[arg-type]
    checks = _twin_checks(cam, cam, ["blue", "white"], calibrated=False)
    assert all("uncalibrated" in c.detail for c in checks) and _failed(checks) == []


@pytest.mark.parametrize(("make", "good", "bad"), [
    (lambda v: ck.slope_check(v, -32.0), -32.9, -33.1),
    (lambda v: ck.fill_check(v, 0.40), 0.419, 0.421),  # 5 % of 0.40 = 0.02
    (lambda v: ck.mi_check(v, 0.97), 0.921, 0.919),
    (lambda v: ck.spread_check("blue", v, 1.0), 1.099, 1.101),
    (lambda v: ck.calibration_check(v, None), -0.9, 1.1),
    (lambda v: ck.orientation_check(v, 0.0), -59.0, 61.0),
    (lambda v: ck.light_check(int(v), 20), 2, 3),  # 10 % of 20 frames
    (lambda v: ck.census_check([100 - v] * 4 + [100 + v] * 4), 7, 8),  # interquartile range over median: 2v / 100
    (lambda v: ck.drum_check([300.0, 300.0 + v, 300.0], [320.0] * 3, [320.0] * 3), 5.9, 6.1),  # 2 % of 300 px
    (lambda v: ck.classes_check({"blue": v, "white": 1.0 - v}, ()), 0.051, 0.049),
], ids=["slope", "fill", "mi", "spread", "calibration", "orientation", "light", "census", "drum", "classes"])
def test_each_check_passes_within_its_tolerance_and_fails_beyond(make, good: float, bad: float) -> None:
    ok, off = make(good), make(bad)
    assert ok.passed and not off.passed, (ok, off)
    assert off.advice and off.step in dict(ck.STEPS)


def test_nan_never_passes() -> None:
    assert not ck.slope_check(math.nan, -32.0).passed
    assert not ck.fill_check(0.4, math.nan).passed
    assert not ck.orientation_check(math.nan, 0.0).passed


def test_a_calibration_out_of_reach_fails_with_its_own_message_as_the_advice() -> None:
    msg = "target slope 28.9 deg is outside the twin's reachable range 30.8-66.0 deg at 5 rpm"
    c = ck.calibration_check(math.nan, msg)
    assert not c.passed and c.advice == msg and math.isnan(c.value)


def test_classes_that_cannot_be_told_apart_fail_with_suggests_warning() -> None:
    warn = "classes 'grey' and 'white' have no valley between their colours"
    c = ck.classes_check({"grey": 0.5, "white": 0.5}, (warn,))
    assert not c.passed and c.advice == warn


def test_the_mixed_frames_start_where_the_mi_reaches_its_plateau() -> None:
    mi = [0.37, 0.55, 0.87, 0.97, np.nan, 0.98, 0.96, 0.97, 0.98, 0.97]
    m = ck.mixed_frames(mi)
    assert m.tolist() == [False, False, False, True, False, True, True, True, True, True]
    assert not ck.mixed_frames([np.nan, np.nan]).any()


def test_the_tolerances_live_in_one_place_and_every_check_reads_them() -> None:
    loose = replace(T, slope_deg=5.0, fill_rel=0.2, mi=0.2, spread_ratio=0.5)
    assert not ck.slope_check(-35.0, -32.0).passed and ck.slope_check(-35.0, -32.0, loose).passed
    assert ck.fill_check(0.45, 0.40, loose).passed and ck.mi_check(0.85, 0.97, loose).passed
    assert ck.spread_check("blue", 1.3, 1.0, loose).passed
    assert (T.slope_deg, T.fill_rel, T.mi, T.spread_ratio) == (1.0, 0.05, 0.05, 0.1)  # issue 39's numbers

"""The calibration's confirming runs (``sim.calibrate_confirm``), on known slope fields: the search's
runs are made noisy (a fixed, deterministic pattern of +-3 deg, as one 5 s window of one seed is on a
monolayer), the confirming measurement is the field itself (or the field read 2 deg steeper, as a
check's rendered measurement might read), so the answer can be checked against the truth.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import sim.calibrate as cal_mod
from sim.calibrate import CONFIRM_RUN, SlopeRun, calibrate
from sim.calibrate_confirm import confirm, fit_crossing, monotone_fit
from sim.calibrate_slope import Measured, frames_slope_deg, seeds_se_deg

HIGH = (0.5, 1.0)


def _u(f: float) -> float:
    return math.log(f / 0.05) / math.log(HIGH[0] / 0.05)


def truth(f: float, r: float) -> float:
    """20 deg at the low corner, 45 at the high point (0.5, 1): linear along the diagonal, lower off it."""
    return 20.0 + 12.5 * _u(f) + 12.5 * r - (2.0 if f > 0.6 else 0.0)


def noise(f: float, r: float) -> float:
    """A search run's error: +-3 deg, fixed by the point (a seed's packing)."""
    return 3.0 * math.sin(997.0 * f + 613.0 * r)


@pytest.fixture
def noisy(monkeypatch) -> list[tuple[float, float]]:
    calls: list[tuple[float, float]] = []

    def fake(friction: float, rolling: float, rpm: float, **kw) -> tuple[float, float]:
        calls.append((friction, rolling))
        return truth(friction, rolling) + noise(friction, rolling), 0.0

    monkeypatch.setattr(cal_mod, "twin_surface", fake)
    return calls


def exact(bias_deg: float = 0.0) -> tuple[list[tuple[float, float, float | None]], object]:
    seen: list[tuple[float, float, float | None]] = []

    def measure(f: float, r: float, e: float | None) -> Measured:
        seen.append((f, r, e))
        return Measured(truth(f, r) + bias_deg, 0.1)

    return seen, measure


def test_the_monotone_fit_pools_a_noisy_run_that_bends_it_back():
    assert monotone_fit([1.0, 3.0, 2.0, 4.0]).tolist() == [1.0, 2.5, 2.5, 4.0]
    assert monotone_fit([5.0, 4.0, 3.0]).tolist() == [4.0, 4.0, 4.0]
    assert monotone_fit([1.0, 2.0]).tolist() == [1.0, 2.0]


def test_the_crossing_is_the_fits_not_the_nearest_run():
    # runs at u 0, 0.5, 0.6, 1 on the line 20 + 25 u, the one at 0.6 read 4 deg low (35 - 4 = 31)
    u, g = fit_crossing([0.0, 0.5, 0.6, 1.0], [20.0, 32.5, 31.0, 45.0], 40.0)
    # the fit pools 32.5 and 31 to 31.75 at u 0.55, then rises to 45 at 1: 40 at 0.55 + 8.25 / 29.4
    assert u == pytest.approx(0.55 + (40.0 - 31.75) / (13.25 / 0.45)) and g == pytest.approx(13.25 / 0.45)
    assert fit_crossing([0.0, 1.0], [20.0, 45.0], 10.0) == (0.0, 25.0)  # below the fit: its low end
    assert fit_crossing([0.0, 1.0], [20.0, 45.0], 50.0)[0] == 1.0


def test_confirming_runs_step_by_secant_until_the_measurement_is_within_the_tolerance():
    line = lambda u: 20.0 + 25.0 * u  # noqa: E731
    got = confirm(lambda f, r, e: Measured(line(f) + 2.0, 0.2), lambda u: (u, 0.0, None), [0.0, 1.0],
                  [20.0, 45.0], 30.0, 0.1, 3)
    assert [round(c.u, 6) for c in got] == [0.4, 0.32]  # the fit's 0.4 reads 32: one step of -2 / 25
    assert got[-1].slope_deg == pytest.approx(30.0) and got[-1].measured.se_deg == 0.2
    none = confirm(lambda f, r, e: Measured(line(f) + 2.0, 0.2), lambda u: (u, 0.0, None), [0.0, 1.0],
                   [20.0, 45.0], 30.0, 0.1, 1)
    assert len(none) == 1  # the budget holds


def test_a_noisy_search_alone_lands_off_and_its_confirmed_answer_lands_on_the_truth(noisy):
    off = []
    for target in (27.0, 30.0, 33.0, 36.0, 39.0):
        alone = calibrate(target, 5.0)  # the search's closest run: its residual is a noisy run's
        assert abs(alone.residual_deg) <= 0.4 or alone.evaluations == 4 + 8
        off.append(abs(truth(alone.friction, alone.rolling) - target))
        seen, measure = exact()
        cal = calibrate(target, 5.0, confirm_evals=3, measure=measure)
        assert abs(truth(cal.friction, cal.rolling) - target) <= 0.4  # the tolerance, on the truth
        assert cal.residual_deg == pytest.approx(truth(cal.friction, cal.rolling) - target)  # a confirming run's
        assert cal.confirmations == len(seen) >= 1 and cal.slope_se_deg == 0.1
        assert cal.history[-len(seen):] == tuple((f, r, f, pytest.approx(truth(f, r))) for f, r, _ in seen)
        k = math.log(cal.history[4][0] / 0.05) / cal.history[4][1]  # the diagonal: log-sliding over rolling
        assert all(math.log(f / 0.05) / r == pytest.approx(k) for f, r, _ in seen), seen  # on the search's path
    assert max(off) > 1.5, off  # the single closest run was chance somewhere


def test_a_check_that_reads_steeper_than_the_search_is_what_the_answer_lands_on(noisy):
    _, measure = exact(bias_deg=2.0)  # the confirming measurement (the check's) reads 2 deg above the search's
    cal = calibrate(33.0, 5.0, confirm_evals=3, measure=measure, tol_deg=0.5)
    assert abs(truth(cal.friction, cal.rolling) + 2.0 - 33.0) <= 0.5 and abs(cal.residual_deg) <= 0.5


def test_without_confirming_runs_the_search_is_as_before(noisy):
    cal = calibrate(33.0, 5.0)
    assert cal.confirmations == 0 and math.isnan(cal.slope_se_deg)
    assert cal.evaluations == len(noisy)  # every run a search run


def test_the_one_slope_statistic_is_the_median_of_the_frames_and_its_noise_the_seeds():
    assert frames_slope_deg([30.0, math.nan, 10.0, 31.0]) == 30.0  # an avalanche's frame does not drag it
    assert math.isnan(frames_slope_deg([math.nan]))
    s = np.array([30.0, 30.0, 32.0, 32.0, 34.0, 34.0])  # three seeds of two frames: medians 30, 32, 34
    assert seeds_se_deg(s, 2) == pytest.approx(2.0 / math.sqrt(3))
    assert math.isnan(seeds_se_deg(s[:2], 2))


def dipped(monkeypatch) -> None:
    """A field of rolling friction only, 20 + 25 r (the diagonal to (1, 1): 20 + 25 u), read 1 deg low by the
    search at 0.3 < r < 0.5: its first step (u 0.4) reads 29, within the search's 1.5 deg: it stops there."""
    monkeypatch.setattr(cal_mod, "twin_surface", lambda f, r, rpm, **kw: (20.0 + 25.0 * r - (0.3 < r < 0.5), 0.0))


def test_one_confirming_run_goes_where_the_search_runs_fit_crosses_the_target(monkeypatch):
    dipped(monkeypatch)
    cal = calibrate(30.0, 10.0, confirm_evals=1, measure=lambda f, r, e: Measured(20.0 + 25.0 * r, 0.1))
    assert cal.evaluations == 1 + 3 + 1 + 1 and cal.confirmations == 1  # the search stopped within 1.5 deg
    # the fit through (0, 20), (0.4, 29), (1, 45) crosses 30 at 0.4 + 0.6 / 16
    assert cal.rolling == pytest.approx(0.4375) and cal.twin_slope_deg == pytest.approx(30.9375)
    assert cal.residual_deg == pytest.approx(0.9375) and cal.slope_se_deg == 0.1


def test_confirming_runs_without_a_slope_leave_the_searchs_answer(monkeypatch):
    dipped(monkeypatch)
    cal = calibrate(30.0, 10.0, confirm_evals=1, measure=lambda f, r, e: Measured(math.nan, math.nan))
    assert (cal.rolling, cal.twin_slope_deg, cal.residual_deg) == (pytest.approx(0.4), 29.0, -1.0)
    assert cal.confirmations == 1 and math.isnan(cal.slope_se_deg) and math.isnan(cal.history[-1][3])


def test_without_a_measure_the_particle_twins_confirming_run_is_asked_for_with_the_calibrations_twin(monkeypatch):
    dipped(monkeypatch)
    asked: list[tuple] = []

    def twin_measure(rpm, twin_kw, run):
        asked.append((rpm, twin_kw, run))
        return lambda f, r, e: Measured(20.0 + 25.0 * r, 0.1)

    monkeypatch.setattr(cal_mod, "twin_measure", twin_measure)
    cal = calibrate(30.0, -10.0, confirm_evals=1, seed=4, window_s=0.7)
    assert cal.confirmations == 1 and cal.twin_slope_deg == pytest.approx(30.9375)
    (rpm, kw, run), = asked
    assert rpm == -10.0 and run is CONFIRM_RUN and kw["seed"] == 4 and kw["window_s"] == 0.7 and kw["mixer"] is None
    mine = SlopeRun(seeds=(1, 2), window_s=2.0)
    calibrate(30.0, 10.0, confirm_evals=1, confirm_run=mine)
    assert asked[-1][2] is mine

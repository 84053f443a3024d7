"""The statistics behind docs/validation.md section 10's claims (sim.validation_pymunk)."""

from __future__ import annotations

import math
import statistics

import pytest

from sim.errors import SimError
from sim.validation_pymunk import difference_in_se, sd_from_one, segregates, window_mean

# measured (docs/validation.md section 10; pymunk, 10 rpm, case C, late third, one value per seed)
CUT_DISC_8S = (1.0427, 0.9631, 1.0431, 1.0142)  # 2 ms step, 8 s windows after 2 s: the convergence runs
CUT_DISC_8S_1MS = (0.9994, 1.0212, 1.0416, 1.0190)
# 150 s runs (``long_runs``), the mean over t >= 30 s (the last 120 s), seeds 0-2, 4-7 / 0-5
CUT_DISC_150S = (1.0298, 1.0109, 1.0173, 1.0310, 1.0300, 1.0454, 1.0177)
DISC_DISC_150S = (1.0015, 1.0004, 1.0095, 1.0259, 0.9994, 1.0113)


def test_the_criterion_counts_seed_standard_deviations_not_standard_errors():
    # 1.025 +- 0.012 over 4 seeds (the 90 s runs): 2.1 sd from 1, but 4.2 standard errors
    ratios = (1.015, 1.020, 1.023, 1.042)
    assert sd_from_one(ratios) == pytest.approx((statistics.mean(ratios) - 1) / statistics.stdev(ratios))
    assert 2.0 < sd_from_one(ratios) < 2.3 and not segregates(ratios)
    assert segregates((1.10, 1.11, 1.09, 1.10))  # a clear segregation
    assert not segregates((1.0, 1.01, 0.99, 1.0))  # a mixed bed
    assert segregates((0.90, 0.91, 0.89, 0.90))  # towards the core counts too


def test_the_measured_cut_disc_runs_do_not_reach_three_sd():
    for runs in (CUT_DISC_8S, CUT_DISC_8S_1MS):
        assert sum(runs) / len(runs) > 1.0  # the cut discs sit further out on average
        assert not segregates(runs)  # ... but not by three seed sd (the must-show does not hold here)


def test_difference_in_standard_errors():
    assert difference_in_se((1.0, 1.2), (1.0, 1.2)) == 0.0
    # two sets of 4 seeds 0.1 apart with sd 0.05: 0.1 / sqrt(2 * 0.05^2 / 4) = 2.83 standard errors
    a, b = (0.85, 0.90, 0.95, 0.90), (0.75, 0.80, 0.85, 0.80)
    sd = math.sqrt(sum((x - 0.9) ** 2 for x in a) / 3)
    assert difference_in_se(a, b) == pytest.approx(0.1 / math.sqrt(2 * sd * sd / 4))
    with pytest.raises(SimError):
        difference_in_se((1.0,), (1.0, 2.0))
    with pytest.raises(SimError):
        sd_from_one((1.0,))


# measured (docs/validation.md section 10): the cut-disc rig from case A at 10 rpm, 30 s, MI (eq. 4) over
# the last 10 s, seeds 0-3, plain drum against 4 lifters 50 mm high and 4 mm thick
PLAIN_MI = (0.7804, 0.8069, 0.7670, 0.7895)
TALL_LIFTERS_MI = (0.9126, 0.8917, 0.9325, 0.8342)


def test_tall_lifters_change_the_plateau_mi_measurably():
    assert difference_in_se(TALL_LIFTERS_MI, PLAIN_MI) > 3.0
    assert min(TALL_LIFTERS_MI) > max(PLAIN_MI)  # every baffled seed above every plain one
    assert difference_in_se(PLAIN_MI[:2], PLAIN_MI[2:]) < 3.0  # two halves of one set: not a change


# measured (docs/validation.md section 10): the rig with the white class half discs (a 180-degree cut),
# 10 rpm, case C, 60 s, seeds 0-3, the spread ratio over the last 30 s and the last 20 s
HALF_DISC_30S = (0.9067, 0.9134, 0.8514, 0.8392)
HALF_DISC_20S = (0.8981, 0.9273, 0.8522, 0.8359)
DISC_DISC_30S = (0.9929, 0.9734, 0.9645, 1.0214)  # the disc/disc control, run the same way


def test_half_discs_segregate_at_three_sd_over_30_s_and_discs_do_not():
    assert segregates(HALF_DISC_30S) and sum(HALF_DISC_30S) / 4 < 1.0  # towards the core
    assert not segregates(HALF_DISC_20S)  # at the threshold: a shorter window does not reach it
    assert not segregates(DISC_DISC_30S)  # the control bed of equal discs does not segregate
    assert difference_in_se(HALF_DISC_30S, DISC_DISC_30S) > 3.0


def test_the_half_disc_variant_config_is_the_studied_rig():
    import tomllib
    from pathlib import Path

    from sim.mixer import parse_mixer, resolve_counts
    from sim.validation_pymunk import rig

    path = Path(__file__).resolve().parents[2] / "configs" / "pmma-halfdisc.toml"
    table = tomllib.loads(path.read_text())
    m = parse_mixer(table, [c["name"] for c in table["classes"]], source=str(path))
    assert m.particles[1].shape.kind == "cut_disc" and m.particles[1].shape.wedge_deg == 180.0
    assert m == rig(True, wedge_deg=180.0)
    assert resolve_counts(m) == (125, 125)


def test_window_mean_takes_the_samples_from_its_start_on():
    row = {"t": [0.5 * k for k in range(1, 21)], "ratio": [float(k) for k in range(1, 21)]}
    assert window_mean(row, "ratio", 5.0) == pytest.approx(sum(range(10, 21)) / 11)  # t = 5.0 .. 10.0
    assert window_mean(row, "ratio", 0.0) == pytest.approx(10.5)


def test_the_long_cut_disc_runs_stay_under_three_sd_and_the_disc_control_does_not_segregate():
    # four times the window of the 90 s runs and the seed scatter does not shrink (0.012 against 0.012):
    # it is each seed's own lasting arrangement, not noise that a longer mean averages away
    assert 2.0 < sd_from_one(CUT_DISC_150S) < 2.5 and not segregates(CUT_DISC_150S)
    assert sd_from_one(DISC_DISC_150S) < 1.0
    assert 2.8 < difference_in_se(CUT_DISC_150S, DISC_DISC_150S) < 3.2  # cut against disc control

"""The statistics behind docs/validation.md section 10's claims (sim.validation_pymunk)."""

from __future__ import annotations

import math
import statistics

import pytest

from sim.errors import SimError
from sim.validation_pymunk import difference_in_se, sd_from_one, segregates, window_mean


def test_the_criterion_counts_seed_standard_deviations_not_standard_errors():
    # 1.025 +- 0.012 over 4 seeds (the 90 s runs): 2.1 sd from 1, but 4.2 standard errors
    ratios = (1.015, 1.020, 1.023, 1.042)
    assert sd_from_one(ratios) == pytest.approx((statistics.mean(ratios) - 1) / statistics.stdev(ratios))
    assert 2.0 < sd_from_one(ratios) < 2.3 and not segregates(ratios)
    assert segregates((1.10, 1.11, 1.09, 1.10))  # a clear segregation
    assert not segregates((1.0, 1.01, 0.99, 1.0))  # a mixed bed
    assert segregates((0.90, 0.91, 0.89, 0.90))  # towards the core counts too


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


def test_baffle_summary_times_each_run_to_the_target_and_takes_its_plateau_from_the_late_window():
    import numpy as np

    from sim.validation_pymunk import baffle_summary

    t = np.arange(0.25, 60.01, 0.25)
    runs = []
    for tau in (5.0, 10.0, 20.0):  # MI rising to 0.97 with time constant tau
        mi = 0.97 * (1 - np.exp(-t / tau))
        runs.append({"t": t, "mi": mi, "ratio": np.full(t.size, 1.0 + tau / 100), "rtf": 2.0})
    got = baffle_summary(runs, target_mi=0.85, late_s=40.0)
    # 0.97 (1 - exp(-t / tau)) = 0.85 at t = tau ln(0.97 / 0.12); the 2 s centred average of the concave curve
    # reaches it a little later (0.2 s at tau = 20 s)
    want = [tau * math.log(0.97 / 0.12) for tau in (5.0, 10.0, 20.0)]
    assert got["t_mix_s"]["values"] == pytest.approx(want, abs=0.3)
    late = [float(np.mean(0.97 * (1 - np.exp(-t[t >= 40.0] / tau)))) for tau in (5.0, 10.0, 20.0)]
    assert got["plateau_mi"]["values"] == pytest.approx(late)
    assert got["ratio"]["values"] == pytest.approx([1.05, 1.10, 1.20])
    # a run that never gets there has no time to mix (NaN), not the end of the run
    flat = {"t": t, "mi": np.full(t.size, 0.8), "ratio": np.ones(t.size), "rtf": 1.0}
    assert math.isnan(baffle_summary([flat, flat])["t_mix_s"]["values"][0])

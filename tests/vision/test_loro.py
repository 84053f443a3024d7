"""Leave-one-rig-out (``vision.loro``): a threshold chosen on data is chosen without the rig it is
then measured on, so a rig unlike the others shows up as a miss instead of moving the threshold
to fit itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vision.loro import RIM_GRID, density_rule, leave_one_rig_out, rim_rule, spread_rule


def rig(spread: float, disagreement: float, n: int = 50, seed: int = 0, density: tuple[float, float] | None = None):
    """A rig's records: ``n`` set-up light estimates around (spread, disagreement), a tone
    curve's estimates four times as spread, and (``density``) upper-drum samples: empty ones
    around the first ratio, bed ones around the second."""
    rng = np.random.default_rng(seed)
    setup = [(spread * (1 + 0.1 * rng.standard_normal()), disagreement * (1 + 0.1 * rng.standard_normal()))
             for _ in range(n)]
    rec: dict = {"setup_spreads": setup, "curve_spreads": [(4 * s, 4 * d) for s, d in setup]}
    if density is not None:
        rec["density_ratio"] = np.concatenate([rng.normal(density[0], 0.03, 200), rng.normal(density[1], 0.1, 200)])
        rec["density_bed"] = np.r_[np.zeros(200, bool), np.ones(200, bool)]
    return rec


def test_each_threshold_is_chosen_without_the_rig_it_is_measured_on():
    """Three alike rigs and one whose set-up light spreads three times as much: left out, the odd
    rig meets thresholds chosen on the alike ones and most of its set-up frames are over them
    (the miss shows); the alike rigs each meet thresholds that include the odd rig and pass. A
    rule that saw the rig it is measured on would let the odd rig pass."""
    records = {f"rig{i}": rig(0.05, 0.08, seed=i) for i in range(3)} | {"odd": rig(0.15, 0.24, seed=9)}
    out = leave_one_rig_out(records)
    odd = out["rigs"]["odd"]
    alike = [0.05 * 2 * 1.3, 0.08 * 2 * 1.3]  # twice the 99th percentile of the alike rigs, roughly
    assert odd["spread_threshold"] < alike[0] and odd["disagreement_threshold"] < alike[1], odd
    assert odd["setup_flagged"] > 0.5, odd
    for name in ("rig0", "rig1", "rig2"):
        row = out["rigs"][name]
        assert row["spread_threshold"] > 0.25 and row["setup_flagged"] == 0.0, (name, row)
        assert row["curve_flagged"] == 0.0, (name, row)  # the odd rig's spread lets a 4x curve through: shown
    assert out["all"]["spread_threshold"] == pytest.approx(spread_rule([p[0] for r in records.values()
                                                                         for p in r["setup_spreads"]]))


def test_the_density_threshold_is_chosen_on_the_other_rigs_and_measured_on_the_one_left_out():
    """The empty-drum density threshold: chosen between empty (ratio ~0.1) and bed (~0.6) samples
    of the other rigs; a left-out rig whose bed is as untextured as the others' empty drum (0.15)
    has much of its bed called empty (the miss shows), the others find their empty drum and call
    none of their bed empty."""
    records = {f"rig{i}": rig(0.05, 0.08, seed=i, density=(0.1, 0.6)) for i in range(3)}
    records["smooth"] = rig(0.05, 0.08, seed=5, density=(0.05, 0.15))
    out = leave_one_rig_out(records)
    assert out["rigs"]["smooth"]["bed_called_empty"] > 0.3, out["rigs"]["smooth"]
    for name in ("rig0", "rig1", "rig2"):
        row = out["rigs"][name]
        assert row["empty_found"] > 0.9 and row["bed_called_empty"] < 0.05, (name, row)
    t = density_rule(np.r_[np.full(10, 0.1), np.full(10, 0.6)], np.r_[np.zeros(10, bool), np.ones(10, bool)])
    assert 0.1 < t <= 0.6


def test_estimates_flagged_for_another_cause_count_as_flagged():
    """A NaN spread (an estimate saturated, too dark, a class lost from view) is not a pass."""
    records = {"a": rig(0.05, 0.08), "b": rig(0.05, 0.08, seed=1)}
    records["b"]["setup_spreads"] = [(math.nan, math.nan)] * 5 + records["b"]["setup_spreads"][:45]
    out = leave_one_rig_out(records)
    assert out["rigs"]["b"]["setup_flagged"] == pytest.approx(0.1)
    assert math.isfinite(out["rigs"]["a"]["spread_threshold"])


def with_rims(rec: dict, rims: tuple[float, ...], particles: tuple[float, ...], known: bool = True) -> dict:
    """``rec`` with colour-model class members: rims and particle members at these bed ratios
    (``known`` False: their truth unknown, as on a synthetic rig)."""
    truth = [1.0] * len(rims) + [0.0] * len(particles)
    return rec | {"rim_ratio": np.asarray(rims + particles), "rim_truth": np.asarray(truth if known else
                                                                                     [math.nan] * len(truth))}


def test_the_rim_threshold_is_chosen_on_the_other_rigs_and_measured_on_the_one_left_out():
    """Rims at bed ratios 0.6-0.7 and particle members at 0.95-1.1 on three rigs: the rule takes the
    middle of the ratios that tell them apart (0.7 < t <= 0.95: 0.85); a rig whose rim lies in
    the bed as much as its particles (0.97) keeps it when left out (the miss shows) and does not
    move the threshold the others meet; the members of a rig of unknown truth are measured (kept),
    never chosen on."""
    records = {f"rig{i}": with_rims(rig(0.05, 0.08, seed=i), (0.6 + 0.05 * i,), (0.95, 1.0 + 0.05 * i))
               for i in range(3)}
    records["odd"] = with_rims(rig(0.05, 0.08, seed=7), (0.97,), (1.02,))
    records["synthetic"] = with_rims(rig(0.05, 0.08, seed=8), (), (0.94, 0.5), known=False)
    out = leave_one_rig_out(records)
    odd = out["rigs"]["odd"]
    assert 0.7 < odd["rim_threshold"] <= 0.95 and odd["rims_dropped"] == 0.0 and odd["particles_kept"] == 1.0, odd
    for name in ("rig0", "rig1", "rig2"):
        row = out["rigs"][name]
        assert row["rims_dropped"] == 1.0 and row["particles_kept"] == 1.0, (name, row)
    syn = out["rigs"]["synthetic"]
    assert math.isnan(syn["rims_dropped"]) and syn["unknown_kept"] == 0.5, syn
    assert out["all"]["rim_threshold"] == pytest.approx(0.85)  # the best: 0.75..0.95 (3 of 4 rims, all particles)
    assert rim_rule(np.array([0.6, 1.0]), np.array([1.0, 0.0])) == pytest.approx(0.825)  # the best: 0.65..1.0
    assert rim_rule(np.array([0.6, 1.0, 0.3]), np.array([1.0, 0.0, math.nan])) == pytest.approx(0.825)
    assert RIM_GRID[0] == 0.5 and RIM_GRID[-1] == 1.0


def test_the_left_out_rig_is_scored_with_the_shipped_rule_bed_and_wall():
    """The shipped rim rule (``colourfit.is_rim``) also asks the member to lie at the wall at least as
    often as its class: a member under the bed threshold but off the wall (a shaded particle colour,
    wall ratio 0.7) is kept on the rig left out, one at the wall (1.2) dropped; with no wall shares
    recorded the bed condition alone decides."""
    records = {f"rig{i}": with_rims(rig(0.05, 0.08, seed=i), (0.6 + 0.05 * i,), (0.95, 1.0 + 0.05 * i))
               for i in range(3)}
    shaded = with_rims(rig(0.05, 0.08, seed=5), (0.6,), (0.65,))  # both under any threshold the others give
    records["shaded"] = shaded | {"rim_wall": np.array([1.2, 0.7])}
    row = leave_one_rig_out(records)["rigs"]["shaded"]
    assert row["rims_dropped"] == 1.0 and row["particles_kept"] == 1.0, row
    records["shaded"] = shaded  # no wall shares: the bed ratio alone drops the shaded particle member
    row = leave_one_rig_out(records)["rigs"]["shaded"]
    assert row["rims_dropped"] == 1.0 and row["particles_kept"] == 0.0, row

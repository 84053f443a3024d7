"""Recipe slicing (equal volume fraction + fill level) and bad-input errors."""

from __future__ import annotations

import math

import pytest

from sim.drum import DrumSim
from sim.errors import SimError
from sim.params import check_rpm
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DrumSpec, ParticleSpec, Recipe, recipe_fill_3d, slice_2d, with_fill


def test_paper_recipe_slices_to_45_large_and_180_small_disks_of_equal_area():
    classes = slice_2d(PAPER_RECIPE, PAPER_DRUM)
    assert [(c.name, c.count) for c in classes] == [("red", 45), ("blue", 180)]
    areas = [c.count * math.pi * c.radius_m**2 for c in classes]
    assert areas[0] == pytest.approx(areas[1], rel=0.02)
    # the recipe's own 3D solid volume corresponds to the paper's filling degree 0.5
    assert recipe_fill_3d(PAPER_RECIPE, PAPER_DRUM) == pytest.approx(0.5, abs=0.02)


def test_counts_follow_the_fill_level():
    low = slice_2d(with_fill(PAPER_RECIPE, 0.25), PAPER_DRUM)
    assert [c.count for c in low] == [22, 90] or [c.count for c in low] == [23, 90]


def test_critical_speed_is_77_rpm_and_above_is_refused_with_the_number():
    assert PAPER_DRUM.critical_rpm == pytest.approx(77.2, abs=0.1)
    with pytest.raises(SimError, match=r"77\.2"):
        check_rpm(80.0, PAPER_DRUM)
    sim = DrumSim(rpm=5.0, settle_s=0.1)
    with pytest.raises(SimError, match="critical"):
        sim.set_rpm(78.0)
    with pytest.raises(SimError):
        sim.set_rpm(float("nan"))


@pytest.mark.parametrize(
    "recipe, drum, match",
    [
        (Recipe((ParticleSpec("red", 0.02, 9000),), 0.5), PAPER_DRUM, "does not fit"),
        (with_fill(PAPER_RECIPE, 0.97), PAPER_DRUM, "fill level"),
        (Recipe((ParticleSpec("red", 0.2, 3),), 0.5), PAPER_DRUM, "do not fit"),
        (PAPER_RECIPE, DrumSpec(diameter_m=-1.0), "positive"),
    ],
)
def test_impossible_recipes_are_clear_errors(recipe, drum, match):
    with pytest.raises(SimError, match=match):
        slice_2d(recipe, drum)


def test_bad_case_and_params_are_clear_errors():
    with pytest.raises(SimError, match="case"):
        DrumSim(case="D")
    with pytest.raises(SimError, match="friction"):
        DrumSim(friction=-1.0)

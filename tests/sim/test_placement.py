"""sim.placement: random sequential addition on a cell grid (issue 42: linear in the disc count).

What a grid can get wrong: a neighbour in a cell it does not look in (an overlap let through), a
disc in a cell it was not filed under, the edge of the grid, a cell far larger than the discs
(a huge drum) or far smaller than the largest disc (mixed sizes); and the generator: the draws
after a placement must be the ones that follow the numbers it used, or every seed's run changes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.placement import GAP_R, SHRINK, DiscGrid, disc_arrays, place_random
from sim.recipe import DiskClass


def _classes(*spec: tuple[float, int]) -> list[DiskClass]:
    return [DiskClass(f"c{k}", r, n, 1190.0, (0, 0, 255)) for k, (r, n) in enumerate(spec)]


def _clear(pos: np.ndarray, r: np.ndarray, x: float, y: float, rc: float, gap: float) -> bool:
    """The definition: no placed disc within its radius + ``rc`` + ``gap`` of (x, y)."""
    return not bool(np.any((pos[:, 0] - x) ** 2 + (pos[:, 1] - y) ** 2 < (r + rc + gap) ** 2))


@pytest.mark.parametrize(("radius_m", "spec"), [
    (0.15, ((0.010, 45), (0.005, 180))),  # the paper bed
    (0.15, ((0.030, 3), (0.001, 900), (0.004, 60))),  # a disc 30x the smallest: it spans many cells
    (5.0, ((0.0044, 40),)),  # a few discs in a huge drum: cells far larger than the discs
])
def test_the_grid_answers_what_checking_every_placed_disc_answers(radius_m, spec):
    classes = _classes(*spec)
    rng = np.random.default_rng(1)
    pos, _ = place_random(classes, "C", radius_m, rng)
    radii, _, _, gap = disc_arrays(classes)
    small = radii * SHRINK
    grid = DiscGrid(radius_m, small, gap)
    for j in range(radii.size):
        grid.add(j, *pos[j], small[j])
    # candidates near the placed discs (where a missed cell matters) and anywhere, with every radius
    near = pos[rng.integers(0, len(pos), 4000)] + rng.normal(0, 2.5 * small.max(), (4000, 2))
    cand = np.concatenate([near, rng.uniform(-radius_m, radius_m, (2000, 2))])
    rc = rng.choice(small, len(cand))
    got = [grid.first_free(cand[k:k + 1], rc[k], np.ones(1, bool)) == 0 for k in range(len(cand))]
    want = [_clear(pos, small, *cand[k], rc[k], gap) for k in range(len(cand))]
    assert got == want
    assert 0 < sum(want) < len(want)  # both answers were asked


@pytest.mark.parametrize("case", ["A", "B", "C"])
def test_placed_discs_keep_their_gap_inside_the_wall_and_their_side(case):
    classes = _classes((0.010, 45), (0.005, 180))
    radius_m = 0.15
    pos, cls = place_random(classes, case, radius_m, np.random.default_rng(7))
    radii, cls_ref, _, gap = disc_arrays(classes)
    assert np.array_equal(cls, cls_ref)
    small = radii * SHRINK
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= small[:, None] + small[None, :] + gap)
    assert np.all(np.hypot(pos[:, 0], pos[:, 1]) <= radius_m - radii - gap)
    assert gap == pytest.approx(GAP_R * 0.010)
    if case == "A":  # class 0 (large) left, the others right
        assert np.all(pos[cls == 0, 0] < 0) and np.all(pos[cls == 1, 0] > 0)
    if case == "B":  # class 0 on top
        assert np.all(pos[cls == 0, 1] > 0) and np.all(pos[cls == 1, 1] < 0)


def test_the_generator_continues_right_after_the_last_placed_disc():
    """The last disc placed took the last two numbers the placement drew, and the generator's next
    number is the one after them (a placement that kept a batch of draws would skip ahead)."""
    classes = _classes((0.010, 45), (0.005, 1800))
    radius_m = 0.3
    rng = np.random.default_rng(11)
    pos, _ = place_random(classes, "C", radius_m, rng)
    after = rng.random()
    radii, _, order, gap = disc_arrays(classes)
    stream = np.random.default_rng(11).random(200_000)
    k = int(np.flatnonzero(stream == after)[0])
    last = order[-1]
    lim = radius_m - radii[last] - gap
    assert k % 2 == 0 and k >= 2 * radii.size
    assert pos[last, 0] == -lim + (lim - -lim) * stream[k - 2]
    assert pos[last, 1] == -lim + (lim - -lim) * stream[k - 1]


def test_the_same_seed_places_alike_and_a_bed_that_cannot_fit_is_one_line():
    from sim.errors import SimError

    classes = _classes((0.010, 45), (0.005, 180))
    a = place_random(classes, "C", 0.15, np.random.default_rng(3))[0]
    assert np.array_equal(a, place_random(classes, "C", 0.15, np.random.default_rng(3))[0])
    assert not np.array_equal(a, place_random(classes, "C", 0.15, np.random.default_rng(4))[0])
    too_many = _classes((0.010, int(0.9 * (0.15 / (0.010 * SHRINK)) ** 2 * math.pi / 4 * 4)))
    with pytest.raises(SimError, match="does not fit"):
        place_random(too_many, "C", 0.15, np.random.default_rng(0))

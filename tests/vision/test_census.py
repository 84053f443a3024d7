"""The mixer census's particle measures (vision/census.py) on constructed frames with known
answers: sizes from the gray image's circles whatever the class map does at the particles'
edges, counts and outlines that survive a class taking the gaps between its particles.
(The real PMMA frames under other light and scale: tests/sim/test_mixer_cli.py.)"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vision.bed import bed_cover, spread_ratios
from vision.census import (
    CIRCLES_MIN,
    ClassSize,
    census,
    circle_census,
    circle_diameters_px,
    class_size,
    count_particles,
    particle_body,
    particle_edges,
    run_diameter_px,
    single_particle_crops,
)

GAP_GRAY, DARK_GRAY = 12, 30  # the background between particles; a class's dark, bled gaps


def hex_cluster(d_px: float, rows: int, cols: int, origin: tuple[float, float]) -> list[tuple[float, float]]:
    """Centres (x, y px) of touching discs of ``d_px`` in a hexagonal patch."""
    x0, y0 = origin
    return [(x0 + d_px * (c + 0.5 * (r % 2)), y0 + d_px * math.sqrt(3) / 2 * r) for r in range(rows)
            for c in range(cols)]


def draw(shape_hw: tuple[int, int], discs: list[tuple[float, float, float, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """A gray frame and its class map: discs (x, y, d px, gray level, class label) on a dark gap."""
    gray = np.full(shape_hw, GAP_GRAY, np.uint8)
    lab = np.zeros(shape_hw, np.uint8)
    for x, y, d, g, k in discs:
        c = (int(round(16 * x)), int(round(16 * y)))
        r = int(round(16 * (0.5 * d - 0.5)))  # a one-pixel dark seam between touching discs
        cv2.circle(gray, c, r, int(g), -1, cv2.LINE_AA, shift=4)
        cv2.circle(lab, c, r, int(k), -1, cv2.LINE_8, shift=4)
    return gray, lab


def bleed(lab: np.ndarray, k: int, centres: list[tuple[float, float]], d_px: float) -> np.ndarray:
    """Class ``k`` also takes the gaps inside its clusters (colour bleeding): its map filled to the
    discs' outer hull."""
    out = lab.copy()
    hull = cv2.convexHull(np.array(centres, np.float32)).astype(np.int32)
    cover = np.zeros_like(lab)
    cv2.fillConvexPoly(cover, hull, 1)
    cover = cv2.dilate(cover, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(d_px) | 1, int(d_px) | 1)))
    out[(cover > 0) & (lab == 0)] = k
    return out


def two_class_frame(bled: bool, which: int = 2, d_small: float = 20.0) -> tuple[
        np.ndarray, np.ndarray, list[tuple[float, float]], list[tuple[float, float]]]:
    """Class 1: light ``d_small`` px discs, class 2: dark 30 px discs (a coloured class), each in a
    cluster; ``bled``: class ``which`` takes the gaps inside its cluster (dark, of its colour)."""
    small = hex_cluster(d_small, 5, 7, (40, 40))
    large = hex_cluster(30.0, 4, 5, (40, 220))
    discs = [(x, y, d_small, 200, 1) for x, y in small] + [(x, y, 30.0, 110, 2) for x, y in large]
    gray, lab = draw((360, 240), discs)
    if bled:
        lab = bleed(lab, which, small if which == 1 else large, d_small if which == 1 else 30.0)
        gray = np.where((lab == which) & (gray == GAP_GRAY), DARK_GRAY, gray).astype(np.uint8)
    return gray, lab, small, large


@pytest.mark.parametrize("bled", [False, True])
def test_circles_give_each_class_its_own_size_whatever_its_map_does_between_particles(bled):
    gray, lab, small, large = two_class_frame(bled)
    got = circle_diameters_px(gray, lab, 2, 12.0, 48.0)
    assert got[0].size >= 0.4 * len(small) and got[1].size >= 0.4 * len(large)
    assert float(np.median(got[0])) == pytest.approx(20.0, rel=0.06)
    assert float(np.median(got[1])) == pytest.approx(30.0, rel=0.06)
    # the class map's runs are what bleeding moves: the bled class's run length is its whole cluster's
    runs = run_diameter_px(lab == 2)
    assert (runs > 60.0) if bled else (runs == pytest.approx(30.0, rel=0.15))


def test_circles_round_rings_of_particles_are_not_particles():
    # a wide search over packed clusters: Hough also finds circles round rings of discs (up to 120 px here)
    gray, lab, _, _ = two_class_frame(bled=True, which=1)
    got = circle_diameters_px(gray, lab, 2, 4.0, 150.0)
    assert got[0].size >= 20 and float(got[0].max()) <= 1.15 * 20.0
    assert got[1].size >= 10 and float(got[1].max()) <= 1.2 * 30.0


def test_small_particles_are_searched_upsampled_and_circles_of_no_class_are_left_out():
    centres = hex_cluster(9.0, 4, 8, (20, 20))
    gray, lab = draw((80, 110), [(x, y, 9.0, 180, 1) for x, y in centres])
    got = circle_diameters_px(gray, lab, 1, 6.0, 14.0)
    assert got[0].size >= 0.25 * len(centres)  # (none at this size without the upsampling)
    assert float(np.median(got[0])) == pytest.approx(9.0, rel=0.1)
    assert circle_diameters_px(gray, np.zeros_like(lab), 1, 6.0, 14.0)[0].size == 0  # no class covers them
    assert all(a.size == 0 for a in circle_diameters_px(gray, lab, 1, math.nan, 14.0))
    with pytest.raises(ValueError):
        circle_diameters_px(gray, lab[:-1], 1, 6.0, 14.0)


def test_the_census_finds_its_scale_in_the_circles_not_in_the_runs_of_a_class_packed_into_a_blob():
    # the small class (14 px; the large 30) packed into one blob: its runs say 80+ px, its circles 14
    gray, lab, _, _ = two_class_frame(bled=True, which=1, d_small=14.0)
    assert run_diameter_px(lab == 1) > 80.0
    got = circle_census([gray] * 3, [lab] * 3, 3, [0, 1], 1.6 * run_diameter_px(lab == 1))
    assert float(np.median(got[0])) == pytest.approx(14.0, rel=0.08)
    assert float(np.median(got[1])) == pytest.approx(30.0, rel=0.06)
    # small particles: the scale search at the frames' resolution finds none, the upsampled one does
    centres = hex_cluster(9.0, 6, 10, (20, 20))
    g9, l9 = draw((100, 130), [(x, y, 9.0, 180, 1) for x, y in centres])
    assert circle_diameters_px(g9, l9, 1, 8.0, 40.0)[0].size < 5
    small = circle_census([g9, g9], [l9, l9], 1, [0], 40.0)[0]
    assert small.size >= 10 and float(np.median(small)) == pytest.approx(9.0, rel=0.12)
    assert circle_census([], [], 1, [0], 40.0)[0].size == 0
    assert circle_census([g9], [np.zeros_like(l9)], 1, [0], 40.0)[0].size == 0  # no class: no circles
    with pytest.raises(ValueError):
        circle_census([g9], [], 1, [0], 40.0)


def test_a_bled_cluster_is_counted_by_its_area_and_separate_particles_by_their_centres():
    _, lab, small, large = two_class_frame(bled=True)
    # class 2 (20 discs) is one blob: its distance transform has peaks only along the middle
    assert count_particles(lab == 2, 30.0, 0.8) == pytest.approx(len(large), rel=0.12)
    assert count_particles(lab == 1, 20.0, 0.8) == len(small)  # touching at a seam: one peak each
    assert count_particles(lab == 1, math.nan, 0.8) == 0


def isolated_bled_discs(d_px: float = 24.0) -> tuple[np.ndarray, np.ndarray, int]:
    """A hexagonal bed of touching discs: class 2 (dark, coloured) at positions no two of which touch,
    each surrounded by class 1 (light); class 2 takes the gap pixels around its discs (bleeding:
    its map is a disc with the interstitial corners around it, as the real blue PMMA discs' maps
    under a warm light). Gray frame, class map, class-2 discs."""
    centres = hex_cluster(d_px, 7, 9, (30, 30))
    two = [i for i, _ in enumerate(centres) if (i // 9) % 2 == 0 and (i % 9) % 3 == 1]
    gray, lab = draw((230, 270), [(x, y, d_px, 110 if i in two else 200, 2 if i in two else 1)
                                  for i, (x, y) in enumerate(centres)])
    yy, xx = np.mgrid[0:lab.shape[0], 0:lab.shape[1]]
    for i in two:
        x, y = centres[i]
        near = ((xx - x) ** 2 + (yy - y) ** 2 <= (0.5 * d_px + 4) ** 2) & (lab == 0)
        lab[near] = 2
        gray[near] = DARK_GRAY
    return gray, lab, len(two)


def test_particle_body_drops_the_dark_gaps_a_class_took_and_keeps_its_particles():
    gray, lab, n = isolated_bled_discs()
    disc_px = math.pi / 4 * 23.0 ** 2  # the drawn discs (a one-pixel seam)
    body = particle_body(lab == 2, gray)
    assert not np.any(body & (gray == DARK_GRAY))
    assert np.all(body[(lab == 2) & (gray >= 100)])
    raw = single_particle_crops(lab == 2, 24.0, max_n=40)  # the corners it took: bigger than a disc
    assert raw and min(c.sum() for c in raw) > 1.1 * disc_px
    crops = single_particle_crops(body, 24.0, max_n=40)  # its particles alone: a disc's area each
    assert len(crops) >= 0.8 * n
    for c in crops:
        assert c.sum() == pytest.approx(disc_px, rel=0.08)
    assert particle_body(np.zeros_like(lab, bool), gray).sum() == 0
    with pytest.raises(ValueError):
        particle_body(lab[:-1] == 2, gray)


def test_class_size_takes_the_circles_when_there_are_enough_and_the_runs_otherwise():
    many = np.full(CIRCLES_MIN, 20.0)
    assert class_size(many, [30.0, 31.0]) == ClassSize(20.0, "circles", CIRCLES_MIN)
    assert class_size(many[:-1], [30.0, 31.0, math.nan]) == ClassSize(30.5, "runs", 2)
    got = class_size(np.zeros(0), [math.nan])
    assert math.isnan(got.diameter_px) and got.source == "runs" and got.count == 0


def test_census_shares_and_fill_from_counts_at_the_merged_size():
    sizes = [ClassSize(20.0, "circles", 40), ClassSize(21.0, "runs", 3)]  # within 10 %: one size, 20.5
    cen = census(["a", "b"], np.array([[300.0, 100.0]]), np.array([10_000.0]), sizes, np.array([[30, 10]]),
                 [-30.0], 50.0, 0.8)
    assert cen.same_size and [c.diameter_px for c in cen.classes] == [20.5, 20.5]
    assert [c.share for c in cen.classes] == pytest.approx([0.75, 0.25])
    assert [c.pixel_share for c in cen.classes] == pytest.approx([0.75, 0.25])
    assert cen.fill == pytest.approx(40 * math.pi / 4 * 20.5 ** 2 / (0.8 * math.pi * 50.0 ** 2))
    assert cen.direction == -1 and cen.classes[1].own == sizes[1]
    with pytest.raises(ValueError):
        census(["a"], np.array([[1.0]]), np.array([1.0]), sizes, np.array([[1]]), [0.0], 1.0, 0.8)


def test_the_beds_cover_is_its_envelope_whatever_is_painted_of_each_particle() -> None:
    """``bed_cover``: the gaps between packed discs and their highlights do not count against the bed;
    a half-filled drum is half covered whether its discs are drawn whole or as rings."""
    r, d = 150, 16.0
    yy, xx = np.mgrid[0:2 * r, 0:2 * r]
    inside = (xx - r + 0.5) ** 2 + (yy - r + 0.5) ** 2 <= r * r
    lower = inside & (yy >= r)  # the bed: the lower half
    centres = [(x, y) for x, y in hex_cluster(d, 30, 30, (0, 0))
               if lower[min(int(y), 2 * r - 1), min(int(x), 2 * r - 1)]]
    whole = np.zeros((2 * r, 2 * r), np.uint8)
    rings = np.zeros_like(whole)
    for x, y in centres:
        cv2.circle(whole, (int(round(x)), int(round(y))), int(0.5 * d) - 1, 1, -1)
        cv2.circle(rings, (int(round(x)), int(round(y))), int(0.5 * d) - 2, 1, 2)  # a glossy disc: its rim only
    for bed in (whole, rings):
        assert bed_cover(bed.astype(bool) & inside, inside, d) == pytest.approx(0.5, abs=0.03)
    assert math.isnan(bed_cover(whole.astype(bool), np.zeros_like(inside), d))


def test_spread_ratios_put_a_core_class_under_one_and_a_rim_class_over() -> None:
    """Parallel-axis theorem against the pixels themselves: a class in the core (a small disc of pixels)
    and one around it (a ring), each class's rms distance from the whole bed's centroid over the bed's."""
    yy, xx = np.mgrid[0:200, 0:200].astype(float)
    rr = np.hypot(xx - 100, yy - 120)
    core, rim = rr < 40, (rr >= 40) & (rr < 70)
    stats = []
    for m in (core, rim):
        x, y = xx[m], yy[m]
        stats.append((x.mean(), y.mean(), math.sqrt(x.var() + y.var()), m.sum()))
    ratios = spread_ratios(*zip(*stats, strict=True))
    bed = core | rim
    bx, by = xx[bed].mean(), yy[bed].mean()
    s_bed = math.sqrt(np.mean((xx[bed] - bx) ** 2 + (yy[bed] - by) ** 2))
    want = [math.sqrt(np.mean((xx[m] - bx) ** 2 + (yy[m] - by) ** 2)) / s_bed for m in (core, rim)]
    assert ratios == pytest.approx(want, rel=1e-9)
    assert ratios[0] < 0.8 < 1.1 < ratios[1]
    mixed = spread_ratios([100.0, 100.0], [120.0, 120.0], [30.0, 30.0], [500, 700])
    assert mixed == pytest.approx((1.0, 1.0))
    assert all(math.isnan(v) for v in spread_ratios([math.nan], [math.nan], [math.nan], [0]))


def test_a_notched_disc_is_one_particle_not_two_however_it_lies() -> None:
    """A notched disc's distance transform has two equal maxima, one each side of its notch: they are
    one particle's (the count of separate and of packed notched discs is their number)."""
    from sim.mixer import Shape, shape_outline_m

    v = shape_outline_m(Shape("notched_disc", 1.0, notch_deg=90.0, notch_depth=0.4)) * 36.0
    rng = np.random.default_rng(1)
    for step, n in ((45.0, 8), (36.0, 9)):  # apart, and packed (touching)
        m = np.zeros((int(step * n) + 40, int(step * n) + 40), np.uint8)
        for i in range(n):
            for j in range(n):
                a = rng.uniform(0, 2 * np.pi)
                rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
                pts = (v @ rot.T + (30 + step * i + 0.5 * step * (j % 2), 30 + step * 0.87 * j)) * 16
                cv2.fillPoly(m, [pts.astype(np.int32)], 1, shift=4)
        assert count_particles(m.astype(bool), 36.0, 0.8) == n * n


def test_a_classs_particles_reach_their_gray_edge_and_stop_at_a_neighbour_of_another_class() -> None:
    """``particle_edges``: a class map eroded by blurred colour (two pixels short of the discs' gray edge)
    gets its particles' own outline back; the pixels of a touching disc of the other class stay out."""
    gray, lab = draw((120, 160), [(40, 60, 30, 200, 1), (70, 60, 30, 110, 2)])
    eroded = cv2.erode((lab == 1).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))).astype(bool)
    edges = particle_edges(eroded, gray, lab == 2, GAP_GRAY)
    true = lab == 1
    assert np.count_nonzero(edges & ~true) <= 0.02 * true.sum()  # nothing of the neighbour, nor the gap
    assert np.count_nonzero(edges) == pytest.approx(true.sum(), rel=0.05)  # the disc's own area back

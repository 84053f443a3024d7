"""What a particle's outline shows (``vision.shapes``), on drawn particles of known shape: a notch of any
depth the camera resolves is a notch, with its opening and depth; a cut disc is a notch to the centre;
elongated and polygonal particles are told apart from discs; outlines too rough to read (the real PMMA
frames' class maps at 22 px) fall back to the coarse area test, and particles too small say so."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from vision.shapes import (
    NOTCH_MIN_DEPTH,
    SHAPE_MIN_PX,
    outline_kind,
    outline_of,
    particle_shape,
)


def _outline_m(kind: str, **kw: float) -> np.ndarray:
    from sim.mixer import Shape, shape_outline_m

    return shape_outline_m(Shape(kind, 1.0, **kw), segments=192)  # type: ignore[arg-type]


def _crop(v: np.ndarray, d_px: float, angle: float, shift: tuple[float, float]) -> np.ndarray:
    """A boolean crop of outline ``v`` (unit diameter) drawn ``d_px`` across at its own area (as the
    renderer draws: ``sim.render.DRAW_INSET_PX``), turned and shifted (sub-pixel)."""
    from sim.render import DRAW_INSET_PX

    n = int(d_px) + 12
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    pts = (v * (d_px - 2 * DRAW_INSET_PX)) @ rot.T + (n / 2 + shift[0], n / 2 + shift[1])
    img = np.zeros((n, n), np.uint8)
    cv2.fillPoly(img, [np.rint(pts * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
    return img.astype(bool)


def _crops(v: np.ndarray, d_px: float, n: int = 16, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [_crop(v, d_px, rng.uniform(0, 2 * math.pi), tuple(rng.uniform(-0.5, 0.5, 2))) for _ in range(n)]


@pytest.mark.parametrize("d_px", [33.0, 44.0])
def test_a_shallow_notch_is_seen_with_its_opening_and_depth(d_px: float) -> None:
    """Issue 39's particle: a 90-degree wedge cut to 40 % of the radius (5 % of the disc's area: a disc by
    area and solidity) is a notched disc, its opening and depth within 10 %, the disc's diameter within 0.8 px."""
    got = particle_shape(_crops(_outline_m("notched_disc", notch_deg=90.0, notch_depth=0.4), d_px), d_px)
    assert got.kind == "notched_disc", got.how
    assert got.notch_deg == pytest.approx(90.0, rel=0.10)
    assert got.notch_depth == pytest.approx(0.4, rel=0.10)
    assert abs(got.diameter_px - d_px) <= 0.8 and got.sized  # within a pixel's edge
    assert "notch of" in got.how


def test_a_cut_disc_is_a_notch_to_the_centre() -> None:
    got = particle_shape(_crops(_outline_m("cut_disc", wedge_deg=90.0), 33.0), 33.0)
    assert got.kind == "notched_disc"
    assert got.notch_depth == pytest.approx(1.0, abs=0.1) and got.notch_deg == pytest.approx(90.0, rel=0.1)


def test_a_disc_has_no_notch_however_it_is_drawn() -> None:
    for d_px in (22.0, 33.0, 44.0):
        crops = _crops(_outline_m("disc"), d_px, seed=int(d_px))
        outlines = [outline_of(c) for c in crops]
        assert all(o is not None and o.notch_depth < NOTCH_MIN_DEPTH for o in outlines)
        got = particle_shape(crops, d_px)
        assert got.kind == "disc" and got.outline_px is None and abs(got.diameter_px - d_px) <= 0.8  # a pixel's edge


def test_an_elongated_particle_is_a_pellet_and_a_hexagon_a_polygon() -> None:
    from sim.mixer import Shape, shape_outline_m

    pellet = shape_outline_m(Shape("pellet", 1.0, width_m=0.5, corner_m=0.1))
    got = particle_shape(_crops(pellet, 40.0), 40.0)
    assert got.kind == "pellet" and got.width_px / got.diameter_px == pytest.approx(0.5, rel=0.15)
    got = particle_shape(_crops(_outline_m("polygon", sides=6), 44.0), 44.0)
    assert got.kind == "polygon" and got.sides == 6
    got = particle_shape(_crops(_outline_m("polygon", sides=4), 44.0), 44.0)
    assert got.kind == "polygon" and got.sides == 4


def test_one_outline_known_answers() -> None:
    o = outline_of(_crop(_outline_m("notched_disc", notch_deg=60.0, notch_depth=0.5), 60.0, 0.3, (0.2, 0.1)))
    assert o is not None and outline_kind(o) == "notched_disc"
    assert o.notch_depth == pytest.approx(0.5, rel=0.1) and o.notch_deg == pytest.approx(60.0, rel=0.15)
    assert 2 * o.radius_px == pytest.approx(60.0, rel=0.02) and o.round_rms < 0.03
    assert outline_of(np.zeros((10, 10), bool)) is None


def test_rough_outlines_fall_back_to_the_area_test_and_say_so() -> None:
    """Discs whose class map is lumpy at their edge (as the real PMMA frames' at 22 px: 0.06 radii from their
    circle, 0.94 of their hull, concavities 0.14-0.23 radii deep from a neighbour or the colour's blur):
    no notch is read into them; round by their area against the enclosing circle and the hull, and the
    note says the outlines were too rough to read."""
    rng = np.random.default_rng(3)
    th = np.linspace(0, 2 * np.pi, 96, endpoint=False)
    crops = []
    for _ in range(20):  # the radius wobbling with harmonics 3-8, 4 % each
        r = 0.5 * (1 + sum(rng.normal(0, 0.04) * np.cos(k * th + rng.uniform(0, 2 * np.pi)) for k in range(3, 9)))
        crops.append(_crop(np.stack([r * np.cos(th), r * np.sin(th)], axis=1), 24.0, 0.0, (0.0, 0.0)))
    got = particle_shape(crops, 24.0)
    assert got.kind == "disc" and not got.sized and "too rough" in got.how, got.how


def test_particles_too_small_to_trace_say_so() -> None:
    got = particle_shape(_crops(_outline_m("notched_disc", notch_deg=90.0, notch_depth=0.4), 12.0), 12.0)
    assert got.kind == "disc" and "too few pixels" in got.how and f"{SHAPE_MIN_PX:g}" in got.how

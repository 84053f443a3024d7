"""The synthetic camera (``sim.render``) draws each particle at its own area: OpenCV's filled circles and
polygons reach ``DRAW_INSET_PX`` past their outline, which made a 36 px disc cover 4 % more than itself
(the commissioning's fill check compares a twin's rendered bed with a camera's, issue 39)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.mixer import Shape, shape_area_m2, shape_outline_m
from sim.recipe import DrumSpec
from sim.render import Renderer, size_for_radius
from sim.twin_base import Particles


@pytest.mark.parametrize("r_m", [0.003, 0.005, 0.008])
def test_a_rendered_disc_covers_its_own_area(r_m: float) -> None:
    ren = Renderer(DrumSpec(0.25, 0.01), 1024, rim_px=3)
    x = np.linspace(-0.08, 0.08, 9) + 0.0003  # off the pixel grid
    p = Particles(x_m=x, y_m=np.full(9, 0.01), r_m=np.full(9, r_m), cls=np.zeros(9, int), class_bgr=((0, 0, 220),))
    img = ren.render(p)
    drawn = np.count_nonzero((img[:, :, 2] > 150) & (img[:, :, 0] < 60)) / 9
    assert drawn == pytest.approx(np.pi * (r_m * ren.px_per_m) ** 2, rel=0.03)  # drawn as is: 4-12 % more


def test_a_rendered_shape_covers_its_own_area() -> None:
    ren = Renderer(DrumSpec(0.25, 0.01), 1024, rim_px=3)
    shape = Shape("notched_disc", 0.010, notch_deg=90.0, notch_depth=0.4)
    p = Particles(x_m=np.array([-0.03, 0.0, 0.03]), y_m=np.zeros(3), r_m=np.full(3, 0.005), cls=np.zeros(3, int),
                  angle_rad=np.array([0.0, 1.0, 2.0]), class_bgr=((0, 0, 220),),
                  class_outline_m=(shape_outline_m(shape),))
    img = ren.render(p)
    drawn = np.count_nonzero((img[:, :, 2] > 150) & (img[:, :, 0] < 60)) / 3
    assert drawn == pytest.approx(shape_area_m2(shape) * ren.px_per_m ** 2, rel=0.03)


def test_a_frame_sized_for_a_cameras_drum_radius() -> None:
    for r_px in (100.0, 312.4, 441.0):
        assert Renderer(DrumSpec(0.25, 0.01), size_for_radius(r_px, 3), rim_px=3).r_px == pytest.approx(r_px, abs=0.6)

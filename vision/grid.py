"""The meter's geometry of one frame size (pure): the drum ROI's stride grid, its row spans, the
occupancy cells of the free surface and their ROI areas, anchored on the drum centre (a camera
turned by quarter turns or mirrored samples the same drum pixels, turned); built once per frame
size by ``vision.meter.Meter`` and reused for every frame of that size."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vision.moments import row_spans
from vision.roi import DrumROI, _mask_in_box, roi_bbox
from vision.slope import cell_areas, occupancy_shift

__all__ = ["Geometry", "anchored_grid", "build_geometry"]


@dataclass
class Geometry:
    """The grid, spans and cells of one frame size (and the kernel's buffers for them)."""

    roi: DrumROI
    box: tuple[int, int, int, int]  # x0, y0, x1, y1 of the ROI's bounding box, px (x0, y0: the grid's first pixel)
    first: np.ndarray  # per grid row of the box: first and one-past-last grid column inside the ROI
    last: np.ndarray
    roi_px: float  # grid pixels inside the ROI
    shift: int  # occupancy cells of 2^shift px
    area: np.ndarray  # grid pixels of the ROI per occupancy cell
    full_area: float
    occ: np.ndarray  # bed pixels per cell (filled by the kernel)
    work: np.ndarray
    gocc: np.ndarray  # glare pixels per cell (filled by the kernel)
    outside: float = 0.0  # share of the ROI's area outside the image
    sample: np.ndarray | None = None  # flat indices of the ROI pixels the light is estimated from
    cell_off: tuple[int, int] = (0, 0)  # the occupancy cells start this far (px) left of / above box[:2]

    @property
    def cells_xy(self) -> tuple[int, int]:
        """Image px of the occupancy grid's corner (may lie left of or above the image)."""
        return self.box[0] - self.cell_off[0], self.box[1] - self.cell_off[1]


def build_geometry(roi: DrumROI, shape_hw: tuple[int, int], stride: int) -> Geometry:
    """The geometry of the drum ``roi`` in frames of ``shape_hw`` (px) on a grid of ``stride``."""
    s = stride
    shift = occupancy_shift(roi.r_px, s)
    clipped = roi_bbox(roi, shape_hw)
    box, off = anchored_grid(clipped, roi, s, 1 << shift)
    inside = _mask_in_box(roi, box)[::s, ::s]
    first, last = row_spans(inside)
    area = cell_areas(inside, s, shift, off)
    full = float(((1 << shift) + s - 1) // s) ** 2
    in_view = float(_mask_in_box(roi, clipped).sum())  # the ROI's pixels in the image
    return Geometry(roi, box, first, last, float(inside.sum()), shift, area, full,
                    np.zeros(area.shape, np.int32), np.empty(2 * area.shape[1] + 5, np.float64),
                    np.zeros(area.shape, np.int32), max(0.0, 1.0 - in_view / roi.area_px), cell_off=off)


def anchored_grid(box: tuple[int, int, int, int], roi: DrumROI, step: int,
                  cell: int) -> tuple[tuple[int, int, int, int], tuple[int, int]]:
    """The stride grid and the occupancy cells anchored on the drum centre, so that a camera
    turned by a quarter turn or mirrored samples the same pixels of the drum and bins them
    into the same cells, turned (the free surface is the same fit, not one on pixels or cells
    shifted by a fraction): the grid through the pixel nearest the centre (the box's first
    pixel moved right/down by less than ``step``), cell edges on the pixel edge nearest the
    centre (the cells start left of/above that pixel by the returned offset, px, less than
    ``cell``; they may start outside the image when the drum fills it). Before, the box itself
    was anchored unless that left the image, and the stride grid's phase followed it: on real
    frames a mirror moved the slope by up to 2.9 deg (0022, 0036, 0064)."""
    x0, y0, x1, y1 = box
    px, py = round(roi.cx_px), round(roi.cy_px)  # the pixel nearest the centre
    gx, gy = x0 + (px - x0) % step, y0 + (py - y0) % step
    ex, ey = round(roi.cx_px + 0.5), round(roi.cy_px + 0.5)  # pixel index right of / below that edge
    return (gx, gy, x1, y1), ((gx - ex) % cell, (gy - ey) % cell)

"""One frame measured for commissioning, a camera's or the rendered twin's alike: the meter's reading
(``vision.meter``: slope, MI, each class's moments) and, from the same frame, the share of the drum the
bed covers and each class's spread ratio (``vision.census.bed_cover``, ``spread_ratios``); then the
numbers a set of frames gives (medians). Pure functions of images, configs and readings."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.calibrate_slope import frames_slope_deg
from vision.bed import bed_cover, spread_ratios
from vision.config import MeterConfig
from vision.meter import Meter, Reading, gravity_matrix
from vision.roi import DrumROI, roi_bbox, roi_mask
from vision.suggest import drum_labels


@dataclass(frozen=True)
class FrameMeasure:
    """One frame: its reading's free-surface slope (deg, gravity's frame) and MI (eq. 4, NaN when not
    valid), the meter's flags, the bed's cover of the drum (0..1), each counted class's spread ratio
    (in the meter's class order) and the bed's centroid's angle from gravity's down, seen from the
    drum's axis (deg; NaN without a bed)."""

    slope_deg: float
    mi: float
    flags: tuple[str, ...]
    cover: float
    ratios: tuple[float, ...]
    bed_angle_deg: float


def bed_angle_deg(reading: Reading, camera_rotation_deg: float, mirror: bool) -> float:
    """The angle (deg) between gravity's down and the line from the drum's axis to the bed's centroid
    (the counted classes' pixels), + towards gravity's right."""
    roi = reading.roi
    n = np.array([c.n_px for c in reading.classes], dtype=float)
    cx = np.array([c.cx_px for c in reading.classes], dtype=float)
    cy = np.array([c.cy_px for c in reading.classes], dtype=float)
    ok = np.isfinite(cx) & np.isfinite(cy) & (n > 0)
    if roi is None or not ok.any():
        return math.nan
    off = np.array([np.dot(n[ok], cx[ok]) / n[ok].sum() - roi.cx_px, np.dot(n[ok], cy[ok]) / n[ok].sum() - roi.cy_px])
    t = gravity_matrix(camera_rotation_deg, mirror)
    gx, gy = off if t is None else t @ off
    return math.degrees(math.atan2(-gx, gy))  # image y down: down is +y


def measure_frame(cfg: MeterConfig, meter: Meter, image: np.ndarray, roi: DrumROI, diameter_px: float) -> FrameMeasure:
    """``image`` measured by ``meter`` (made from ``cfg``) in the drum ``roi``, with particles
    ``diameter_px`` across (for the bed's cover)."""
    rd = meter.measure(image)
    lab = drum_labels(cfg, image, roi)
    x0, y0, x1, y1 = roi_bbox(roi, image.shape[:2])
    counted = [j + 1 for j, c in enumerate(cfg.classes) if not c.reject]
    cover = bed_cover(np.isin(lab, counted), roi_mask(roi, image.shape[:2])[y0:y1, x0:x1], diameter_px)
    cs = rd.classes
    ratios = spread_ratios([c.cx_px for c in cs], [c.cy_px for c in cs], [c.sigma_px for c in cs],
                           [c.n_px for c in cs])
    return FrameMeasure(float(rd.slope_deg), float(rd.mi) if rd.valid else math.nan, tuple(rd.flags), cover, ratios,
                        bed_angle_deg(rd, cfg.camera_rotation_deg, cfg.mirror))


@dataclass(frozen=True)
class Summary:
    """What a set of frames says (medians over the frames that have the number): the slope (deg,
    ``sim.calibrate_slope.frames_slope_deg``: the calibration's statistic) and
    its standard error (deg, ``1.25 sd / sqrt(n)``), the bed's cover, the MI over ``mi_frames``, each
    class's spread ratio over the same frames, the bed's angle from down (deg); ``frames`` measured,
    ``slopes`` with a free surface, ``mixed`` frames the MI and ratios are taken over."""

    slope_deg: float
    slope_se_deg: float
    cover: float
    mi: float
    ratios: tuple[float, ...]
    bed_angle_deg: float
    frames: int
    slopes: int
    mixed: int


def _median(v: Sequence[float] | np.ndarray) -> float:
    a = np.asarray(v, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else math.nan


def summarize(ms: Sequence[FrameMeasure], mixed: np.ndarray | None = None) -> Summary:
    """The medians of frames ``ms``; the MI and the spread ratios over ``mixed`` (a boolean per frame;
    None: every frame)."""
    slopes = np.array([m.slope_deg for m in ms], dtype=float)
    s = slopes[np.isfinite(slopes)]
    se = 1.25 * float(np.std(s)) / math.sqrt(s.size) if s.size > 1 else math.nan
    sel = np.ones(len(ms), dtype=bool) if mixed is None else np.asarray(mixed, dtype=bool)
    chosen = [m for m, k in zip(ms, sel, strict=True) if k]
    k = len(ms[0].ratios) if ms else 0
    return Summary(frames_slope_deg(s), se, _median([m.cover for m in ms]), _median([m.mi for m in chosen]),
                   tuple(_median([m.ratios[i] for m in chosen]) for i in range(k)),
                   _median([m.bed_angle_deg for m in ms]), len(ms), int(s.size), len(chosen))


__all__ = ["FrameMeasure", "Summary", "bed_angle_deg", "measure_frame", "summarize"]

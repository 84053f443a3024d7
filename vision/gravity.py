"""Gravity's frame: a camera turned (by any angle) or filmed through a mirror. The meter measures
the free surface and the bed's axis in gravity's frame and draws them back in the image (pure)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision.grid import Geometry
from vision.roi import DrumROI

__all__ = ["from_gravity", "gravity_matrix", "turn_grid", "turn_moments"]

_NAN = float("nan")


def gravity_matrix(camera_rotation_deg: float, mirror: bool) -> np.ndarray | None:
    """2x2 map of image offsets (px, y down) to gravity's frame, or None for the identity.

    The image is gravity's view mirrored (x -> -x, when ``mirror``), then turned
    counter-clockwise on screen by ``camera_rotation_deg``; this undoes both."""
    a = math.radians(camera_rotation_deg % 360.0)
    if a == 0.0 and not mirror:
        return None
    c, s = round(math.cos(a), 12), round(math.sin(a), 12)  # exact 0/1 for multiples of 90 deg
    turn_back = np.array([[c, -s], [s, c]])  # clockwise on screen by the angle (y down)
    flip = np.diag([-1.0, 1.0]) if mirror else np.eye(2)
    return flip @ turn_back


def turn_moments(t: np.ndarray, m00: float, m10: float, m01: float, m20: float, m11: float, m02: float,
                  cx: float, cy: float) -> tuple[float, float, float, float, float]:
    """Raw moments of the bed in gravity's frame (about the same drum centre)."""
    if not m00 > 0:
        return m10, m01, m20, m11, m02
    xb, yb = m10 / m00, m01 / m00
    cov = np.array([[m20 / m00 - xb * xb, m11 / m00 - xb * yb], [m11 / m00 - xb * yb, m02 / m00 - yb * yb]])
    gx, gy = t @ np.array([xb - cx, yb - cy]) + (cx, cy)
    cg = t @ cov @ t.T
    return (m00 * gx, m00 * gy, m00 * (cg[0, 0] + gx * gx), m00 * (cg[0, 1] + gx * gy),
            m00 * (cg[1, 1] + gy * gy))


def turn_grid(t: np.ndarray, g: Geometry, occ: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """The occupancy and area cells turned into gravity's frame (same cell size, about the
    drum centre): exact cell moves for multiples of 90 deg, bilinear otherwise. Returns the
    cells, their ROI areas and the new grid's origin (px in gravity's frame)."""
    cs = float(1 << g.shift)
    roi = g.roi
    c = np.array([roi.cx_px, roi.cy_px])
    o = np.array(g.cells_xy) + 0.5 * cs  # centre of cell (0, 0)
    span = roi.r_px + max(roi.half_w_px or 0.0, roi.half_h_px or 0.0)
    n = int(math.ceil(2.0 * span / cs)) + 4
    nominal = c - (0.5 * n) * cs
    shift = np.round((c + t @ (o - c) - nominal - 0.5 * cs) / cs)  # whole cells: exact for 90 deg turns
    go = c + t @ (o - c) - shift * cs  # centre of the new cell (0, 0)
    m = np.hstack([t, shift[:, None]])
    flags = cv2.INTER_LINEAR
    area = cv2.warpAffine(g.area.astype(np.float32), m, (n, n), flags=flags, borderValue=0).astype(np.float64)
    cells = cv2.warpAffine(occ[: g.area.shape[0], : g.area.shape[1]].astype(np.float32), m, (n, n), flags=flags,
                           borderValue=0).astype(np.float64)
    return cells, area, (float(go[0] - 0.5 * cs), float(go[1] - 0.5 * cs))


def from_gravity(t: np.ndarray, mid: tuple[float, float], slope_deg: float,
                  roi: DrumROI) -> tuple[tuple[float, float], float]:
    """A point and a line angle (deg, y up) of gravity's frame back in the image."""
    if not (math.isfinite(mid[0]) and math.isfinite(slope_deg)):
        return (_NAN, _NAN), _NAN
    inv = np.linalg.inv(t)
    c = np.array([roi.cx_px, roi.cy_px])
    p = inv @ (np.array(mid) - c) + c
    a = math.radians(slope_deg)
    dx, dy = inv @ np.array([math.cos(a), -math.sin(a)])
    ang = math.degrees(math.atan2(-dy, dx))
    ang = ang + 180.0 if ang <= -90.0 else ang - 180.0 if ang > 90.0 else ang
    return (float(p[0]), float(p[1])), ang

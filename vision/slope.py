"""Bed slope angle (degrees) from the moments of the bed mask.

The bed of a rotating drum is close to a circular segment whose free surface is a
chord. Such a segment is mirror-symmetric about the line through the drum centre
perpendicular to the chord, so one principal axis of the bed's pixel distribution lies
along the free surface. Of the two principal axes we take the one more perpendicular to
the offset from the drum centre to the bed centroid (that offset points away from the
surface), so the choice is right at any fill level. Cost: one moments pass.

Sign: the angle of the free surface against the image horizontal, in (-90, 90] degrees,
positive when the surface rises towards +x (to the right in the image, y up).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision.roi import DrumROI, roi_mask

__all__ = ["bed_slope_deg", "slope_from_moments"]


def slope_from_moments(
    m00: float, m10: float, m01: float, m20: float, m11: float, m02: float,
    cx_px: float, cy_px: float, min_px: float = 1.0,
) -> float:
    """Free-surface angle (deg) from raw image moments of the bed (px units) and drum centre.

    NaN when the bed has fewer than ``min_px`` pixels or is isotropic (full drum).
    """
    if not (m00 >= min_px) or not math.isfinite(m00):
        return float("nan")
    xb, yb = m10 / m00, m01 / m00
    mu20 = m20 / m00 - xb * xb
    mu02 = m02 / m00 - yb * yb
    mu11 = m11 / m00 - xb * yb
    if not (math.isfinite(mu20) and math.isfinite(mu02) and math.isfinite(mu11)):
        return float("nan")
    theta = 0.5 * math.atan2(2.0 * mu11, mu20 - mu02)  # major axis, image coords (y down)
    ux, uy = math.cos(theta), math.sin(theta)
    ox, oy = xb - cx_px, yb - cy_px
    onorm = math.hypot(ox, oy)
    spread = math.sqrt(max(mu20 + mu02, 0.0))
    if onorm > 0.02 * spread:
        # the surface direction is the principal axis most perpendicular to the offset
        if abs(ux * ox + uy * oy) > abs(-uy * ox + ux * oy):
            ux, uy = -uy, ux
    elif abs(mu20 - mu02) < 1e-9 and abs(mu11) < 1e-9:
        return float("nan")
    ang = math.degrees(math.atan2(-uy, ux))  # y up
    if ang <= -90.0:
        ang += 180.0
    elif ang > 90.0:
        ang -= 180.0
    return ang


def bed_slope_deg(bed_mask: np.ndarray, roi: DrumROI) -> float:
    """Slope angle (deg) of the free surface of the bed in ``bed_mask`` (bool/uint8, image-sized).

    Only pixels inside ``roi`` count. NaN for an empty bed.
    """
    m = np.asarray(bed_mask)
    inside = roi_mask(roi, m.shape[:2])
    b = ((m != 0) & inside).astype(np.uint8)
    mo = cv2.moments(b, binaryImage=False)
    return slope_from_moments(mo["m00"], mo["m10"], mo["m01"], mo["m20"], mo["m11"], mo["m02"], roi.cx_px, roi.cy_px)

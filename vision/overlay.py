"""Monitoring overlay: ROI, class centroids and spreads, and the numbers (paper fig. 7b)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision.colours import ColourClass
from vision.meter import Reading

__all__ = ["draw_overlay"]


def _fmt(x: float, spec: str = ".3f") -> str:
    return "nan" if not math.isfinite(x) else format(x, spec)


def draw_overlay(
    image_bgr: np.ndarray,
    reading: Reading,
    classes: tuple[ColourClass, ...] | None = None,
    *,
    mi_avg: float | None = None,
) -> np.ndarray:
    """A copy of the frame with the ROI, the fitted free surface over its central chord (line),
    each class's centroid (cross) and spread (circle of radius sigma), and a panel with MI,
    eq. 3, d, dsigma, slope (and the principal-axis angle), S-shape, concentration (and the
    moving average ``mi_avg`` if given). Colours come from ``classes`` (display_bgr)."""
    img = np.asarray(image_bgr)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    out = img.copy() if img.size else np.zeros((240, 320, 3), np.uint8)
    h, w = out.shape[:2]
    scale = max(0.4, min(w, h) / 900.0)
    th = max(1, int(round(2 * scale)))
    roi = reading.roi
    if roi is not None:
        c = (int(round(roi.cx_px)), int(round(roi.cy_px)))
        if roi.kind == "circle":
            cv2.circle(out, c, int(round(roi.r_px)), (0, 255, 255), th, cv2.LINE_AA)
        else:
            hw, hh = float(roi.half_w_px or 0.0), float(roi.half_h_px or 0.0)
            p0 = (int(roi.cx_px - hw), int(roi.cy_px - hh))
            p1 = (int(roi.cx_px + hw), int(roi.cy_px + hh))
            cv2.rectangle(out, p0, p1, (0, 255, 255), th, cv2.LINE_AA)
    mx, my = reading.surface_mid_px
    if math.isfinite(reading.surface_image_deg) and math.isfinite(mx) and math.isfinite(my) and roi is not None:
        a = math.radians(reading.surface_image_deg)  # the line as it lies in the image (turned camera)
        half = 0.5 * roi.r_px  # the central chord the angle is fitted over
        dx, dy = half * math.cos(a), -half * math.sin(a)
        p0 = (int(round(mx - dx)), int(round(my - dy)))
        p1 = (int(round(mx + dx)), int(round(my + dy)))
        for colour, t in (((0, 0, 0), th + 2), ((0, 220, 255), th)):
            cv2.line(out, p0, p1, colour, t, cv2.LINE_AA)
    colours = {c.name: c.display_bgr for c in classes} if classes else {}
    for k, st in enumerate(reading.classes):
        if not (math.isfinite(st.cx_px) and math.isfinite(st.cy_px)):
            continue
        col = colours.get(st.name, ((0, 0, 255), (255, 0, 0), (0, 255, 0))[k % 3])
        c = (int(round(st.cx_px)), int(round(st.cy_px)))
        arm = int(14 * scale) + 4
        for colour, t in (((0, 0, 0), th + 2), (col, th)):
            cv2.line(out, (c[0] - arm, c[1]), (c[0] + arm, c[1]), colour, t, cv2.LINE_AA)
            cv2.line(out, (c[0], c[1] - arm), (c[0], c[1] + arm), colour, t, cv2.LINE_AA)
        if math.isfinite(st.sigma_px):
            cv2.circle(out, c, int(round(st.sigma_px)), col, th, cv2.LINE_AA)
    lines = [f"MI {_fmt(reading.mi)}  (eq.3 {_fmt(reading.mi_sigmoid)})"]
    if mi_avg is not None:
        lines.append(f"MI avg {_fmt(mi_avg)}")
    lines += [
        f"d {_fmt(reading.d_px, '.1f')} px  dsigma {_fmt(reading.dsigma_px, '.1f')} px",
        f"slope {_fmt(reading.slope_deg, '.1f')} deg (axis {_fmt(reading.slope_axis_deg, '.1f')})  "
        f"S {_fmt(reading.surface_curvature, '.2f')}  conc {_fmt(reading.concentration, '.2f')}",
    ]
    if not reading.valid:
        lines.append("INVALID " + " ".join(reading.flags)[:60])
    fs = 0.5 * scale * 1.6
    lh = int(22 * scale * 1.6)
    pw = int(max(cv2.getTextSize(s, cv2.FONT_HERSHEY_SIMPLEX, fs, 1)[0][0] for s in lines)) + 12
    ph = lh * len(lines) + 8
    roi_box = out[0 : min(h, ph), 0 : min(w, pw)]
    roi_box[...] = (roi_box * 0.35).astype(np.uint8)
    for i, s in enumerate(lines):
        cv2.putText(out, s, (6, lh * (i + 1)), cv2.FONT_HERSHEY_SIMPLEX, fs, (255, 255, 255), 1, cv2.LINE_AA)
    return out

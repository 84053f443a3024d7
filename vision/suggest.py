"""``classes suggest``: cluster the particle pixels inside the ROI into colour classes.

K-means (OpenCV) in CIE Lab on a sample of the ROI pixels with ``k + 1`` clusters; the
cluster that dominates the ring just inside the drum wall is the background. Each other
cluster becomes a class whose HSV box spans its 2nd..98th percentiles (plus a margin);
for weakly saturated clusters (white, grey) the hue is left open.
"""

from __future__ import annotations

import cv2
import numpy as np

from vision.colours import ColourClass
from vision.config import MeterConfig
from vision.errors import VisionError
from vision.roi import DrumROI, roi_bbox, _mask_in_box

__all__ = ["suggest_classes", "colour_name"]

_HUE_NAMES = ((8, "red"), (20, "orange"), (33, "yellow"), (78, "green"), (95, "teal"), (130, "blue"),
              (155, "purple"), (170, "magenta"), (180, "red"))


def colour_name(h: float, s: float, v: float) -> str:
    """A plain colour name for a mean HSV colour (OpenCV scale)."""
    if v < 60:
        return "black"
    if s < 60:
        return "white" if v > 150 else "grey"
    for top, name in _HUE_NAMES:
        if h < top:
            return name
    return "red"


def _hsv_box(hsv: np.ndarray, margin: int = 8) -> tuple[tuple, ...]:
    h, s, v = hsv[:, 0].astype(int), hsv[:, 1].astype(int), hsv[:, 2].astype(int)
    s_lo, s_hi = np.percentile(s, [2, 98])
    v_lo, v_hi = np.percentile(v, [2, 98])
    s_lo, s_hi = max(0, int(s_lo) - margin), min(255, int(s_hi) + margin)
    v_lo, v_hi = max(0, int(v_lo) - margin), min(255, int(v_hi) + margin)
    if np.median(s) < 70:  # hue is meaningless for white/grey
        return (((0, s_lo, v_lo), (179, s_hi, v_hi)),)
    # circular hue: rotate so the cluster's mean hue sits at 90, take percentiles, rotate back
    ang = h * (np.pi / 90.0)
    mean = int(round(np.degrees(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) / 2.0)) % 180
    rot = (h - mean + 90) % 180
    lo, hi = np.percentile(rot, [2, 98])
    lo, hi = int(lo) - margin // 2 + mean - 90, int(hi) + margin // 2 + mean - 90
    if hi - lo >= 179:
        return (((0, s_lo, v_lo), (179, s_hi, v_hi)),)
    if lo < 0:
        return (((0, s_lo, v_lo), (hi, s_hi, v_hi)), ((180 + lo, s_lo, v_lo), (179, s_hi, v_hi)))
    if hi > 179:
        return (((lo, s_lo, v_lo), (179, s_hi, v_hi)), ((0, s_lo, v_lo), (hi - 180, s_hi, v_hi)))
    return (((lo, s_lo, v_lo), (hi, s_hi, v_hi)),)


def suggest_classes(image_bgr: np.ndarray, roi: DrumROI, k: int = 2, seed: int = 0, max_samples: int = 40000) -> MeterConfig:
    """A ``MeterConfig`` with ``k`` classes found in the frame (ROI kept as given)."""
    img = np.asarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise VisionError(f"classes suggest needs a colour (BGR) image, got shape {img.shape}")
    if not 2 <= k <= 6:
        raise VisionError(f"k must be within 2..6, got {k}")
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    crop = img[y0:y1, x0:x1]
    inside = _mask_in_box(roi, box)
    yy, xx = np.nonzero(inside)
    rng = np.random.default_rng(seed)
    if yy.size > max_samples:
        pick = rng.choice(yy.size, max_samples, replace=False)
        yy, xx = yy[pick], xx[pick]
    bgr = crop[yy, xx].reshape(-1, 1, 3)
    lab = cv2.cvtColor(bgr, cv2.COLOR_BGR2Lab).reshape(-1, 3).astype(np.float32)
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV).reshape(-1, 3)
    cv2.setRNGSeed(seed)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.5)
    _, lbl, _ = cv2.kmeans(lab, k + 1, None, crit, 4, cv2.KMEANS_PP_CENTERS)
    lbl = lbl.ravel()
    rr = np.hypot(xx + x0 - roi.cx_px, yy + y0 - roi.cy_px) / roi.r_px
    ring = (rr > 0.8) & (rr < 0.95)
    counts = np.bincount(lbl[ring] if ring.any() else lbl, minlength=k + 1)
    bg = int(np.argmax(counts))
    classes: list[ColourClass] = []
    used: set[str] = set()
    order = sorted((c for c in range(k + 1) if c != bg), key=lambda c: -np.sum(lbl == c))
    for c in order:
        members = hsv[lbl == c]
        if members.shape[0] < 20:
            raise VisionError("could not find two particle colours inside the drum (too few pixels)")
        h_mean = np.degrees(np.arctan2(np.sin(members[:, 0] * np.pi / 90).mean(),
                                       np.cos(members[:, 0] * np.pi / 90).mean())) / 2 % 180
        name = colour_name(h_mean, float(np.median(members[:, 1])), float(np.median(members[:, 2])))
        base, n = name, 2
        while name in used:
            name = f"{base}{n}"
            n += 1
        used.add(name)
        mean_bgr = tuple(int(v) for v in crop[yy[lbl == c], xx[lbl == c]].mean(axis=0))
        classes.append(ColourClass(name, _hsv_box(members), mean_bgr))
    return MeterConfig(tuple(classes), None, "color", 50, 80, 1, "<suggested>")

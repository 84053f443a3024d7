"""Image builders with known geometry for the vision tests."""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision.roi import DrumROI

RED = (0, 0, 220)
BLUE = (220, 60, 0)


def blank(w: int = 640, h: int = 480) -> np.ndarray:
    img = np.full((h, w, 3), 15, np.uint8)
    cv2.circle(img, (w // 2, h // 2), int(0.45 * min(w, h)) + 4, (150, 150, 150), 3)
    return img


def roi_for(w: int = 640, h: int = 480) -> DrumROI:
    return DrumROI(w / 2, h / 2, 0.45 * min(w, h))


def half_disks(w: int = 640, h: int = 480) -> np.ndarray:
    img = blank(w, h)
    r = int(0.45 * min(w, h))
    c = (w // 2, h // 2)
    cv2.ellipse(img, c, (r, r), 0, 90, 270, RED, -1)
    cv2.ellipse(img, c, (r, r), 0, -90, 90, BLUE, -1)
    return img


def fine_mix(w: int = 640, h: int = 480, cell: int = 4, seed: int = 0) -> np.ndarray:
    img = blank(w, h)
    rng = np.random.default_rng(seed)
    gy, gx = h // cell + 1, w // cell + 1
    choice = rng.random((gy, gx)) < 0.5
    big = np.kron(choice, np.ones((cell, cell), bool))[:h, :w]
    inside = np.zeros((h, w), np.uint8)
    cv2.circle(inside, (w // 2, h // 2), int(0.45 * min(w, h)), 1, -1)
    img[(inside > 0) & big] = RED
    img[(inside > 0) & ~big] = BLUE
    return img


def core_ring(w: int = 640, h: int = 480, core_frac: float = 0.7071) -> np.ndarray:
    """Blue (small particles) in a central core, red (large) in the ring around it:
    equal areas when core_frac = 1/sqrt(2); both centroids at the centre."""
    img = blank(w, h)
    r = int(0.45 * min(w, h))
    c = (w // 2, h // 2)
    cv2.circle(img, c, r, RED, -1)
    cv2.circle(img, c, int(round(core_frac * r)), BLUE, -1)
    return img


def tilted_bed(
    angle_deg: float, fill: float = 0.5, w: int = 640, h: int = 480, dark: bool = False
) -> tuple[np.ndarray, DrumROI]:
    """A circular-segment bed whose flat free surface is at ``angle_deg`` (positive rises to
    the right), half red half blue along the surface; or a dark bed on a light drum."""
    roi = roi_for(w, h)
    R = roi.r_px
    # distance t of the chord below the centre for the wanted fill fraction
    lo, hi = -R, R
    for _ in range(60):
        t = 0.5 * (lo + hi)
        th = math.acos(t / R)
        seg = (th - math.sin(th) * math.cos(th)) / math.pi  # share beyond distance t
        if seg > fill:
            lo = t
        else:
            hi = t
    t = 0.5 * (lo + hi)
    a = math.radians(angle_deg)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    dx, dy = xs - roi.cx_px, ys - roi.cy_px
    # down-normal of the surface in image coords (y down): rotate (0, 1) by the angle
    nx, ny = math.sin(a), math.cos(a)
    inside = dx * dx + dy * dy <= R * R
    bed = inside & (dx * nx + dy * ny >= t)
    if dark:
        img = np.full((h, w, 3), 235, np.uint8)
        img[bed] = (30, 30, 30)
        return img, roi
    img = blank(w, h)
    along = dx * math.cos(a) - dy * math.sin(a)
    img[bed & (along < 0)] = RED
    img[bed & (along >= 0)] = BLUE
    return img, roi


def paired_errors(readings, truths):
    """Error / R of the class matched to colour 0 (classes matched to colours by the
    assignment with the smaller total error)."""
    best = None
    for order in ((0, 1), (1, 0)):
        errs = []
        for r, tru in zip(readings, truths, strict=True):
            st = r.classes[order[0]]
            errs.append(math.hypot(st.cx_px - tru[0][0], st.cy_px - tru[0][1]) / r.roi.r_px)
        other = sum(math.hypot(r.classes[order[1]].cx_px - t[1][0], r.classes[order[1]].cy_px - t[1][1])
                    for r, t in zip(readings, truths, strict=True))
        total = sum(errs) + other / readings[0].roi.r_px
        if best is None or total < best[0]:
            best = (total, errs)
    return best[1]


def jpeg(img: np.ndarray, quality: int = 90) -> np.ndarray:
    """The frame through a camera's JPEG (4:2:0 chroma) at ``quality``."""
    return cv2.imdecode(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])[1], cv2.IMREAD_COLOR)

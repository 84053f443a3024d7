"""Synthetic drum frames with known geometry (benchmarks and tests; no I/O)."""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["RED_BGR", "BLUE_BGR", "drum_frame"]

RED_BGR = (0, 0, 220)
BLUE_BGR = (220, 60, 0)


def drum_frame(
    size_wh: tuple[int, int] = (640, 480),
    *,
    mix: float = 1.0,
    fill: float = 0.5,
    slope_deg: float = 30.0,
    particle_r_frac: float = 0.035,
    seed: int = 0,
    r_frac: float = 0.46,
) -> np.ndarray:
    """A front-view drum: dark background, grey rim, a tilted bed of red and blue disks.

    ``mix`` 0 puts red on one side of the bed and blue on the other, 1 mixes them at
    random. ``slope_deg`` is the free-surface angle (positive rises to the right).
    """
    w, h = size_wh
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 18, np.uint8)
    cx, cy = w / 2.0, h / 2.0
    R = r_frac * min(w, h)
    cv2.circle(img, (int(cx), int(cy)), int(R), (150, 150, 150), max(2, int(R / 60)), cv2.LINE_AA)
    pr = particle_r_frac * R * 2
    # chord at distance t from the centre, normal pointing up (rotated by the slope)
    a = math.radians(slope_deg)
    nx, ny = -math.sin(a), -math.cos(a)  # image coords, "up" rotated
    # fill fraction -> chord offset t (segment below the chord) by bisection
    lo, hi = -R, R
    for _ in range(50):
        t = 0.5 * (lo + hi)
        th = math.acos(max(-1.0, min(1.0, t / R)))
        seg = (R * R * (th - math.sin(th) * math.cos(th))) / (math.pi * R * R)
        # seg = share of the disc beyond distance t from the centre
        if 1.0 - seg < fill:
            lo = t
        else:
            hi = t
    t = -0.5 * (lo + hi)
    step = pr * 2.05
    for gy in np.arange(cy - R, cy + R, step * 0.87):
        off = (int((gy - cy) / (step * 0.87)) % 2) * step / 2
        for gx in np.arange(cx - R + off, cx + R, step):
            x, y = gx + rng.normal(0, pr * 0.08), gy + rng.normal(0, pr * 0.08)
            dx, dy = x - cx, y - cy
            if math.hypot(dx, dy) > R - pr * 1.1:
                continue
            if dx * nx + dy * ny > t:  # above the free surface
                continue
            along = dx * math.cos(a) - dy * math.sin(a)
            seg_red = along < 0
            red = seg_red if rng.random() > mix else rng.random() < 0.5
            cv2.circle(img, (int(round(x)), int(round(y))), int(round(pr)), RED_BGR if red else BLUE_BGR, -1, cv2.LINE_AA)
    return img

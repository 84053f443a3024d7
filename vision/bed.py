"""The bed as a whole, as commissioning holds a twin's rendered frames against a camera's (issue 39):
the share of the drum the bed covers and each class's spread about the bed's centroid. Pure functions of
masks and a meter's class moments; px in the image."""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

__all__ = ["COVER_CELL_D", "bed_cover", "spread_ratios"]

COVER_CELL_D = 8.0  # the bed's cover is measured on a grid of this many cells per particle diameter


def bed_cover(bed: np.ndarray, inside: np.ndarray, diameter_px: float) -> float:
    """The share of the drum the bed covers: the bed's pixels (``bed``: the counted classes' union,
    boolean) closed by a disc of one particle ``diameter_px`` (the gaps between particles, their
    highlights and shaded rims) with the holes filled, over the drum's pixels (``inside``, same shape).
    A camera's and a rendered twin's frame read alike whatever each paints of a particle. Measured on a
    grid of ``COVER_CELL_D`` cells per diameter (cost); NaN for an empty drum."""
    b, m = np.asarray(bed, dtype=bool), np.asarray(inside, dtype=bool)
    if b.shape != m.shape:
        raise ValueError(f"bed and inside must be one (h, w) map (got {b.shape}, {m.shape})")
    s = max(1, int(diameter_px / COVER_CELL_D)) if math.isfinite(diameter_px) else 1
    b, m = b[::s, ::s] & m[::s, ::s], m[::s, ::s]
    if not m.any():
        return math.nan
    k = max(3, int(round(diameter_px / s)) | 1) if math.isfinite(diameter_px) else 3
    closed = cv2.morphologyEx(b.astype(np.uint8), cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE,
                                                                                              (k, k)))
    cnts, _ = cv2.findContours(closed, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(closed, cnts, -1, 1, thickness=cv2.FILLED)
    return float(np.count_nonzero(closed.astype(bool) & m)) / float(np.count_nonzero(m))


def spread_ratios(cx_px: Sequence[float], cy_px: Sequence[float], sigma_px: Sequence[float],
                  n_px: Sequence[float]) -> tuple[float, ...]:
    """Each class's spread about the whole bed's centroid over the bed's own (1 for a mixed bed; under 1
    for a class in the core, over 1 for one at the rim), from each class's centroid, own spread
    (``sigma = sqrt(var_x + var_y)``) and pixel count (the meter's ``ClassStats``): the parallel-axis
    theorem, ``s_k^2 = sigma_k^2 + |c_k - c_bed|^2`` with ``c_bed`` pixel-weighted. NaN for a class
    without pixels or a bed without any."""
    cx, cy, sg, n = (np.asarray(v, dtype=float) for v in (cx_px, cy_px, sigma_px, n_px))
    ok = np.isfinite(cx) & np.isfinite(cy) & np.isfinite(sg) & (n > 0)
    if not ok.any():
        return tuple(math.nan for _ in n)
    w = n[ok] / n[ok].sum()
    bx, by = float(np.dot(w, cx[ok])), float(np.dot(w, cy[ok]))
    s2 = sg ** 2 + (cx - bx) ** 2 + (cy - by) ** 2
    bed = math.sqrt(float(np.dot(w, s2[ok])))
    return tuple(math.sqrt(float(v)) / bed if k and bed > 0 else math.nan for v, k in zip(s2, ok, strict=True))

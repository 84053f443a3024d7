"""Particle-level measurements of the twin: MI (paper eq. 3/4) and the bed's free surface.

MI uses exactly the formulas of ``vision`` (``vision.mixing.mixing_indices``) on
area-weighted disk moments, so it is what the pixel meter would see on a perfect
frame: each disk counts with its area ``pi r^2`` at its centre plus its own second
moment ``r^2 / 2`` (polar) about it.

The slope is the angle of the bed's **free surface** (DESIGN.md), the definition the
camera's meter uses: the upper boundary of the disks, sampled in columns half a small
radius apart, and a robust straight-line fit over the central chord -- the columns
within ``CHORD_HALF_R * R`` of the surface's midpoint (the foot of the perpendicular
from the drum axis onto the surface line). A cubic fit over the same chord gives the
surface's S-shape (``curvature``). The principal axis of the bed's area moments is a
different, flatter number (``particle_axis_deg``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.drum import Particles
from sim.recipe import DrumSpec
from vision.meter import Meter
from vision.mixing import MixingIndices, mixing_indices
from vision.slope import slope_from_moments

__all__ = [
    "CHORD_HALF_R", "FreeSurface", "class_moments", "free_surface", "particle_axis_deg", "particle_mi",
    "particle_slope_deg", "surface_profile", "twin_meter",
]

CHORD_HALF_R = 0.5  # half-width of the central chord, in drum radii
_TRIM_K = 2.5  # robust fit: drop columns more than this many robust sd off the line


@dataclass(frozen=True)
class FreeSurface:
    """The bed's free surface: slope (deg, rising to the right > 0), S-shape, chord used.

    ``curvature``: the cubic term of ``y/R`` over the chord in the chord's own unit
    ``u = (x - x_mid) / (CHORD_HALF_R R)``, sign chosen so that an S-shaped surface
    (steeper in the middle, flatter at both ends -- the cascading "kidney") is positive
    whichever way the bed leans; 0 for a straight surface.
    """

    slope_deg: float
    curvature: float
    x_mid_m: float
    n_columns: int


def class_moments(particles: Particles, k: int) -> tuple[tuple[float, float], float, float]:
    """Area-weighted centroid ``(x_m, y_m)`` (y up), spread ``sigma_m`` and area (m^2) of class ``k``.

    ``sigma^2 = sum A_i (|p_i - c|^2 + r_i^2 / 2) / sum A_i`` -- the radius of gyration of
    the union of the disks, as the pixel meter computes it. NaN for an empty class.
    """
    m = particles.cls == k
    if not np.any(m):
        nan = float("nan")
        return (nan, nan), nan, 0.0
    r = particles.r_m[m]
    a = math.pi * r * r
    area = float(a.sum())
    cx = float(np.dot(a, particles.x_m[m]) / area)
    cy = float(np.dot(a, particles.y_m[m]) / area)
    var = float(np.dot(a, (particles.x_m[m] - cx) ** 2 + (particles.y_m[m] - cy) ** 2 + 0.5 * r * r) / area)
    return (cx, cy), math.sqrt(var), area


def particle_mi(particles: Particles, drum: DrumSpec, d0_m: float | None = None) -> MixingIndices:
    """Particle-level mixing indices of classes 0 and 1 (eq. 4 ``mi``, eq. 3 ``mi_sigmoid``).

    Lengths of the result (``d_px``, ``dsigma_px``) are in metres here.
    """
    c1, s1, _ = class_moments(particles, 0)
    c2, s2, _ = class_moments(particles, 1)
    return mixing_indices(c1, c2, s1, s2, drum.radius_m, d0_m)


def surface_profile(particles: Particles, drum: DrumSpec, step_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Upper boundary of the bed (y up, m) in columns ``step_m`` apart (default half a small radius).

    A column's height is the top of the highest disk over it; NaN where no disk is.
    """
    r = particles.r_m
    big_r = drum.radius_m
    if r.size == 0:
        return np.zeros(0), np.zeros(0)
    h = 0.5 * float(r.min()) if step_m is None else float(step_m)
    xs = np.arange(-big_r + 0.5 * h, big_r, h)
    dx = xs[:, None] - particles.x_m[None, :]
    rr = r[None, :] ** 2 - dx * dx
    top = np.where(rr > 0, particles.y_m[None, :] + np.sqrt(np.maximum(rr, 0.0)), -np.inf).max(axis=1)
    return xs, np.where(np.isfinite(top), top, np.nan)


def _robust_polyfit(x: np.ndarray, y: np.ndarray, deg: int, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares polynomial with two rounds of trimming beyond ``_TRIM_K`` robust sd; (coefs, inliers)."""
    keep = np.ones(x.size, dtype=bool)
    coef = np.polyfit(x, y, deg)
    for _ in range(2):
        res = y - np.polyval(coef, x)
        mad = 1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep]))))
        keep = np.abs(res) <= max(_TRIM_K * mad, floor)
        if keep.sum() <= deg + 2:
            break
        coef = np.polyfit(x[keep], y[keep], deg)
    return coef, keep


def free_surface(particles: Particles, drum: DrumSpec) -> FreeSurface:
    """Slope and S-shape of the bed's free surface over the central chord (module doc); NaN if no bed."""
    nan = FreeSurface(float("nan"), float("nan"), float("nan"), 0)
    xs, top = surface_profile(particles, drum)
    ok = np.isfinite(top)
    if ok.sum() < 8:
        return nan
    big_r = drum.radius_m
    half = CHORD_HALF_R * big_r
    floor = 0.5 * float(particles.r_m.min())
    x_mid = 0.0
    coef = np.zeros(2)
    sel = ok
    for _ in range(3):  # centre the chord on the surface's midpoint
        sel = ok & (np.abs(xs - x_mid) <= half)
        if sel.sum() < 6:
            return nan
        coef, _ = _robust_polyfit(xs[sel], top[sel], 1, floor)
        b, a = float(coef[0]), float(coef[1])
        new_mid = float(np.clip(-a * b / (1.0 + b * b), -big_r + half, big_r - half))
        if abs(new_mid - x_mid) < 1e-4:
            x_mid = new_mid
            break
        x_mid = new_mid
    sel = ok & (np.abs(xs - x_mid) <= half)
    coef, keep = _robust_polyfit(xs[sel], top[sel], 1, floor)
    slope = float(coef[0])
    u = (xs[sel][keep] - x_mid) / half
    curv = float("nan")
    if u.size >= 6:
        c3 = np.polyfit(u, top[sel][keep] / big_r, 3)
        curv = float(-c3[0] * math.copysign(1.0, slope))
    return FreeSurface(math.degrees(math.atan(slope)), curv, x_mid, int(keep.sum()))


def particle_slope_deg(particles: Particles, drum: DrumSpec) -> float:
    """Free-surface slope angle (deg, positive rising to the right): ``free_surface(...).slope_deg``."""
    return free_surface(particles, drum).slope_deg


def particle_axis_deg(particles: Particles, drum: DrumSpec) -> float:
    """Principal-axis angle of the bed (deg) from the disks' area moments (``vision.slope`` method).

    The bed as a circular segment: flatter than the free surface when the surface is
    curved; kept as ``slope_axis_deg``'s particle-level twin.
    """
    r = particles.r_m
    if r.size == 0:
        return float("nan")
    a = math.pi * r * r
    x = particles.x_m
    y = -particles.y_m  # image orientation (y down), drum centre at the origin
    self_m = 0.25 * r * r  # each disk's own second moment about an axis
    m00 = float(a.sum())
    m10 = float(np.dot(a, x))
    m01 = float(np.dot(a, y))
    m20 = float(np.dot(a, x * x + self_m))
    m02 = float(np.dot(a, y * y + self_m))
    m11 = float(np.dot(a, x * y))
    return slope_from_moments(m00, m10, m01, m20, m11, m02, 0.0, 0.0, min_px=0.0) if m00 > 0 else float("nan")


def twin_meter(renderer, **kwargs) -> Meter:
    """A ``vision`` Meter for the renderer's frames: default classes, the exact drum ROI."""
    return Meter(roi=renderer.roi, **kwargs)

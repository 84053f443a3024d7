"""Particle-level measurements of the twin: MI (paper eq. 3/4) and free-surface slope.

Both use exactly the formulas of ``vision`` (``vision.mixing.mixing_indices`` and
``vision.slope.slope_from_moments``) on area-weighted disk moments, so they are what
the pixel meter would see on a perfect frame: each disk counts with its area
``pi r^2`` at its centre plus its own second moment ``r^2 / 2`` (polar) about it.
"""

from __future__ import annotations

import math

import numpy as np

from sim.drum import Particles
from sim.recipe import DrumSpec
from vision.meter import Meter
from vision.mixing import MixingIndices, mixing_indices
from vision.slope import slope_from_moments

__all__ = ["class_moments", "particle_mi", "particle_slope_deg", "twin_meter"]


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


def particle_slope_deg(particles: Particles, drum: DrumSpec) -> float:
    """Free-surface slope angle (deg, positive rising to the right) from the disks' area moments.

    Same principal-axis method as ``vision.slope`` (the bed as a circular segment), on the
    union of all disks; NaN for an empty bed.
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

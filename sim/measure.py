"""Particle-level measurements of the twin: MI (paper eq. 3/4) and the bed's free surface.

MI uses exactly the formulas of ``vision`` (``vision.mixing.mixing_indices``) on
area-weighted disk moments, so it is what the pixel meter would see on a perfect
frame: each disk counts with its area ``pi r^2`` at its centre plus its own second
moment ``r^2 / 2`` (polar) about it.

The slope is the angle of the bed's **free surface** (DESIGN.md), measured with the
camera meter's own fit (``vision.slope.fit_surface_points``: one fit for the camera and
the twin's calibration target) on the upper boundary of the disks, sampled in columns
half a small radius apart: a robust straight-line fit over the central chord (the points
within ``CHORD_HALF_R * R`` of the surface's midpoint along it), and a cubic through all
the points for the surface's S-shape (``curvature``). The principal axis of the bed's area moments is a
different, flatter number (``particle_axis_deg``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.recipe import DrumSpec
from sim.twin_base import Particles
from vision.meter import Meter
from vision.mixing import MixingIndices, mixing_indices
from vision.slope import CENTRAL_HALF_CHORD, fit_surface_points, slope_from_moments

__all__ = [
    "CHORD_HALF_R", "FreeSurface", "class_moments", "free_surface", "particle_axis_deg", "particle_mi",
    "particle_slope_deg", "radial_spread_m", "surface_profile", "twin_meter",
]

CHORD_HALF_R = CENTRAL_HALF_CHORD  # half-width of the central chord, in drum radii (the meter's)


@dataclass(frozen=True)
class FreeSurface:
    """The bed's free surface: slope (deg, rising to the right > 0), S-shape, chord centre.

    ``curvature``: minus the cubic coefficient of the profile ``v(u)`` (``u`` uphill along
    the surface line, ``v`` out of the bed, both in drum radii), as ``vision.slope``'s
    ``surface_curvature``: 0 for a flat surface, > 0 for the S-shape of a cascading bed
    (steeper in the middle, flatter at both ends) whichever way the bed leans.
    """

    slope_deg: float
    curvature: float
    x_mid_m: float
    n_columns: int
    y_mid_m: float = float("nan")  # a point of the surface line (x_mid_m, y_mid_m), m


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


def free_surface(particles: Particles, drum: DrumSpec) -> FreeSurface:
    """Slope and S-shape of the bed's free surface (module doc); NaN if there is no free surface.

    The surface points are the disks' upper boundary (``surface_profile``), less the columns whose
    bed reaches the drum wall above (no free surface there); the fit is the camera meter's own
    (``vision.slope.fit_surface_points``: a robust orthogonal line over the central chord, the
    cubic S-shape), on those points in metres (y flipped to the image's down), with half the
    smallest radius as the least residual scale.
    """
    nan = FreeSurface(float("nan"), float("nan"), float("nan"), 0, float("nan"))
    xs, top = surface_profile(particles, drum)
    if xs.size == 0:
        return nan
    big_r = drum.radius_m
    r_min = float(particles.r_m.min())
    wall_top = np.sqrt(np.maximum(big_r * big_r - xs * xs, 0.0))
    ok = np.isfinite(top) & (top < wall_top - 4.0 * r_min)  # the bed reaches the wall above: no surface
    if ok.sum() < 5:
        return nan
    fit = fit_surface_points(xs[ok], -top[ok], big_r, 0.5 * r_min)
    if not math.isfinite(fit.slope_deg):
        return nan
    return FreeSurface(fit.slope_deg, fit.curvature, fit.mid_px[0], int(ok.sum()), -fit.mid_px[1])


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


def radial_spread_m(particles: Particles, areas_m2: np.ndarray | None = None) -> tuple[float, ...]:
    """Each class's spread about the whole bed's centroid (m): ``sqrt(mean |p_i - c_bed|^2)`` over
    its particles, ``c_bed`` area-weighted (``areas_m2`` per class; None: ``pi r^2``)."""
    a = np.pi * particles.r_m ** 2 if areas_m2 is None else np.asarray(areas_m2)[particles.cls]
    cx = float(np.dot(a, particles.x_m) / a.sum())
    cy = float(np.dot(a, particles.y_m) / a.sum())
    d2 = (particles.x_m - cx) ** 2 + (particles.y_m - cy) ** 2
    k_max = int(particles.cls.max()) + 1 if len(particles) else 0
    return tuple(float(np.sqrt(d2[particles.cls == k].mean())) if np.any(particles.cls == k) else float("nan")
                 for k in range(k_max))


def twin_meter(renderer, **kwargs) -> Meter:
    """A ``vision`` Meter for the renderer's frames: default classes, the exact drum ROI."""
    return Meter(roi=renderer.roi, **kwargs)

"""The DEM's contact constants, computed in Python before a run (``sim.dem.run`` reads them):
the damping ratio that gives a restitution, a collision's duration, and per class pair the
stiffness, damping and rolling constants (``contact_tables``; the laws are in ``sim.dem``'s doc).

Units: m, s, kg, N.
"""

from __future__ import annotations

import math

import numpy as np

_KT_SCALE = 2.0 / 7.0  # tangential stiffness / normal stiffness (balls: the same frequency)


def _clamped_collision(zeta: float) -> tuple[float, float]:
    """Restitution and duration (in units of ``1/omega_0``) of a linear spring-dashpot collision
    whose normal force may not pull (it ends when the force reaches zero), damping ratio ``zeta``
    (Schwager & Poeschel, Phys. Rev. E 78, 051304, 2008; the overdamped branch likewise)."""
    if zeta <= 0.0:
        return 1.0, math.pi
    if zeta < 1.0:
        w = math.sqrt(1.0 - zeta * zeta)
        if zeta < math.sqrt(0.5):
            phase = math.pi - math.atan(2.0 * zeta * w / (w * w - zeta * zeta))
        else:
            phase = math.atan(2.0 * zeta * w / (zeta * zeta - w * w))
        return math.exp(-zeta / w * phase), phase / w
    w = math.sqrt(zeta * zeta - 1.0)
    if w == 0.0:  # critical damping: the limit of both branches
        return math.exp(-2.0), 2.0
    tau = math.atanh(2.0 * zeta * w / (2.0 * zeta * zeta - 1.0)) / w
    return -math.exp(-zeta * tau) * (math.cosh(w * tau) - zeta / w * math.sinh(w * tau)), tau


def damping_ratio(restitution: float) -> float:
    """Damping ratio ``zeta`` (``c_n = 2 zeta sqrt(m* k_n)``) that gives ``restitution`` (0..1] to a
    collision whose normal force may not pull (``_clamped_collision``), by bisection."""
    if restitution >= 1.0:
        return 0.0
    lo, hi = 0.0, 50.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if _clamped_collision(mid)[0] > restitution:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def contact_time_s(stiffness_n_m: float, mass_kg: float, restitution: float) -> float:
    """Duration (s) of a collision of effective mass ``mass_kg`` (no pull at the end)."""
    return _clamped_collision(damping_ratio(restitution))[1] * math.sqrt(mass_kg / stiffness_n_m)


def contact_tables(mass_kg: np.ndarray, radius_m: np.ndarray, stiffness_n_m: float,
                   restitution: float) -> tuple[np.ndarray, np.ndarray]:
    """Per class pair and per class at the wall, the contact constants ``run`` reads.

    Every contact lasts the same time (MercuryDPM's collision-time parametrisation): the lightest
    pair has the normal stiffness ``stiffness_n_m`` (N/m), every other pair (and a disk at the
    wall, whose effective mass is its own) a stiffness in proportion to its effective mass ``m*``.
    ``mass_kg``, ``radius_m``: (n_cls,) per class. Returns ``c_pair`` (n_cls, n_cls, 6): normal
    damping (N s/m), ``r_eff`` (m), ``1 / (1/I_i + 1/I_j)`` (kg m^2), ``k_n``, ``k_t = 2/7 k_n``
    (N/m), ``1 / k_t`` (m/N); and ``c_wall`` (n_cls, 4): normal damping, ``k_n``, ``k_t``, ``1 / k_t``.
    """
    m = np.asarray(mass_kg, dtype=np.float64)
    r = np.asarray(radius_m, dtype=np.float64)
    zeta = damping_ratio(restitution)
    m_pair = m[:, None] * m[None, :] / (m[:, None] + m[None, :])
    k_per_kg = stiffness_n_m / m_pair.min()
    inv_i = 1.0 / (0.4 * m * r**2)
    k_pair = k_per_kg * m_pair
    k_wall = k_per_kg * m
    c_pair = np.stack([2.0 * zeta * np.sqrt(m_pair * k_pair), r[:, None] * r[None, :] / (r[:, None] + r[None, :]),
                       1.0 / (inv_i[:, None] + inv_i[None, :]), k_pair, _KT_SCALE * k_pair,
                       1.0 / (_KT_SCALE * k_pair)], axis=-1)
    c_wall = np.stack([2.0 * zeta * np.sqrt(m * k_wall), k_wall, _KT_SCALE * k_wall, 1.0 / (_KT_SCALE * k_wall)],
                      axis=-1)
    return np.ascontiguousarray(c_pair), np.ascontiguousarray(c_wall)


__all__ = ["contact_tables", "contact_time_s", "damping_ratio"]

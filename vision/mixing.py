"""Centroid mixing indices (Byun & Son 2024, eq. 1, 3, 4) as pure functions.

All lengths are in pixels of the original image. NaN in, NaN out: a missing class
never raises and never produces a fake number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MixingIndices", "characteristic_distance", "mixing_indices", "sigmoid_f"]


@dataclass(frozen=True, slots=True)
class MixingIndices:
    """Mixing indices of one frame (dimensionless) and the distances behind them (px).

    ``mi`` is paper eq. 4 (the headline number), ``mi_sigmoid`` eq. 3, ``mi_linear``
    eq. 1 (NaN until a reference distance ``d0`` is known).
    """

    mi: float
    mi_sigmoid: float
    mi_linear: float
    d_px: float
    dsigma_px: float


def sigmoid_f(x):
    """The paper's sigmoid ``f(x) = 1 - 1 / (1 + exp(-10 (x - 1/2)))``.

    ``f(0) ~ 0.993``, ``f(1/2) = 0.5``, ``f(1) ~ 0.007``. Works on floats and arrays;
    NaN stays NaN.
    """
    if isinstance(x, (float, int)):
        z = -10.0 * (float(x) - 0.5)
        if z > 700.0:  # exp overflow: 1/(1+inf) = 0
            return 1.0
        return 1.0 - 1.0 / (1.0 + math.exp(z))
    xa = np.asarray(x, dtype=np.float64)
    with np.errstate(over="ignore"):
        return 1.0 - 1.0 / (1.0 + np.exp(-10.0 * (xa - 0.5)))


def characteristic_distance(r_px: float) -> float:
    """``d_c = 8 R / (3 pi)`` (px): centroid distance of the two halves of a disc of radius R.

    The characteristic spread is ``sigma_c = d_c / 2``.
    """
    return 8.0 * float(r_px) / (3.0 * math.pi)


def _finite(*vals: float) -> bool:
    return all(v is not None and math.isfinite(v) for v in vals)


def mixing_indices(
    c1: tuple[float, float],
    c2: tuple[float, float],
    sigma1: float,
    sigma2: float,
    r_px: float,
    d0: float | None = None,
) -> MixingIndices:
    """Mixing indices from two class centroids ``(x_px, y_px)`` and spreads ``sigma_px``.

    - ``d = |c1 - c2|``, ``dsigma = |sigma1 - sigma2|``, ``d_c = 8R/(3 pi)``, ``sigma_c = d_c/2``
    - eq. 1 ``mi_linear = 1 - d / d0`` (NaN when ``d0`` is None, non-finite or <= 0)
    - eq. 3 ``mi_sigmoid = f(d / d_c)``
    - eq. 4 ``mi = f(d / d_c) * f(dsigma / sigma_c)``

    Any NaN input (an empty class) gives NaN outputs; it never raises.
    """
    nan = float("nan")
    x1, y1 = float(c1[0]), float(c1[1])
    x2, y2 = float(c2[0]), float(c2[1])
    s1, s2, r = float(sigma1), float(sigma2), float(r_px)
    if not _finite(x1, y1, x2, y2, s1, s2, r) or r <= 0.0:
        return MixingIndices(nan, nan, nan, nan, nan)
    d = math.hypot(x1 - x2, y1 - y2)
    ds = abs(s1 - s2)
    dc = characteristic_distance(r)
    mi_sig = sigmoid_f(d / dc)
    mi = mi_sig * sigmoid_f(ds / (0.5 * dc))
    mi_lin = nan
    if d0 is not None and _finite(float(d0)) and float(d0) > 0.0:
        mi_lin = 1.0 - d / float(d0)
    return MixingIndices(float(mi), float(mi_sig), float(mi_lin), float(d), float(ds))

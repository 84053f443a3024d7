"""Kalman trend of the mixing index (filterpy), replacing the paper's moving average.

State ``x = [level, rate, ripple_c, ripple_s]``: the MI level, its rate of change
(MI/s, a random walk: constant-velocity model) and a rotating ripple pair at the
drum's rotation frequency ``omega = 2*pi*rpm/60 * harmonic`` (rad/s). The bed rolls
once per revolution, so vision MI oscillates at that frequency; the pair is rotated by
``omega*dt`` each step, with ``omega`` from the *actual* rpm passed to ``update`` (it
may change at run time). The measurement is ``MI = level + ripple_c + noise``.

- NaN MI (missing or invalid frame): predict only.
- Each measurement is gated by its normalised innovation squared
  ``d2 = y^2 / S`` (squared Mahalanobis distance): ``d2 > gate_d2`` is rejected
  (predict only); after ``max_rejections`` consecutive rejections the filter
  re-initialises on the current measurement (the process really moved).
- ``lo95``/``hi95`` is the 95 % band of the *level estimate* (``level +- 1.96 sd``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from control.errors import ControlError

Z95 = 1.959963984540054


@dataclass(frozen=True)
class TrendConfig:
    """Noise model and gating of :class:`MITrend`.

    ``meas_sd``: measurement noise sd (MI); ``rate_q``: spectral density of the rate
    random walk (MI^2/s^3); ``ripple_q``: ripple random walk (MI^2/s); ``ripple_harmonic``:
    ripple frequency in multiples of the rotation frequency; ``gate_d2``: rejection
    threshold on the squared Mahalanobis distance (9 = 3 sigma); ``max_rejections``:
    consecutive rejections before re-initialising; ``init_rate_sd`` (MI/s) and
    ``init_ripple_sd`` (MI): initial uncertainty; ``max_dt_s``: longer gaps re-initialise.
    """

    meas_sd: float = 0.05
    rate_q: float = 3e-4
    ripple_q: float = 1e-5
    ripple_harmonic: float = 1.0
    gate_d2: float = 9.0
    max_rejections: int = 15
    init_rate_sd: float = 0.02
    init_ripple_sd: float = 0.05
    max_dt_s: float = 30.0

    def __post_init__(self) -> None:
        if not (self.meas_sd > 0 and self.rate_q > 0 and self.ripple_q >= 0 and self.gate_d2 > 0):
            raise ControlError("trend noise levels must be positive (meas_sd, rate_q, gate_d2)")
        if self.max_rejections < 1:
            raise ControlError("max_rejections must be at least 1")


@dataclass(frozen=True)
class TrendEstimate:
    """One trend output. ``level`` (MI), ``rate`` (MI/s), their sds, the 95 % band of the
    level, whether this sample was ``accepted`` (False for NaN or gated) and whether
    the filter re-initialised on it; ``ripple`` is the current ripple term (MI) and
    ``nis`` the squared Mahalanobis distance of the innovation (NaN when no update)."""

    t_s: float
    level: float
    rate: float
    level_sd: float
    rate_sd: float
    lo95: float
    hi95: float
    accepted: bool
    reinit: bool
    ripple: float = 0.0
    nis: float = math.nan
    rejections: int = 0

    @property
    def valid(self) -> bool:
        """False until the first valid MI has initialised the filter."""
        return math.isfinite(self.level)


def estimate_meas_sd(mi: Sequence[float] | np.ndarray) -> float:
    """Measurement-noise sd of a window of raw MI (NaNs ignored).

    Robust: the median absolute first difference / (0.6745 * sqrt 2) — differencing
    removes the slow level and most of the (slow) ripple; the MAD ignores outliers.
    """
    x = np.asarray(mi, dtype=float)
    x = x[np.isfinite(x)]
    if x.size < 10:
        raise ControlError(f"need at least 10 valid MI samples to estimate noise, got {x.size}")
    d = np.diff(x)
    mad = float(np.median(np.abs(d - np.median(d))))
    return max(mad / (0.6744897501960817 * math.sqrt(2.0)), 1e-4)


def config_from_window(mi: Sequence[float] | np.ndarray, base: TrendConfig | None = None) -> TrendConfig:
    """``base`` (default :class:`TrendConfig`) with ``meas_sd`` estimated from ``mi``;
    ``rate_q`` and ``ripple_q`` scale with the measurement variance (keeps the filter's
    bandwidth, which depends only on their ratio)."""
    base = base or TrendConfig()
    sd = estimate_meas_sd(mi)
    k = (sd / base.meas_sd) ** 2
    return replace(base, meas_sd=sd, rate_q=base.rate_q * k, ripple_q=base.ripple_q * k)


class MITrend:
    """Online Kalman trend of MI: ``update(t_s, mi, rpm) -> TrendEstimate``.

    ``t_s`` (s) must not go backwards; ``mi`` may be NaN; ``rpm`` is the drum's actual
    speed, which sets the ripple frequency for the step that ends at ``t_s``.
    """

    def __init__(self, config: TrendConfig | None = None) -> None:
        from filterpy.kalman import KalmanFilter  # ~2 s import (scipy, matplotlib): only when used

        self.config = config or TrendConfig()
        self.kf = KalmanFilter(dim_x=4, dim_z=1)
        self.kf.H = np.array([[1.0, 0.0, 1.0, 0.0]])
        self.kf.R = np.array([[self.config.meas_sd**2]])
        self._t: float | None = None
        self._init = False
        self.rejections = 0
        self.n_reinit = 0

    def reset(self) -> None:
        """Forget everything; the next valid MI initialises the filter."""
        self._t = None
        self._init = False
        self.rejections = 0

    def _initialise(self, z: float) -> None:
        c = self.config
        self.kf.x = np.array([[z], [0.0], [0.0], [0.0]])
        self.kf.P = np.diag([c.meas_sd**2, c.init_rate_sd**2, c.init_ripple_sd**2, c.init_ripple_sd**2])
        self._init = True
        self.rejections = 0

    def _transition(self, dt: float, rpm: float) -> None:
        c = self.config
        w = 2.0 * math.pi * max(0.0, float(rpm) if math.isfinite(rpm) else 0.0) / 60.0 * c.ripple_harmonic
        cs, sn = math.cos(w * dt), math.sin(w * dt)
        self.kf.F = np.array(
            [[1.0, dt, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, cs, sn], [0.0, 0.0, -sn, cs]]
        )
        q = c.rate_q
        self.kf.Q = np.array(
            [
                [q * dt**3 / 3, q * dt**2 / 2, 0.0, 0.0],
                [q * dt**2 / 2, q * dt, 0.0, 0.0],
                [0.0, 0.0, c.ripple_q * dt, 0.0],
                [0.0, 0.0, 0.0, c.ripple_q * dt],
            ]
        )

    def update(self, t_s: float, mi: float, rpm: float = 0.0) -> TrendEstimate:
        """Advance to ``t_s`` and fold in ``mi`` (NaN: predict only)."""
        c = self.config
        t_s = float(t_s)
        z = float(mi) if mi is not None else math.nan
        reinit = accepted = False
        nis = math.nan
        if self._t is not None and t_s < self._t:
            raise ControlError(f"trend time went backwards ({t_s} < {self._t})")
        if self._init and self._t is not None:
            dt = t_s - self._t
            if dt > c.max_dt_s:
                self._init = False  # too long without data: start over
            elif dt > 0:
                self._transition(dt, rpm)
                self.kf.predict()
        self._t = t_s
        if math.isfinite(z):
            if not self._init:
                self._initialise(z)
                reinit = accepted = True
                self.n_reinit += 1
            else:
                y = z - float((self.kf.H @ self.kf.x)[0, 0])
                s = float((self.kf.H @ self.kf.P @ self.kf.H.T)[0, 0] + self.kf.R[0, 0])
                nis = y * y / s
                if nis <= c.gate_d2:
                    self.kf.update(np.array([[z]]))
                    accepted = True
                    self.rejections = 0
                else:
                    self.rejections += 1
                    if self.rejections >= c.max_rejections:
                        self._initialise(z)
                        reinit = accepted = True
                        self.n_reinit += 1
        return self.estimate(t_s, accepted=accepted, reinit=reinit, nis=nis)

    def estimate(
        self, t_s: float, *, accepted: bool = False, reinit: bool = False, nis: float = math.nan
    ) -> TrendEstimate:
        """The current estimate (NaN fields before the first valid MI)."""
        if not self._init:
            n = math.nan
            return TrendEstimate(t_s, n, n, n, n, n, n, accepted, reinit, n, nis, self.rejections)
        x, P = self.kf.x[:, 0], self.kf.P
        lvl, rate = float(x[0]), float(x[1])
        lsd, rsd = math.sqrt(max(P[0, 0], 0.0)), math.sqrt(max(P[1, 1], 0.0))
        return TrendEstimate(
            t_s, lvl, rate, lsd, rsd, lvl - Z95 * lsd, lvl + Z95 * lsd, accepted, reinit, float(x[2]), nis,
            self.rejections,
        )


class MovingAverage:
    """The paper's baseline filter: causal mean of the last ``window`` *finite* samples.

    The one moving average of the project. ``update(x)`` returns the current mean; a NaN
    (or inf) sample is skipped: it neither enters the window nor resets it, so the
    average holds its value over invalid frames. NaN before the first finite sample.
    """

    def __init__(self, window: int = 150) -> None:
        if int(window) < 1:
            raise ControlError(f"moving-average window must be >= 1, got {window}")
        self.window = int(window)
        self._buf: deque[float] = deque(maxlen=self.window)
        self._sum = 0.0

    def update(self, x: float) -> float:
        """Add one sample; return the current average."""
        x = float(x)
        if math.isfinite(x):
            if len(self._buf) == self.window:
                self._sum -= self._buf[0]
            self._buf.append(x)
            self._sum += x
            if len(self._buf) == self.window:  # curb float drift once per full window
                self._sum = math.fsum(self._buf)
        return self.value

    @property
    def value(self) -> float:
        """The current average (NaN before any finite sample)."""
        return self._sum / len(self._buf) if self._buf else math.nan

    def reset(self) -> None:
        self._buf.clear()
        self._sum = 0.0


def moving_average(x: Sequence[float] | np.ndarray, window: int = 150) -> np.ndarray:
    """:class:`MovingAverage` over a whole sequence (same length; same NaN rule: element i
    is the mean of the last ``window`` finite samples up to i, NaN before the first)."""
    if int(window) < 1:
        raise ControlError(f"moving-average window must be >= 1, got {window}")
    a = np.asarray(x, dtype=float).ravel()
    ok = np.isfinite(a)
    vals = a[ok]
    cs = np.concatenate([[0.0], np.cumsum(vals)])
    k = np.arange(1, vals.size + 1)
    lo = np.maximum(k - int(window), 0)
    means = (cs[k] - cs[lo]) / (k - lo)  # mean of the finite samples ending at each finite one
    n_seen = np.cumsum(ok)  # finite samples up to and including i
    out = np.full(a.size, np.nan)
    has = n_seen > 0
    out[has] = means[n_seen[has] - 1]
    return out

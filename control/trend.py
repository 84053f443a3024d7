"""Kalman trend of the mixing index: the level the supervisor and the endpoint decide on.

The paper smooths MI with a 150-sample moving average (:class:`MovingAverage`, the baseline);
camera MI is a level plus things a mean cannot tell from it, so the trend is a Kalman filter:

- **State** ``[level, rate, ripple_c, ripple_s, e]``: the MI level; its rate (MI/s, a random
  walk: constant velocity); a ripple pair turned by ``omega * dt`` each step, ``omega = 2 pi
  rpm / 60 * ripple_harmonic`` with the drum's *actual* rpm given to ``update`` (the bed rolls
  once a turn; rpm 0, negative or NaN: at rest, the pair neither turns nor enters the
  measurement); and ``e``, the bed's coloured noise, AR(1) with ``phi = exp(-dt / tau_e)`` and
  stationary variance ``R`` (frames a few hundred ms apart show the same bed). Measurement
  ``MI = level + ripple_c + e + v``, ``v`` white with variance ``min_meas_sd**2``.
- **Noise learned on line**, with no feedback from the filter's own covariance: ``R`` from pairs
  ``noise_lag_s`` apart that the gate accepted at both ends (longer than the bed's correlation
  time, so the level cancels; a rejected frame is no sample of the bed), the frame-to-frame
  ``D1`` from consecutive valid samples, gated or not (a gate set too narrow cannot trap its
  own noise), each pair ``(z_i - z_j)^2 / 2`` capped at ``gate_d2`` times the variance in use,
  exponential means with time constant ``noise_tau_s``. The variance is ``max(R, D1)``; their
  ratio is the lag-1 correlation, hence ``tau_e``. ``rate_q`` and ``ripple_q`` scale with ``D1``,
  so the bandwidth stays the reference's. A re-initialisation keeps the noise.
- **Odd frames versus steps.** A sample whose squared Mahalanobis distance exceeds ``gate_d2`` is
  rejected (predict only): glare, a hand, a corrupt frame never move the level. A real step is
  told from a burst by the share of rejections among the valid samples of a window (the last
  ``reinit_window_s``, never fewer than ``reinit_min``): from ``reinit_share`` of it the level
  restarts at the rejected samples' median. So a burst of fewer than ``reinit_share *
  reinit_min`` frames (6 at the defaults, at any frame rate) never re-initialises, an accepted
  sample now and then cannot lock the level out, and the lag after a step is about
  ``reinit_share * reinit_window_s`` (at low frame rates ``ceil(reinit_share * reinit_min)``
  frames). From ``unsettle_share`` of rejections the 95 % band includes their median.
- **Bounds.** After each step the level is projected into [0, 1] and the rate into
  ``+-max_rate_per_s`` (a rate at its bound loses its covariances). NaN MI predicts only; a gap
  longer than ``max_dt_s`` restarts on the next valid sample.
- **Settled** (decisions wait for it): ``settle_s`` of accepted data and ``reinit_min`` accepted
  samples since the (re)start, and a band no wider than the settle width (``settle_band``, or one
  reading's 95 % spread when wider, at most ``settle_band_max``; once settled, up to
  ``SETTLE_HYSTERESIS`` times that).

The arithmetic is :class:`Kalman` (numpy; checked against filterpy's ``KalmanFilter`` by the
tests). Why each rule, what it replaced and the measurements: docs/validation.md, section 13.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from control.errors import ControlError

Z95 = 1.959963984540054
SETTLE_HYSTERESIS = 1.5  # a settled trend unsettles when its band exceeds this times the settle width


@dataclass(frozen=True)
class TrendConfig:
    """Noise model, gating, re-initialisation and settling of :class:`MITrend`.

    ``meas_sd``: initial measurement noise sd (MI; the stationary sd, estimated on line from
    there from pairs ``noise_lag_s`` s apart, never below ``min_meas_sd``, time constant
    ``noise_tau_s`` s; its correlation time from consecutive pairs, see the module doc); ``rate_q``: spectral density of
    the rate random walk (MI^2/s^3); ``ripple_q``: ripple random walk (MI^2/s);
    ``ripple_harmonic``: ripple frequency in multiples of the rotation frequency;
    ``gate_d2``: rejection threshold on the squared Mahalanobis distance (9 = 3 sigma);
    ``reinit_window_s``/``reinit_share``/``reinit_min``: re-initialise when at least that
    share of at least that many valid samples of the last window were rejected;
    ``unsettle_share``: from this share of rejections the band includes them;
    ``max_rate_per_s``: bound of the rate (MI/s); ``init_rate_sd`` (MI/s) and
    ``init_ripple_sd`` (MI): initial uncertainty; ``max_dt_s``: longer gaps re-initialise;
    ``settle_s``: seconds of accepted data since (re)init before a trend settles;
    ``settle_band``/``settle_band_max``: the settle width (MI) is ``settle_band`` or one
    reading's 95 % spread when wider, at most ``settle_band_max`` (it unsettles again on a
    re-init or when the band grows past ``SETTLE_HYSTERESIS`` times that).
    """

    meas_sd: float = 0.05
    min_meas_sd: float = 0.002
    noise_tau_s: float = 20.0
    noise_lag_s: float = 1.0
    rate_q: float = 4.7e-4
    ripple_q: float = 1e-5
    ripple_harmonic: float = 1.0
    gate_d2: float = 9.0
    reinit_window_s: float = 0.6
    reinit_share: float = 0.6
    reinit_min: int = 11
    unsettle_share: float = 0.3
    max_rate_per_s: float = 0.5
    init_rate_sd: float = 0.02
    init_ripple_sd: float = 0.05
    max_dt_s: float = 30.0
    settle_s: float = 1.0
    settle_band: float = 0.1
    settle_band_max: float = 0.35

    def __post_init__(self) -> None:
        if not (self.meas_sd > 0 and self.min_meas_sd > 0 and self.rate_q > 0 and self.ripple_q >= 0
                and self.gate_d2 > 0 and self.noise_tau_s > 0 and self.max_rate_per_s > 0):
            raise ControlError("trend noise levels must be positive (meas_sd, min_meas_sd, rate_q, gate_d2, "
                               "noise_tau_s, max_rate_per_s)")
        if not (self.reinit_window_s > 0 and 0 < self.unsettle_share <= self.reinit_share <= 1):
            raise ControlError("trend re-init needs reinit_window_s > 0 and 0 < unsettle_share <= reinit_share <= 1")
        if not (math.isfinite(self.noise_lag_s) and 0 < self.noise_lag_s <= 10):
            raise ControlError(f"trend noise_lag_s must be in (0, 10] s, got {self.noise_lag_s}")
        if self.reinit_min < 1 or not self.settle_s >= 0 or not self.settle_band > 0:
            raise ControlError("reinit_min must be >= 1, settle_s >= 0 and settle_band > 0")


@dataclass(frozen=True)
class TrendEstimate:
    """One trend output. ``level`` (MI, in [0, 1]), ``rate`` (MI/s), their sds, the 95 % band
    of the level (widened while rejections pile up, see the module doc), whether this
    sample was ``accepted`` (False for NaN or gated) and whether the filter re-initialised
    on it; ``ripple`` is the current ripple term (MI), ``nis`` the squared Mahalanobis
    distance of the innovation (NaN when no update), ``rejections`` the consecutive
    rejections, ``n_since_init`` the accepted samples since the start or the last
    re-initialisation, ``meas_sd`` the current measurement-noise estimate (MI) and
    ``settled`` whether decisions may be made on it."""

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
    n_since_init: int = 0
    meas_sd: float = math.nan
    settled: bool = False

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


class Kalman:
    """A linear Kalman filter with a scalar measurement: state ``x`` (n,), covariance ``P`` (n, n).

    The sums of filterpy's ``KalmanFilter.predict``/``update`` (the covariance update in Joseph
    form: symmetric and positive semi-definite under rounding), written out because the trend
    gates on the innovation *before* it updates, and because ``filterpy.kalman`` imports scipy
    (+43 MB of the live run's peak memory, docs/validation.md section 13). The tests compare it
    with filterpy's class.
    """

    def __init__(self, x: np.ndarray, P: np.ndarray) -> None:
        self.x = np.array(x, dtype=float)
        self.P = np.array(P, dtype=float)

    def predict(self, F: np.ndarray, Q: np.ndarray) -> None:
        """``x = F x``, ``P = F P F' + Q``."""
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q

    def innovation(self, z: float, h: np.ndarray, r: float) -> tuple[float, float]:
        """``y = z - h x`` of a measurement ``z = h x + v`` (``var v = r``) and its variance ``h P h' + r``."""
        return float(z - h @ self.x), float(h @ self.P @ h + r)

    def update(self, z: float, h: np.ndarray, r: float) -> None:
        """Fold in ``z``: gain ``k = P h' / s``, ``x += k y``, ``P = (I - k h) P (I - k h)' + r k k'``."""
        y, s = self.innovation(z, h, r)
        k = self.P @ h / s
        self.x = self.x + k * y
        ikh = np.eye(self.x.size) - np.outer(k, h)
        self.P = ikh @ self.P @ ikh.T + r * np.outer(k, k)


def turning(rpm: float) -> float:
    """The drum speed the ripple turns with (rpm): ``rpm`` when finite and positive, else 0 (at rest)."""
    return float(rpm) if math.isfinite(rpm) and rpm > 0 else 0.0


def transition(dt_s: float, rpm: float, c: TrendConfig, tau_e_s: float, var: float, k: float) -> tuple[np.ndarray,
                                                                                                     np.ndarray]:
    """``F`` and ``Q`` of one step of ``dt_s``: constant velocity with the rate a random walk of density
    ``k * rate_q``, the ripple pair turned by ``omega * dt_s`` (``omega = 2 pi rpm / 60 * ripple_harmonic``,
    ``rpm`` through :func:`turning`) with a random walk of density ``k * ripple_q`` on each, and the AR(1)
    noise ``e`` decaying by ``phi = exp(-dt_s / tau_e_s)`` (0 for white noise, ``tau_e_s`` 0) with
    innovation variance ``var (1 - phi^2)`` (its stationary variance stays ``var``)."""
    a = 2.0 * math.pi * turning(rpm) / 60.0 * c.ripple_harmonic * dt_s
    cs, sn = math.cos(a), math.sin(a)
    phi = math.exp(-dt_s / tau_e_s) if tau_e_s > 0.0 else 0.0
    F = np.array([[1.0, dt_s, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, cs, sn, 0.0],
                  [0.0, 0.0, -sn, cs, 0.0], [0.0, 0.0, 0.0, 0.0, phi]])
    q, qr = c.rate_q * k, c.ripple_q * k
    Q = np.zeros((5, 5))
    Q[0, 0], Q[0, 1], Q[1, 0], Q[1, 1] = q * dt_s**3 / 3.0, q * dt_s**2 / 2.0, q * dt_s**2 / 2.0, q * dt_s
    Q[2, 2] = Q[3, 3] = qr * dt_s
    Q[4, 4] = var * (1.0 - phi * phi)
    return F, Q


def project(kf: Kalman, max_rate_per_s: float) -> None:
    """The level into [0, 1] (MI cannot leave it: the mode of the Gaussian truncated there) and the rate
    into ``+-max_rate_per_s``; a rate at its bound loses its covariances (the projection removes
    information, never adds it)."""
    x, P = kf.x, kf.P
    x[0] = min(1.0, max(0.0, float(x[0])))
    if abs(float(x[1])) > max_rate_per_s:
        x[1] = math.copysign(max_rate_per_s, float(x[1]))
        for j in (0, 2, 3, 4):
            P[1, j] = P[j, 1] = 0.0


class MITrend:
    """Online Kalman trend of MI: ``update(t_s, mi, rpm) -> TrendEstimate`` (see the module doc).

    ``t_s`` (s) must not go backwards; ``mi`` may be NaN or None (a missing frame); ``rpm`` is
    the drum's actual speed, which sets the ripple frequency for the step that ends at ``t_s``.
    """

    engine: type[Kalman] = Kalman
    """The Kalman arithmetic, made with ``(x, P)`` at each (re)initialisation (the tests run filterpy's here)."""

    def __init__(self, config: TrendConfig | None = None) -> None:
        self.config = config or TrendConfig()
        self.kf: Kalman  # made by the first valid sample (nothing reads it before)
        self.n_reinit = 0
        self.reset()

    def reset(self) -> None:
        """Forget everything, the learned noise too; the next valid MI initialises the filter."""
        c = self.config
        self._t: float | None = None
        self._init = False
        self.rejections = 0
        self._window: deque[tuple[float, float, bool]] = deque()  # (t_s, mi, rejected) of valid samples
        self._n_since_init = 0
        self._accepted_s = 0.0  # seconds of accepted data since the start or the last re-init
        self._samples: deque[tuple[float, float, bool]] = deque()  # (t_s, mi, accepted) for the noise pairs
        self._settled = False
        self._r = c.meas_sd**2  # stationary measurement variance (MI^2), from pairs noise_lag_s apart
        self._d1 = c.meas_sd**2  # half the mean squared difference of consecutive valid samples (MI^2)
        self._dt1 = 0.0  # mean time between those samples (s)
        self._n_lag = self._n_one = 0  # pairs learned from (since reset: the noise outlives a re-init)

    @property
    def accepted_s(self) -> float:
        """Seconds of accepted data since the start or the last re-initialisation (s)."""
        return self._accepted_s

    @property
    def frame_sd(self) -> float:
        """sd of the frame-to-frame change over sqrt 2: the consecutive pairs' estimate (MI)."""
        return math.sqrt(self._d1)

    @property
    def noise_tau_e_s(self) -> float:
        """Correlation time of the coloured noise (s; 0: white): ``-dt1 / ln(rho)`` with the lag-1
        correlation ``rho = 1 - D1 / var`` and ``dt1`` the mean frame gap, at most ``noise_lag_s``."""
        if self._n_one == 0 or self._dt1 <= 0.0:
            return 0.0
        rho = 1.0 - self._d1 / self._var()
        if rho <= 0.0:
            return 0.0
        return min(self.config.noise_lag_s, -self._dt1 / math.log(min(rho, 1.0 - 1e-12)))

    def settle_width(self) -> float:
        """The widest band (MI) a trend settles with: ``settle_band``, or the 95 % spread of one
        MI reading (``2 * Z95 * meas_sd``) when wider, never above ``settle_band_max``."""
        c = self.config
        return min(c.settle_band_max, max(c.settle_band, 2.0 * Z95 * math.sqrt(self._var())))

    def _var(self) -> float:
        """The stationary measurement variance in use (MI^2): ``max(R, D1)``, at least
        ``min_meas_sd**2``, at most 0.25 (MI's whole range)."""
        return min(0.25, max(self.config.min_meas_sd**2, self._r, self._d1))

    def _q_scale(self) -> float:
        """Factor on ``rate_q``, ``ripple_q`` and the initial rate/ripple variances, given at ``meas_sd``:
        the frame-to-frame variance (at most the one in use) over ``meas_sd**2``."""
        c = self.config
        return min(self._var(), max(c.min_meas_sd**2, self._d1)) / c.meas_sd**2

    def _initialise(self, z: float) -> None:
        c = self.config
        r, k = self._var(), self._q_scale()
        self.kf = self.engine(np.array([min(1.0, max(0.0, z)), 0.0, 0.0, 0.0, 0.0]),
                              np.diag([r, k * c.init_rate_sd**2, k * c.init_ripple_sd**2, k * c.init_ripple_sd**2, r]))
        self._init = True
        self.rejections = 0
        self._window.clear()
        self._n_since_init = 1
        self._accepted_s = 0.0
        self._samples.clear()
        self._samples.append((float(self._t), z, True))  # type: ignore[arg-type]  # update sets _t first
        self.n_reinit += 1

    @staticmethod
    def _weight(dt: float, n: int, tau_s: float) -> float:
        """Exponential mean with time constant ``tau_s``; a running mean (the prior counting once) at first."""
        return max(min(1.0, dt / tau_s), 1.0 / (n + 1))

    def _learn_noise(self, t_s: float, z: float, accepted: bool) -> None:
        """The two noise statistics (module doc): ``D1`` from this sample and the previous valid one
        (at most ``noise_lag_s`` before), ``R`` from this sample and its partner, the newest valid
        sample at least ``noise_lag_s`` old, when the gate accepted both. Each pair ``(z_i - z_j)^2 / 2``,
        capped at ``gate_d2`` times the variance in use before this sample, enters an exponential mean
        (weight: the gap since the previous sample over ``noise_tau_s``; a running mean at first, the
        configured ``meas_sd**2`` counting once). No pair spans a re-initialisation or a gap longer
        than ``noise_lag_s + 1`` s."""
        c = self.config
        acc = self._samples
        cap = c.gate_d2 * self._var()  # a pair farther apart than the gate counts as at the gate
        if acc and 0.0 < t_s - acc[-1][0] <= c.noise_lag_s:  # consecutive pair
            dt = t_s - acc[-1][0]
            self._n_one += 1
            a = self._weight(dt, self._n_one, c.noise_tau_s)
            self._d1 = (1.0 - a) * self._d1 + a * min(0.5 * (z - acc[-1][1]) ** 2, cap)
            self._dt1 = (1.0 - a) * self._dt1 + a * dt if self._n_one > 1 else dt
        acc.append((t_s, z, accepted))
        while len(acc) > 2 and t_s - acc[1][0] >= c.noise_lag_s:  # acc[0]: the newest at least the lag old
            acc.popleft()
        if len(acc) < 2:
            return
        t0, z0, ok0 = acc[0]
        if t_s - t0 > c.noise_lag_s + 1.0:  # a gap: this sample starts the next pair
            while len(acc) > 1:
                acc.popleft()
            return
        if t_s - t0 >= c.noise_lag_s and accepted and ok0:
            self._n_lag += 1
            a = self._weight(t_s - acc[-2][0], self._n_lag, c.noise_tau_s)
            self._r = (1.0 - a) * self._r + a * min(0.5 * (z - z0) ** 2, cap)

    def _window_at(self, t_s: float) -> tuple[int, list[float]]:
        """Valid samples of the re-init window ending at ``t_s`` (the last ``reinit_window_s``,
        never fewer than the last ``reinit_min``) and the rejected values among them."""
        w, c = self._window, self.config
        while len(w) > c.reinit_min and w[0][0] < t_s - c.reinit_window_s:
            w.popleft()
        return len(w), [z for _, z, rej in w if rej]

    def update(self, t_s: float, mi: float | None, rpm: float = 0.0) -> TrendEstimate:
        """Advance to ``t_s`` and fold in ``mi`` (NaN or None: predict only)."""
        c = self.config
        t_s = float(t_s)
        z = float(mi) if mi is not None else math.nan
        reinit = accepted = False
        nis = math.nan
        if self._t is not None and t_s < self._t:
            raise ControlError(f"trend time went backwards ({t_s} < {self._t})")
        dt = 0.0
        if self._init and self._t is not None:
            dt = t_s - self._t
            if dt > c.max_dt_s:
                self._init = False  # too long without data: start over
            elif dt > 0:
                self.kf.predict(*transition(dt, rpm, c, self.noise_tau_e_s, self._var(), self._q_scale()))
                project(self.kf, c.max_rate_per_s)
        self._t = t_s
        if math.isfinite(z):
            if not self._init:
                self._initialise(z)
                reinit = accepted = True
            else:  # a drum at rest has no rotation ripple: the pair then stays out of the measurement
                h = np.array([1.0, 0.0, 1.0 if turning(rpm) > 0 else 0.0, 0.0, 1.0])
                y, s = self.kf.innovation(z, h, c.min_meas_sd**2)
                nis = y * y / s
                rejected = nis > c.gate_d2
                self._learn_noise(t_s, z, not rejected)
                self._window.append((t_s, z, rejected))
                n, rej = self._window_at(t_s)
                if not rejected:
                    self.kf.update(z, h, c.min_meas_sd**2)
                    project(self.kf, c.max_rate_per_s)
                    accepted = True
                    self.rejections = 0
                    self._n_since_init += 1
                    self._accepted_s += dt
                else:
                    self.rejections += 1
                    if n >= c.reinit_min and len(rej) >= c.reinit_share * n:
                        self._initialise(float(np.median(rej)))  # the learned noise stays
                        reinit = accepted = True
        est = self.estimate(t_s, accepted=accepted, reinit=reinit, nis=nis)
        self._settled = est.settled
        return est

    def estimate(
        self, t_s: float, *, accepted: bool = False, reinit: bool = False, nis: float = math.nan
    ) -> TrendEstimate:
        """The current estimate (NaN fields before the first valid MI)."""
        if not self._init:
            n = math.nan
            return TrendEstimate(t_s, n, n, n, n, n, n, accepted, reinit, n, nis, self.rejections)
        c = self.config
        x, P = self.kf.x, self.kf.P
        lvl, rate = float(x[0]), float(x[1])
        lsd, rsd = math.sqrt(max(P[0, 0], 0.0)), math.sqrt(max(P[1, 1], 0.0))
        lo, hi = lvl - Z95 * lsd, lvl + Z95 * lsd
        n, rej = self._window_at(t_s)
        if n >= c.reinit_min and len(rej) >= c.unsettle_share * n:  # the level may be moving there
            med = float(np.median(rej))
            lo, hi = min(lo, med), max(hi, med)
        lo, hi = max(0.0, lo), min(1.0, hi)
        widest = self.settle_width()
        widest = min(SETTLE_HYSTERESIS, c.settle_band_max / widest) * widest if self._settled else widest
        settled = self._accepted_s >= c.settle_s and self._n_since_init >= c.reinit_min and hi - lo <= widest
        return TrendEstimate(
            t_s, lvl, rate, lsd, rsd, lo, hi, accepted, reinit, float(x[2]), nis,
            self.rejections, self._n_since_init, math.sqrt(self._var()), settled,
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

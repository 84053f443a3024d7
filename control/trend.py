"""Kalman trend of the mixing index (filterpy), replacing the paper's moving average.

State ``x = [level, rate, ripple_c, ripple_s]``: the MI level, its rate of change
(MI/s, a random walk: constant-velocity model) and a rotating ripple pair at the
drum's rotation frequency ``omega = 2*pi*rpm/60 * harmonic`` (rad/s). The bed rolls
once per revolution, so vision MI oscillates at that frequency; the pair is rotated by
``omega*dt`` each step, with ``omega`` from the *actual* rpm passed to ``update`` (it
may change at run time). The measurement is ``MI = level + ripple_c + noise`` (a drum
at rest, rpm 0: ``MI = level + noise``, the pair is not observable).

Why it is built this way (issue 21: real camera MI, not twin MI)
    Real MI is a mixture of two things the filter must tell apart: isolated wrong frames
    (glare, a hand, a corrupt or dropped frame: single frames or short bursts far from
    the level) and real steps (the bed changes within a frame or two when a video starts on
    another state, or the operator changes the drum). The old filter rejected samples by a
    gate on the normalised innovation and re-initialised after ``N`` *consecutive*
    rejections; on a real sequence where a frame near the stuck level comes back now and
    then, the count never reached ``N`` and the level locked out for good (MI 0.43 on a
    bed at 0.97). And its rate state grew while the gate slowly opened: overshoot past 1.

    - **Gate + windowed share of rejections.** Each sample is gated by its squared
      Mahalanobis distance ``d2 = y^2 / S`` (``d2 > gate_d2``: rejected, predict only), so
      a single glitch never moves the level (a soft Huber/Student-t weight still would,
      by a bounded amount, on every glitch). Re-initialisation is decided on the *share* of
      rejected samples among the valid ones of the last ``reinit_window_s``: at least
      ``reinit_share`` of at least ``reinit_min`` samples rejected means the process
      moved; the level restarts at the *median* of the rejected samples of the window
      (robust to the glitches in between) with rate 0. A burst shorter than
      ``reinit_share * reinit_window_s`` cannot re-initialise; an accepted sample now and
      then cannot prevent it (no lock-out). Lag after a real step: about
      ``reinit_share * reinit_window_s``.
    - **Honest band.** The measurement noise is not a constant (camera MI of a mixed bed
      varies by ~0.01, of a segregated bed by less, a synthetic model by 0.04): it is
      estimated on line from consecutive accepted samples (half the mean squared
      difference: the level cancels, and there is no feedback from the filter's own
      covariance; time constant ``noise_tau_s``, floored at ``min_meas_sd``), and after a
      re-init from the robust spread (MAD) of the samples it restarted on. ``rate_q`` and
      ``ripple_q`` are given at the reference noise ``meas_sd`` and scale with the
      estimate, so the filter's bandwidth (which depends on q/R only) stays the same.
      While rejections pile up but have not yet reached the re-init share (at least
      ``unsettle_share`` of the window), the reported band ``lo95``/``hi95`` is widened
      to include the median of the rejected samples: the level may be there, and the
      supervisor must not act on it.
    - **Bounded state.** After every predict and update the level is projected into
      ``[0, 1]`` (MI cannot leave it; the projection is the mode of the Gaussian
      truncated to the interval) and the rate into ``[-max_rate_per_s, max_rate_per_s]``;
      a rate at its bound loses the cross-covariance with the level (the projection
      removes information, never adds it).
    - **Settled.** ``TrendEstimate.settled``: at least ``settle_frames`` accepted samples
      since the start or the last re-initialisation and a band no wider than
      ``settle_band`` (with hysteresis: it unsettles past ``SETTLE_HYSTERESIS`` times
      that). Decisions (segregation detection, AUTO what-if requests) wait for it.

- NaN MI (missing or invalid frame): predict only; a gap longer than ``max_dt_s``
  re-initialises on the next valid sample.
- ``lo95``/``hi95`` is the 95 % band of the *level estimate* (``level +- 1.96 sd``, widened
  as above, clipped to ``[0, 1]``).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from control.errors import ControlError

Z95 = 1.959963984540054
MAD_SD = 1.482602218505602  # sd / MAD of a normal distribution
SETTLE_HYSTERESIS = 1.5  # a settled trend unsettles when its band exceeds this times settle_band


@dataclass(frozen=True)
class TrendConfig:
    """Noise model, gating, re-initialisation and settling of :class:`MITrend`.

    ``meas_sd``: initial measurement noise sd (MI; estimated on line from there, never
    below ``min_meas_sd``, time constant ``noise_tau_s`` s); ``rate_q``: spectral density of
    the rate random walk (MI^2/s^3); ``ripple_q``: ripple random walk (MI^2/s);
    ``ripple_harmonic``: ripple frequency in multiples of the rotation frequency;
    ``gate_d2``: rejection threshold on the squared Mahalanobis distance (9 = 3 sigma);
    ``reinit_window_s``/``reinit_share``/``reinit_min``: re-initialise when at least that
    share of at least that many valid samples of the last window were rejected;
    ``unsettle_share``: from this share of rejections the band includes them;
    ``max_rate_per_s``: bound of the rate (MI/s); ``init_rate_sd`` (MI/s) and
    ``init_ripple_sd`` (MI): initial uncertainty; ``max_dt_s``: longer gaps re-initialise;
    ``settle_frames``/``settle_band``: accepted samples since (re)init and widest band
    (MI) of a trend that settles (it unsettles again on a re-init or when the band grows
    past ``SETTLE_HYSTERESIS * settle_band``).
    """

    meas_sd: float = 0.05
    min_meas_sd: float = 0.002
    noise_tau_s: float = 20.0
    rate_q: float = 4.7e-4
    ripple_q: float = 1e-5
    ripple_harmonic: float = 1.0
    gate_d2: float = 9.0
    reinit_window_s: float = 0.6
    reinit_share: float = 0.6
    reinit_min: int = 8
    unsettle_share: float = 0.3
    max_rate_per_s: float = 0.5
    init_rate_sd: float = 0.02
    init_ripple_sd: float = 0.05
    max_dt_s: float = 30.0
    settle_frames: int = 30
    settle_band: float = 0.1

    def __post_init__(self) -> None:
        if not (self.meas_sd > 0 and self.min_meas_sd > 0 and self.rate_q > 0 and self.ripple_q >= 0
                and self.gate_d2 > 0 and self.noise_tau_s > 0 and self.max_rate_per_s > 0):
            raise ControlError("trend noise levels must be positive (meas_sd, min_meas_sd, rate_q, gate_d2, "
                               "noise_tau_s, max_rate_per_s)")
        if not (self.reinit_window_s > 0 and 0 < self.unsettle_share <= self.reinit_share <= 1):
            raise ControlError("trend re-init needs reinit_window_s > 0 and 0 < unsettle_share <= reinit_share <= 1")
        if self.reinit_min < 1 or self.settle_frames < 0 or not self.settle_band > 0:
            raise ControlError("reinit_min must be >= 1, settle_frames >= 0 and settle_band > 0")


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


_KF_LOCK = threading.Lock()


def kalman_filter_class() -> type:
    """filterpy's ``KalmanFilter`` (the class of ``filterpy/kalman/kalman_filter.py``, unchanged)
    without the ~60 MB of resident memory its packages' imports cost: ``filterpy.kalman``'s
    ``__init__`` imports every filter, ``filterpy.common`` imports ``scipy.linalg`` and
    ``filterpy.stats`` ``scipy.stats``, all for ``logpdf``, which the class calls only for its
    ``log_likelihood`` (never read here; the first call imports the real ``filterpy.stats``).
    The module is loaded once under a private name; ``sys.modules`` holds no stand-in afterwards."""
    import importlib.util
    import sys
    import types

    with _KF_LOCK:
        name = "control._filterpy_kalman_filter"
        mod = sys.modules.get(name)
        if mod is not None:
            return mod.KalmanFilter
        spec = importlib.util.find_spec("filterpy")  # found, not imported (its __init__ imports it all)
        if spec is None or spec.origin is None:
            raise ModuleNotFoundError("filterpy is not installed", name="filterpy")
        root = Path(spec.origin).parent

        def load(modname: str, path: Path) -> types.ModuleType:
            spec = importlib.util.spec_from_file_location(modname, path)
            assert spec is not None and spec.loader is not None
            m = importlib.util.module_from_spec(spec)
            sys.modules[modname] = m
            spec.loader.exec_module(m)
            return m

        helpers = load("control._filterpy_helpers", root / "common" / "helpers.py")  # numpy only

        def logpdf(*args: object, **kwargs: object) -> object:
            from filterpy.stats import logpdf as real

            return real(*args, **kwargs)

        stats = types.ModuleType("filterpy.stats")
        stats.logpdf = logpdf  # type: ignore[attr-defined]
        stand_ins = {"filterpy.stats": stats, "filterpy.common": helpers}
        saved = {k: sys.modules.get(k) for k in stand_ins}
        try:
            sys.modules.update(stand_ins)
            mod = load(name, root / "kalman" / "kalman_filter.py")
        finally:
            for k, v in saved.items():
                if v is None:
                    sys.modules.pop(k, None)
                else:
                    sys.modules[k] = v
        return mod.KalmanFilter


class MITrend:
    """Online Kalman trend of MI: ``update(t_s, mi, rpm) -> TrendEstimate``.

    ``t_s`` (s) must not go backwards; ``mi`` may be NaN; ``rpm`` is the drum's actual
    speed, which sets the ripple frequency for the step that ends at ``t_s``.
    """

    def __init__(self, config: TrendConfig | None = None) -> None:
        self.config = config or TrendConfig()
        self.kf = kalman_filter_class()(dim_x=4, dim_z=1)
        self.kf.H = np.array([[1.0, 0.0, 1.0, 0.0]])
        self._t: float | None = None
        self._init = False
        self.rejections = 0
        self.n_reinit = 0
        self._r = self.config.meas_sd**2  # measurement variance estimate (MI^2)
        self.kf.R = np.array([[self._r]])
        self._window: deque[tuple[float, float, bool]] = deque()  # (t_s, mi, rejected) of valid samples
        self._n_since_init = 0
        self._last_accepted: tuple[float, float] | None = None  # (t_s, mi) for the noise estimate
        self._settled = False

    def reset(self) -> None:
        """Forget everything; the next valid MI initialises the filter."""
        self._t = None
        self._init = False
        self.rejections = 0
        self._r = self.config.meas_sd**2
        self._window.clear()
        self._n_since_init = 0
        self._last_accepted = None
        self._settled = False

    def _set_r(self, r: float) -> None:
        self._r = min(0.25, max(self.config.min_meas_sd**2, r))
        self.kf.R = np.array([[self._r]])

    def _initialise(self, z: float, r: float | None = None) -> None:
        c = self.config
        if r is not None:
            self._set_r(r)
        self.kf.x = np.array([[min(1.0, max(0.0, z))], [0.0], [0.0], [0.0]])
        k = self._r / c.meas_sd**2
        self.kf.P = np.diag([self._r, k * c.init_rate_sd**2, k * c.init_ripple_sd**2, k * c.init_ripple_sd**2])
        self._init = True
        self.rejections = 0
        self._window.clear()
        self._n_since_init = 1
        self._last_accepted = (self._t, z) if self._t is not None else None
        self.n_reinit += 1

    def _project(self) -> None:
        """Level into [0, 1], rate into +-max_rate_per_s (see the module doc)."""
        x, m = self.kf.x, self.config.max_rate_per_s
        x[0, 0] = min(1.0, max(0.0, float(x[0, 0])))
        if abs(float(x[1, 0])) > m:
            x[1, 0] = math.copysign(m, float(x[1, 0]))
            p = self.kf.P
            p[0, 1] = p[1, 0] = 0.0
            p[1, 2] = p[2, 1] = p[1, 3] = p[3, 1] = 0.0

    def _transition(self, dt: float, rpm: float) -> None:
        c = self.config
        w = 2.0 * math.pi * max(0.0, float(rpm) if math.isfinite(rpm) else 0.0) / 60.0 * c.ripple_harmonic
        cs, sn = math.cos(w * dt), math.sin(w * dt)
        self.kf.F = np.array(
            [[1.0, dt, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, cs, sn], [0.0, 0.0, -sn, cs]]
        )
        k = self._r / c.meas_sd**2  # the noise densities are given at meas_sd: same bandwidth at any noise
        q, qr = c.rate_q * k, c.ripple_q * k
        self.kf.Q = np.array(
            [
                [q * dt**3 / 3, q * dt**2 / 2, 0.0, 0.0],
                [q * dt**2 / 2, q * dt, 0.0, 0.0],
                [0.0, 0.0, qr * dt, 0.0],
                [0.0, 0.0, 0.0, qr * dt],
            ]
        )

    def _learn_noise(self, t_s: float, z: float) -> None:
        """Measurement variance from consecutive accepted samples: ``E[(z_i - z_{i-1})^2] / 2``
        (the level and the slow ripple cancel; no feedback from the filter's own P), an
        exponential mean with time constant ``noise_tau_s``, a running mean at first."""
        last = self._last_accepted
        self._last_accepted = (t_s, z)
        if last is None or not 0.0 < t_s - last[0] <= 1.0:
            return
        c = self.config
        a = max(min(1.0, (t_s - last[0]) / c.noise_tau_s), 1.0 / (self._n_since_init + 1))
        self._set_r((1.0 - a) * self._r + a * 0.5 * (z - last[1]) ** 2)

    def _window_at(self, t_s: float) -> tuple[int, list[float]]:
        """Valid samples in the re-init window ending at ``t_s`` and the rejected values."""
        w = self._window
        while w and w[0][0] < t_s - self.config.reinit_window_s:
            w.popleft()
        return len(w), [z for _, z, rej in w if rej]

    def update(self, t_s: float, mi: float, rpm: float = 0.0) -> TrendEstimate:
        """Advance to ``t_s`` and fold in ``mi`` (NaN: predict only)."""
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
                self._transition(dt, rpm)
                self.kf.predict()
                self._project()
        self._t = t_s
        if math.isfinite(z):
            if not self._init:
                self._initialise(z)
                reinit = accepted = True
            else:
                # a drum at rest has no rotation ripple: the pair then stays out of the measurement
                self.kf.H = np.array([[1.0, 0.0, 1.0 if math.isfinite(rpm) and rpm > 0 else 0.0, 0.0]])
                y = z - float((self.kf.H @ self.kf.x)[0, 0])
                hph = float((self.kf.H @ self.kf.P @ self.kf.H.T)[0, 0])
                nis = y * y / (hph + self._r)
                rejected = nis > c.gate_d2
                self._window.append((t_s, z, rejected))
                n, rej = self._window_at(t_s)
                if not rejected:
                    self._learn_noise(t_s, z)
                    self.kf.update(np.array([[z]]))
                    self._project()
                    accepted = True
                    self.rejections = 0
                    self._n_since_init += 1
                else:
                    self.rejections += 1
                    if n >= c.reinit_min and len(rej) >= c.reinit_share * n:
                        med = float(np.median(rej))
                        mad = float(np.median(np.abs(np.asarray(rej) - med)))
                        self._initialise(med, (MAD_SD * mad) ** 2)
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
        x, P = self.kf.x[:, 0], self.kf.P
        lvl, rate = float(x[0]), float(x[1])
        lsd, rsd = math.sqrt(max(P[0, 0], 0.0)), math.sqrt(max(P[1, 1], 0.0))
        lo, hi = lvl - Z95 * lsd, lvl + Z95 * lsd
        n, rej = self._window_at(t_s)
        if n >= c.reinit_min and len(rej) >= c.unsettle_share * n:  # the level may be moving there
            med = float(np.median(rej))
            lo, hi = min(lo, med), max(hi, med)
        lo, hi = max(0.0, lo), min(1.0, hi)
        widest = SETTLE_HYSTERESIS * c.settle_band if self._settled else c.settle_band
        settled = self._n_since_init >= c.settle_frames and hi - lo <= widest
        return TrendEstimate(
            t_s, lvl, rate, lsd, rsd, lo, hi, accepted, reinit, float(x[2]), nis,
            self.rejections, self._n_since_init, math.sqrt(self._r), settled,
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

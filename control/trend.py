"""Kalman trend of the mixing index (filterpy), replacing the paper's moving average.

State ``x = [level, rate, ripple_c, ripple_s, e]``: the MI level, its rate of change
(MI/s, a random walk: constant-velocity model), a rotating ripple pair at the
drum's rotation frequency ``omega = 2*pi*rpm/60 * harmonic`` (rad/s) and the coloured
measurement noise ``e`` (MI). The bed rolls once per revolution, so vision MI oscillates
at that frequency; the pair is rotated by ``omega*dt`` each step, with ``omega`` from the
*actual* rpm passed to ``update`` (it may change at run time). The measurement is
``MI = level + ripple_c + e + v`` (a drum at rest, rpm 0: ``MI = level + e + v``, the pair
is not observable), ``v`` a white floor of variance ``min_meas_sd**2``.

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
      rejected samples among the valid ones of the last ``reinit_window_s``, never fewer
      than the last ``reinit_min`` (a 10 fps camera has 6 in 0.6 s: with the window in
      seconds only, the trend could never re-initialise there): at least
      ``reinit_share`` of at least ``reinit_min`` samples rejected means the process
      moved; the level restarts at the *median* of the rejected samples of the window
      (robust to the glitches in between) with rate 0. A burst shorter than
      ``reinit_share * reinit_window_s`` cannot re-initialise; an accepted sample now and
      then cannot prevent it (no lock-out). Lag after a real step: about
      ``reinit_share * reinit_window_s``.
    - **Honest band, coloured noise (issue: the trend runaway on the demo).** A bed's MI is
      not white noise about its level: the bed's configuration changes continuously, so
      frames a few hundred ms apart are strongly correlated (the demo at 10 fps: lag-1
      autocorrelation 0.80-0.89, structure function flat after ~1 s, sd 0.05-0.07; real
      camera stills drawn i.i.d.: none). The noise is therefore an AR(1) state,
      ``e_k+1 = phi e_k + w``, ``phi = exp(-dt/tau_e)``, ``var(w) = R (1 - phi^2)``, so its
      stationary variance is ``R`` whatever the frame rate. Two statistics are learned on
      line (half the mean squared difference of a pair: the level cancels, and there is no
      feedback from the filter's own covariance; time constant ``noise_tau_s``, a running
      mean at first; each pair capped at ``gate_d2`` times the variance): ``R`` from pairs
      ``noise_lag_s`` (1 s) apart that end on an accepted sample, longer than the
      correlation time, and the frame-to-frame ``D1`` from consecutive valid samples, gated
      or not. The variance in use is ``max(R, D1)``, floored at ``min_meas_sd``: learned from
      accepted samples only, it could never grow past what its own gate let through (on the
      real frames' drift pools, spread 0.36-0.45, it learnt 0.009 from the two middle values,
      gated the others and lost the level for 1.8 s); the cap keeps a glitch's weight to that
      of a sample at the gate, and a real step (rejected samples close to each other) barely
      moves ``D1``. Their ratio is the lag-1 correlation ``rho = 1 - D1/max(R, D1)``,
      hence ``tau_e = -dt1 / ln(rho)`` (``dt1`` the mean frame gap; ``rho <= 0``: white,
      ``phi = 0``; ``tau_e`` at most ``noise_lag_s``). On i.i.d. MI ``D1 ~ R`` and
      ``phi ~ 0``: the filter is the white-noise one (the variance that of consecutive pairs,
      as before). Learned only from
      consecutive pairs, ``R`` saw a third of the demo's spread (sd 0.02 against 0.06): the
      3-sigma gate rejected the real wander, the rate state followed the rest and the trend
      ran to 1.0 and 0.35 on camera MI 0.85-0.92. ``rate_q`` and ``ripple_q`` are given at
      the reference noise ``meas_sd`` and scale with the frame-to-frame variance ``D1``
      (white noise: ``R``), so the filter's bandwidth stays that of the reference. A
      re-initialisation *keeps* the learned noise (it belongs to the camera and the bed, not
      to the level; the old MAD of 0.6 s of correlated samples underestimated it and each
      re-init bred the next) and clears only the pairs (a pair across a step is no noise).
      While rejections pile up but have not yet reached the re-init share (at least
      ``unsettle_share`` of the window), the reported band ``lo95``/``hi95`` is widened
      to include the median of the rejected samples: the level may be there, and the
      supervisor must not act on it.
    - **Bounded state.** After every predict and update the level is projected into
      ``[0, 1]`` (MI cannot leave it; the projection is the mode of the Gaussian
      truncated to the interval) and the rate into ``[-max_rate_per_s, max_rate_per_s]``;
      a rate at its bound loses the cross-covariance with the level (the projection
      removes information, never adds it).
    - **Settled.** ``TrendEstimate.settled``: at least ``settle_s`` seconds of accepted data
      (the sum of the frame gaps of accepted samples) and ``reinit_min`` accepted samples
      since the start or the last re-initialisation (the same minimum at 10 fps and 30 fps;
      30 frames were 3 s at 10 fps; the band then takes what the data need), and a band no wider than the settle
      width: ``settle_band``, or the 95 % spread of one MI reading ``2 * 1.96 * meas_sd``
      when that is wider (the level is then known better than any frame tells; an honest
      band on correlated MI cannot be as narrow as on white MI), never above
      ``settle_band_max`` (with hysteresis: it unsettles past ``SETTLE_HYSTERESIS`` times
      that, still at most ``settle_band_max``). Decisions (segregation detection, AUTO
      what-if requests) wait for it.

    Measured (six demo runs run_time_s0-s5 at 10 fps replayed, against a 3 s centred mean of
    raw MI; settled share after the first 10 s): old RMSE 0.070-0.206, max 0.27-0.78, settled
    89-100 % (on a band far too narrow); new RMSE 0.029-0.043, max 0.18-0.33, settled 94-97 %.
    The reverted first fix (1 s pairs, white noise, MAD at re-init, 30 frames to settle) was
    settled 10 % of a loaded demo run. ``drumtwin bench trend``: real frames RMSE 0.038,
    lock-out 1.10 -> 1.00 s, coverage 98.3 -> 97.9 %; synthetic lock-out 1.17 -> 1.53 s.

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
SETTLE_HYSTERESIS = 1.5  # a settled trend unsettles when its band exceeds this times settle_band


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
    reinit_min: int = 8
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
        self.kf = kalman_filter_class()(dim_x=5, dim_z=1)
        self.kf.H = np.array([[1.0, 0.0, 1.0, 0.0, 1.0]])
        self.kf.R = np.array([[self.config.min_meas_sd**2]])  # the white floor under the AR(1) noise
        self._t: float | None = None
        self._init = False
        self.rejections = 0
        self.n_reinit = 0
        self._window: deque[tuple[float, float, bool]] = deque()  # (t_s, mi, rejected) of valid samples
        self._n_since_init = 0
        self._accepted_s = 0.0  # seconds of accepted data since the start or the last re-init
        self._samples: deque[tuple[float, float]] = deque()  # (t_s, mi) valid since (re)init, for the noise
        self._settled = False
        self._forget_noise()

    def _forget_noise(self) -> None:
        c = self.config
        self._r = c.meas_sd**2  # stationary measurement variance (MI^2), from pairs noise_lag_s apart
        self._d1 = c.meas_sd**2  # half mean squared difference of consecutive accepted samples (MI^2)
        self._dt1 = 0.0  # mean time between those samples (s)
        self._n_lag = self._n_one = 0  # pairs learned from (since reset: the noise outlives a re-init)

    def reset(self) -> None:
        """Forget everything, the learned noise too; the next valid MI initialises the filter."""
        self._t = None
        self._init = False
        self.rejections = 0
        self._window.clear()
        self._n_since_init = 0
        self._accepted_s = 0.0
        self._samples.clear()
        self._settled = False
        self._forget_noise()

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
        """Correlation time of the coloured measurement noise (s; 0: white), see the module doc."""
        c = self.config
        if self._n_one == 0 or self._dt1 <= 0.0:
            return 0.0
        rho = 1.0 - self._d1 / self._var()
        if rho <= 0.0:
            return 0.0
        return min(c.noise_lag_s, -self._dt1 / math.log(min(rho, 1.0 - 1e-12)))

    def settle_width(self) -> float:
        """The widest band (MI) a trend settles with: ``settle_band``, or the 95 % spread of one
        MI reading (``2 * Z95 * meas_sd``) when wider, never above ``settle_band_max``."""
        c = self.config
        return min(c.settle_band_max, max(c.settle_band, 2.0 * Z95 * math.sqrt(self._var())))

    def _var(self) -> float:
        """The stationary measurement variance in use (MI^2): the pairs' ``R``, never below the
        frame-to-frame ``D1`` (white noise) nor ``min_meas_sd**2``, at most 0.25."""
        return min(0.25, max(self.config.min_meas_sd**2, self._r, self._d1))

    def _q_scale(self) -> float:
        """Factor on ``rate_q``, ``ripple_q`` and the initial rate/ripple variances: they are given at
        ``meas_sd`` and scale with the frame-to-frame variance (``_d1``, at most the stationary one;
        white noise: the stationary one), so the filter's bandwidth stays that of the reference."""
        c = self.config
        return min(self._var(), max(c.min_meas_sd**2, self._d1)) / c.meas_sd**2

    def _initialise(self, z: float) -> None:
        c = self.config
        r = self._var()
        self.kf.x = np.array([[min(1.0, max(0.0, z))], [0.0], [0.0], [0.0], [0.0]])
        k = self._q_scale()
        self.kf.P = np.diag([r, k * c.init_rate_sd**2, k * c.init_ripple_sd**2, k * c.init_ripple_sd**2, r])
        self._init = True
        self.rejections = 0
        self._window.clear()
        self._n_since_init = 1
        self._accepted_s = 0.0
        self._samples.clear()
        if self._t is not None:
            self._samples.append((self._t, z))
        self.n_reinit += 1

    def _project(self) -> None:
        """Level into [0, 1], rate into +-max_rate_per_s (see the module doc)."""
        x, m = self.kf.x, self.config.max_rate_per_s
        x[0, 0] = min(1.0, max(0.0, float(x[0, 0])))
        if abs(float(x[1, 0])) > m:
            x[1, 0] = math.copysign(m, float(x[1, 0]))
            p = self.kf.P
            p[0, 1] = p[1, 0] = 0.0
            p[1, 2] = p[2, 1] = p[1, 3] = p[3, 1] = p[1, 4] = p[4, 1] = 0.0

    def _transition(self, dt: float, rpm: float) -> None:
        c = self.config
        w = 2.0 * math.pi * max(0.0, float(rpm) if math.isfinite(rpm) else 0.0) / 60.0 * c.ripple_harmonic
        cs, sn = math.cos(w * dt), math.sin(w * dt)
        tau = self.noise_tau_e_s
        phi = math.exp(-dt / tau) if tau > 0.0 else 0.0
        self.kf.F = np.array(
            [[1.0, dt, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, cs, sn, 0.0],
             [0.0, 0.0, -sn, cs, 0.0], [0.0, 0.0, 0.0, 0.0, phi]]
        )
        r, k = self._var(), self._q_scale()
        q, qr = c.rate_q * k, c.ripple_q * k
        self.kf.Q = np.array(
            [
                [q * dt**3 / 3, q * dt**2 / 2, 0.0, 0.0, 0.0],
                [q * dt**2 / 2, q * dt, 0.0, 0.0, 0.0],
                [0.0, 0.0, qr * dt, 0.0, 0.0],
                [0.0, 0.0, 0.0, qr * dt, 0.0],
                [0.0, 0.0, 0.0, 0.0, r * (1.0 - phi * phi)],
            ]
        )

    @staticmethod
    def _weight(dt: float, n: int, tau_s: float) -> float:
        """Exponential mean with time constant ``tau_s``; a running mean (the prior counting once) at first."""
        return max(min(1.0, dt / tau_s), 1.0 / (n + 1))

    def _learn_noise(self, t_s: float, z: float, accepted: bool) -> None:
        """The two noise statistics (see the module doc): the frame-to-frame ``D1`` from
        consecutive valid samples, gated or not (at most ``noise_lag_s`` apart), and the
        stationary ``R`` from pairs ``noise_lag_s`` apart that end on an ``accepted`` sample (the
        partner: the newest valid sample at least that old); each ``(z_i - z_j)^2 / 2``, capped
        at ``gate_d2`` times the variance in use before this sample (the level cancels; no
        feedback from the filter's own P), an exponential mean with time constant ``noise_tau_s`` (the weight
        of a pair: the gap since the previous sample over it), a running mean at first (the
        configured ``meas_sd**2`` counting once). Pairs never span a re-initialisation (the
        level stepped there) nor a gap longer than ``noise_lag_s + 1`` s."""
        c = self.config
        acc = self._samples
        cap = c.gate_d2 * self._var()  # a pair farther apart than the gate counts as at the gate
        if acc and 0.0 < t_s - acc[-1][0] <= c.noise_lag_s:  # consecutive pair
            dt = t_s - acc[-1][0]
            self._n_one += 1
            a = self._weight(dt, self._n_one, c.noise_tau_s)
            self._d1 = (1.0 - a) * self._d1 + a * min(0.5 * (z - acc[-1][1]) ** 2, cap)
            self._dt1 = (1.0 - a) * self._dt1 + a * dt if self._n_one > 1 else dt
        acc.append((t_s, z))
        while len(acc) > 2 and t_s - acc[1][0] >= c.noise_lag_s:  # acc[0]: the newest at least the lag old
            acc.popleft()
        if len(acc) < 2:
            return
        t0, z0 = acc[0]
        lag = t_s - t0
        if lag > c.noise_lag_s + 1.0:  # a gap: this sample starts the next pair
            while len(acc) > 1:
                acc.popleft()
            return
        if lag >= c.noise_lag_s and accepted:
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
                self.kf.H = np.array([[1.0, 0.0, 1.0 if math.isfinite(rpm) and rpm > 0 else 0.0, 0.0, 1.0]])
                y = z - float((self.kf.H @ self.kf.x)[0, 0])
                hph = float((self.kf.H @ self.kf.P @ self.kf.H.T)[0, 0])
                nis = y * y / (hph + float(self.kf.R[0, 0]))
                rejected = nis > c.gate_d2
                self._learn_noise(t_s, z, not rejected)  # every valid sample (see the doc)
                self._window.append((t_s, z, rejected))
                n, rej = self._window_at(t_s)
                if not rejected:
                    self.kf.update(np.array([[z]]))
                    self._project()
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
        x, P = self.kf.x[:, 0], self.kf.P
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

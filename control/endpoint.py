"""Batch endpoint: is the mix done? (the mixing time; issue 24, docs/endpoint.md).

Two criteria, both on numbers the loop already has, both pure:

- **Dwell in band on the trend.** The Kalman trend level (``control.trend``) has stayed
  within ``band`` of its plateau for ``dwell_s``: every settled level of the last
  ``dwell_s`` seconds lies within ``+-band`` of the window's midpoint (max - min <=
  ``2 band``), its net change over the window (mean of the last tenth minus mean of the
  first) is at most ``band`` (a curve still rising slowly is not a plateau yet), and that
  plateau is at least ``target_mi`` (a flat *segregated* bed is a
  plateau too: the target tells the two apart). The **mixing time** is the start of that
  window, ``t_detect - dwell_s``: the first time after which the trend stayed in the band.
- **Moving-block standard deviation** (MBSD, as NIR blend monitoring does): the standard
  deviation of the raw MI of the last ``block_s`` seconds, estimated robustly (1.4826 x the
  median absolute deviation: one odd frame, or any minority of them, cannot decide it), is
  at most ``block_sd_max`` (None: not used). Both must hold for ``mixed``.

Once mixed, the batch is **unmixed** again when the trend falls below the plateau it was
mixed at by more than ``exit_band`` (or below ``target_mi - band``) for ``exit_dwell_s``
(hysteresis: a trend still creeping upwards is not unmixed; the plateau follows it up).

An unsettled or invalid trend sample (NaN, ``settled`` False) restarts the dwell: the
trend must hold continuously. Times are the samples' own (run or video seconds).
:class:`EndpointDetector` is the streaming form (live); :func:`detect_endpoint` replays a
whole recording through it (offline), :func:`endpoint_of_series` with the Kalman trend in
front (raw MI of a video): one definition for both.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

from control.errors import ControlError
from control.trend import MITrend, TrendConfig


@dataclass(frozen=True)
class EndpointConfig:
    """Endpoint criteria (MI units; times in s).

    ``target_mi``: the plateau must be at least this (also the twin's target MI for
    AUTO's "time"/"energy" objectives); ``band``: half-width of the plateau band;
    ``dwell_s``: how long the trend must stay in it; ``block_s``/``block_sd_max``: moving
    block of raw MI and the largest standard deviation of a mixed batch (None: MBSD not
    used); ``exit_band``/``exit_dwell_s``: how far below the plateau, for how long, before
    the batch is unmixed again.
    """

    target_mi: float = 0.85
    band: float = 0.02
    dwell_s: float = 10.0
    block_s: float = 5.0
    block_sd_max: float | None = 0.05
    exit_band: float = 0.05
    exit_dwell_s: float = 5.0

    def __post_init__(self) -> None:
        vals = (self.target_mi, self.band, self.dwell_s, self.block_s, self.exit_band, self.exit_dwell_s)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in vals):
            raise ControlError("endpoint settings must be finite numbers (target_mi, band, dwell_s, block_s, ...)")
        if not 0.0 <= self.target_mi <= 1.0:
            raise ControlError(f"endpoint target_mi must be in [0, 1], got {self.target_mi}")
        for key, lo, hi, lo_open in _RANGES:
            v = getattr(self, key)
            if not ((lo < v if lo_open else lo <= v) and v <= hi):
                raise ControlError(f"endpoint {key} must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], got {v}")
        sd = self.block_sd_max
        if sd is not None and not (isinstance(sd, (int, float)) and not isinstance(sd, bool) and math.isfinite(sd)
                                   and 0 < sd <= 1):
            raise ControlError(f"endpoint block_sd_max must be in (0, 1] (or off), got {sd}")


_RANGES = (("band", 0.0, 0.5, True), ("dwell_s", 0.0, 3600.0, True), ("block_s", 0.0, 3600.0, True),
           ("exit_band", 0.0, 1.0, True), ("exit_dwell_s", 0.0, 3600.0, False))
"""(key, low, high, low open) of the endpoint's ranged settings (MI, s)."""

ENDPOINT_KEYS = ("target_mi", "band", "dwell_s", "block_s", "block_sd_max", "exit_band", "exit_dwell_s")
"""The settings of an ``[endpoint]`` table / the ``--endpoint-*`` options (:class:`EndpointConfig`'s fields)."""


def endpoint_settings(table: Mapping[str, object], base: EndpointConfig | None = None) -> EndpointConfig:
    """``base`` (default: :class:`EndpointConfig`'s defaults, the one definition of them) with the keys
    of ``table`` replaced. ``block_sd_max`` 0 or false turns the moving-block criterion off. An unknown
    key, a value that is no number or one out of range: a one-line ControlError naming the key."""
    unknown = sorted(set(table) - set(ENDPOINT_KEYS))
    if unknown:
        raise ControlError(f"endpoint: unknown key(s) {unknown} (allowed: {', '.join(ENDPOINT_KEYS)})")
    vals: dict[str, float | None] = {}
    for key, v in table.items():
        if key == "block_sd_max" and (v is False or v is None or v == 0):
            vals[key] = None
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ControlError(f"endpoint {key} must be a number, got {v!r}")
        else:
            vals[key] = float(v)
    return replace(base or EndpointConfig(), **vals)  # type: ignore[arg-type]  # __post_init__ checks


@dataclass(frozen=True)
class EndpointStatus:
    """The detector after one sample. ``mixed``: the batch is at its endpoint now;
    ``mixing_time_s``: when it got there (start of the dwell window; None while not
    mixed); ``plateau_mi``: the plateau level (None while not mixed); ``block_sd``: the
    moving-block sd of raw MI now (NaN: too few samples); ``changed``: "mixed" or
    "unmixed" on the sample where the state changed, else ""; ``reason``: why, in words."""

    t_s: float
    mixed: bool
    mixing_time_s: float | None = None
    plateau_mi: float | None = None
    block_sd: float = math.nan
    changed: str = ""
    reason: str = ""


MAD_TO_SD = 1.482602218505602
"""1 / the normal distribution's 75th percentile: the median absolute deviation of normal data times
this is their standard deviation."""


def block_sd(values: Iterable[float]) -> float:
    """Standard deviation of the finite ``values``, estimated robustly: ``MAD_TO_SD`` x their median
    absolute deviation from their median (docs/endpoint.md: frames unlike the rest, up to half of
    them, cannot move it; on normal data it is the sd). NaN for fewer than 2."""
    v = [float(x) for x in values if math.isfinite(x)]
    if len(v) < 2:
        return math.nan
    med = statistics.median(v)
    return MAD_TO_SD * statistics.median(abs(x - med) for x in v)


class EndpointDetector:
    """Streaming endpoint detector (see module doc): ``update(t_s, raw_mi, level, settled)``
    once per frame, in time order."""

    def __init__(self, config: EndpointConfig | None = None) -> None:
        self.config = config or EndpointConfig()
        self._levels: deque[tuple[float, float]] = deque()  # (t, trend level) of the current stretch
        self._raw: deque[tuple[float, float]] = deque()  # (t, raw MI) of the last block
        self.mixed = False
        self.mixing_time_s: float | None = None
        self.plateau_mi: float | None = None
        self._below_since: float | None = None
        self._last_t = -math.inf

    def reset(self) -> None:
        """Forget everything (a new batch)."""
        self._levels.clear()
        self._raw.clear()
        self.mixed, self.mixing_time_s, self.plateau_mi, self._below_since = False, None, None, None
        self._last_t = -math.inf

    def _block_sd(self, t: float) -> float:
        while self._raw and self._raw[0][0] < t - self.config.block_s:
            self._raw.popleft()
        return block_sd(v for _, v in self._raw)

    def update(self, t_s: float, raw_mi: float, level: float, settled: bool = True) -> EndpointStatus:
        """One frame: raw MI (NaN: invalid frame), the trend level and whether it is settled."""
        c = self.config
        t = float(t_s)
        if not math.isfinite(t) or t < self._last_t:
            return self._status(t, math.nan)  # no news (a frame from the past): nothing changes
        self._last_t = t
        if math.isfinite(raw_mi):
            self._raw.append((t, float(raw_mi)))
        sd = self._block_sd(t)
        ok = settled and math.isfinite(level)
        if not ok:
            self._levels.clear()
        else:
            self._levels.append((t, float(level)))
            while len(self._levels) > 1 and self._levels[1][0] <= t - c.dwell_s:
                self._levels.popleft()  # keep one sample at or before t - dwell: the window covers it
        if self.mixed:
            return self._watch_exit(t, level if ok else math.nan, sd)
        if not ok or self._levels[0][0] > t - c.dwell_s + 1e-9:
            return self._status(t, sd)
        lv = [v for _, v in self._levels]
        lo, hi = min(lv), max(lv)
        mid = 0.5 * (lo + hi)
        k = max(1, len(lv) // 10)  # net change over the window: mean of its last tenth - of its first
        drift = sum(lv[-k:]) / k - sum(lv[:k]) / k
        if hi - lo > 2.0 * c.band or abs(drift) > c.band or mid < c.target_mi:
            return self._status(t, sd)
        if c.block_sd_max is not None and not (math.isfinite(sd) and sd <= c.block_sd_max):
            return self._status(t, sd)
        self.mixed, self.mixing_time_s, self.plateau_mi, self._below_since = True, t - c.dwell_s, mid, None
        why = (f"trend within +-{c.band:g} of {mid:.3f} (>= target {c.target_mi:g}) for {c.dwell_s:g} s"
               + ("" if c.block_sd_max is None else f"; block sd {sd:.4f} <= {c.block_sd_max:g} over {c.block_s:g} s"))
        return self._status(t, sd, "mixed", why)

    def _watch_exit(self, t: float, level: float, sd: float) -> EndpointStatus:
        c = self.config
        assert self.plateau_mi is not None
        if not math.isfinite(level):
            return self._status(t, sd)  # no trend: no evidence either way
        floor = max(self.plateau_mi - c.exit_band, c.target_mi - c.band)
        if level >= floor:
            self._below_since = None
            if level > self.plateau_mi:  # still creeping up: the plateau follows it
                self.plateau_mi = level
            return self._status(t, sd)
        self._below_since = t if self._below_since is None else self._below_since
        if t - self._below_since < c.exit_dwell_s:
            return self._status(t, sd)
        why = f"trend {level:.3f} < {floor:.3f} (plateau {self.plateau_mi:.3f} - {c.exit_band:g}) for " \
              f"{t - self._below_since:.1f} s"
        self.mixed, self.mixing_time_s, self.plateau_mi, self._below_since = False, None, None, None
        self._levels.clear()
        return self._status(t, sd, "unmixed", why)

    def _status(self, t: float, sd: float, changed: str = "", reason: str = "") -> EndpointStatus:
        return EndpointStatus(t, self.mixed, self.mixing_time_s, self.plateau_mi, sd, changed, reason)


@dataclass(frozen=True)
class EndpointResult:
    """An offline replay: ``mixing_time_s`` when the recording ends mixed (None: it never
    mixed, or left the band again), the plateau then, and every change (t, "mixed" |
    "unmixed", mixing time or None, reason)."""

    mixing_time_s: float | None
    plateau_mi: float | None
    changes: tuple[tuple[float, str, float | None, str], ...]


def detect_endpoint(
    samples: Iterable[tuple[float, float, float, bool]], config: EndpointConfig | None = None
) -> EndpointResult:
    """Replay ``(t_s, raw_mi, trend_level, settled)`` samples through one detector."""
    det = EndpointDetector(config)
    changes = []
    for t, raw, level, settled in samples:
        st = det.update(t, raw, level, settled)
        if st.changed:
            changes.append((st.t_s, st.changed, st.mixing_time_s, st.reason))
    return EndpointResult(det.mixing_time_s if det.mixed else None, det.plateau_mi if det.mixed else None,
                          tuple(changes))


def endpoint_of_series(
    t_s: Sequence[float],
    mi: Sequence[float],
    config: EndpointConfig | None = None,
    trend: TrendConfig | None = None,
    rpm: float = 0.0,
) -> EndpointResult:
    """Offline: raw MI at times ``t_s`` (NaN: invalid frames) through a fresh Kalman trend
    (``trend``; ``rpm``: the drum speed for its ripple, 0 when unknown) and the detector."""
    tr = MITrend(trend or TrendConfig())

    def samples() -> Iterable[tuple[float, float, float, bool]]:
        for t, m in zip(t_s, mi, strict=True):
            e = tr.update(float(t), float(m), rpm)
            yield float(t), float(m), e.level, bool(e.valid and e.settled)

    return detect_endpoint(samples(), config)

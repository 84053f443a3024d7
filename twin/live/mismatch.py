"""Twin versus reality: the residual of the twin's bed against the camera's (pure).

Three comparisons, each with its tolerance (:class:`MismatchTolerance`):

- rotation direction: the free surface rises toward the direction the drum turns, so
  the sign of the bed slope angle is the direction. Twin and camera disagree when both
  slopes are steeper than ``direction_min_deg`` and their signs differ;
- slope: ``|twin_slope_deg - camera_slope_deg| > slope_deg``;
- MI: ``|twin_mi - camera_mi| > mi`` (the twin's MI is measured by the same meter on its
  rendered frames, so the two are comparable).

:class:`MismatchMonitor` turns residuals into a state with hysteresis: *mismatch* after
``raise_after_s`` of continuous disagreement, *agree* again after ``clear_after_s`` of
continuous agreement. Missing numbers (NaN: no valid camera reading, no twin yet) are no
evidence either way: they neither raise nor clear; nor is a twin that lags behind the camera
(its newest state older than ``fresh_s``; one that falls ``twin.live.twin.MAX_LAG_S`` behind skips
ahead, logged as a ``twin_lag`` record, and the supervisor's ``twin_timeout_s`` covers one that
stops) or has simulated less than ``warmup_s`` since it was seeded (:func:`twin_is_evidence`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class MismatchTolerance:
    """How far twin and camera may differ (degrees, MI units) and for how long (s, run time)."""

    slope_deg: float = 15.0
    mi: float = 0.3
    direction_min_deg: float = 5.0
    raise_after_s: float = 3.0
    clear_after_s: float = 5.0
    fresh_s: float = 2.0  # a twin whose newest state is older than this (run time, s) is no evidence
    warmup_s: float = 5.0  # nor is a twin before it has run this long (s): its bed is still spinning up


@dataclass(frozen=True)
class Residual:
    """Twin minus camera: slope (deg) and MI; ``reasons`` lists what is beyond tolerance
    (empty: they agree); ``known`` is False when a number was missing (no verdict)."""

    slope_deg: float
    mi: float
    direction_agrees: bool
    reasons: tuple[str, ...]
    known: bool

    @property
    def bad(self) -> bool:
        return self.known and bool(self.reasons)


def residual(
    camera_slope_deg: float, twin_slope_deg: float, camera_mi: float, twin_mi: float,
    tol: MismatchTolerance | None = None,
) -> Residual:
    """The residual of one comparison (see module doc)."""
    t = tol or MismatchTolerance()
    cs, ts, cm, tm = (float(x) for x in (camera_slope_deg, twin_slope_deg, camera_mi, twin_mi))
    slopes = math.isfinite(cs) and math.isfinite(ts)
    mis = math.isfinite(cm) and math.isfinite(tm)
    d_slope = ts - cs if slopes else math.nan
    d_mi = tm - cm if mis else math.nan
    reasons: list[str] = []
    direction = True
    if slopes and abs(cs) > t.direction_min_deg and abs(ts) > t.direction_min_deg and (cs > 0) != (ts > 0):
        direction = False
        reasons.append(f"rotation direction: twin slope {ts:+.1f} deg, camera {cs:+.1f} deg")
    elif slopes and abs(d_slope) > t.slope_deg:
        reasons.append(f"slope: twin {ts:+.1f} deg, camera {cs:+.1f} deg (tolerance {t.slope_deg:g})")
    if mis and abs(d_mi) > t.mi:
        reasons.append(f"MI: twin {tm:.2f}, camera {cm:.2f} (tolerance {t.mi:g})")
    return Residual(d_slope, d_mi, direction, tuple(reasons), slopes)


class MismatchMonitor:
    """Hysteresis over residuals of medians (pure: the caller passes run time, s).

    ``observe`` takes one sample of the four numbers, compares the medians of the last
    ``window_s`` (frame-to-frame slopes and MI are noisy: a single frame is no verdict),
    and returns ``"raise"`` or ``"clear"`` on a change of state, else None. ``mismatch``
    is the state, ``reason`` the last disagreement, ``last`` the last residual."""

    def __init__(self, tol: MismatchTolerance | None = None, window_s: float = 3.0) -> None:
        self.tol = tol or MismatchTolerance()
        self.window_s = float(window_s)
        self.mismatch = False
        self.reason = ""
        self.last: Residual | None = None
        self._samples: deque[tuple[float, float, float, float, float]] = deque()
        self._bad_since: float | None = None
        self._good_since: float | None = None

    def observe(self, t_s: float, camera_slope_deg: float, twin_slope_deg: float,
                camera_mi: float, twin_mi: float) -> str | None:
        self._samples.append((float(t_s), camera_slope_deg, twin_slope_deg, camera_mi, twin_mi))
        while self._samples and t_s - self._samples[0][0] > self.window_s:
            self._samples.popleft()
        cols = list(zip(*self._samples, strict=True))[1:]
        meds = [_median(c) for c in cols]
        return self.update(t_s, residual(meds[0], meds[1], meds[2], meds[3], self.tol))

    def update(self, t_s: float, r: Residual) -> str | None:
        """One residual at run time ``t_s`` (``observe`` calls it with the medians)."""
        self.last = r
        if not r.known:
            return None
        if r.bad:
            self._good_since = None
            self.reason = "; ".join(r.reasons)
            if self._bad_since is None:
                self._bad_since = t_s
            if not self.mismatch and t_s - self._bad_since >= self.tol.raise_after_s:
                self.mismatch = True
                return "raise"
        else:
            self._bad_since = None
            if self._good_since is None:
                self._good_since = t_s
            if self.mismatch and t_s - self._good_since >= self.tol.clear_after_s:
                self.mismatch = False
                return "clear"
        return None


def twin_is_evidence(now_s: float, twin_updated_s: float | None, twin_age_s: float,
                     tol: MismatchTolerance | None = None) -> bool:
    """True when the twin's numbers may be compared with the camera's at run time ``now_s``:
    it is fresh (stepped to within ``fresh_s`` of now) and past its spin-up (``twin_age_s``,
    ``TwinInfo.age_s``: simulated seconds since its latest seeding, at least ``warmup_s``). A twin
    that was slow to seed and skipped ahead to catch up, or was seeded again, is spinning up
    still, however long ago run time first saw it."""
    t = tol or MismatchTolerance()
    if twin_updated_s is None:
        return False
    return now_s - twin_updated_s <= t.fresh_s and twin_age_s >= t.warmup_s


def _median(values: tuple[float, ...]) -> float:
    """Median of the finite values (NaN when none is)."""
    finite = sorted(float(v) for v in values if math.isfinite(float(v)))
    if not finite:
        return math.nan
    n = len(finite)
    return finite[n // 2] if n % 2 else 0.5 * (finite[n // 2 - 1] + finite[n // 2])


__all__ = ["MismatchMonitor", "MismatchTolerance", "Residual", "residual", "twin_is_evidence"]

"""Segregation detection on the Kalman trend and the radial factor (pure; the supervisor's).

*Bad* when ``level < seg_level`` or ``rate < seg_rate_per_s`` (falling faster) or
``radial_factor < radial_min`` (``radial_factor`` = the std-weighting factor of eq. 4, i.e.
MI(eq. 4) / MI(eq. 3)); *good* when ``level > clear_level`` and ``rate > seg_rate_per_s / 2``
and the radial factor is above ``radial_clear`` (hysteresis). The state turns *segregated*
after ``detect_dwell_s`` of continuous bad, and *mixed* again after ``clear_dwell_s`` of
continuous good (thresholds: ``control.supervisor_config.SupervisorConfig``).

Only a settled trend counts (``TrendEstimate.settled``: enough accepted frames since the
start or the last re-initialisation and a narrow enough band, see ``control.trend``): while
it is unsettled the dwell does not run, and it restarts once settled.
"""

from __future__ import annotations

import math

from control.supervisor_config import SupervisorConfig
from control.trend import TrendEstimate


class SegregationDetector:
    """Bad/good conditions with hysteresis and dwell (see module doc)."""

    def __init__(self, config: SupervisorConfig) -> None:
        self.config = config
        self.segregated = False
        self._since: float | None = None  # start of the current opposite-condition stretch
        self.why = ""

    def reset(self) -> None:
        self.segregated = False
        self._since = None
        self.why = ""

    def bad_reasons(self, trend: TrendEstimate, radial: float | None) -> list[str]:
        c, r = self.config, []
        if trend.level < c.seg_level:
            r.append(f"MI {trend.level:.3f} < {c.seg_level}")
        if trend.rate < c.seg_rate_per_s:
            r.append(f"MI falling {trend.rate:+.4f}/s < {c.seg_rate_per_s}/s")
        if radial is not None and math.isfinite(radial) and radial < c.radial_min:
            r.append(f"radial factor {radial:.3f} < {c.radial_min}")
        return r

    def is_good(self, trend: TrendEstimate, radial: float | None) -> bool:
        c = self.config
        ok = trend.level > c.clear_level and trend.rate > c.seg_rate_per_s / 2
        if radial is not None and math.isfinite(radial):
            ok = ok and radial > c.radial_clear
        return ok

    def update(self, now_s: float, trend: TrendEstimate | None, radial: float | None) -> bool:
        """Advance; returns True when the state changed this step."""
        if trend is None or not trend.valid or not trend.settled:  # decide nothing on an unsettled trend
            self._since = None
            return False
        if not self.segregated:
            bad = self.bad_reasons(trend, radial)
            if not bad:
                self._since = None
                return False
            self._since = now_s if self._since is None else self._since
            if now_s - self._since >= self.config.detect_dwell_s:
                self.segregated, self._since, self.why = True, None, "; ".join(bad)
                return True
            return False
        if not self.is_good(trend, radial):
            self._since = None
            return False
        self._since = now_s if self._since is None else self._since
        if now_s - self._since >= self.config.clear_dwell_s:
            self.segregated, self._since, self.why = False, None, ""
            return True
        return False

    @property
    def suspect(self) -> bool:
        """Bad conditions seen but the dwell not over yet."""
        return not self.segregated and self._since is not None


__all__ = ["SegregationDetector"]

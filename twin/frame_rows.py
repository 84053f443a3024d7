"""Readings -> frame rows: the second half of the one measurement path (the first is
``vision.stream``: frames -> ``Reading``).

:class:`FrameRows` folds each camera ``Reading`` into the Kalman trend, the paper's moving
average and the batch endpoint, and builds the one frame record, ``twin.records.FrameReading``
(a row of ``frames.csv``). ``drumtwin mi`` and the live run's process worker both call it, so
the two write the same row for the same frame; what only a run knows (the twin, the mill's
speeds, the supervisor's mode, the link's flags) the process worker adds to that row, and
``drumtwin mi`` leaves empty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from control.endpoint import EndpointDetector, EndpointStatus
from control.trend import MITrend, MovingAverage, TrendEstimate
from twin.records import FrameReading
from vision.meter import Reading

__all__ = ["FrameRows", "RowStep", "is_valid_mi"]


def is_valid_mi(r: Reading) -> bool:
    """The reading counts as vision: flagged valid and its MI a number in [0, 1] (the meter's
    indices are; anything else is a broken reading, never fed to the trend or the timeout)."""
    return bool(r.valid) and math.isfinite(r.mi) and 0.0 <= r.mi <= 1.0


@dataclass(frozen=True)
class RowStep:
    """One reading folded in: the frame's row, whether its MI counted as vision, and the trend
    and endpoint after it."""

    row: FrameReading
    valid: bool
    estimate: TrendEstimate
    endpoint: EndpointStatus


class FrameRows:
    """``step(t_s, frame, reading, rpm)`` once per frame, in time order -> :class:`RowStep`
    (None for a frame whose time is not a number or goes back before the newest one: the
    trend's time only runs forward). ``rpm``: the drum's actual speed for the trend's ripple
    (0 when unknown)."""

    def __init__(self, trend: MITrend, ma_window: int = 150, endpoint: EndpointDetector | None = None) -> None:
        self.trend = trend
        self.ma = MovingAverage(ma_window)
        self.endpoint = endpoint or EndpointDetector()
        self.last_t_s: float | None = None  # the newest frame's time

    def in_order(self, t_s: float) -> bool:
        """``t_s`` is a number and not before the newest frame's."""
        return math.isfinite(t_s) and (self.last_t_s is None or t_s >= self.last_t_s)

    def step(self, t_s: float, frame: int, reading: Reading, rpm: float = 0.0) -> RowStep | None:
        if not self.in_order(t_s):
            return None
        self.last_t_s = t_s
        r = reading
        valid = is_valid_mi(r)
        mi = r.mi if valid else math.nan
        est = self.trend.update(t_s, mi, rpm)
        ma = self.ma.update(mi)
        end = self.endpoint.update(t_s, mi, est.level, est.valid and est.settled)
        row = FrameReading(
            t_s=t_s, frame=frame, mi=r.mi, mi_sigmoid=r.mi_sigmoid, mi_linear=r.mi_linear,
            d_px=r.d_px, dsigma_px=r.dsigma_px, concentration=r.concentration, slope_deg=r.slope_deg,
            valid=valid, trend_mi=est.level, trend_lo95=est.lo95, trend_hi95=est.hi95, trend_rate=est.rate,
            ma_mi=ma, twin_mi=None, twin_slope_deg=None, rpm_setpoint=None, rpm_actual=None, mode="",
            flags=tuple(r.flags), mixed=end.mixed, mixing_time_s=end.mixing_time_s,
        )
        return RowStep(row, valid, est, end)

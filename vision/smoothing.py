"""The paper's moving-average filter (window 150): the baseline the Kalman trend must beat."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

__all__ = ["MovingAverage", "moving_average"]


class MovingAverage:
    """Causal moving average over the last ``window`` finite samples.

    ``update(x)`` returns the mean of the buffered samples; NaN samples are skipped
    (they neither enter the buffer nor reset it). Before any finite sample it returns NaN.
    """

    def __init__(self, window: int = 150) -> None:
        if int(window) < 1:
            raise ValueError(f"moving-average window must be >= 1, got {window}")
        self.window = int(window)
        self._buf: deque[float] = deque(maxlen=self.window)
        self._sum = 0.0

    def update(self, x: float) -> float:
        """Add one sample and return the current average."""
        x = float(x)
        if math.isfinite(x):
            if len(self._buf) == self.window:
                self._sum -= self._buf[0]
            self._buf.append(x)
            self._sum += x
            if len(self._buf) == self.window and self.window > 1:  # curb float drift
                self._sum = math.fsum(self._buf)
        return self._sum / len(self._buf) if self._buf else float("nan")

    @property
    def value(self) -> float:
        """Current average (NaN before any finite sample)."""
        return self._sum / len(self._buf) if self._buf else float("nan")

    def reset(self) -> None:
        self._buf.clear()
        self._sum = 0.0


def moving_average(xs, window: int = 150) -> np.ndarray:
    """Causal moving average of a sequence, same length; NaN samples are skipped.

    Element i is the mean of the last ``window`` finite samples up to and including i.
    """
    ma = MovingAverage(window)
    return np.array([ma.update(x) for x in np.asarray(xs, dtype=np.float64).ravel()], dtype=np.float64)

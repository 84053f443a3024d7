"""A run clock that runs ``speed`` times faster than the wall clock (``--speed``)."""

from __future__ import annotations

import threading
import time


class RunClock:
    """Run time ``now_s() = speed * (monotonic() - start)``, in seconds.

    ``sleep_until(t_s)`` waits (in wall time) until the run clock reaches ``t_s`` or
    ``stop`` is set; returns False when stopped.
    """

    def __init__(self, speed: float = 1.0, stop: threading.Event | None = None) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.speed = float(speed)
        self.stop = stop or threading.Event()
        self._t0 = time.monotonic()

    def now_s(self) -> float:
        return (time.monotonic() - self._t0) * self.speed

    def wall_s(self, run_s: float) -> float:
        """Wall seconds that ``run_s`` run seconds take."""
        return run_s / self.speed

    def sleep_until(self, t_s: float) -> bool:
        delay = (t_s - self.now_s()) / self.speed
        if delay > 0:
            return not self.stop.wait(delay)
        return not self.stop.is_set()

    def sleep(self, run_s: float) -> bool:
        """Sleep ``run_s`` of run time; False when stopped."""
        return not self.stop.wait(max(0.0, run_s / self.speed))

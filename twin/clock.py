"""A run clock that runs ``speed`` times faster than the wall clock (``--speed``), and a cadence."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class RunClock:
    """Run time ``now_s() = speed * (monotonic() - start)``, in seconds.

    ``sleep_until(t_s)`` waits (in wall time) until the run clock reaches ``t_s`` or
    ``stop`` is set; returns False when stopped. ``monotonic`` is the wall clock (s) it
    reads, injectable as in ``Rate`` and ``RunView``, so a test moves time instead of
    sleeping.
    """

    def __init__(self, speed: float = 1.0, stop: threading.Event | None = None,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.speed = float(speed)
        self.stop = stop or threading.Event()
        self._monotonic = monotonic
        self._t0 = monotonic()

    def now_s(self) -> float:
        return (self._monotonic() - self._t0) * self.speed

    def restart(self) -> None:
        """Make run time 0 now (the run starts when its workers do, not when it was built)."""
        self._t0 = self._monotonic()

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


class Cadence:
    """Ticks every ``period_s`` on average from irregular calls, keeping its schedule.

    ``due(now_s)`` is True when a tick is due and then books the next one a period after
    the last booked tick, not after ``now_s``: frames at 20 Hz give a 12 Hz cadence 12
    times a second, not every second frame (10 Hz). After falling more than a period
    behind it drops the missed ticks instead of catching up. Pure: the caller passes the
    time (any clock, s).
    """

    def __init__(self, period_s: float, start_s: float = 0.0) -> None:
        if not period_s > 0:
            raise ValueError(f"period must be > 0 s, got {period_s}")
        self.period_s = float(period_s)
        self._next = float(start_s)

    def due(self, now_s: float) -> bool:
        if now_s < self._next:
            return False
        self._next = max(self._next + self.period_s, now_s)
        return True

    def restart(self, now_s: float) -> None:
        """Make the next tick due at ``now_s`` (after a jump of the clock)."""
        self._next = float(now_s)

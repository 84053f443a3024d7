"""One way for a test to wait on something another thread or process does (``wait_until``),
and a wall clock a test moves by hand instead of sleeping (``ManualClock``)."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_until(pred: Callable[[], bool], timeout_s: float, what: str, poll_s: float = 0.05) -> None:
    """Poll ``pred`` until it is true; AssertionError naming ``what`` after ``timeout_s``.

    ``pred`` may act as well as look (``lambda: worker.cycle().connected``): it is called
    once more at the deadline, so a slow machine that reaches the state late still passes."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(poll_s)  # the one poll of the suite
    if pred():
        return
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


class ManualClock:
    """A monotonic clock (s) that only moves when the test calls ``advance``: inject it where
    code takes ``monotonic=`` (``RunClock``, ``Rate``, ``RunView``)."""

    def __init__(self, t_s: float = 1000.0) -> None:
        self.t_s = float(t_s)

    def __call__(self) -> float:
        return self.t_s

    def advance(self, dt_s: float) -> None:
        if dt_s < 0:
            raise ValueError(f"a monotonic clock does not go back ({dt_s} s)")
        self.t_s += dt_s

"""The cadence that paces the camera overlay and the twin's renders, and the run clock
(``--speed``), on a clock the test moves."""

from __future__ import annotations

import threading

import pytest

from tests.waiting import ManualClock
from twin.clock import Cadence, RunClock


def test_cadence_keeps_its_rate_from_faster_irregular_calls() -> None:
    c = Cadence(1.0 / 12.0)
    ticks = sum(c.due(i / 20.0) for i in range(200))  # 10 s of 20 fps frames
    assert ticks in (119, 120, 121)  # 12 Hz, not every second frame (10 Hz)


def test_cadence_drops_missed_ticks_after_a_stall_and_restarts() -> None:
    c = Cadence(0.1)
    assert c.due(0.0) and not c.due(0.05) and c.due(0.1)
    assert c.due(5.0)  # after a 4.9 s stall: one tick, not 49 to catch up
    assert sum(c.due(5.0 + i * 0.01) for i in range(1, 10)) <= 1
    c.restart(2.0)
    assert c.due(2.0)
    with pytest.raises(ValueError):
        Cadence(0.0)


class RecordingStop(threading.Event):
    """A stop event whose ``wait`` records the wall seconds asked and returns at once."""

    def __init__(self) -> None:
        super().__init__()
        self.waits: list[float | None] = []

    def wait(self, timeout: float | None = None) -> bool:
        self.waits.append(timeout)
        return self.is_set()


def test_run_clock_restarts_at_zero_and_scales_wall_time() -> None:
    wall, stop = ManualClock(), RecordingStop()
    c = RunClock(speed=4.0, stop=stop, monotonic=wall)
    assert c.now_s() == 0.0
    wall.advance(0.5)
    assert c.now_s() == 2.0  # 0.5 wall s at 4x
    c.restart()
    assert c.now_s() == 0.0 and c.wall_s(4.0) == 1.0
    wall.advance(0.25)
    assert c.sleep_until(3.0) and stop.waits == [0.5]  # run 1.0 -> 3.0 is 0.5 wall s at 4x
    assert c.sleep_until(0.5) and stop.waits == [0.5]  # already past: no wait
    assert c.sleep(2.0) and stop.waits == [0.5, 0.5]
    stop.set()
    assert not c.sleep_until(10.0) and not c.sleep(1.0)  # stopped: False, whatever is left
    with pytest.raises(ValueError):
        RunClock(speed=0.0)

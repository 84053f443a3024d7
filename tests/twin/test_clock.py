"""The cadence that paces the camera overlay and the twin's renders."""

from __future__ import annotations

import pytest

from twin.clock import Cadence


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


def test_run_clock_restarts_at_zero_and_scales_wall_time() -> None:
    import time

    from twin.clock import RunClock

    c = RunClock(speed=4.0)
    time.sleep(0.5)
    assert c.now_s() >= 2.0
    c.restart()
    assert 0.0 <= c.now_s() < 1.0 and c.wall_s(4.0) == 1.0
    with pytest.raises(ValueError):
        RunClock(speed=0.0)

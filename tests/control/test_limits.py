"""The one set of limits (control.limits): the supervisor enforces exactly them, and the
what-if caps are the ``whatif`` command's."""

from __future__ import annotations

import math

import pytest

from control.errors import ControlError
from control.limits import WHATIF_MAX_RUNS, WHATIF_MAX_S, Limits
from control.supervisor import Supervisor
from tests.control.supervisor_values import worked_config


def test_rpm_range_takes_the_critical_speed_fraction() -> None:
    lim = Limits(min_rpm=5.0, max_rpm=45.0, critical_rpm=77.2, max_critical_frac=0.5)
    assert lim.rpm_range == (5.0, pytest.approx(38.6))
    assert "critical speed 77.2" in lim.describe()
    assert Limits(min_rpm=5.0, max_rpm=45.0).rpm_range == (5.0, 45.0)


def test_check_rpm_says_what_was_clamped() -> None:
    lim = Limits(min_rpm=5.0, max_rpm=45.0)
    ok = lim.check_rpm(20)
    assert ok.rpm == 20.0 and not ok.clamped and ok.message == ""
    hi = lim.check_rpm(100)
    assert hi.rpm == 45.0 and hi.clamped and "100 rpm is outside the limits 5-45 rpm" in hi.message
    assert lim.check_rpm(1).rpm == 5.0
    for bad in (math.nan, math.inf, "fast", None):
        with pytest.raises(ControlError):
            lim.check_rpm(bad)  # type: ignore[arg-type]


def test_refuse_rpm_names_the_limit_and_allows_stop() -> None:
    lim = Limits(min_rpm=5.0, max_rpm=45.0, critical_rpm=77.2, max_critical_frac=0.6)
    assert lim.refuse_rpm(30) == 30.0 and lim.refuse_rpm(0) == 0.0
    with pytest.raises(ControlError, match=r"100 is outside the limits 5-45 rpm"):
        lim.refuse_rpm(100)
    with pytest.raises(ControlError, match="outside the limits"):
        lim.refuse_rpm(2)


def test_whatif_caps_are_the_whatif_commands() -> None:
    from twin.cli import sim_cmds

    assert sim_cmds.MAX_SIM_S == WHATIF_MAX_S  # `whatif` checks its runs with Limits.check_whatif itself
    lim = Limits(critical_rpm=77.2)
    assert lim.check_whatif([5, 40], 60) == ([5.0, 40.0], 60.0)
    for rpms, dur, needle in [
        ([5.0], 1e9, "duration"), ([5.0], math.nan, "duration"), ([5.0], 0.0, "duration"),
        ([10000.0], 60, "10000"), ([5.0] * (WHATIF_MAX_RUNS + 1), 60, "at most 2000"), ([], 60, "at least"),
        ([-5.0], 60, "-5"), ([math.inf], 60, "inf"), (["x"], 60, "numbers"),
    ]:
        with pytest.raises(ControlError, match=needle):
            lim.check_whatif(rpms, dur)  # type: ignore[arg-type]


def test_supervisor_enforces_the_same_limits() -> None:
    cfg = worked_config(min_rpm=5.0, max_rpm=45.0, critical_rpm=60.0, max_critical_frac=0.5)
    assert cfg.limits == Limits(5.0, 45.0, 60.0, 0.5, cfg.limits.max_rate_rpm_per_s)
    assert cfg.limits.rpm_range == (5.0, 30.0)
    sup = Supervisor(cfg)
    assert sup.set_manual_rpm(100.0) == cfg.limits.check_rpm(100.0).rpm == 30.0
    with pytest.raises(ControlError):
        worked_config(min_rpm=50.0, max_rpm=45.0)
    with pytest.raises(ControlError):
        Limits(min_rpm=5.0, max_rpm=45.0, critical_rpm=5.0, max_critical_frac=0.5)

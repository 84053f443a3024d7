"""The limits (control/limits.py) rule by rule: each setting's edges, the messages that name
the limit, the what-if caps at their edges, and the one cap of a simulated drum (pure)."""

from __future__ import annotations

import math

import pytest

from control.errors import ControlError
from control.limits import SIM_CRITICAL_FRAC, WHATIF_MAX_RUNS, WHATIF_MAX_S, Limits, simulated_rpm


def _refused(**kw: float) -> str:
    with pytest.raises(ControlError) as e:
        Limits(**kw)
    return str(e.value)


def test_a_simulated_drum_follows_the_measured_rpm_up_to_95_percent_of_its_critical_speed() -> None:
    assert SIM_CRITICAL_FRAC == 0.95
    assert simulated_rpm(10, 40.0) == 10.0 and isinstance(simulated_rpm(10, 40), float)
    assert simulated_rpm(38.0, 40.0) == 38.0
    assert simulated_rpm(50.0, 40.0) == 38.0  # the board's rpm beyond it: the bed would centrifuge
    assert simulated_rpm(-3.0, 40.0) == 0.0  # a drum turning backwards is a stopped twin
    assert simulated_rpm(0.0, 40.0) == 0.0


@pytest.mark.parametrize("name", ["min_rpm", "max_rpm", "max_critical_frac", "max_rate_rpm_per_s"])
def test_a_setting_that_is_not_finite_is_named(name: str) -> None:
    assert _refused(**{name: math.inf}) == f"{name} must be finite, got inf"


def test_the_rpm_range_edges() -> None:
    assert Limits(min_rpm=0.0).rpm_range == (0.0, 45.0)  # a mill that may stand still
    assert Limits(min_rpm=0.5).rpm_range == (0.5, 45.0)
    assert _refused(min_rpm=45.0) == "rpm limits must satisfy 0 <= min < max (got 45.0, 45.0)"
    assert _refused(min_rpm=-1.0) == "rpm limits must satisfy 0 <= min < max (got -1.0, 45.0)"


def test_the_critical_fraction_is_in_0_1() -> None:
    assert Limits(critical_rpm=40.0, max_critical_frac=1.0).rpm_range == (5.0, 40.0)
    for bad in (0.0, 1.5):
        assert _refused(max_critical_frac=bad) == "max_critical_frac must be in (0, 1]"


def test_the_critical_speed_must_be_a_positive_number_and_leave_room_above_min_rpm() -> None:
    for bad in (math.inf, -5.0, 0.0):
        assert _refused(critical_rpm=bad) == f"critical_rpm must be a positive number, got {bad}"
    assert Limits(min_rpm=0.0, critical_rpm=0.5).rpm_range == (0.0, 0.3)  # a small positive one is a number
    # 0.5 x 10 rpm = 5 rpm = min_rpm: no rpm left to command
    assert _refused(critical_rpm=10.0, max_critical_frac=0.5) == "the critical-speed limit leaves no rpm above min_rpm"


def test_describe_names_the_critical_speed_only_when_it_limits() -> None:
    assert Limits(critical_rpm=40.0).describe() == "5-24 rpm (0.6 x critical speed 40.0 rpm)"
    assert Limits(critical_rpm=100.0).describe() == "5-45 rpm"  # 0.6 x 100 = 60 > max_rpm
    assert Limits(critical_rpm=75.0).describe() == "5-45 rpm"  # 0.6 x 75 = 45 = max_rpm: max_rpm limits


def test_the_rpm_messages_name_the_value_and_the_limits() -> None:
    lim = Limits()
    with pytest.raises(ControlError) as e:
        lim.check_rpm(math.nan)
    assert str(e.value) == "rpm must be a finite number (got nan)"
    with pytest.raises(ControlError) as e:
        lim.refuse_rpm(50.0)
    assert str(e.value) == "rpm 50 is outside the limits 5-45 rpm"


def test_whatif_takes_exactly_its_caps_and_refuses_one_past() -> None:
    lim = Limits()
    assert len(lim.check_whatif([10.0] * WHATIF_MAX_RUNS, 60)[0]) == WHATIF_MAX_RUNS  # one seed by default
    assert len(lim.check_whatif([10.0] * (WHATIF_MAX_RUNS // 2), 60, seeds=2)[0]) == WHATIF_MAX_RUNS // 2
    with pytest.raises(ControlError) as e:
        lim.check_whatif([10.0] * (WHATIF_MAX_RUNS // 2 + 1), 60, seeds=2)
    assert str(e.value) == f"what-if: at most {WHATIF_MAX_RUNS} runs per study (got {WHATIF_MAX_RUNS + 2})"
    with pytest.raises(ControlError) as e:
        lim.check_whatif([], 60)
    assert str(e.value) == "what-if: give at least one rpm"
    assert lim.check_whatif([10.0], 0.5) == ([10.0], 0.5)
    assert lim.check_whatif([10.0], WHATIF_MAX_S) == ([10.0], WHATIF_MAX_S)


def test_whatif_rpms_go_up_to_the_critical_speed_or_without_one_to_max_rpm() -> None:
    crit = Limits(critical_rpm=100.0)
    assert crit.check_whatif([60.0, 100.0, 0.5], 60)[0] == [60.0, 100.0, 0.5]  # above max_rpm: a study may
    with pytest.raises(ControlError, match=r"^what-if rpm 100\.5 outside \(0, 100\] rpm$"):
        crit.check_whatif([100.5], 60)
    plain = Limits()
    assert plain.check_whatif([45.0], 60)[0] == [45.0]
    for bad in (45.5, 0.0):
        with pytest.raises(ControlError, match=rf"^what-if rpm {bad:g} outside \(0, 45\] rpm$"):
            plain.check_whatif([bad], 60)

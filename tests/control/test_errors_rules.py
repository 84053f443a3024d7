"""control/errors.py: the one range check (``check_number``) at its edges and in its messages,
and the refusals' messages and fields (pure)."""

from __future__ import annotations

import pytest

from control.errors import ControlError, MillRefused, SafetyRefused, check_number


def _message(value: object, **bounds: float) -> str:
    with pytest.raises(ControlError) as e:
        check_number("--x", value, **bounds)  # type: ignore[arg-type]
    return str(e.value)


def test_a_number_given_as_text_or_float_passes_inside_its_bounds_edges_included() -> None:
    assert check_number("--x", "2.5", above=0.0) == 2.5
    assert check_number("--x", 1.0, at_least=1.0) == 1.0 and check_number("--x", 5, at_most=5.0) == 5.0
    assert check_number("--x", -3.0) == -3.0  # no bounds: any finite number


def test_each_bound_is_named_in_the_message() -> None:
    assert _message(0.0, above=0.0) == "--x must be a finite number > 0 (got 0.0)"
    assert _message(0.5, at_least=1.0) == "--x must be a finite number >= 1 (got 0.5)"
    assert _message(7, at_most=5.0) == "--x must be a finite number <= 5 (got 7)"
    assert _message(9, above=0.0, at_most=5.0) == "--x must be a finite number > 0 and <= 5 (got 9)"
    assert _message(9, at_least=1.0, at_most=5.0) == "--x must be a finite number >= 1 and <= 5 (got 9)"
    assert _message("fast", at_least=1.0) == "--x must be a finite number >= 1 (got fast)"
    assert _message(None) == "--x must be a finite number (got None)"
    assert _message("nan") == "--x must be a finite number (got nan)"


def test_a_refusal_names_the_command_and_the_reason() -> None:
    e = MillRefused("SET", "RANGE")
    assert (str(e), e.command, e.reason) == ("mill refused SET: NAK RANGE", "SET", "RANGE")
    s = SafetyRefused("RUN", "the drive's comm-loss trip is disabled")
    assert (str(s), s.command, s.reason) == ("refused RUN: the drive's comm-loss trip is disabled", "RUN",
                                             "the drive's comm-loss trip is disabled")
    assert isinstance(s, MillRefused) and isinstance(s, ControlError)

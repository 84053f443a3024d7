"""The one exception type of ``control``: bad input or a broken environment, said in one line."""

from __future__ import annotations

import math


class ControlError(ValueError):
    """A clear, user-facing error of the ``control`` package (the CLI prints it as one line)."""


class MillRefused(ControlError):
    """The motor board answered a command with ``NAK`` and a reason: the link is fine, the
    command was not applied. Not a lost link: the caller logs it and drops the command."""

    def __init__(self, command: str, reason: str) -> None:
        super().__init__(f"mill refused {command}: NAK {reason}")
        self.command = command
        self.reason = reason


class SafetyRefused(MillRefused):
    """This host would not send the command: it would start the motor or raise its speed on a
    device that cannot be relied on to stop by itself (a drive whose comm-loss trip is
    disabled, too slow or unreadable). A stop, a lower speed and reads are always sent."""

    def __init__(self, command: str, reason: str) -> None:
        ControlError.__init__(self, f"refused {command}: {reason}")
        self.command = command
        self.reason = reason


def check_number(
    name: str, value: float | str, *, above: float | None = None, at_least: float | None = None,
    at_most: float | None = None,
) -> float:
    """``value`` as a finite float inside the given bounds, else a one-line ControlError
    naming ``name`` (an option such as ``--timeout``) and the allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    ok = math.isfinite(v)
    ok = ok and (above is None or v > above) and (at_least is None or v >= at_least)
    ok = ok and (at_most is None or v <= at_most)
    if not ok:
        lo = f"> {above:g}" if above is not None else (f">= {at_least:g}" if at_least is not None else "")
        hi = f"<= {at_most:g}" if at_most is not None else ""
        rng = " and ".join(x for x in (lo, hi) if x)
        raise ControlError(f"{name} must be a finite number{' ' + rng if rng else ''} (got {value})")
    return v

"""The one set of limits of the mill and of what-if studies (pure, no I/O).

Every entry point reads them from here: the supervisor enforces the rpm range and the
rate (``SupervisorConfig.limits``), the dashboard's slider and what-if form show them,
``drumtwin mill ... set-rpm`` refuses above them and ``drumtwin whatif`` / the
dashboard's what-if use the same study sizes.

rpm range: ``[min_rpm, min(max_rpm, max_critical_frac * critical_rpm)]`` (``critical_rpm``
None: only ``max_rpm`` limits). What-if: at most ``WHATIF_MAX_S`` simulated seconds per
run and ``WHATIF_MAX_RUNS`` runs (rpm values x seeds) per study, each rpm in
``(0, critical_rpm]`` (a twin above critical speed is not a mixer). A simulated drum that
follows a measured one (the twin beside the mill, the demo's hidden plant) turns at
:func:`simulated_rpm`: at most ``SIM_CRITICAL_FRAC`` of its critical speed.

The defaults of :class:`Limits` are the ones a run uses (``drumtwin run``, ``drumtwin mill``);
only the critical speed comes from the drum (``sim.recipe.DrumSpec.critical_rpm``, handed in).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from control.errors import ControlError

WHATIF_MAX_S = 3600.0  # longest simulated run of one what-if job, s
WHATIF_MAX_RUNS = 2000  # rpm values x seeds of one study
SIM_CRITICAL_FRAC = 0.95
"""The highest share of its critical speed a simulated drum is turned at when it follows a
measured rpm (the twin mirroring the mill, the demo plant following its motor), whatever the
board does: at critical speed the bed centrifuges (and ``sim`` refuses to run above it)."""


def simulated_rpm(rpm: float, critical_rpm: float) -> float:
    """The rpm a simulated drum runs at to follow the measured ``rpm``: inside
    ``[0, SIM_CRITICAL_FRAC * critical_rpm]``."""
    return min(max(float(rpm), 0.0), SIM_CRITICAL_FRAC * float(critical_rpm))


@dataclass(frozen=True)
class RpmCheck:
    """The outcome of checking a requested rpm: ``rpm`` is what will be used (clamped),
    ``message`` says why it differs from the request ("" when it does not)."""

    requested: float
    rpm: float
    message: str = ""

    @property
    def clamped(self) -> bool:
        return bool(self.message)


@dataclass(frozen=True)
class Limits:
    """rpm limits of the mill (rpm, rpm/s) and the drum's critical speed (rpm); the defaults
    are a run's (the drum's critical speed is handed in)."""

    min_rpm: float = 5.0  # the paper's slowest speed; below it the bed only rolls
    max_rpm: float = 45.0
    critical_rpm: float | None = None  # the drum's (the application's: sim.recipe); None: max_rpm only
    max_critical_frac: float = 0.6
    max_rate_rpm_per_s: float = 4.0  # the setpoint's ramp

    def __post_init__(self) -> None:
        for name in ("min_rpm", "max_rpm", "max_critical_frac", "max_rate_rpm_per_s"):
            if not math.isfinite(float(getattr(self, name))):
                raise ControlError(f"{name} must be finite, got {getattr(self, name)}")
        if not 0 <= self.min_rpm < self.max_rpm:
            raise ControlError(f"rpm limits must satisfy 0 <= min < max (got {self.min_rpm}, {self.max_rpm})")
        if not 0 < self.max_critical_frac <= 1:
            raise ControlError("max_critical_frac must be in (0, 1]")
        if self.critical_rpm is not None and not (math.isfinite(self.critical_rpm) and self.critical_rpm > 0):
            raise ControlError(f"critical_rpm must be a positive number, got {self.critical_rpm}")
        if self.rpm_range[1] <= self.min_rpm:
            raise ControlError("the critical-speed limit leaves no rpm above min_rpm")

    @property
    def rpm_range(self) -> tuple[float, float]:
        """(lowest, highest) rpm any entry point may command."""
        if self.critical_rpm is None:
            return self.min_rpm, self.max_rpm
        return self.min_rpm, min(self.max_rpm, self.max_critical_frac * self.critical_rpm)

    def describe(self) -> str:
        """The range in words, for messages: ``"5-45 rpm"`` (+ the critical-speed reason)."""
        lo, hi = self.rpm_range
        text = f"{lo:g}-{hi:.4g} rpm"
        if self.critical_rpm is not None and hi < self.max_rpm:
            text += f" ({self.max_critical_frac:g} x critical speed {self.critical_rpm:.1f} rpm)"
        return text

    def clamp(self, rpm: float) -> float:
        """``rpm`` moved into :attr:`rpm_range`."""
        lo, hi = self.rpm_range
        return min(hi, max(lo, float(rpm)))

    def check_rpm(self, rpm: float) -> RpmCheck:
        """A requested rpm and what will be used; ControlError when it is not a number."""
        try:
            r = float(rpm)
        except (TypeError, ValueError):
            r = math.nan
        if not math.isfinite(r):
            raise ControlError(f"rpm must be a finite number (got {rpm})")
        used = self.clamp(r)
        if used == r:
            return RpmCheck(r, used)
        return RpmCheck(r, used, f"{r:g} rpm is outside the limits {self.describe()}: using {used:g} rpm")

    def refuse_rpm(self, rpm: float, what: str = "rpm") -> float:
        """``rpm`` when inside :attr:`rpm_range` (0 is always allowed: stopped), else a
        one-line ControlError naming the limit."""
        check = self.check_rpm(rpm)
        if check.requested == 0 or not check.clamped:
            return check.requested
        raise ControlError(f"{what} {check.requested:g} is outside the limits {self.describe()}")

    def check_whatif(self, rpms: Sequence[float], duration_s: float, seeds: int = 1) -> tuple[list[float], float]:
        """A what-if study's rpm values and duration (s) as floats, or a one-line
        ControlError naming the limit: at most ``WHATIF_MAX_RUNS`` runs, ``(0,
        WHATIF_MAX_S]`` s, each rpm in ``(0, critical_rpm]`` (``max_rpm`` without one)."""
        try:
            values = [float(r) for r in rpms]
            duration = float(duration_s)
        except (TypeError, ValueError):
            raise ControlError(f"what-if needs numbers (got rpms {rpms!r}, duration {duration_s!r})") from None
        if not values:
            raise ControlError("what-if: give at least one rpm")
        if len(values) * max(1, int(seeds)) > WHATIF_MAX_RUNS:
            raise ControlError(f"what-if: at most {WHATIF_MAX_RUNS} runs per study (got {len(values) * seeds})")
        if not (math.isfinite(duration) and 0 < duration <= WHATIF_MAX_S):
            raise ControlError(f"what-if duration must be in (0, {WHATIF_MAX_S:g}] s (got {duration_s})")
        top = self.critical_rpm if self.critical_rpm is not None else self.max_rpm
        for r in values:
            if not (math.isfinite(r) and 0 < r <= top):
                raise ControlError(f"what-if rpm {r:g} outside (0, {top:.4g}] rpm")
        return values, duration


__all__ = ["SIM_CRITICAL_FRAC", "WHATIF_MAX_RUNS", "WHATIF_MAX_S", "Limits", "RpmCheck", "simulated_rpm"]

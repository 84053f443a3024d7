"""A model of the mill's drive: setpoint -> actual rpm (pure, advanced by ``step``)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class MotorConfig:
    """Drive limits: top speed (rpm), acceleration limit (rpm/s), first-order lag (s)."""

    max_rpm: float = 60.0
    accel_rpm_per_s: float = 10.0
    tau_s: float = 0.5


@dataclass(frozen=True)
class MotorState:
    """A snapshot of the motor (safe to hand to another thread)."""

    setpoint_rpm: float
    actual_rpm: float
    running: bool
    fault: str | None = None


class MotorModel:
    """Speed loop of the drive.

    The speed follows ``target`` (the setpoint when running, 0 when stopped) as a
    first-order lag with time constant ``tau_s`` whose slope is clipped to
    ``accel_rpm_per_s``; the speed never exceeds ``max_rpm`` and never goes negative.
    """

    def __init__(self, config: MotorConfig | None = None) -> None:
        self.config = config or MotorConfig()
        self.setpoint_rpm = 0.0
        self.actual_rpm = 0.0
        self.running = False
        self.fault: str | None = None

    @property
    def target_rpm(self) -> float:
        return self.setpoint_rpm if self.running else 0.0

    def step(self, dt_s: float) -> float:
        """Advance by ``dt_s`` seconds; returns the new actual rpm."""
        if dt_s <= 0:
            return self.actual_rpm
        c = self.config
        err = self.target_rpm - self.actual_rpm
        # exact first-order response over dt, then the acceleration clip
        delta = err * (1.0 - math.exp(-dt_s / max(c.tau_s, 1e-9)))
        max_d = c.accel_rpm_per_s * dt_s
        delta = max(-max_d, min(max_d, delta))
        self.actual_rpm = max(0.0, min(c.max_rpm, self.actual_rpm + delta))
        if abs(self.target_rpm - self.actual_rpm) < 0.005:  # below the 0.01 rpm the board reports
            self.actual_rpm = self.target_rpm
        return self.actual_rpm

    def state(self) -> MotorState:
        return MotorState(self.setpoint_rpm, self.actual_rpm, self.running, self.fault)

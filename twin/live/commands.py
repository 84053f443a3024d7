"""What the live workers are told: small frozen commands, each put on the queue of the worker
that owns what it changes (the mill worker, the supervisor worker, the camera, the twin, the
what-if worker), and served on that worker's own thread."""

from __future__ import annotations

import queue
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TypeVar

from vision.meter import Meter

T = TypeVar("T")


def drain(q: queue.Queue[T] | queue.SimpleQueue[T]) -> Iterator[T]:
    """Every item waiting in ``q`` now, oldest first, without blocking."""
    while True:
        try:
            yield q.get_nowait()
        except queue.Empty:
            return



@dataclass(frozen=True)
class SetRpm:
    """Set the mill's setpoint; ``epoch``: the :class:`MillSnapshot` epoch it was decided on."""

    rpm: float
    epoch: int
    source: str = "supervisor"


@dataclass(frozen=True)
class StartMill:
    """Start the motor (only ever on an operator's command); ``epoch`` as in :class:`SetRpm`."""

    epoch: int
    source: str = "operator"


@dataclass(frozen=True)
class StopMill:
    """Stop the motor. Never stale. ``urgent``: drop every pending command first (E-stop)."""

    source: str = "operator"
    urgent: bool = False


MillCommand = SetRpm | StartMill | StopMill


@dataclass(frozen=True)
class SetMode:
    mode: str


@dataclass(frozen=True)
class SetManualRpm:
    rpm: float


SupervisorCommand = SetMode | SetManualRpm


@dataclass(frozen=True)
class SwapClasses:
    """Measure from the next camera frame on with ``meter``: one built off the camera thread
    (1-3 s) from ``vision.suggest.relearn_classes``' config (the classes re-learned from the
    live bed after ``lighting_changed:``; names and order kept)."""

    meter: Meter
    source: str = "operator"


@dataclass(frozen=True)
class Recalibrate:
    """Calibrate the twin again once the camera's slope window and a steady drum allow it."""


@dataclass(frozen=True)
class Reseed:
    """Seed the twin again from the newest camera frame (between two of its steps)."""


TwinCommand = Recalibrate | Reseed


@dataclass(frozen=True)
class RunStudy:
    """An operator's what-if study: ``rpms`` for ``duration_s`` simulated seconds each, from the
    twin's newest state (checked against ``control.limits`` before it is sent)."""

    rpms: tuple[float, ...]
    duration_s: float
    reason: str = "operator"


__all__ = ["MillCommand", "Recalibrate", "Reseed", "RunStudy", "SetManualRpm", "SetMode", "SetRpm", "StartMill",
           "StopMill", "SupervisorCommand", "SwapClasses", "TwinCommand", "drain"]

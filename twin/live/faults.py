"""Fault injection into the live workers, typed: :class:`FaultHooks` names every point a test may
hook (a misspelt point is a type error, not a silent no-op), and each worker calls its own
hooks on its own thread. A production run has none (every hook None)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from twin.live.snapshots import TwinInfo

Hook = Callable[[float], None]
"""Called with the run time (s) at a worker's point; it may raise (a bug in that worker: the
run ends, ``worker_crashed``) or block (a hung worker)."""


@dataclass(frozen=True)
class FaultHooks:
    """Where a test may break the live loop. Each ``Hook`` runs on its worker's thread:
    ``camera_frame`` before each frame is measured (the frame's time), ``process_reading``
    before each reading is processed (its time), ``mill_cycle`` at each poll of the mill,
    ``twin_pass`` at each pass of the twin's loop once seeded, ``whatif_pass`` at each
    look for a pending study, ``supervisor_tick`` at each supervision step.
    ``twin_published``: the twin's state as it is published (a twin gone wrong)."""

    camera_frame: Hook | None = None
    process_reading: Hook | None = None
    mill_cycle: Hook | None = None
    twin_pass: Hook | None = None
    whatif_pass: Hook | None = None
    supervisor_tick: Hook | None = None
    twin_published: Callable[[TwinInfo], TwinInfo] | None = None


def at(hook: Hook | None, now_s: float) -> None:
    """Run ``hook`` at run time ``now_s`` (nothing when there is none)."""
    if hook is not None:
        hook(now_s)


NO_FAULTS = FaultHooks()

__all__ = ["NO_FAULTS", "FaultHooks", "Hook", "at"]

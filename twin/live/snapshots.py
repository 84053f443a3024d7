"""What the live workers read of each other: immutable snapshots and the read-only view of the run.

Threads never share mutable fields. Each snapshot has exactly one writer (the worker that
owns it) and is replaced whole in a :class:`Latest` box; readers get the current value and
keep it as long as they like. A worker reads the others only through a :class:`RunView`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from control.protocol import MillStatus
from control.trend import TrendEstimate
from vision.meter import Reading
from vision.roi import DrumROI

T = TypeVar("T")


class Latest(Generic[T]):
    """The newest value of one snapshot: one writer ``set``s, any thread ``get``s."""

    def __init__(self, value: T) -> None:
        self._lock = threading.Lock()
        self._value = value

    def get(self) -> T:
        with self._lock:
            return self._value

    def set(self, value: T) -> None:
        with self._lock:
            self._value = value



@dataclass(frozen=True)
class MillSnapshot:
    """The mill as the mill worker last saw it: the board's own report (``status``, None
    before the first answer) plus the link. ``epoch`` grows by one each time the board
    was read again after a link loss or a refused command: commands decided on an older
    epoch are stale and are dropped. ``polled``: the worker has tried at least once.
    ``refused``: commands the board refused (NAK) or acknowledged without taking them, so
    far in this run (the supervisor goes safe when it grows)."""

    status: MillStatus | None = None
    connected: bool = False
    epoch: int = 0
    polled: bool = False
    refused: int = 0

    @property
    def actual_rpm(self) -> float:
        """The board's actual rpm, NaN when unknown: never read, or the link is lost (the
        last report is then history, not a measurement; ``status`` keeps it)."""
        return math.nan if self.status is None or not self.connected else float(self.status.actual_rpm)

    @property
    def setpoint_rpm(self) -> float:
        """The board's setpoint (rpm), NaN when unknown (as :attr:`actual_rpm`)."""
        return math.nan if self.status is None or not self.connected else float(self.status.setpoint_rpm)

    @property
    def link_flag(self) -> str | None:
        """``"link_lost:mill"`` while the link is lost after it was polled (the frame row's
        flag beside the empty rpm columns), else None."""
        return "link_lost:mill" if self.polled and not self.connected else None

    @property
    def running(self) -> bool:
        return bool(self.status is not None and self.status.running)

    @property
    def fault(self) -> str | None:
        return None if self.status is None else self.status.fault

    @property
    def state(self) -> str:
        """One word for the dashboard: link lost, fault X, running, stopped."""
        if not self.connected:
            return "link lost" if self.polled else "connecting"
        if self.fault:
            return f"fault {self.fault}"
        return "running" if self.running else "stopped"


@dataclass(frozen=True)
class CameraInfo:
    """The camera worker's newest frame: run time ``t_s`` (None before the first),
    ``wall_s`` (``time.monotonic()`` when it arrived), the image (never mutated), the
    drum ROI the meter used, frame count, and whether the source has ended."""

    t_s: float | None = None
    wall_s: float = 0.0
    image: np.ndarray | None = None
    roi: DrumROI | None = None
    n_frames: int = 0
    ended: bool = False


@dataclass(frozen=True)
class FrameInfo:
    """The process worker's newest result: run time of the newest processed frame, frames
    processed, time of the last valid MI, the reading and the Kalman estimate; whether the
    batch is at its endpoint (``control.endpoint``) and since when."""

    t_s: float = 0.0
    n_frames: int = 0
    last_valid_t_s: float | None = None
    reading: Reading | None = None
    estimate: TrendEstimate | None = None
    mixed: bool = False
    mixing_time_s: float | None = None


@dataclass(frozen=True)
class TwinInfo:
    """The twin worker's newest state: run time it last stepped to (None: no twin yet),
    its measured MI and slope, the engine's snapshot (``Twin.snapshot()``: opaque, picklable;
    a ``sim.drum.SimState`` or a pymunk state) no older than a few seconds for what-if studies,
    ``seeds``: how many times it was seeded (from the camera's bed), and ``age_s``: the simulated
    seconds since its latest seeding (its bed's spin-up; run time skipped to catch up is not in it),
    ``energy_j``: the drive energy its drum torque and speed add up to over the run."""

    updated_s: float | None = None
    mi: float = math.nan
    slope_deg: float = math.nan
    state: Any = None  # as sim.engine.Twin.snapshot() (Any there: each engine its own state class)
    seeds: int = 0
    age_s: float = 0.0
    energy_j: float = 0.0  # drive energy the twin estimates since the run started (sim.power), J


class RunView:
    """What a worker may read: run time and the newest snapshots (never the loop itself).

    Run time is the newest camera frame's time plus the run time since it arrived (so
    time still passes for the supervisor when the camera stops); it never goes backwards
    once frames come. Before the first frame it is ``clock_now()`` (the run clock), which
    the first frame's time then replaces.
    """

    def __init__(
        self,
        speed: float,
        camera: Latest[CameraInfo],
        frames: Latest[FrameInfo],
        mill: Latest[MillSnapshot],
        twin: Latest[TwinInfo],
        mode: Latest[str],
        clock_now: Callable[[], float],
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.speed = float(speed)
        self._camera, self._frames, self._mill, self._twin, self._mode = camera, frames, mill, twin, mode
        self._clock_now = clock_now
        self._monotonic = monotonic
        self._lock = threading.Lock()
        self._last = -math.inf

    def now_s(self) -> float:
        cam = self._camera.get()
        if cam.t_s is None:
            return self._clock_now()
        t = cam.t_s + (self._monotonic() - cam.wall_s) * self.speed
        with self._lock:
            self._last = max(self._last, t)
            return self._last

    def camera(self) -> CameraInfo:
        return self._camera.get()

    def frames(self) -> FrameInfo:
        return self._frames.get()

    def mill(self) -> MillSnapshot:
        return self._mill.get()

    def twin(self) -> TwinInfo:
        return self._twin.get()

    def mode(self) -> str:
        return self._mode.get()


__all__ = ["CameraInfo", "FrameInfo", "Latest", "MillSnapshot", "RunView", "TwinInfo"]

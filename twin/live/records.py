"""What the live workers exchange: immutable snapshots, typed commands, a read-only view
of the run, and the event sink (typed run records onto the run's bus: ``twin.records``).

Threads never share mutable fields. Each snapshot has exactly one writer (the worker
that owns it) and is replaced whole in a :class:`Latest` box; readers get the current
value and keep it as long as they like. Commands are small frozen dataclasses put on
the owning worker's queue.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from control.protocol import MillStatus
from control.trend import TrendEstimate
from twin.records import Bus, DecisionMade, FaultCleared, FaultRaised, Record
from twin.runlog import RecordWriter, write_record
from twin.state import LiveState
from vision.meter import Meter, Reading
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


def drain(q: queue.Queue[T] | queue.SimpleQueue[T]) -> Iterator[T]:
    """Every item waiting in ``q`` now, oldest first, without blocking."""
    while True:
        try:
            yield q.get_nowait()
        except queue.Empty:
            return


# -- snapshots --------------------------------------------------------------------------------
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
    seconds since its latest seeding (its bed's spin-up; run time skipped to catch up is not in it)."""

    updated_s: float | None = None
    mi: float = math.nan
    slope_deg: float = math.nan
    state: Any = None  # as sim.engine.Twin.snapshot() (Any there: each engine its own state class)
    seeds: int = 0
    age_s: float = 0.0


# -- commands ---------------------------------------------------------------------------------
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


# -- the read-only view -----------------------------------------------------------------------
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


# -- events ---------------------------------------------------------------------------------
class EventSink(Protocol):
    """Where workers report: typed run records (``publish``, see ``twin.records``; a
    ``FaultRaised`` goes out once until its ``FaultCleared``) and metadata for the run log's
    ``metadata.json``."""

    def publish(self, rec: Record) -> None: ...
    def metadata(self, **data: object) -> None: ...


class RunLogLike(RecordWriter, Protocol):
    """The run log as the sink uses it (``twin.runlog.RunLog``): a record writer with metadata."""

    def set_metadata(self, **data: Any) -> None: ...


class RunEvents:
    """The run's :class:`EventSink`: records go on the run's :class:`Bus` (``bus``), to which the
    run log (``twin.runlog.write_record``: CSV rows, JSONL events) and the dashboard's state
    (``LiveState.record``) subscribe. Faults go through the run's one ``ActiveFaults``
    (``state.faults``): a ``FaultRaised`` is published only when its fault is not active, a
    ``FaultCleared`` only when it is. Thread-safe; counts faults and decisions. A run-log write
    that fails (disk full, read-only) never raises into a worker: the first one is a ``run_log``
    alarm and goes to ``on_failure`` (the loop ends the run)."""

    def __init__(
        self, runlog: RunLogLike, state: LiveState, on_failure: Callable[[str], None] | None = None,
        bus: Bus | None = None,
    ) -> None:
        self.runlog = runlog
        self.state = state
        self.faults = state.faults
        self.on_failure = on_failure
        self.bus = bus if bus is not None else Bus()
        self._lock = threading.Lock()
        self.n_faults = 0
        self.n_decisions = 0
        self.log_error: str | None = None
        self.bus.subscribe(self._log)
        self.bus.subscribe(state.record)

    def _log(self, rec: Record) -> None:
        self._write(write_record, self.runlog, rec)

    def _write(self, write: Callable[..., object], *args: object, **kwargs: object) -> None:
        try:
            write(*args, **kwargs)
        except OSError as exc:
            with self._lock:
                if self.log_error is not None:
                    return
                self.log_error = reason = f"cannot write the run log: {exc}"
            self.faults.raise_fault("run_log", reason)
            if self.on_failure is not None:
                self.on_failure(reason)

    def publish(self, rec: Record) -> None:
        if isinstance(rec, FaultRaised):
            if not self.faults.raise_fault(rec.fault, rec.message, shown=False):
                return
            with self._lock:
                self.n_faults += 1
            self.bus.publish(rec)
            self.faults.show(rec.fault)  # the alarm once its event is logged
            return
        if isinstance(rec, FaultCleared) and not self.faults.clear(rec.fault):
            return
        if isinstance(rec, DecisionMade):
            with self._lock:
                self.n_decisions += 1
        self.bus.publish(rec)

    def metadata(self, **data: object) -> None:
        self._write(self.runlog.set_metadata, **data)

    def active(self) -> frozenset[str]:
        return self.faults.keys()

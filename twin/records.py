"""What a run emits: one stream of typed, immutable run records, and the bus that carries them.

Every record is a frozen dataclass with a run time ``t_s`` and a ``kind``. Each kind declares
its fields and their units once, here; everything else is derived from these classes:

* the frame CSV's columns (:data:`FRAME_COLUMNS`, from :class:`FrameReading`) and the
  dashboard's plot series (:data:`SERIES`, the fields marked ``plot``);
* the ``events.jsonl`` lines: ``{"t_s", "wall_s", "kind", **fields}`` of every record whose
  class is ``logged`` (:func:`event_fields`; optional fields that are None are left out);
* the dashboard's numbers panel (``twin.state.Panel``), which folds the records it sees;
* the table of record kinds in ``docs/architecture.md`` (:func:`records_table`, checked by a test);
* the run log's descriptors (units, dtype, source of each column and field: ``twin.descriptors``)

Producers (the live workers, the loop, the dashboard) construct these classes and ``publish``
them (``twin.live.events.EventSink``; no producer names a kind by string, so a misspelt kind
or field is a mypy error) onto a :class:`Bus`; consumers subscribe: the run log
(``twin.runlog.RunLog.record``: CSV rows and JSONL lines), the dashboard's state
(``twin.state.LiveState.record``: plots, numbers panel). The one set of active faults is
:class:`ActiveFaults` (the sink publishes a :class:`FaultRaised` only when its fault is not
active). ``compare``, ``report`` and the tests read the same records back with
``twin.runlog.read_frames`` / ``read_events`` (dicts, the JSONL keys) or ``read_records``
(typed: the one name -> class lookup, :func:`record_of`).

Adding a record kind is a one-place change: a frozen dataclass here, derived from :class:`Record`
(or a group base), with a ``kind`` ClassVar, its fields with :func:`unit` / :func:`opt`, and
``@register``; the docs table is regenerated with ``python -m twin.records``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import MISSING, Field, dataclass, field, fields
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

if TYPE_CHECKING:
    from control.supervisor import Decision

log = logging.getLogger("drumtwin.records")


def unit(u: str = "", doc: str = "", *, plot: bool = False, default: object = MISSING, source: str = "") -> Any:
    """A record field with its unit (``""``: none, a count, a name) and a short description;
    ``plot``: a dashboard plot series (frame readings only); ``source``: where the value comes
    from when not from the record's ``producer`` (the descriptors' ``source``)."""
    meta = {"unit": u, "doc": doc, "plot": plot, "source": source}
    if default is MISSING:
        return field(metadata=meta)
    return field(default=default, metadata=meta)


def opt(u: str = "", doc: str = "") -> Any:
    """An optional event field (default None): left out of the JSONL line when None."""
    return field(default=None, metadata={"unit": u, "doc": doc, "plot": False, "optional": True})


@dataclass(frozen=True, kw_only=True)
class Record:
    """One run record. ``kind``: its name in ``events.jsonl`` (and in the docs table);
    ``logged``: written to ``events.jsonl`` (the frame reading goes to ``frames.csv``; the
    dashboard-only status records to neither)."""

    kind: ClassVar[str] = ""
    logged: ClassVar[bool] = True
    doc: ClassVar[str] = ""
    producer: ClassVar[str] = ""
    """The producer (a module or person): the descriptors' ``source`` of its fields (unless a field names its own)."""

    t_s: float = unit("s", "run time (the demo clock, scaled by --speed)")


R = TypeVar("R", bound=type[Record])

KINDS: dict[str, type[Record]] = {}
"""Every record kind by name (the registry :func:`register` fills)."""


def register(cls: R) -> R:
    """Register a record class under its ``kind`` (one class per kind, each kind once)."""
    if not cls.kind or cls.kind in KINDS:
        raise TypeError(f"record kind {cls.kind!r} of {cls.__name__} is empty or registered twice")
    KINDS[cls.kind] = cls
    return cls


# -- the frame reading: one row of frames.csv ------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class FrameReading(Record):
    """One processed camera frame: the run log's CSV row and the plots' point."""

    kind: ClassVar[str] = "frame"
    logged: ClassVar[bool] = False
    doc: ClassVar[str] = "one processed camera frame (a row of frames.csv)"
    producer: ClassVar[str] = "twin.live.camera"

    t_s: float = unit("s", "run time of the frame", plot=True, source="vision.sources")
    frame: int = unit("", "camera frame index", source="vision.sources")
    mi: float = unit("", "mixing index, paper eq. 4 (0..1, NaN when invalid)", plot=True, source="vision.meter")
    mi_sigmoid: float = unit("", "paper eq. 3", source="vision.meter")
    mi_linear: float = unit("", "paper eq. 1", source="vision.meter")
    d_px: float = unit("px", "centroid distance of the two classes", source="vision.meter")
    dsigma_px: float = unit("px", "spread difference of the two classes", source="vision.meter")
    concentration: float = unit("", "n_1 / (n_1 + n_2)", source="vision.meter")
    slope_deg: float = unit("deg", "bed free-surface slope", plot=True, source="vision.meter")
    valid: bool = unit("", "the reading counts as vision", source="vision.meter")
    trend_mi: float = unit("", "Kalman trend level", plot=True, source="control.trend")
    trend_lo95: float = unit("", "trend 95 % band, low", plot=True, source="control.trend")
    trend_hi95: float = unit("", "trend 95 % band, high", plot=True, source="control.trend")
    trend_rate: float = unit("1/s", "trend rate of change", source="control.trend")
    ma_mi: float = unit("", "the paper's 150-sample moving average", plot=True, source="control.trend")
    twin_mi: float | None = unit("", "twin MI (empty: no twin yet)", plot=True, source="twin.live.twin")
    twin_slope_deg: float | None = unit("deg", "twin slope (empty: no twin yet)", plot=True, source="twin.live.twin")
    rpm_setpoint: float | None = unit("rpm", "board setpoint (empty: link lost)", plot=True, source="twin.live.mill")
    rpm_actual: float | None = unit("rpm", "board actual speed (empty: link lost)", plot=True, source="twin.live.mill")
    mode: str = unit("", "supervisor mode: off | manual | auto", source="control.supervisor")
    flags: tuple[str, ...] = unit("", "reading flags, ';'-separated", source="vision.meter")
    mixed: bool = unit("", "the batch is at its endpoint", default=False, source="control.endpoint")
    mixing_time_s: float | None = unit("s", "mixing time of the endpoint (empty: not mixed)", default=None,
                                       source="control.endpoint")

    def as_dict(self) -> dict[str, object]:
        """The CSV row (without ``wall_s``, which the run log fills in)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


FRAME_COLUMNS: tuple[str, ...] = ("t_s", "wall_s", *(f.name for f in fields(FrameReading)[1:]))
"""The columns of ``frames.csv``: the frame reading's fields, with ``wall_s`` (unix time when
the row was written, s) after ``t_s``."""

SERIES: tuple[str, ...] = tuple(f.name for f in fields(FrameReading) if f.metadata.get("plot"))
"""The dashboard's plot series (x is ``t_s``)."""


# -- run start / stop -------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class RunStart(Record):
    kind: ClassVar[str] = "start"
    doc: ClassVar[str] = "the workers start: the run's configuration, versions and mixer (also in metadata.json)"
    producer: ClassVar[str] = "twin.run.loop"
    mode: str = unit("", "supervisor mode at start")
    mill: str = unit("", "mill link URL")
    config: Mapping[str, object] | None = unit("", "the resolved run options (RunConfig.to_metadata: the token never)",
                                        default=None)
    versions: Mapping[str, str] | None = unit("", "drumtwin, python, numpy, opencv, pymunk, viser, ... versions",
                                       default=None)
    mixer: Mapping[str, object] | None = unit("", "the twin's mixer: drum, fill, direction, particle classes",
                                              default=None)


@register
@dataclass(frozen=True, kw_only=True)
class RunStop(Record):
    kind: ClassVar[str] = "stop"
    doc: ClassVar[str] = "the run ended"
    producer: ClassVar[str] = "twin.run.loop"
    frames: int = unit("", "frames processed")
    workers_alive: Sequence[str] = unit("", "workers still running after the join")
    failure: str | None = unit("", "why the run had to end (null: it did not)")
    energy_j: float | None = opt("J", "drive energy over the run as the twin estimates it (its drum torque x "
                                 "angular speed, sim.power; null: no twin ran)")


# -- faults -----------------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class FaultRaised(Record):
    kind: ClassVar[str] = "fault"
    doc: ClassVar[str] = "a named fault raised (once until cleared; a dashboard alarm)"
    producer: ClassVar[str] = "twin.live"
    fault: str = unit("", "fault key, e.g. mill_link, vision_lost")
    message: str = unit("", "what the operator reads")
    url: str | None = opt("", "mill link URL")
    mill_fault: str | None = opt("", "the board's fault code")
    frame: int | None = opt("", "camera frame index")
    worker: str | None = opt("", "the worker that crashed (worker_crashed)")
    error: str | None = opt("", "the exception in one line: Type: message (worker_crashed)")
    traceback: str | None = opt("", "where it was raised (worker_crashed: the stderr shows one line)")


@register
@dataclass(frozen=True, kw_only=True)
class FaultCleared(Record):
    kind: ClassVar[str] = "recovered"
    doc: ClassVar[str] = "an active fault cleared"
    producer: ClassVar[str] = "twin.live"
    fault: str = unit("", "fault key")
    message: str = unit("", "why it cleared")
    url: str | None = opt("", "mill link URL")


# -- operator ---------------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class OperatorAction(Record):
    kind: ClassVar[str] = "operator"
    doc: ClassVar[str] = "an operator command taken"
    producer: ClassVar[str] = "operator"
    action: str = unit("", "start | stop | emergency_stop | manual_rpm | recalibrate | reseed | whatif | ...")
    rpm: float | None = opt("rpm", "requested rpm")
    clamped_rpm: float | None = opt("rpm", "rpm after the limits")
    rpms: Sequence[float] | None = opt("rpm", "what-if speeds")
    duration_s: float | None = opt("s", "what-if duration")
    cancelled: bool | None = opt("", "a study was cancelled")


@register
@dataclass(frozen=True, kw_only=True)
class OperatorRejected(Record):
    kind: ClassVar[str] = "operator_rejected"
    doc: ClassVar[str] = "an operator command refused (bad input, busy)"
    producer: ClassVar[str] = "operator"
    action: str = unit("", "the command")
    error: str = unit("", "why")
    mode: str | None = opt("", "requested mode")
    rpm: float | None = opt("rpm", "requested rpm")
    client: int | None = opt("", "dashboard client id")


@register
@dataclass(frozen=True, kw_only=True)
class OperatorClamped(Record):
    kind: ClassVar[str] = "operator_clamped"
    doc: ClassVar[str] = "a dashboard rpm brought inside the limits"
    producer: ClassVar[str] = "twin.dashboard"
    client: int = unit("", "dashboard client id")
    requested: float = unit("rpm", "what was asked")
    rpm: float = unit("rpm", "what is sent")


# -- supervisor -------------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class DecisionMade(Record):
    kind: ClassVar[str] = "decision"
    doc: ClassVar[str] = "a supervisor decision and the inputs it was made on"
    producer: ClassVar[str] = "control.supervisor"
    decision: str = unit("", "mode | manual | move | ramp | hold | safe | recover")
    mode: str = unit("", "supervisor mode")
    action: str = unit("", "none | set_rpm | stop")
    reason: str = unit("", "why")
    rpm: float | None = unit("rpm", "setpoint to send now")
    target_rpm: float | None = unit("rpm", "where a ramp is heading")
    safe: bool = unit("", "in the safe state")
    level: float | None = unit("", "trend MI level")
    rate: float | None = unit("1/s", "trend rate")
    predictions: Mapping[str, float] | None = unit("", "rpm -> predicted plateau MI")
    inputs: Mapping[str, object] | None = unit("", "the supervisor's inputs (see control.supervisor)")
    predicted_time_to_target_s: float | None = opt("s", "objective time/energy: the twin's time to the target MI "
                                                   "at the rpm picked, from the study's start")
    predicted_energy_j: float | None = opt("J", "objective time/energy: the twin's drive energy to the target there")
    prediction_t_s: float | None = opt("s", "run time the supervisor asked for the study behind the pick")

    @classmethod
    def of(cls, d: Decision) -> DecisionMade:
        """The record of a supervisor decision (``Decision.as_dict``, its ``kind`` as ``decision``)."""
        data = d.as_dict()
        data.pop("t_s", None)
        data["decision"] = data.pop("kind")  # "kind" is the record's kind
        return cls(t_s=d.t_s, **data)  # type: ignore[arg-type]


# -- mill -------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class _MillCommandRecord(Record):
    producer: ClassVar[str] = "twin.live.mill"
    command: str = unit("", "set_rpm | start | stop")
    source: str = unit("", "supervisor | operator | emergency_stop | run_failed | run_end")
    rpm: float | None = opt("rpm", "setpoint of a set_rpm")


@register
@dataclass(frozen=True, kw_only=True)
class MillCommandSent(_MillCommandRecord):
    kind: ClassVar[str] = "mill_command"
    doc: ClassVar[str] = "a command the board took"


@register
@dataclass(frozen=True, kw_only=True)
class MillCommandDropped(_MillCommandRecord):
    kind: ClassVar[str] = "mill_command_dropped"
    doc: ClassVar[str] = "a command never sent (stale, superseded, link lost)"
    reason: str = unit("", "why")


@register
@dataclass(frozen=True, kw_only=True)
class MillRefused(_MillCommandRecord):
    kind: ClassVar[str] = "mill_refused"
    doc: ClassVar[str] = "a command the board refused (NAK)"
    reason: str = unit("", "the board's reason")


@dataclass(frozen=True, kw_only=True)
class _MillStatusRecord(Record):
    producer: ClassVar[str] = "twin.live.mill"
    setpoint_rpm: float = unit("rpm", "board setpoint")
    actual_rpm: float = unit("rpm", "board actual speed")
    running: bool = unit("", "motor running")
    fault: str | None = unit("", "board fault code")


@register
@dataclass(frozen=True, kw_only=True)
class MillMismatch(_MillStatusRecord):
    kind: ClassVar[str] = "mill_mismatch"
    doc: ClassVar[str] = "an acknowledged setpoint the board does not show"
    rpm: float = unit("rpm", "the setpoint sent")


@register
@dataclass(frozen=True, kw_only=True)
class MillChangedElsewhere(_MillStatusRecord):
    kind: ClassVar[str] = "mill_changed_elsewhere"
    doc: ClassVar[str] = "the board changed without this run (front panel, another host)"
    was: Mapping[str, object] = unit("", "the board's previous status")


@register
@dataclass(frozen=True, kw_only=True)
class MillSynced(_MillStatusRecord):
    kind: ClassVar[str] = "mill_synced"
    doc: ClassVar[str] = "the board read (again) after connecting"
    epoch: int = unit("", "mill state epoch")


# -- trend ------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class _TrendChange(Record):
    producer: ClassVar[str] = "control.trend"
    level: float = unit("", "trend MI level")
    lo95: float = unit("", "95 % band, low")
    hi95: float = unit("", "95 % band, high")
    n_since_init: int = unit("", "accepted frames since the last (re-)init")
    reason: str = unit("", "why")


@register
@dataclass(frozen=True, kw_only=True)
class TrendSettled(_TrendChange):
    kind: ClassVar[str] = "trend_settled"
    doc: ClassVar[str] = "the Kalman trend became settled (the supervisor may decide)"


@register
@dataclass(frozen=True, kw_only=True)
class TrendUnsettled(_TrendChange):
    kind: ClassVar[str] = "trend_unsettled"
    doc: ClassVar[str] = "the Kalman trend is unsettled (the supervisor decides nothing)"


# -- batch endpoint (control.endpoint, docs/endpoint.md) ----------------------------------------
@dataclass(frozen=True, kw_only=True)
class _EndpointChange(Record):
    producer: ClassVar[str] = "control.endpoint"
    mixing_time_s: float | None = opt("s", "mixing time (run time since which the trend holds its plateau)")
    plateau_mi: float | None = opt("", "the plateau the trend holds")
    block_sd: float | None = opt("", "moving-block spread of the raw MI: 1.4826 x its median absolute deviation "
                                 "(an sd that one odd frame cannot move)")
    reason: str = unit("", "why", default="")


@register
@dataclass(frozen=True, kw_only=True)
class Mixed(_EndpointChange):
    kind: ClassVar[str] = "mixed"
    doc: ClassVar[str] = "the batch reached its endpoint (the trend in its band for the dwell, the block sd low)"


@register
@dataclass(frozen=True, kw_only=True)
class Unmixed(_EndpointChange):
    kind: ClassVar[str] = "unmixed"
    doc: ClassVar[str] = "the batch left its endpoint band again"


# -- the run catalogue (twin.catalogue) ---------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class CatalogueUnavailable(Record):
    kind: ClassVar[str] = "catalogue_unavailable"
    doc: ClassVar[str] = "the run could not be indexed in the run catalogue (it goes on; 'runs list' indexes it later)"
    producer: ClassVar[str] = "twin.catalogue"
    message: str = unit("", "why, and what happens next")


@register
@dataclass(frozen=True, kw_only=True)
class SlowerThanGolden(Record):
    kind: ClassVar[str] = "slower_than_golden"
    doc: ClassVar[str] = "this batch is behind its rig's golden batch by more than the rig's usual spread (no alarm)"
    producer: ClassVar[str] = "twin.live.golden"
    golden_run: str = unit("", "the golden batch's run id")
    mi: float = unit("", "this run's trend MI now")
    golden_mi: float = unit("", "the golden batch's trend MI at the same run time")
    deviation: float = unit("", "mi - golden_mi")
    spread: float = unit("", "the rig's usual spread of MI at this run time (its runs' sd, or the floor)")


# -- twin -------------------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class TwinLag(Record):
    kind: ClassVar[str] = "twin_lag"
    doc: ClassVar[str] = "the twin fell behind the camera and skipped ahead"
    producer: ClassVar[str] = "twin.live.twin"
    lag_s: float = unit("s", "run time skipped")


@register
@dataclass(frozen=True, kw_only=True)
class TwinSeeded(Record):
    kind: ClassVar[str] = "twin_seeded"
    doc: ClassVar[str] = "the twin was (re)seeded"
    producer: ClassVar[str] = "twin.live.twin"
    source: str = unit("", "live frame | recipe case (...)")
    n_particles: int = unit("", "particles in the twin")


@register
@dataclass(frozen=True, kw_only=True)
class CalibrationWaiting(Record):
    kind: ClassVar[str] = "calibration_waiting"
    doc: ClassVar[str] = "the twin waits for a turning, steady drum before it calibrates (not a fault)"
    producer: ClassVar[str] = "twin.live.twin"
    reason: str = unit("", "why it waits")
    rpm: float = unit("rpm", "the board's actual speed now")


@register
@dataclass(frozen=True, kw_only=True)
class CalibrationStarted(Record):
    kind: ClassVar[str] = "calibration_started"
    doc: ClassVar[str] = "a twin calibration started"
    producer: ClassVar[str] = "twin.live.twin"
    target_slope_deg: float = unit("deg", "camera slope to match")
    rpm: float = unit("rpm", "speed it is calibrated at")


@register
@dataclass(frozen=True, kw_only=True)
class Calibrated(Record):
    kind: ClassVar[str] = "calibration"
    doc: ClassVar[str] = "a twin calibration applied"
    producer: ClassVar[str] = "twin.live.twin"
    target_slope_deg: float = unit("deg", "camera slope to match")
    rpm: float = unit("rpm", "speed it was calibrated at")
    friction: float = unit("", "sliding friction coefficient")
    rolling: float = unit("", "rolling friction coefficient")
    twin_slope_deg: float = unit("deg", "the calibrated twin's slope")
    residual_deg: float = unit("deg", "twin minus target")
    took_s: float = unit("s", "wall time")


# -- what-if ----------------------------------------------------------------------------------
@register
@dataclass(frozen=True, kw_only=True)
class WhatIfResult(Record):
    kind: ClassVar[str] = "whatif"
    doc: ClassVar[str] = "a what-if study's result"
    producer: ClassVar[str] = "twin.live.whatif"
    reason: str = unit("", "AUTO | operator")
    requested_t_s: float = unit("s", "run time it was asked")
    duration_s: float = unit("s", "simulated time per rpm")
    predictions: Mapping[str, float] = unit("", "rpm -> plateau MI")
    took_s: float = unit("s", "wall time")
    target_mi: float | None = opt("", "the MI the times and energies are to (the endpoint's target)")
    time_to_target_s: Mapping[str, float] | None = opt("s", "rpm -> twin time to the target MI (NaN: not reached)")
    power_w: Mapping[str, float] | None = opt("W", "rpm -> drive power on the plateau, whole drum (sim.power)")
    energy_to_target_j: Mapping[str, float] | None = opt("J", "rpm -> drive energy to the target MI")


@register
@dataclass(frozen=True, kw_only=True)
class WhatIfError(Record):
    kind: ClassVar[str] = "whatif_error"
    doc: ClassVar[str] = "a what-if study failed"
    producer: ClassVar[str] = "twin.live.whatif"
    reason: str = unit("", "AUTO | operator")
    error: str = unit("", "why")


@register
@dataclass(frozen=True, kw_only=True)
class WhatIfCancelled(Record):
    kind: ClassVar[str] = "whatif_cancelled"
    doc: ClassVar[str] = "the operator cancelled a study"
    producer: ClassVar[str] = "twin.live.whatif"
    reason: str = unit("", "AUTO | operator")


# -- dashboard security -----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class DashboardEvent(Record):
    """A dashboard security event (the fields each kind may carry)."""

    producer: ClassVar[str] = "twin.dashboard"
    client: int | None = opt("", "viser client id")
    address: str | None = opt("", "client address")
    origin: str | None = opt("", "Origin header")
    host: str | None = opt("", "Host header")
    wait_s: float | None = opt("s", "wait before the next unlock attempt")
    error: str | None = opt("", "what was wrong")
    suppressed: int | None = opt("", "throttled events not written since the last one")
    summary: bool | None = opt("", "a count of suppressed events only")


@register
@dataclass(frozen=True, kw_only=True)
class DashboardRefused(DashboardEvent):
    kind: ClassVar[str] = "dashboard_refused"
    doc: ClassVar[str] = "a connection refused (origin or host)"


@register
@dataclass(frozen=True, kw_only=True)
class DashboardUnlockLimited(DashboardEvent):
    kind: ClassVar[str] = "dashboard_unlock_limited"
    doc: ClassVar[str] = "too many unlock attempts"


@register
@dataclass(frozen=True, kw_only=True)
class DashboardUnlockFailed(DashboardEvent):
    kind: ClassVar[str] = "dashboard_unlock_failed"
    doc: ClassVar[str] = "a wrong control token"


@register
@dataclass(frozen=True, kw_only=True)
class DashboardUnlocked(DashboardEvent):
    kind: ClassVar[str] = "dashboard_unlocked"
    doc: ClassVar[str] = "a viewer unlocked the controls"


@register
@dataclass(frozen=True, kw_only=True)
class DashboardBadMessage(DashboardEvent):
    kind: ClassVar[str] = "dashboard_bad_message"
    doc: ClassVar[str] = "a malformed or oversized client message"


# -- dashboard-only status (neither CSV nor JSONL) --------------------------------------------
@dataclass(frozen=True, kw_only=True)
class _Status(Record):
    logged: ClassVar[bool] = False


@register
@dataclass(frozen=True, kw_only=True)
class CameraRate(_Status):
    kind: ClassVar[str] = "camera_rate"
    doc: ClassVar[str] = "the camera's frame rate (with each frame)"
    fps: float = unit("1/s", "camera frames per wall second")


@register
@dataclass(frozen=True, kw_only=True)
class MillState(_Status):
    kind: ClassVar[str] = "mill_state"
    doc: ClassVar[str] = "the mill as last polled"
    state: str = unit("", "connecting | link lost | fault X | running | stopped")
    connected: bool = unit("", "the link is up and the board was read")
    setpoint_rpm: float | None = unit("rpm", "board setpoint (None: unknown)")
    actual_rpm: float | None = unit("rpm", "board actual speed (None: unknown)")


@register
@dataclass(frozen=True, kw_only=True)
class ModeSet(_Status):
    kind: ClassVar[str] = "mode"
    doc: ClassVar[str] = "the supervisor's mode now"
    mode: str = unit("", "off | manual | auto")


@register
@dataclass(frozen=True, kw_only=True)
class TwinStatus(_Status):
    kind: ClassVar[str] = "twin_status"
    doc: ClassVar[str] = "the twin's state in words"
    state: str = unit("", "running | running, calibrating | running (uncalibrated)")


@register
@dataclass(frozen=True, kw_only=True)
class TwinReading(_Status):
    kind: ClassVar[str] = "twin_reading"
    doc: ClassVar[str] = "the twin's newest rendered frame, measured"
    mi: float = unit("", "twin MI")
    slope_deg: float = unit("deg", "twin slope")
    fps: float = unit("1/s", "twin frames per wall second")


# -- building, encoding -----------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class UntypedEvent(Record):
    """A JSONL event read back whose kind or fields no class here declares (a log of another
    release). It holds the line as it came, so no data is lost (and is written back whole)."""

    name: str = unit("", "the unregistered kind")
    data: Mapping[str, object] = unit("", "its fields")


def record_of(kind: str, t_s: float, **data: object) -> Record:
    """The record of ``kind`` built from ``data``: the name -> class lookup of the JSONL reader
    (``twin.runlog.read_records``; producers construct their record classes, so a misspelt kind
    or field is a type error). A kind not registered, or fields its class does not declare,
    give an :class:`UntypedEvent` and a warning: reading never crashes and never loses data."""
    cls = KINDS.get(kind)
    if cls is not None:
        try:
            return cls(t_s=float(t_s), **data)
        except TypeError as exc:
            log.warning("event %s does not fit its record: %s", kind, exc)
    else:
        log.warning("event kind %s is not a registered record kind (twin/records.py)", kind)
    return UntypedEvent(t_s=float(t_s), name=kind, data=dict(data))


def kind_of(rec: Record) -> str:
    return rec.name if isinstance(rec, UntypedEvent) else rec.kind


def event_fields(rec: Record) -> dict[str, object]:
    """The JSONL payload of ``rec`` (beside ``t_s``, ``wall_s``, ``kind``): its fields, the
    optional ones only when set."""
    if isinstance(rec, UntypedEvent):
        return dict(rec.data)
    out: dict[str, object] = {}
    for f in fields(rec):
        if f.name == "t_s":
            continue
        v = getattr(rec, f.name)
        if v is None and f.metadata.get("optional"):
            continue
        out[f.name] = v
    return out


# -- the bus ----------------------------------------------------------------------------------
Subscriber = Callable[[Record], None]


class Bus:
    """Publish/subscribe of run records: ``publish`` hands each record to every subscriber in
    the order they subscribed, synchronously on the publisher's thread (subscribers are
    thread-safe and quick: a lock and an append)."""

    def __init__(self) -> None:
        self._subs: tuple[Subscriber, ...] = ()
        self._lock = threading.Lock()

    def subscribe(self, fn: Subscriber) -> None:
        with self._lock:
            self._subs = (*self._subs, fn)

    def publish(self, rec: Record) -> None:
        for fn in self._subs:
            fn(rec)


# -- the one set of active faults -------------------------------------------------------------
class ActiveFaults:
    """The run's active faults, key -> message (the one place they are kept): the event sink
    raises a fault only when it is not active and clears it only when it is; the dashboard
    shows the messages as alarms. A fault raised with ``shown=False`` is active at once but
    shown only from :meth:`show` on (the sink shows it once its event is logged, as the run
    always did). Thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._active: dict[str, tuple[str, bool]] = {}  # key -> (message, shown)

    def raise_fault(self, key: str, message: str, shown: bool = True) -> bool:
        """True when ``key`` was not active (it is now)."""
        with self._lock:
            if key in self._active:
                return False
            self._active[key] = (message, shown)
            return True

    def show(self, key: str) -> None:
        """Show an active fault raised with ``shown=False``."""
        with self._lock:
            if key in self._active:
                self._active[key] = (self._active[key][0], True)

    def clear(self, key: str) -> bool:
        """True when ``key`` was active (it is not now)."""
        with self._lock:
            return self._active.pop(key, None) is not None

    def keys(self) -> frozenset[str]:
        with self._lock:
            return frozenset(self._active)

    def messages(self) -> tuple[str, ...]:
        with self._lock:
            return tuple(m for m, shown in self._active.values() if shown)


# -- the docs table ---------------------------------------------------------------------------
def _type_name(f: Field[Any]) -> str:
    t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    return t.replace("|", "\\|")


def records_table() -> str:
    """The Markdown table of every record kind, its fields and their units (the one in
    ``docs/architecture.md``; ``python -m twin.records`` prints it)."""
    lines = ["| kind | goes to | fields (unit) |", "|---|---|---|"]
    for kind, cls in KINDS.items():
        where = "frames.csv" if cls is FrameReading else "events.jsonl" if cls.logged else "dashboard"
        parts = []
        for f in fields(cls):
            u = f.metadata.get("unit", "")
            name = f"{f.name}?" if f.metadata.get("optional") else f.name
            parts.append(f"`{name}`" + (f" ({u})" if u else ""))
        lines.append(f"| `{kind}` | {where}: {cls.doc} | {', '.join(parts)} |")
    return "\n".join(lines) + "\n"


def fields_of(cls: type[Record]) -> Mapping[str, str]:
    """Field name -> unit of a record class."""
    return {f.name: str(f.metadata.get("unit", "")) for f in fields(cls)}


if __name__ == "__main__":
    print(records_table(), end="")

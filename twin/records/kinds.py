"""Every run record kind but the frame reading, by concern: the run's start and stop, faults,
the operator, the supervisor's decisions, the mill link, the trend, the batch endpoint, the run
catalogue and the golden batch, the twin, the what-if studies, the dashboard's security events
and the dashboard-only status. One module on purpose: the kinds are declared alike (a frozen
dataclass, ``kind``, ``doc``, ``producer``, fields), and in one place they read as one table;
the order here is the registry's (the docs' table, the descriptors)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from twin.records.declare import Record, opt, register, unit

if TYPE_CHECKING:
    from control.supervisor import Decision


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
    end_friction: float | None = opt("", "the end plates' friction (a monolayer's is calibrated; sim.calibrate)")
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

"""What goes into one supervisor step and what comes out of it (pure data, no I/O).

``control.supervisor.Supervisor.step(now_s, SupervisorInputs, PredictionResult | None)``
returns a ``StepResult``: a :class:`Decision` (what to do, why, on which inputs: the run
log's ``decision`` record) and a :class:`PredictionRequest` (twin predictions the
application computes in the background and hands in on a later step as a
:class:`PredictionResult`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from control.objective import RpmPrediction
from control.trend import TrendEstimate


class Mode(StrEnum):
    OFF = "off"
    MANUAL = "manual"
    AUTO = "auto"


class Action(StrEnum):
    """What the application should do with a decision."""

    NONE = "none"  #: nothing to send (mode change, hold, recovery): log it
    SET_RPM = "set_rpm"  #: send ``Decision.rpm`` as the new setpoint
    STOP = "stop"  #: stop the motor



@dataclass(frozen=True)
class SupervisorInputs:
    """What the supervisor sees each step.

    ``trend``: the latest Kalman estimate; ``actual_rpm``/``setpoint_rpm``/``mill_running``:
    from the mill status; ``mill_connected``: the link is up; ``mill_epoch``: changes each
    time the board was (re)read after a link loss or a refusal (the supervisor resyncs);
    ``mill_refused``: commands the mill refused so far (growing: a fault for one step);
    ``radial_factor``: MI(eq. 4)/MI(eq. 3) of the latest valid reading (None: not used);
    ``last_valid_mi_s``: time of the last valid MI; ``camera_ended``: the frame source has
    ended (vision is lost now, no timeout); ``twin_updated_s``: time the twin last synced
    (None: no twin); ``twin_doubt``: why the application does not trust the twin now (it
    disagrees with the camera, its what-if study failed; "" = trusted): AUTO treats a
    twin in doubt as stale (safe state) until it is trusted again. ``mixed``: the batch is
    at its endpoint (``control.endpoint``), mixed since ``mixing_time_s``.
    """

    trend: TrendEstimate | None = None
    actual_rpm: float | None = None
    setpoint_rpm: float | None = None
    mill_connected: bool = True
    mill_running: bool | None = None
    mill_epoch: int = 0
    mill_refused: int = 0
    radial_factor: float | None = None
    last_valid_mi_s: float | None = None
    camera_ended: bool = False
    twin_updated_s: float | None = None
    twin_doubt: str = ""
    mixed: bool = False
    mixing_time_s: float | None = None


@dataclass(frozen=True)
class PredictionRequest:
    """Predictions wanted at ``t_s``: MI after ``horizon_s`` for each of ``rpms``
    (``target_mi``: also the time and energy to reach it, for the "time"/"energy" objectives;
    ``ramp_rpm_s``: the rate the rpm will be ramped at, so the twin ramps as the mill will;
    ``from_bed``: start from the bed the camera shows now, not from the running twin's state:
    a time to the target counts from the start state, and a twin that drifted from the plant
    predicts the time from another bed)."""

    t_s: float
    rpms: tuple[float, ...]
    horizon_s: float
    target_mi: float | None = None
    ramp_rpm_s: float | None = None
    from_bed: bool = False


@dataclass(frozen=True)
class PredictionResult:
    """Predicted MI after ``horizon_s`` per rpm, for the request made at ``t_s``; ``rows``:
    per rpm the time and energy to the target too (None: the study gave only MI)."""

    t_s: float
    horizon_s: float
    predictions: Mapping[float, float]
    rows: Mapping[float, RpmPrediction] | None = None


@dataclass(frozen=True)
class Decision:
    """One supervisor event: when, in which mode, what to do, why, and on what inputs.

    ``kind``: ``mode`` | ``manual`` | ``move`` | ``ramp`` | ``hold`` | ``safe`` |
    ``recover``; ``rpm``: the setpoint to send now (``SET_RPM``); ``target_rpm``: where a
    ramp is heading; ``scores``: candidate rpm -> score when predictions were used;
    ``chosen``: the "time"/"energy" row of the rpm picked (its predicted time s and energy J to
    the target) and ``prediction_t_s`` when the study it came from was asked (run s).
    """

    t_s: float
    mode: Mode
    action: Action
    kind: str
    reason: str
    rpm: float | None = None
    target_rpm: float | None = None
    safe: bool = False
    inputs: SupervisorInputs | None = None
    predictions: Mapping[float, float] | None = None
    scores: Mapping[float, float] | None = None
    chosen: RpmPrediction | None = None
    prediction_t_s: float | None = None

    def as_dict(self) -> dict[str, object]:
        """JSON-ready record (for run logs): the decision and the inputs it was made on."""
        inp = self.inputs
        tr = inp.trend if inp is not None else None
        return {
            "t_s": self.t_s,
            "mode": self.mode.value,
            "action": self.action.value,
            "kind": self.kind,
            "reason": self.reason,
            "rpm": self.rpm,
            "target_rpm": self.target_rpm,
            "safe": self.safe,
            "level": None if tr is None else tr.level,
            "rate": None if tr is None else tr.rate,
            "predictions": None if self.predictions is None else {str(k): v for k, v in self.predictions.items()},
            "predicted_time_to_target_s": None if self.chosen is None else self.chosen.time_to_target_s,
            "predicted_energy_j": None if self.chosen is None else self.chosen.energy_j,
            "prediction_t_s": self.prediction_t_s,
            "inputs": None
            if inp is None
            else {
                "level": None if tr is None else tr.level,
                "rate": None if tr is None else tr.rate,
                "level_sd": None if tr is None else tr.level_sd,
                "trend_settled": None if tr is None else tr.settled,
                "actual_rpm": inp.actual_rpm,
                "setpoint_rpm": inp.setpoint_rpm,
                "mill_connected": inp.mill_connected,
                "mill_running": inp.mill_running,
                "mill_epoch": inp.mill_epoch,
                "mill_refused": inp.mill_refused,
                "camera_ended": inp.camera_ended,
                "radial_factor": inp.radial_factor,
                "last_valid_mi_s": inp.last_valid_mi_s,
                "twin_updated_s": inp.twin_updated_s,
                "twin_doubt": inp.twin_doubt,
                "mixed": inp.mixed,
                "mixing_time_s": inp.mixing_time_s,
            },
        }


__all__ = ["Action", "Decision", "Mode", "PredictionRequest", "PredictionResult", "SupervisorInputs"]

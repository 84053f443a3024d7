"""Supervisory rpm controller: segregation detection, AUTO rpm choice, limits, safe state.

The :class:`Supervisor` is a pure state machine:
``step(now_s, inputs, predictions=None) -> StepResult(decision, request)``. It never does
I/O, never blocks and never calls out. ``decision`` is a :class:`Decision` (an event with
time, inputs, action and reason) when it wants something done, else ``None``; every
decision is also kept in ``events``. ``request`` is a :class:`PredictionRequest` when it
wants twin predictions: the application computes them (in the background, however it
likes) and hands them in as ``predictions`` on a later step. That is the only way
predictions get in.

Modes
    ``OFF``: hands off, no commands. ``MANUAL``: follows the operator's rpm
    (``set_manual_rpm``) inside the limits; watches only the mill link. ``AUTO``: picks
    the rpm itself when the mix segregates; watches mill link, vision and twin.

Segregation detection (on the Kalman trend and the radial factor)
    *bad* when ``level < seg_level`` or ``rate < seg_rate_per_s`` (falling faster) or
    ``radial_factor < radial_min`` (``radial_factor`` = the std-weighting factor of eq. 4,
    i.e. MI(eq. 4) / MI(eq. 3)); *good* when ``level > clear_level`` and
    ``rate > seg_rate_per_s / 2`` and the radial factor is above ``radial_clear``
    (hysteresis). The state turns *segregated* after ``detect_dwell_s`` of continuous
    bad, and *mixed* again after ``clear_dwell_s`` of continuous good.

Settled trend
    Detection and AUTO act only on a settled trend (``TrendEstimate.settled``: enough
    accepted frames since the start or the last re-initialisation and a narrow enough
    band, see ``control.trend``). While it is unsettled the detector's dwell does not run
    (and restarts once settled) and AUTO neither asks for predictions nor moves; the
    application logs the unsettled state (``trend_unsettled``/``trend_settled`` events).

AUTO rpm choice
    With predictions (``Mapping[rpm, predicted MI at now + horizon]``, no older than
    ``prediction_max_age_s``): ``score(r) = MI(r) - move_penalty_per_rpm * |r - current|``
    over the candidates inside the limits; move to the best when it beats staying by
    ``min_gain``, else log a *hold* decision. Without predictions (the request made when
    the decision fell due was not answered within ``prediction_wait_s``), the
    **fallback rule**: step the rpm up by ``fallback_step_rpm`` (size segregation in
    the rolling regime is broken up by a faster, more energetic cascade), clipped to the
    upper limit; at the upper limit, step down by ``fallback_step_rpm`` instead.
    Evaluations are at least ``min_change_interval_s`` apart (also the minimum dwell
    between rpm changes).

Objective and endpoint (issue 24, ``control.objective``, ``control.endpoint``)
    ``objective`` "plateau" (the default) is the scoring above. "time" / "energy": the
    predictions carry per-rpm rows (``PredictionResult.rows``: time to ``target_mi`` and
    drive energy to it) and ``control.objective.choose`` picks the rpm that reaches the
    target soonest / with least energy (rows missing: the plateau scoring, said in the
    reason); a decision is then also due while the trend is below ``target_mi`` and the
    batch is not mixed. A study whose twin bed was at the target at once (a 0 s row) while the
    trend is below it or the bed segregated (``control.objective.stale_start``) is asked again once (a *hold*
    decision says so). The request carries ``max_rate_rpm_per_s`` so the twin ramps as the mill.
    ``stop_at_endpoint``: in AUTO, once the application reports the
    batch mixed (``inputs.mixed``, from ``control.endpoint``), one ``endpoint`` decision
    stops the mill (its reason names the mixing time) and AUTO then holds hands off until
    a mode is set again. OFF and MANUAL never act on the endpoint (the application
    reports it).

Limits
    Every commanded rpm is inside ``[min_rpm, min(max_rpm, max_critical_frac * n_c)]``
    with ``n_c`` = ``critical_rpm``, the drum's critical speed, handed in by the
    application (``sim.recipe.DrumSpec.critical_rpm`` is the one formula; ``None``: only
    ``max_rpm`` limits). The setpoint moves
    at most ``max_rate_rpm_per_s`` (ramped in steps every ``ramp_interval_s``, each one a
    ``ramp`` decision); a ramp from a board found outside the limits (started from its
    front panel) steps inside them at once; a board found above them in MANUAL or AUTO (at
    a resync) is brought down to the upper limit that way, even before any decision.

Board resync
    ``inputs.mill_epoch`` changes whenever the application has (re)read the board after a
    link loss or a refused command: the supervisor then takes the board's state as its
    own (``commanded_rpm`` = the board's actual rpm while running, else its setpoint), so
    a ramp goes on from where the motor really is, never from a stale belief.

Safe state
    Mill link lost (``inputs.mill_connected`` False), a command the mill refused
    (``inputs.mill_refused`` grew since the last step), the camera ended, no valid MI for
    ``vision_timeout_s`` (the one vision timeout: applications raise their own alarm with
    :meth:`SupervisorConfig.vision_lost`) or the twin not updated for ``twin_timeout_s``
    (AUTO) -> ``safe_action``: ``HOLD``
    (keep the setpoint, the device watchdog covers a dead link), ``RAMP`` (ramp to
    ``safe_rpm``) or ``STOP``. HOLD/RAMP recover by themselves after ``recover_s`` without
    faults; STOP is latched until the operator sets a mode again.

"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

from control.errors import ControlError
from control.limits import Limits
from control.objective import RpmPrediction, check_objective, choose, stale_start
from control.trend import TrendEstimate


class Mode(StrEnum):
    OFF = "off"
    MANUAL = "manual"
    AUTO = "auto"


class SafeAction(StrEnum):
    HOLD = "hold"
    RAMP = "ramp"
    STOP = "stop"


class Action(StrEnum):
    """What the application should do with a decision."""

    NONE = "none"  #: nothing to send (mode change, hold, recovery): log it
    SET_RPM = "set_rpm"  #: send ``Decision.rpm`` as the new setpoint
    STOP = "stop"  #: stop the motor


@dataclass(frozen=True)
class SupervisorConfig:
    """Limits, detection thresholds, AUTO tuning and safe-state policy (units in names)."""

    # limits
    min_rpm: float = 2.0
    max_rpm: float = 45.0
    critical_rpm: float | None = None  # the drum's critical speed (rpm), from the application
    max_critical_frac: float = 0.6
    max_rate_rpm_per_s: float = 2.0
    ramp_interval_s: float = 1.0
    min_change_interval_s: float = 30.0
    # segregation detection (MI units; rate in MI/s)
    seg_level: float = 0.5
    clear_level: float = 0.6
    seg_rate_per_s: float = -0.01
    radial_min: float = 0.5
    radial_clear: float = 0.6
    detect_dwell_s: float = 5.0
    clear_dwell_s: float = 5.0
    # AUTO
    n_candidates: int = 7
    horizon_s: float = 60.0
    move_penalty_per_rpm: float = 0.002
    min_gain: float = 0.02
    prediction_max_age_s: float = 30.0
    prediction_wait_s: float = 20.0
    fallback_step_rpm: float = 5.0
    # objective and endpoint (issue 24)
    objective: str = "plateau"  # plateau | time | energy (control.objective)
    target_mi: float | None = None  # the target of "time"/"energy" (None: the endpoint's, from the application)
    objective_min_rel_gain: float = 0.1  # "time"/"energy": move when the best saves this share vs staying
    stop_at_endpoint: bool = False  # AUTO stops the mill once the batch is mixed
    # safe state
    safe_action: SafeAction = SafeAction.HOLD
    safe_rpm: float = 5.0
    vision_timeout_s: float = 5.0
    twin_timeout_s: float | None = 60.0
    require_twin: bool = False
    recover_s: float = 5.0

    def __post_init__(self) -> None:
        self.limits  # noqa: B018 -- validates the rpm limits (control.limits: the one set)
        if not (math.isfinite(self.vision_timeout_s) and self.vision_timeout_s > 0):
            raise ControlError(f"vision_timeout_s must be > 0, got {self.vision_timeout_s}")
        if self.clear_level < self.seg_level:
            raise ControlError("clear_level must be >= seg_level (hysteresis)")
        check_objective(self.objective)
        if self.target_mi is not None and not (math.isfinite(self.target_mi) and 0.0 <= self.target_mi <= 1.0):
            raise ControlError(f"target_mi must be in [0, 1], got {self.target_mi}")
        if self.objective != "plateau" and self.target_mi is None:
            raise ControlError(f"objective {self.objective} needs a target_mi")

    @property
    def limits(self) -> Limits:
        """The one set of rpm limits (``control.limits``) these settings describe."""
        return Limits(self.min_rpm, self.max_rpm, self.critical_rpm, self.max_critical_frac, self.max_rate_rpm_per_s)

    @property
    def rpm_limits(self) -> tuple[float, float]:
        """(lowest, highest) rpm the supervisor will ever command."""
        return self.limits.rpm_range

    def vision_lost(self, now_s: float, last_valid_mi_s: float | None) -> bool:
        """True when no valid MI has been seen for more than ``vision_timeout_s`` (the one
        vision timeout of supervisor and application; None = never seen: not lost yet)."""
        return last_valid_mi_s is not None and now_s - last_valid_mi_s > self.vision_timeout_s

    def clamp(self, rpm: float) -> float:
        return self.limits.clamp(rpm)

    def candidates(self, current: float | None = None) -> tuple[float, ...]:
        """Evenly spaced candidate rpms over the limits (plus ``current``), rounded to 0.1."""
        lo, hi = self.rpm_limits
        n = max(2, self.n_candidates)
        c = {round(lo + (hi - lo) * i / (n - 1), 1) for i in range(n)}
        if current is not None:
            c.add(round(self.clamp(current), 1))
        return tuple(sorted(c))


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


class SegregationDetector:
    """Bad/good conditions with hysteresis and dwell (see module docstring)."""

    def __init__(self, config: SupervisorConfig) -> None:
        self.config = config
        self.segregated = False
        self._since: float | None = None  # start of the current opposite-condition stretch
        self.why = ""

    def reset(self) -> None:
        self.segregated = False
        self._since = None
        self.why = ""

    def bad_reasons(self, trend: TrendEstimate, radial: float | None) -> list[str]:
        c, r = self.config, []
        if trend.level < c.seg_level:
            r.append(f"MI {trend.level:.3f} < {c.seg_level}")
        if trend.rate < c.seg_rate_per_s:
            r.append(f"MI falling {trend.rate:+.4f}/s < {c.seg_rate_per_s}/s")
        if radial is not None and math.isfinite(radial) and radial < c.radial_min:
            r.append(f"radial factor {radial:.3f} < {c.radial_min}")
        return r

    def is_good(self, trend: TrendEstimate, radial: float | None) -> bool:
        c = self.config
        ok = trend.level > c.clear_level and trend.rate > c.seg_rate_per_s / 2
        if radial is not None and math.isfinite(radial):
            ok = ok and radial > c.radial_clear
        return ok

    def update(self, now_s: float, trend: TrendEstimate | None, radial: float | None) -> bool:
        """Advance; returns True when the state changed this step."""
        if trend is None or not trend.valid or not trend.settled:  # decide nothing on an unsettled trend
            self._since = None
            return False
        if not self.segregated:
            bad = self.bad_reasons(trend, radial)
            if not bad:
                self._since = None
                return False
            self._since = now_s if self._since is None else self._since
            if now_s - self._since >= self.config.detect_dwell_s:
                self.segregated, self._since, self.why = True, None, "; ".join(bad)
                return True
            return False
        if not self.is_good(trend, radial):
            self._since = None
            return False
        self._since = now_s if self._since is None else self._since
        if now_s - self._since >= self.config.clear_dwell_s:
            self.segregated, self._since, self.why = False, None, ""
            return True
        return False

    @property
    def suspect(self) -> bool:
        """Bad conditions seen but the dwell not over yet."""
        return not self.segregated and self._since is not None


class StepResult(NamedTuple):
    """What one :meth:`Supervisor.step` gives back: a decision to carry out (or None) and
    predictions it wants computed (or None)."""

    decision: Decision | None
    request: PredictionRequest | None


class Supervisor:
    """The supervisory controller (see the module docstring for the rules)."""

    def __init__(
        self,
        config: SupervisorConfig | None = None,
        mode: Mode = Mode.OFF,
        max_events: int = 10000,
    ) -> None:
        self.config = config or SupervisorConfig()
        self._mode = Mode(mode)
        self.detector = SegregationDetector(self.config)
        self.events: deque[Decision] = deque(maxlen=max_events)
        self.commanded_rpm: float | None = None  # last setpoint sent (or read from the mill)
        self.target_rpm: float | None = None  # where the ramp is heading
        self.manual_rpm: float | None = None
        self.safe = False
        self.safe_reason = ""
        self._latched_stop = False
        self._endpoint_stopped = False  # AUTO stopped the mill at the endpoint: hands off until a mode is set
        self._t0: float | None = None
        self._epoch: int | None = None  # the board state last synced to
        self._refused = 0  # the mill's refusals seen so far
        self._last_cmd_s = -math.inf
        self._last_eval_s = -math.inf
        self._due_since: float | None = None  # AUTO decision due, waiting for predictions
        self._restudy_t: float | None = None  # a stale "time"/"energy" study was asked again at this time
        self._clear_since: float | None = None
        self._predictions: PredictionResult | None = None
        self._last_inputs: SupervisorInputs | None = None
        self._request: PredictionRequest | None = None  # wanted by the current step

    # -- operator ----------------------------------------------------------------------------
    @property
    def mode(self) -> Mode:
        return self._mode

    def set_mode(self, mode: Mode | str, now_s: float, reason: str = "operator") -> Decision:
        """Change mode (also re-arms after a latched safe stop); returns the mode event."""
        try:
            new = Mode(mode)
        except ValueError:
            raise ControlError(f"unknown mode {mode!r} (use off, manual, auto)") from None
        old, self._mode = self._mode, new
        self.detector.reset()
        self.safe, self.safe_reason, self._latched_stop = False, "", False
        self._endpoint_stopped = False
        self._clear_since = self._due_since = self._restudy_t = None
        self.target_rpm = self.commanded_rpm
        lo, hi = self.config.rpm_limits
        if new is Mode.MANUAL and self.manual_rpm is None and self.commanded_rpm is not None \
                and lo <= self.commanded_rpm <= hi:
            self.manual_rpm = self.commanded_rpm  # a board outside the limits: no operator rpm until one is given
        return self._emit(now_s, Action.NONE, "mode", f"mode {old.value} -> {new.value} ({reason})")

    def set_manual_rpm(self, rpm: float) -> float:
        """Operator rpm for MANUAL, clamped into the limits; returns the clamped value."""
        rpm = float(rpm)
        if not math.isfinite(rpm):
            raise ControlError(f"manual rpm must be a number, got {rpm}")
        self.manual_rpm = self.config.clamp(rpm)
        return self.manual_rpm

    # -- predictions -------------------------------------------------------------------------
    def _take_predictions(self, result: PredictionResult | None) -> None:
        if result is not None and (self._predictions is None or result.t_s >= self._predictions.t_s):
            self._predictions = result

    def fresh_predictions(self, now_s: float) -> PredictionResult | None:
        """The latest predictions handed in, unless older than ``prediction_max_age_s``."""
        p = self._predictions
        if p is None or now_s - p.t_s > self.config.prediction_max_age_s:
            return None
        return p

    # -- the step ----------------------------------------------------------------------------
    def step(
        self, now_s: float, inputs: SupervisorInputs, predictions: PredictionResult | None = None
    ) -> StepResult:
        """Advance to ``now_s`` with ``inputs`` (and any ``predictions`` that arrived since
        the last step); see :class:`StepResult`."""
        self._request = None
        decision = self._step(now_s, inputs, predictions)
        return StepResult(decision, self._request)

    def _step(self, now_s: float, inputs: SupervisorInputs, predictions: PredictionResult | None) -> Decision | None:
        if self._t0 is None:
            self._t0 = now_s
        self._last_inputs = inputs
        if inputs.mill_connected and inputs.mill_epoch != self._epoch:
            self._resync(inputs)
        refused, self._refused = inputs.mill_refused > self._refused, inputs.mill_refused
        self._take_predictions(predictions)
        if self._mode is Mode.OFF:
            return None
        self.detector.update(now_s, inputs.trend, inputs.radial_factor)
        if self._mode is Mode.AUTO and self.config.stop_at_endpoint and (inputs.mixed or self._endpoint_stopped):
            return self._endpoint_stop(now_s, inputs)

        faults = self.faults(now_s, inputs)
        if refused:
            faults.append("the mill refused a command")
        if faults:
            self._clear_since = None
            if not self.safe:
                return self._enter_safe(now_s, "; ".join(faults))
            return self._ramp_step(now_s, "safe")
        if self.safe:
            if self._latched_stop:
                return None
            self._clear_since = now_s if self._clear_since is None else self._clear_since
            if now_s - self._clear_since >= self.config.recover_s:
                self.safe, self._clear_since = False, None
                self.target_rpm = self.commanded_rpm
                why, self.safe_reason = self.safe_reason, ""
                self.detector.reset()
                why_txt = f"faults cleared for {self.config.recover_s:g} s (was: {why})"
                return self._emit(now_s, Action.NONE, "recover", why_txt)
            return self._ramp_step(now_s, "safe")

        if self._mode is Mode.MANUAL:
            return self._manual(now_s)
        ramp = self._ramp_step(now_s, "ramp")
        if ramp is not None or self._ramping:
            return ramp
        return self._auto(now_s, inputs)

    def _resync(self, inputs: SupervisorInputs) -> None:
        """Take the board's state as ours (see "Board resync" in the module doc)."""
        first = inputs.actual_rpm if inputs.mill_running else inputs.setpoint_rpm
        if first is None:
            first = inputs.setpoint_rpm if inputs.setpoint_rpm is not None else inputs.actual_rpm
        board = first
        if board is None or not math.isfinite(board):
            return
        self._epoch = inputs.mill_epoch
        ramping = self._ramping
        self.commanded_rpm = round(float(board), 2)
        if not ramping or self.safe:
            self.target_rpm = self.commanded_rpm
        lo, hi = self.config.rpm_limits
        if self._mode is not Mode.OFF and self.commanded_rpm > hi:  # found above the limits (another host,
            self.target_rpm = hi  # the front panel): this run controls it, so it is brought inside at once
        if self.manual_rpm is None and self._mode is Mode.MANUAL and lo <= self.commanded_rpm <= hi:
            self.manual_rpm = self.commanded_rpm  # (a board outside the limits: no operator rpm until one is given)

    # -- internals ---------------------------------------------------------------------------
    def faults(self, now_s: float, inputs: SupervisorInputs) -> list[str]:
        """Reasons for the safe state now (empty: none)."""
        c, out = self.config, []
        if not inputs.mill_connected:
            out.append("mill link lost")
        if self._mode is Mode.AUTO:
            t0 = self._t0 if self._t0 is not None else now_s
            seen = inputs.last_valid_mi_s if inputs.last_valid_mi_s is not None else t0
            if inputs.camera_ended:
                out.append("camera ended: no valid MI")
            elif c.vision_lost(now_s, seen):
                out.append(f"no valid MI for {now_s - seen:.1f} s")
            if c.twin_timeout_s is not None and (inputs.twin_updated_s is not None or c.require_twin):
                tw = inputs.twin_updated_s if inputs.twin_updated_s is not None else t0
                if now_s - tw > c.twin_timeout_s:
                    out.append(f"twin stale for {now_s - tw:.1f} s")
            if inputs.twin_doubt:  # the application does not trust the twin: stale too
                out.append(f"twin stale: {inputs.twin_doubt}")
        return out

    @property
    def _ramping(self) -> bool:
        return (
            self.target_rpm is not None
            and self.commanded_rpm is not None
            and abs(self.target_rpm - self.commanded_rpm) > 1e-6
        )

    def _emit(self, now_s: float, action: Action, kind: str, reason: str, **kw: object) -> Decision:
        d = Decision(now_s, self._mode, action, kind, reason, safe=self.safe, inputs=self._last_inputs, **kw)  # type: ignore[arg-type]
        self.events.append(d)
        return d

    def _enter_safe(self, now_s: float, why: str) -> Decision:
        c = self.config
        self.safe, self.safe_reason = True, why
        self._due_since = None
        if c.safe_action is SafeAction.STOP:
            self._latched_stop = True
            self.target_rpm = self.commanded_rpm
            return self._emit(now_s, Action.STOP, "safe", f"safe stop: {why}")
        if c.safe_action is SafeAction.RAMP and self.commanded_rpm is not None:
            self.target_rpm = c.clamp(c.safe_rpm)
            first = self._next_setpoint(now_s)
            return self._emit(
                now_s,
                Action.SET_RPM if first is not None else Action.NONE,
                "safe",
                f"safe ramp to {self.target_rpm:g} rpm: {why}",
                rpm=first,
                target_rpm=self.target_rpm,
            )
        self.target_rpm = self.commanded_rpm
        return self._emit(now_s, Action.NONE, "safe", f"safe hold at {self.commanded_rpm} rpm: {why}", rpm=None)

    def _next_setpoint(self, now_s: float) -> float | None:
        """Advance the rate-limited setpoint toward ``target_rpm`` when a step is due."""
        if not self._ramping or (self.safe and self._latched_stop):
            return None
        c = self.config
        if now_s - self._last_cmd_s < c.ramp_interval_s - 1e-9:
            return None
        assert self.target_rpm is not None and self.commanded_rpm is not None
        diff = self.target_rpm - self.commanded_rpm
        max_d = c.max_rate_rpm_per_s * c.ramp_interval_s if c.max_rate_rpm_per_s > 0 else abs(diff)
        nxt = round(self.commanded_rpm + max(-max_d, min(max_d, diff)), 2)
        if abs(self.target_rpm - nxt) < 0.01:
            nxt = self.target_rpm
        # a board found outside the limits (front panel): the first step goes inside them at once
        nxt = c.clamp(nxt)
        self.commanded_rpm, self._last_cmd_s = nxt, now_s
        return nxt

    def _ramp_step(self, now_s: float, kind: str) -> Decision | None:
        """The next ramp step as a decision of ``kind``, when one is due."""
        nxt = self._next_setpoint(now_s)
        if nxt is None:
            return None
        c = self.config
        return self._emit(
            now_s, Action.SET_RPM, kind,
            f"ramp {nxt:g} rpm toward {self.target_rpm:g} (<= {c.max_rate_rpm_per_s:g} rpm/s)",
            rpm=nxt, target_rpm=self.target_rpm,
        )

    def _start_move(self, now_s: float, target: float, kind: str, reason: str, **kw: object) -> Decision:
        self.target_rpm = target
        self._last_eval_s = now_s
        if self.commanded_rpm is None:  # nothing known about the mill: jump
            self.commanded_rpm, self._last_cmd_s = target, now_s
            return self._emit(now_s, Action.SET_RPM, kind, reason, rpm=target, target_rpm=target, **kw)
        nxt = self._next_setpoint(now_s)  # None: a ramp step was sent < ramp_interval_s ago
        action = Action.SET_RPM if nxt is not None else Action.NONE
        return self._emit(now_s, action, kind, reason, rpm=nxt, target_rpm=target, **kw)

    def _manual(self, now_s: float) -> Decision | None:
        """Follow the operator's rpm; a new one re-targets a ramp in progress at once. No
        operator rpm yet: only the ramp of a board found above the limits (brought down)."""
        m = self.manual_rpm
        if m is None:
            return self._ramp_step(now_s, "ramp")
        if self.target_rpm is None or abs(m - self.target_rpm) > 1e-6:
            return self._start_move(now_s, m, "manual", f"operator rpm {m:g}")
        return self._ramp_step(now_s, "ramp")

    def _endpoint_stop(self, now_s: float, inputs: SupervisorInputs) -> Decision | None:
        """AUTO with ``stop_at_endpoint``: the batch is mixed: one stop decision, then hands off."""
        if self._endpoint_stopped:  # hands off, but a fault is still the safe state, logged (once)
            faults = self.faults(now_s, inputs)
            if faults and not self.safe:
                self.safe, self.safe_reason = True, "; ".join(faults)
                self._latched_stop = True  # stopped at the endpoint: nothing to ramp, it stays stopped
                return self._emit(now_s, Action.NONE, "safe", f"safe (stopped at the endpoint): {self.safe_reason}")
            return None
        self._endpoint_stopped = True
        self._due_since = None
        self.target_rpm = self.commanded_rpm
        mt = "" if inputs.mixing_time_s is None else f" (mixing time {inputs.mixing_time_s:.1f} s)"
        lvl = "" if inputs.trend is None or not inputs.trend.valid else f", trend MI {inputs.trend.level:.3f}"
        return self._emit(now_s, Action.STOP, "endpoint", f"batch mixed{mt}{lvl}: stop at endpoint")

    def _below_target(self, inputs: SupervisorInputs) -> bool:
        """"time"/"energy": the batch is not mixed yet and the trend is below the target MI."""
        c, tr = self.config, inputs.trend
        return (c.objective != "plateau" and c.target_mi is not None and not inputs.mixed and tr is not None
                and tr.valid and tr.level < c.target_mi)

    def _auto(self, now_s: float, inputs: SupervisorInputs) -> Decision | None:
        c = self.config
        if not self.detector.segregated and not self._below_target(inputs):
            self._due_since = None
            return None
        if inputs.trend is None or not inputs.trend.settled:  # no what-if, no move on an unsettled trend
            return None
        if now_s - self._last_eval_s < c.min_change_interval_s:
            return None
        current = self.commanded_rpm if self.commanded_rpm is not None else c.clamp(inputs.actual_rpm or c.safe_rpm)
        preds = self.fresh_predictions(now_s)
        if preds is None:
            if self._due_since is None:  # ask once per decision, then wait a bounded time
                self._due_since = now_s
                self._request = self._prediction_request(now_s, current)
                return None
            if now_s - self._due_since < c.prediction_wait_s:
                return None
        self._due_since = None
        why = self.detector.why if self.detector.segregated else f"below target MI {c.target_mi}"
        if preds is not None and c.objective != "plateau" and preds.rows:
            stale = stale_start(preds.rows.values(), inputs.trend.level, c.target_mi, self.detector.segregated)
            if stale and (self._restudy_t is None or preds.t_s < self._restudy_t):  # ask once more, then use it
                self._predictions, self._restudy_t, self._due_since = None, now_s, now_s
                self._request = self._prediction_request(now_s, current)
                return self._emit(now_s, Action.NONE, "hold", f"{why}; objective {c.objective}: {stale}: "
                                  "asking the twin again from the bed now", predictions=preds.predictions)
            return self._choose_objective(now_s, current, preds, why + (f"; {stale} (asked again)" if stale else ""))
        if preds is not None:
            return self._choose(now_s, current, preds, why, inputs)
        target = c.clamp(current + c.fallback_step_rpm)
        if abs(target - current) < 1e-6:
            target = c.clamp(current - c.fallback_step_rpm)
        return self._start_move(
            now_s, target, "move", f"segregation ({why}); no predictions -> fallback rule {current:g} -> {target:g} rpm"
        )

    def _prediction_request(self, now_s: float, current: float) -> PredictionRequest:
        c = self.config
        return PredictionRequest(now_s, c.candidates(current), c.horizon_s, c.target_mi,
                                 c.max_rate_rpm_per_s if c.max_rate_rpm_per_s > 0 else None,
                                 from_bed=c.objective != "plateau")

    def _choose_objective(self, now_s: float, current: float, preds: PredictionResult, why: str) -> Decision:
        """"time"/"energy" (``control.objective.choose``) on the per-rpm rows."""
        c = self.config
        assert preds.rows is not None
        ch = choose(preds.rows.values(), c.objective, current, c.rpm_limits, c.target_mi,
                    min_rel_gain=c.objective_min_rel_gain)
        self._last_eval_s, self._restudy_t = now_s, None
        scores = {r: -v for r, v in ch.values.items()}  # higher is better, as the plateau scores
        row = None if ch.rpm is None else preds.rows.get(ch.rpm)
        if ch.rpm is None or not ch.move:
            return self._emit(now_s, Action.NONE, "hold", f"{why}; {ch.reason}", predictions=preds.predictions,
                              scores=scores, chosen=row, prediction_t_s=preds.t_s)
        return self._start_move(now_s, ch.rpm, "move", f"{why}; {ch.reason}", predictions=preds.predictions,
                                scores=scores, chosen=row, prediction_t_s=preds.t_s)

    def _choose(
        self, now_s: float, current: float, preds: PredictionResult, why: str, inputs: SupervisorInputs
    ) -> Decision:
        c = self.config
        plateau_note = "" if c.objective == "plateau" else f"objective {c.objective}: no time/energy rows -> plateau; "
        why = plateau_note + why
        lo, hi = c.rpm_limits
        scores: dict[float, float] = {}
        for r, mi in preds.predictions.items():
            r, mi = float(r), float(mi)
            if lo - 1e-9 <= r <= hi + 1e-9 and math.isfinite(mi):
                scores[r] = mi - c.move_penalty_per_rpm * abs(r - current)
        near = [r for r in scores if abs(r - current) <= 0.5]
        if near:
            stay = scores[min(near, key=lambda r: abs(r - current))]
        elif inputs.trend is not None and inputs.trend.valid:
            stay = inputs.trend.level
        else:
            stay = -math.inf
        self._last_eval_s = now_s
        if not scores:
            return self._emit(
                now_s, Action.NONE, "hold", f"segregation ({why}); predictions empty or out of limits",
                predictions=preds.predictions,
            )
        best = max(scores, key=lambda r: (scores[r], -abs(r - current)))
        if abs(best - current) < 1e-6 or scores[best] - stay < c.min_gain:
            return self._emit(
                now_s, Action.NONE, "hold",
                f"segregation ({why}); best {best:g} rpm gains {scores[best] - stay:+.3f} < {c.min_gain} "
                f"-> stay at {current:g}",
                predictions=preds.predictions, scores=scores,
            )
        return self._start_move(
            now_s, best, "move",
            f"segregation ({why}); twin predicts MI {preds.predictions[best]:.3f} at {best:g} rpm "
            f"(score {scores[best]:.3f} vs {stay:.3f} staying at {current:g})",
            predictions=preds.predictions, scores=scores,
        )

"""Supervisory rpm controller: the mode, AUTO's rpm choice, the ramp, the safe state (pure).

Its settings are ``control.supervisor_config.SupervisorConfig`` (the run's defaults, the
limits of ``control.limits``), what goes in and out of a step ``control.decision``, the
segregation detector ``control.segregation``.

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

Segregation detection (``control.segregation``)
    On the Kalman trend and the radial factor, with hysteresis and dwell, on a settled trend
    only (``TrendEstimate.settled``): while the trend is unsettled AUTO neither asks for
    predictions nor moves; the application logs the unsettled state
    (``trend_unsettled``/``trend_settled`` events).

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

Limits (``control.limits``: the one set)
    Every commanded rpm is inside ``limits.rpm_range`` (the drum's critical speed handed in by
    the application). The setpoint moves at most ``max_rate_rpm_per_s`` (ramped in steps every
    ``ramp_interval_s``, each one a ``ramp`` decision); a ramp from a board found outside the
    limits (started from its front panel) steps inside them at once; a board found above them
    in MANUAL or AUTO (at a resync) is brought down to the upper limit that way, even before
    any decision.

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
    (AUTO) -> ``safe_action``: ``HOLD`` (keep the setpoint, the device watchdog covers a dead
    link), ``RAMP`` (ramp to ``safe_rpm``) or ``STOP``. HOLD/RAMP recover by themselves after
    ``recover_s`` without faults; STOP is latched until the operator sets a mode again.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

from control.decision import Action, Decision, Mode, PredictionRequest, PredictionResult, SupervisorInputs
from control.errors import ControlError
from control.objective import choose, stale_start
from control.segregation import SegregationDetector
from control.supervisor_config import SafeAction, SupervisorConfig


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
        lo, hi = self.config.limits.rpm_range
        if new is Mode.MANUAL and self.manual_rpm is None and self.commanded_rpm is not None \
                and lo <= self.commanded_rpm <= hi:
            self.manual_rpm = self.commanded_rpm  # a board outside the limits: no operator rpm until one is given
        return self._emit(now_s, Action.NONE, "mode", f"mode {old.value} -> {new.value} ({reason})")

    def set_manual_rpm(self, rpm: float) -> float:
        """Operator rpm for MANUAL, clamped into the limits; returns the clamped value."""
        rpm = float(rpm)
        if not math.isfinite(rpm):
            raise ControlError(f"manual rpm must be a number, got {rpm}")
        self.manual_rpm = self.config.limits.clamp(rpm)
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
        def known(x: float | None) -> float | None:  # a NaN from the board says nothing
            return x if x is not None and math.isfinite(x) else None

        actual, setpoint = known(inputs.actual_rpm), known(inputs.setpoint_rpm)
        board = actual if inputs.mill_running else setpoint
        if board is None:
            board = setpoint if setpoint is not None else actual
        if board is None:
            return
        self._epoch = inputs.mill_epoch
        ramping = self._ramping
        self.commanded_rpm = round(float(board), 2)
        if not ramping or self.safe:
            self.target_rpm = self.commanded_rpm
        lo, hi = self.config.limits.rpm_range
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
            self.target_rpm = c.limits.clamp(c.safe_rpm)
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
        max_d = c.limits.max_rate_rpm_per_s * c.ramp_interval_s if c.limits.max_rate_rpm_per_s > 0 else abs(diff)
        nxt = round(self.commanded_rpm + max(-max_d, min(max_d, diff)), 2)
        if abs(self.target_rpm - nxt) < 0.01:
            nxt = self.target_rpm
        # a board found outside the limits (front panel): the first step goes inside them at once
        nxt = c.limits.clamp(nxt)
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
            f"ramp {nxt:g} rpm toward {self.target_rpm:g} (<= {c.limits.max_rate_rpm_per_s:g} rpm/s)",
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
        known = self.commanded_rpm
        current = known if known is not None else c.limits.clamp(inputs.actual_rpm or c.safe_rpm)
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
        target = c.limits.clamp(current + c.fallback_step_rpm)
        if abs(target - current) < 1e-6:
            target = c.limits.clamp(current - c.fallback_step_rpm)
        return self._start_move(
            now_s, target, "move", f"segregation ({why}); no predictions -> fallback rule {current:g} -> {target:g} rpm"
        )

    def _prediction_request(self, now_s: float, current: float) -> PredictionRequest:
        c = self.config
        return PredictionRequest(now_s, c.candidates(current), c.horizon_s, c.target_mi,
                                 c.limits.max_rate_rpm_per_s if c.limits.max_rate_rpm_per_s > 0 else None,
                                 from_bed=c.objective != "plateau")

    def _choose_objective(self, now_s: float, current: float, preds: PredictionResult, why: str) -> Decision:
        """"time"/"energy" (``control.objective.choose``) on the per-rpm rows."""
        c = self.config
        assert preds.rows is not None
        ch = choose(preds.rows.values(), c.objective, current, c.limits.rpm_range, c.target_mi,
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
        lo, hi = c.limits.rpm_range
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

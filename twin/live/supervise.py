"""The supervisor worker: ticks the pure ``control.supervisor.Supervisor`` on run time,
serves operator commands, raises the vision alarms, turns decisions into mill commands.

Every ``period_s`` of run time (and at once after an operator command) one
:meth:`SupervisorWorker.tick`: read the newest snapshots, raise or clear the camera and
vision alarms (with the supervisor's own vision timeout: one timeout, so the alarm and
the safe state come together), ``step`` the supervisor with any predictions that
arrived, pass its prediction request on, and carry out its decision: a ``SetRpm``
stamped with the mill epoch it was decided on, or a stop. Operator commands (mode,
manual rpm) are handled on this thread too, so the supervisor has one owner.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from typing import Protocol

from control.decision import Action, Decision, PredictionRequest, PredictionResult, SupervisorInputs
from control.errors import ControlError
from control.supervisor import Supervisor
from twin.live.camera import is_valid_mi
from twin.live.commands import MillCommand, SetManualRpm, SetMode, SetRpm, StopMill, SupervisorCommand
from twin.live.events import EventSink
from twin.live.faults import NO_FAULTS, FaultHooks, at
from twin.live.mismatch import MismatchMonitor, twin_is_evidence
from twin.live.snapshots import Latest, RunView
from twin.records import DecisionMade, FaultCleared, FaultRaised, ModeSet, OperatorAction, OperatorRejected

RPM_LIMIT_SLACK = 0.5  # rpm above the upper limit before a board counts as above it (its speed loop overshoots)


class Predictions(Protocol):
    """The application's predictor: takes requests, hands results back later (never blocks)."""

    def request(self, req: PredictionRequest) -> None: ...
    def poll(self) -> PredictionResult | None: ...


def inputs_of(view: RunView, now_s: float, twin_doubt: str = "") -> SupervisorInputs:
    """What the supervisor sees now, from the newest snapshots (``twin_doubt``: why the
    twin is not trusted now, "" when it is)."""
    frames, mill, twin, cam = view.frames(), view.mill(), view.twin(), view.camera()
    r = frames.reading
    radial = r.mi / r.mi_sigmoid if r is not None and is_valid_mi(r) and r.mi_sigmoid > 0 else None
    sp, act = mill.setpoint_rpm, mill.actual_rpm
    return SupervisorInputs(
        trend=frames.estimate,
        actual_rpm=act if math.isfinite(act) else None,
        setpoint_rpm=sp if math.isfinite(sp) else None,
        mill_connected=mill.connected,
        mill_running=mill.running if mill.status is not None else None,
        mill_epoch=mill.epoch,
        mill_refused=mill.refused,
        radial_factor=radial,
        last_valid_mi_s=frames.last_valid_t_s,
        camera_ended=cam.ended,
        twin_updated_s=twin.updated_s,
        twin_doubt=twin_doubt,
        mixed=frames.mixed,
        mixing_time_s=frames.mixing_time_s,
    )


class SupervisorWorker:
    """Owner of the :class:`Supervisor` (see module doc)."""

    def __init__(
        self,
        supervisor: Supervisor,
        view: RunView,
        sink: EventSink,
        send: Callable[[MillCommand], None],
        predictions: Predictions | None,
        mode_box: Latest[str],
        *,
        period_s: float = 1.0,
        speed: float = 1.0,
        alive: Latest[float] | None = None,
        mismatch: MismatchMonitor | None = None,
        on_twin_mismatch: Callable[[], None] | None = None,
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.supervisor = supervisor
        self.faults = faults
        self.view = view
        self.sink = sink
        self.send = send
        self.predictions = predictions
        self.mode_box = mode_box
        self.period_s = float(period_s)
        self.speed = float(speed)
        self.alive = alive  # the wall time (monotonic s) of each pass of run(): the loop's stall watch
        self._inbox: queue.SimpleQueue[SupervisorCommand] = queue.SimpleQueue()
        self._epoch = 0  # the mill epoch of the inputs of the latest step
        self.safe = False  # mirrors supervisor.safe after each tick (read by tests and the CLI)
        self.mismatch = mismatch  # twin vs camera (None: not compared)
        self.on_twin_mismatch = on_twin_mismatch  # e.g. request a recalibration
        self._doubts: dict[str, str] = {}  # why the twin is not trusted (key -> reason)
        self._doubts_lock = threading.Lock()
        mode_box.set(supervisor.mode.value)

    # -- any thread ------------------------------------------------------------------------
    def submit(self, cmd: SupervisorCommand) -> None:
        self._inbox.put(cmd)

    def doubt_twin(self, key: str, reason: str) -> None:
        """The twin is not to be trusted (``key``: what says so): AUTO treats it as stale."""
        with self._doubts_lock:
            self._doubts[key] = reason

    def trust_twin(self, key: str) -> None:
        """``key`` no longer doubts the twin."""
        with self._doubts_lock:
            self._doubts.pop(key, None)

    @property
    def twin_doubt(self) -> str:
        """Why the twin is not trusted now ("" when it is)."""
        with self._doubts_lock:
            return "; ".join(self._doubts.values())

    # -- the worker thread -----------------------------------------------------------------
    def run(self, stop: threading.Event) -> None:
        period_wall = self.period_s / self.speed
        while not stop.is_set():
            if self.alive is not None:
                self.alive.set(time.monotonic())
            try:
                cmd = self._inbox.get(timeout=period_wall)
            except queue.Empty:
                self.tick(self.view.now_s())
                continue
            self.handle(cmd)

    def handle(self, cmd: SupervisorCommand) -> None:
        """An operator command, served at the current run time (never a frame's time)."""
        now = self.view.now_s()
        sup = self.supervisor
        if isinstance(cmd, SetMode):
            try:
                d = sup.set_mode(cmd.mode, now, reason="operator")
            except ControlError as exc:
                self.sink.publish(OperatorRejected(t_s=now, action="mode", mode=cmd.mode, error=str(exc)))
                return
            self.mode_box.set(sup.mode.value)
            self.sink.publish(ModeSet(t_s=now, mode=sup.mode.value))
            if "whatif" in self._doubts:  # the operator chose again: a failed study is acknowledged
                self.trust_twin("whatif")
                self.sink.publish(FaultCleared(t_s=now, fault="whatif_failed", message="mode set by the operator"))
            self._apply(d)
        elif isinstance(cmd, SetManualRpm):
            try:
                clamped = sup.set_manual_rpm(cmd.rpm)
            except ControlError as exc:
                self.sink.publish(OperatorRejected(t_s=now, action="manual_rpm", rpm=cmd.rpm, error=str(exc)))
                return
            self.sink.publish(OperatorAction(t_s=now, action="manual_rpm", rpm=cmd.rpm, clamped_rpm=clamped))
        self.tick(now)  # act now, not at the next tick

    def tick(self, now_s: float) -> Decision | None:
        """One supervision step at run time ``now_s``."""
        at(self.faults.supervisor_tick, now_s)
        if not self.view.mill().polled:
            return None  # nothing is known about the board yet: decide nothing
        self._alarms(now_s)
        self._compare_twin(now_s)
        res = self.predictions.poll() if self.predictions is not None else None
        inputs = inputs_of(self.view, now_s, self.twin_doubt)
        self._epoch = inputs.mill_epoch
        decision, request = self.supervisor.step(now_s, inputs, res)
        self.safe = self.supervisor.safe
        if request is not None and self.predictions is not None:
            self.predictions.request(request)
        if decision is not None:
            self._apply(decision)
        return decision

    def _compare_twin(self, now: float) -> None:
        """Twin against camera (``twin.live.mismatch``): beyond tolerance a ``twin_mismatch``
        alarm, a recalibration request, and the twin in doubt until they agree again."""
        if self.mismatch is None:
            return
        r, twin = self.view.frames().reading, self.view.twin()
        if not twin_is_evidence(now, twin.updated_s, twin.age_s, self.mismatch.tol):
            return  # lagging or still spinning up: no evidence either way
        valid = r is not None and is_valid_mi(r)
        change = self.mismatch.observe(
            now, r.slope_deg if r is not None else math.nan, twin.slope_deg,
            r.mi if r is not None and valid else math.nan, twin.mi,
        )
        if change == "raise":
            reason = f"twin disagrees with the camera: {self.mismatch.reason}"
            self.sink.publish(FaultRaised(t_s=now, fault="twin_mismatch", message=reason))
            self.doubt_twin("mismatch", reason)
            if self.on_twin_mismatch is not None:
                self.on_twin_mismatch()
        elif change == "clear":
            self.trust_twin("mismatch")
            self.sink.publish(FaultCleared(t_s=now, fault="twin_mismatch", message="twin and camera agree again"))

    def _alarms(self, now: float) -> None:
        c = self.supervisor.config
        cam, frames = self.view.camera(), self.view.frames()
        if cam.ended:
            self.sink.publish(FaultRaised(t_s=now, fault="camera_ended", message="the camera source ended"))
        if cam.t_s is None:
            if now > c.vision_timeout_s:
                self.sink.publish(FaultRaised(t_s=now, fault="camera_stopped",
                                              message=f"camera stopped: no frame yet after {now:.0f} s"))
        else:
            silent = now - cam.t_s
            if c.vision_lost(now, cam.t_s):
                self.sink.publish(FaultRaised(t_s=now, fault="camera_stopped",
                                              message=f"camera stopped: no frame for {silent:.0f} s"))
            else:
                self.sink.publish(FaultCleared(t_s=now, fault="camera_stopped", message="camera frames again"))
        mill = self.view.mill()
        if mill.connected:  # fresh reads only (unknown values are NaN)
            hi = c.limits.rpm_range[1]
            over = [f"{name} {v:g}" for name, v in (("setpoint", mill.setpoint_rpm), ("actual", mill.actual_rpm))
                    if math.isfinite(v) and v > hi + RPM_LIMIT_SLACK]
            if over:
                acting = "; it is brought inside" if self.supervisor.mode.value != "off" else " (mode OFF: hands off)"
                self.sink.publish(FaultRaised(t_s=now, fault="mill_above_limits",
                                              message=f"the mill runs above the limits ({', '.join(over)} rpm > "
                                f"{hi:g} rpm){acting}"))
            else:
                self.sink.publish(FaultCleared(t_s=now, fault="mill_above_limits",
                                               message="the mill is inside the limits"))
        last = frames.last_valid_t_s
        if last is not None:
            if c.vision_lost(now, last):
                self.sink.publish(FaultRaised(t_s=now, fault="vision_lost",
                                              message=f"no valid MI for {now - last:.0f} s"))
            else:
                self.sink.publish(FaultCleared(t_s=now, fault="vision_lost", message="valid MI again"))

    def _apply(self, d: Decision) -> None:
        self.sink.publish(DecisionMade.of(d))
        if d.action is Action.STOP:
            self.send(StopMill(source="supervisor"))
        elif d.action is Action.SET_RPM and d.rpm is not None:
            self.send(SetRpm(float(d.rpm), self._epoch))

"""The operator's commands: the dashboard's ``twin.state.Controls``, implemented by putting typed
commands on the workers' queues (``twin.live.commands``) and logging each as an operator record.

Every call returns at once and never raises into the dashboard's callback: bad input is an
``operator_rejected`` record. Nothing here runs a worker's work; the one exception, learning
the colour classes again (seconds of work), runs on a thread the loop starts (``spawn``).
"""

from __future__ import annotations

import queue
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from control.errors import ControlError
from control.limits import Limits
from twin.live.commands import (
    MillCommand,
    Recalibrate,
    Reseed,
    RunStudy,
    SetManualRpm,
    SetMode,
    StartMill,
    StopMill,
    SupervisorCommand,
    SwapClasses,
    TwinCommand,
)
from twin.live.events import EventSink
from twin.live.snapshots import CameraInfo, Latest, MillSnapshot
from twin.records import FaultCleared, FaultRaised, OperatorAction, OperatorRejected
from vision.errors import VisionError

if TYPE_CHECKING:
    from vision.colours import ColourClass
    from vision.config import MeterConfig
    from vision.roi import DrumROI


class MillTakes(Protocol):
    def submit(self, cmd: MillCommand) -> None: ...


class SupervisorTakes(Protocol):
    def submit(self, cmd: SupervisorCommand) -> None: ...


class TwinTakes(Protocol):
    def request(self, cmd: TwinCommand) -> None: ...


class Studies(Protocol):
    """The what-if worker as the operator uses it."""

    def submit(self, study: RunStudy) -> bool: ...
    def cancel(self) -> bool: ...


class Operator:
    """The dashboard's ``Controls`` for one run (see module doc). ``spawn(name, target)``: the
    loop starts ``target`` on a thread of its own (the loop starts and joins every thread);
    ``meter_config`` / ``classes`` / ``roi``: the camera meter's set-up, where learning the
    classes again starts from."""

    def __init__(
        self,
        *,
        now_s: Callable[[], float],
        events: EventSink,
        mill: MillTakes,
        mill_box: Latest[MillSnapshot],
        supervisor: SupervisorTakes,
        twin: TwinTakes,
        whatif: Studies,
        limits: Limits,
        camera_box: Latest[CameraInfo],
        camera_commands: queue.SimpleQueue[SwapClasses],
        spawn: Callable[[str, Callable[[], None]], None],
        meter_config: MeterConfig | None = None,
        classes: Sequence[ColourClass] = (),
        roi: DrumROI | None = None,
    ) -> None:
        self.now_s = now_s
        self.events = events
        self.mill, self.mill_box = mill, mill_box
        self.supervisor, self.twin, self.whatif = supervisor, twin, whatif
        self.limits = limits
        self.camera_box, self.camera_commands = camera_box, camera_commands
        self.spawn = spawn
        self.meter_config, self.classes, self.roi = meter_config, tuple(classes), roi

    # -- the mode and the mill -------------------------------------------------------------
    def set_mode(self, mode: str) -> None:
        self.supervisor.submit(SetMode(str(mode).lower()))

    def set_manual_rpm(self, rpm: float) -> None:
        self.supervisor.submit(SetManualRpm(float(rpm)))

    def start_mill(self) -> None:
        t = self.now_s()
        self.events.publish(OperatorAction(t_s=t, action="start"))
        self.events.publish(FaultCleared(t_s=t, fault="emergency_stop", message="mill started again"))
        self.mill.submit(StartMill(self.mill_box.get().epoch))

    def stop_mill(self) -> None:
        self.events.publish(OperatorAction(t_s=self.now_s(), action="stop"))
        self.mill.submit(StopMill())

    def emergency_stop(self) -> None:
        t = self.now_s()
        self.mill.submit(StopMill(source="emergency_stop", urgent=True))  # first: jumps every queue
        self.events.publish(OperatorAction(t_s=t, action="emergency_stop"))
        self.supervisor.submit(SetMode("off"))
        self.events.publish(FaultRaised(t_s=t, fault="emergency_stop",
                                        message="EMERGENCY STOP pressed: mill stopped, mode OFF"))

    # -- the twin ------------------------------------------------------------------------------
    def recalibrate(self) -> None:
        self.events.publish(OperatorAction(t_s=self.now_s(), action="recalibrate"))
        self.twin.request(Recalibrate())

    def reseed_twin(self) -> None:
        self.events.publish(OperatorAction(t_s=self.now_s(), action="reseed"))
        self.twin.request(Reseed())

    # -- what-if ---------------------------------------------------------------------------------
    def run_whatif(self, rpms: Sequence[float], duration_s: float) -> None:
        """Queue an operator study (bad input is an ``operator_rejected`` event, never an
        exception in the dashboard's callback)."""
        t = self.now_s()
        try:  # the one set of limits (control.limits): the ``whatif`` command's caps
            rpm_list, duration = self.limits.check_whatif(rpms, duration_s)
        except ControlError as exc:
            self.events.publish(OperatorRejected(t_s=t, action="whatif", error=str(exc)))
            return
        self.events.publish(OperatorAction(t_s=t, action="whatif", rpms=rpm_list, duration_s=duration))
        if not self.whatif.submit(RunStudy(tuple(rpm_list), duration)):
            self.events.publish(OperatorRejected(t_s=t, action="whatif", error="a study is already running"))

    def cancel_whatif(self) -> bool:
        """Abandon the operator's running or waiting what-if study; True when there was one."""
        cancelled = self.whatif.cancel()
        self.events.publish(OperatorAction(t_s=self.now_s(), action="whatif_cancel", cancelled=cancelled))
        return cancelled

    # -- the colour classes ------------------------------------------------------------------------
    def relearn_classes(self) -> str:
        """Operator (after ``lighting_changed:``): learn the colour classes again from the newest
        camera frame (``vision.suggest.relearn_classes``: names and order kept, the light
        reference the frame's) off the camera thread, then swap the meter in from the next
        frame on (``SwapClasses``). Logged as an operator action, a refusal or failure as
        ``operator_rejected``. Returns what the dashboard tells the operator."""
        t, image = self.now_s(), self.camera_box.get().image
        if image is None:
            self.events.publish(OperatorRejected(t_s=t, action="relearn_classes", error="no camera frame yet"))
            return "**re-learn refused: no camera frame yet**"
        self.events.publish(OperatorAction(t_s=t, action="relearn_classes"))
        frame = image.copy()
        self.spawn("relearn", lambda: self._relearn(frame))
        return "re-learning the classes from the live bed ..."

    def _relearn(self, image: np.ndarray) -> None:
        from vision.config import MeterConfig
        from vision.suggest import relearn_classes

        try:
            cfg = relearn_classes(self.meter_config or MeterConfig(self.classes), [image])
            meter = cfg.make_meter(roi=self.roi)
        except VisionError as exc:
            self.events.publish(OperatorRejected(t_s=self.now_s(), action="relearn_classes", error=str(exc)))
            return
        self.meter_config = cfg  # the next re-learn starts from it
        self.camera_commands.put(SwapClasses(meter))
        self.events.publish(OperatorAction(t_s=self.now_s(), action="relearn_classes_swapped"))


__all__ = ["Operator"]

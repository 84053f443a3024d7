"""The live loop's composition root: builds the workers, wires them, starts and joins
their threads. Nothing else in the application starts a thread of the loop.

Workers (``twin/live/``), one thread each, none of which sees the loop:

* **camera** (:class:`CameraWorker`): frames -> ``Meter.measure`` -> readings queue
  (bounded, drops the oldest: the camera is never blocked); publishes ``CameraInfo``.
* **process** (:class:`ProcessWorker`): readings -> Kalman trend + the paper's moving
  average -> one ``FrameRow`` (CSV row and plot point); publishes ``FrameInfo``.
* **mill** (:class:`MillWorker`): the one poller of the mill link; sends the commands it
  is given, never anything else; publishes ``MillSnapshot``.
* **twin** (:class:`TwinWorker`): calibrates, seeds and runs the physics twin.
* **whatif** (:class:`WhatIfWorker`): twin studies for AUTO and the operator.
* **supervisor** (:class:`SupervisorWorker`): the pure supervisor on run time, alarms,
  operator commands; decisions become mill commands.

They read each other only through a :class:`RunView` of immutable snapshots, report
through one event sink (run log + dashboard alarms) and take typed commands on their
own queues. :class:`LiveLoop` implements the dashboard's ``Controls`` by putting
commands on those queues.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from control.errors import ControlError
from control.limits import Limits
from control.supervisor import Mode, Supervisor, SupervisorConfig
from control.trend import MITrend, TrendConfig
from sim.errors import SimError
from twin.clock import RunClock
from twin.config import RunConfig
from twin.errors import TwinError
from twin.live.camera import CameraReading, CameraWorker, ProcessWorker
from twin.live.mill import MillLink, MillWorker
from twin.live.mismatch import MismatchMonitor, MismatchTolerance
from twin.live.records import (
    CameraInfo,
    FrameInfo,
    Latest,
    MillSnapshot,
    RunEvents,
    RunView,
    SetManualRpm,
    SetMode,
    StartMill,
    StopMill,
    TwinInfo,
)
from twin.live.supervise import SupervisorWorker
from twin.live.twin import TwinSettings, TwinWorker
from twin.live.whatif import WhatIfWorker
from twin.records import MillState, ModeSet
from twin.state import LiveState
from vision.errors import VisionError
from vision.meter import Meter

log = logging.getLogger("drumtwin.loop")

EXPECTED_ERRORS: tuple[type[Exception], ...] = (VisionError, SimError, ControlError, TwinError, OSError)
"""A worker stopped by bad input or its environment (no drum in the frames, a camera gone):
a one-line fault, no traceback. Anything else is a bug and logged with its traceback."""

ESSENTIAL_WORKERS = ("mill", "process", "supervisor")
"""Workers without which the run ends (see ``LiveLoop._fail``): with the supervisor gone the
mill worker would feed the watchdog of a mill nobody supervises; with the mill worker gone
the supervisor would believe a board nobody reads; without the process worker no frames
are logged. (A camera that fails is an ended camera, unless the meter cannot read its
frames at all, a ``VisionError``: bad input ends the run too; a dead twin goes stale.)"""

SUPERVISOR_STALL_S = 5.0
"""Wall seconds (at least; 5 supervisor periods if longer) without one pass of the supervisor
worker's loop before the run ends: a supervisor that hangs (no crash) would otherwise leave
the mill worker feeding the watchdog of a mill nobody supervises."""


@dataclass
class Summary:
    """The ``--json`` summary of a run."""

    final_trend_mi: float
    final_rpm: float
    decisions: int
    faults: int
    log_dir: str
    frames: int = 0
    run_time_s: float = 0.0
    wall_time_s: float = 0.0
    camera_fps: float = 0.0
    twin_fps: float = 0.0
    extra: dict = field(default_factory=dict)


def open_mill(url: str) -> MillLink:
    """The run's mill client: opened now (``ConnectionError`` when it cannot be), with no
    thread of its own (the mill worker is its one user and poller). A ``modbus:`` URL is a
    frequency inverter (``control.modbus.link.ModbusMill``: its comm-loss trip is checked
    now, a ``ControlError`` when it is unsafe and not overridden); anything else is the
    line protocol's board."""
    if url.startswith("modbus:"):
        from control.modbus.link import ModbusMill

        return ModbusMill(url, connect=True)
    from control.driver import MillClient

    return MillClient(url, heartbeat_s=None, connect=True)


class LiveLoop:
    """The composition root (see module doc). ``frames``: the camera (an iterable of
    ``vision.sources.Frame``); ``mill``: an opened mill link (:func:`open_mill`);
    ``runlog``: the run's log; ``roi``/``classes``: the meter's drum ROI and colour
    classes when known. Implements the dashboard's ``Controls``."""

    def __init__(
        self,
        config: RunConfig,
        frames: Iterable[Any],
        mill: MillLink,
        runlog: Any,
        state: LiveState | None = None,
        *,
        clock: RunClock | None = None,
        roi: Any = None,
        classes: Sequence[Any] | None = None,
        overlay: Callable[..., Any] | None = None,
        mixer: Any = None,
        meter_config: Any = None,
    ) -> None:
        self.config = config
        self.clock = clock or RunClock(1.0)
        self.stop_event = self.clock.stop
        self.runlog = runlog
        self.state = state or LiveState()
        self.mill_link = mill
        self.failure: str | None = None  # why the run had to end (see _fail)
        self._fail_lock = threading.Lock()
        self.events = RunEvents(runlog, self.state, on_failure=self._fail)
        if meter_config is not None:  # a vision.config.MeterConfig: its camera turn, light reference, opening
            meter = meter_config.make_meter(roi=roi)
        else:
            meter = Meter(roi=roi) if classes is None else Meter(roi=roi, classes=tuple(classes))
        self._classes = tuple(meter.colour_classes)
        # snapshots (one writer each)
        self.camera_box: Latest[CameraInfo] = Latest(CameraInfo())
        self.frames_box: Latest[FrameInfo] = Latest(FrameInfo())
        self.mill_box: Latest[MillSnapshot] = Latest(MillSnapshot())
        self.twin_box: Latest[TwinInfo] = Latest(TwinInfo())
        self.mode_box: Latest[str] = Latest(config.mode)
        self.supervisor_alive: Latest[float] = Latest(time.monotonic())  # its last pass (wall, monotonic s)
        self.view = RunView(
            self.clock.speed, self.camera_box, self.frames_box, self.mill_box, self.twin_box, self.mode_box,
            self.clock.now_s,
        )
        readings: queue.Queue[CameraReading] = queue.Queue(maxsize=512)
        slopes: queue.SimpleQueue[tuple[float, float]] = queue.SimpleQueue()
        self.camera = CameraWorker(
            frames, meter, readings, self.camera_box, self.state,
            overlay_hz=config.dashboard_hz if config.dashboard else 0.0, overlay=overlay or _overlay,
        )
        self.process = ProcessWorker(
            readings, MITrend(trend_config(config)), self.frames_box, self.view, self.events, slopes,
            camera_fps=self.camera.fps.rate,
        )
        self.mill = MillWorker(mill, self.events, self.mill_box, self.view.now_s)
        self.twin = TwinWorker(
            TwinSettings(
                case=config.case, seed=config.seed, start_rpm=config.start_rpm, size_px=config.frame_px,
                classes=self._classes, mixer=mixer, engine=config.engine,
                calibrate_kwargs={"mixer": mixer, "engine": config.engine,
                                  **config.extra.get("calibrate_kwargs", {})},
            ),
            self.view, self.events, self.state, self.twin_box, slopes,
        )
        self.whatif = WhatIfWorker(
            self.view, self.events, self.state, scheduler=config.scheduler, workers=config.whatif_workers,
            study=config.extra.get("whatif_study"),
        )
        sup_config = supervisor_config(config, None if mixer is None else mixer.drum.critical_rpm)
        self._limits = sup_config.limits
        self.supervisor = SupervisorWorker(
            Supervisor(sup_config, mode=Mode(config.mode)), self.view, self.events, self.mill.submit,
            self.whatif, self.mode_box, period_s=config.supervisor_period_s, speed=self.clock.speed,
            alive=self.supervisor_alive,
            mismatch=MismatchMonitor(MismatchTolerance(**config.extra.get("mismatch", {}))),
            on_twin_mismatch=lambda: self.twin.request("calibrate"),
        )
        self.whatif.on_auto_result = self._auto_study_result
        self._threads: list[threading.Thread] = []
        self.events.publish(ModeSet(t_s=0.0, mode=config.mode))
        self.events.publish(MillState(t_s=0.0, state="connecting", setpoint_rpm=None, actual_rpm=None))

    # -- lifecycle (the only place threads start and stop) ---------------------------------
    def warm_up(self) -> None:
        """Compile the compiled kernels the workers will use (the meter's one pass and free
        surface, the DEM twin) before the run's clock starts. A first compile holds the GIL
        for seconds; on a fresh machine it would stall the camera and vision threads at run
        time and look like a stopped camera. With numba's on-disk cache this takes well under
        a second after the first run. A throwaway meter and twin: no worker's state is touched."""
        from sim.drum import DrumSim
        from vision.synthetic import particle_drum

        Meter(classes=self._classes).measure(particle_drum((320, 240)).image)
        DrumSim(settle_s=0.0).advance(0.01)

    def start(self) -> LiveLoop:
        self.events.event("start", 0.0, mode=self.config.mode, mill=getattr(self.mill_link, "url", ""))
        override = getattr(self.mill_link, "safety_override", None)  # a drive run against its check
        if override:
            self.events.fault("mill_safety_override", f"operator override: {override}", 0.0)
        if self.config.mode == "auto":
            self.whatif.warm_up()
        for name, worker in (
            ("mill", self.mill),
            ("camera", self.camera),
            ("process", self.process),
            ("twin", self.twin),
            ("whatif", self.whatif),
            ("supervisor", self.supervisor),
        ):
            th = threading.Thread(target=self._guard(name, worker.run), name=f"drumtwin-{name}", daemon=True)
            th.start()
            self._threads.append(th)
        th = threading.Thread(target=self._watch, name="drumtwin-watch", daemon=True)
        th.start()
        self._threads.append(th)
        return self

    def _watch(self) -> None:
        """End the run when the supervisor worker stops passing through its loop (hung, not
        crashed: a crash is the guard's) for ``SUPERVISOR_STALL_S``."""
        self.supervisor_alive.set(time.monotonic())
        limit = max(SUPERVISOR_STALL_S, 5.0 * self.config.supervisor_period_s / self.clock.speed)
        while not self.stop_event.wait(0.25):
            quiet = time.monotonic() - self.supervisor_alive.get()
            if quiet > limit:
                reason = f"the supervisor worker has not run for {quiet:.1f} s"
                self.events.fault("supervisor_stalled", reason, self.view.now_s())
                self._fail(reason)
                return

    def _guard(self, name: str, run: Callable[[threading.Event], None]) -> Callable[[], None]:
        def target() -> None:
            try:
                run(self.stop_event)
            except Exception as exc:  # a crashed worker is a fault, never silent
                if not isinstance(exc, EXPECTED_ERRORS):  # a bug: its traceback (bad input is one line)
                    log.exception("worker %s crashed", name)
                self.events.fault(f"thread_{name}", f"{name} worker crashed: {exc}", self.view.now_s())
                if name in ESSENTIAL_WORKERS:
                    self._fail(f"the {name} worker crashed: {exc}")
                elif name == "camera" and isinstance(exc, VisionError):  # e.g. no drum in the frames
                    self._fail(f"camera: {exc}")

        return target

    def _fail(self, reason: str) -> None:
        """The run cannot keep its rules any more (the run log cannot be written, or an
        essential worker crashed): end it now; :meth:`stop` stops the mill on the way out
        and ``failure`` says why (the CLI's one-line error)."""
        with self._fail_lock:
            if self.failure is not None:
                return
            self.failure = reason
        self.stop_event.set()

    def now_s(self) -> float:
        """Run time (see :class:`RunView`)."""
        return self.view.now_s()

    def wait(self, duration_s: float | None) -> None:
        """Block until ``duration_s`` of run time has passed (None: until stopped)."""
        while not self.stop_event.is_set():
            if duration_s is not None and self.now_s() >= duration_s:
                return
            self.stop_event.wait(0.05)

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop every worker and join it (``timeout_s`` in all), then close the mill link.

        The what-if pool is closed first, so a running study ends at once instead of being
        waited for. The mill keeps its last setpoint; its watchdog stops it once nobody
        feeds it.
        """
        self.stop_event.set()
        self.whatif.close()
        self.twin.close()
        deadline = time.monotonic() + timeout_s
        for th in self._threads:
            th.join(timeout=max(0.0, deadline - time.monotonic()))
        alive = [th.name for th in self._threads if th.is_alive()]
        if alive:
            log.warning("workers still running after stop: %s", ", ".join(alive))
        if self.failure is not None:  # the workers are gone: the link is ours to stop the mill
            t = self.now_s()
            try:
                self.mill_link.stop()
            except (OSError, ControlError) as exc:
                self.events.event("mill_command_dropped", t, command="stop", source="run_failed", reason=str(exc))
            else:
                self.events.event("mill_command", t, command="stop", source="run_failed")
        self.mill_link.close()
        f = self.frames_box.get()
        self.events.event("stop", f.t_s, frames=f.n_frames, workers_alive=alive, failure=self.failure)

    def summary(self, wall_s: float = 0.0) -> Summary:
        f = self.frames_box.get()
        est = f.estimate
        return Summary(
            final_trend_mi=float(est.level) if est is not None else math.nan,
            final_rpm=self.mill_box.get().actual_rpm,
            decisions=self.events.n_decisions,
            faults=self.events.n_faults,
            log_dir=str(self.runlog.paths.directory),
            frames=f.n_frames,
            run_time_s=f.t_s,
            wall_time_s=wall_s,
            camera_fps=self.camera.fps.rate(),
            twin_fps=self.twin.fps.rate(),
        )

    @property
    def mode_name(self) -> str:
        return self.mode_box.get()

    # -- controls (dashboard): typed commands onto the workers' queues ---------------------
    def set_mode(self, mode: str) -> None:
        self.supervisor.submit(SetMode(str(mode).lower()))

    def set_manual_rpm(self, rpm: float) -> None:
        self.supervisor.submit(SetManualRpm(float(rpm)))

    def start_mill(self) -> None:
        t = self.now_s()
        self.events.event("operator", t, action="start")
        self.events.clear_fault("emergency_stop", "mill started again", t)
        self.mill.submit(StartMill(self.mill_box.get().epoch))

    def stop_mill(self) -> None:
        self.events.event("operator", self.now_s(), action="stop")
        self.mill.submit(StopMill())

    def emergency_stop(self) -> None:
        t = self.now_s()
        self.mill.submit(StopMill(source="emergency_stop", urgent=True))  # first: jumps every queue
        self.events.event("operator", t, action="emergency_stop")
        self.supervisor.submit(SetMode("off"))
        self.events.fault("emergency_stop", "EMERGENCY STOP pressed: mill stopped, mode OFF", t)

    def recalibrate(self) -> None:
        self.events.event("operator", self.now_s(), action="recalibrate")
        self.twin.request("calibrate")

    def reseed_twin(self) -> None:
        self.events.event("operator", self.now_s(), action="reseed")
        self.twin.request("reseed")

    def run_whatif(self, rpms: Sequence[float], duration_s: float) -> None:
        """Queue an operator study (bad input is an ``operator_rejected`` event, never an
        exception in the dashboard's callback)."""
        t = self.now_s()
        try:  # the one set of limits (control.limits): the ``whatif`` command's caps
            rpm_list, duration = self.limits.check_whatif(rpms, duration_s)
        except ControlError as exc:
            self.events.event("operator_rejected", t, action="whatif", error=str(exc))
            return
        self.events.event("operator", t, action="whatif", rpms=rpm_list, duration_s=duration)
        if not self.whatif.submit(rpm_list, duration, reason="operator"):
            self.events.event("operator_rejected", t, action="whatif", error="a study is already running")

    def _auto_study_result(self, error: str | None) -> None:
        """A failed AUTO what-if study is a fault: an alarm, and AUTO's safe state (the twin
        in doubt) until a study succeeds or the operator sets a mode again."""
        t = self.now_s()
        if error is not None:
            self.events.fault("whatif_failed", f"AUTO's what-if study failed: {error}", t)
            self.supervisor.doubt_twin("whatif", f"what-if study failed ({error})")
        else:
            self.supervisor.trust_twin("whatif")
            self.events.clear_fault("whatif_failed", "an AUTO what-if study succeeded", t)

    def cancel_whatif(self) -> bool:
        """Abandon the operator's running or waiting what-if study; True when there was one."""
        cancelled = self.whatif.cancel()
        self.events.event("operator", self.now_s(), action="whatif_cancel", cancelled=cancelled)
        return cancelled

    @property
    def limits(self) -> Limits:
        """The run's one set of limits (the supervisor's): dashboard and what-if read them."""
        return self._limits


# Supervisor settings of the live loop. The camera MI of a well-mixed bed is ~0.93-0.95;
# radial segregation at 5 rpm brings it to ~0.80-0.85 (vision MI of the demo plant).
LOOP_SUPERVISOR: dict[str, Any] = dict(
    seg_level=0.88,
    clear_level=0.91,
    seg_rate_per_s=-0.004,
    detect_dwell_s=5.0,
    min_rpm=5.0,  # the paper's slowest speed; below it the bed only rolls
    n_candidates=3,  # 5, 25, 45 rpm (+ the current speed)
    horizon_s=40.0,
    prediction_wait_s=150.0,
    prediction_max_age_s=150.0,  # a study takes 10-30 s wall: up to ~120 s of run time at --speed 4
    move_penalty_per_rpm=0.0002,  # 40 rpm up costs 0.008 MI
    min_gain=0.01,
    min_change_interval_s=30.0,
    max_rate_rpm_per_s=4.0,
    vision_timeout_s=5.0,  # the one vision timeout (run s): alarm and safe state together
    require_twin=True,  # a twin that never ran (died or hung before its first step) is stale too
)


# Trend settings of the live loop: the defaults of ``control.trend.TrendConfig`` (the noise is
# estimated on line and re-initialisation is decided on the share of rejections, so camera MI
# needs no loop-specific tuning; issue 21). ``config.extra["trend"]`` overrides.
LOOP_TREND: dict[str, Any] = {}


def trend_config(config: RunConfig) -> TrendConfig:
    """The Kalman trend's settings for this run (``config.extra["trend"]`` overrides)."""
    return TrendConfig(**{**LOOP_TREND, **config.extra.get("trend", {})})


def supervisor_config(config: RunConfig, critical_rpm: float | None = None) -> SupervisorConfig:
    """The supervisor's settings for this run (``config.extra["supervisor"]`` overrides);
    the critical speed comes from the twin's drum (``critical_rpm``, the mixer's drum's;
    default the paper's: ``sim.recipe``, the one formula)."""
    from sim.recipe import PAPER_DRUM

    overrides = config.extra.get("supervisor", {})
    crit = PAPER_DRUM.critical_rpm if critical_rpm is None else float(critical_rpm)
    return SupervisorConfig(**{"critical_rpm": crit, **LOOP_SUPERVISOR, **overrides})


def _overlay(image: Any, reading: Any) -> Any:
    from vision.overlay import draw_overlay

    return draw_overlay(image, reading)


__all__ = ["LOOP_SUPERVISOR", "LiveLoop", "Summary", "open_mill", "supervisor_config", "trend_config"]

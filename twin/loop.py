"""The live loop's composition root, for the demo and for hardware alike: :func:`run_live`
builds the plant (demo) or opens the camera, the mill link, the run log, the dashboard's
state, the :class:`LiveLoop` and the dashboard, starts them in order (the demo's start is a
small plan, :class:`DemoStart`), waits and shuts them down; the CLI only parses and calls it.
:class:`LiveLoop` builds the workers, wires them, starts and joins their threads. Nothing
else in the application starts a thread of the loop. Test seams are typed (:class:`Seams`).

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
import platform
import queue
import threading
import time
import traceback as tb
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from control.endpoint import EndpointConfig, EndpointDetector, endpoint_settings
from control.errors import ControlError
from control.limits import Limits
from control.supervisor import Mode, Supervisor, SupervisorConfig
from control.trend import MITrend, TrendConfig
from sim.errors import SimError
from twin.clock import RunClock
from twin.config import RunConfig
from twin.errors import EXIT_BAD_INPUT, EXIT_WORKER_CRASHED, RunFailed, TwinError
from twin.live.camera import READINGS_MAX, SLOPES_MAX, CameraReading, CameraWorker, ProcessWorker
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
    SwapClasses,
    TwinInfo,
)
from twin.live.supervise import SupervisorWorker
from twin.live.twin import TwinSettings, TwinWorker
from twin.live.whatif import Study, WhatIfWorker
from twin.records import (
    FaultCleared,
    FaultRaised,
    MillCommandDropped,
    MillCommandSent,
    MillState,
    ModeSet,
    OperatorAction,
    OperatorRejected,
    Record,
    RunStart,
    RunStop,
)
from twin.runlog import RunLog
from twin.state import LiveState
from vision.errors import VisionError
from vision.meter import Meter, Reading

if TYPE_CHECKING:
    from sim.mixer import Mixer
    from twin.dashboard import Dashboard
    from twin.demo import DemoPlant
    from vision.colours import ColourClass
    from vision.config import MeterConfig
    from vision.roi import DrumROI
    from vision.sources import Frame

log = logging.getLogger("drumtwin.loop")

EXPECTED_ERRORS: tuple[type[Exception], ...] = (VisionError, SimError, ControlError, TwinError, OSError)
"""A worker stopped by bad input or its environment (no drum in the frames, a camera gone):
a one-line fault, no traceback. Anything else is a bug and logged with its traceback."""

def crash_summary(exc: BaseException) -> str:
    """An exception in one line: ``Type: first line of its message``."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


ESSENTIAL_WORKERS = ("mill", "process", "supervisor")
"""Workers without which the run ends when they stop on an expected error (see ``LiveLoop._fail``;
any other exception, a bug, in any worker ends the run: ``worker_crashed``, exit 3): with the supervisor gone the
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
        frames: Iterable[Frame],
        mill: MillLink,
        runlog: RunLog,
        state: LiveState | None = None,
        *,
        clock: RunClock | None = None,
        roi: DrumROI | None = None,
        classes: Sequence[ColourClass] | None = None,
        overlay: Callable[[np.ndarray, Reading], np.ndarray] | None = None,
        mixer: Mixer | None = None,
        meter_config: MeterConfig | None = None,
        seams: Seams | None = None,
    ) -> None:
        seams = seams or Seams()
        self.config = config
        self._mixer = mixer  # None: the paper's (the demo's twin)
        self.clock = clock or RunClock(1.0)
        self.stop_event = self.clock.stop
        self.runlog = runlog
        self.state = state or LiveState()
        self.mill_link = mill
        self.failure: str | None = None  # why the run had to end (see _fail)
        self.exit_code = EXIT_BAD_INPUT  # the CLI's exit code when it had to (see _fail)
        self._fail_lock = threading.Lock()
        self.events = RunEvents(runlog, self.state, on_failure=self._fail)
        if meter_config is not None:  # a vision.config.MeterConfig: its camera turn, light reference, opening
            meter = meter_config.make_meter(roi=roi)
        else:
            meter = Meter(roi=roi) if classes is None else Meter(roi=roi, classes=tuple(classes))
        self._classes = tuple(meter.colour_classes)
        self._meter_config, self._roi = meter_config, roi  # (re-learning the classes starts from them)
        self._camera_commands: queue.SimpleQueue[SwapClasses] = queue.SimpleQueue()
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
        readings: queue.Queue[CameraReading] = queue.Queue(maxsize=READINGS_MAX)  # bounded: drops the oldest
        slopes: queue.Queue[tuple[float, float]] = queue.Queue(maxsize=SLOPES_MAX)
        self.camera = CameraWorker(
            frames, meter, readings, self.camera_box, self.state,
            overlay_hz=config.dashboard_hz if config.dashboard else 0.0, overlay=overlay or _overlay,
            commands=self._camera_commands,
        )
        self.process = ProcessWorker(
            readings, MITrend(trend_config(seams)), self.frames_box, self.view, self.events, slopes,
            camera_fps=self.camera.fps.rate,
            endpoint=EndpointDetector(endpoint_config(config, seams)),
        )
        self.mill = MillWorker(mill, self.events, self.mill_box, self.view.now_s)
        sup_config = supervisor_config(seams, None if mixer is None else mixer.drum.critical_rpm, config)
        self._limits = sup_config.limits
        self.twin = TwinWorker(
            TwinSettings(
                case=config.case, seed=config.seed, start_rpm=config.start_rpm, size_px=config.frame_px,
                classes=self._classes, mixer=mixer, engine=config.engine,
                calibrate_kwargs={"mixer": mixer, "engine": config.engine, **seams.calibrate},
                min_rpm=self._limits.min_rpm,  # calibrated only where the supervisor may run the drum
            ),
            self.view, self.events, self.state, self.twin_box, slopes,
        )
        self.whatif = WhatIfWorker(
            self.view, self.events, self.state, scheduler=config.scheduler, workers=config.whatif_workers,
            study=seams.whatif_study, target_mi=endpoint_config(config, seams).target_mi,
            reseed_twin=lambda: self.twin.request("reseed"),
        )
        self.supervisor = SupervisorWorker(
            Supervisor(sup_config, mode=Mode(config.mode)), self.view, self.events, self.mill.submit,
            self.whatif, self.mode_box, period_s=config.supervisor_period_s, speed=self.clock.speed,
            alive=self.supervisor_alive,
            mismatch=MismatchMonitor(seams.mismatch),
            on_twin_mismatch=lambda: self.twin.request("calibrate"),
        )
        self.whatif.on_auto_result = self._auto_study_result
        if seams.crash is not None:
            self._inject(seams.crash)
        self._threads: list[threading.Thread] = []
        self.events.publish(ModeSet(t_s=0.0, mode=config.mode))
        self.events.publish(MillState(t_s=0.0, state="connecting", connected=False, setpoint_rpm=None,
                                      actual_rpm=None))

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
        from sim.mixer import paper_mixer

        self.events.publish(RunStart(
            t_s=0.0, mode=self.config.mode, mill=getattr(self.mill_link, "url", ""),
            config=self.config.to_metadata(), versions=versions(),
            mixer=mixer_metadata(self._mixer if self._mixer is not None else paper_mixer()),
        ))
        override = getattr(self.mill_link, "safety_override", None)  # a drive run against its check
        if override:
            self.events.publish(FaultRaised(t_s=0.0, fault="mill_safety_override",
                                            message=f"operator override: {override}"))
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
                self.events.publish(FaultRaised(t_s=self.view.now_s(), fault="supervisor_stalled", message=reason))
                self._fail(reason, crashed=True)
                return

    def _guard(self, name: str, run: Callable[[threading.Event], None]) -> Callable[[], None]:
        def target() -> None:
            try:
                run(self.stop_event)
            except Exception as exc:  # a crashed worker is a fault, never silent
                t = self.view.now_s()
                if not isinstance(exc, EXPECTED_ERRORS):  # a bug: the run ends (exit 3), the traceback in the log
                    what = crash_summary(exc)
                    log.debug("worker %s crashed", name, exc_info=True)
                    self.events.publish(FaultRaised(t_s=t, fault="worker_crashed",
                                                    message=f"the {name} worker crashed: {what}", worker=name,
                                                    error=what, traceback=tb.format_exc()))
                    self._fail(f"the {name} worker crashed: {what}", crashed=True)
                    return
                self.events.publish(FaultRaised(t_s=t, fault=f"thread_{name}", message=f"{name} worker crashed: {exc}"))
                if name in ESSENTIAL_WORKERS:
                    self._fail(f"the {name} worker crashed: {exc}")
                elif name == "camera" and isinstance(exc, VisionError):  # e.g. no drum in the frames
                    self._fail(f"camera: {exc}")

        return target

    def _inject(self, crash: WorkerCrash) -> None:
        """``Seams.crash``: wrap the worker's per-pass step so it raises from ``crash.at_s`` on."""

        def fire() -> None:
            if self.view.now_s() >= crash.at_s:
                raise RuntimeError(crash.message)

        if crash.worker == "camera":
            frames = self.camera.frames

            def crashing() -> Iterator[Frame]:
                for f in frames:
                    fire()
                    yield f

            self.camera.frames = crashing()
            return
        owner, step = {"process": (self.process, "process"), "mill": (self.mill, "cycle"),
                       "twin": (self.twin, "_serve_requests"), "whatif": (self.whatif, "serve_once"),
                       "supervisor": (self.supervisor, "tick")}[crash.worker]
        inner = getattr(owner, step)

        def wrapped(*args: object, **kwargs: object) -> object:
            fire()
            return inner(*args, **kwargs)

        setattr(owner, step, wrapped)

    def _fail(self, reason: str, crashed: bool = False) -> None:
        """The run cannot keep its rules any more (the run log cannot be written, an
        essential worker stopped, any worker crashed or the supervisor hung): end it now;
        :meth:`stop` stops the mill on the way out and ``failure`` says why (the CLI's
        one-line error); ``crashed``: a bug, not bad input (``exit_code`` 3)."""
        with self._fail_lock:
            if self.failure is not None:
                return
            self.failure = reason
            self.exit_code = EXIT_WORKER_CRASHED if crashed else EXIT_BAD_INPUT
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
                self.events.publish(MillCommandDropped(t_s=t, command="stop", source="run_failed", reason=str(exc)))
            else:
                self.events.publish(MillCommandSent(t_s=t, command="stop", source="run_failed"))
        self.mill_link.close()
        f = self.frames_box.get()
        self.events.publish(RunStop(t_s=f.t_s, frames=f.n_frames, workers_alive=alive, failure=self.failure))

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

    def recalibrate(self) -> None:
        self.events.publish(OperatorAction(t_s=self.now_s(), action="recalibrate"))
        self.twin.request("calibrate")

    def reseed_twin(self) -> None:
        self.events.publish(OperatorAction(t_s=self.now_s(), action="reseed"))
        self.twin.request("reseed")

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
        th = threading.Thread(target=self._relearn, args=(image.copy(),), name="relearn", daemon=True)
        self._threads.append(th)
        th.start()
        return "re-learning the classes from the live bed ..."

    def _relearn(self, image: np.ndarray) -> None:
        from vision.config import MeterConfig
        from vision.suggest import relearn_classes

        try:
            cfg = relearn_classes(self._meter_config or MeterConfig(self._classes), [image])
            meter = cfg.make_meter(roi=self._roi)
        except VisionError as exc:
            self.events.publish(OperatorRejected(t_s=self.now_s(), action="relearn_classes", error=str(exc)))
            return
        self._meter_config = cfg
        self._camera_commands.put(SwapClasses(meter))
        self.events.publish(OperatorAction(t_s=self.now_s(), action="relearn_classes_swapped"))

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
        if not self.whatif.submit(rpm_list, duration, reason="operator"):
            self.events.publish(OperatorRejected(t_s=t, action="whatif", error="a study is already running"))

    def _auto_study_result(self, error: str | None) -> None:
        """A failed AUTO what-if study is a fault: an alarm, and AUTO's safe state (the twin
        in doubt) until a study succeeds or the operator sets a mode again."""
        t = self.now_s()
        if error is not None:
            self.events.publish(FaultRaised(t_s=t, fault="whatif_failed",
                                            message=f"AUTO's what-if study failed: {error}"))
            self.supervisor.doubt_twin("whatif", f"what-if study failed ({error})")
        else:
            self.supervisor.trust_twin("whatif")
            self.events.publish(FaultCleared(t_s=t, fault="whatif_failed", message="an AUTO what-if study succeeded"))

    def cancel_whatif(self) -> bool:
        """Abandon the operator's running or waiting what-if study; True when there was one."""
        cancelled = self.whatif.cancel()
        self.events.publish(OperatorAction(t_s=self.now_s(), action="whatif_cancel", cancelled=cancelled))
        return cancelled

    @property
    def limits(self) -> Limits:
        """The run's one set of limits (the supervisor's): dashboard and what-if read them."""
        return self._limits


# Supervisor settings of the live loop. The camera MI of a well-mixed bed is ~0.93-0.95;
# radial segregation at 5 rpm brings it to ~0.80-0.85 (vision MI of the demo plant).
LOOP_SUPERVISOR: dict[str, float | int | bool] = dict(
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
# needs no loop-specific tuning; issue 21). ``Seams.trend`` overrides.
LOOP_TREND: dict[str, float | int | bool] = {}


# Endpoint settings of the live loop (control.endpoint; docs/endpoint.md): a mixed bed's camera MI is
# ~0.93-0.95, a radially segregated one ~0.80-0.85. ``--target-mi`` and ``Seams.endpoint`` override.
LOOP_ENDPOINT: dict[str, float | int | bool] = dict(target_mi=0.9)


def endpoint_config(config: RunConfig | None = None, seams: Seams | None = None) -> EndpointConfig:
    """The endpoint detector's settings for a run (``RunConfig.endpoint``, ``RunConfig.target_mi``, then
    ``seams.endpoint`` override ``LOOP_ENDPOINT``, which overrides ``EndpointConfig``'s defaults)."""
    target = {} if config is None or config.target_mi is None else {"target_mi": float(config.target_mi)}
    options = {} if config is None else dict(config.endpoint)  # --endpoint-* (twin.config.endpoint_options)
    over = seams.endpoint if seams is not None else {}
    return endpoint_settings({**LOOP_ENDPOINT, **options, **target, **over})


def trend_config(seams: Seams | None = None) -> TrendConfig:
    """The Kalman trend's settings for a run (``seams.trend`` overrides)."""
    return TrendConfig(**{**LOOP_TREND, **(seams.trend if seams is not None else {})})  # type: ignore[arg-type]


def supervisor_config(
    seams: Seams | None = None, critical_rpm: float | None = None, config: RunConfig | None = None
) -> SupervisorConfig:
    """The supervisor's settings for a run (``seams.supervisor`` overrides); the critical
    speed comes from the twin's drum (``critical_rpm``, the mixer's drum's; default the
    paper's: ``sim.recipe``, the one formula); AUTO's objective, target MI and stop at the
    endpoint from ``config`` (``RunConfig``)."""
    from sim.recipe import PAPER_DRUM

    overrides = seams.supervisor if seams is not None else {}
    crit = PAPER_DRUM.critical_rpm if critical_rpm is None else float(critical_rpm)
    batch: dict[str, object] = {}
    if config is not None:  # one target: the endpoint's
        batch = {"objective": config.objective, "stop_at_endpoint": config.stop_at_endpoint,
                 "target_mi": endpoint_config(config, seams).target_mi}
    return SupervisorConfig(**{"critical_rpm": crit, **LOOP_SUPERVISOR, **batch, **overrides})  # type: ignore[arg-type]


def _overlay(image: np.ndarray, reading: Reading) -> np.ndarray:
    from vision.overlay import draw_overlay

    return draw_overlay(image, reading)


# -- test seams and the demo's start ------------------------------------------------------------
Overrides = Mapping[str, float | int | bool]
"""Field overrides of a settings dataclass (names checked by the dataclass: a typo is a TypeError)."""


@dataclass(frozen=True)
class Seams:
    """What a test (or a bench) may change about a run, typed; a production run uses the
    defaults. ``supervisor``/``trend``: overrides of the loop's ``SupervisorConfig`` /
    ``TrendConfig``; ``calibrate``: keyword arguments of the twin's calibration
    (``sim.calibrate``); ``whatif_study``: runs what-if jobs instead of the process pool;
    ``mismatch``: the twin-against-camera tolerance; ``plant_watchdog_s``: the demo board's
    watchdog (wall s); ``on_started(loop, plant, dashboard)``: called once everything runs
    (fault injection); ``crash``: a bug injected into one worker (:class:`WorkerCrash`)."""

    supervisor: Overrides = field(default_factory=dict)
    trend: Overrides = field(default_factory=dict)
    endpoint: Overrides = field(default_factory=dict)
    calibrate: Overrides = field(default_factory=dict)
    whatif_study: Study | None = None
    mismatch: MismatchTolerance = field(default_factory=MismatchTolerance)
    plant_watchdog_s: float | None = None
    on_started: Callable[[LiveLoop, DemoPlant | None, Dashboard | None], None] | None = None
    crash: WorkerCrash | None = None


WORKERS = ("mill", "camera", "process", "twin", "whatif", "supervisor")
"""The live loop's workers, one thread each (their thread is ``drumtwin-<name>``)."""


@dataclass(frozen=True)
class WorkerCrash:
    """A bug injected into one worker (``Seams.crash``): from run time ``at_s`` on, the
    worker's next pass on its own thread raises ``RuntimeError(message)`` (camera: its next
    frame; process: its next reading; mill: its next cycle; twin, what-if, supervisor: their
    next pass)."""

    worker: str
    at_s: float = 0.0
    message: str = "injected crash"

    def __post_init__(self) -> None:
        if self.worker not in WORKERS:
            raise ValueError(f"no worker {self.worker!r} (one of {', '.join(WORKERS)})")


class DemoStart:
    """The demo's start plan: once the mill worker has read the board (its first connected
    ``MillState`` record on the run's bus, at most ``connect_timeout_s`` wall), the plant's
    front panel spins the drive at its start rpm and the demo's operator presses Start (the
    loop then feeds the board's watchdog). A hardware run has no plan: its operator starts
    the mill from the dashboard."""

    def __init__(self, plant: DemoPlant, connect_timeout_s: float = 20.0) -> None:
        self.plant = plant
        self.connect_timeout_s = connect_timeout_s
        self._connected = threading.Event()

    def record(self, rec: Record) -> None:
        """The bus subscriber: the mill is connected."""
        if isinstance(rec, MillState) and rec.connected:
            self._connected.set()

    def execute(self, loop: LiveLoop) -> None:
        end = time.monotonic() + self.connect_timeout_s
        while not self._connected.wait(0.05) and time.monotonic() < end and not loop.stop_event.is_set():
            pass
        self.plant.start_drive()
        loop.start_mill()


def versions() -> dict[str, str]:
    """The versions a run's results depend on (``RunStart.versions``, metadata.json)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for pkg in ("drumtwin", "numpy", "opencv-python-headless", "pymunk", "viser", "numba", "filterpy", "pyserial",
                "pymodbus"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def _paced(frames: Iterator[Frame], clock: RunClock) -> Iterator[Frame]:
    """Replay a recording at its own speed (``frame.t_s`` on the run clock)."""
    t0 = None
    for f in frames:
        t0 = f.t_s if t0 is None else t0
        if not clock.sleep_until(f.t_s - t0):
            return
        yield f


def check_scheduler_answers(address: str, timeout_s: float = 3.0) -> None:
    """TwinError (one line) unless something accepts a TCP connection at the Dask
    scheduler ``address`` within ``timeout_s`` (a dead or garbage address is refused at
    the start of the run, not found by the first what-if study in AUTO)."""
    import socket

    from twin.config import check_scheduler

    host, port = check_scheduler(address)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        raise TwinError(f"--scheduler {address}: no Dask scheduler answers ({exc.strerror or exc})") from None


def _wait_plain(loop: LiveLoop) -> None:
    loop.wait(loop.config.duration_s)


def run_live(
    cfg: RunConfig,
    seams: Seams | None = None,
    *,
    wait: Callable[[LiveLoop], None] = _wait_plain,
    on_dashboard: Callable[[str], None] | None = None,
) -> Summary:
    """The one composition root of a run, demo and hardware alike: builds the plant (demo)
    or opens the camera, the mill link, the run log, the dashboard's state, the loop and the
    dashboard; starts them in order (the demo's :class:`DemoStart` plan once the loop runs);
    ``wait(loop)`` blocks until the run is over (the CLI's progress bar; default: the
    duration); then stops everything and returns the :class:`Summary`.

    The mill link is opened first: a URL that cannot be opened raises ``ConnectionError``
    before anything else starts (the CLI exits 2). A run that had to end (its log could not
    be written, an essential worker crashed: ``LiveLoop.failure``) raises ``TwinError`` once
    it is shut down. ``on_dashboard(url)``: told the dashboard's address once it serves.
    """
    from twin.demo import DemoPlant, PlantConfig
    from twin.runlog import RunLog, default_run_dir

    seams = seams or Seams()
    if cfg.scheduler is not None:
        check_scheduler_answers(cfg.scheduler)  # before anything starts: one line, exit 2
    clock = RunClock(cfg.speed)
    classes = None
    roi = None
    mixer = None
    mc = None
    if cfg.meter_config is not None:
        from sim.mixer import mixer_from_config
        from vision.config import load_config

        mc = load_config(cfg.meter_config)
        if mc.endpoint_table:  # [endpoint] under the --endpoint-* options
            from twin.config import config_endpoint

            cfg = replace(cfg, endpoint=config_endpoint(mc.endpoint_table, mc.source, cfg.endpoint))
        classes, roi = mc.classes, mc.roi
        mixer = mixer_from_config(mc)  # checked in any case; the demo's plant and twin stay the paper's
        mixer = None if cfg.demo else mixer
    if cfg.engine is not None:
        from sim.engine import engine_for
        from sim.mixer import paper_mixer

        engine_for(paper_mixer() if mixer is None else mixer, cfg.engine)
    plant: DemoPlant | None = None
    mill: MillLink | None = None
    runlog: RunLog | None = None
    loop: LiveLoop | None = None
    dash: Dashboard | None = None
    summary: Summary | None = None
    t_wall = time.monotonic()
    try:
        frames: Iterable[Frame] | None
        if cfg.demo:
            plant_cfg = PlantConfig(case=cfg.case, seed=cfg.seed, start_rpm=cfg.start_rpm, fps=cfg.camera_fps,
                                    size_px=cfg.frame_px, drive=cfg.drive)
            if seams.plant_watchdog_s is not None:
                plant_cfg = replace(plant_cfg, watchdog_s=seams.plant_watchdog_s)
            plant = DemoPlant(plant_cfg, clock)
            frames, mill_url, roi = plant.frames(), plant.url, plant.roi
        else:
            mill_url = str(cfg.mill)
            frames = None
            if mc is not None:  # the config's [drive] hz_per_rpm goes into a modbus: URL (docs/drives.md)
                from control.modbus.link import config_mill_url

                mill_url = config_mill_url(mill_url, mc.drive_table, f"config {mc.source}")
        mill = open_mill(mill_url)  # ConnectionError now, before any log or thread exists
        if frames is None:
            from vision.sources import open_source

            frames = _paced(open_source(str(cfg.video)), clock) if cfg.video is not None else open_source(cfg.camera)
        runlog = RunLog(cfg.log_dir or default_run_dir())  # columns: twin.records.FRAME_COLUMNS
        started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        runlog.set_metadata(config=cfg.to_metadata(), versions=versions(), started=started)
        if plant is not None:
            runlog.set_metadata(plant=asdict(plant.config), mill_url="emulator pty")
        state = LiveState()
        loop = LiveLoop(cfg, frames, mill, runlog, state, clock=clock, roi=roi, classes=classes, mixer=mixer,
                        meter_config=mc, seams=seams)
        if mixer is not None:
            runlog.set_metadata(mixer=mixer_metadata(mixer))
        if cfg.dashboard:
            from twin.dashboard import Dashboard

            dash = Dashboard(
                state, loop, host=cfg.host, port=cfg.port, control_token=cfg.control_token,
                update_hz=cfg.dashboard_hz, on_event=loop.events.publish, now_s=loop.now_s,
                limits=loop.limits, estop_needs_token=cfg.estop_needs_token,
            ).start()
            if on_dashboard is not None:
                on_dashboard(dash.url)
            runlog.set_metadata(dashboard_url=dash.url)
        plan = DemoStart(plant) if plant is not None else None
        if plan is not None:
            loop.events.bus.subscribe(plan.record)
        loop.warm_up()  # compile before the clock runs, not while the camera does
        clock.restart()  # run time 0 = the workers start (the plant's first frame is due now)
        loop.start()
        if plan is not None:
            plan.execute(loop)
        if seams.on_started is not None:
            seams.on_started(loop, plant, dash)
        wait(loop)
    finally:
        clock.stop.set()
        if loop is not None:
            loop.stop()  # joins the workers, closes the what-if pool and the mill link
        elif mill is not None:
            mill.close()
        if dash is not None:
            dash.stop()
        if plant is not None:
            plant.close()
        if runlog is not None:
            if loop is not None:
                summary = loop.summary(time.monotonic() - t_wall)
                loop.events.metadata(summary=asdict(summary))
            runlog.close()
    if loop is not None and loop.failure is not None:
        raise RunFailed(f"the run stopped: {loop.failure} (log in {loop.runlog.paths.directory})", loop.exit_code)
    assert summary is not None  # the run log exists once the loop does
    return summary


def mixer_metadata(mixer: Mixer) -> dict[str, object]:
    """The user's mixer for ``metadata.json``."""
    from sim.mixer import resolve

    return {"classes": [{"name": k.name, "count": k.count, "diameter_mm": 1e3 * k.shape.diameter_m,
                         "shape": k.shape.kind} for k in resolve(mixer)],
            "drum_diameter_mm": 1e3 * mixer.drum.diameter_m, "fill": mixer.fill,
            "direction": mixer.direction, "monolayer": mixer.monolayer}


__all__ = ["LOOP_ENDPOINT", "LOOP_SUPERVISOR", "WORKERS", "DemoStart", "LiveLoop", "Seams", "Summary", "WorkerCrash",
           "crash_summary", "endpoint_config", "open_mill", "run_live", "supervisor_config", "trend_config"]

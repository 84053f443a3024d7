"""The run's threads and their lifecycle: :class:`LiveLoop` builds the workers (``twin/live/``),
wires them, starts and joins their threads, and ends the run when it can no longer keep its
rules. Nothing else in the application starts a thread of the loop.

Workers, one thread each, none of which sees the loop:

* **camera** (``CameraWorker``): frames -> ``Meter.measure`` -> readings queue (bounded, drops
  the oldest: the camera is never blocked); publishes ``CameraInfo``.
* **process** (``ProcessWorker``): readings -> Kalman trend + the paper's moving average -> one
  ``FrameReading`` (CSV row and plot point); publishes ``FrameInfo``.
* **mill** (``MillWorker``): the one poller of the mill link; sends the commands it is given,
  never anything else; publishes ``MillSnapshot``.
* **twin** (``TwinWorker``): calibrates, seeds and runs the physics twin.
* **whatif** (``WhatIfWorker``): twin studies for AUTO and the operator.
* **supervisor** (``SupervisorWorker``): the pure supervisor on run time, alarms, operator
  commands; decisions become mill commands.

They read each other only through a ``RunView`` of immutable snapshots, report through one
event sink (run log + dashboard alarms) and take typed commands on their own queues; the
operator's commands come through ``loop.controls`` (``twin.run.operator.Operator``).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
import traceback as tb
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from control.decision import Mode
from control.endpoint import EndpointDetector
from control.errors import ControlError
from control.limits import Limits
from control.supervisor import Supervisor
from control.trend import MITrend
from sim.errors import SimError
from twin.clock import RunClock
from twin.config import RunConfig
from twin.errors import EXIT_BAD_INPUT, EXIT_WORKER_CRASHED, TwinError
from twin.live.camera import READINGS_MAX, SLOPES_MAX, CameraReading, CameraWorker, ProcessWorker
from twin.live.commands import Recalibrate, Reseed, SwapClasses
from twin.live.events import RunEvents
from twin.live.mill import MillLink, MillWorker
from twin.live.mismatch import MismatchMonitor
from twin.live.snapshots import CameraInfo, FrameInfo, Latest, MillSnapshot, RunView, TwinInfo
from twin.live.supervise import SupervisorWorker
from twin.live.twin import TwinSettings, TwinWorker
from twin.live.whatif import WhatIfWorker
from twin.records import (
    FaultCleared,
    FaultRaised,
    MillCommandDropped,
    MillCommandSent,
    MillState,
    ModeSet,
    RunStart,
    RunStop,
)
from twin.run.metadata import mixer_metadata, versions
from twin.run.operator import Operator
from twin.run.settings import Seams, endpoint_config, supervisor_config, trend_config
from twin.runlog import RunLog
from twin.state import LiveState
from vision.errors import VisionError
from vision.meter import Meter, Reading

if TYPE_CHECKING:
    from sim.mixer import Mixer
    from vision.colours import ColourClass
    from vision.config import MeterConfig
    from vision.roi import DrumROI
    from vision.sources import Frame

log = logging.getLogger("drumtwin.loop")

WORKERS = ("mill", "camera", "process", "twin", "whatif", "supervisor")
"""The live loop's workers, one thread each (their thread is ``drumtwin-<name>``)."""

EXPECTED_ERRORS: tuple[type[Exception], ...] = (VisionError, SimError, ControlError, TwinError, OSError)
"""A worker stopped by bad input or its environment (no drum in the frames, a camera gone):
a one-line fault, no traceback. Anything else is a bug and logged with its traceback."""

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


def crash_summary(exc: BaseException) -> str:
    """An exception in one line: ``Type: first line of its message``."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


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


def _overlay(image: np.ndarray, reading: Reading) -> np.ndarray:
    from vision.overlay import draw_overlay

    return draw_overlay(image, reading)


class LiveLoop:
    """The composition root of the workers (see module doc). ``frames``: the camera (an iterable
    of ``vision.sources.Frame``); ``mill``: an opened mill link (``twin.run.main.open_mill``);
    ``runlog``: the run's log; ``roi``/``classes``/``meter_config``: the camera meter's drum ROI,
    colour classes or whole set-up when known; ``mixer``: the twin's (None: the paper's)."""

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
        self.seams = seams or Seams()
        self.config = config
        self.mixer = mixer  # None: the paper's (the demo's twin)
        self.clock = clock or RunClock(1.0)
        self.stop_event = self.clock.stop
        self.runlog = runlog
        self.state = state or LiveState()
        self.mill_link = mill
        self.failure: str | None = None  # why the run had to end (see _fail)
        self.exit_code = EXIT_BAD_INPUT  # the CLI's exit code when it had to (see _fail)
        self._fail_lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self.events = RunEvents(runlog, self.state, on_failure=self._fail)
        # snapshots (one writer each) and the view the workers read them through
        self.camera_box: Latest[CameraInfo] = Latest(CameraInfo())
        self.frames_box: Latest[FrameInfo] = Latest(FrameInfo())
        self.mill_box: Latest[MillSnapshot] = Latest(MillSnapshot())
        self.twin_box: Latest[TwinInfo] = Latest(TwinInfo())
        self.mode_box: Latest[str] = Latest(config.mode)
        self.supervisor_alive: Latest[float] = Latest(time.monotonic())  # its last pass (wall, monotonic s)
        self.view = RunView(self.clock.speed, self.camera_box, self.frames_box, self.mill_box, self.twin_box,
                            self.mode_box, self.clock.now_s)
        sup_config = supervisor_config(self.seams, None if mixer is None else mixer.drum.critical_rpm, config)
        self.limits: Limits = sup_config.limits  # the run's one set (the supervisor's): dashboard, what-if, twin
        meter = meter_config.make_meter(roi=roi) if meter_config is not None else (
            Meter(roi=roi) if classes is None else Meter(roi=roi, classes=tuple(classes)))
        self._classes = tuple(meter.colour_classes)
        camera_commands: queue.SimpleQueue[SwapClasses] = queue.SimpleQueue()
        self._build_workers(frames, meter, camera_commands, overlay, Supervisor(sup_config, mode=Mode(config.mode)))
        self.controls = Operator(
            now_s=self.now_s, events=self.events, mill=self.mill, mill_box=self.mill_box,
            supervisor=self.supervisor, twin=self.twin, whatif=self.whatif, limits=self.limits,
            camera_box=self.camera_box, camera_commands=camera_commands, spawn=self._spawn,
            meter_config=meter_config, classes=self._classes, roi=roi,
        )  # the dashboard's Controls: typed commands onto the workers' queues
        self.events.publish(ModeSet(t_s=0.0, mode=config.mode))
        self.events.publish(MillState(t_s=0.0, state="connecting", connected=False, setpoint_rpm=None,
                                      actual_rpm=None))

    def _build_workers(
        self, frames: Iterable[Frame], meter: Meter, camera_commands: queue.SimpleQueue[SwapClasses],
        overlay: Callable[[np.ndarray, Reading], np.ndarray] | None, supervisor: Supervisor,
    ) -> None:
        """The six workers, wired (camera -> process -> twin; mill; what-if; supervisor)."""
        config, seams, faults = self.config, self.seams, self.seams.faults
        readings: queue.Queue[CameraReading] = queue.Queue(maxsize=READINGS_MAX)  # bounded: drops the oldest
        slopes: queue.Queue[tuple[float, float]] = queue.Queue(maxsize=SLOPES_MAX)
        self.camera = CameraWorker(
            frames, meter, readings, self.camera_box, self.state,
            overlay_hz=config.dashboard_hz if config.dashboard else 0.0, overlay=overlay or _overlay,
            commands=camera_commands, faults=faults,
        )
        self.process = ProcessWorker(
            readings, MITrend(trend_config(seams)), self.frames_box, self.view, self.events, slopes,
            camera_fps=self.camera.fps.rate, endpoint=EndpointDetector(endpoint_config(config, seams)),
            faults=faults,
        )
        self.mill = MillWorker(self.mill_link, self.events, self.mill_box, self.view.now_s, faults=faults)
        self.twin = TwinWorker(
            TwinSettings(
                case=config.case, seed=config.seed, start_rpm=config.start_rpm, size_px=config.frame_px,
                classes=self._classes, mixer=self.mixer, engine=config.engine,
                calibrate_kwargs={"mixer": self.mixer, "engine": config.engine, **seams.calibrate},
                limits=self.limits,  # calibrated only where the supervisor may run the drum
            ),
            self.view, self.events, self.state, self.twin_box, slopes, faults=faults,
        )
        self.whatif = WhatIfWorker(
            self.view, self.events, self.state, scheduler=config.scheduler, workers=config.whatif_workers,
            study=seams.whatif_study, target_mi=endpoint_config(config, seams).target_mi,
            reseed_twin=lambda: self.twin.request(Reseed()), faults=faults,
        )
        self.whatif.on_auto_result = self._auto_study_result
        self.supervisor = SupervisorWorker(
            supervisor, self.view, self.events, self.mill.submit, self.whatif, self.mode_box,
            period_s=config.supervisor_period_s, speed=self.clock.speed, alive=self.supervisor_alive,
            mismatch=MismatchMonitor(seams.mismatch), on_twin_mismatch=lambda: self.twin.request(Recalibrate()),
            faults=faults,
        )

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
        """Log the run's start, then start the workers' threads and the supervisor's watch."""
        from sim.mixer import paper_mixer

        self.events.publish(RunStart(
            t_s=0.0, mode=self.config.mode, mill=getattr(self.mill_link, "url", ""),
            config=self.config.to_metadata(), versions=versions(),
            mixer=mixer_metadata(self.mixer if self.mixer is not None else paper_mixer()),
        ))
        override = getattr(self.mill_link, "safety_override", None)  # a drive run against its check
        if override:
            self.events.publish(FaultRaised(t_s=0.0, fault="mill_safety_override",
                                            message=f"operator override: {override}"))
        if self.config.mode == "auto":
            self.whatif.warm_up()
        runs: dict[str, Callable[[threading.Event], None]] = {
            "mill": self.mill.run, "camera": self.camera.run, "process": self.process.run, "twin": self.twin.run,
            "whatif": self.whatif.run, "supervisor": self.supervisor.run,
        }
        for name in WORKERS:
            self._spawn(f"drumtwin-{name}", self._guard(name, runs[name]))
        self._spawn("drumtwin-watch", self._watch)
        return self

    def run_beside(self, name: str, job: Callable[[threading.Event], None]) -> None:
        """A one-off job of the run on its own thread ``drumtwin-<name>`` (the rig's history read
        from the catalogue): started now, given the run's stop event, joined by :meth:`stop`. No
        worker: nothing depends on it, and it catches what it meets itself."""
        self._spawn(f"drumtwin-{name}", lambda: job(self.stop_event))

    def _spawn(self, name: str, target: Callable[[], None]) -> None:
        """Start ``target`` on a daemon thread of the run (joined by :meth:`stop`)."""
        th = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(th)
        th.start()

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

    def now_s(self) -> float:
        """Run time (see ``RunView``)."""
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
        waited for. Then the loop, owning the link again, stops the mill when this run had
        control of it (a command of this run went through: ``run_end``) or had to end
        (``failure``: ``run_failed``); a stop is never gated (docs/safety.md), and the board's
        watchdog or the drive's comm-loss trip remains the stop of last resort. A mill this
        run never commanded (OFF, or a manual run that sent nothing) is left as it was.
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
        if self.failure is not None or self.mill.controlling:  # the workers are gone: the link is ours
            t, source = self.now_s(), "run_failed" if self.failure is not None else "run_end"
            try:
                self.mill_link.stop()
            except (OSError, ControlError) as exc:
                self.events.publish(MillCommandDropped(t_s=t, command="stop", source=source, reason=str(exc)))
            else:
                self.events.publish(MillCommandSent(t_s=t, command="stop", source=source))
        self.mill_link.close()
        f = self.frames_box.get()
        twin = self.twin_box.get()
        self.events.publish(RunStop(t_s=f.t_s, frames=f.n_frames, workers_alive=alive, failure=self.failure,
                                    energy_j=twin.energy_j if twin.updated_s is not None else None))

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


__all__ = ["ESSENTIAL_WORKERS", "SUPERVISOR_STALL_S", "WORKERS", "LiveLoop", "Summary", "crash_summary"]

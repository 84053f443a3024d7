"""The live loop: camera -> meter -> trend -> supervisor -> mill, with the twin beside it.

Threads (all daemons, all stopped by one event):

* **camera**: frames from the source at their own rate -> ``Meter.measure`` -> the
  readings queue (bounded; when full the oldest reading is dropped, so the camera is
  never blocked by anything downstream).
* **process**: readings -> Kalman trend (+ the paper's moving average) -> CSV row ->
  plot point. Sets the loop's run time ``t_s`` (the newest frame's time).
* **mill**: the only thread that talks to the serial driver: polls the status, sends
  queued commands (set rpm, start, stop), notices lost and restored links.
* **twin**: calibrates the twin from the camera's slope angle, seeds it from the live
  frame, then keeps it in step with run time at the mill's actual rpm; renders and
  measures it with the same kind of meter as the camera.
* **supervisor**: every ``supervisor_period_s`` of run time: ``Supervisor.step`` with
  the trend, the link, vision and twin health; decisions become mill commands and
  events. Twin predictions for AUTO come from ``WhatIfRunner`` (a background study in
  worker processes or on a Dask cluster) and never block this thread.

Everything the dashboard shows goes through ``LiveState``; every fault, decision and
calibration is an event in the run log.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from control.driver import MillClient
from control.supervisor import Action, AsyncPredictor, Mode, Supervisor, SupervisorConfig, SupervisorInputs
from control.trend import MITrend, TrendConfig
from twin.clock import Cadence, RunClock
from twin.config import RunConfig
from twin.runlog import RunLog
from twin.state import LiveState
from twin.twinrun import Rate, TwinRunner, WhatIfRunner
from vision.meter import Meter, Reading
from vision.smoothing import MovingAverage

log = logging.getLogger("drumtwin.loop")

VISION_STALE_S = 3.0  # run seconds without a frame / valid reading -> alarm
MILL_POLL_S = 0.1  # wall seconds between status polls


@dataclass
class _Reading:
    t_s: float
    frame: int
    reading: Reading


@dataclass
class MillView:
    """What the loop knows about the mill (updated by the mill thread)."""

    connected: bool = False
    setpoint_rpm: float = float("nan")
    actual_rpm: float = float("nan")
    running: bool = False
    fault: str | None = None
    last_ok_wall: float = 0.0

    @property
    def state(self) -> str:
        if not self.connected:
            return "link lost"
        if self.fault:
            return f"fault {self.fault}"
        return "running" if self.running else "stopped"


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


class LiveLoop:
    """Wires camera, meter, trend, supervisor, mill and twin (see module doc).

    ``frames`` is the camera (an iterator of ``vision.sources.Frame``); ``mill_url`` the
    serial URL; ``roi`` the drum ROI if known (else the meter detects it).
    Implements the dashboard's ``Controls`` protocol.
    """

    def __init__(
        self,
        config: RunConfig,
        frames: Iterator[Any],
        mill_url: str,
        runlog: RunLog,
        state: LiveState | None = None,
        *,
        clock: RunClock | None = None,
        roi: Any = None,
        classes: Sequence[Any] | None = None,
    ) -> None:
        self.config = config
        self.clock = clock or RunClock(1.0)
        self.stop_event = self.clock.stop
        self.frames = frames
        self.runlog = runlog
        self.state = state or LiveState()
        self.roi = roi
        meter_kwargs: dict[str, Any] = {}
        if classes is not None:
            meter_kwargs["classes"] = tuple(classes)
        self.classes = tuple(classes) if classes is not None else None
        self.meter = Meter(roi=roi, **meter_kwargs)
        self.trend = MITrend(trend_config(config))
        self.ma = MovingAverage(150)
        self.mill = MillClient(mill_url, heartbeat_s=0.25, connect=False)
        self.mill_view = MillView()
        self._mill_cmds: queue.Queue[tuple[str, float]] = queue.Queue()
        self._readings: queue.Queue[_Reading] = queue.Queue(maxsize=512)
        self.whatif = WhatIfRunner(self, scheduler=config.scheduler, workers=config.whatif_workers)
        self.supervisor = Supervisor(
            supervisor_config(config), predictor=AsyncPredictor(self.whatif.predict), mode=Mode(config.mode)
        )
        self.twin = TwinRunner(self)
        self._lock = threading.Lock()
        self.t_s = 0.0  # run time of the newest processed frame
        self.last_valid_t = -math.inf
        self.last_frame_wall = time.monotonic()
        self.last_image: np.ndarray | None = None
        self.last_estimate: Any = None
        self.last_reading: Reading | None = None
        self._sup_lock = threading.RLock()
        self.manual_rpm = float(config.start_rpm)
        self.want_running = True  # the operator has not stopped the mill
        self._estop = threading.Event()
        self.n_frames = 0
        self.n_decisions = 0
        self.n_faults = 0
        self._faults_active: set[str] = set()
        self._camera_fps = Rate()
        self._threads: list[threading.Thread] = []
        self.state.update_numbers(mode=config.mode, rpm_setpoint=config.start_rpm)

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> LiveLoop:
        self.runlog.event("start", 0.0, mode=self.config.mode, mill=self.mill.url)
        if self.config.mode == "auto":
            self.whatif.warm_up()
        for name, target in (
            ("camera", self._camera_loop),
            ("process", self._process_loop),
            ("mill", self._mill_loop),
            ("twin", self.twin.run),
            ("supervisor", self._supervisor_loop),
        ):
            th = threading.Thread(target=self._guard(name, target), name=f"drumtwin-{name}", daemon=True)
            th.start()
            self._threads.append(th)
        return self

    def _guard(self, name: str, fn):
        def run() -> None:
            try:
                fn()
            except Exception as exc:  # a crashed thread is a fault, never silent
                log.exception("thread %s crashed", name)
                self.fault(f"thread_{name}", f"{name} thread crashed: {exc}")

        return run

    def wait(self, duration_s: float | None) -> None:
        """Block until ``duration_s`` of run time has passed (None: until stopped)."""
        while not self.stop_event.is_set():
            if duration_s is not None and self.now_s() >= duration_s:
                return
            self.stop_event.wait(0.05)

    def stop(self) -> None:
        """Stop all threads and close the mill link (the mill keeps its last setpoint)."""
        self.stop_event.set()
        for th in self._threads:
            th.join(timeout=10)
        self.whatif.close()
        self.mill.close()
        self.runlog.event("stop", self.t_s, frames=self.n_frames)

    def summary(self, wall_s: float = 0.0) -> Summary:
        est = self.last_estimate
        level = float(est.level) if est is not None else float("nan")
        return Summary(
            final_trend_mi=level,
            final_rpm=float(self.mill_view.actual_rpm),
            decisions=self.n_decisions,
            faults=self.n_faults,
            log_dir=str(self.runlog.paths.directory),
            frames=self.n_frames,
            run_time_s=self.t_s,
            wall_time_s=wall_s,
            camera_fps=self._camera_fps.rate(),
            twin_fps=self.twin.fps.rate(),
        )

    # -- faults ----------------------------------------------------------------------------
    def fault(self, key: str, message: str, **data: Any) -> None:
        """Raise a named fault once (event + alarm) until ``clear_fault``."""
        with self._lock:
            if key in self._faults_active:
                return
            self._faults_active.add(key)
            self.n_faults += 1
        self.runlog.event("fault", self.t_s, fault=key, message=message, **data)
        self.state.set_alarm(key, message)

    def clear_fault(self, key: str, message: str, **data: Any) -> None:
        with self._lock:
            if key not in self._faults_active:
                return
            self._faults_active.discard(key)
        self.runlog.event("recovered", self.t_s, fault=key, message=message, **data)
        self.state.set_alarm(key, None)

    # -- camera ----------------------------------------------------------------------------
    def _camera_loop(self) -> None:
        want_overlay = self.config.dashboard
        overlay = Cadence(1.0 / max(self.config.dashboard_hz, 1.0))  # wall clock
        for frame in self.frames:
            if self.stop_event.is_set():
                return
            reading = self.meter.measure(frame.image)
            self.last_image = frame.image
            self.last_frame_wall = time.monotonic()
            self._camera_fps.tick()
            item = _Reading(float(frame.t_s), int(frame.index), reading)
            try:
                self._readings.put_nowait(item)
            except queue.Full:  # never block the camera: drop the oldest
                try:
                    self._readings.get_nowait()
                except queue.Empty:
                    pass
                self._readings.put_nowait(item)
            if want_overlay and overlay.due(time.monotonic()):
                self.state.publish_camera(_overlay(frame.image, reading))
        if not self.stop_event.is_set():
            self.fault("camera_ended", "the camera source ended")

    # -- processing ------------------------------------------------------------------------
    def _process_loop(self) -> None:
        while not self.stop_event.is_set():
            try:
                item = self._readings.get(timeout=0.1)
            except queue.Empty:
                continue
            self._process(item)

    def _process(self, item: _Reading) -> None:
        r = item.reading
        mv = self.mill_view
        rpm = mv.actual_rpm if math.isfinite(mv.actual_rpm) else 0.0
        est = self.trend.update(item.t_s, r.mi, rpm)
        self.last_estimate = est
        self.last_reading = r
        ma = self.ma.update(r.mi) if r.valid else self.ma.value
        self.t_s = item.t_s
        self.n_frames += 1
        if r.valid:
            self.last_valid_t = item.t_s
            self.twin.observe_slope(item.t_s, r.slope_deg)
        tw = self.twin.latest
        row = {
            "t_s": item.t_s,
            "frame": item.frame,
            "mi": r.mi,
            "mi_sigmoid": r.mi_sigmoid,
            "mi_linear": r.mi_linear,
            "d_px": r.d_px,
            "dsigma_px": r.dsigma_px,
            "concentration": r.concentration,
            "slope_deg": r.slope_deg,
            "valid": r.valid,
            "trend_mi": est.level,
            "trend_lo95": est.lo95,
            "trend_hi95": est.hi95,
            "trend_rate": est.rate,
            "ma_mi": ma,
            "twin_mi": tw.get("mi"),
            "twin_slope_deg": tw.get("slope_deg"),
            "rpm_setpoint": mv.setpoint_rpm,
            "rpm_actual": mv.actual_rpm,
            "mode": self.mode_name,
            "flags": r.flags,
        }
        self.runlog.frame(row)
        self.state.publish_point(row)
        self.state.update_numbers(
            t_s=item.t_s,
            mi=r.mi,
            d_px=r.d_px,
            dsigma_px=r.dsigma_px,
            concentration=r.concentration,
            slope_deg=r.slope_deg,
            trend_mi=est.level,
            camera_fps=self._camera_fps.rate(),
        )

    # -- mill ------------------------------------------------------------------------------
    def _mill_loop(self) -> None:
        mv = self.mill_view
        while not self.stop_event.is_set():
            if self._estop.is_set():  # jumps the queue: drop pending wishes, stop now
                self._estop.clear()
                while not self._mill_cmds.empty():
                    self._mill_cmds.get_nowait()
                cmd, arg = "stop", 0.0
            else:
                try:
                    cmd, arg = self._mill_cmds.get(timeout=MILL_POLL_S)
                except queue.Empty:
                    cmd, arg = "status", 0.0
            try:
                if cmd == "set_rpm":
                    self.mill.set_rpm(arg)
                    mv.setpoint_rpm = arg
                elif cmd == "start":
                    self.mill.start()
                elif cmd == "stop":
                    self.mill.stop()
                st = self.mill.status()
                mv.setpoint_rpm, mv.actual_rpm = float(st.setpoint_rpm), float(st.actual_rpm)
                mv.running, mv.fault = bool(st.running), st.fault
                mv.last_ok_wall = time.monotonic()
                if not mv.connected:
                    mv.connected = True
                    self.clear_fault("mill_link", "mill link restored", url=self.mill.url)
                    if self.want_running and not st.running:
                        # the board's watchdog stopped the drive while the link was down
                        self.runlog.event("mill_restart", self.now_s(), fault=st.fault, setpoint_rpm=st.setpoint_rpm)
                        self.mill_command("start")
                if st.fault:
                    self.fault("mill_fault", f"mill reports fault {st.fault}", mill_fault=st.fault)
                else:
                    self.clear_fault("mill_fault", "mill fault cleared")
            except Exception as exc:  # ConnectionError, TimeoutError, ControlError, SerialException
                if cmd != "status":
                    self._requeue(cmd, arg)
                if mv.connected or "mill_link" not in self._faults_active:
                    mv.connected = False
                    self.fault("mill_link", f"mill link lost: {exc}", url=self.mill.url)
                self.stop_event.wait(MILL_POLL_S)
            self.state.update_numbers(
                mill_state=mv.state, rpm_setpoint=mv.setpoint_rpm, rpm_actual=mv.actual_rpm
            )

    def _requeue(self, cmd: str, arg: float) -> None:
        """Keep the newest wish of each kind for when the link returns."""
        pending = []
        while True:
            try:
                pending.append(self._mill_cmds.get_nowait())
            except queue.Empty:
                break
        pending = [(c, a) for c, a in pending if c != cmd]
        self._mill_cmds.put((cmd, arg))
        for p in pending:
            self._mill_cmds.put(p)

    def mill_command(self, cmd: str, arg: float = 0.0) -> None:
        """Queue a command for the mill thread (never blocks)."""
        self._mill_cmds.put((cmd, float(arg)))

    # -- supervisor ------------------------------------------------------------------------
    def now_s(self) -> float:
        """Run time: the newest frame's time, plus the run time since it arrived (so time
        still passes for the supervisor when the camera stops)."""
        return self.t_s + (time.monotonic() - self.last_frame_wall) * self.clock.speed

    def _supervisor_loop(self) -> None:
        period_wall = self.config.supervisor_period_s / self.clock.speed
        while not self.stop_event.wait(period_wall):
            self._supervise(self.now_s())

    @property
    def mode_name(self) -> str:
        return str(getattr(self.supervisor.mode, "name", self.supervisor.mode)).lower()

    def _supervise(self, now: float) -> None:
        est = self.last_estimate
        mv = self.mill_view
        camera_silent_s = now - self.t_s
        if self.n_frames and camera_silent_s > VISION_STALE_S:
            self.fault("camera_stopped", f"camera stopped: no frame for {camera_silent_s:.0f} s")
        elif self.n_frames:
            self.clear_fault("camera_stopped", "camera frames again")
        last_valid = self.last_valid_t if math.isfinite(self.last_valid_t) else None
        if last_valid is not None and now - last_valid > VISION_STALE_S:
            self.fault("vision_lost", f"no valid MI for {now - last_valid:.0f} s")
        elif last_valid is not None:
            self.clear_fault("vision_lost", "valid MI again")
        r = self.last_reading
        radial = None
        if r is not None and r.valid and r.mi_sigmoid > 0:
            radial = r.mi / r.mi_sigmoid
        inputs = SupervisorInputs(
            trend=est,
            actual_rpm=mv.actual_rpm if math.isfinite(mv.actual_rpm) else None,
            setpoint_rpm=mv.setpoint_rpm if math.isfinite(mv.setpoint_rpm) else None,
            mill_connected=mv.connected,
            radial_factor=radial,
            last_valid_mi_s=last_valid,
            twin_updated_s=self.twin.updated_s,
        )
        with self._sup_lock:
            decision = self.supervisor.step(now, inputs)
        if decision is not None:
            self._apply(decision)

    def _apply(self, d: Any) -> None:
        self.n_decisions += 1
        fields = d.as_dict()
        fields.pop("t_s", None)
        fields["decision"] = fields.pop("kind")  # "kind" is the event's kind
        self.runlog.event("decision", d.t_s, **fields)
        rpm_txt = "" if d.rpm is None else f" -> {d.rpm:g} rpm"
        self.state.update_numbers(last_decision=f"{d.kind}{rpm_txt}", last_reason=d.reason)
        if d.action is Action.STOP:
            self.want_running = False
            self.mill_command("stop")
        elif d.action is Action.SET_RPM and d.rpm is not None:
            self.mill_command("set_rpm", float(d.rpm))

    # -- controls (dashboard) --------------------------------------------------------------
    def set_mode(self, mode: str) -> None:
        with self._sup_lock:
            d = self.supervisor.set_mode(str(mode).lower(), self.now_s(), reason="operator")
        self._apply(d)
        self.state.update_numbers(mode=self.mode_name)

    def set_manual_rpm(self, rpm: float) -> None:
        with self._sup_lock:
            clamped = self.supervisor.set_manual_rpm(float(rpm))
        self.manual_rpm = clamped
        self.runlog.event("operator", self.t_s, action="manual_rpm", rpm=float(rpm), clamped_rpm=clamped)
        if self.mode_name == "manual":
            self._supervise(self.t_s)  # act now, not at the next tick

    def start_mill(self) -> None:
        self.want_running = True
        self.runlog.event("operator", self.t_s, action="start")
        self.clear_fault("emergency_stop", "mill started again")
        self.mill_command("start")

    def stop_mill(self) -> None:
        self.want_running = False
        self.runlog.event("operator", self.t_s, action="stop")
        self.mill_command("stop")

    def emergency_stop(self) -> None:
        self.want_running = False
        self.runlog.event("operator", self.t_s, action="emergency_stop")
        self._estop.set()
        self.set_mode("off")
        self.fault("emergency_stop", "EMERGENCY STOP pressed: mill stopped, mode OFF")

    def recalibrate(self) -> None:
        self.runlog.event("operator", self.t_s, action="recalibrate")
        self.twin.request("calibrate")

    def reseed_twin(self) -> None:
        self.runlog.event("operator", self.t_s, action="reseed")
        self.twin.request("reseed")

    def run_whatif(self, rpms: Sequence[float], duration_s: float) -> None:
        self.runlog.event("operator", self.t_s, action="whatif", rpms=list(rpms), duration_s=duration_s)
        self.whatif.submit(rpms, duration_s, reason="operator")


# Supervisor settings of the live loop. The camera MI of a well-mixed bed is ~0.93-0.95;
# radial segregation at 5 rpm brings it to ~0.80-0.85 (vision MI of the demo plant).
LOOP_SUPERVISOR = dict(
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
)


# Trend settings of the live loop: camera MI wanders slowly with the bed's motion
# (frame-to-frame differences are small, deviations from the level are ~0.05-0.1, more
# once the bed segregates), so the level must be slow (small rate and ripple noise) and
# the outlier gate must not re-initialise on a long excursion.
LOOP_TREND = dict(meas_sd=0.08, rate_q=1e-7, ripple_q=1e-6, max_rejections=60)


def trend_config(config: RunConfig) -> TrendConfig:
    """The Kalman trend's settings for this run (``config.extra["trend"]`` overrides)."""
    return TrendConfig(**{**LOOP_TREND, **config.extra.get("trend", {})})


def supervisor_config(config: RunConfig) -> SupervisorConfig:
    """The supervisor's settings for this run (``config.extra["supervisor"]`` overrides)."""
    return SupervisorConfig(**{**LOOP_SUPERVISOR, **config.extra.get("supervisor", {})})


def _overlay(image: np.ndarray, reading: Reading) -> np.ndarray:
    try:
        from vision.overlay import draw_overlay
    except ImportError:  # vision's overlay not there yet: the plain frame
        return image
    return draw_overlay(image, reading)


__all__ = ["LiveLoop", "MillView", "Summary", "supervisor_config", "trend_config"]

"""The twin worker: seed, run and calibrate the physics twin beside the camera.

As soon as the camera has a frame, the twin is seeded from it (``sim.from_image``) with
the paper's materials and kept in step with run time at the mill's actual rpm, rendered
(``sim.render``) and measured with a vision ``Meter`` like the camera. Calibration runs
beside it, in a worker process of its own (``sim.pool.make_pool``; a converged
calibration takes tens of seconds): once ``CALIBRATION_WINDOW_S`` of camera slope angles
are in, their median is the target of ``sim.calibrate``, and the result is applied to the
running twin when it arrives. ``Recalibrate``/``Reseed`` commands are served between steps. It reads only the
:class:`RunView`; it publishes :class:`TwinInfo` and reports through the event sink. The twin follows
the mill's measured rpm at ``control.limits.simulated_rpm`` (the one cap of a simulated drum).
"""

from __future__ import annotations

import math
import queue
import statistics
import threading
import time
from collections import deque
from collections.abc import Mapping
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from control.limits import Limits, simulated_rpm
from twin.clock import Cadence
from twin.live.camera import Rate
from twin.live.commands import Recalibrate, TwinCommand, drain
from twin.live.events import EventSink
from twin.live.faults import NO_FAULTS, FaultHooks, at
from twin.live.snapshots import Latest, RunView, TwinInfo
from twin.records import (
    Calibrated,
    CalibrationStarted,
    CalibrationWaiting,
    FaultCleared,
    FaultRaised,
    TwinLag,
    TwinReading,
    TwinSeeded,
    TwinStatus,
)
from twin.state import LiveState

if TYPE_CHECKING:
    from sim.calibrate import Calibration
    from sim.engine import Twin
    from sim.mixer import Mixer
    from sim.render import Renderer
    from vision.colours import ColourClass
    from vision.meter import Meter

CALIBRATION_WINDOW_S = 3.0  # run seconds of camera slope angles for a calibration
TWIN_FPS = 10.0  # twin renders per run second (the dashboard's 10 Hz)
MAX_LAG_S = 5.0  # run seconds the twin may fall behind before it skips ahead
SNAPSHOT_EVERY_S = 2.0  # run seconds between twin snapshots kept for what-if studies
CALIBRATION_STEADY_S = 3.0  # run seconds the drum must turn steadily before a calibration
CALIBRATION_RPM_SPREAD = 0.05  # steady: actual rpm within this share of its median (+ 0.1 rpm) all along


@dataclass(frozen=True)
class TwinSettings:
    """What the twin worker needs of the run's configuration."""

    case: str = "C"
    seed: int = 0
    start_rpm: float = 5.0
    size_px: int = 240
    classes: tuple[ColourClass, ...] = ()  # the camera meter's colour classes (the twin's meters use the same)
    mixer: Mixer | None = None  # the user's mixer (``sim.mixer.Mixer``); None: the paper's (``paper_mixer``)
    engine: str | None = None  # None: the mixer's engine (``sim.engine.engine_for``)
    calibrate_kwargs: Mapping[str, Any] = field(default_factory=dict)
    limits: Limits = field(default_factory=Limits)  # the run's (its supervisor's): calibrated only from their min_rpm


def _calibrate_job(target_slope_deg: float, rpm: float, kwargs: Mapping[str, Any]) -> Any:
    """``sim.calibrate.calibrate`` in a worker process (module level: picklable)."""
    from sim.calibrate import calibrate

    return calibrate(target_slope_deg, rpm, **dict(kwargs))


class TwinWorker:
    """The twin thread's state and work (see module doc)."""

    def __init__(
        self,
        settings: TwinSettings,
        view: RunView,
        sink: EventSink,
        state: LiveState,
        box: Latest[TwinInfo],
        slopes: queue.Queue[tuple[float, float]] | queue.SimpleQueue[tuple[float, float]],
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.settings = settings
        self.faults = faults
        self.view = view
        self.sink = sink
        self.state = state
        self.box = box
        self.slopes = slopes
        self.sim: Twin | None = None
        self.renderer: Renderer | None = None
        self.meter: Meter | None = None
        self.calibration: Calibration | None = None
        self.fps = Rate()
        self.t0_run = 0.0  # run time at which the twin's own clock read 0
        self._requests: queue.SimpleQueue[TwinCommand] = queue.SimpleQueue()
        self._slopes: deque[tuple[float, float]] = deque(maxlen=4000)
        self._state: Any = None
        self._seeds = 0  # times seeded (TwinInfo.seeds: a what-if "from the bed" waits for the next)
        self._seeded_sim_s = 0.0  # the twin's own time at its latest seeding (TwinInfo.age_s counts from it)
        self._mi = math.nan
        self._slope = math.nan
        self._energy_j = 0.0  # drive energy over the run (sim.power: drum torque x angular speed)
        self._depth_scale = 1.0  # slice -> drum (sim.power.depth_scale), per seeding
        self._pool: Executor | None = None
        self._closed = False
        self._cal_future: Future | None = None
        self._cal_started: tuple[float, float, float, float] | None = None  # t, target, rpm, wall
        self._cal_wanted = True  # calibrate once the camera slope window is full
        self._rpm_seen: deque[tuple[float, float]] = deque(maxlen=4000)  # (run s, actual rpm) for _rpm_now
        self._cal_waiting: str | None = None  # why a wanted calibration waits (logged once per reason)

    # -- any thread ------------------------------------------------------------------------
    def request(self, cmd: TwinCommand) -> None:
        """``Recalibrate`` or ``Reseed``: served by the twin thread between steps."""
        self._requests.put(cmd)

    # -- the worker thread -----------------------------------------------------------------
    @property
    def now_s(self) -> float:
        """The twin's time on the run clock."""
        return self.t0_run + (self.sim.t_s if self.sim is not None else 0.0)

    def _publish(self, updated_s: float | None) -> None:
        age = self.sim.t_s - self._seeded_sim_s if self.sim is not None else 0.0
        info = TwinInfo(updated_s, self._mi, self._slope, self._state, self._seeds, age, self._energy_j)
        hook = self.faults.twin_published
        self.box.set(info if hook is None else hook(info))

    def _drain_slopes(self) -> None:
        self._slopes.extend(drain(self.slopes))

    def run(self, stop: threading.Event) -> None:
        view = self.view
        while not stop.is_set() and view.camera().image is None:
            self._drain_slopes()
            stop.wait(0.05)
        if stop.is_set():
            return
        self._reseed()
        render = Cadence(1.0 / TWIN_FPS, start_s=self.now_s)  # run clock
        next_snap = self.now_s
        while not stop.is_set():
            at(self.faults.twin_pass, view.now_s())
            self._drain_slopes()
            self._serve_requests()
            self._tend_calibration()
            target = view.frames().t_s
            lag = target - self.now_s
            if lag > MAX_LAG_S:  # cannot keep up: skip ahead and say so
                self.sink.publish(TwinLag(t_s=target, lag_s=lag))
                self.t0_run += lag
                render.restart(self.now_s)
                self._publish(self.now_s)  # caught up: its bed as it was (the skipped time is not simulated)
                continue
            if lag <= 1e-6:
                stop.wait(0.005)
                continue
            sim = self.sim  # set by _reseed (a reseed request replaces it between passes)
            if sim is None:  # cannot happen: _reseed sets it or raises (a crash, as before)
                raise RuntimeError("the twin worker has no twin after seeding")
            rpm = view.mill().actual_rpm
            if math.isfinite(rpm):
                sim.set_rpm(simulated_rpm(rpm, sim.critical_rpm))
            dt = min(lag, 1.0 / TWIN_FPS)
            sim.step(dt)
            self._add_energy(sim, dt)
            if render.due(self.now_s):
                self._render_and_measure()
            if self.now_s >= next_snap:
                next_snap = self.now_s + SNAPSHOT_EVERY_S
                self._state = sim.snapshot()
            self._publish(self.now_s)

    def _add_energy(self, sim: Twin, dt_s: float) -> None:
        """The drive's energy over the step the twin just took (its mean drum torque there, scaled
        from the slice to the drum, at its actual speed; a NaN torque adds nothing)."""
        from sim.power import drive_power_w

        power = float(drive_power_w(sim.drum_torque_nm() * self._depth_scale, sim.rpm_actual))
        if math.isfinite(power):
            self._energy_j += power * dt_s

    def _serve_requests(self) -> None:
        for cmd in drain(self._requests):
            if isinstance(cmd, Recalibrate):
                self._cal_wanted = True
            else:
                self._reseed()

    def camera_slope(self, now_s: float) -> float | None:
        """Median camera slope angle over the last window, once a full window is seen."""
        s = self._slopes
        if not s or s[-1][0] - s[0][0] < CALIBRATION_WINDOW_S * 0.9:
            return None
        vals = [a for t, a in s if t >= now_s - CALIBRATION_WINDOW_S]
        return statistics.median(vals) if len(vals) >= 3 else None

    def _rpm_now(self, t: float) -> tuple[float | None, str]:
        """The drum's measured rpm to calibrate at, from the mill's actual rpm seen at run time
        ``t`` (called every step): the median over the last ``CALIBRATION_STEADY_S`` once the
        drum has turned at >= the run's lowest rpm (``TwinSettings.limits``: the supervisor's)
        and steadily (within ``CALIBRATION_RPM_SPREAD`` of it) all that time; else ``(None, why)``."""
        seen = self._rpm_seen
        rpm = self.view.mill().actual_rpm
        if not math.isfinite(rpm):  # not read yet, or the link is lost: start over
            seen.clear()
            return None, "unknown: the mill's actual rpm is not known (no reading, or the link is lost)"
        if not seen or t > seen[-1][0] or rpm != seen[-1][1]:
            seen.append((t, rpm))
        while len(seen) > 1 and seen[1][0] <= t - CALIBRATION_STEADY_S:
            seen.popleft()  # keep one sample at or before the window's start
        lo_rpm = self.settings.limits.min_rpm
        if rpm < lo_rpm:
            return None, f"not turning: the drum turns at {rpm:.2f} rpm, below the run's {lo_rpm:g} rpm minimum"
        if t - seen[0][0] < CALIBRATION_STEADY_S:
            return None, (f"not steady yet: the drum has turned steadily for {t - seen[0][0]:.1f} of "
                          f"{CALIBRATION_STEADY_S:g} s")
        vals = [r for _, r in seen]
        mid = statistics.median(vals)
        if min(vals) < lo_rpm or max(vals) - min(vals) > CALIBRATION_RPM_SPREAD * mid + 0.1:
            return None, f"not steady: {min(vals):.2f}-{max(vals):.2f} rpm over the last {CALIBRATION_STEADY_S:g} s"
        return mid, ""

    def _tend_calibration(self) -> None:
        """Start a wanted calibration once there is a target and a steadily turning drum
        (else a ``calibration_waiting`` event says why, once per reason); apply a finished one."""
        t = self.view.frames().t_s
        fut = self._cal_future
        if fut is None:
            if not self._cal_wanted:
                return
            rpm, why = self._rpm_now(t)
            target = self.camera_slope(t)
            if target is None:
                return
            if rpm is None:
                reason = why.split(":", 1)[0]
                if reason != self._cal_waiting:  # an event, not a fault: the twin runs on as it is
                    self._cal_waiting = reason
                    self.sink.publish(CalibrationWaiting(t_s=t, reason=why, rpm=self.view.mill().actual_rpm))
                    self.sink.publish(TwinStatus(t_s=t, state="running, waiting to calibrate"))
                return
            self._cal_waiting = None
            self._cal_wanted = False
            self._cal_started = (t, target, rpm, time.monotonic())
            self.sink.publish(TwinStatus(t_s=t, state="running, calibrating"))
            self.sink.publish(CalibrationStarted(t_s=t, target_slope_deg=target, rpm=rpm))
            try:
                self._cal_future = self._get_pool().submit(
                    _calibrate_job, target, rpm, dict(self.settings.calibrate_kwargs)
                )
            except Exception as exc:  # no pool (closing): the twin runs on uncalibrated
                self._calibration_failed(t, exc)
            return
        if not fut.done():
            return
        self._cal_future = None
        try:
            cal = fut.result()
        except Exception as exc:  # the twin runs on with its current friction
            self._calibration_failed(t, exc)
            return
        assert self._cal_started is not None  # set together with the future
        _, target, rpm, wall0 = self._cal_started
        self.calibration = cal
        self.sink.publish(Calibrated(
            t_s=t, target_slope_deg=target, rpm=rpm, friction=cal.friction, rolling=cal.rolling,
            end_friction=cal.end_friction, twin_slope_deg=cal.twin_slope_deg, residual_deg=cal.residual_deg,
            took_s=time.monotonic() - wall0,
        ))
        self.sink.metadata(calibration=cal)
        self.sink.publish(TwinStatus(t_s=t, state="running"))
        self.sink.publish(FaultCleared(t_s=t, fault="calibration", message="calibrated"))
        if self.sim is not None:
            self.sim.set_friction(**cal.twin_kwargs())  # sliding, rolling and the end plates' (a monolayer's)

    def _calibration_failed(self, t: float, exc: BaseException) -> None:
        self.sink.publish(FaultRaised(t_s=t, fault="calibration", message=f"calibration failed: {exc}"))
        self.sink.publish(TwinStatus(t_s=t, state="running (uncalibrated)"))

    def _get_pool(self) -> Executor:
        if self._closed:
            raise RuntimeError("the twin worker is closed")
        if self._pool is None:
            from sim.pool import make_pool
            from twin.live.whatif import short_pool_tempdir

            short_pool_tempdir()
            self._pool = make_pool(1)
        return self._pool

    def close(self) -> None:
        """End the calibration process (a running calibration is abandoned)."""
        from sim.pool import close_pool

        self._closed = True
        pool, self._pool = self._pool, None
        close_pool(pool)

    def _reseed(self) -> None:
        from sim.engine import make_twin
        from sim.errors import SimError
        from sim.from_image import seed_from_frame
        from sim.mixer import paper_mixer
        from sim.power import depth_scale
        from sim.render import Renderer
        from vision.meter import Meter

        s = self.settings
        cam = self.view.camera()
        t = self.view.frames().t_s
        cal = self.calibration
        kw = {} if cal is None else {"friction": cal.friction, "rolling": cal.rolling}
        rpm = self.view.mill().actual_rpm
        rpm = rpm if math.isfinite(rpm) else s.start_rpm
        mixer = paper_mixer() if s.mixer is None else s.mixer
        if cam.image is None:
            sim = make_twin(mixer, s.engine, case=s.case, seed=s.seed, rpm=rpm, **kw)
            how = "recipe case"
        else:
            try:
                sim = seed_from_frame(cam.image, Meter(roi=cam.roi, classes=s.classes), rpm=rpm, seed=s.seed,
                                      mixer=mixer, engine=s.engine, **kw)
                how = "live frame"
            except SimError as exc:  # an engine that cannot place from a frame: a fresh bed, said in the log
                sim = make_twin(mixer, s.engine, case=s.case, seed=s.seed, rpm=rpm, **kw)
                how = f"recipe case ({exc})"
        if cal is not None:  # the end plates' friction too (a monolayer's is calibrated)
            sim.set_friction(**cal.twin_kwargs())
        if self.renderer is None:
            self.renderer = Renderer(sim.drum, s.size_px)
            self.meter = Meter(roi=self.renderer.roi, classes=s.classes)
        self.sim = sim
        self.t0_run = t - sim.t_s
        self._seeded_sim_s = sim.t_s
        self._depth_scale = depth_scale(sim)
        sim.drum_torque_nm()  # the torque's mean starts at the first step of this bed
        self._state = sim.snapshot()
        self._seeds += 1
        self.sink.publish(TwinSeeded(t_s=t, source=how, n_particles=len(sim.particles())))
        self._render_and_measure()
        self._publish(t)

    def _render_and_measure(self) -> None:
        sim, renderer, meter = self.sim, self.renderer, self.meter
        if sim is None or renderer is None or meter is None:  # not seeded yet
            return
        parts = sim.particles()
        image = renderer.render(parts)
        if image is None:  # only a renderer with realism drops frames (the twin's has none)
            return
        r = meter.measure(image)
        self.fps.tick()
        self._mi, self._slope = float(r.mi), float(r.slope_deg)
        self.state.publish_twin(image, parts, sim.drum.radius_m)
        self.sink.publish(TwinReading(t_s=self.now_s, mi=r.mi, slope_deg=r.slope_deg, fps=self.fps.rate()))


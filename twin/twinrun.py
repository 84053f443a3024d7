"""The twin beside the live loop, and the what-if studies AUTO asks for.

``TwinRunner.run`` (the loop's twin thread): waits for ``CALIBRATION_WINDOW_S`` of
camera slope angles, calibrates the twin's friction to their median
(``sim.calibrate``), seeds the twin's particles from the live frame
(``sim.from_image``), then keeps the twin in step with the loop's run time at the
mill's actual rpm, rendering it (``sim.render``) and measuring it with a vision
``Meter`` like the camera. ``recalibrate``/``reseed`` requests are served between
steps.

``WhatIfRunner``: studies from the twin's latest state (``sim.whatif.run_study`` in
worker processes, or on a Dask cluster with ``--scheduler``), run in a background
thread; AUTO gets them through ``control.supervisor.AsyncPredictor`` so the
supervisor never waits.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import queue
import statistics
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.clock import Cadence
from twin.state import WhatIfView

if TYPE_CHECKING:
    from twin.loop import LiveLoop

CALIBRATION_WINDOW_S = 3.0  # run seconds of camera slope angles for a calibration
TWIN_FPS = 10.0  # twin renders per run second (the dashboard's 10 Hz)
MAX_LAG_S = 5.0  # run seconds the twin may fall behind before it skips ahead
SNAPSHOT_EVERY_S = 2.0  # run seconds between twin snapshots kept for what-if studies


class Rate:
    """Events per wall second over the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 3.0) -> None:
        self.window_s = window_s
        self._times: deque[float] = deque()
        self._lock = threading.Lock()

    def tick(self) -> None:
        now = time.monotonic()
        with self._lock:
            self._times.append(now)
            cut = now - self.window_s
            while self._times and self._times[0] < cut:
                self._times.popleft()

    def rate(self) -> float:
        with self._lock:
            if len(self._times) < 2:
                return 0.0
            span = self._times[-1] - self._times[0]
            return (len(self._times) - 1) / span if span > 0 else 0.0


class TwinRunner:
    """The twin thread's state and work (see module doc)."""

    def __init__(self, loop: LiveLoop, size_px: int | None = None) -> None:
        self.loop = loop
        self.size_px = int(size_px or loop.config.frame_px)
        self.sim: Any = None
        self.renderer: Any = None
        self.meter: Any = None
        self.calibration: Any = None
        self.latest: dict[str, float] = {}
        self.latest_state: Any = None  # a SimState no older than SNAPSHOT_EVERY_S
        self.fps = Rate()
        self.t0_run = 0.0  # run time at which the twin's own clock read 0
        self.updated_s: float | None = None  # run time of the last twin step
        self._requests: queue.Queue[str] = queue.Queue()
        self._slopes: deque[tuple[float, float]] = deque(maxlen=4000)
        self._slopes_lock = threading.Lock()

    # -- inputs from other threads --------------------------------------------------------
    def observe_slope(self, t_s: float, slope_deg: float) -> None:
        if math.isfinite(slope_deg):
            with self._slopes_lock:
                self._slopes.append((t_s, slope_deg))

    def request(self, kind: str) -> None:
        """``"calibrate"`` or ``"reseed"``: served by the twin thread between steps."""
        self._requests.put(kind)

    def age_s(self, now_s: float) -> float:
        """Run seconds since the twin last stepped (inf before it exists)."""
        return math.inf if self.updated_s is None else now_s - self.updated_s

    @property
    def now_s(self) -> float:
        """The twin's time on the loop's run clock."""
        return self.t0_run + (self.sim.t_s if self.sim is not None else 0.0)

    # -- the thread ------------------------------------------------------------------------
    def run(self) -> None:
        loop = self.loop
        stop = loop.stop_event
        while not stop.is_set() and self._camera_slope(loop.t_s) is None:
            stop.wait(0.05)
        if stop.is_set():
            return
        self._calibrate()
        self._reseed()
        render = Cadence(1.0 / TWIN_FPS, start_s=self.now_s)  # run clock
        next_snap = self.now_s
        while not stop.is_set():
            self._serve_requests()
            target = loop.t_s
            lag = target - self.now_s
            if lag > MAX_LAG_S:  # cannot keep up: skip ahead and say so
                loop.runlog.event("twin_lag", loop.t_s, lag_s=lag)
                self.t0_run += lag
                render.restart(self.now_s)
            if lag <= 1e-6:
                stop.wait(0.005)
                continue
            rpm = loop.mill_view.actual_rpm
            if math.isfinite(rpm):
                self.sim.set_rpm(min(max(rpm, 0.0), 0.95 * self.sim.critical_rpm))
            self.sim.step(min(lag, 1.0 / TWIN_FPS))
            self.updated_s = self.now_s
            if render.due(self.now_s):
                self._render_and_measure()
            if self.now_s >= next_snap:
                next_snap = self.now_s + SNAPSHOT_EVERY_S
                self.latest_state = self.sim.snapshot()

    def _serve_requests(self) -> None:
        while True:
            try:
                kind = self._requests.get_nowait()
            except queue.Empty:
                return
            if kind == "calibrate":
                self._calibrate()
            elif kind == "reseed":
                self._reseed()

    def _camera_slope(self, now_s: float) -> float | None:
        """Median camera slope angle over the last window, once a full window is seen."""
        with self._slopes_lock:
            if not self._slopes or self._slopes[-1][0] - self._slopes[0][0] < CALIBRATION_WINDOW_S * 0.9:
                return None
            vals = [s for t, s in self._slopes if t >= now_s - CALIBRATION_WINDOW_S]
        return statistics.median(vals) if len(vals) >= 3 else None

    def _calibrate(self) -> None:
        loop = self.loop
        try:
            self._fit()
        except Exception as exc:  # the twin runs on with its current friction
            loop.fault("calibration", f"calibration failed: {exc}")
            loop.state.update_numbers(twin_state="running (uncalibrated)")
        else:
            loop.clear_fault("calibration", "calibrated")

    def _fit(self) -> None:
        from sim.calibrate import calibrate

        loop = self.loop
        target = self._camera_slope(loop.t_s)
        if target is None:
            loop.runlog.event("calibration_skipped", loop.t_s, reason="no camera slope angle yet")
            return
        rpm = loop.mill_view.actual_rpm
        rpm = rpm if math.isfinite(rpm) and rpm > 0 else loop.config.start_rpm
        loop.state.update_numbers(twin_state="calibrating")
        t0 = time.monotonic()
        cal = calibrate(target, rpm, **loop.config.extra.get("calibrate_kwargs", {}))
        self.calibration = cal
        loop.runlog.event(
            "calibration",
            loop.t_s,
            target_slope_deg=target,
            rpm=rpm,
            friction=cal.friction,
            rolling=cal.rolling,
            twin_slope_deg=cal.twin_slope_deg,
            residual_deg=cal.residual_deg,
            took_s=time.monotonic() - t0,
        )
        loop.runlog.set_metadata(calibration=cal)
        loop.state.update_numbers(friction=cal.friction, twin_state="running")
        if self.sim is not None:
            self.sim.set_friction(cal.friction, cal.rolling)

    def _reseed(self) -> None:
        from sim.drum import DrumSim
        from sim.from_image import seed_from_frame
        from sim.render import Renderer
        from vision.meter import Meter

        loop = self.loop
        image = loop.last_image
        cal = self.calibration
        kw = {} if cal is None else {"friction": cal.friction, "rolling": cal.rolling}
        rpm = loop.mill_view.actual_rpm
        rpm = rpm if math.isfinite(rpm) else loop.config.start_rpm
        if image is None:
            sim = DrumSim(case=loop.config.case, seed=loop.config.seed, rpm=rpm, **kw)
            how = "recipe case"
        else:
            sim = seed_from_frame(image, loop.meter, rpm=rpm, seed=loop.config.seed, **kw)
            how = "live frame"
        if self.renderer is None:
            self.renderer = Renderer(sim.drum, self.size_px)
            classes = loop.classes
            self.meter = Meter(roi=self.renderer.roi, **({} if classes is None else {"classes": classes}))
        self.sim = sim
        self.t0_run = loop.t_s - sim.t_s
        self.updated_s = loop.t_s
        self.latest_state = sim.snapshot()
        loop.runlog.event("twin_seeded", loop.t_s, source=how, n_particles=len(sim.particles()))
        self._render_and_measure()

    def _render_and_measure(self) -> None:
        parts = self.sim.particles()
        image = self.renderer.render(parts)
        r = self.meter.measure(image)
        self.fps.tick()
        self.latest = {"mi": r.mi, "slope_deg": r.slope_deg, "t_s": self.now_s}
        self.loop.state.publish_twin(image, parts, self.sim.drum.radius_m)
        self.loop.state.update_numbers(twin_mi=r.mi, twin_slope_deg=r.slope_deg, twin_fps=self.fps.rate())


class WhatIfRunner:
    """Twin what-if studies in the background (worker processes or Dask).

    ``submit(rpms, duration_s)`` starts a study from the twin's latest state unless one
    is running; ``predict(rpms, horizon_s)`` is the supervisor's (blocking) predictor,
    meant to be wrapped in ``AsyncPredictor``: it runs a study and returns the MI each
    rpm reaches at the horizon (mean of the last 10 % of the curve).
    """

    def __init__(self, loop: LiveLoop, *, scheduler: str | None = None, workers: int = 1) -> None:
        self.loop = loop
        self.scheduler = scheduler
        self.workers = max(1, int(workers))
        self._busy = threading.Lock()
        self._seq = 0
        self._thread: threading.Thread | None = None
        self._executor: ProcessPoolExecutor | None = None

    def _pool(self) -> ProcessPoolExecutor:
        """One long-lived worker process (spawned once; studies run there)."""
        if self._executor is None:
            self._executor = ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn"))
        return self._executor

    def warm_up(self) -> None:
        """Start the worker process and import the twin there now, not at the first study."""
        if not self.scheduler:
            self._pool().submit(_import_sim)

    def _study(self, rpms: Sequence[float], duration_s: float, reason: str) -> dict[float, float]:
        from sim.whatif import WhatIfJob, run_study

        loop = self.loop
        state = loop.twin.latest_state
        if state is None:
            raise RuntimeError("the twin is not running yet")
        self._seq += 1
        loop.state.set_whatif(WhatIfView(status=f"running {len(rpms)} rpm x {duration_s:g} s ({reason})", seq=self._seq))
        t_req = loop.t_s
        t0 = time.monotonic()
        jobs = [WhatIfJob(rpm=float(r), duration_s=float(duration_s), start=state) for r in rpms]
        try:
            if self.scheduler:
                results = run_study(jobs, scheduler=self.scheduler)
            else:  # in a worker process, so the study never competes with the loop for the GIL
                results = self._pool().submit(run_study, jobs, workers=self.workers).result()
        except Exception as exc:
            self._seq += 1
            loop.state.set_whatif(WhatIfView(status=f"error: {exc}", seq=self._seq))
            loop.runlog.event("whatif_error", loop.t_s, reason=reason, error=str(exc))
            raise
        preds = {float(r): float(res.plateau_mi) for r, res in zip(rpms, results)}
        self._seq += 1
        loop.state.set_whatif(
            WhatIfView(
                status=f"done at t={loop.t_s:.0f} s ({reason}, {time.monotonic() - t0:.1f} s wall)",
                rpms=tuple(float(r) for r in rpms),
                t_s=tuple(np.asarray(res.t_s, float) for res in results),
                mi=tuple(np.asarray(res.mi, float) for res in results),
                plateau_mi=tuple(preds.values()),
                regime=tuple(str(getattr(res, "regime", "")) for res in results),
                seq=self._seq,
            )
        )
        loop.runlog.event(
            "whatif", loop.t_s, reason=reason, requested_t_s=t_req, duration_s=duration_s,
            predictions={str(k): v for k, v in preds.items()}, took_s=time.monotonic() - t0,
        )
        return preds

    def predict(self, rpms: Sequence[float], horizon_s: float) -> Mapping[float, float]:
        with self._busy:
            return self._study(rpms, horizon_s, "AUTO")

    def submit(self, rpms: Sequence[float], duration_s: float, reason: str = "operator") -> bool:
        """Start an operator study in the background; False when one is already running."""
        if self._busy.locked():
            return False

        def work() -> None:
            with self._busy:
                try:
                    self._study(rpms, duration_s, reason)
                except Exception:
                    pass

        self._thread = threading.Thread(target=work, name="drumtwin-whatif", daemon=True)
        self._thread.start()
        return True

    def close(self) -> None:
        """Shut the worker process down (a running study is abandoned)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            for p in list((getattr(self._executor, "_processes", None) or {}).values()):
                p.terminate()
            self._executor = None


def _import_sim() -> bool:
    import sim.whatif  # noqa: F401

    return True

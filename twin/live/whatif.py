"""The what-if worker: twin studies in the background, for AUTO and for the operator.

This is the application's predictor (the supervisor itself only asks): ``request`` takes
the supervisor's :class:`PredictionRequest` (a newer one supersedes one not started yet;
it waits for the twin's first state), ``poll`` hands a finished :class:`PredictionResult`
back once. ``submit`` takes an operator's study (a ``RunStudy`` command). One thread serves
both, one study at a time, from the twin's newest state (:class:`TwinInfo`); the studies
themselves run in a local process pool (``sim.pool.make_pool``) or on a Dask cluster
(``--scheduler``), so they never compete with the loop for the GIL.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from typing import TYPE_CHECKING

import numpy as np

from control.decision import PredictionRequest, PredictionResult
from control.objective import RpmPrediction
from twin.errors import TwinError
from twin.live.commands import RunStudy
from twin.live.events import EventSink
from twin.live.faults import NO_FAULTS, FaultHooks, at
from twin.live.snapshots import RunView
from twin.records import WhatIfCancelled, WhatIfError, WhatIfResult
from twin.state import LiveState, WhatIfView

if TYPE_CHECKING:
    from sim.whatif import WhatIfJob
    from sim.whatif import WhatIfResult as StudyResult

Study = Callable[[Sequence["WhatIfJob"]], Sequence["StudyResult"]]
"""``study(jobs) -> results`` (``sim.whatif.WhatIfJob`` -> ``WhatIfResult``, in order)."""


POOL_TMP_MAX = 60
"""Longest temp directory (characters) the process pools' fork server may put its socket under:
an AF_UNIX path is at most 107 bytes, and multiprocessing adds ``/pymp-XXXXXXXX/listener-XXXXXXXX``."""

RESEED_WAIT_S = 10.0  # wall seconds an AUTO study "from the bed" waits for the twin to seed itself
SHORT_TMP_BASES = ("/tmp", "/var/tmp", "/dev/shm")


def short_pool_tempdir(limit: int = POOL_TMP_MAX) -> str:
    """multiprocessing's private temp directory of this process (``multiprocessing.util.get_temp_dir``:
    a ``pymp-*`` directory, mode 0700, removed at exit), made under a short base when the temp
    directory (``$TMPDIR``) is longer than ``limit``: the fork server's socket in it would be "AF_UNIX
    path too long" and every what-if study and calibration would fail. Call before a pool starts;
    TwinError when the directory was already made under a long path."""
    import multiprocessing.util as mpu
    import os
    import tempfile

    if len(tempfile.gettempdir()) > limit:
        base = next((d for d in SHORT_TMP_BASES if os.path.isdir(d) and os.access(d, os.W_OK | os.X_OK)), None)
        old = tempfile.tempdir
        if base is not None:
            tempfile.tempdir = base
        try:
            path = mpu.get_temp_dir()  # made once per process (the first call wins)
        finally:
            tempfile.tempdir = old
    else:
        path = mpu.get_temp_dir()
    if len(path) > limit + len("/pymp-xxxxxxxx"):
        raise TwinError(f"the temp directory {path} is too long for the what-if pool's socket: set TMPDIR shorter")
    return path


class WhatIfWorker:
    """See module doc. ``study`` replaces the process pool (tests). ``target_mi``: the MI every study reports
    the time and energy to (the config's endpoint target; None: none). ``reseed_twin``: asks the twin
    worker to seed itself from the camera's bed; an AUTO request ``from_bed`` waits (at most
    ``RESEED_WAIT_S`` s) for the twin's next seed and starts from it (None: from the running twin)."""

    def __init__(
        self,
        view: RunView,
        sink: EventSink,
        state: LiveState,
        *,
        scheduler: str | None = None,
        workers: int = 1,
        study: Study | None = None,
        target_mi: float | None = None,
        reseed_twin: Callable[[], None] | None = None,
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.view = view
        self.faults = faults
        self.reseed_twin = reseed_twin  # asks the twin to seed itself from the camera's bed (a request)
        self.target_mi = target_mi
        self.sink = sink
        self.state = state
        self.scheduler = scheduler
        self.workers = max(1, int(workers))
        self._study_fn = study
        self._pool: Executor | None = None
        self._closed = False
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._pending_pred: PredictionRequest | None = None
        self._pending_study: RunStudy | None = None
        self._result: PredictionResult | None = None
        self._busy = False
        self._running_reason: str | None = None
        self._cancelled = False
        self._seq = 0
        self.on_auto_result: Callable[[str | None], None] | None = None
        """Called after each AUTO prediction study: None when it succeeded, else the error
        (the loop makes a failure a ``whatif_failed`` alarm and AUTO's safe state)."""

    # -- any thread ------------------------------------------------------------------------
    def request(self, req: PredictionRequest) -> None:
        with self._lock:
            self._pending_pred = req
        self._wake.set()

    def poll(self) -> PredictionResult | None:
        with self._lock:
            res, self._result = self._result, None
        return res

    def submit(self, study: RunStudy) -> bool:
        """Queue an operator study; False when one is already waiting or running."""
        with self._lock:
            if self._busy or self._pending_study is not None:
                return False
            self._pending_study = study
        self._wake.set()
        return True

    def cancel(self) -> bool:
        """Abandon the operator's waiting or running study (the local pool's workers are
        terminated; a new pool starts with the next study); an AUTO prediction is left
        alone. True when there was one. A study on a Dask cluster is only dropped here."""
        with self._lock:
            waiting = self._pending_study is not None
            self._pending_study = None
            running = self._busy and self._running_reason not in (None, "AUTO")
            if running:
                self._cancelled = True
                pool, self._pool = self._pool, None
        if running:
            from sim.pool import close_pool

            close_pool(pool)
        return waiting or running

    @property
    def busy(self) -> bool:
        with self._lock:
            return self._busy

    # -- the worker thread -----------------------------------------------------------------
    def warm_up(self) -> None:
        """Start the worker process(es) now, not at the first study."""
        if self._study_fn is None and not self.scheduler:
            from sim.whatif import froude

            self._get_pool().submit(froude, 5.0)

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self._wake.wait(0.1)
            self._wake.clear()
            self.serve_once()

    def serve_once(self) -> bool:
        """Run the next pending study (a prediction first); False when none was pending."""
        at(self.faults.whatif_pass, self.view.now_s())
        twin_ready = self.view.twin().state is not None
        with self._lock:
            pred, study = self._pending_pred, self._pending_study
            if not twin_ready:  # nothing to start a study from yet: keep them waiting
                pred = None
                if study is not None:
                    self._pending_study = None
                    self.sink.publish(WhatIfError(t_s=self.view.now_s(), reason=study.reason,
                                                  error="the twin is not running yet"))
                    return False
            if pred is not None:
                self._pending_pred = None
            elif study is not None:
                self._pending_study = None
            else:
                return False
            self._busy = True
            self._running_reason = "AUTO" if pred is not None else study.reason if study is not None else None
            self._cancelled = False
        try:
            if pred is not None:
                if pred.from_bed:
                    self._seed_from_bed()
                try:
                    preds, rows = self._study(pred.rpms, pred.horizon_s, "AUTO", pred.target_mi, pred.ramp_rpm_s)
                except Exception as exc:
                    self._report_auto(f"{type(exc).__name__}: {exc}")
                    return True
                with self._lock:
                    self._result = PredictionResult(pred.t_s, pred.horizon_s, preds, rows)
                self._report_auto(None)
            elif study is not None:
                try:
                    self._study(study.rpms, study.duration_s, study.reason)
                except Exception:
                    pass
            return True
        finally:
            with self._lock:
                self._busy = False
                self._running_reason = None

    def _seed_from_bed(self) -> bool:
        """Ask the twin to seed itself from the camera's bed and wait for its new state (wall
        clock, at most ``RESEED_WAIT_S``); False when it did not come (the study then starts
        from the running twin's state)."""
        if self.reseed_twin is None:
            return False
        seeds = self.view.twin().seeds
        self.reseed_twin()
        end = time.monotonic() + RESEED_WAIT_S
        while not self._closed and time.monotonic() < end:
            tw = self.view.twin()
            if tw.seeds > seeds and tw.state is not None:
                return True
            time.sleep(0.02)
        return False

    def _report_auto(self, error: str | None) -> None:
        if self._closed:  # the run is ending: its pool was shut down under the study
            return
        if self.on_auto_result is not None:
            try:
                self.on_auto_result(error)
            except Exception:
                pass

    def _get_pool(self) -> Executor:
        if self._closed:
            raise RuntimeError("the what-if worker is closed")
        if self._pool is None:
            from sim.pool import make_pool

            short_pool_tempdir()
            self._pool = make_pool(self.workers)
        return self._pool

    def _run_jobs(self, jobs: Sequence[WhatIfJob]) -> Sequence[StudyResult]:
        if self._study_fn is not None:
            return self._study_fn(jobs)
        from sim.whatif import run_study

        if self.scheduler:
            return run_study(jobs, scheduler=self.scheduler)
        return run_study(jobs, workers=self.workers, pool=self._get_pool())

    def _study(self, rpms: Sequence[float], duration_s: float, reason: str, target_mi: float | None = None,
               ramp_rpm_s: float | None = None) -> tuple[dict[float, float], dict[float, RpmPrediction] | None]:
        """Run one study; plateau MI per rpm and (``target_mi`` given) the rows to the target
        (time, drive power and energy: ``sim.whatif``) for AUTO's objective."""
        from sim.whatif import WhatIfJob

        state = self.view.twin().state
        t_req = self.view.now_s()
        if state is None:
            self.sink.publish(WhatIfError(t_s=t_req, reason=reason, error="the twin is not running yet"))
            raise RuntimeError("the twin is not running yet")
        self._seq += 1
        status = f"running {len(rpms)} rpm x {duration_s:g} s ({reason})"
        self.state.set_whatif(WhatIfView(status=status, seq=self._seq))
        t0 = time.monotonic()
        target = self.target_mi if target_mi is None else target_mi  # AUTO's request, else the run's
        jobs = [WhatIfJob(rpm=float(r), duration_s=float(duration_s), start=state, target_mi=target,
                          ramp_rpm_s=ramp_rpm_s) for r in rpms]  # AUTO's: the twin ramps as the mill will
        try:
            results = list(self._run_jobs(jobs))
        except Exception as exc:
            self._seq += 1
            if self._cancelled:
                self.state.set_whatif(WhatIfView(status="cancelled by the operator", seq=self._seq))
                self.sink.publish(WhatIfCancelled(t_s=self.view.now_s(), reason=reason))
                raise
            self.state.set_whatif(WhatIfView(status=f"error: {exc}", seq=self._seq))
            self.sink.publish(WhatIfError(t_s=self.view.now_s(), reason=reason, error=str(exc)))
            raise
        preds = {float(r): float(res.plateau_mi) for r, res in zip(rpms, results, strict=False)}
        times = tuple(float(getattr(res, "time_to_target_s", np.nan)) for res in results)
        powers = tuple(float(getattr(res, "plateau_power_w", np.nan)) for res in results)
        energies = tuple(float(getattr(res, "energy_to_target_j", np.nan)) for res in results)
        rows = None if target is None else {  # issue 24: time and energy to the target (sim.whatif)
            float(r): RpmPrediction(float(r), preds[float(r)], t, e, p)
            for r, t, e, p in zip(rpms, times, energies, powers, strict=False)}
        self._seq += 1
        t_done = self.view.now_s()
        self.state.set_whatif(
            WhatIfView(
                status=f"done at t={t_done:.0f} s ({reason}, {time.monotonic() - t0:.1f} s wall)",
                rpms=tuple(float(r) for r in rpms),
                t_s=tuple(np.asarray(res.t_s, float) for res in results),
                mi=tuple(np.asarray(res.mi, float) for res in results),
                plateau_mi=tuple(preds.values()),
                regime=tuple(str(getattr(res, "regime", "")) for res in results),
                seq=self._seq, target_mi=target, time_to_target_s=times, power_w=powers,
                energy_to_target_j=energies,
            )
        )
        self.sink.publish(WhatIfResult(
            t_s=t_done, reason=reason, requested_t_s=t_req, duration_s=duration_s,
            predictions={str(k): v for k, v in preds.items()}, took_s=time.monotonic() - t0,
            target_mi=target, time_to_target_s=dict(zip(map(str, preds), times, strict=False)),
            power_w=dict(zip(map(str, preds), powers, strict=False)),
            energy_to_target_j=dict(zip(map(str, preds), energies, strict=False)),
        ))
        return preds, rows

    def close(self) -> None:
        """Shut the worker processes down (a running study is abandoned: it fails at once)."""
        from sim.pool import close_pool

        self._closed = True
        pool, self._pool = self._pool, None
        close_pool(pool)

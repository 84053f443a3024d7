"""The camera worker (frames -> readings: ``vision.stream.FrameMeter``) and the process worker
(readings -> Kalman trend + the paper's moving average -> one ``FrameReading`` record on the run's
bus: ``twin.frame_rows.FrameRows``, and the newest :class:`FrameInfo` for the other workers). The
two steps are the ones ``drumtwin mi`` runs on a file, in one thread; here each has its own."""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from control.endpoint import EndpointDetector
from control.trend import MITrend, TrendEstimate
from twin.clock import Cadence
from twin.frame_rows import FrameRows, is_valid_mi
from twin.live.commands import SwapClasses
from twin.live.events import EventSink
from twin.live.faults import NO_FAULTS, FaultHooks, at
from twin.live.snapshots import CameraInfo, FrameInfo, Latest, RunView
from twin.records import (
    CameraRate,
    FaultCleared,
    FaultRaised,
    FrameReading,
    Mixed,
    TrendSettled,
    TrendUnsettled,
    Unmixed,
)
from twin.state import LiveState
from vision.meter import Meter, Reading
from vision.sources import Frame
from vision.stream import FrameMeter

__all__ = ["READINGS_MAX", "SLOPES_MAX", "CameraReading", "CameraWorker", "ProcessWorker", "Rate", "is_valid_mi",
           "make_room", "put_dropping_oldest"]

T = TypeVar("T")

READINGS_MAX = 512  # readings waiting for the process worker; beyond that the oldest go (counted)
SLOPES_MAX = 4000  # camera slope angles waiting for the twin worker (its own window keeps as many)


@dataclass(frozen=True)
class CameraReading:
    """One measured frame on its way to the process worker."""

    t_s: float
    frame: int
    reading: Reading
    dropped_total: int = 0  # readings the camera dropped so far, this one's room included (process behind)


class Rate:
    """Events per wall second over the last ``window_s`` seconds (thread-safe)."""

    def __init__(self, window_s: float = 3.0, monotonic: Callable[[], float] = time.monotonic) -> None:
        self.window_s = window_s
        self._monotonic = monotonic
        self._times: list[float] = []
        self._lock = threading.Lock()

    def tick(self) -> None:
        now = self._monotonic()
        with self._lock:
            self._times.append(now)
            cut = now - self.window_s
            while self._times and self._times[0] < cut:
                self._times.pop(0)

    def rate(self) -> float:
        with self._lock:
            if len(self._times) < 2:
                return 0.0
            span = self._times[-1] - self._times[0]
            return (len(self._times) - 1) / span if span > 0 else 0.0


def put_dropping_oldest(q: queue.Queue[T], item: T) -> int:
    """Put without ever blocking: when ``q`` is full its oldest item is dropped; returns how
    many items were dropped."""
    dropped = 0
    while True:
        try:
            q.put_nowait(item)
            return dropped
        except queue.Full:
            try:
                q.get_nowait()
                dropped += 1
            except queue.Empty:
                pass


def make_room(q: queue.Queue[T]) -> int:
    """Drop the oldest items of a full ``q`` until one more fits; returns how many were dropped
    (the producer then puts without blocking, as long as it is the only one)."""
    dropped = 0
    while q.full():
        try:
            q.get_nowait()
            dropped += 1
        except queue.Empty:
            break
    return dropped


class CameraWorker:
    """Reads frames at the source's own rate, measures them (``vision.stream.FrameMeter``: the
    no-drum policy, ``vision.stream.NO_DRUM_GRACE_S``), and hands the readings on (never blocked by anything
    downstream). Publishes :class:`CameraInfo`; draws the overlay for the dashboard at
    ``overlay_hz`` (0: none)."""

    def __init__(
        self,
        frames: Iterable[Frame],
        meter: Meter,
        out: queue.Queue[CameraReading],
        box: Latest[CameraInfo],
        state: LiveState,
        *,
        overlay_hz: float = 0.0,
        overlay: Callable[[np.ndarray, Reading], np.ndarray] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        commands: queue.SimpleQueue[SwapClasses] | None = None,
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.frames = frames
        self.faults = faults
        self.frame_meter = FrameMeter(meter)
        self.commands = commands  # SwapClasses: a new meter from the next frame on
        self.out = out
        self.box = box
        self.state = state
        self.overlay = overlay
        self._overlay_cadence = Cadence(1.0 / overlay_hz) if overlay_hz > 0 and overlay is not None else None
        self._monotonic = monotonic
        self.fps = Rate(monotonic=monotonic)
        self.dropped = 0  # readings dropped because the process worker was behind (frames_dropped:)

    @property
    def meter(self) -> Meter:
        """The meter measuring the frames now (a ``SwapClasses`` command replaces it)."""
        return self.frame_meter.meter

    def run(self, stop: threading.Event) -> None:
        """Until the source ends or fails (then ``CameraInfo.ended``: vision is lost now)."""
        try:
            self._run(stop)
        finally:
            if not stop.is_set():
                self.box.set(replace(self.box.get(), ended=True))

    def _run(self, stop: threading.Event) -> None:
        n = 0
        for frame in self.frames:
            at(self.faults.camera_frame, float(frame.t_s))
            if stop.is_set():
                return
            wall = self._monotonic()  # when the frame arrived
            n += 1
            t, prev = float(frame.t_s), self.box.get()
            # a frame without a time or from before the newest one (the camera's clock jumped
            # back) is no news: run time and the camera alarm go on; the process worker drops it
            came = math.isfinite(t) and (prev.t_s is None or t >= prev.t_s)
            roi = prev.roi
            if came:
                self.box.set(CameraInfo(t, wall, frame.image, roi, n, False))  # it came (alarms)
            while self.commands is not None and not self.commands.empty():
                self.frame_meter.meter = self.commands.get_nowait().meter
            reading = self.frame_meter.measure(frame)  # flagged when it cannot be measured; raises past the grace
            if came and reading.roi is not roi:
                self.box.set(CameraInfo(t, wall, frame.image, reading.roi, n, False))
            self.fps.tick()
            self.dropped += make_room(self.out)  # the one producer: the put below never blocks
            self.out.put_nowait(CameraReading(t, int(frame.index), reading, self.dropped))
            cadence = self._overlay_cadence
            if cadence is not None and self.overlay is not None and cadence.due(self._monotonic()):
                self.state.publish_camera(self.overlay(frame.image, reading))
        if not stop.is_set():
            self.frame_meter.finish()  # the source ended: bad input when it never showed a drum


def _known(value: float) -> float | None:
    """A measurement for the frame row: None (an empty cell) when unknown (NaN)."""
    return value if math.isfinite(value) else None


class ProcessWorker:
    """Readings -> trend, moving average, one ``FrameReading`` record (published: the run log's
    row, the plots, the numbers panel) and the newest :class:`FrameInfo`; camera slope angles
    go on to the twin (``slopes``). Each
    change of the trend between unsettled and settled (``TrendEstimate.settled``: the
    supervisor decides nothing on an unsettled trend) is a ``trend_unsettled`` /
    ``trend_settled`` record (a logged state, not a fault; the panel's ``trend_state``)."""

    def __init__(
        self,
        inbox: queue.Queue[CameraReading],
        trend: MITrend,
        box: Latest[FrameInfo],
        view: RunView,
        sink: EventSink,
        slopes: queue.Queue[tuple[float, float]] | None = None,
        ma_window: int = 150,
        camera_fps: Callable[[], float] = lambda: 0.0,
        endpoint: EndpointDetector | None = None,
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.inbox = inbox
        self.faults = faults
        self.trend = trend
        self.rows = FrameRows(trend, ma_window, endpoint)  # the batch endpoint: events mixed / unmixed
        self.box = box
        self.view = view
        self.sink = sink
        self.slopes = slopes
        self.camera_fps = camera_fps
        self._settled: bool | None = None  # the trend's state last logged (None: no valid trend yet)
        self._dropped = 0  # the camera's dropped count at the last reading processed

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            try:
                item = self.inbox.get(timeout=0.1)
            except queue.Empty:
                continue
            at(self.faults.process_reading, item.t_s)
            self.process(item)

    def process(self, item: CameraReading) -> FrameReading | None:
        """One reading -> trend, row, :class:`FrameInfo`. A frame whose time is not a number
        or goes back before the newest processed one is dropped (None) with a
        ``camera_clock`` fault: the trend's time only runs forward."""
        prev = self.box.get()
        mill = self.view.mill()
        rpm = mill.actual_rpm if math.isfinite(mill.actual_rpm) else 0.0
        step = self.rows.step(item.t_s, item.frame, item.reading, rpm)
        if step is None:
            why = (f"went back from {prev.t_s:g} to {item.t_s:g} s" if math.isfinite(item.t_s)
                   else f"is {item.t_s}")
            self.sink.publish(FaultRaised(
                t_s=self.view.now_s(), fault="camera_clock", frame=item.frame,
                message=f"camera frame time {why}: frames dropped until it runs forward again"))
            return None
        self.sink.publish(FaultCleared(t_s=item.t_s, fault="camera_clock", message="frame times in order again"))
        r, est, end = item.reading, step.estimate, step.endpoint
        self._log_settled(est)
        if end.changed:  # issue 24: the endpoint, live (the frame record carries it to the panel)
            change = Mixed if end.changed == "mixed" else Unmixed  # control.endpoint: "mixed" | "unmixed"
            self.sink.publish(change(t_s=item.t_s, mixing_time_s=end.mixing_time_s, plateau_mi=end.plateau_mi,
                                     block_sd=end.block_sd, reason=end.reason))
        last_valid = item.t_s if step.valid else prev.last_valid_t_s
        self.box.set(FrameInfo(item.t_s, prev.n_frames + 1, last_valid, r, est, end.mixed, end.mixing_time_s))
        if step.valid and self.slopes is not None and math.isfinite(r.slope_deg):
            put_dropping_oldest(self.slopes, (item.t_s, float(r.slope_deg)))  # bounded: a stalled twin
        dropped, self._dropped = item.dropped_total - self._dropped, max(self._dropped, item.dropped_total)
        tw = self.view.twin()
        row = replace(  # what only the run knows, beside the measurement's row
            step.row, twin_mi=None if tw.updated_s is None else tw.mi,
            twin_slope_deg=None if tw.updated_s is None else tw.slope_deg,
            rpm_setpoint=_known(mill.setpoint_rpm), rpm_actual=_known(mill.actual_rpm), mode=self.view.mode(),
            flags=step.row.flags + ((mill.link_flag,) if mill.link_flag else ())
            + ((f"frames_dropped:{dropped}",) if dropped > 0 else ()),
        )
        self.sink.publish(row)  # the one way a frame leaves: the CSV row, the plots, the numbers panel
        self.sink.publish(CameraRate(t_s=item.t_s, fps=self.camera_fps()))
        return row

    def _log_settled(self, est: TrendEstimate) -> None:
        """One event per change of the trend's settled state (see the class doc)."""
        if not est.valid or est.settled == self._settled:
            return
        self._settled = est.settled
        c = self.trend.config
        band = est.hi95 - est.lo95
        width, acc_s = self.trend.settle_width(), self.trend.accepted_s
        if est.settled:
            why = f"band {band:.3f} <= {width:.3g} after {acc_s:.1f} s of accepted frames"
        elif acc_s < c.settle_s or est.n_since_init < c.reinit_min:
            why = f"{acc_s:.1f} s ({est.n_since_init} frames) accepted since " \
                  f"{'a re-init' if self.trend.n_reinit > 1 else 'start'} < {c.settle_s:g} s ({c.reinit_min} frames)"
        else:
            why = f"band {band:.3f} > {width:.3g}"
        change = TrendSettled if est.settled else TrendUnsettled
        self.sink.publish(change(t_s=est.t_s, level=est.level, lo95=est.lo95, hi95=est.hi95,
                                 n_since_init=est.n_since_init, reason=why))

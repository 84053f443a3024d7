"""Fakes of the live loop's surroundings for the worker tests (no threads, no sim, no serial):
a settable wall clock, the loop's latest-value boxes with a run view on them, a prediction
channel, a supervisor worker on the worked settings, and a camera reading at a given MI."""

from __future__ import annotations

from control.decision import Mode, PredictionRequest, PredictionResult
from control.protocol import MillStatus
from control.supervisor import Supervisor
from control.trend import TrendEstimate
from tests.control.supervisor_values import worked_config
from tests.twin.test_mill_worker import Sink
from twin.live.snapshots import CameraInfo, FrameInfo, Latest, MillSnapshot, RunView, TwinInfo
from twin.live.supervise import SupervisorWorker


class Wall:
    """A settable monotonic clock (s)."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Boxes:
    def __init__(self, mode: str = "auto") -> None:
        self.camera: Latest[CameraInfo] = Latest(CameraInfo())
        self.frames: Latest[FrameInfo] = Latest(FrameInfo())
        self.mill: Latest[MillSnapshot] = Latest(MillSnapshot())
        self.twin: Latest[TwinInfo] = Latest(TwinInfo())
        self.mode: Latest[str] = Latest(mode)
        self.wall = Wall()
        self.view = RunView(1.0, self.camera, self.frames, self.mill, self.twin, self.mode,
                            clock_now=lambda: 0.0, monotonic=self.wall)

    def frame(self, t_s: float, level: float = 0.9, valid: bool = True) -> None:
        """A frame at run time t_s arriving now (wall), with a trend at ``level``."""
        est = TrendEstimate(t_s, level, 0.0, 0.01, 0.001, level - 0.02, level + 0.02, True, False, settled=True)
        prev = self.frames.get()
        self.camera.set(CameraInfo(t_s, self.wall.t, None, None, prev.n_frames + 1, False))
        self.frames.set(FrameInfo(t_s, prev.n_frames + 1, t_s if valid else prev.last_valid_t_s, None, est))

    def mill_at(self, rpm: float, running: bool = True, epoch: int = 1, connected: bool = True) -> None:
        self.mill.set(MillSnapshot(MillStatus(rpm, rpm if running else 0.0, running, None), connected, epoch, True))


class FakePredictions:
    def __init__(self) -> None:
        self.requests: list[PredictionRequest] = []
        self.results: list[PredictionResult] = []

    def request(self, req: PredictionRequest) -> None:
        self.requests.append(req)

    def poll(self) -> PredictionResult | None:
        return self.results.pop(0) if self.results else None


def sup_worker(b: Boxes, mode: Mode, preds: FakePredictions | None = None, **cfg):
    base = dict(detect_dwell_s=2.0, min_change_interval_s=10.0, max_rate_rpm_per_s=100.0, vision_timeout_s=3.0,
                seg_level=0.5, clear_level=0.6, prediction_wait_s=0.0, min_rpm=2.0, max_rpm=40.0)
    sent: list = []
    sink = Sink()
    w = SupervisorWorker(Supervisor(worked_config(**{**base, **cfg}), mode=mode), b.view, sink, sent.append,
                         preds, b.mode)
    return w, sink, sent


def advance(b: Boxes, w: SupervisorWorker, t0: float, t1: float, level: float = 0.9, frames: bool = True) -> None:
    """Frames (optional) and a supervisor tick every 0.5 s of run time from t0 to t1."""
    t = t0
    while t < t1 - 1e-9:
        b.wall.t += 0.5
        if frames:
            b.frame(t, level)
        w.tick(b.view.now_s())
        t += 0.5


def reading(mi: float, valid: bool = True, slope: float = 30.0):
    """A meter reading of MI ``mi`` and bed slope ``slope`` (deg); invalid: a few-pixels flag."""
    from vision.meter import Reading

    return Reading(mi=mi, mi_sigmoid=mi, mi_linear=mi, d_px=1.0, dsigma_px=1.0, slope_deg=slope,
                   concentration=0.5, valid=valid, flags=() if valid else ("few_pixels:red",), classes=(), roi=None)

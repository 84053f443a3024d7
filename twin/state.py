"""The live state the dashboard reads: latest images, plot histories, the numbers panel
(:class:`Panel`) and what-if results, behind one lock.

It is a subscriber of the run's record bus (``twin.records``): :meth:`LiveState.record` folds
each record into the plots and the panel (a frozen dataclass, never a dict of strings).
Images, what-if curves and the rig's history come through ``publish_camera`` /
``publish_twin`` / ``set_whatif`` / ``set_rig_history``. The alarms are the messages of the
run's one :class:`ActiveFaults`. Readers take ``snapshot()``, a consistent copy they can use
without holding the lock. Nothing here blocks for long: a slow dashboard can never stall the
camera thread.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

from twin.live.golden import RigHistory
from twin.records import (
    FRAME_COLUMNS,
    SERIES,
    ActiveFaults,
    Calibrated,
    CameraRate,
    DecisionMade,
    FrameReading,
    MillState,
    ModeSet,
    Record,
    TrendSettled,
    TrendUnsettled,
    TwinReading,
    TwinStatus,
)

if TYPE_CHECKING:
    from sim.twin_base import Particles

FrameRow = FrameReading
"""The frame record (``twin.records.FrameReading``) under its old name."""
FRAME_ROW_COLUMNS: tuple[str, ...] = FRAME_COLUMNS

HISTORY_LEN = 900
NO_RIG_HISTORY = RigHistory()  # not read: a dashboard outside a run


@dataclass(frozen=True)
class WhatIfView:
    """What-if results for the dashboard: per rpm a curve and its plateau."""

    status: str = "idle"  # idle | running | done | error: ...
    rpms: tuple[float, ...] = ()
    t_s: tuple[np.ndarray, ...] = ()
    mi: tuple[np.ndarray, ...] = ()
    plateau_mi: tuple[float, ...] = ()
    regime: tuple[str, ...] = ()
    seq: int = 0
    target_mi: float | None = None  # the study's target MI (None: none)
    time_to_target_s: tuple[float, ...] = ()  # per rpm, s (NaN: not reached in the study)
    power_w: tuple[float, ...] = ()  # per rpm, drive power over the plateau part, W (whole drum)
    energy_to_target_j: tuple[float, ...] = ()  # per rpm, J (NaN: not reached)


@dataclass(frozen=True)
class Panel:
    """The dashboard's numbers panel: the newest value of each, folded from the run records
    (None: not seen yet). Units as in ``twin.records``."""

    t_s: float | None = None  # run time of the newest frame, s
    mi: float | None = None
    trend_mi: float | None = None
    d_px: float | None = None
    dsigma_px: float | None = None
    concentration: float | None = None
    slope_deg: float | None = None
    light_state: str | None = None  # ok | changed (cause)
    camera_fps: float | None = None
    trend_state: str | None = None  # settled | unsettled
    mixed: bool = False  # the batch is at its endpoint (control.endpoint)
    mixing_time_s: float | None = None  # its mixing time, s
    twin_mi: float | None = None
    twin_slope_deg: float | None = None
    twin_fps: float | None = None
    twin_state: str | None = None
    friction: float | None = None
    rpm_setpoint: float | None = None
    rpm_actual: float | None = None
    mill_state: str | None = None
    mode: str | None = None
    last_decision: str | None = None
    last_reason: str | None = None


def fold(panel: Panel, rec: Record) -> Panel:
    """The panel after ``rec`` (records that show nothing leave it as it is)."""
    if isinstance(rec, FrameReading):
        light = next((f for f in rec.flags if f.startswith("lighting_changed:")), None)
        return replace(
            panel, t_s=rec.t_s, mi=rec.mi, d_px=rec.d_px, dsigma_px=rec.dsigma_px, concentration=rec.concentration,
            slope_deg=rec.slope_deg, trend_mi=rec.trend_mi, mixed=rec.mixed, mixing_time_s=rec.mixing_time_s,
            light_state="ok" if light is None else "changed (" + light.split(":", 1)[1] + ")",
        )
    if isinstance(rec, CameraRate):
        return replace(panel, camera_fps=rec.fps)
    if isinstance(rec, (TrendSettled, TrendUnsettled)):
        return replace(panel, trend_state="settled" if isinstance(rec, TrendSettled) else "unsettled")
    if isinstance(rec, MillState):
        return replace(panel, mill_state=rec.state, rpm_setpoint=rec.setpoint_rpm, rpm_actual=rec.actual_rpm)
    if isinstance(rec, ModeSet):
        return replace(panel, mode=rec.mode)
    if isinstance(rec, DecisionMade):
        rpm_txt = "" if rec.rpm is None else f" -> {rec.rpm:g} rpm"
        return replace(panel, last_decision=f"{rec.decision}{rpm_txt}", last_reason=rec.reason)
    if isinstance(rec, TwinStatus):
        return replace(panel, twin_state=rec.state)
    if isinstance(rec, Calibrated):
        return replace(panel, friction=rec.friction)
    if isinstance(rec, TwinReading):
        return replace(panel, twin_mi=rec.mi, twin_slope_deg=rec.slope_deg, twin_fps=rec.fps)
    return panel


def plot_point(rec: FrameReading) -> dict[str, float | None]:
    """The plot point of a frame: its :data:`SERIES` values; an unknown rpm (link lost) is a
    gap (NaN), any other missing value (no twin yet) repeats the last one (None)."""
    point: dict[str, float | None] = {k: getattr(rec, k) for k in SERIES}
    for k in ("rpm_setpoint", "rpm_actual"):
        if point[k] is None:
            point[k] = math.nan
    return point


@dataclass(frozen=True)
class Snapshot:
    """A consistent copy of the live state."""

    camera_image: np.ndarray | None
    camera_seq: int
    twin_image: np.ndarray | None
    twin_seq: int
    twin_particles: Particles | None  # the twin's disks (drum frame, m)
    twin_drum_r_m: float | None
    history: dict[str, np.ndarray]
    history_seq: int
    panel: Panel
    alarms: tuple[str, ...]
    whatif: WhatIfView
    rig_history: RigHistory = NO_RIG_HISTORY  # the rig's earlier runs and golden batch (twin.live.golden)
    rig_history_seq: int = 0


class Controls(Protocol):
    """What the dashboard may ask of the loop (all return at once; ``twin.run.operator.Operator``
    in a run). ``cancel_whatif``: True when there was a study to cancel; ``relearn_classes``:
    what to tell the operator (Markdown)."""

    def set_mode(self, mode: str) -> None: ...
    def set_manual_rpm(self, rpm: float) -> None: ...
    def start_mill(self) -> None: ...
    def stop_mill(self) -> None: ...
    def emergency_stop(self) -> None: ...
    def recalibrate(self) -> None: ...
    def reseed_twin(self) -> None: ...
    def run_whatif(self, rpms: Sequence[float], duration_s: float) -> None: ...
    def cancel_whatif(self) -> bool: ...
    def relearn_classes(self) -> str: ...


class LiveState:
    """Thread-safe holder of the latest loop state (see module doc)."""

    def __init__(self, history_len: int = HISTORY_LEN, faults: ActiveFaults | None = None) -> None:
        self._lock = threading.Lock()
        self._camera: np.ndarray | None = None
        self._camera_seq = 0
        self._twin: np.ndarray | None = None
        self._twin_seq = 0
        self._particles: Particles | None = None
        self._drum_r_m: float | None = None
        self._hist: dict[str, deque] = {k: deque(maxlen=history_len) for k in SERIES}
        self._hist_seq = 0
        self._panel = Panel()
        self.faults = faults if faults is not None else ActiveFaults()  # the run's one set of active faults
        self._whatif = WhatIfView()
        self._rig_history = NO_RIG_HISTORY
        self._rig_history_seq = 0

    def publish_camera(self, image_bgr: np.ndarray) -> None:
        """The newest camera frame (with its overlay drawn)."""
        with self._lock:
            self._camera = image_bgr
            self._camera_seq += 1

    def publish_twin(
        self, image_bgr: np.ndarray | None, particles: Particles | None = None, drum_r_m: float | None = None
    ) -> None:
        """The newest twin frame and (optionally) its particles and drum radius (m)."""
        with self._lock:
            if image_bgr is not None:
                self._twin = image_bgr
                self._twin_seq += 1
            if particles is not None:
                self._particles = particles
                self._drum_r_m = drum_r_m

    def record(self, rec: Record) -> None:
        """The bus subscriber: a frame reading is a plot point (missing values repeat their
        last one, see :func:`plot_point`); every record is folded into the panel."""
        point = plot_point(rec) if isinstance(rec, FrameReading) else None
        with self._lock:
            if point is not None:
                for k, buf in self._hist.items():
                    v = point[k]
                    if v is None:
                        v = buf[-1] if buf else math.nan
                    buf.append(float(v))
                self._hist_seq += 1
            self._panel = fold(self._panel, rec)

    def set_whatif(self, view: WhatIfView) -> None:
        with self._lock:
            self._whatif = view

    def set_rig_history(self, history: RigHistory) -> None:
        """The rig's earlier runs and golden batch (``twin.catalogue.history``, read once per run)."""
        with self._lock:
            self._rig_history = history
            self._rig_history_seq += 1

    @property
    def panel(self) -> Panel:
        with self._lock:
            return self._panel

    @property
    def alarms(self) -> tuple[str, ...]:
        return self.faults.messages()

    def snapshot(self) -> Snapshot:
        """A consistent copy (arrays are fresh; images are shared, never mutated)."""
        with self._lock:
            return Snapshot(
                camera_image=self._camera,
                camera_seq=self._camera_seq,
                twin_image=self._twin,
                twin_seq=self._twin_seq,
                twin_particles=self._particles,
                twin_drum_r_m=self._drum_r_m,
                history={k: np.fromiter(v, dtype=float, count=len(v)) for k, v in self._hist.items()},
                history_seq=self._hist_seq,
                panel=self._panel,
                alarms=self.faults.messages(),
                whatif=self._whatif,
                rig_history=self._rig_history,
                rig_history_seq=self._rig_history_seq,
            )


def forward_fill(x: np.ndarray) -> np.ndarray:
    """NaN replaced by the last finite value before it (leading NaN stay NaN)."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if ok.all() or not ok.any():
        return x
    idx = np.where(ok, np.arange(len(x)), 0)
    np.maximum.accumulate(idx, out=idx)
    out = x[idx]
    out[: int(np.argmax(ok))] = np.nan
    return out

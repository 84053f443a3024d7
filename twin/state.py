"""The live state the loop publishes and the dashboard reads: latest frames, plot
histories, the numbers panel and what-if results, behind one lock; and the
:class:`FrameRow`, one processed frame, whose fields are the run log's CSV columns and
whose :data:`SERIES` are the dashboard's plots.

Writers (loop threads) call ``publish_*``; readers take ``snapshot()``, a consistent
copy they can use without holding the lock. Nothing here blocks for long: a slow
dashboard can never stall the camera thread.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from sim.drum import Particles

@dataclass(frozen=True)
class FrameRow:
    """One processed camera frame: the run log's CSV row and the plots' point.

    Its fields, in order, are the CSV columns (``FRAME_ROW_COLUMNS``, with ``wall_s``
    that the run log fills in); :data:`SERIES` are the plotted ones. Times in run seconds.
    """

    t_s: float
    frame: int
    mi: float
    mi_sigmoid: float
    mi_linear: float
    d_px: float
    dsigma_px: float
    concentration: float
    slope_deg: float
    valid: bool
    trend_mi: float
    trend_lo95: float
    trend_hi95: float
    trend_rate: float
    ma_mi: float  # the paper's 150-sample moving average
    twin_mi: float | None
    twin_slope_deg: float | None
    rpm_setpoint: float | None  # None (an empty cell): unknown, the mill link is lost (flag link_lost:)
    rpm_actual: float | None
    mode: str
    flags: tuple[str, ...]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


FRAME_ROW_COLUMNS: tuple[str, ...] = ("t_s", "wall_s", *tuple(f.name for f in fields(FrameRow))[1:])

# Plot series (x is run time ``t_s``); each is a ring buffer of ``HISTORY_LEN`` points.
SERIES: tuple[str, ...] = (
    "t_s",
    "mi",
    "trend_mi",
    "trend_lo95",
    "trend_hi95",
    "ma_mi",
    "twin_mi",
    "rpm_setpoint",
    "rpm_actual",
    "slope_deg",
    "twin_slope_deg",
)
HISTORY_LEN = 900


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
    numbers: dict[str, Any]
    alarms: tuple[str, ...]
    whatif: WhatIfView


class Controls(Protocol):
    """What the dashboard may ask of the loop (all return at once)."""

    def set_mode(self, mode: str) -> None: ...
    def set_manual_rpm(self, rpm: float) -> None: ...
    def start_mill(self) -> None: ...
    def stop_mill(self) -> None: ...
    def emergency_stop(self) -> None: ...
    def recalibrate(self) -> None: ...
    def reseed_twin(self) -> None: ...
    def run_whatif(self, rpms: Sequence[float], duration_s: float) -> None: ...


class LiveState:
    """Thread-safe holder of the latest loop state (see module doc)."""

    def __init__(self, history_len: int = HISTORY_LEN) -> None:
        self._lock = threading.Lock()
        self._camera: np.ndarray | None = None
        self._camera_seq = 0
        self._twin: np.ndarray | None = None
        self._twin_seq = 0
        self._particles: Particles | None = None
        self._drum_r_m: float | None = None
        self._hist: dict[str, deque] = {k: deque(maxlen=history_len) for k in SERIES}
        self._hist_seq = 0
        self._numbers: dict[str, Any] = {}
        self._alarms: dict[str, str] = {}
        self._whatif = WhatIfView()

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

    def publish_point(self, values: Mapping[str, float]) -> None:
        """Append one point to every plot series (missing ones repeat their last value)."""
        with self._lock:
            for k, buf in self._hist.items():
                v = values.get(k)
                if v is None:
                    v = buf[-1] if buf else float("nan")
                buf.append(float(v))
            self._hist_seq += 1

    def update_numbers(self, **values: Any) -> None:
        """Merge values into the numbers panel."""
        with self._lock:
            self._numbers.update(values)

    def set_alarm(self, key: str, message: str | None) -> None:
        """Raise (message) or clear (None) a named alarm."""
        with self._lock:
            if message is None:
                self._alarms.pop(key, None)
            else:
                self._alarms[key] = message

    def set_whatif(self, view: WhatIfView) -> None:
        with self._lock:
            self._whatif = view

    @property
    def numbers(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._numbers)

    @property
    def alarms(self) -> tuple[str, ...]:
        with self._lock:
            return tuple(self._alarms.values())

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
                numbers=dict(self._numbers),
                alarms=tuple(self._alarms.values()),
                whatif=self._whatif,
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

"""The frame reading: one processed camera frame, a row of ``frames.csv`` and the dashboard's
plot point; :data:`FRAME_COLUMNS` and :data:`SERIES` are derived from its fields."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

from twin.records.declare import Record, register, unit


@register
@dataclass(frozen=True, kw_only=True)
class FrameReading(Record):
    """One processed camera frame: the run log's CSV row and the plots' point."""

    kind: ClassVar[str] = "frame"
    logged: ClassVar[bool] = False
    doc: ClassVar[str] = "one processed camera frame (a row of frames.csv)"
    producer: ClassVar[str] = "twin.live.camera"

    t_s: float = unit("s", "run time of the frame", plot=True, source="vision.sources")
    frame: int = unit("", "camera frame index", source="vision.sources")
    mi: float = unit("", "mixing index, paper eq. 4 (0..1, NaN when invalid)", plot=True, source="vision.meter")
    mi_sigmoid: float = unit("", "paper eq. 3", source="vision.meter")
    mi_linear: float = unit("", "paper eq. 1", source="vision.meter")
    d_px: float = unit("px", "centroid distance of the two classes", source="vision.meter")
    dsigma_px: float = unit("px", "spread difference of the two classes", source="vision.meter")
    concentration: float = unit("", "n_1 / (n_1 + n_2)", source="vision.meter")
    slope_deg: float = unit("deg", "bed free-surface slope", plot=True, source="vision.meter")
    valid: bool = unit("", "the reading counts as vision", source="vision.meter")
    trend_mi: float = unit("", "Kalman trend level", plot=True, source="control.trend")
    trend_lo95: float = unit("", "trend 95 % band, low", plot=True, source="control.trend")
    trend_hi95: float = unit("", "trend 95 % band, high", plot=True, source="control.trend")
    trend_rate: float = unit("1/s", "trend rate of change", source="control.trend")
    ma_mi: float = unit("", "the paper's 150-sample moving average", plot=True, source="control.trend")
    twin_mi: float | None = unit("", "twin MI (empty: no twin yet)", plot=True, source="twin.live.twin")
    twin_slope_deg: float | None = unit("deg", "twin slope (empty: no twin yet)", plot=True, source="twin.live.twin")
    rpm_setpoint: float | None = unit("rpm", "board setpoint (empty: link lost)", plot=True, source="twin.live.mill")
    rpm_actual: float | None = unit("rpm", "board actual speed (empty: link lost)", plot=True, source="twin.live.mill")
    mode: str = unit("", "supervisor mode: off | manual | auto", source="control.supervisor")
    flags: tuple[str, ...] = unit("", "reading flags, ';'-separated", source="vision.meter")
    mixed: bool = unit("", "the batch is at its endpoint", default=False, source="control.endpoint")
    mixing_time_s: float | None = unit("s", "mixing time of the endpoint (empty: not mixed)", default=None,
                                       source="control.endpoint")

    def as_dict(self) -> dict[str, object]:
        """The CSV row (without ``wall_s``, which the run log fills in)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


FRAME_COLUMNS: tuple[str, ...] = ("t_s", "wall_s", *(f.name for f in fields(FrameReading)[1:]))
"""The columns of ``frames.csv``: the frame reading's fields, with ``wall_s`` (unix time when
the row was written, s) after ``t_s``."""

SERIES: tuple[str, ...] = tuple(f.name for f in fields(FrameReading) if f.metadata.get("plot"))
"""The dashboard's plot series (x is ``t_s``)."""

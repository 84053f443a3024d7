"""The report's plots: matplotlib (Agg), each a PNG in memory as a ``data:`` URI.

They draw what ``twin.report.load`` kept: decimated series whose values are finite and within
``PLOT_LIMIT`` or NaN (a gap), so no log can hand matplotlib a number it cannot place.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from typing import Any

import numpy as np

from twin.report.events import PLOT_LIMIT
from twin.report.load import RunData

COLOURS = {"mi": "#9e9e9e", "trend_mi": "#1565c0", "twin_mi": "#2e7d32", "rpm_setpoint": "#ef6c00",
           "rpm_actual": "#6a1b9a", "slope_deg": "#1565c0", "twin_slope_deg": "#2e7d32"}


def png(fig: Any) -> str:
    """``fig`` as a PNG data URI (the figure closed)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def axes(ylabel: str, size: tuple[float, float] = (6.4, 2.8), left: float = 0.11) -> tuple[Any, Any]:
    """One figure and its axes, with fixed margins (a layout engine draws every figure twice:
    half a report's time)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    fig.subplots_adjust(left=left, right=0.98, bottom=0.17, top=0.96)
    ax.set_xlabel("run time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    return fig, ax


def _nothing(ax: Any, what: str = "nothing logged") -> None:
    ax.text(0.5, 0.5, what, transform=ax.transAxes, ha="center", va="center", color="#c62828")


def lines(run: RunData, names: Sequence[tuple[str, str]], ylabel: str, marks: Sequence[float] = ()) -> str:
    """Columns of ``run`` against run time, one line each; ``marks``: vertical dashed lines."""
    fig, ax = axes(ylabel)
    drawn = False
    for name, label in names:
        t, y = run.series(name)
        if t.size and np.isfinite(y).any():
            style = dict(lw=0.8, alpha=0.6) if name == "mi" else dict(lw=2.0)
            ax.plot(t, y, color=COLOURS.get(name, "#000000"), label=label, **style)
            drawn = True
    for m in marks:
        if abs(m) <= PLOT_LIMIT:
            ax.axvline(m, color="#c62828", ls="--", lw=1.2)
    if drawn:
        ax.legend(loc="best", fontsize=8)
    else:
        _nothing(ax)
    return png(fig)


def timeline(run: RunData) -> str:
    """Events against run time, one row per kind (decimated: the first and last of each bucket)."""
    fig, ax = axes("event", left=0.27)
    kinds = sorted(run.events.timeline)
    for i, k in enumerate(kinds):
        t, _ = run.events.timeline[k].points()
        col = "#c62828" if k in ("fault", "mixed", "unmixed") else "#1565c0"
        ax.plot(t, np.full(t.size, i), "o", color=col, ms=8)
    ax.set_yticks(range(len(kinds)), [k[:30] for k in kinds], fontsize=7)
    if not kinds:
        _nothing(ax, "no events")
    return png(fig)


def energy(run: RunData) -> str | None:
    """Drive energy used against run time (None: no power logged)."""
    e = run.frames.energy
    if e is None or e.n < 2:
        return None
    fig, ax = axes("drive energy used (J)")
    t, j = e.curve.points()
    ax.plot(t, j, color="#ef6c00", lw=2.0, label="used (from power_w)")
    ax.legend(loc="best", fontsize=8)
    return png(fig)


def overview(curves: Sequence[tuple[str, np.ndarray, np.ndarray]], ylabel: str = "Kalman trend MI") -> str:
    """Every run's trend in one plot (many runs: a thin line each, a legend for a dozen or fewer)."""
    fig, ax = axes(ylabel, (9.6, 3.6), left=0.08)
    many = len(curves) > 12
    for label, t, y in curves:
        if t.size and np.isfinite(y).any():
            ax.plot(t, y, lw=0.6 if many else 1.5, alpha=0.5 if many else 0.9, label=None if many else label)
    if not many and curves:
        ax.legend(loc="best", fontsize=7)
    if not curves:
        _nothing(ax)
    return png(fig)

"""``drumtwin compare``: MI curves of several runs in one figure (matplotlib, a PNG file).

Each run is read as the report reads it (``twin.report.load_run``: streamed, bounded, what could
not be read skipped and counted in its notes) and drawn from its decimated series, one run at a
time, so neither the length of a log nor the number of runs sets the memory, only the figure:
each run gets ``POINTS // runs`` buckets (at least ``MIN_BUCKETS``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin.report.events import PLOT_LIMIT

POINTS = 16_000
"""Buckets (min/max pairs) of a series shared by all the runs of one figure."""
MIN_BUCKETS = 100
ANNOTATED = 4
"""Runs up to which each move is written beside its mark (more: marks only)."""
COLOURS = ("#1565c0", "#c62828", "#2e7d32", "#6a1b9a")


def compare_runs(runs: Sequence[tuple[str, Path | str]], out_png: Path | str, title: str = "") -> tuple[Path, list]:
    """MI (raw, faint) and Kalman trend (bold) against run time for each ``(label, run dir)``, the
    rpm actually reached below and the AUTO moves marked; writes ``out_png``. Returns it and, per
    run, ``(label, summary, notes)``: frames, run time and rpm at the last trend, moves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from twin.report.load import load_run

    fig, (ax, ax2) = plt.subplots(
        2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1.2]}, constrained_layout=True
    )
    buckets = max(MIN_BUCKETS, POINTS // max(1, len(runs)))
    table: list[tuple[str, dict[str, Any], list[str]]] = []
    try:
        for i, (label, run_dir) in enumerate(runs):
            run = load_run(run_dir, label)
            _draw(ax, ax2, run, COLOURS[i % len(COLOURS)], buckets, annotate=len(runs) <= ANNOTATED)
            last = run.frames.last_trend
            table.append((label, {"frames": run.n_frames, "t_s": run.frames.t_max if last is None else last[0],
                                  "trend_mi": None if last is None else last[1],
                                  "rpm_actual": None if last is None else last[2],
                                  "moves": run.events.n_moves}, run.notes))
        ax.set_ylabel("mixing index (eq. 4, camera)")
        ax.set_ylim(0.6, 1.02)
        ax.grid(alpha=0.3)
        if len(runs) <= 12:
            ax.legend(loc="lower left", fontsize=9)
        if title:
            ax.set_title(title)
        ax2.set_ylabel("mill rpm (actual)")
        ax2.set_xlabel("run time (s)")
        ax2.grid(alpha=0.3)
        out = Path(out_png)
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
    finally:
        plt.close(fig)
    return out, table


def _draw(ax: Any, ax2: Any, run: Any, col: str, buckets: int, annotate: bool) -> None:
    """One run's curves and marks."""
    def series(name: str) -> tuple[np.ndarray, np.ndarray]:
        s = run.frames.series.get(name)
        return (np.zeros(0), np.zeros(0)) if s is None else s.coarser(buckets)

    ax.plot(*series("mi"), color=col, alpha=0.18, lw=0.8)
    ax.plot(*series("trend_mi"), color=col, lw=2.2, label=f"{run.label}: Kalman trend (raw MI faint)")
    ax2.plot(*series("rpm_actual"), color=col, lw=2, label=run.label)
    for t, rpm in run.events.marks:
        if abs(t) > PLOT_LIMIT:
            continue
        ax.axvline(t, color=col, ls="--", lw=1)
        if annotate:
            what = "?" if rpm is None else f"{rpm:g}"
            ax.annotate(f"{run.label}: segregation -> {what} rpm", (t, 0.62), rotation=90, va="bottom", ha="right",
                        fontsize=8, color=col)


def plot_runs(runs: Mapping[str, Path | str], out_png: Path | str, title: str = "") -> Path:
    """:func:`compare_runs` of ``{label: run dir}``: the PNG written."""
    return compare_runs(list(runs.items()), out_png, title)[0]

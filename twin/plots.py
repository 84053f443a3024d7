"""Plots of run logs (matplotlib, files only): MI curves of several runs in one figure."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from twin.runlog import read_events, read_frames


def _series(rows: list[dict], name: str) -> np.ndarray:
    """One column of run-log rows as floats (None -> NaN)."""
    return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)


def plot_runs(runs: Mapping[str, Path | str], out_png: Path | str, title: str = "") -> Path:
    """MI (raw, faint) and Kalman trend (bold) against run time for each labelled run dir,
    with the rpm actually reached below and the AUTO decisions marked; writes ``out_png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(
        2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1.2]}, constrained_layout=True
    )
    colours = ("#1565c0", "#c62828", "#2e7d32", "#6a1b9a")
    for i, (label, run_dir) in enumerate(runs.items()):
        rows = read_frames(run_dir)
        col = colours[i % len(colours)]

        t = _series(rows, "t_s")
        ax.plot(t, _series(rows, "mi"), color=col, alpha=0.18, lw=0.8)
        ax.plot(t, _series(rows, "trend_mi"), color=col, lw=2.2, label=f"{label}: Kalman trend (raw MI faint)")
        ax2.plot(t, _series(rows, "rpm_actual"), color=col, lw=2, label=label)
        moves = [e for e in read_events(run_dir) if e["kind"] == "decision" and e.get("decision") == "move"]
        for e in moves:
            ax.axvline(e["t_s"], color=col, ls="--", lw=1)
            ax.annotate(
                f"{label}: segregation -> {e.get('target_rpm') or e.get('rpm'):g} rpm",
                (e["t_s"], 0.62), rotation=90, va="bottom", ha="right", fontsize=8, color=col,
            )
    ax.set_ylabel("mixing index (eq. 4, camera)")
    ax.set_ylim(0.6, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=9)
    if title:
        ax.set_title(title)
    ax2.set_ylabel("mill rpm (actual)")
    ax2.set_xlabel("run time (s)")
    ax2.grid(alpha=0.3)
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out

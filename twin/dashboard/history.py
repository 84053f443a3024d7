"""The dashboard's history: the rig's recent runs under the MI plot, and the golden batch's MI
curve drawn behind the live one (the MI plot's first series: uPlot draws series in order), with
the current deviation from it.

Everything here reads the ``LiveState`` snapshot (``Snapshot.rig_history``, filled once by the
run's history thread, ``twin.catalogue.history``): the dashboard's thread never waits on the
catalogue. The pure helpers (:func:`golden_column`, :func:`history_markdown`) are tested on
their own.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np
from viser.uplot import Series

from twin.live.golden import RigHistory, deviation
from twin.state import Panel, Snapshot

GOLDEN_COLOUR = "#f9a825"
"""The golden batch's curve (amber: apart from the plot's grey, blue, orange and green)."""
GOLDEN_SERIES: Series = {"label": "golden batch", "stroke": GOLDEN_COLOUR, "width": 4}

NO_HISTORY = ("No earlier run of this rig in the run catalogue: this is its first batch, with no golden batch "
              "to compare.")


def golden_column(history: RigHistory, t_s: np.ndarray) -> np.ndarray:
    """The golden batch's trend MI at the live plot's run times (NaN where it has none)."""
    if history.golden is None:
        return np.full(np.shape(t_s), math.nan)
    return history.golden.mi_at(t_s)


def _num(x: float | None, spec: str) -> str:
    return "–" if x is None or not math.isfinite(x) else format(x, spec)


def _when(t: float) -> str:
    return dt.datetime.fromtimestamp(t).strftime("%Y-%m-%d %H:%M")


def history_markdown(h: RigHistory, panel: Panel) -> str:
    """The history panel (markdown): the rig's recent runs (time, mode, mixing time, final MI),
    its golden batch and this run's deviation from it now."""
    rig = f" of rig **{h.rig}**" if h.rig else ""
    if h.state == "none":
        return "**History:** not read (no run catalogue for this dashboard)."
    if h.state == "loading":
        return f"**History{rig}:** reading the run catalogue ..."
    if h.state == "unavailable":
        return f"**History{rig}:** the run catalogue could not be read ({h.message}): no history."
    if not h.runs and h.golden is None:
        return f"**History{rig}:** {NO_HISTORY}"
    lines = [f"**History{rig}:** the last {len(h.runs)} run(s)", "",
             "| started | mode | mixing time s | final MI |", "|---|---|---:|---:|"]
    lines += [f"| {_when(r.started_s)}{' ★' if r.golden else ''} | {r.mode} | {_num(r.mixing_time_s, '.1f')} | "
              f"{_num(r.final_mi, '.3f')} |" for r in h.runs]
    lines.append("")
    g = h.golden
    if g is None:
        lines.append("No golden batch for this rig (`drumtwin runs golden ID` marks one)." + (
            f" {h.message}." if h.message else ""))
        return "\n".join(lines)
    lines.append(f"**Golden batch** ★ {g.run_id[:8]} of {_when(g.started_s)}: drawn behind the live MI "
                 f"(spread from {g.runs} run(s)).  ")
    d = deviation(g, panel.t_s, panel.trend_mi)
    if d is None:
        lines.append("Deviation: – (no trend yet, or past the golden batch's end).")
    else:
        state = ("**behind the golden batch** by more than the rig's usual spread" if d.behind else
                 "ahead of the golden batch" if d.deviation > d.spread else "within the rig's usual spread")
        lines.append(f"Deviation now: **{d.deviation:+.3f}** (trend {d.mi:.3f}, golden {d.golden_mi:.3f} at "
                     f"{d.t_s:.0f} s; usual spread ±{d.spread:.3f}): {state}.")
    return "\n".join(lines)


class HistoryPanel:
    """The history's markdown element (added where it is built: under the MI plot)."""

    def __init__(self, gui: Any) -> None:
        self._md = gui.add_markdown(history_markdown(RigHistory(), Panel()))
        self._text = ""

    def push(self, snap: Snapshot) -> None:
        text = history_markdown(snap.rig_history, snap.panel)
        if text != self._text:
            self._md.content = text
            self._text = text

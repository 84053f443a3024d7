"""The dashboard's shared layout: the elements every viewer sees (camera and twin images,
the twin's particles, plots, the numbers panel, alarms, what-if results) and how one
``LiveState`` snapshot is pushed into them; the pure formatting helpers beside it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
import viser

from control.errors import ControlError
from control.limits import Limits
from twin.dashboard.history import GOLDEN_SERIES, HistoryPanel, golden_column
from twin.dashboard.scene import TwinScene
from twin.state import Panel, Snapshot, WhatIfView, forward_fill

MODE_LABELS = ("OFF", "MANUAL", "AUTO")
_BLANK = np.full((240, 240, 3), 24, dtype=np.uint8)
_WHATIF_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
DISPLAY_PX = 400  # frames are scaled to this width for the panel


def _rgb(image_bgr: np.ndarray) -> np.ndarray:
    """RGB copy for viser, scaled to ``DISPLAY_PX`` wide (small demo frames are enlarged)."""
    h, w = image_bgr.shape[:2]
    if w != DISPLAY_PX and w > 0:
        size = (DISPLAY_PX, max(1, round(h * DISPLAY_PX / w)))
        image_bgr = cv2.resize(image_bgr, size, interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(image_bgr[..., ::-1])


def _fmt(value: float | str | None, spec: str = ".3f") -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return "–" if not math.isfinite(value) else format(value, spec)
    return str(value)


def parse_rpm_list(text: str, limits: Limits | None = None) -> list[float]:
    """``"5, 20,40"`` -> ``[5.0, 20.0, 40.0]``; raises ValueError on junk, and on a list the
    what-if limits refuse (``control.limits``: the ``whatif`` command's caps), naming them."""
    try:
        rpms = [float(p) for p in str(text).replace(";", ",").split(",") if p.strip()]
    except ValueError:
        raise ValueError(f"rpm list must be numbers separated by commas (got {str(text)[:40]!r})") from None
    try:
        return (limits or Limits()).check_whatif(rpms, 1.0)[0]
    except ControlError as exc:
        raise ValueError(str(exc)) from None


def numbers_markdown(n: Panel) -> str:
    """The numbers panel (``twin.state.Panel``) as a markdown table."""
    rows = [
        ("MI (eq. 4)", _fmt(n.mi), "trend", _fmt(n.trend_mi)),
        ("d px", _fmt(n.d_px, ".1f"), "dσ px", _fmt(n.dsigma_px, ".1f")),
        ("concentration", _fmt(n.concentration), "twin MI", _fmt(n.twin_mi)),
        ("slope °", _fmt(n.slope_deg, ".1f"), "twin slope °", _fmt(n.twin_slope_deg, ".1f")),
        ("rpm set", _fmt(n.rpm_setpoint, ".1f"), "rpm actual", _fmt(n.rpm_actual, ".1f")),
        ("camera fps", _fmt(n.camera_fps, ".1f"), "twin fps", _fmt(n.twin_fps, ".1f")),
        ("mill", _fmt(n.mill_state), "mode", _fmt(n.mode)),
        ("run time s", _fmt(n.t_s, ".1f"), "friction", _fmt(n.friction)),
        ("trend", _fmt(n.trend_state), "light", _fmt(n.light_state)),
    ]
    lines = ["| | | | |", "|---|---:|---|---:|"]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    decision = n.last_decision
    reason = n.last_reason
    lines.append("")
    if str(n.light_state or "").startswith("changed"):
        lines.append("**The light moved too far to map back to the set-up's: no MI.** Re-learn the classes "
                     "from the live bed: **Re-learn classes** under Controls (with the control token).  ")
    if n.mixed:  # issue 24: the batch endpoint (control.endpoint)
        lines.append(f"**MIXED** since {_fmt(n.mixing_time_s, '.1f')} s (endpoint)  ")
    if n.trend_state == "unsettled":
        lines.append("*Trend not settled yet: no segregation decision until it is.*  ")
    lines.append(f"**Last decision:** {decision or '–'}  \n{reason or ''}")
    return "\n".join(lines)


def whatif_table_md(w: WhatIfView) -> str:
    """The what-if table (markdown): per rpm the plateau MI, regime, time and energy to the target MI
    and the drive power (whole drum)."""
    target = "target" if w.target_mi is None else f"MI {w.target_mi:g}"
    lines = [f"| rpm | plateau MI | regime | time to {target} (s) | power (W) | energy (J) |",
             "|---:|---:|---|---:|---:|---:|"]
    lines += [
        f"| {r:g} | {_fmt(p)} | {g} | {_fmt(_at(w.time_to_target_s, i), '.1f')} | "
        f"{_fmt(_at(w.power_w, i), '.2f')} | {_fmt(_at(w.energy_to_target_j, i), '.0f')} |"
        for i, (r, p, g) in enumerate(zip(w.rpms, w.plateau_mi, w.regime, strict=True))
    ]
    return "\n".join(lines)


def _at(values: tuple[float, ...], i: int) -> float:
    """``values[i]``, NaN past its end (a study without that column)."""
    return values[i] if i < len(values) else float("nan")


def axis_range(*series: np.ndarray, step: float, pad: float = 0.0) -> tuple[float, float] | None:
    """Y-axis range over the finite values of ``series``, padded and widened to multiples of ``step``.

    uPlot's own auto-range turns NaN (a twin not started yet) into an empty plot, so the
    dashboard sets the range itself; the step keeps it from changing on every update.
    None when no value is finite.
    """
    vals = np.concatenate([np.asarray(x, float).ravel() for x in series]) if series else np.zeros(0)
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return None
    lo = math.floor((float(vals.min()) - pad) / step) * step
    hi = math.ceil((float(vals.max()) + pad) / step) * step
    return (lo, hi) if hi > lo else (lo, lo + step)


def alarms_html(alarms: Sequence[str]) -> str:
    """A red banner per alarm, or a quiet OK line."""
    if not alarms:
        return '<div id="drumtwin-alarms" style="color:#2e7d32;font-weight:600">✔ no alarms</div>'
    items = "".join(f"<div>⚠ {a}</div>" for a in alarms)
    return (
        '<div id="drumtwin-alarms" style="background:#c62828;color:white;padding:6px 8px;'
        f'border-radius:4px;font-weight:600">ALARM{items}</div>'
    )



class Layout:
    """The shared elements of one viser server (see module doc); ``controls_folder``,
    ``whatif_folder`` and ``setup_folder`` are where each viewer's own controls go
    (``twin.dashboard.controls``); ``plots_panel`` holds the set-up view's tab (``twin.dashboard.setup``)."""

    def __init__(self, server: viser.ViserServer, title: str = "drumtwin") -> None:
        self._server = server
        self._y_ranges: dict[int, tuple[float, float]] = {}  # per plot: the y range last sent
        self._build_shared(title)
        self.scene = TwinScene(server)

    def _build_shared(self, title: str) -> None:
        gui = self._server.gui
        gui.configure_theme(show_share_button=False, brand_color=(33, 90, 160))
        self._live_panel = gui.add_panel()
        with self._live_panel.add_tab("Camera vs twin"):
            self._alarm = gui.add_html(alarms_html(()))
            self._camera_img = gui.add_image(_BLANK, label="camera (live, with overlay)", jpeg_quality=80)
            self._twin_img = gui.add_image(_BLANK, label="twin (rendered)", jpeg_quality=80)
        self._live_panel.dock_left()
        self._live_panel.set_width(420)

        self.plots_panel = self._plots_panel = gui.add_panel()
        with self._plots_panel.add_tab("Plots"):
            self._numbers = gui.add_markdown(numbers_markdown(Panel()))
            z = np.zeros(1)
            self._mi_plot = gui.add_uplot(
                (z,) * 8,
                (
                    {"label": "t s"},
                    GOLDEN_SERIES,  # first: drawn behind the live curves
                    {"label": "MI raw", "stroke": "#9e9e9e", "width": 1},
                    {"label": "trend", "stroke": "#1565c0", "width": 2},
                    {"label": "lo95", "stroke": "rgba(21,101,192,0.3)", "width": 1},
                    {"label": "hi95", "stroke": "rgba(21,101,192,0.3)", "width": 1},
                    {"label": "MA150", "stroke": "#ef6c00", "width": 1.5},
                    {"label": "twin MI", "stroke": "#2e7d32", "width": 2},
                ),
                title="Mixing index",
                bands=({"series": (5, 4), "fill": "rgba(21,101,192,0.15)"},),
                scales={"x": {"time": False}, "y": {"auto": False, "range": (0.0, 1.0)}},
                aspect=1.8,
            )
            self.history = HistoryPanel(gui)
            self._rpm_plot = gui.add_uplot(
                (z,) * 3,
                (
                    {"label": "t s"},
                    {"label": "setpoint rpm", "stroke": "#6a1b9a", "width": 2},
                    {"label": "actual rpm", "stroke": "#00897b", "width": 2},
                ),
                title="Mill rpm",
                scales={"x": {"time": False}},
                aspect=2.6,
            )
            self._slope_plot = gui.add_uplot(
                (z,) * 3,
                (
                    {"label": "t s"},
                    {"label": "slope °", "stroke": "#5d4037", "width": 1.5},
                    {"label": "twin slope °", "stroke": "#2e7d32", "width": 1.5},
                ),
                title="Bed slope angle",
                scales={"x": {"time": False}},
                aspect=2.6,
            )
        self._plots_panel.dock_right()
        self._plots_panel.set_width(520)

        self._server.gui.main_panel.dock_right()
        self._server.gui.main_panel.set_width(340)
        self.controls_folder = gui.add_folder("Controls")
        self.whatif_folder = gui.add_folder("What-if")
        self.setup_folder = gui.add_folder("Commissioning")
        with self.whatif_folder:
            self._whatif_status = gui.add_markdown("No study yet.")
            self._whatif_plot = gui.add_uplot(
                (np.zeros(1), np.zeros(1)),
                ({"label": "t s"}, {"label": "–"}),
                title="What-if MI",
                scales={"x": {"time": False}, "y": {"auto": False, "range": (0.0, 1.0)}},
                aspect=1.5,
            )
            self._whatif_table = gui.add_markdown("")
        self._whatif_seq = -1

    def push(self, snap: Snapshot, seen: dict[str, int | str | None], plots: bool) -> bool:
        """Push what changed since ``seen`` (sequence numbers, updated here); the plots only
        when ``plots``. True when an image or the plots were pushed."""
        pushed = False
        if snap.camera_image is not None and snap.camera_seq != seen["camera"]:
            self._camera_img.image = _rgb(snap.camera_image)
            seen["camera"] = snap.camera_seq
            pushed = True
        if snap.twin_image is not None and snap.twin_seq != seen["twin"]:
            self._twin_img.image = _rgb(snap.twin_image)
            if snap.twin_particles is not None and snap.twin_drum_r_m:
                self.scene.update(snap.twin_particles, snap.twin_drum_r_m)
            seen["twin"] = snap.twin_seq
        self._alarm.content = alarms_html(snap.alarms)
        self._numbers.content = numbers_markdown(snap.panel)
        fresh = snap.history_seq != seen["hist"] or snap.rig_history_seq != seen.get("rig")  # new frames or golden
        if plots and fresh and len(snap.history["t_s"]) >= 2:
            h = {k: forward_fill(v) for k, v in snap.history.items()}
            t = h["t_s"]
            self._mi_plot.data = (t, golden_column(snap.rig_history, t), h["mi"], h["trend_mi"], h["trend_lo95"],
                                  h["trend_hi95"], h["ma_mi"], h["twin_mi"])
            for plot, ys in (
                (self._rpm_plot, (h["rpm_setpoint"], h["rpm_actual"])),
                (self._slope_plot, (h["slope_deg"], h["twin_slope_deg"])),
            ):
                rng = axis_range(*ys, step=5.0, pad=1.0)  # rpm and degrees alike
                if rng is not None and rng != self._y_ranges.get(id(plot)):
                    plot.scales = {"x": {"time": False}, "y": {"auto": False, "range": rng}}
                    self._y_ranges[id(plot)] = rng
                plot.data = (t, *ys)
            seen["hist"], seen["rig"] = snap.history_seq, snap.rig_history_seq
            pushed = True
        if plots:
            self.history.push(snap)
        if snap.whatif.seq != self._whatif_seq:
            self._push_whatif(snap)
        return pushed

    def _push_whatif(self, snap: Snapshot) -> None:
        w = snap.whatif
        self._whatif_seq = w.seq
        self._whatif_status.content = f"**status:** {w.status}"
        if not w.rpms:
            return
        # one x axis for all curves: the union of the time grids, each curve interpolated
        t = np.unique(np.concatenate([np.asarray(x, float) for x in w.t_s]))
        ys = tuple(np.interp(t, np.asarray(x, float), np.asarray(y, float)) for x, y in zip(w.t_s, w.mi, strict=True))
        series: tuple[Any, ...] = (
            {"label": "t s"},
            *({"label": f"{r:g} rpm", "stroke": _WHATIF_COLOURS[i % len(_WHATIF_COLOURS)], "width": 2}
              for i, r in enumerate(w.rpms)),
        )
        with self._server.atomic():
            self._whatif_plot.series = series
            # pin x to this study's horizon (uPlot otherwise keeps a wider range from an earlier study)
            self._whatif_plot.scales = {
                "x": {"time": False, "auto": False, "range": (float(t[0]), float(max(t[-1], t[0] + 1.0)))},
                "y": {"auto": False, "range": (0.0, 1.0)},
            }
            self._whatif_plot.data = (t, *ys)
        self._whatif_table.content = whatif_table_md(w)


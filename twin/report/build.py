"""The report: read run dirs (``twin.runlog``), draw the plots (matplotlib, PNG in memory),
write one HTML file with everything inline. See the package doc for the sections."""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.errors import TwinError
from twin.runlog import FRAMES_FILE, read_events, read_frames, read_metadata

SECTIONS: tuple[tuple[str, str], ...] = (
    ("summary", "Summary"),
    ("mi", "Mixing index: raw, trend, twin"),
    ("rpm", "Mill rpm: set and actual"),
    ("slope", "Bed slope angle"),
    ("events", "Events"),
    ("endpoint", "Endpoint and mixing time"),
    ("energy", "Energy: used and predicted"),
    ("config", "Configuration"),
    ("versions", "Versions"),
)
"""(id, title) of every section, in order: each run has each one (``data-section``)."""

PLOT_SECTIONS = ("mi", "rpm", "slope", "events")
"""Sections whose plot is always drawn (an empty run shows empty axes, never nothing)."""

COLOURS = {"mi": "#9e9e9e", "trend_mi": "#1565c0", "twin_mi": "#2e7d32", "rpm_setpoint": "#ef6c00",
           "rpm_actual": "#6a1b9a", "slope_deg": "#1565c0", "twin_slope_deg": "#2e7d32"}


@dataclass
class RunData:
    """One run dir, read back: frame rows, events, metadata ({} when absent or unreadable)
    and what is wrong with it (``notes``: e.g. no stop event)."""

    path: Path
    label: str
    frames: list[dict[str, Any]]
    events: list[dict[str, Any]]
    metadata: dict[str, Any]
    notes: list[str] = field(default_factory=list)

    def series(self, name: str) -> np.ndarray:
        """One frame column as floats (missing or empty cells: NaN)."""
        out = []
        for r in self.frames:
            v = r.get(name)
            out.append(float(v) if isinstance(v, (int, float)) else math.nan)
        return np.asarray(out, dtype=float)

    @property
    def clean_stop(self) -> bool:
        return any(e.get("kind") == "stop" for e in self.events)


def load_run(path: Path | str, label: str | None = None) -> RunData:
    """Read one run dir; a missing dir or one without ``frames.csv`` is a one-line TwinError."""
    p = Path(path)
    if not p.exists():
        raise TwinError(f"no such run dir: {p}")
    if not p.is_dir() or not (p / FRAMES_FILE).is_file():
        raise TwinError(f"{p} is not a run log dir (no {FRAMES_FILE})")
    try:
        frames = read_frames(p)
    except (OSError, UnicodeDecodeError) as exc:
        raise TwinError(f"cannot read {p / FRAMES_FILE}: {exc}") from None
    notes: list[str] = []
    try:
        events = read_events(p) if (p / "events.jsonl").is_file() else []
    except (OSError, UnicodeDecodeError) as exc:
        events, notes = [], [f"events unreadable: {exc}"]
    try:
        meta = read_metadata(p) if (p / "metadata.json").is_file() else {}
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        meta = {}
        notes.append(f"metadata.json unreadable: {exc}")
    run = RunData(p, label or p.name, frames, events, meta if isinstance(meta, dict) else {}, notes)
    if not run.clean_stop:
        run.notes.append("the run did not end cleanly (no stop event; killed?): showing what was logged")
    if not frames:
        run.notes.append("no frame rows were logged")
    return run


# -- plots ----------------------------------------------------------------------------------------
def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _axes(ylabel: str) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 2.8), constrained_layout=True)
    ax.set_xlabel("run time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    return fig, ax


def _lines(run: RunData, names: Sequence[tuple[str, str]], ylabel: str, marks: Sequence[float] = ()) -> str:
    fig, ax = _axes(ylabel)
    t = run.series("t_s")
    drawn = False
    for name, label in names:
        y = run.series(name)
        if t.size and np.isfinite(y).any():
            style = dict(lw=0.8, alpha=0.6) if name == "mi" else dict(lw=2.0)
            ax.plot(t, y, color=COLOURS.get(name, "#000000"), label=label, **style)
            drawn = True
    for m in marks:
        ax.axvline(m, color="#c62828", ls="--", lw=1.2)
    if drawn:
        ax.legend(loc="best", fontsize=8)
    else:
        ax.text(0.5, 0.5, "nothing logged", transform=ax.transAxes, ha="center", va="center", color="#c62828")
    return _png(fig)


def _timeline(run: RunData) -> str:
    fig, ax = _axes("event")
    kinds = sorted({str(e.get("kind")) for e in run.events})
    ys = {k: i for i, k in enumerate(kinds)}
    for e in run.events:
        t = e.get("t_s")
        if isinstance(t, (int, float)) and math.isfinite(t):
            k = str(e.get("kind"))
            col = "#c62828" if k in ("fault", "mixed", "unmixed") else "#1565c0"
            ax.plot([t], [ys[k]], "o", color=col, ms=8)
    ax.set_yticks(range(len(kinds)), kinds, fontsize=7)
    if not kinds:
        ax.text(0.5, 0.5, "no events", transform=ax.transAxes, ha="center", va="center", color="#c62828")
    return _png(fig)


def _energy_plot(used_t: np.ndarray, used_j: np.ndarray) -> str:
    fig, ax = _axes("drive energy used (J)")
    ax.plot(used_t, used_j, color="#ef6c00", lw=2.0, label="used (from power_w)")
    ax.legend(loc="best", fontsize=8)
    return _png(fig)


# -- sections -------------------------------------------------------------------------------------
def _fmt(v: Any, spec: str = ".3f") -> str:
    if isinstance(v, bool) or v is None:
        return "–" if v is None else str(v)
    if isinstance(v, (int, float)):
        return format(v, spec) if math.isfinite(v) else "–"
    return html.escape(str(v))


def _table(rows: Sequence[Sequence[Any]], head: Sequence[str] = ()) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table>{'<tr>' + h + '</tr>' if h else ''}{body}</table>"


def _img(section: str, idx: int, uri: str, alt: str) -> str:
    return f'<img class="plot" id="plot-{section}-{idx}" data-plot="{section}" alt="{html.escape(alt)}" src="{uri}">'


def endpoint_of(run: RunData) -> dict[str, Any]:
    """The run's endpoint: the live ``mixed``/``unmixed`` events, or (none logged) the
    detector replayed on the logged raw MI (``source`` says which)."""
    changes = [e for e in run.events if e.get("kind") in ("mixed", "unmixed")]
    if changes:
        last = changes[-1]
        mixed = last.get("kind") == "mixed"
        return {"source": "live", "mixing_time_s": last.get("mixing_time_s") if mixed else None,
                "plateau_mi": last.get("plateau_mi") if mixed else None,
                "changes": [(e.get("t_s"), e.get("kind"), e.get("mixing_time_s"), e.get("reason", ""))
                            for e in changes]}
    from control.endpoint import endpoint_of_series
    from twin.run.settings import endpoint_config, trend_config

    t, mi = run.series("t_s"), run.series("mi")
    ok = np.isfinite(t)
    res = endpoint_of_series(t[ok], mi[ok], endpoint_config(), trend_config())
    return {"source": "offline (no endpoint events in the log: the run's raw MI replayed through the detector)",
            "mixing_time_s": res.mixing_time_s, "plateau_mi": res.plateau_mi, "changes": list(res.changes)}


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _rpm_key(k: Any) -> float | None:
    """An rpm key of a logged mapping ("45.0") as a number (None: not one)."""
    try:
        return float(k)
    except (TypeError, ValueError):
        return None


DEFAULT_HORIZON_S = 40.0
"""The plant's window after a decision when the run logged no study horizon (``RunConfig.whatif_horizon_s``)."""


def time_to_mix_check(run: RunData) -> dict[str, Any] | None:
    """The twin's predicted time to mix at the rpm AUTO picked against the plant's (docs/endpoint.md).

    The decision: the first ``move`` whose target rpm the mill reached (within 1 rpm) before the next
    ``move`` (a ramp cut short by the safe state does not count) and that carries a predicted time
    (``predicted_time_to_target_s``, objective time/energy) or whose predictions are a what-if study's
    with times. ``predicted_s``: the study's time to the target at that rpm (from its start state, the
    rpm ramped as the mill does); ``actual_s``: from the decision until the logged raw camera MI reaches
    the target and stays there to the end of the study's horizon after the decision (or the next
    ``move``): ``sim.whatif.time_to_target``, the twin's own definition, None when it does not; ``endpoint_s``:
    until the endpoint's mixing time; ``error_pct``: 100 (predicted - actual) / actual;
    ``state_t_s``: when the study's start state was taken; ``twin_mi_at_state``: the running twin's MI then
    and ``plant_mi_at_decision``: the camera's raw MI at the decision (means of the logged rows within
    1 s, the 2 s of ``time_to_target``): a twin bed more mixed than the plant's predicts too short a
    time. None when the run has no such decision."""
    from sim.whatif import time_to_target

    studies = [e for e in run.events if e.get("kind") == "whatif" and isinstance(e.get("time_to_target_s"), dict)]
    moves = [e for e in run.events if e.get("kind") == "decision" and e.get("decision") == "move"
             and _num(e.get("t_s")) is not None and _num(e.get("target_rpm")) is not None]
    t, mi, rpm_act = run.series("t_s"), run.series("mi"), run.series("rpm_actual")
    for i, d in enumerate(moves):
        t_d, rpm = float(d["t_s"]), float(d["target_rpm"])
        t_next = float(moves[i + 1]["t_s"]) if i + 1 < len(moves) else math.inf
        reached = np.nonzero(np.isfinite(t) & (t >= t_d) & (t < t_next) & (np.abs(rpm_act - rpm) <= 1.0))[0]
        if reached.size == 0:
            continue
        study = next((w for w in reversed(studies) if w.get("predictions") == d.get("predictions")
                      and (_num(w.get("t_s")) or math.inf) <= t_d + 1e-6), None)
        pred = _num(d.get("predicted_time_to_target_s"))
        if pred is None and study is not None:
            pred = _num(next((v for k, v in study["time_to_target_s"].items() if _rpm_key(k) == rpm), None))
        if pred is None:
            continue
        meta_cfg = run.metadata.get("config")
        cfg: dict[str, Any] = meta_cfg if isinstance(meta_cfg, dict) else {}
        target = _num(None if study is None else study.get("target_mi")) or _num(cfg.get("target_mi"))
        if target is None:
            from twin.run.settings import endpoint_config

            target = endpoint_config().target_mi
        horizon = _num(None if study is None else study.get("duration_s")) or DEFAULT_HORIZON_S
        after = np.isfinite(t) & (t >= t_d) & (t <= min(t_d + horizon, t_next))  # the study's horizon
        actual = None
        if after.sum() >= 2:
            tt = t[after]
            hit = time_to_target(tt, mi[after], target)
            actual = float(hit + tt[0] - t_d) if math.isfinite(hit) else None
        first_mixed = next((e for e in run.events if e.get("kind") == "mixed" and (_num(e.get("t_s")) or -1) >= t_d),
                           None)
        mt = None if first_mixed is None else _num(first_mixed.get("mixing_time_s"))
        state_t = None if study is None else _num(study.get("requested_t_s"))
        return {"t_decision_s": t_d, "rpm": rpm, "t_reached_s": float(t[reached[0]]), "target_mi": target,
                "twin_mi_at_state": None if state_t is None else _mean_near(t, run.series("twin_mi"), state_t),
                "plant_mi_at_decision": _mean_near(t, mi, t_d),
                "predicted_s": pred, "state_t_s": state_t,
                "actual_s": actual, "endpoint_s": None if mt is None else max(0.0, mt - t_d),
                "error_pct": None if not actual else 100.0 * (pred - actual) / actual,
                "predicted_energy_j": _num(d.get("predicted_energy_j"))}
    return None


def _mean_near(t: np.ndarray, y: np.ndarray, t0: float, half_s: float = 1.0) -> float | None:
    """Mean of the finite ``y`` with ``|t - t0| <= half_s`` (None: none)."""
    sel = np.isfinite(t) & np.isfinite(y) & (np.abs(t - t0) <= half_s)
    return float(np.mean(y[sel])) if sel.any() else None


def _time_to_mix_html(run: RunData) -> str:
    c = time_to_mix_check(run)
    if c is None:
        return '<p class="none">No AUTO move (whose rpm the mill reached) with a predicted time to mix.</p>'
    rows = [("decision at s", _fmt(c["t_decision_s"], ".1f")), ("rpm picked", _fmt(c["rpm"], "g")),
            ("mill at that rpm at s", _fmt(c["t_reached_s"], ".1f")), ("target MI", _fmt(c["target_mi"], "g")),
            ("twin state of the study from s", _fmt(c["state_t_s"], ".1f")),
            ("twin MI then / plant MI at the decision (2 s means)",
             f'{_fmt(c["twin_mi_at_state"])} / {_fmt(c["plant_mi_at_decision"])}'),
            ("twin: predicted time to target s", _fmt(c["predicted_s"], ".1f")),
            ("plant: time to target s (raw MI, 2 s mean, held 5 s)", _fmt(c["actual_s"], ".1f")),
            ("error %", f'<b class="ttm-error">{_fmt(c["error_pct"], "+.0f")}</b>'),
            ("plant: time to the endpoint's mixing time s", _fmt(c["endpoint_s"], ".1f"))]
    return "<h4>Twin's time to mix against the plant's</h4>" + _table(rows)


def _energy(run: RunData) -> tuple[str, str | None]:
    """Energy used (frames ``power_w``, integrated over run time) and predicted (what-if
    events with ``energy_to_target_j`` per rpm): HTML and an optional plot."""
    parts: list[str] = []
    plot = None
    t, p = run.series("t_s"), run.series("power_w")
    ok = np.isfinite(t) & np.isfinite(p)
    if ok.sum() >= 2:
        tt, pp = t[ok], p[ok]
        used = np.concatenate([[0.0], np.cumsum(0.5 * (pp[1:] + pp[:-1]) * np.diff(tt))])
        parts.append(f"<p>Drive energy used: <b>{used[-1]:.1f} J</b> over {tt[-1] - tt[0]:.0f} s "
                     f"(mean power {float(np.mean(pp)):.2f} W).</p>")
        plot = _energy_plot(tt, used)
    preds = [e for e in run.events if e.get("kind") == "whatif" and isinstance(e.get("energy_to_target_j"), dict)]
    for e in preds[-3:]:
        def col(key: str, rpm: str, spec: str, ev: dict = e) -> str:
            d = ev.get(key)
            return _fmt(d.get(rpm), spec) if isinstance(d, dict) else "–"

        rows = [(html.escape(str(r)), _fmt(j, ".1f"), col("time_to_target_s", r, ".0f"), col("power_w", r, ".2f"),
                 col("predictions", r, ".3f")) for r, j in e["energy_to_target_j"].items()]
        target = f" to MI {_fmt(e.get('target_mi'), 'g')}" if e.get("target_mi") is not None else ""
        parts.append(f"<p>Predicted{target} at t = {_fmt(e.get('t_s'), '.0f')} s "
                     f"({html.escape(str(e.get('reason', '')))}):</p>"
                     + _table(rows, ("rpm", "energy to target J", "time to target s", "power W", "plateau MI")))
    if not parts:
        parts.append('<p class="none">No energy logged in this run (no power_w column, no what-if energy).</p>')
    return "".join(parts), plot


def _run_column(run: RunData, idx: int) -> dict[str, str]:
    """HTML of each section for one run."""
    out: dict[str, str] = {}
    t = run.series("t_s")
    end = endpoint_of(run)
    mt = end["mixing_time_s"]
    decisions = [e for e in run.events if e.get("kind") == "decision"]
    faults = [e for e in run.events if e.get("kind") == "fault"]
    mode = run.metadata.get("config", {}).get("mode") if isinstance(run.metadata.get("config"), dict) else None
    if mode is None and run.frames:
        mode = run.frames[-1].get("mode")
    trend = run.series("trend_mi")
    last_trend = trend[np.isfinite(trend)][-1] if np.isfinite(trend).any() else math.nan
    notes = "".join(f'<p class="note">{html.escape(n)}</p>' for n in run.notes)
    out["summary"] = notes + _table([
        ("run dir", html.escape(str(run.path))), ("mode", _fmt(mode)), ("frames", str(len(run.frames))),
        ("run time s", _fmt(float(np.nanmax(t)) if np.isfinite(t).any() else None, ".1f")),
        ("final trend MI", _fmt(last_trend)), ("decisions", str(len(decisions))), ("faults", str(len(faults))),
        ("mixing time s", _fmt(mt, ".1f")), ("ended cleanly", "yes" if run.clean_stop else "no"),
    ])
    marks = [float(mt)] if isinstance(mt, (int, float)) else []
    out["mi"] = _img("mi", idx, _lines(run, (("mi", "raw MI"), ("trend_mi", "Kalman trend"), ("twin_mi", "twin")),
                                       "mixing index", marks), "MI raw, trend and twin")
    out["rpm"] = _img("rpm", idx, _lines(run, (("rpm_setpoint", "set"), ("rpm_actual", "actual")), "rpm"),
                      "rpm set and actual")
    out["slope"] = _img("slope", idx, _lines(run, (("slope_deg", "camera"), ("twin_slope_deg", "twin")),
                                             "slope (deg)"), "bed slope")
    shown = [e for e in run.events if e.get("kind") not in ("trend_settled", "trend_unsettled")][-200:]
    rows = [(_fmt(e.get("t_s"), ".1f"), html.escape(str(e.get("kind"))),
             html.escape(str(e.get("decision") or e.get("fault") or e.get("action") or e.get("command") or "")),
             html.escape(str(e.get("reason") or e.get("message") or ""))[:300]) for e in shown]
    out["events"] = _img("events", idx, _timeline(run), "event timeline") + (
        f'<details><summary>{len(run.events)} events</summary>{_table(rows, ("t s", "kind", "what", "why"))}'
        "</details>")
    ch_rows = [(_fmt(c[0], ".1f"), html.escape(str(c[1])), _fmt(c[2], ".1f"), html.escape(str(c[3]))[:300])
               for c in end["changes"]]
    first = next((c for c in end["changes"] if c[1] == "mixed"), None)
    if mt is not None:
        banner = (f'<p class="mixed">MIXED: mixing time <b class="mixing-time">{_fmt(mt, ".1f")} s</b>, plateau MI '
                  f'{_fmt(end["plateau_mi"])}</p>')
    elif first is not None:  # the batch reached its endpoint, then left the band (e.g. the mill stopped)
        left = next((c for c in end["changes"] if c[1] == "unmixed" and c[0] >= first[0]), None)
        banner = (f'<p class="mixed">MIXED at {_fmt(first[0], ".1f")} s: mixing time <b class="mixing-time">'
                  f'{_fmt(first[2], ".1f")} s</b>; it left the band again at '
                  f'{_fmt(None if left is None else left[0], ".1f")} s: not mixed at the end of the log.</p>')
    else:
        banner = '<p class="none">Not mixed at the end of the log (no mixing time).</p>'
    out["endpoint"] = banner + f"<p>source: {html.escape(end['source'])}</p>" + (
        _table(ch_rows, ("t s", "change", "mixing time s", "why")) if ch_rows else "") + _time_to_mix_html(run)
    energy_html, energy_plot = _energy(run)
    out["energy"] = energy_html + ("" if energy_plot is None else _img("energy", idx, energy_plot, "energy used"))
    cfg = run.metadata.get("config")
    out["config"] = (f"<pre>{html.escape(json.dumps(cfg, indent=1, sort_keys=True))}</pre>" if cfg
                     else '<p class="none">No configuration logged (no metadata.json).</p>')
    vers = run.metadata.get("versions")
    out["versions"] = (_table([(html.escape(str(k)), html.escape(str(v))) for k, v in vers.items()])
                       if isinstance(vers, dict) and vers else '<p class="none">No versions logged.</p>')
    return out


CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:16px;color:#212121;background:#fff}
h1{font-size:20px} h2{font-size:16px;margin:18px 0 6px;border-bottom:1px solid #ccc}
.runs{display:grid;grid-template-columns:repeat(var(--n),minmax(420px,1fr));gap:16px}
.run{min-width:0} .run h3{margin:4px 0;font-size:15px}
img.plot{width:100%;height:auto;border:1px solid #eee}
table{border-collapse:collapse;font-size:12px} td,th{border:1px solid #ddd;padding:2px 6px;text-align:left}
pre{font-size:11px;max-height:300px;overflow:auto;background:#fafafa}
.note{color:#b71c1c;font-weight:bold} .mixed{color:#1b5e20;font-size:16px} .none{color:#757575}
"""


def render_html(runs: Sequence[RunData], title: str = "drumtwin report") -> str:
    """The whole report as one HTML string (no external resource of any kind)."""
    cols = [_run_column(r, i) for i, r in enumerate(runs)]
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>"
             f"<p>{len(runs)} run(s): " + ", ".join(html.escape(r.label) for r in runs) + "</p>"]
    for sid, stitle in SECTIONS:
        parts.append(f'<h2 id="{sid}">{html.escape(stitle)}</h2><div class="runs" style="--n:{len(runs)}">')
        for i, (run, col) in enumerate(zip(runs, cols, strict=True)):
            parts.append(f'<section class="run" data-section="{sid}" data-run="{i}"><h3>{html.escape(run.label)}'
                         f"</h3>{col[sid]}</section>")
        parts.append("</div>")
    parts.append("</body></html>")
    return "".join(parts)


def build_report(run_dirs: Sequence[Path | str], out: Path | str, title: str = "drumtwin report") -> Path:
    """Read ``run_dirs`` (each ``LABEL=DIR`` or ``DIR``) and write the report to ``out``
    (atomically: a temporary file, then renamed). Bad input: one-line TwinError."""
    if not run_dirs:
        raise TwinError("give at least one run dir")
    target = Path(out)
    if target.is_dir():
        raise TwinError(f"--out {target} is a directory: give a file name (report.html)")
    if not target.parent.is_dir():
        raise TwinError(f"--out: folder {target.parent} does not exist")
    runs = []
    for spec in run_dirs:
        label, sep, d = str(spec).partition("=")
        runs.append(load_run(d if sep else spec, label if sep else None))
    text = render_html(runs, title)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise TwinError(f"cannot write --out {target}: {exc.strerror or exc}") from None
    return target

"""The report's HTML: read run dirs one at a time (``twin.report.load``), draw the plots
(``twin.report.figures``), write one HTML file with everything inline. See the package doc for
the sections.

Runs are read one at a time and only what the page shows of each is kept. Up to
``MAX_DETAILED`` runs each get every section, side by side; a report of more runs opens with an
"All runs" table (one row per run, its notes in it) and one plot of every run's trend, and the
sections below show the first ``MAX_DETAILED`` runs given: the page stays a few MB for a
thousand runs.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.errors import TwinError
from twin.report import figures
from twin.report.batch import batch_html
from twin.report.cells import fmt, table
from twin.report.events import text
from twin.report.frames import PLOTS
from twin.report.load import RunData, check_dir, load_run

if TYPE_CHECKING:
    from twin.catalogue.select import Batch

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
"""(id, title) of every section, in order: each run shown in detail has each one (``data-section``)."""

MAX_DETAILED = 8
"""Runs shown section by section, side by side (the first ones given)."""
OVERVIEW_BUCKETS = 200
"""Points a run's trend gets in the all-runs plot (min/max of 200 buckets)."""
MAX_TEXT = 200_000
"""Characters of a run's configuration or versions shown (a metadata.json can be large)."""


def _img(section: str, idx: int, uri: str, alt: str) -> str:
    return f'<img class="plot" id="plot-{section}-{idx}" data-plot="{section}" alt="{html.escape(alt)}" src="{uri}">'


def endpoint_of(run: RunData) -> dict[str, Any]:
    """The run's endpoint (``twin.report.load``): source, mixing time, plateau, the changes kept."""
    return run.endpoint


def time_to_mix_check(run: RunData) -> dict[str, Any] | None:
    """The twin's time to mix against the plant's (``twin.report.ttm``; None: no such decision)."""
    return run.time_to_mix


# -- sections -------------------------------------------------------------------------------------
def _summary(run: RunData) -> str:
    s = run.summary()
    notes = "".join(f'<p class="note">{html.escape(n)}</p>' for n in run.notes)
    return notes + table([
        ("run dir", html.escape(str(run.path))), ("mode", fmt(s["mode"])), ("frames", str(s["frames"])),
        ("run time s", fmt(s["run_time_s"], ".1f")), ("final trend MI", fmt(s["final_trend_mi"])),
        ("decisions", str(s["decisions"])), ("faults", str(s["faults"])),
        ("mixing time s", fmt(s["mixing_time_s"], ".1f")), ("ended cleanly", "yes" if s["ended_cleanly"] else "no")])


def _events(run: RunData, idx: int) -> str:
    ev = run.events
    shown = "trend changes left out" + (f"; the last {len(ev.shown)} shown" if ev.n > len(ev.shown) else "")
    return _img("events", idx, figures.timeline(run), "event timeline") + (
        f"<details><summary>{ev.n} events ({shown})</summary>"
        f"{table(list(ev.shown), ('t s', 'kind', 'what', 'why'))}</details>")


def _endpoint(run: RunData) -> str:
    end = run.endpoint
    mt, first, left = end["mixing_time_s"], end["first_mixed"], end["left_after"]
    if mt is not None:
        banner = (f'<p class="mixed">MIXED: mixing time <b class="mixing-time">{fmt(mt, ".1f")} s</b>, plateau MI '
                  f'{fmt(end["plateau_mi"])}</p>')
    elif first is not None:  # the batch reached its endpoint, then left the band (e.g. the mill stopped)
        banner = (f'<p class="mixed">MIXED at {fmt(first[0], ".1f")} s: mixing time <b class="mixing-time">'
                  f'{fmt(first[2], ".1f")} s</b>; it left the band again at '
                  f'{fmt(None if left is None else left[0], ".1f")} s: not mixed at the end of the log.</p>')
    else:
        banner = '<p class="none">Not mixed at the end of the log (no mixing time).</p>'
    rows = [(fmt(c[0], ".1f"), text(c[1]), fmt(c[2], ".1f"), text(c[3])) for c in end["changes"]]
    more = f"<p>{end['total']} changes, the last {len(rows)} shown.</p>" if end["total"] > len(rows) else ""
    return banner + f"<p>source: {html.escape(end['source'])}</p>" + more + (
        table(rows, ("t s", "change", "mixing time s", "why")) if rows else "") + _time_to_mix_html(run)


def _time_to_mix_html(run: RunData) -> str:
    c = run.time_to_mix
    if c is None:
        return '<p class="none">No AUTO move (whose rpm the mill reached) with a predicted time to mix.</p>'
    rows = [("decision at s", fmt(c["t_decision_s"], ".1f")), ("rpm picked", fmt(c["rpm"], "g")),
            ("mill at that rpm at s", fmt(c["t_reached_s"], ".1f")), ("target MI", fmt(c["target_mi"], "g")),
            ("twin state of the study from s", fmt(c["state_t_s"], ".1f")),
            ("twin MI then / plant MI at the decision (2 s means)",
             f'{fmt(c["twin_mi_at_state"])} / {fmt(c["plant_mi_at_decision"])}'),
            ("twin: predicted time to target s", fmt(c["predicted_s"], ".1f")),
            ("plant: time to target s (raw MI, 2 s mean, held 5 s)", fmt(c["actual_s"], ".1f")),
            ("error %", f'<b class="ttm-error">{fmt(c["error_pct"], "+.0f")}</b>'),
            ("plant: time to the endpoint's mixing time s", fmt(c["endpoint_s"], ".1f"))]
    return "<h4>Twin's time to mix against the plant's</h4>" + table(rows)


def _energy(run: RunData, idx: int) -> str:
    """Energy used (frames ``power_w``, integrated over run time) and predicted (the last what-if
    events with ``energy_to_target_j`` per rpm)."""
    parts: list[str] = []
    e = run.frames.energy
    if e is not None and e.n >= 2 and e.t_first is not None and e.t_last is not None:
        parts.append(f"<p>Drive energy used: <b>{e.used_j:.1f} J</b> over {e.t_last - e.t_first:.0f} s "
                     f"(mean power {e.sum_w / e.n:.2f} W).</p>")
    for s in run.events.energy:
        rows = [(text(r), fmt(j, ".1f"), fmt(t, ".0f"), fmt(p, ".2f"), fmt(m, ".3f")) for r, j, t, p, m in s["rows"]]
        target = f" to MI {fmt(s['target_mi'], 'g')}" if s["target_mi"] is not None else ""
        parts.append(f"<p>Predicted{target} at t = {fmt(s['t_s'], '.0f')} s ({text(s['reason'])}):</p>"
                     + table(rows, ("rpm", "energy to target J", "time to target s", "power W", "plateau MI")))
    if not parts:
        parts.append('<p class="none">No energy logged in this run (no power_w column, no what-if energy).</p>')
    plot = figures.energy(run)
    return "".join(parts) + ("" if plot is None else _img("energy", idx, plot, "energy used"))


def _json_text(v: Any) -> str:
    try:
        s = json.dumps(v, indent=1, sort_keys=True, default=str)
    except (TypeError, ValueError, RecursionError):
        s = repr(v)
    return html.escape(s[:MAX_TEXT] + (" ... (cut)" if len(s) > MAX_TEXT else ""))


def run_column(run: RunData, idx: int) -> dict[str, str]:
    """HTML of each section for one run."""
    mt = run.endpoint["mixing_time_s"]
    cfg, vers = run.metadata.get("config"), run.metadata.get("versions")
    return {
        "summary": _summary(run),
        "mi": _img("mi", idx, figures.lines(run, PLOTS["mi"], "mixing index", [mt] if mt is not None else []),
                   "MI raw, trend and twin"),
        "rpm": _img("rpm", idx, figures.lines(run, PLOTS["rpm"], "rpm"), "rpm set and actual"),
        "slope": _img("slope", idx, figures.lines(run, PLOTS["slope"], "slope (deg)"), "bed slope"),
        "events": _events(run, idx),
        "endpoint": _endpoint(run),
        "energy": _energy(run, idx),
        "config": f"<pre>{_json_text(cfg)}</pre>" if cfg else
                  '<p class="none">No configuration logged (none in metadata.json).</p>',
        "versions": table([(text(k), text(v)) for k, v in list(vers.items())[:200]])
                    if isinstance(vers, dict) and vers else '<p class="none">No versions logged.</p>',
    }


# -- the page -------------------------------------------------------------------------------------
CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:16px;color:#212121;background:#fff}
h1{font-size:20px} h2{font-size:16px;margin:18px 0 6px;border-bottom:1px solid #ccc}
.runs{display:grid;grid-template-columns:repeat(var(--n),minmax(420px,1fr));gap:16px}
.run{min-width:0} .run h3{margin:4px 0;font-size:15px}
img.plot{width:100%;height:auto;border:1px solid #eee}
table{border-collapse:collapse;font-size:12px} td,th{border:1px solid #ddd;padding:2px 6px;text-align:left}
pre{font-size:11px;max-height:300px;overflow:auto;background:#fafafa}
.note{color:#b71c1c;font-weight:bold} .mixed{color:#1b5e20;font-size:16px} .none{color:#757575}
.golden-mark{color:#f57f17}
"""

ALL_RUNS_HEAD = ("run", "run dir", "mode", "frames", "run time s", "final trend MI", "decisions", "faults",
                 "mixing time s", "ended cleanly", "notes")


def all_runs_row(run: RunData) -> tuple[str, ...]:
    """One run's row of the "All runs" table."""
    s = run.summary()
    notes = "<br>".join(f'<span class="note">{html.escape(n)}</span>' for n in run.notes)
    return (f'<span class="run-label">{text(run.label)}</span>', text(run.path, 500), fmt(s["mode"]),
            str(s["frames"]), fmt(s["run_time_s"], ".1f"),
            fmt(s["final_trend_mi"]), str(s["decisions"]), str(s["faults"]), fmt(s["mixing_time_s"], ".1f"),
            "yes" if s["ended_cleanly"] else "no", notes)


def page(title: str, labels: Sequence[str], columns: Sequence[dict[str, str]],
         all_runs: tuple[Sequence[Sequence[str]], str] | None = None, batches: str = "") -> str:
    """The whole report: ``labels`` of every run; ``columns``: the sections of the runs shown in
    detail; ``all_runs``: the rows and the overview plot of a report of many runs; ``batches``:
    the batch table's section (``twin.report.batch``)."""
    parts = [f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>", batches]
    if all_runs is None:
        parts.append(f"<p>{len(labels)} run(s): " + ", ".join(html.escape(x) for x in labels) + "</p>")
    else:
        rows, plot = all_runs
        parts.append(f'<h2 id="all-runs">All runs</h2><p>{len(labels)} runs; the sections below show the first '
                     f"{len(columns)} in detail.</p>" + _img("overview", 0, plot, "trend MI of every run")
                     + table(rows, ALL_RUNS_HEAD))
    for sid, stitle in SECTIONS:
        parts.append(f'<h2 id="{sid}">{html.escape(stitle)}</h2><div class="runs" style="--n:{len(columns)}">')
        for i, col in enumerate(columns):
            parts.append(f'<section class="run" data-section="{sid}" data-run="{i}"><h3>{html.escape(labels[i])}'
                         f"</h3>{col[sid]}</section>")
        parts.append("</div>")
    parts.append("</body></html>")
    return "".join(parts)


def render_html(runs: Sequence[RunData], title: str = "drumtwin report") -> str:
    """The report of runs already read (every one in detail; no external resource of any kind)."""
    return page(title, [r.label for r in runs], [run_column(r, i) for i, r in enumerate(runs)])


def run_specs(specs: Sequence[Path | str], labels: Sequence[str] | None = None) -> list[tuple[str, Path]]:
    """(label, dir) of each run: ``labels`` given (``--label``, one per run) name them in order;
    else a spec that exists as a path is that path (its folder name the label), else ``LABEL=DIR``
    is split at the last ``=``, else it is a path (that does not exist)."""
    if labels:
        if len(labels) != len(specs):
            raise TwinError(f"--label given {len(labels)} time(s) for {len(specs)} run(s): give one per run, or none")
        if not all(lab.strip() for lab in labels):
            raise TwinError("--label: a label cannot be empty")
        return [(lab, Path(s)) for lab, s in zip(labels, specs, strict=True)]
    out = []
    for s in specs:
        p = Path(s)
        if not p.exists() and "=" in str(s):
            lab, _, d = str(s).rpartition("=")
            out.append((lab or Path(d).name, Path(d)))
        else:
            out.append((p.name or str(p), p))
    return out


def check_out(out: Path | str) -> Path:
    target = Path(out)
    if target.is_dir():
        raise TwinError(f"--out {target} is a directory: give a file name (report.html)")
    if not target.parent.is_dir():
        raise TwinError(f"--out: folder {target.parent} does not exist")
    return target


def write_report(run_dirs: Sequence[Path | str], out: Path | str, title: str = "drumtwin report",
                 labels: Sequence[str] | None = None, detailed: int = MAX_DETAILED, batch: Batch | None = None,
                 ) -> tuple[Path, dict[str, dict[str, Any]]]:
    """Read the runs one at a time and write the report to ``out`` (atomically: a temporary file,
    then renamed); returns it and each run's endpoint and time-to-mix check by label. More runs
    than ``detailed``: the "All runs" table and plot, and the sections of the first ``detailed``.
    ``batch``: the catalogue's summaries of the runs, in order: a batch table first."""
    if not run_dirs:
        raise TwinError("give at least one run dir")
    target = check_out(out)
    specs = run_specs(run_dirs, labels)
    for _, path in specs:  # a wrong path is one line before any run is read
        check_dir(path)
    many = len(specs) > detailed
    columns, rows, curves, results = [], [], [], {}
    for i, (label, path) in enumerate(specs):
        run = load_run(path, label)
        results[run.label] = {"mixing_time_s": run.endpoint["mixing_time_s"], "time_to_mix": run.time_to_mix}
        if i < detailed:
            columns.append(run_column(run, i))
        if many:
            rows.append(all_runs_row(run))
            trend = run.frames.series.get("trend_mi")
            if trend is not None:
                curves.append((run.label, *trend.coarser(OVERVIEW_BUCKETS)))
        del run
    all_runs = (rows, figures.overview(curves)) if many else None
    labels_ = [lab for lab, _ in specs]
    text_ = page(title, labels_, columns, all_runs, batch_html(labels_, batch) if batch is not None else "")
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text_, encoding="utf-8")
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise TwinError(f"cannot write --out {target}: {exc.strerror or exc}") from None
    return target, results


def build_report(run_dirs: Sequence[Path | str], out: Path | str, title: str = "drumtwin report",
                 labels: Sequence[str] | None = None) -> Path:
    """Read ``run_dirs`` (each ``LABEL=DIR`` or ``DIR``; ``labels``: one per run instead) and write
    the report to ``out``. Bad input: one-line TwinError."""
    return write_report(run_dirs, out, title, labels)[0]

"""``drumtwin runs show``: a run's summary as rows and the events of its log that matter."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

from twin import runread
from twin.catalogue.summary import EVENTS_FILE, RunSummary

KEY_KINDS = ("start", "stop", "mixed", "unmixed", "fault", "recovered", "decision", "calibration",
             "operator", "mill_refused", "slower_than_golden")
"""The event kinds ``runs show`` lists (decisions, faults, the endpoint, calibrations, the operator)."""

MAX_EVENTS = 200


def _text(e: dict[str, Any]) -> str:
    kind = e.get("kind")
    if kind == "fault":
        return f"{e.get('fault', '?')}: {e.get('message', '')}"
    if kind == "recovered":
        return f"{e.get('fault', '?')} cleared"
    if kind in ("mixed", "unmixed"):
        return f"mixing time {e.get('mixing_time_s')} s, plateau MI {e.get('plateau_mi')}"
    if kind == "decision":
        rpm = f" {e['rpm']:g} rpm" if isinstance(e.get("rpm"), (int, float)) else ""
        return f"{e.get('decision', '')}{rpm}: {e.get('reason', '')}"
    if kind == "calibration":
        return (f"friction {e.get('friction')}, rolling {e.get('rolling')}, slope {e.get('twin_slope_deg')} deg "
                f"(target {e.get('target_slope_deg')})")
    if kind == "operator":
        return " ".join(str(e[k]) for k in ("action", "rpm") if e.get(k) is not None)
    if kind == "stop":
        return f"{e.get('frames')} frames" + (f", failure: {e['failure']}" if e.get("failure") else "")
    if kind == "start":
        return f"mode {e.get('mode')}, mill {e.get('mill')}"
    return ", ".join(f"{k}={v}" for k, v in e.items() if k not in ("t_s", "wall_s", "kind"))[:200]


def key_events(run_dir: str | Path, limit: int = MAX_EVENTS) -> list[dict[str, Any]]:
    """The events of a run that matter, each ``{t_s, kind, text}``; at most ``limit`` (the rest
    counted in a last line)."""
    out: list[dict[str, Any]] = []
    more = 0
    for e in runread.events(runread.open_run(run_dir)):
        if e.get("kind") not in KEY_KINDS:
            continue
        if len(out) >= limit:
            more += 1
            continue
        t = e.get("t_s")
        out.append({"t_s": float(t) if isinstance(t, (int, float)) else float("nan"),
                    "kind": str(e.get("kind")), "text": _text(e)})
    if more:
        out.append({"t_s": out[-1]["t_s"], "kind": "...", "text": f"{more} more events in {EVENTS_FILE}"})
    return out


def summary_table(s: RunSummary) -> list[tuple[str, str]]:
    """A run's summary as (name, value) rows."""
    def when(t: float | None) -> str:
        return "-" if t is None else dt.datetime.fromtimestamp(t).isoformat(timespec="seconds")

    def num(x: float | None, unit: str = "", fmt: str = ".3g") -> str:
        return "-" if x is None else f"{format(x, fmt)}{unit}"

    return [
        ("run", s.id), ("folder", s.path), ("rig", f"{s.rig} ({s.rig_hash})" + ("  golden batch" if s.golden else "")),
        ("started", when(s.started_s)), ("ended", f"{s.ended} {when(s.ended_s)}" + (
            f": {s.failure}" if s.failure else "")),
        ("run time", num(s.duration_s, " s", ".1f")), ("frames", "-" if s.frames is None else str(s.frames)),
        ("mode", s.mode + (f", objective {s.objective}" if s.objective else "")),
        ("rpm", f"start {num(s.rpm_start)}, {num(s.rpm_min)}..{num(s.rpm_max)}, final {num(s.rpm_final)}"),
        ("endpoint", (f"mixed at {num(s.mixing_time_s, ' s', '.1f')}, plateau MI {num(s.plateau_mi)}"
                      if s.mixed else "not mixed")),
        ("final MI", num(s.final_mi)), ("energy", num(s.energy_j, " J")),
        ("faults", f"{s.n_faults}" + (f" ({s.faults})" if s.faults else "")),
        ("tags", " ".join(f"{k}={v}" for k, v in sorted(s.tags.items())) or "-"), ("note", s.note or "-"),
    ]

"""One run folder read for the report: :func:`load_run` -> :class:`RunData`, in bounded memory.

Three passes, each streamed (``twin.runread``): the events (``twin.report.events``), the frames
(``twin.report.frames``) and, only when an AUTO move qualifies for the time-to-mix check, the
frames again up to the end of that move's window (``twin.report.ttm``). What was skipped on the
way, and why, is in ``RunData.notes``; a folder with nothing readable at all is a one-line
``TwinError``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.errors import TwinError
from twin.report.events import EventSummary
from twin.report.frames import FrameScan
from twin.report.ttm import config_target, time_to_mix
from twin.runread import EVENTS_FILE, FRAMES_FILE, METADATA_FILE, events, frame_batches, frame_header, open_run

EMPTY = (np.zeros(0), np.zeros(0))


@dataclass
class RunData:
    """One run, read back and summarised: what the report and ``compare`` show of it."""

    path: Path
    label: str
    metadata: dict[str, Any]
    events: EventSummary
    frames: FrameScan
    endpoint: dict[str, Any]
    time_to_mix: dict[str, Any] | None
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return self.frames.n

    @property
    def clean_stop(self) -> bool:
        return self.events.clean_stop

    def series(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t_s, values) of a plotted column, decimated (empty: not logged)."""
        s = self.frames.series.get(name)
        return EMPTY if s is None else s.points()

    def summary(self) -> dict[str, Any]:
        """The numbers of its row in the summary table (and ``report --json``)."""
        cfg = self.metadata.get("config")
        mode = cfg.get("mode") if isinstance(cfg, dict) else None
        return {"frames": self.n_frames, "run_time_s": self.frames.t_max,
                "final_trend_mi": None if self.frames.last_trend is None else self.frames.last_trend[1],
                "mode": mode if isinstance(mode, str) else self.frames.mode,
                "decisions": self.events.counts.get("decision", 0), "faults": self.events.counts.get("fault", 0),
                "mixing_time_s": self.endpoint["mixing_time_s"], "ended_cleanly": self.clean_stop}


def _endpoint(ev: EventSummary, scan: FrameScan) -> dict[str, Any]:
    """The run's endpoint: the live ``mixed``/``unmixed`` events; else the live detector's
    ``mixed`` column of the frames; else (a log of an earlier release) the detector replayed on
    the raw MI. ``source`` says which."""
    if ev.changes.total:
        ch, source = ev.changes, "live"
    elif scan.changes is not None:
        ch, source = scan.changes, "live (no endpoint events: frames.csv's mixed column, the live detector's state)"
    elif scan.replay is not None:
        ch = scan.replay.changes
        source = "offline (no endpoint events in the log: the run's raw MI replayed through the detector"
        source += f"; its first {scan.replay.n:,} rows)" if scan.replay.skipped else ")"
        ch.plateau_mi = scan.replay.plateau_mi
    else:
        return {"source": "none (no endpoint events, no mixed column, no MI)", "mixing_time_s": None,
                "plateau_mi": None, "changes": [], "total": 0, "first_mixed": None, "left_after": None}
    mt = ch.mixing_time_s
    return {"source": source, "mixing_time_s": mt, "plateau_mi": ch.plateau_mi if mt is not None else None,
            "changes": list(ch.last), "total": ch.total, "first_mixed": ch.first_mixed, "left_after": ch.left_after}


def check_dir(p: Path) -> None:
    """A one-line TwinError unless ``p`` is a folder with one of the run log's files."""
    if not p.exists():
        raise TwinError(f"no such run dir: {p}")
    names = (FRAMES_FILE, EVENTS_FILE, METADATA_FILE)
    if not p.is_dir() or not any((p / n).is_file() for n in names):
        raise TwinError(f"{p} is not a run log dir (no {FRAMES_FILE}, {EVENTS_FILE} or {METADATA_FILE})")


def load_run(path: Path | str, label: str | None = None) -> RunData:
    """Read one run dir (module doc); a missing dir, one with none of the three files, or one with
    nothing readable in them is a one-line TwinError."""
    p = Path(path)
    check_dir(p)
    run = open_run(p)
    ev = EventSummary()
    for e in events(run):
        ev.add(e)
    ev.finish()
    header = frame_header(run)
    replay = not ev.changes.total and header is not None and "mixed" not in header
    scan = FrameScan(run.skips, replay=replay, moves=ev.moves)
    for cols, rows in frame_batches(run):
        scan.add(cols, rows)
    if header is None and not ev.n and not run.metadata:
        raise TwinError(f"{p}: nothing readable in the run dir ({'; '.join(run.skips.notes())})")
    reached = scan.reach.first()
    ttm = None if reached is None else time_to_mix(run, reached[0], reached[1], ev.mixed_at,
                                                  config_target(run.metadata))
    notes = run.skips.notes()
    if not ev.clean_stop:
        notes.append("the run did not end cleanly (no stop event; killed?): showing what was logged")
    if not scan.n:
        notes.append("no frame rows were logged")
    return RunData(p, label or p.name, run.metadata, ev, scan, _endpoint(ev, scan), ttm, notes)

"""One run folder -> the catalogue's row: what a run was and how it ended.

The run folder is the truth (``frames.csv``, ``events.jsonl``, ``metadata.json``, and the
operator's ``annotations.jsonl``); a :class:`RunSummary` is what the catalogue indexes of
it, recomputed at any time by :func:`summarise`. Reading is tolerant: a line or a cell that
does not parse is passed over (the report counts them; the index only needs the run's
outline), and a folder with no readable file at all is not a run (None).

How a run ended: its ``stop`` record says clean or failed; without one, the process that
wrote it is asked (same host, same pid, same start tick): alive is ``running``, gone is
``killed`` (``kill -9``, a power cut: it ended without a stop).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import socket
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from twin import runread

FRAMES_FILE, EVENTS_FILE, METADATA_FILE = runread.FRAMES_FILE, runread.EVENTS_FILE, runread.METADATA_FILE
ANNOTATIONS_FILE = "annotations.jsonl"
RUN_FILES = (FRAMES_FILE, EVENTS_FILE, METADATA_FILE)

ENDED = ("running", "clean", "failed", "killed")
"""How a run ended: still running, a clean stop, a stop with a failure, no stop and its
process gone."""

_TAIL_BYTES = 64 * 1024  # the last rows of frames.csv: the final MI and rpm


@dataclass(frozen=True)
class RunSummary:
    """The catalogue's row of one run (times are unix seconds; MI 0..1; energy in J)."""

    id: str
    path: str
    rig: str
    rig_hash: str
    started_s: float
    mode: str
    ended: str = "running"
    ended_s: float | None = None
    duration_s: float | None = None
    failure: str | None = None
    objective: str | None = None
    rpm_start: float | None = None
    rpm_min: float | None = None
    rpm_max: float | None = None
    rpm_final: float | None = None
    mixed: bool = False
    mixing_time_s: float | None = None
    plateau_mi: float | None = None
    final_mi: float | None = None
    energy_j: float | None = None
    frames: int | None = None
    n_faults: int = 0
    faults: str = ""
    golden: bool = False
    note: str = ""
    pid: int | None = None
    host: str | None = None
    proc_start: str | None = None
    indexed_mtime: float = 0.0
    tags: Mapping[str, str] = field(default_factory=dict)

    def row(self) -> dict[str, Any]:
        """The ``runs`` table's row (tags go to their own table)."""
        return {k: v for k, v in self.__dict__.items() if k != "tags"}

    def as_json(self) -> dict[str, Any]:
        """The row with its tags (``runs list --json``, ``runs show --json``)."""
        return {**self.row(), "tags": dict(self.tags)}


# -- readers -------------------------------------------------------------------------------------
def _number(value: Any) -> float | None:
    """A finite float of a JSON or CSV value, else None."""
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):  # an int no float holds is no number either
        return None
    return x if math.isfinite(x) else None


def _mapping(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}


def _last_row(path: Path) -> tuple[dict[str, str], int | None]:
    """The last complete row of a ``frames.csv`` (header -> cell) and, for a small file, the
    row count (None when only the tail was read)."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            header = fh.readline().decode("utf-8", "replace").strip().split(",")
            start = max(fh.tell(), size - _TAIL_BYTES)
            fh.seek(start)
            tail = fh.read().decode("utf-8", "replace")
    except OSError:
        return {}, None
    lines = tail.split("\n")
    complete = lines[:-1]  # the last piece has no newline yet: being written, or cut
    if start > len(",".join(header)) + 1 and complete:
        complete = complete[1:]  # the first piece may start mid-row
    count = len(complete) if start <= len(",".join(header)) + 1 else None
    for line in reversed(complete):
        cells = line.split(",")
        if len(cells) == len(header):
            return dict(zip(header, cells, strict=True)), count
    return {}, count


# -- the process behind a run ----------------------------------------------------------------
def process_identity(pid: int | None = None) -> dict[str, Any]:
    """This (or ``pid``'s) process as a run records it: pid, host and start tick (the tick
    tells a reused pid from the run's own process)."""
    pid = os.getpid() if pid is None else pid
    return {"pid": pid, "host": socket.gethostname(), "start": _start_tick(pid)}


def _start_tick(pid: int) -> str | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]  # field 22: starttime, after the command name


def process_alive(pid: int | None, host: str | None, start: str | None) -> bool | None:
    """Is the process that wrote a run still running? None: it ran on another host (cannot
    tell from here)."""
    if pid is None:
        return False
    if host is not None and host != socket.gethostname():
        return None
    tick = _start_tick(pid)
    return tick is not None and (start is None or tick == start)


# -- the summary ------------------------------------------------------------------------------
def rig_of(metadata: Mapping[str, Any]) -> tuple[str, str]:
    """The rig's name (the config's name; ``demo`` for the embedded demo) and a short hash of
    its mixer and classes (two runs of one rig with another mixer differ)."""
    rig = metadata.get("rig")
    if isinstance(rig, Mapping) and isinstance(rig.get("name"), str) and isinstance(rig.get("hash"), str):
        return rig["name"], rig["hash"]
    source = _mapping(metadata.get("config")).get("meter_config")
    name = Path(source).stem if isinstance(source, str) and source else "demo"
    return name, rig_hash(metadata.get("mixer"), metadata.get("classes"))


def rig_hash(mixer: object, classes: object) -> str:
    """12 hex digits of the canonical JSON of a mixer and its colour classes."""
    text = json.dumps({"mixer": mixer, "classes": classes}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def run_id(directory: Path, uid: str | None) -> str:
    """The run's uid (``twin.runread`` decides it from the run's files); a folder of an older
    release, without one, gets one from its path."""
    if uid is not None and 0 < len(uid) <= 64:
        return uid
    return "path-" + hashlib.sha1(str(directory.resolve()).encode()).hexdigest()[:16]


def newest_mtime(directory: Path) -> float:
    """The newest modification time of a run's files (0: none)."""
    times = []
    for name in (*RUN_FILES, ANNOTATIONS_FILE):
        try:
            times.append((directory / name).stat().st_mtime)
        except OSError:
            continue
    return max(times, default=0.0)


def is_run_dir(directory: Path) -> bool:
    return any((directory / name).is_file() for name in RUN_FILES)


@dataclass
class _Events:
    """What the events of a run say, folded one line at a time."""

    first_wall_s: float | None = None
    last_wall_s: float | None = None
    last_t_s: float | None = None
    mode: str | None = None
    stop: dict[str, Any] | None = None
    mixed: dict[str, Any] | None = None
    unmixed_after: bool = False
    faults: list[str] = field(default_factory=list)
    rpms: list[float] = field(default_factory=list)
    last_rpm_wall_s: float = -math.inf
    uid: str | None = None

    def fold(self, e: Mapping[str, Any]) -> None:
        wall, t = _number(e.get("wall_s")), _number(e.get("t_s"))
        if wall is not None:
            self.first_wall_s = wall if self.first_wall_s is None else min(self.first_wall_s, wall)
            self.last_wall_s = wall if self.last_wall_s is None else max(self.last_wall_s, wall)
        if t is not None:
            self.last_t_s = t if self.last_t_s is None else max(self.last_t_s, t)
        kind = e.get("kind")
        if kind == "start":
            self.mode = str(e.get("mode", "")) or self.mode
        elif kind == "stop":
            self.stop = dict(e)
        elif kind == "mixed":
            self.mixed, self.unmixed_after = dict(e), False
        elif kind == "unmixed":
            self.unmixed_after = True
        elif kind == "fault":
            self.faults.append(str(e.get("fault", "?")))
        elif kind == "mill_command" and e.get("command") == "set_rpm":
            rpm = _number(e.get("rpm"))
            if rpm is not None:
                self.rpms.append(rpm)
                self.last_rpm_wall_s = wall if wall is not None else self.last_rpm_wall_s


def summarise(directory: Path | str) -> RunSummary | None:
    """The catalogue row of a run folder (None: no run file in it)."""
    d = Path(directory).resolve()
    if not is_run_dir(d):
        return None
    run = runread.open_run(d)
    meta = run.metadata
    ev = _Events(uid=run.uid)
    for e in runread.events(run):
        ev.fold(e)
    last, count = _last_row(d / FRAMES_FILE)
    mixed: Mapping[str, Any] = ev.mixed or {}
    config = _mapping(meta.get("config"))
    rig, rhash = rig_of(meta)
    process = _mapping(meta.get("process"))
    start_rpm = _number(config.get("start_rpm"))
    rpms = [r for r in (start_rpm, *ev.rpms) if r is not None]
    row_rpm, row_wall = _number(last.get("rpm_setpoint")), _number(last.get("wall_s"))
    if row_rpm is not None and (row_wall or math.inf) >= ev.last_rpm_wall_s:
        rpms.append(row_rpm)  # the last frame is newer than the last command: its setpoint is final
    mtime = newest_mtime(d)
    summary = RunSummary(
        id=run_id(d, ev.uid),
        path=str(d),
        rig=rig,
        rig_hash=rhash,
        started_s=ev.first_wall_s or _number(last.get("wall_s")) or mtime,
        mode=ev.mode or str(config.get("mode") or "?"),
        objective=str(config["objective"]) if isinstance(config.get("objective"), str) else None,
        rpm_start=start_rpm if start_rpm is not None else (rpms[0] if rpms else None),
        rpm_min=min(rpms) if rpms else None,
        rpm_max=max(rpms) if rpms else None,
        rpm_final=rpms[-1] if rpms else None,
        mixed=ev.mixed is not None and not ev.unmixed_after,
        mixing_time_s=_number(mixed.get("mixing_time_s")),
        plateau_mi=_number(mixed.get("plateau_mi")),
        final_mi=_number(last.get("trend_mi")) if last else None,
        duration_s=max((x for x in (ev.last_t_s, _number(last.get("t_s"))) if x is not None), default=None),
        n_faults=len(ev.faults),
        faults=";".join(sorted(set(ev.faults))),
        pid=int(process["pid"]) if isinstance(process.get("pid"), int) else None,
        host=process.get("host") if isinstance(process.get("host"), str) else None,
        proc_start=process.get("start") if isinstance(process.get("start"), str) else None,
        indexed_mtime=mtime,
    )
    return _ending(summary, ev, last, count)


def _ending(s: RunSummary, ev: _Events, last: Mapping[str, str], count: int | None) -> RunSummary:
    """How the run ended, when, and what its stop record says."""
    last_wall = max((x for x in (ev.last_wall_s, _number(last.get("wall_s"))) if x is not None), default=None)
    stop = ev.stop
    if stop is not None:
        failure = stop.get("failure")
        frames = stop.get("frames")
        return replace(
            s, ended="failed" if failure else "clean", failure=str(failure) if failure else None,
            ended_s=last_wall, frames=frames if isinstance(frames, int) else count,
            energy_j=_number(stop.get("energy_j")))
    alive = process_alive(s.pid, s.host, s.proc_start)
    if alive is None or alive:
        return replace(s, ended="running", frames=count)
    return replace(s, ended="killed", ended_s=last_wall, frames=count,
                   failure="ended without a stop record (killed, or the machine went down)")

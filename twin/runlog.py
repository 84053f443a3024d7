"""Crash-safe run log: ``frames.csv`` (one row per camera frame), ``events.jsonl``
(decisions, faults, calibrations) and ``metadata.json`` (config, calibration, versions).

The run log is a subscriber of the run's record bus (``twin.records``): :meth:`RunLog.record`
writes a ``FrameReading`` as a CSV row (columns ``twin.records.FRAME_COLUMNS``, then
``run_uid``) and every logged record as one JSONL line ``{"t_s", "wall_s", "kind", "run_uid",
**fields}``.

The log describes itself (after bluesky's event-model): the run's uid (a uuid4, as
event-model's ``RunStart`` uid) is in every file (``metadata.json``'s ``run_uid``, a last
``run_uid`` column of ``frames.csv``, a ``run_uid`` key on every ``events.jsonl`` line), and
``metadata.json`` carries from the start a descriptor of every CSV column and every event
kind's fields (``descriptors``: dtype, shape, units, source; ``twin.records.descriptors``,
derived from the record declarations). The readers (``read_*``, streamed and forgiving:
``twin.runread``) check that the lines belong to the run and read the logs of earlier releases,
which carry no uid, the same as before.

Every row and every event is written with one ``write`` and flushed to the OS at
once, so ``kill -9`` of the process loses nothing that was logged; ``fsync`` (for a
power cut) runs at most once per ``fsync_interval_s``, so a crash of the machine
loses at most the last second. The metadata file is replaced atomically
(write to a temporary file, then ``os.replace``).

A run log never overwrites another run: ``RunLog`` claims its directory by creating
``frames.csv`` exclusively (``O_EXCL``) and refuses a directory that already holds
anything (``TwinError``: one line, exit 2). ``default_run_dir`` names a fresh directory
(timestamp, pid and a random suffix) and ``make_run_dir`` creates it with an exclusive
``mkdir``, so two runs started in the same second never collide.
"""

from __future__ import annotations

import csv
import enum
import io
import json
import math
import os
import secrets
import threading
import time
import uuid
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Any, Protocol

from twin.descriptors import descriptors
from twin.errors import TwinError
from twin.records import FRAME_COLUMNS, FrameReading, Record, event_fields, kind_of, record_of
from twin.runread import (
    EVENTS_FILE,
    FRAMES_FILE,
    METADATA_FILE,
    UID_KEY,
    RunFiles,
    Skips,
    events,
    frame_batches,
    open_run,
)

__all__ = ["EVENTS_FILE", "FRAMES_FILE", "FRAME_COLUMNS", "METADATA_FILE", "RunLog", "Skips", "read_events",
           "read_frames", "read_metadata", "read_records", "write_record"]


def _cell(value: Any) -> str:
    """One CSV cell: floats with 6 significant digits, bools as 0/1, None as ''."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.13g}"
    if isinstance(value, (list, tuple, set, frozenset)):
        return ";".join(str(v) for v in value)
    return str(value)


def to_jsonable(obj: Any) -> Any:
    """Plain JSON data of ``obj``: numpy scalars/arrays, enums, paths and dataclasses
    converted; NaN/inf floats become ``None`` so the JSON is strict."""
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in obj]
    if is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value)
    if hasattr(obj, "tolist"):  # numpy scalar or array
        return to_jsonable(obj.tolist())
    return str(obj)


def dumps(obj: Any) -> str:
    """Strict one-line JSON of ``obj`` (see ``to_jsonable``)."""
    return json.dumps(to_jsonable(obj), allow_nan=False)


@dataclass(frozen=True)
class RunLogPaths:
    """Where one run's files live."""

    directory: Path
    frames: Path
    events: Path
    metadata: Path

    @classmethod
    def of(cls, directory: Path | str) -> RunLogPaths:
        d = Path(directory)
        return cls(d, d / FRAMES_FILE, d / EVENTS_FILE, d / METADATA_FILE)


def default_run_dir(root: Path | str = "runs", now_s: float | None = None) -> Path:
    """A fresh run directory name under ``root``: ``YYYYmmdd-HHMMSS-<pid>-<random>``
    (not created; :func:`make_run_dir` creates it exclusively)."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now_s))
    return Path(root) / f"{stamp}-{os.getpid()}-{secrets.token_hex(3)}"


def make_run_dir(root: Path | str = "runs") -> Path:
    """Create and return a new, empty run directory under ``root`` (exclusive ``mkdir``:
    never one another run uses, even for runs started in the same second)."""
    Path(root).mkdir(parents=True, exist_ok=True)
    for _ in range(100):
        d = default_run_dir(root)
        try:
            d.mkdir()
        except FileExistsError:
            continue
        return d
    raise TwinError(f"cannot create a fresh run directory under {root}")


def _claim(directory: Path) -> None:
    """Make ``directory`` (parents too) unless it exists; refuse one that holds anything."""
    if directory.exists() and not directory.is_dir():
        raise TwinError(f"--log {directory} is a file, not a directory")
    directory.mkdir(parents=True, exist_ok=True)
    if any(directory.iterdir()):
        raise TwinError(f"--log {directory} already holds files (a previous run?): choose a new or empty directory")


class RunLog:
    """Append-only, thread-safe writer of one run's log directory (new or empty: an
    existing run is never overwritten, ``TwinError`` instead).

    ``frame(row)`` takes a mapping with (a subset of) ``FRAME_COLUMNS``;
    ``event(kind, t_s, **fields)`` one JSON line; ``set_metadata(**fields)`` merges
    into ``metadata.json``. Files are line-buffered by hand: one ``write`` + ``flush``
    per record, ``fsync`` at most every ``fsync_interval_s``. ``run_uid``: the run's uid
    (default a fresh uuid4), written into every file; ``metadata.json`` is written at once
    with it and the descriptors of ``columns`` and of every event kind.
    """

    def __init__(
        self,
        directory: Path | str,
        *,
        columns: Sequence[str] = FRAME_COLUMNS,
        fsync_interval_s: float = 1.0,
        run_uid: str | None = None,
    ) -> None:
        self.paths = RunLogPaths.of(directory)
        _claim(self.paths.directory)
        self.run_uid = run_uid or str(uuid.uuid4())
        self.columns = (*(c for c in columns if c != UID_KEY), UID_KEY)
        self.fsync_interval_s = float(fsync_interval_s)
        self._lock = threading.Lock()
        try:  # exclusive: of two runs racing for one directory, exactly one gets it
            self._frames = open(self.paths.frames, "x", encoding="utf-8", newline="")
        except FileExistsError:
            raise TwinError(f"--log {self.paths.directory} is being written by another run") from None
        self._events = open(self.paths.events, "x", encoding="utf-8")
        self._metadata: dict[str, Any] = {UID_KEY: self.run_uid, "descriptors": descriptors(self.columns)}
        self._last_sync = time.monotonic()
        self._closed = False
        self.n_frames = 0
        self.n_events = 0
        self._write(self._frames, ",".join(self.columns) + "\n")
        self._sync(force=True)
        self.set_metadata()

    # -- writing -----------------------------------------------------------------
    def _write(self, fh: io.TextIOBase, text: str) -> None:
        fh.write(text)
        fh.flush()  # into the kernel: survives kill -9 of this process

    def _sync(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._last_sync >= self.fsync_interval_s:
            for fh in (self._frames, self._events):
                try:
                    os.fsync(fh.fileno())
                except OSError:
                    pass
            self._last_sync = now

    def frame(self, row: Mapping[str, Any]) -> None:
        """Append one frame row (missing columns are empty cells; ``wall_s`` is filled in)."""
        row = {"wall_s": time.time(), **row, UID_KEY: self.run_uid}
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([_cell(row.get(c)) for c in self.columns])
        with self._lock:
            if self._closed:
                return
            self._write(self._frames, buf.getvalue())
            self.n_frames += 1
            self._sync()

    def event(self, kind: str, t_s: float, **data: Any) -> dict[str, Any]:
        """Append one event ``{"t_s", "wall_s", "kind", "run_uid", **data}``; returns it as JSON
        data, as ``read_events`` reads it back (without the uid)."""
        data.pop(UID_KEY, None)
        record = to_jsonable({"t_s": float(t_s), "wall_s": time.time(), "kind": kind, **data})
        line = json.dumps({**record, UID_KEY: self.run_uid}, allow_nan=False) + "\n"
        with self._lock:
            if self._closed:
                return record
            self._write(self._events, line)
            self.n_events += 1
            self._sync()
        return record

    def record(self, rec: Record) -> None:
        """The bus subscriber (see :func:`write_record`)."""
        write_record(self, rec)

    def set_metadata(self, **data: Any) -> None:
        """Merge ``data`` into ``metadata.json`` (atomic replace)."""
        with self._lock:
            self._metadata.update(data)
            self._metadata[UID_KEY] = self.run_uid
            text = json.dumps(to_jsonable(self._metadata), indent=2, allow_nan=False) + "\n"
            tmp = self.paths.metadata.with_suffix(".json.tmp")
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.paths.metadata)

    @property
    def metadata(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._metadata)

    def close(self) -> None:
        """Flush, fsync and close (idempotent). A flush that fails here (disk full) is not
        raised again: the write that failed first was (see ``twin.live.events.RunEvents``)."""
        with self._lock:
            if self._closed:
                return
            self._sync(force=True)
            for fh in (self._frames, self._events):
                try:
                    fh.close()
                except OSError:
                    pass
            self._closed = True

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RecordWriter(Protocol):
    """What :func:`write_record` writes to (a :class:`RunLog`, or a test's stand-in)."""

    def frame(self, row: Mapping[str, Any]) -> None: ...
    def event(self, kind: str, t_s: float, **data: Any) -> object: ...


def write_record(log: RecordWriter, rec: Record) -> None:
    """A frame reading -> one CSV row; a logged record -> one JSONL event; the dashboard-only
    status records -> nothing."""
    if isinstance(rec, FrameReading):
        log.frame(rec.as_dict())
    elif rec.logged:
        log.event(kind_of(rec), rec.t_s, **event_fields(rec))


# -- reading (tests, plots, summaries): twin.runread, as lists -----------------------------------
def _open(path: Path | str, name: str, skipped: Skips | None) -> tuple[RunFiles, Path]:
    """The run folder of ``path`` (a run dir, or a file in it read as its ``name``), opened;
    what is skipped is counted in ``skipped`` when given."""
    p = Path(path)
    run = open_run(p if p.is_dir() else p.parent)
    if skipped is not None:
        skipped.files.extend(n for n in run.skips.files if n not in skipped.files)
        run.skips = skipped
    return run, p / name if p.is_dir() else p


_FRAME_KEYS: Mapping[str, Any] = descriptors(FRAME_COLUMNS)["frame"]["data_keys"]  # type: ignore[assignment]


def _cell_value(column: str, value: str, skips: Skips) -> Any:
    """A CSV cell read back: '' -> None; a number by its descriptor as a float (not one: None,
    counted); a string by its descriptor as it is; an undeclared column a float when it reads as one."""
    if value == "":
        return None
    key = _FRAME_KEYS.get(column)
    if key is not None and key["dtype"] == "string":
        return value
    try:
        return float(value)
    except ValueError:
        if key is not None:
            skips.add(FRAMES_FILE, f"{column} not a number", what="cell")
            return None
        return value


def iter_frames(path: Path | str, skipped: Skips | None = None) -> Iterator[dict[str, Any]]:
    """The rows of a ``frames.csv`` (a run dir or the file) one by one, as dicts of its columns
    (without ``run_uid``), numbers as floats. A row cut off by a crash, of the wrong width or of
    another run is skipped and counted in ``skipped``."""
    run, p = _open(path, FRAMES_FILE, skipped)
    for header, rows in frame_batches(run, p):
        cols = [(i, h) for i, h in enumerate(header) if h != UID_KEY]
        for cells in rows:
            yield {h: _cell_value(h, cells[i], run.skips) for i, h in cols}


def read_frames(path: Path | str, skipped: Skips | None = None) -> list[dict[str, Any]]:
    """Rows of a ``frames.csv`` (a run dir or the file): :func:`iter_frames` as a list (for a
    log that fits in memory; ``drumtwin report`` streams)."""
    return list(iter_frames(path, skipped))


def iter_events(path: Path | str, skipped: Skips | None = None) -> Iterator[dict[str, Any]]:
    """Events of an ``events.jsonl`` (a run dir or the file) one by one, as their JSON objects
    without the uid; a line that is not an event of this run is skipped and counted."""
    run, p = _open(path, EVENTS_FILE, skipped)
    yield from events(run, p)


def read_events(path: Path | str, skipped: Skips | None = None) -> list[dict[str, Any]]:
    """Events of an ``events.jsonl`` (a run dir or the file): :func:`iter_events` as a list."""
    return list(iter_events(path, skipped))


_LINE_KEYS = ("t_s", "wall_s", "kind")  # the JSONL line's own keys beside the record's fields


def read_records(path: Path | str, skipped: Skips | None = None) -> list[Record]:
    """The events of an ``events.jsonl`` (a run dir or the file) as typed records: the one
    place a kind's name is looked up (``twin.records.record_of``). A line of a kind or with a
    field this release does not declare is an ``UntypedEvent`` holding it whole (and a
    warning); JSON ``null`` stays None (a NaN when it was written; a null ``t_s`` is NaN)."""
    return [
        record_of(str(e["kind"]), math.nan if e.get("t_s") is None else float(e["t_s"]),
                  **{k: v for k, v in e.items() if k not in _LINE_KEYS})
        for e in iter_events(path, skipped)
    ]


def read_metadata(path: Path | str, skipped: Skips | None = None) -> dict[str, Any]:
    """The ``metadata.json`` of a run dir (or the file): ``{}`` when it is missing, cannot be
    read as a JSON object or is of another run (a note in ``skipped``)."""
    run, _ = _open(path, METADATA_FILE, skipped)
    return run.metadata

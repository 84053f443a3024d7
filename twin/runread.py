"""Reading a run folder back, streamed and forgiving: what ``twin.runlog``'s ``read_*``,
``drumtwin report`` and ``drumtwin compare`` read with.

A run log is read by whoever finds it: cut short by ``kill -9``, edited by hand, put together
from two runs, or garbage. Nothing in it raises: a line or cell that cannot be read is skipped
and counted in a :class:`Skips` (file, what, why), whose :meth:`Skips.notes` the report prints
for the run ("12 lines of events.jsonl skipped: not a JSON object").

Memory is bounded by a block, never by the file: files are read in binary blocks of
``BLOCK_BYTES``; a line longer than its file's limit is skipped without being held; frame rows
come out as batches of one block's rows, events one at a time.

The run's uid (``twin.runlog``: ``metadata.json``'s ``run_uid``, a ``run_uid`` column in
``frames.csv``, a ``run_uid`` key on each ``events.jsonl`` line) ties the three files together:
:func:`open_run` decides it from the three (two files that agree outvote the third), a line of
another run is skipped and counted, a ``metadata.json`` of another run is not used (a note).
Logs of earlier releases carry no uid and are read as they always were.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

FRAMES_FILE = "frames.csv"
EVENTS_FILE = "events.jsonl"
METADATA_FILE = "metadata.json"
UID_KEY = "run_uid"

BLOCK_BYTES = 1 << 20
MAX_ROW_BYTES = 1 << 16
"""A ``frames.csv`` line longer than this is skipped (a row is ~300 bytes; it also keeps every
cell under the csv module's 131,072-character field limit)."""
MAX_EVENT_BYTES = 1 << 20
"""An ``events.jsonl`` line longer than this is skipped (a decision with its inputs is ~2 kB)."""
LIMIT = 1e15
"""A time or reading beyond this magnitude is no run's (1e15 s: 30 million years) and no plot can
place 1e308: an event whose ``t_s`` is beyond it is skipped, and so is a frame row
(``twin.report``)."""
MAX_METADATA_BYTES = 16 << 20
"""A ``metadata.json`` larger than this is not read (a note)."""


@dataclass
class Skips:
    """What was skipped while reading one run, counted by (file, what, why); ``files``: notes
    about whole files (missing, empty, of another run)."""

    counts: dict[tuple[str, str, str], int] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def add(self, file: str, why: str, n: int = 1, what: str = "line") -> None:
        if n > 0:
            key = (file, what, why)
            self.counts[key] = self.counts.get(key, 0) + n

    def note(self, text: str) -> None:
        if text not in self.files:
            self.files.append(text)

    def notes(self) -> list[str]:
        """One sentence per file note and per (file, what, why): "3 lines of frames.csv skipped: ..."."""
        out = list(self.files)
        for (f, what, why), n in self.counts.items():
            out.append(f"{n:,} {what}{'' if n == 1 else 's'} of {f} skipped: {why}")
        return out


@dataclass
class RunFiles:
    """One run folder opened for reading: its uid (None: a log without one), its metadata
    (``{}``: missing, unreadable or of another run) and the skips counted so far."""

    path: Path
    uid: str | None
    metadata: dict[str, Any]
    skips: Skips

    def file(self, name: str) -> Path:
        return self.path / name


# -- lines ----------------------------------------------------------------------------------------
def _decode(data: bytes, limit: int, skips: Skips, name: str) -> list[str]:
    """The lines of ``data`` (whole lines, the last newline cut), as text; a line longer than
    ``limit`` or not UTF-8 is skipped and counted."""
    try:
        lines = data.decode("utf-8").split("\n")
    except UnicodeDecodeError:
        lines = []
        for raw in data.split(b"\n"):
            try:
                lines.append(raw.decode("utf-8"))
            except UnicodeDecodeError:
                skips.add(name, "not UTF-8 text")
    if b"\r" in data:  # CRLF line ends (a file edited elsewhere)
        lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    if lines and max(map(len, lines)) > limit:
        kept = [ln for ln in lines if len(ln) <= limit]
        skips.add(name, f"longer than {limit:,} characters", len(lines) - len(kept))
        lines = kept
    return lines


def line_batches(fh: Any, limit: int, skips: Skips, name: str) -> Iterator[list[str]]:
    """The lines of the binary file ``fh`` from where it stands, one batch per block read. A line
    longer than ``limit`` bytes is skipped without being held; the last line without its newline
    (a run killed while writing it) is skipped and counted."""
    rest, skipping = b"", False
    while True:
        block = fh.read(BLOCK_BYTES)
        if not block:
            break
        if skipping:  # inside a line too long: drop up to its end
            nl = block.find(b"\n")
            if nl < 0:
                continue
            block, skipping = block[nl + 1:], False
        data = rest + block if rest else block
        last = data.rfind(b"\n")
        rest = data[last + 1:]
        if len(rest) > limit:
            skips.add(name, f"longer than {limit:,} characters")
            rest, skipping = b"", True
        if last >= 0:
            yield _decode(data[:last], limit, skips, name)
    if rest:
        skips.add(name, "cut off at the end (no newline: the run was writing it)")


def _first_line(fh: Any, limit: int) -> tuple[str | None, str]:
    """The first line of ``fh`` (binary) and why it is None (empty, too long, cut off, not text)."""
    raw = fh.readline(limit + 1)
    if not raw:
        return None, "empty"
    if not raw.endswith(b"\n"):
        if len(raw) > limit:
            while raw and not raw.endswith(b"\n"):
                raw = fh.readline(BLOCK_BYTES)
            return None, f"its first line is longer than {limit:,} characters"
        return None, "its first line is cut off (no newline)"
    try:
        return raw[:-1].decode("utf-8"), ""
    except UnicodeDecodeError:
        return None, "its first line is not UTF-8 text"


def _csv_rows(lines: list[str], width: int, skips: Skips) -> list[list[str]]:
    """The rows of ``lines`` with ``width`` cells (others skipped and counted). Lines without a
    quote (every line the run log writes: its cells hold no comma) are split on commas, as the
    csv module would, only faster."""
    if '"' not in "\n".join(lines):
        rows = [ln.split(",") for ln in lines]
    else:
        try:
            rows = list(csv.reader(lines))
        except csv.Error:
            rows = []
            for ln in lines:
                try:
                    rows.extend(csv.reader([ln]))
                except csv.Error:
                    skips.add(FRAMES_FILE, "not a CSV row")
    good = [r for r in rows if len(r) == width]
    skips.add(FRAMES_FILE, "wrong number of cells", len(rows) - len(good))
    return good


def frame_header(run: RunFiles) -> tuple[str, ...] | None:
    """The columns of ``frames.csv`` (None: no file, no readable header, or no ``t_s`` in it)."""
    path = run.file(FRAMES_FILE)
    if not path.is_file():
        return None
    with open(path, "rb") as fh:
        line, _ = _first_line(fh, MAX_ROW_BYTES)
    header = next(csv.reader([line]), []) if line is not None else []
    return tuple(header) if "t_s" in header else None


def frame_batches(run: RunFiles, path: Path | None = None) -> Iterator[tuple[tuple[str, ...], list[list[str]]]]:
    """``(header, rows)`` of ``frames.csv`` (or ``path``), one batch per block read: every row has
    the header's width and belongs to the run (its ``run_uid`` cell; the column stays in the
    header and rows). A file without a readable header, or without ``t_s``, yields nothing (a note)."""
    path = path or run.file(FRAMES_FILE)
    if not path.is_file():
        run.skips.note(f"no {FRAMES_FILE}")
        return
    with open(path, "rb") as fh:
        line, why = _first_line(fh, MAX_ROW_BYTES)
        header = next(csv.reader([line]), []) if line is not None else []
        if line is None or "t_s" not in header:
            run.skips.note(f"{FRAMES_FILE} not read: {why or 'no t_s column in its header'}")
            return
        width, k = len(header), header.index(UID_KEY) if UID_KEY in header else -1
        for lines in line_batches(fh, MAX_ROW_BYTES, run.skips, FRAMES_FILE):
            rows = _csv_rows(lines, width, run.skips)
            if k >= 0 and run.uid is not None:
                ours = [r for r in rows if r[k] == run.uid]
                if len(ours) != len(rows):
                    run.skips.add(FRAMES_FILE, _other_run(run.uid), len(rows) - len(ours))
                rows = ours
            if rows:
                yield tuple(header), rows


def _other_run(uid: str) -> str:
    return f"of another run (this run's run_uid is {uid[:8]}...)"


# -- events ---------------------------------------------------------------------------------------
def _event_or_why(line: str) -> tuple[dict[str, Any] | None, str]:
    """The event of one JSONL line, or None and why not."""
    try:
        e = json.loads(line)
    except (ValueError, RecursionError):
        return None, "not JSON"
    if not isinstance(e, dict):
        return None, "not a JSON object"
    if not isinstance(e.get("kind"), str):
        return None, "no kind (a string)"
    t = e.get("t_s")
    if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))):
        return None, "t_s not a number"
    if t is not None and not abs(t) <= LIMIT:  # NaN compares False; a 400-digit int is no float
        return None, f"t_s not a finite number within ±{LIMIT:g}"
    return e, ""


def events(run: RunFiles, path: Path | None = None) -> Iterator[dict[str, Any]]:
    """The events of ``events.jsonl`` (or ``path``) one by one, as their JSON objects without the
    run's uid: ``kind`` a string, ``t_s`` a finite number or null. Others, and lines of another
    run, are skipped and counted."""
    path = path or run.file(EVENTS_FILE)
    if not path.is_file():
        run.skips.note(f"no {EVENTS_FILE}")
        return
    with open(path, "rb") as fh:
        for lines in line_batches(fh, MAX_EVENT_BYTES, run.skips, EVENTS_FILE):
            for line in lines:
                e, why = _event_or_why(line)
                if e is None:
                    run.skips.add(EVENTS_FILE, why)
                    continue
                uid = e.pop(UID_KEY, None)
                if uid is not None and run.uid is not None and uid != run.uid:
                    run.skips.add(EVENTS_FILE, _other_run(run.uid))
                    continue
                yield e


# -- metadata and the run's uid -------------------------------------------------------------------
def _metadata(path: Path, skips: Skips) -> dict[str, Any]:
    """``metadata.json`` as an object ({} and a note when it is missing or cannot be one)."""
    if not path.is_file():
        skips.note(f"no {METADATA_FILE}")
        return {}
    why = ""
    if path.stat().st_size > MAX_METADATA_BYTES:
        why = f"larger than {MAX_METADATA_BYTES >> 20} MiB"
    else:
        try:
            meta = json.loads(path.read_bytes().decode("utf-8"))
            why = "" if isinstance(meta, dict) else "not a JSON object"
        except UnicodeDecodeError:
            why = "not UTF-8 text"
        except (ValueError, RecursionError):
            why = "empty" if path.stat().st_size == 0 else "not JSON"
    if why:
        skips.note(f"{METADATA_FILE} not read: {why}")
        return {}
    return meta


def _peek_uid(path: Path, kind: str) -> str | None:
    """The uid on the first readable line of ``frames.csv`` (its ``run_uid`` cell) or of
    ``events.jsonl`` (its ``run_uid`` key): a few lines are looked at, none held."""
    if not path.is_file():
        return None
    probe = Skips()
    with open(path, "rb") as fh:
        header: list[str] = []
        if kind == "frames":
            line, _ = _first_line(fh, MAX_ROW_BYTES)
            header = next(csv.reader([line]), []) if line is not None else []
            if UID_KEY not in header:
                return None
        for lines in line_batches(fh, MAX_EVENT_BYTES, probe, kind):
            for ln in lines[:20]:
                if kind == "frames":
                    rows = _csv_rows([ln], len(header), probe)
                    uid: object = rows[0][header.index(UID_KEY)] if rows else None
                else:
                    e, _ = _event_or_why(ln)
                    uid = None if e is None else e.get(UID_KEY)
                if isinstance(uid, str) and uid:
                    return uid
            return None
    return None


def open_run(path: Path | str) -> RunFiles:
    """Open a run folder: its metadata and its uid, from the three files (module doc)."""
    p = Path(path)
    skips = Skips()
    meta = _metadata(p / METADATA_FILE, skips)
    m = meta.get(UID_KEY) if isinstance(meta.get(UID_KEY), str) else None
    f, e = _peek_uid(p / FRAMES_FILE, "frames"), _peek_uid(p / EVENTS_FILE, "events")
    uid = m or e or f
    if m is not None and e is not None and f is not None and e == f != m:  # two against one
        uid = e
    if m is not None and uid != m:
        skips.note(f"{METADATA_FILE} not used: of another run (run_uid {m[:8]}..., "
                   f"{FRAMES_FILE} and {EVENTS_FILE} say {uid[:8] if uid else '?'}...)")
        meta = {}
    return RunFiles(p, uid, meta, skips)

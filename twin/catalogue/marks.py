"""The operator's words on a run (tags, a note, the golden mark), kept in the run folder.

The run folder is the truth and the catalogue only its index, so what an operator says of a
run is appended to the folder's ``annotations.jsonl`` before the catalogue is updated: ``runs
rebuild`` recovers it. Its lines are run-log lines (``kind`` "annotation", the run's uid), read
back by ``twin.runread`` like the events. A rig has one
golden batch: the run marked golden most recently.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from twin import runread
from twin.catalogue.summary import ANNOTATIONS_FILE
from twin.errors import TwinError


def append(directory: Path | str, **entry: Any) -> dict[str, Any]:
    """Append one annotation (``tag={key: value}``, ``note=text`` or ``golden=True``) to a run
    folder, with its wall time; flushed and synced before it returns."""
    d = Path(directory)
    if not d.is_dir():
        raise TwinError(f"run folder {d} is gone: its annotation cannot be kept")
    run = runread.open_run(d)
    line = {"t_s": None, "wall_s": time.time(), "kind": "annotation", **entry,
            **({runread.UID_KEY: run.uid} if run.uid else {})}
    text = json.dumps(line, allow_nan=False) + "\n"
    with open(d / ANNOTATIONS_FILE, "a", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    return line


def read(directory: Path | str) -> dict[str, Any]:
    """The annotations of a run folder folded: ``tags`` (key -> value; an empty value removes
    the tag), ``note`` (the latest), ``golden_s`` (wall time of the latest golden mark, or
    None)."""
    tags: dict[str, str] = {}
    note = ""
    golden_s: float | None = None
    run = runread.open_run(directory)
    for a in runread.events(run, Path(directory) / ANNOTATIONS_FILE):
        tag = a.get("tag")
        if isinstance(tag, dict):
            for k, v in tag.items():
                if v in ("", None):
                    tags.pop(str(k), None)
                else:
                    tags[str(k)] = str(v)
        if isinstance(a.get("note"), str):
            note = a["note"]
        if a.get("golden") is True and isinstance(a.get("wall_s"), (int, float)):
            golden_s = float(a["wall_s"])
    return {"tags": tags, "note": note, "golden_s": golden_s}

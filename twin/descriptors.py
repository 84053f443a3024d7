"""The run log's descriptors, after bluesky's event-model: an EventDescriptor's ``data_keys``
(dtype, shape, units, source) for every ``frames.csv`` column and every logged record kind's
fields, derived from the declarations in ``twin.records`` (``unit(...)`` / ``opt(...)``, the
field's ``source``, the class's ``producer``): no second table. ``twin.runlog.RunLog`` writes
them into ``metadata.json`` when a run's log opens; ``twin.runlog.read_frames`` reads the CSV's
cells by them. docs/architecture.md, "Run records"."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import Field, fields
from typing import Any

from twin.records import KINDS, FrameReading, Record

LOG_KEYS: Mapping[str, Mapping[str, object]] = {
    "wall_s": {"dtype": "number", "shape": [], "units": "s", "source": "twin.runlog",
               "doc": "unix time when the line was written"},
    "run_uid": {"dtype": "string", "shape": [], "units": "", "source": "twin.runlog",
                "doc": "the run's uid (metadata.json's run_uid): the line belongs to that run"},
}
"""The keys the run log adds to every line beside the record's fields (``frames.csv`` columns,
``events.jsonl`` keys), described as the fields are."""

_DTYPES = {"float": "number", "int": "integer", "bool": "boolean", "str": "string"}


def _dtype(f: Field[Any], csv: bool) -> tuple[str, list[None]]:
    """(event-model dtype, shape) of a field from its annotation: ``Mapping`` -> "object" (a JSON
    object; event-model has no such dtype), ``Sequence``/``tuple`` -> "array" of any length (in
    ``frames.csv``: one ';'-joined "string" cell)."""
    t = str(f.type).replace(" | None", "").strip()
    if t in _DTYPES:
        return _DTYPES[t], []
    if t.startswith(("Mapping[", "dict[")):
        return "object", []
    if t.startswith(("Sequence[", "tuple[", "list[")):
        return ("string", []) if csv else ("array", [None])
    raise TypeError(f"field {f.name} of type {t}: no descriptor dtype for it (twin/descriptors.py _dtype)")


def data_keys(cls: type[Record], *, csv: bool = False) -> dict[str, dict[str, object]]:
    """Every field of ``cls`` described as event-model's ``data_keys`` do: ``dtype``, ``shape``
    (``[]``: a scalar, ``[null]``: any length), ``units``, ``source`` (the field's own, else the
    class's ``producer``), with its ``doc`` and ``optional`` (left out of the line when unset)."""
    out: dict[str, dict[str, object]] = {}
    for f in fields(cls):
        dtype, shape = _dtype(f, csv)
        key: dict[str, object] = {"dtype": dtype, "shape": shape, "units": f.metadata.get("unit", ""),
                                  "source": f.metadata.get("source") or cls.producer, "doc": f.metadata.get("doc", "")}
        if f.metadata.get("optional"):
            key["optional"] = True
        out[f.name] = key
    return out


def descriptors(frame_columns: Sequence[str]) -> dict[str, dict[str, object]]:
    """The run log's descriptors, one per stream: ``frame`` (``frames.csv``: its columns in order,
    ``frame_columns``; a column no record declares is a "string" of source "undeclared") and each
    logged kind (``events.jsonl``); each ``{"file", "doc", "data_keys"}``."""
    frame = {**data_keys(FrameReading, csv=True), **LOG_KEYS}
    undeclared = {"dtype": "string", "shape": [], "units": "", "source": "undeclared", "doc": ""}
    out: dict[str, dict[str, object]] = {"frame": {
        "file": "frames.csv", "doc": FrameReading.doc,
        "data_keys": {c: dict(frame.get(c, undeclared)) for c in frame_columns}}}
    for kind, cls in KINDS.items():
        if cls.logged:
            out[kind] = {"file": "events.jsonl", "doc": cls.doc, "data_keys": {**data_keys(cls), **LOG_KEYS}}
    return out

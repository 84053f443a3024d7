"""How a run record is declared, and the one name -> class lookup: :func:`unit` / :func:`opt`
(a field with its unit, doc and source), :class:`Record` (every kind's base: ``t_s``, ``kind``,
``doc``, ``producer``, ``logged``), :func:`register` and :data:`KINDS` (the registry, in the
order the kind modules are imported by ``twin.records``), and the JSONL side: :func:`record_of`,
:class:`UntypedEvent`, :func:`kind_of`, :func:`event_fields`."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar, TypeVar

log = logging.getLogger("drumtwin.records")


def unit(u: str = "", doc: str = "", *, plot: bool = False, default: object = MISSING, source: str = "") -> Any:
    """A record field with its unit (``""``: none, a count, a name) and a short description;
    ``plot``: a dashboard plot series (frame readings only); ``source``: where the value comes
    from when not from the record's ``producer`` (the descriptors' ``source``)."""
    meta = {"unit": u, "doc": doc, "plot": plot, "source": source}
    if default is MISSING:
        return field(metadata=meta)
    return field(default=default, metadata=meta)


def opt(u: str = "", doc: str = "") -> Any:
    """An optional event field (default None): left out of the JSONL line when None."""
    return field(default=None, metadata={"unit": u, "doc": doc, "plot": False, "optional": True})


@dataclass(frozen=True, kw_only=True)
class Record:
    """One run record. ``kind``: its name in ``events.jsonl`` (and in the docs table);
    ``logged``: written to ``events.jsonl`` (the frame reading goes to ``frames.csv``; the
    dashboard-only status records to neither)."""

    kind: ClassVar[str] = ""
    logged: ClassVar[bool] = True
    doc: ClassVar[str] = ""
    producer: ClassVar[str] = ""
    """The producer (a module or person): the descriptors' ``source`` of its fields (unless a field names its own)."""

    t_s: float = unit("s", "run time (the demo clock, scaled by --speed)")


R = TypeVar("R", bound=type[Record])

KINDS: dict[str, type[Record]] = {}
"""Every record kind by name (the registry :func:`register` fills)."""


def register(cls: R) -> R:
    """Register a record class under its ``kind`` (one class per kind, each kind once)."""
    if not cls.kind or cls.kind in KINDS:
        raise TypeError(f"record kind {cls.kind!r} of {cls.__name__} is empty or registered twice")
    KINDS[cls.kind] = cls
    return cls


@dataclass(frozen=True, kw_only=True)
class UntypedEvent(Record):
    """A JSONL event read back whose kind or fields no class here declares (a log of another
    release). It holds the line as it came, so no data is lost (and is written back whole)."""

    name: str = unit("", "the unregistered kind")
    data: Mapping[str, object] = unit("", "its fields")


def record_of(kind: str, t_s: float, **data: object) -> Record:
    """The record of ``kind`` built from ``data``: the name -> class lookup of the JSONL reader
    (``twin.runlog.read_records``; producers construct their record classes, so a misspelt kind
    or field is a type error). A kind not registered, or fields its class does not declare,
    give an :class:`UntypedEvent` and a warning: reading never crashes and never loses data."""
    cls = KINDS.get(kind)
    if cls is not None:
        try:
            return cls(t_s=float(t_s), **data)
        except TypeError as exc:
            log.warning("event %s does not fit its record: %s", kind, exc)
    else:
        log.warning("event kind %s is not a registered record kind (twin.records)", kind)
    return UntypedEvent(t_s=float(t_s), name=kind, data=dict(data))


def kind_of(rec: Record) -> str:
    return rec.name if isinstance(rec, UntypedEvent) else rec.kind


def event_fields(rec: Record) -> dict[str, object]:
    """The JSONL payload of ``rec`` (beside ``t_s``, ``wall_s``, ``kind``): its fields, the
    optional ones only when set."""
    if isinstance(rec, UntypedEvent):
        return dict(rec.data)
    out: dict[str, object] = {}
    for f in fields(rec):
        if f.name == "t_s":
            continue
        v = getattr(rec, f.name)
        if v is None and f.metadata.get("optional"):
            continue
        out[f.name] = v
    return out




def fields_of(cls: type[Record]) -> Mapping[str, str]:
    """Field name -> unit of a record class."""
    return {f.name: str(f.metadata.get("unit", "")) for f in fields(cls)}

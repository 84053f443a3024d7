"""The docs' table of record kinds (``docs/architecture.md``, "Run records"; checked by
``tests/twin/test_records.py``)."""

from __future__ import annotations

from dataclasses import fields

from twin.records.declare import KINDS
from twin.records.frame import FrameReading


def records_table() -> str:
    """The Markdown table of every record kind, its fields and their units (the one in
    ``docs/architecture.md``; ``python -m twin.records`` prints it)."""
    lines = ["| kind | goes to | fields (unit) |", "|---|---|---|"]
    for kind, cls in KINDS.items():
        where = "frames.csv" if cls is FrameReading else "events.jsonl" if cls.logged else "dashboard"
        parts = []
        for f in fields(cls):
            u = f.metadata.get("unit", "")
            name = f"{f.name}?" if f.metadata.get("optional") else f.name
            parts.append(f"`{name}`" + (f" ({u})" if u else ""))
        lines.append(f"| `{kind}` | {where}: {cls.doc} | {', '.join(parts)} |")
    return "\n".join(lines) + "\n"

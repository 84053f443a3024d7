"""The report's HTML cells: a number or text as escaped HTML, rows as a table."""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any


def fmt(v: Any, spec: str = ".3f") -> str:
    """A number formatted (``spec``), any other value escaped; None, NaN, inf: "–"."""
    if isinstance(v, bool) or v is None:
        return "–" if v is None else str(v)
    if isinstance(v, (int, float)):
        return format(v, spec) if abs(v) <= 1e300 else "–"  # not NaN, inf or an int no float holds
    return html.escape(str(v))


def table(rows: Sequence[Sequence[Any]], head: Sequence[str] = (), cls: str = "") -> str:
    """Rows of HTML cells (already escaped) as a table; ``cls``: its class."""
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    attr = f' class="{cls}"' if cls else ""
    return f"<table{attr}>{'<tr>' + h + '</tr>' if h else ''}{body}</table>"

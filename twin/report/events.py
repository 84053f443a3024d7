"""What the report keeps of a run's events: one streaming pass over ``events.jsonl``, bounded
whatever the log's length (counts by kind, the last events for the table, a decimated timeline
per kind, the endpoint's changes, the AUTO moves the time-to-mix check needs, the last
predicted energies, the first moves for ``compare``'s marks).

Every value read from an event is checked for its type where it is used: a log is data from
anywhere (``twin.runread`` has already dropped what is not an event at all).
"""

from __future__ import annotations

import html
import json
import math
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.report.decimate import MinMax
from twin.runread import LIMIT

MAX_KINDS = 40
"""Kinds counted and drawn one by one; the rest are counted as "other kinds"."""
SHOWN = 200
"""Events in the table (the last ones, trend changes left out)."""
MAX_CHANGES = 100
"""Endpoint changes kept for the table (the last ones)."""
MAX_MOVES = 10_000
"""AUTO moves kept as candidates of the time-to-mix check (the first ones)."""
MARKS = 50
"""Moves marked on ``compare``'s plot (the first ones)."""
STUDIES = 64
"""What-if studies remembered to match a decision to the study behind it (the latest ones)."""
PLOT_LIMIT = LIMIT
"""A number beyond this (in magnitude) is not drawn: matplotlib cannot place 1e308 on an axis."""


def num(v: Any) -> float | None:
    """``v`` as a float (None: not a number, a bool, NaN, or beyond ``PLOT_LIMIT``)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) <= PLOT_LIMIT:
        return None  # NaN compares False; a JSON integer of 400 digits is no float
    return float(v)


def rpm_key(k: Any) -> float | None:
    """An rpm key of a logged mapping ("45.0") as a number (None: not one)."""
    try:
        return num(float(k))
    except (TypeError, ValueError, OverflowError):
        return None


def text(v: Any, limit: int = 300) -> str:
    """``v`` as escaped HTML text of at most ``limit`` characters ("" for None)."""
    return "" if v is None else html.escape(str(v)[:limit])


@dataclass
class Changes:
    """The endpoint's changes (``mixed``/``unmixed``), from events or the frames: the last ones,
    the first ``mixed`` and the first ``unmixed`` after it, and the last of all."""

    last: deque[tuple[float | None, str, float | None, str]] = field(
        default_factory=lambda: deque(maxlen=MAX_CHANGES))
    total: int = 0
    first_mixed: tuple[float | None, str, float | None, str] | None = None
    left_after: tuple[float | None, str, float | None, str] | None = None
    plateau_mi: float | None = None

    def add(self, t: float | None, kind: str, mixing_time_s: float | None, reason: str,
            plateau_mi: float | None = None) -> None:
        c = (t, kind, mixing_time_s, reason)
        self.last.append(c)
        self.total += 1
        self.plateau_mi = plateau_mi if kind == "mixed" else None
        if kind == "mixed" and self.first_mixed is None:
            self.first_mixed = c
        elif kind == "unmixed" and self.first_mixed is not None and self.left_after is None:
            self.left_after = c

    @property
    def mixing_time_s(self) -> float | None:
        """The mixing time when the log ends mixed (None: never mixed, or left the band)."""
        return self.last[-1][2] if self.last and self.last[-1][1] == "mixed" else None


@dataclass
class Move:
    """An AUTO move the time-to-mix check may use (see ``twin.report.ttm``)."""

    t_s: float
    rpm: float
    predicted_s: float
    target_mi: float | None
    horizon_s: float | None
    state_t_s: float | None
    predicted_energy_j: float | None
    end_s: float = math.inf  # the next move's time


class EventSummary:
    """The bounded summary of a run's events (module doc); ``add(e)`` per event in log order."""

    def __init__(self) -> None:
        self.n = 0
        self.counts: dict[str, int] = {}
        self.other = 0
        self.shown: deque[tuple[str, str, str, str]] = deque(maxlen=SHOWN)
        self.timeline: dict[str, MinMax] = {}
        self.changes = Changes()
        self.moves: list[Move] = []
        self.marks: list[tuple[float, float | None]] = []
        self.n_moves = 0
        self.mixed_at: list[tuple[float, float | None]] = []
        self.energy: deque[dict[str, Any]] = deque(maxlen=3)
        self.clean_stop = False
        self._studies: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._times: dict[str, list[float]] = {}
        self._last_move: Move | None = None

    def add(self, e: dict[str, Any]) -> None:
        kind, t = str(e["kind"])[:100], num(e.get("t_s"))
        self.n += 1
        self._count(kind, t)
        if kind not in ("trend_settled", "trend_unsettled"):
            what = e.get("decision") or e.get("fault") or e.get("action") or e.get("command") or ""
            self.shown.append(("–" if t is None else f"{t:.1f}", text(kind, 60), text(what, 100),
                               text(e.get("reason") or e.get("message") or "")))
        self.clean_stop = self.clean_stop or kind == "stop"
        if kind in ("mixed", "unmixed"):
            mt = num(e.get("mixing_time_s"))
            self.changes.add(t, kind, mt if kind == "mixed" else None, str(e.get("reason", ""))[:300],
                             num(e.get("plateau_mi")))
            if kind == "mixed" and t is not None and len(self.mixed_at) < MAX_MOVES:
                self.mixed_at.append((t, mt))
        elif kind == "whatif":
            self._study(e, t)
        elif kind == "decision" and e.get("decision") == "move":
            self._move(e, t)

    def _count(self, kind: str, t: float | None) -> None:
        if kind not in self.counts and len(self.counts) >= MAX_KINDS:
            self.other += 1
            kind = "(other kinds)"
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if t is not None:
            pending = self._times.setdefault(kind, [])
            pending.append(t)
            if len(pending) >= 4096:
                self._flush(kind)

    def _flush(self, kind: str) -> None:
        ts = np.asarray(self._times.pop(kind, []), dtype=float)
        self.timeline.setdefault(kind, MinMax(500)).add(ts, ts)

    def finish(self) -> EventSummary:
        """After the last event: the timeline complete."""
        for kind in list(self._times):
            self._flush(kind)
        return self

    def _study(self, e: dict[str, Any], t: float | None) -> None:
        if isinstance(e.get("energy_to_target_j"), dict):
            self.energy.append(_energy_table(e))
        if isinstance(e.get("time_to_target_s"), dict):
            key = _key(e.get("predictions"))
            self._studies.pop(key, None)
            self._studies[key] = {"t_s": t, "ttt": _rpm_map(e["time_to_target_s"]),
                                  "target_mi": num(e.get("target_mi")), "duration_s": num(e.get("duration_s")),
                                  "requested_t_s": num(e.get("requested_t_s"))}
            while len(self._studies) > STUDIES:
                self._studies.popitem(last=False)

    def _move(self, e: dict[str, Any], t: float | None) -> None:
        self.n_moves += 1
        rpm = num(e.get("target_rpm"))
        if t is not None and len(self.marks) < MARKS:
            self.marks.append((t, rpm if rpm is not None else num(e.get("rpm"))))
        if t is None or rpm is None:
            return
        if self._last_move is not None and self._last_move.end_s == math.inf:
            self._last_move.end_s = t
        study = self._studies.get(_key(e.get("predictions")))
        if study is not None and (study["t_s"] is None or study["t_s"] > t + 1e-6):
            study = None
        pred = num(e.get("predicted_time_to_target_s"))
        if pred is None and study is not None:
            pred = num(study["ttt"].get(rpm))
        if pred is None or len(self.moves) >= MAX_MOVES:
            self._last_move = None if pred is None else self._last_move
            return
        s = study or {}
        self._last_move = Move(t, rpm, pred, s.get("target_mi"), s.get("duration_s"), s.get("requested_t_s"),
                               num(e.get("predicted_energy_j")))
        self.moves.append(self._last_move)


def _key(v: Any) -> str:
    """A decision's or study's predictions as a comparable key (equal mappings, equal keys)."""
    try:
        return json.dumps(v, sort_keys=True, default=str)
    except (TypeError, ValueError, RecursionError):
        return repr(v)


def _rpm_map(d: dict[Any, Any]) -> dict[float, Any]:
    return {k: v for k, v in ((rpm_key(k), v) for k, v in list(d.items())[:1000]) if k is not None}


def _energy_table(e: dict[str, Any]) -> dict[str, Any]:
    """What the energy section shows of a study with energies: at most 100 rpm rows."""
    def col(key: str, rpm: str) -> Any:
        d = e.get(key)
        return d.get(rpm) if isinstance(d, dict) else None

    rows = [(str(r), num(j), num(col("time_to_target_s", r)), num(col("power_w", r)), num(col("predictions", r)))
            for r, j in list(e["energy_to_target_j"].items())[:100]]
    return {"t_s": num(e.get("t_s")), "reason": str(e.get("reason", ""))[:100], "target_mi": num(e.get("target_mi")),
            "rows": rows}

"""The twin's predicted time to mix at the rpm AUTO picked, against the plant's (docs/endpoint.md).

The decision: the first AUTO ``move`` whose target rpm the mill reached (within 1 rpm) before the
next ``move`` (a ramp cut short by the safe state does not count) and that carries a predicted
time (``predicted_time_to_target_s``, objective time/energy) or whose predictions are a what-if
study's with times (``twin.report.events``). ``predicted_s``: the study's time to the target at
that rpm (from its start state, the rpm ramped as the mill does); ``actual_s``: from the decision
until the logged raw camera MI reaches the target and stays there to the end of the study's
horizon after the decision (or the next ``move``): ``sim.whatif.time_to_target``, the twin's own
definition, None when it does not; ``endpoint_s``: until the endpoint's mixing time;
``error_pct``: 100 (predicted - actual) / actual; ``state_t_s``: when the study's start state
was taken; ``twin_mi_at_state``: the running twin's MI then and ``plant_mi_at_decision``: the
camera's raw MI at the decision (means of the logged rows within 1 s, the 2 s of
``time_to_target``): a twin bed more mixed than the plant's predicts too short a time.

The move is found in the report's one pass over the frames (``twin.report.frames.Reach``); the
rows of its window are read in a second pass that stops after the window (at most
``WINDOW_MAX_ROWS`` rows are held).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from twin.report.events import Move, num
from twin.report.frames import finite, numbers
from twin.runread import RunFiles, Skips, frame_batches

DEFAULT_HORIZON_S = 40.0
"""The plant's window after a decision when the run logged no study horizon (``RunConfig.whatif_horizon_s``)."""
WINDOW_MAX_ROWS = 100_000
"""Rows of the decision's window held for ``time_to_target`` (2.8 h at 10 fps)."""
MAX_SMOOTH_ROWS = 2_000
"""``time_to_target`` smooths over 2 s of rows: rows denser than this in 2 s are not a camera log."""


def _window(run: RunFiles, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, mi, twin_mi) of the rows with ``lo <= t <= hi`` (file order; the pass stops at the
    first batch past ``hi``)."""
    parts: list[tuple[np.ndarray, ...]] = []
    held = 0
    again = RunFiles(run.path, run.uid, run.metadata, Skips())  # the first pass counted what it skips
    for header, rows in frame_batches(again):
        cols = []
        for name in ("t_s", "mi", "twin_mi"):
            if name in header:
                i = header.index(name)
                v = numbers([r[i] for r in rows])[0]
                v[~finite(v)] = math.nan  # as the first pass: no number beyond the limit
                cols.append(v)
            else:
                cols.append(np.full(len(rows), math.nan))
        t = cols[0]
        with np.errstate(invalid="ignore"):
            sel = np.isfinite(t) & (t >= lo) & (t <= hi)
        if sel.any() and held < WINDOW_MAX_ROWS:
            parts.append(tuple(c[sel][: WINDOW_MAX_ROWS - held] for c in cols))
            held += len(parts[-1][0])
        if np.isfinite(t).any() and np.nanmin(t) > hi:
            break
    if not parts:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    t, mi, twin = (np.concatenate([p[i] for p in parts]) for i in range(3))
    return t, mi, twin


def _mean_near(t: np.ndarray, y: np.ndarray, t0: float | None, half_s: float = 1.0) -> float | None:
    """Mean of the finite ``y`` with ``|t - t0| <= half_s`` (None: none)."""
    if t0 is None:
        return None
    sel = np.isfinite(t) & np.isfinite(y) & (np.abs(t - t0) <= half_s)
    return float(np.mean(y[sel])) if sel.any() else None


def _actual_s(t: np.ndarray, mi: np.ndarray, t_d: float, until: float, target: float) -> float | None:
    """The plant's time from the decision to the target MI held (``sim.whatif.time_to_target``)."""
    from sim.whatif import TARGET_SMOOTH_S, time_to_target

    after = np.isfinite(t) & (t >= t_d) & (t <= until)
    if after.sum() < 2:
        return None
    tt = t[after]
    dt = float(np.median(np.diff(tt)))
    if not dt > 0 or TARGET_SMOOTH_S / dt > MAX_SMOOTH_ROWS:
        return None
    hit = time_to_target(tt, mi[after], target)
    return float(hit + tt[0] - t_d) if math.isfinite(hit) else None


def time_to_mix(run: RunFiles, move: Move, t_reached: float, mixed_at: list[tuple[float, float | None]],
                config_target: float | None) -> dict[str, Any]:
    """The check's numbers for ``move`` (module doc), reading its window of rows."""
    target = move.target_mi or config_target
    if target is None:
        from twin.run.settings import endpoint_config

        target = endpoint_config().target_mi
    horizon = move.horizon_s or DEFAULT_HORIZON_S
    until = min(move.t_s + horizon, move.end_s)
    lo = min(move.t_s, move.state_t_s if move.state_t_s is not None else move.t_s) - 1.0
    t, mi, twin = _window(run, lo, max(until, move.t_s + 1.0))
    actual = _actual_s(t, mi, move.t_s, until, target)
    mt = next((m for tm, m in mixed_at if tm >= move.t_s), None)
    return {"t_decision_s": move.t_s, "rpm": move.rpm, "t_reached_s": t_reached, "target_mi": target,
            "twin_mi_at_state": _mean_near(t, twin, move.state_t_s),
            "plant_mi_at_decision": _mean_near(t, mi, move.t_s),
            "predicted_s": move.predicted_s, "state_t_s": move.state_t_s,
            "actual_s": actual, "endpoint_s": None if mt is None else max(0.0, mt - move.t_s),
            "error_pct": None if not actual else 100.0 * (move.predicted_s - actual) / actual,
            "predicted_energy_j": move.predicted_energy_j}


def config_target(metadata: dict[str, Any]) -> float | None:
    """The run's endpoint target MI from its metadata (``config.target_mi``), when it logged one."""
    cfg = metadata.get("config")
    return num(cfg.get("target_mi")) if isinstance(cfg, dict) else None

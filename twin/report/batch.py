"""A multi-run report's batch table: mixing time and energy per run, their mean and spread per
rpm profile, and each run against its rig's golden batch. It reads only the catalogue's
summaries (``twin.catalogue.select.Batch``), never the runs' frames: its memory is a row
per run whatever the logs hold.

Runs are grouped by rig and **rpm profile** (start rpm -> final rpm), not by final rpm alone:
mixing time is counted from the run's start, so a batch that ran at 20 rpm throughout and one
that AUTO moved from 5 to 20 rpm after a minute are different recipes, and pooling them would
make the spread of either meaningless. The rpm are the catalogue's (setpoints, exact values the
operator or AUTO chose), so equal profiles compare equal; they are rounded to ``RPM_STEP``
against float noise.
"""

from __future__ import annotations

import datetime as dt
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from twin.catalogue.summary import RunSummary
from twin.report.cells import fmt, table
from twin.report.events import text

if TYPE_CHECKING:
    from twin.catalogue.select import Batch

RPM_STEP = 0.1
"""rpm of a profile are compared to this step."""

RUN_HEAD = ("run", "started", "rig", "mode", "rpm start→final", "mixed", "mixing time s", "energy J",
            "vs golden: mixing time s", "vs golden: energy J")
GROUP_HEAD = ("rig", "rpm start→final", "runs", "mixed", "mixing time s: mean", "sd", "energy J: mean", "sd")
GOLDEN_HEAD = ("rig", "golden batch", "started", "rpm start→final", "mixing time s", "energy J")


def _rpm(x: float | None) -> float | None:
    return None if x is None else round(x / RPM_STEP) * RPM_STEP


def profile(s: RunSummary) -> tuple[float | None, float | None]:
    """The run's rpm profile: (start, final) rpm, rounded to ``RPM_STEP``."""
    return _rpm(s.rpm_start), _rpm(s.rpm_final)


def profile_text(prof: tuple[float | None, float | None]) -> str:
    """``start→final`` of a profile."""
    start, final = prof
    return "–" if start is None and final is None else f"{fmt(start, 'g')}→{fmt(final, 'g')}"


@dataclass(frozen=True)
class Group:
    """Runs of one rig and rpm profile: how many, how many mixed, mean and sample sd (None:
    fewer than two values) of the mixing time (mixed runs) and of the energy (runs that
    logged it)."""

    rig: str
    profile: tuple[float | None, float | None]
    runs: int
    mixed: int
    mixing_time_s: tuple[float | None, float | None]
    energy_j: tuple[float | None, float | None]


def mean_sd(values: Sequence[float]) -> tuple[float | None, float | None]:
    """Mean and sample sd (n - 1) of ``values``: (None, None) of none, sd None of one."""
    if not values:
        return None, None
    return statistics.fmean(values), statistics.stdev(values) if len(values) > 1 else None


def groups(summaries: Sequence[RunSummary]) -> list[Group]:
    """The runs by rig and rpm profile (module doc), in the order each group first appears."""
    by: dict[tuple[str, tuple[float | None, float | None]], list[RunSummary]] = {}
    for s in summaries:
        by.setdefault((s.rig, profile(s)), []).append(s)
    out = []
    for (rig, prof), runs in by.items():
        times = [t for s in runs if s.mixed and (t := _finite(s.mixing_time_s)) is not None]
        energies = [e for s in runs if (e := _finite(s.energy_j)) is not None]
        out.append(Group(rig, prof, len(runs), sum(s.mixed for s in runs), mean_sd(times), mean_sd(energies)))
    return out


def _finite(x: float | None) -> float | None:
    return x if x is not None and math.isfinite(x) else None


def _mixing_time(s: RunSummary) -> float | None:
    """A mixed run's mixing time (None: not mixed, or none logged)."""
    return _finite(s.mixing_time_s) if s.mixed else None


def against(s: RunSummary, golden: RunSummary | None) -> tuple[float | None, float | None]:
    """(mixing time, energy) of ``s`` minus its golden batch's: positive is slower, or more
    energy; None where either is unknown (not mixed, no energy logged, no golden batch)."""
    if golden is None:
        return None, None
    t, t_g, e, e_g = _mixing_time(s), _mixing_time(golden), _finite(s.energy_j), _finite(golden.energy_j)
    return (None if t is None or t_g is None else t - t_g), (None if e is None or e_g is None else e - e_g)


def _when(t: float | None) -> str:
    return "–" if t is None else dt.datetime.fromtimestamp(t).strftime("%Y-%m-%d %H:%M")


def batch_html(labels: Sequence[str], batch: Batch) -> str:
    """The batch section: the runs, the groups and the golden batches (module doc)."""
    known = [(lab, s) for lab, s in zip(labels, batch.summaries, strict=True) if s is not None]
    rows = []
    for lab, s in known:
        golden = batch.golden.get(s.rig)
        d_t, d_e = against(s, golden)
        mark = ' <b class="golden-mark">golden</b>' if golden is not None and golden.id == s.id else ""
        rows.append((f'<span class="batch-label">{text(lab)}</span>{mark}', _when(s.started_s), text(s.rig),
                     text(s.mode), profile_text(profile(s)), "yes" if s.mixed else "no",
                     fmt(_mixing_time(s), ".1f"), fmt(s.energy_j, ".1f"),
                     fmt(d_t, "+.1f"), fmt(d_e, "+.1f")))
    grows = [(text(g.rig), profile_text(g.profile), str(g.runs), str(g.mixed),
              fmt(g.mixing_time_s[0], ".1f"), fmt(g.mixing_time_s[1], ".1f"),
              fmt(g.energy_j[0], ".1f"), fmt(g.energy_j[1], ".1f")) for g in groups([s for _, s in known])]
    parts = ['<h2 id="batches">Batches</h2>',
             "<p>Mixing time and drive energy of each run (the catalogue's summaries), against its rig's "
             "golden batch (positive: slower, or more energy); below, mean and sample sd per rig and rpm "
             "profile (start→final rpm: mixing time counts from the start, so the profile is the recipe).</p>",
             table(rows, RUN_HEAD, "batch-runs"), "<h4>By rig and rpm profile</h4>",
             table(grows, GROUP_HEAD, "batch-groups")]
    rigs = sorted({s.rig for _, s in known})
    golden_rows = [(text(rig), text(g.id[:8]) + f' <span class="batch-label">{text(_name(g))}</span>',
                    _when(g.started_s), profile_text(profile(g)), fmt(_mixing_time(g), ".1f"),
                    fmt(g.energy_j, ".1f")) for rig in rigs if (g := batch.golden.get(rig)) is not None]
    if golden_rows:
        parts.append("<h4>Golden batches</h4>" + table(golden_rows, GOLDEN_HEAD, "batch-golden"))
    missing = [rig for rig in rigs if rig not in batch.golden]
    if batch.note is not None:
        parts.append(f'<p class="none">{text(batch.note)}</p>')
    elif missing:
        parts.append(f'<p class="none">No golden batch for rig {", ".join(text(r) for r in missing)} '
                     "('drumtwin runs golden ID' marks one).</p>")
    skipped = len(labels) - len(known)
    if skipped:
        parts.append(f'<p class="note">{skipped} run(s) without run files left out of the table.</p>')
    return "".join(parts)


def _name(s: RunSummary) -> str:
    return s.path.rstrip("/").rsplit("/", 1)[-1]

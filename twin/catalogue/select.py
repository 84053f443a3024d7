"""Which runs ``report`` and ``compare`` show: folders, run ids and catalogue filters.

An argument that is an existing folder stays that folder; ``LABEL=X`` names the run ``X``
(split at the last ``=``); anything else is a run id, a unique prefix of one or a run
folder's name, looked up in the catalogue (``Catalogue.get``). A filter (``runs list``'s
options) adds the runs it selects, newest first, after the arguments. The catalogue is only
opened when an argument or a filter needs it, and never created here: a lab without one has
no run ids to look up (``drumtwin run`` makes it beside the runs; ``runs rebuild`` too).

For a report's batch table, :func:`batch_of` gives each run's catalogue summary (a folder the
catalogue does not hold is summarised from its files) and its rig's golden batch.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from twin.catalogue.store import Catalogue, CatalogueError, RunFilter, check_url, resolve_url, runs_root_of
from twin.catalogue.summary import RunSummary, summarise
from twin.errors import TwinError


@dataclass(frozen=True)
class Batch:
    """What a report's batch table reads: each run's summary (None: no run files) and each
    rig's golden batch; ``note``: why golden batches are unknown (no catalogue), else None."""

    summaries: tuple[RunSummary | None, ...]
    golden: dict[str, RunSummary] = field(default_factory=dict)
    note: str | None = None


class Lookup:
    """The catalogue, opened on first use (never created), reconciled with the folders once."""

    def __init__(self, url: str | None, runs_dir: Path | str) -> None:
        self.url, self.runs_dir = url, Path(runs_dir)
        self._cat: Catalogue | None = None

    def catalogue(self) -> Catalogue:
        """The catalogue (a ``CatalogueError`` when there is none or it cannot be read)."""
        if self._cat is None:
            where = self.where()
            if "://" not in where and not Path(where).expanduser().is_file():  # opening it would make one
                raise CatalogueError(f"no run catalogue at {where}")
            self._cat = Catalogue.open(self.url, self.runs_dir, create=False)
            with contextlib.suppress(CatalogueError):  # read-only or full: the index as it is still answers
                self._cat.reconcile()
        return self._cat

    def where(self) -> str:
        return resolve_url(self.url, self.runs_dir)

    def close(self) -> None:
        if self._cat is not None:
            self._cat.close()


@contextlib.contextmanager
def lookup(url: str | None, runs_dir: Path | None) -> Iterator[Lookup]:
    """The catalogue ``report``/``compare`` look runs up in, opened when first needed; a
    ``--catalogue`` or ``--runs-dir`` that cannot be one is bad input at once, used or not."""
    if url is not None:
        check_url(url)
    found = Lookup(url, runs_root_of(runs_dir))
    try:
        yield found
    finally:
        found.close()


def _find(spec: str, cat: Lookup) -> tuple[str, Path]:
    """(folder name, folder) of a folder that exists, else of a run in the catalogue."""
    p = Path(spec)
    if p.exists():
        return p.name or str(p), p
    if os.sep in spec or (os.altsep and os.altsep in spec) or not spec.strip():
        raise TwinError(f"no such run dir: {p}")
    try:
        s = cat.catalogue().get(spec)
    except CatalogueError as exc:
        raise TwinError(f"no such run dir or run id: {spec} ({exc})") from None
    return Path(s.path).name, Path(s.path)


def select_runs(specs: Sequence[str], labels: Sequence[str] | None, run_filter: RunFilter | None,
                cat: Lookup) -> list[tuple[str, Path]]:
    """(label, folder) of each run (module doc): the arguments in order, then the filter's runs
    not already given. ``labels``: one per argument (``--label``), taken as given."""
    if labels:
        if run_filter is not None:
            raise TwinError("--label names the runs given as arguments: not with a filter (--rig, --last, ...)")
        if len(labels) != len(specs):
            raise TwinError(f"--label given {len(labels)} time(s) for {len(specs)} run(s): give one per run, or none")
        if not all(lab.strip() for lab in labels):
            raise TwinError("--label: a label cannot be empty")
    out: list[tuple[str, Path]] = []
    for i, spec in enumerate(specs):
        if labels:
            out.append((labels[i], _find(spec, cat)[1]))
        elif not Path(spec).exists() and "=" in spec:
            lab, _, rest = spec.rpartition("=")
            name, path = _find(rest, cat)
            out.append((lab or name, path))
        else:
            out.append(_find(spec, cat))
    if run_filter is not None:
        given = {p.resolve() for _, p in out}
        db = cat.catalogue()
        found = db.list(run_filter)
        if not found:
            raise TwinError(f"no run in the catalogue {db.where} matches the filter "
                            "('drumtwin runs list' with the same options lists the runs)")
        out += [(Path(s.path).name, Path(s.path)) for s in found if Path(s.path).resolve() not in given]
    if not out:
        raise TwinError("give at least one run dir or run id, or a filter (--rig, --last, ...)")
    return out


def batch_of(runs: Sequence[tuple[str, Path]], cat: Lookup) -> Batch:
    """Each run's summary, from the catalogue when it holds the folder (else from its files),
    and the golden batch of each rig among them. A catalogue that cannot be opened is a note
    (the table shows no golden batch), never an error: the folders were given."""
    try:
        db: Catalogue | None = cat.catalogue()
    except CatalogueError as exc:
        db, note = None, f"no golden batches: {exc}"
    summaries: list[RunSummary | None] = []
    for _, path in runs:
        s = None
        if db is not None:
            with contextlib.suppress(CatalogueError):
                s = db.get(str(path.resolve()))
        summaries.append(s if s is not None else summarise(path))
    if db is None:
        return Batch(tuple(summaries), {}, note)
    rigs = sorted({s.rig for s in summaries if s is not None})
    golden = {rig: g for rig in rigs if (g := db.golden_of(rig)) is not None}
    return Batch(tuple(summaries), golden, None)

"""``drumtwin runs``: every batch in one place (the run catalogue, ``twin.catalogue``).

``list`` (newest first, filtered), ``show ID``, ``tag ID key=value``, ``note ID TEXT``,
``golden ID`` and ``rebuild``. The catalogue is ``--catalogue`` (a path or a
``postgresql://`` URL), else ``$DRUMTWIN_CATALOGUE``, else ``<runs-dir>/catalogue.sqlite``.
``list`` and ``show`` first index what the folders hold and the catalogue missed.
"""

from __future__ import annotations

import datetime as dt
import functools
import inspect
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from twin.cli.app import app, bench_app, print_json, say
from twin.errors import TwinError

if TYPE_CHECKING:
    from twin.catalogue.store import RunFilter

runs_app = typer.Typer(help="The run catalogue: list, show, tag, note, golden, rebuild.")
app.add_typer(runs_app, name="runs")

CATALOGUE_HELP = "Catalogue: an SQLite path or postgresql://user@host/db (default $DRUMTWIN_CATALOGUE, " \
                 "else RUNS_DIR/catalogue.sqlite)."
RUNS_DIR_HELP = "Folder of the run folders (default: runs, where drumtwin run writes them)."


CATALOGUE_OPT = typer.Option(None, "--catalogue", help=CATALOGUE_HELP)
RUNS_DIR_OPT = typer.Option(None, "--runs-dir", help=RUNS_DIR_HELP, show_default=False)


def parse_date(text: str, option: str) -> float:
    """A date (YYYY-MM-DD) or date and time (YYYY-MM-DDTHH:MM) in local time -> unix s."""
    try:
        return dt.datetime.fromisoformat(text).timestamp()
    except ValueError:
        raise TwinError(f"{option} {text!r}: give a date as YYYY-MM-DD or YYYY-MM-DDTHH:MM") from None


def parse_tags(tags: Sequence[str]) -> list[tuple[str, str | None]]:
    """``key`` (any value) or ``key=value`` (the LAST '=' is not special: keys have none)."""
    out: list[tuple[str, str | None]] = []
    for t in tags:
        key, sep, value = t.partition("=")
        if not key.strip():
            raise TwinError(f"--tag {t!r}: give key or key=value")
        out.append((key.strip(), value if sep else None))
    return out


def parse_rpm_range(text: str) -> tuple[float | None, float | None]:
    """``LO:HI``, ``LO:`` or ``:HI`` (rpm) -> bounds."""
    lo, sep, hi = text.partition(":")
    try:
        bounds = (float(lo) if lo.strip() else None, float(hi) if hi.strip() else None)
    except ValueError:
        raise TwinError(f"--rpm {text!r}: give LO:HI in rpm (either side may be empty)") from None
    if not sep or bounds == (None, None):
        raise TwinError(f"--rpm {text!r}: give LO:HI in rpm (either side may be empty)")
    return bounds



FILTER_OPTIONS: tuple[inspect.Parameter, ...] = tuple(
    inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=kind)
    for name, kind, option in (
        ("rig", str, typer.Option(None, "--rig", help="Only this rig (the config's name; 'demo' for the demo).")),
        ("mode", str, typer.Option(None, "--mode", help="Only runs in this mode: off, manual or auto.")),
        ("tag", list[str], typer.Option([], "--tag", help="Only runs with this tag: key or key=value (repeatable).")),
        ("since", str, typer.Option(None, "--since", help="Started on or after this date (YYYY-MM-DD[THH:MM]).")),
        ("until", str, typer.Option(None, "--until", help="Started before this date (YYYY-MM-DD[THH:MM]).")),
        ("mixed", bool, typer.Option(None, "--mixed/--not-mixed", help="Only batches that reached (or missed) "
                                     "their endpoint.")),
        ("rpm", str, typer.Option(None, "--rpm", help="Only runs whose rpm went into LO:HI.")),
        ("ended", str, typer.Option(None, "--ended", help="Only runs that ended so: running, clean, failed, "
                                    "killed.")),
        ("last", int, typer.Option(None, "--last", min=1, max=1_000_000, help="At most this many (the newest).")),
    )
)
"""The run filter's options, one definition for ``runs list``, ``report`` and ``compare``
(:func:`filter_options` adds them to a command)."""


def run_filter(rig: str | None = None, mode: str | None = None, tag: Sequence[str] = (), since: str | None = None,
               until: str | None = None, mixed: bool | None = None, rpm: str | None = None,
               ended: str | None = None, last: int | None = None) -> RunFilter | None:
    """The ``RunFilter`` of the filter options (None: none of them given); bad values are one line."""
    from control.decision import Mode
    from twin.catalogue.store import RunFilter
    from twin.catalogue.summary import ENDED

    if ended is not None and ended not in ENDED:
        raise TwinError(f"--ended {ended!r}: one of {', '.join(ENDED)}")
    modes = [m.value for m in Mode]
    if mode is not None and mode not in modes:
        raise TwinError(f"--mode {mode!r}: one of {', '.join(modes)}")
    if rig is not None and not rig.strip():
        raise TwinError("--rig: give the rig's name (the config's name; 'demo' for the demo)")
    if all(v is None for v in (rig, mode, since, until, mixed, rpm, ended, last)) and not tag:
        return None
    lo, hi = parse_rpm_range(rpm) if rpm is not None else (None, None)
    return RunFilter(rig=rig, mode=mode, tags=parse_tags(tag),
                     since_s=parse_date(since, "--since") if since is not None else None,
                     until_s=parse_date(until, "--until") if until is not None else None,
                     mixed=mixed, rpm_lo=lo, rpm_hi=hi, ended=ended, last=last)


def filter_options(command: Callable[..., None]) -> Callable[..., None]:
    """Give ``command`` the filter options (:data:`FILTER_OPTIONS`): it is called with
    ``run_filter`` (:func:`run_filter` of them) in their place."""
    names = [p.name for p in FILTER_OPTIONS]
    sig = inspect.signature(command)  # typer reads the command's own types from its annotations
    own = [p for p in sig.parameters.values() if p.name != "run_filter"]

    @functools.wraps(command)
    def with_filter(**kwargs: Any) -> None:
        chosen = {k: kwargs.pop(k) for k in names}
        command(**kwargs, run_filter=run_filter(**chosen))

    with_filter.__signature__ = sig.replace(parameters=[*own, *FILTER_OPTIONS])  # type: ignore[attr-defined]
    with_filter.__annotations__ = {k: v for k, v in command.__annotations__.items() if k != "run_filter"}
    return with_filter


def _when(t: float | None) -> str:
    return "-" if t is None else dt.datetime.fromtimestamp(t).strftime("%Y-%m-%d %H:%M")


def _num(x: float | None, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def summary_line(s: object) -> str:
    """One run as a line of ``runs list``."""
    from twin.catalogue.summary import RunSummary

    assert isinstance(s, RunSummary)
    rpm = "-" if s.rpm_start is None else f"{s.rpm_start:g}->{_num(s.rpm_final, 'g')}"
    mixed = f"mixed {s.mixing_time_s:.0f}s" if s.mixed and s.mixing_time_s is not None else (
        "mixed" if s.mixed else "not mixed")
    tags = " ".join(f"{k}={v}" for k, v in sorted(s.tags.items()))
    star = "*" if s.golden else " "
    return (f"{star}{s.id[:8]:<8}  {_when(s.started_s)}  {s.rig[:16]:<16} {s.mode:<6} {rpm:>10} rpm  "
            f"{mixed:<14} MI {_num(s.final_mi, '.3f'):>5}  {s.ended:<7} {tags}").rstrip()


@runs_app.command("list")
@filter_options
def runs_list(
    as_json: bool = typer.Option(False, "--json", help="Print the runs as JSON (stdout)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
    *,
    run_filter: RunFilter | None,
) -> None:
    """The runs, newest first (one line each; * marks a rig's golden batch)."""
    from twin.catalogue.store import RunFilter, open_for_runs

    with open_for_runs(catalogue, runs_dir) as cat:
        cat.reconcile()
        found = cat.list(run_filter or RunFilter())
    if as_json:
        print_json([s.as_json() for s in found])
        return
    for s in found:
        print(summary_line(s))
    say(f"{len(found)} run(s)")


@runs_app.command("show")
def runs_show(
    run: str = typer.Argument(..., help="Run id (or a unique prefix of it, or its folder or the folder's name)."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary and events as JSON (stdout)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
) -> None:
    """One run: its summary, its folder and the events that matter."""
    from twin.catalogue.show import key_events, summary_table
    from twin.catalogue.store import open_for_runs

    with open_for_runs(catalogue, runs_dir) as cat:
        cat.reconcile()
        s = cat.get(run)
    events = key_events(s.path)
    if as_json:
        print_json({"summary": s.as_json(), "events": events})
        return
    for name, value in summary_table(s):
        print(f"{name:>14}  {value}")
    print()
    for e in events:
        print(f"{e['t_s']:>9.1f} s  {e['kind']:<16} {e['text']}")


@runs_app.command("tag")
def runs_tag(
    run: str = typer.Argument(..., help="Run id (or a unique prefix)."),
    tags: list[str] = typer.Argument(..., help="key=value (an empty value removes the tag)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
) -> None:
    """Tag a run (kept in its folder's annotations.jsonl, indexed in the catalogue)."""
    from twin.catalogue.store import open_for_runs

    pairs = parse_tags(tags)
    if any(v is None for _k, v in pairs):
        raise TwinError("runs tag: give each tag as key=value")
    with open_for_runs(catalogue, runs_dir) as cat:
        s = cat.get(run)
        for k, v in pairs:
            s = cat.tag(s.id, k, v or "")
    say(f"run {s.id}: tags {', '.join(f'{k}={v}' for k, v in sorted(s.tags.items())) or 'none'}")


@runs_app.command("note")
def runs_note(
    run: str = typer.Argument(..., help="Run id (or a unique prefix)."),
    text: str = typer.Argument(..., help="The note (replaces the run's earlier note)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
) -> None:
    """Write a note on a run (kept in its folder, indexed in the catalogue)."""
    from twin.catalogue.store import open_for_runs

    with open_for_runs(catalogue, runs_dir) as cat:
        s = cat.note(cat.get(run).id, text)
    say(f"run {s.id}: note kept")


@runs_app.command("golden")
def runs_golden(
    run: str = typer.Argument(..., help="Run id (or a unique prefix)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
) -> None:
    """Mark a run as its rig's golden batch (the reference the dashboard and reports draw)."""
    from twin.catalogue.store import open_for_runs

    with open_for_runs(catalogue, runs_dir) as cat:
        s = cat.golden(cat.get(run).id)
    say(f"run {s.id} is the golden batch of rig {s.rig}")


@runs_app.command("rebuild")
def runs_rebuild(
    roots: list[Path] = typer.Argument(None, help="Folders of run folders to index (default: --runs-dir)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
) -> None:
    """Recreate the catalogue from the run folders (a corrupt or foreign file is kept aside)."""
    from twin.catalogue.store import rebuild, runs_root_of

    root = runs_root_of(runs_dir)
    for r in roots or [root]:
        if not r.is_dir():
            raise TwinError(f"runs rebuild: {r} is not a folder of runs" + ("" if roots else " (--runs-dir)"))
    n, moved = rebuild(catalogue, root, list(roots or []), progress=lambda i: say(f"... {i} folders read"))
    if moved:
        say(f"the unreadable catalogue was kept as {moved}")
    say(f"catalogue rebuilt: {n} run(s)")


@bench_app.command("catalogue")
def bench_catalogue(
    runs: int = typer.Option(10_000, "--runs", min=1, max=200_000, help="Run folders to generate."),
    template: Path = typer.Option(None, "--template", help="A real run folder to copy (default: the run log "
                                  "shipped under tests/data)."),
    as_json: bool = typer.Option(False, "--json", help="Print the numbers as JSON (stdout)."),
) -> None:
    """Rebuild and filtered-list times of a catalogue of N generated run folders."""
    from twin.catalogue.bench import run_bench

    src = template or Path(__file__).resolve().parents[2] / "tests" / "data" / "runlog-previous"
    if not (src / "events.jsonl").is_file():
        raise TwinError(f"--template {src}: not a run folder (no events.jsonl)")
    out = run_bench(runs, src, progress=say)
    if as_json:
        print_json(out)
    else:
        for k, v in out.items():
            print(f"{k:>26}  {v}")

"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML report (issue 24)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from twin.cli.app import app, bench_app, console_err, print_json, say
from twin.cli.runs_cmd import CATALOGUE_OPT, RUNS_DIR_OPT, filter_options
from twin.errors import TwinError

if TYPE_CHECKING:
    from twin.catalogue.store import RunFilter

RUNS_HELP = ("Runs: each a run log DIR (its folder name is the label), a run id (or a unique prefix, or a run "
             "folder's name) from the catalogue, or LABEL=DIR / LABEL=ID (split at the last '='; a path that "
             "exists is a path). The filter options add the catalogue's runs they select, newest first.")
LABEL_HELP = ("A label for each run, in order (repeat once per run): the runs are then taken as paths "
              "as given (a folder name with '=' in it).")


@app.command("report")
@filter_options
def report(
    runs: list[str] = typer.Argument(None, help=RUNS_HELP, show_default=False),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained: opens offline)."),
    title: str = typer.Option("drumtwin report", "--title", help="Report title."),
    label: list[str] = typer.Option([], "--label", help=LABEL_HELP),
    json_out: bool = typer.Option(False, "--json", help="Also print each run's endpoint and the twin's time to "
                                  "mix against the plant's (JSON, stdout)."),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
    *,
    run_filter: RunFilter | None,
) -> None:
    """One HTML file of runs side by side: MI, rpm, slope, events, endpoint, energy, config; of
    several runs, a batch table first (mixing time and energy per run and per rpm profile, against
    the rig's golden batch). A line or cell of a log that cannot be read is skipped and counted in
    a note on its run."""
    from twin.catalogue.select import batch_of, lookup, select_runs
    from twin.report import write_report
    from twin.report.build import check_out

    check_out(out)
    with lookup(catalogue, runs_dir) as cat:
        chosen = select_runs(runs or [], label or None, run_filter, cat)
        batch = batch_of(chosen, cat) if len(chosen) > 1 else None
    path, results = write_report([str(p) for _, p in chosen], out, title, [lab for lab, _ in chosen], batch=batch)
    say(f"report of {len(chosen)} run(s) written to {path}")
    if json_out:
        print_json(results)


@app.command("compare")
@filter_options
def compare(
    runs: list[str] = typer.Argument(None, help=RUNS_HELP, show_default=False),
    plot: Path = typer.Option(..., "--plot", help="PNG to write: MI and Kalman trend of every run, rpm below."),
    title: str = typer.Option("", "--title", help="Plot title."),
    label: list[str] = typer.Option([], "--label", help=LABEL_HELP),
    catalogue: str = CATALOGUE_OPT,
    runs_dir: Path | None = RUNS_DIR_OPT,
    *,
    run_filter: RunFilter | None,
) -> None:
    """Compare run logs: one plot of their MI curves and rpm (e.g. AUTO against OFF). A line or
    cell of a log that cannot be read is skipped and counted in a note on stderr."""
    from rich.markup import escape
    from rich.table import Table

    from twin.catalogue.select import lookup, select_runs
    from twin.cli.app import check_outputs, console
    from twin.plots import compare_runs
    from twin.report.load import check_dir

    check_outputs(plot)  # a directory as --plot would become DIR.png
    with lookup(catalogue, runs_dir) as cat:
        specs = select_runs(runs or [], label or None, run_filter, cat)
    for _, path in specs:
        check_dir(path)
    out, rows = compare_runs(specs, plot, title)
    table = Table(title="runs")
    for col in ("run", "frames", "run time s", "final trend MI", "final rpm", "rpm moves"):
        table.add_column(col, justify="right" if col != "run" else "left")
    fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
    for name, s, notes in rows:
        table.add_row(escape(name), str(s["frames"]), fmt(s["t_s"], ".1f"), fmt(s["trend_mi"], ".3f"),
                      fmt(s["rpm_actual"], ".1f"), str(s["moves"]))
        for n in notes:
            say(f"note: {name}: {n}")
    console.print(table)
    say(f"plot written to {out}")


@bench_app.command("report")
def bench_report_cmd(
    rows: int = typer.Option(100_000, "--rows", help="Frame rows per generated run (10 fps)."),
    runs: int = typer.Option(1, "--runs", help="Run folders to generate and report together."),
    keep: Path | None = typer.Option(None, "--keep", help="Write the logs and the report into this new folder "
                                     "and keep them (default: a temporary folder, removed)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON: wall_s, peak_rss_mb, html_mb, ..."),
) -> None:
    """Wall time and peak memory of `drumtwin report` (a subprocess) on generated run logs."""
    from dataclasses import asdict

    from control.errors import check_number
    from twin.report.bench import bench_report

    check_number("--rows", rows, at_least=0, at_most=100_000_000)
    check_number("--runs", runs, at_least=1, at_most=10_000)
    if keep is not None:
        if keep.exists():
            raise TwinError(f"--keep {keep} exists: give a new folder")
        keep.mkdir(parents=True)
    with console_err.status(f"generating {runs} run(s) of {rows} rows and reporting them ..."):
        res = bench_report(rows, runs, keep)
    if as_json:
        print_json(asdict(res))
        return
    say(f"drumtwin report of {runs} run(s) x {rows} rows: {res.wall_s:.1f} s, peak RSS {res.peak_rss_mb:.0f} MB, "
        f"HTML {res.html_mb:.2f} MB (logs {res.logs_mb:.0f} MB, written in {res.generate_s:.1f} s)")

"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML report (issue 24)."""

from __future__ import annotations

from pathlib import Path

import typer

from twin.cli.app import app, bench_app, console_err, print_json, say
from twin.errors import TwinError

RUNS_HELP = ("Run log dirs, each DIR (its folder name is the label) or LABEL=DIR (split at the last '='; "
             "a path that exists is a path).")
LABEL_HELP = ("A label for each run, in order (repeat once per run): the runs are then taken as paths "
              "as given (a folder name with '=' in it).")


@app.command("report")
def report(
    runs: list[str] = typer.Argument(..., help=RUNS_HELP),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained: opens offline)."),
    title: str = typer.Option("drumtwin report", "--title", help="Report title."),
    label: list[str] = typer.Option([], "--label", help=LABEL_HELP),
    json_out: bool = typer.Option(False, "--json", help="Also print each run's endpoint and the twin's time to "
                                  "mix against the plant's (JSON, stdout)."),
) -> None:
    """One HTML file of runs side by side: MI, rpm, slope, events, endpoint, energy, config.
    A line or cell of a log that cannot be read is skipped and counted in a note on its run."""
    from twin.report import write_report

    path, results = write_report(runs, out, title, label or None)
    say(f"report of {len(runs)} run(s) written to {path}")
    if json_out:
        print_json(results)


@app.command("compare")
def compare(
    runs: list[str] = typer.Argument(..., help=RUNS_HELP),
    plot: Path = typer.Option(..., "--plot", help="PNG to write: MI and Kalman trend of every run, rpm below."),
    title: str = typer.Option("", "--title", help="Plot title."),
    label: list[str] = typer.Option([], "--label", help=LABEL_HELP),
) -> None:
    """Compare run logs: one plot of their MI curves and rpm (e.g. AUTO against OFF). A line or
    cell of a log that cannot be read is skipped and counted in a note on stderr."""
    from rich.markup import escape
    from rich.table import Table

    from twin.cli.app import check_outputs, console
    from twin.plots import compare_runs
    from twin.report import run_specs
    from twin.report.load import check_dir

    check_outputs(plot)  # a directory as --plot would become DIR.png
    specs = run_specs(runs, label or None)
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

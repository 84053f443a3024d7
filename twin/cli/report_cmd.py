"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML report (issue 24)."""

from __future__ import annotations

from pathlib import Path

import typer

from twin.cli.app import app, bench_app, console_err, print_json, say
from twin.errors import TwinError


@app.command("report")
def report(
    runs: list[str] = typer.Argument(..., help="Run log dirs, each LABEL=DIR (or just DIR: its folder name)."),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained: opens offline)."),
    title: str = typer.Option("drumtwin report", "--title", help="Report title."),
    json_out: bool = typer.Option(False, "--json", help="Also print each run's endpoint and the twin's time to "
                                  "mix against the plant's (JSON, stdout)."),
) -> None:
    """One HTML file of runs side by side: MI, rpm, slope, events, endpoint, energy, config."""
    from twin.report import build_report, load_run, time_to_mix_check
    from twin.report.build import endpoint_of

    path = build_report(runs, out, title)
    say(f"report of {len(runs)} run(s) written to {path}")
    if json_out:
        out_runs = {}
        for spec in runs:
            label, sep, d = spec.partition("=")
            run = load_run(d if sep else spec, label if sep else None)
            end = endpoint_of(run)
            out_runs[run.label] = {"mixing_time_s": end["mixing_time_s"], "time_to_mix": time_to_mix_check(run)}
        print_json(out_runs)


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

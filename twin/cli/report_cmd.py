"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML report (issue 24)."""

from __future__ import annotations

from pathlib import Path

import typer

from twin.cli.app import app, print_json, say


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

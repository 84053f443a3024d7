"""``drumtwin report RUN_DIR... --out report.html``: one self-contained HTML report (issue 24)."""

from __future__ import annotations

from pathlib import Path

import typer

from twin.cli.app import app, console_err


@app.command("report")
def report(
    runs: list[str] = typer.Argument(..., help="Run log dirs, each LABEL=DIR (or just DIR: its folder name)."),
    out: Path = typer.Option(..., "--out", help="HTML file to write (self-contained: opens offline)."),
    title: str = typer.Option("drumtwin report", "--title", help="Report title."),
) -> None:
    """One HTML file of runs side by side: MI, rpm, slope, events, endpoint, energy, config."""
    from twin.report import build_report

    path = build_report(runs, out, title)
    console_err.print(f"report of {len(runs)} run(s) written to {path}", highlight=False)

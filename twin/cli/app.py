"""The typer application objects shared by every command module."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console

from control.errors import ControlError
from sim.errors import SimError
from twin.errors import TwinError
from vision.errors import VisionError

app = typer.Typer(
    name="drumtwin",
    help="Watch and steer a rotary drum particle mixer: vision MI, physics twin, supervisor.",
    no_args_is_help=False,
    add_completion=False,
    pretty_exceptions_enable=False,
)
bench_app = typer.Typer(help="Benchmarks that print numbers (frames/s, real-time factor, trend RMSE).")
app.add_typer(bench_app, name="bench")

console = Console()
console_err = Console(stderr=True)

ENDPOINT_HELP = {  # the --endpoint-* options of run and mi (defaults: control.endpoint.EndpointConfig)
    "band": "Endpoint: half-width of the plateau band (MI).",
    "dwell_s": "Endpoint: how long the trend must stay in the band (s).",
    "block_s": "Endpoint: moving block of raw MI (s).",
    "block_sd_max": "Endpoint: largest sd of raw MI in the block of a mixed batch (0: off).",
}


def say(msg: str) -> None:
    """One plain message on stderr: no markup (a path's ``[x]`` stays), no highlighting, no
    wrapping (a long path stays one piece to copy, also in a log file)."""
    console_err.print(msg, highlight=False, markup=False, soft_wrap=True)


def print_json(obj: object) -> None:
    """Print ``obj`` as one line of strict JSON on stdout (NaN/inf -> null, numpy -> plain)."""
    import json

    from twin.runlog import to_jsonable

    print(json.dumps(to_jsonable(obj)))

# Errors that mean "bad input or environment", reported as one line, exit 2.
USER_ERRORS: tuple[type[BaseException], ...] = (
    VisionError,
    SimError,
    ControlError,
    TwinError,
    FileNotFoundError,
    PermissionError,
    IsADirectoryError,
    NotADirectoryError,
    ConnectionError,
    TimeoutError,
    OSError,  # a read-only or full directory, a device that went away: the environment, in one line
    RecursionError,  # a TOML nested thousands deep
    OverflowError,  # a number too large for its use (roi = [1e308, ...])
    UnicodeDecodeError,  # a binary file where text (CSV, JSON lines, TOML) was expected
)


def check_outputs(*paths: Path | None) -> None:
    """Refuse, before any work, an output file that cannot be written: an existing
    directory, or a parent that is a regular file (one-line TwinError)."""
    for p in paths:
        if p is None:
            continue
        if p.is_dir():
            raise TwinError(f"{p} is a directory: give a file name to write")
        parent = next((q for q in p.parents if q.exists()), None)
        if parent is not None and not parent.is_dir():
            raise TwinError(f"cannot write {p}: {parent} is not a directory")

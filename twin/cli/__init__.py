"""The ``drumtwin`` command line.

One typer app; each command group lives in its own module and registers itself on
import. ``main`` turns expected user errors into a one-line message and exit code 2
(set ``DRUMTWIN_DEBUG=1`` to see the traceback instead).
"""

from __future__ import annotations

import importlib
import os
import sys

from rich.markup import escape

from twin.cli.app import USER_ERRORS, app, bench_app, console_err  # noqa: F401

# Command modules, in the order they appear in --help. Each registers its commands
# on ``app`` / ``bench_app`` at import time.
_COMMAND_MODULES = (
    "twin.cli.run_cmd",
    "twin.cli.vision_cmds",
    "twin.cli.sim_cmds",
    "twin.cli.control_cmds",
)

for _name in _COMMAND_MODULES:
    try:
        importlib.import_module(_name)
    except ModuleNotFoundError as exc:  # a command module not written yet
        if exc.name != _name:
            raise


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``drumtwin`` console script."""
    try:
        app(args=argv, prog_name="drumtwin", standalone_mode=True)
    except USER_ERRORS as exc:
        if os.environ.get("DRUMTWIN_DEBUG"):
            raise
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        console_err.print(f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
        sys.exit(2)

"""The ``drumtwin`` command line.

One typer app; each command group lives in its own module and registers itself on
import. ``main`` turns expected user errors into a one-line message and exit code 2
(set ``DRUMTWIN_DEBUG=1`` to see the traceback instead).
"""

from __future__ import annotations

import functools
import importlib
import os
import sys
from typing import TYPE_CHECKING, NoReturn

try:  # typer >= 0.20 vendors click; older typer uses the click package
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover
    from click import exceptions as click_exc  # type: ignore[no-redef]

import typer
from rich.markup import escape

from twin.cli.app import USER_ERRORS, app, bench_app, console_err, say  # noqa: F401

if TYPE_CHECKING:
    from typer._click.core import Command

# Command modules, in the order they appear in --help. Each registers its commands
# on ``app`` / ``bench_app`` at import time.
_COMMAND_MODULES = (
    "twin.cli.run_cmd",
    "twin.cli.vision_cmds",
    "twin.cli.sim_cmds",
    "twin.cli.control_cmds",
    "twin.cli.report_cmd",
    "twin.cli.runs_cmd",
    "twin.cli.commission_cmd",
)

for _name in _COMMAND_MODULES:
    try:
        importlib.import_module(_name)
    except ModuleNotFoundError as exc:  # a command module not written yet
        if exc.name != _name:
            raise


def _one_line_error(msg: str, code: int = 2) -> NoReturn:
    """Print ``error: MSG`` (first line only) on stderr and exit with ``code`` (2: bad input;
    a ``TwinError``'s own ``exit_code``, e.g. 3 for a run whose worker crashed)."""
    msg = msg.strip().splitlines()[0] if msg.strip() else "bad input"
    console_err.print(f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    sys.exit(code)


@functools.cache
def _command() -> Command:
    """``app``'s click command tree, built once per process: ``app(...)`` rebuilds it on every
    call (typer reads every command's signature again: ~12 ms a call, a third of a bad-input
    case). The app has no pretty exceptions (``twin.cli.app``), so nothing else of typer's
    ``__call__`` is lost."""
    return typer.main.get_command(app)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``drumtwin`` console script.

    Usage errors (unknown option, a value out of range) and expected user errors
    (``USER_ERRORS``) are one line on stderr and exit code 2, never a traceback.
    """
    try:
        rv = _command().main(args=argv, prog_name="drumtwin", standalone_mode=False)
    except click_exc.UsageError as exc:
        if os.environ.get("DRUMTWIN_DEBUG"):
            raise
        hint = f" (see 'drumtwin {exc.ctx.command_path.split(' ', 1)[1]} --help')" if (
            exc.ctx is not None and " " in exc.ctx.command_path) else " (see 'drumtwin --help')"
        _one_line_error(exc.format_message() + hint)
    except (typer.Abort, KeyboardInterrupt):
        say("aborted")
        sys.exit(130)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except click_exc.ClickException as exc:
        if os.environ.get("DRUMTWIN_DEBUG"):
            raise
        _one_line_error(exc.format_message())
    except USER_ERRORS as exc:
        if os.environ.get("DRUMTWIN_DEBUG"):
            raise
        if isinstance(exc, UnicodeDecodeError):
            _one_line_error(f"a file is not text ({exc.reason} at byte {exc.start}): a binary or corrupt file")
        if isinstance(exc, RecursionError):
            _one_line_error("input nested too deeply to read (e.g. a TOML nested thousands of levels deep)")
        _one_line_error(str(exc) if str(exc).strip() else type(exc).__name__, getattr(exc, "exit_code", 2))
    if isinstance(rv, int) and rv != 0:
        sys.exit(rv)

"""Run the ``drumtwin`` command line in-process (fast) and check its one-line errors.

``cli("mi", path, "--window", 0)`` calls :func:`twin.cli.main` exactly as the console
script does and returns the exit code and what it printed. Use the real console script
in a subprocess only where a test needs a separate process (signals, ``kill -9``).
"""

from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass

from twin.cli import main


@dataclass(frozen=True)
class CliResult:
    code: int
    out: str
    err: str


def cli(*args: object) -> CliResult:
    """``drumtwin ARGS...`` in this process; never raises (SystemExit becomes ``code``)."""
    out, err = io.StringIO(), io.StringIO()
    old_debug = os.environ.pop("DRUMTWIN_DEBUG", None)
    old_cols = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "400"  # rich wraps at 80 columns when not on a terminal
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        if old_debug is not None:
            os.environ["DRUMTWIN_DEBUG"] = old_debug
        if old_cols is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old_cols
    return CliResult(code, out.getvalue(), err.getvalue())


def assert_one_line_error(r: CliResult, *needles: str) -> str:
    """Exit code 2, no traceback, exactly one non-empty stderr line starting ``error:``
    that contains every needle (case-insensitive). Returns that line."""
    assert r.code == 2, (r.code, r.out[-500:], r.err[-2000:])
    assert "Traceback" not in r.err and "Traceback" not in r.out, r.err
    lines = [ln for ln in r.err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.err
    for n in needles:
        assert n.lower() in lines[0].lower(), (n, lines[0])
    return lines[0]

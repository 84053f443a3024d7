"""Shared fixtures: the real drum frames that ship with the tests (``tests/data``)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from tests.cli import CliResult

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
TEST_DATA = TESTS / "data"


@pytest.fixture(scope="session")
def real_drum_dir() -> Path:
    """Folder of the real blue/white PMMA drum frames and their YOLO labels
    (CC BY 4.0, T. Delorenzi; see ``tests/data/real-drum-pmma/README.md``)."""
    path = TEST_DATA / "real-drum-pmma"
    if not path.is_dir():
        raise FileNotFoundError(f"test data missing: {path}")
    return path


def pytest_sessionstart(session: pytest.Session) -> None:
    """Under xdist, the controller compiles the numba kernels once before the workers start
    (tests/numba_warm.py); one process (``-n 0``) compiles them as it goes, once anyway."""
    config = session.config
    if (not hasattr(config, "workerinput") and getattr(config.option, "numprocesses", None)
            and not config.option.collectonly):
        from tests import numba_warm

        numba_warm.start()


def pytest_unconfigure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):
        from tests import numba_warm

        numba_warm.stop()


@pytest.fixture(scope="session", autouse=True)
def numba_warm_up() -> None:
    """A worker's first test waits for the controller's numba warm-up (none: at once)."""
    from tests import numba_warm

    numba_warm.wait()


LEARNED_SESSION_DIR = "DRUMTWIN_LEARNED_SESSION_DIR"  # the controller's memo dir without a cache dir


def pytest_configure(config: pytest.Config) -> None:
    """The learned-classes memo (tests/learned.py) keeps its results in pytest's cache dir;
    with ``-p no:cacheprovider`` under xdist, in a temp dir of this session that the controller
    makes for its workers (they inherit its environment) and removes at its end: the workers
    still learn each key once between them, and nothing outlives the run. One process without
    a cache dir: the memo is in the process only. ``--dist loadgroup`` groups on this pytest
    (tests/xdist_groups.py)."""
    import tempfile

    from tests import learned

    config.pluginmanager.import_plugin("tests.xdist_groups")

    cache = getattr(config, "cache", None)  # None with -p no:cacheprovider
    if cache is not None:
        learned.cache_dir = cache.mkdir("drumtwin-learned")
        return
    if not hasattr(config, "workerinput") and getattr(config.option, "numprocesses", None):
        os.environ[LEARNED_SESSION_DIR] = tempfile.mkdtemp(prefix="drumtwin-learned-")
        config.add_cleanup(lambda: shutil.rmtree(os.environ.pop(LEARNED_SESSION_DIR), ignore_errors=True))
    session_dir = os.environ.get(LEARNED_SESSION_DIR) if hasattr(config, "workerinput") else None
    learned.cache_dir = Path(session_dir) if session_dir else None


# `drumtwin bench dashboard` (a demo in its own process, chromium on its dashboard) once per
# session: the bad-input sweep's base of that command and twin/test_live_browser.py's bench test read it.
BENCH_DASHBOARD_ARGS = ["--seconds", "2", "--warmup", "0", "--speed", "2"]


@pytest.fixture(scope="session")
def bench_dashboard_run() -> subprocess.CompletedProcess:
    """``drumtwin bench dashboard BENCH_DASHBOARD_ARGS --port FREE --json`` through the real
    console script; its users are in xdist group "live" (one worker: one run)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", str(REPO)), "COLUMNS": "400"}
    env.pop("DRUMTWIN_DEBUG", None)
    return subprocess.run([str(Path(sys.executable).with_name("drumtwin")), "bench", "dashboard",
                           *BENCH_DASHBOARD_ARGS, "--port", str(port), "--json"],
                          capture_output=True, text=True, timeout=380, env=env)


@pytest.fixture
def memo_learning() -> Iterator[None]:
    """``vision.suggest.suggest_classes`` memoised for this test (tests/learned.py): the same
    result for the same frames, arguments and code, learned once per key."""
    from tests.learned import memoised_learning

    with memoised_learning():
        yield


# Benches that the bad-input sweep's base check and a bench test both need, with the same
# arguments: run once per session (``cli_once``), both tests assert on the one result. Their
# users share xdist group "benches" (one worker: one run).
BENCH_TREND_ARGS = ["--json", "--sequences", "2", "--real-seeds", "1"]  # control/test_cli.py's bench test
BENCH_MEMORY_ARGS = ["--seconds", "5", "--json"]  # twin/test_memory.py's bench test
BENCH_TWIN_ARGS = ["--duration", "0.02", "--json"]  # sim/test_cli.py's bench test
BENCHES = pytest.mark.xdist_group("benches")


@pytest.fixture(scope="session")
def cli_once() -> Callable[..., CliResult]:
    """``tests.cli.cli`` memoised for the session: ``cli_once("bench", "trend", ...)`` runs the
    command in this process the first time and returns the same ``CliResult`` after that. The
    classes it learns come from the learned-classes memo (tests/learned.py), as ``memo_learning``'s."""
    from tests.cli import cli
    from tests.learned import memoised_learning

    runs: dict[tuple[str, ...], CliResult] = {}

    def run(*args: object) -> CliResult:
        key = tuple(str(a) for a in args)
        if key not in runs:
            with memoised_learning():
                runs[key] = cli(*key)
        return runs[key]

    return run


# `drumtwin commission` of the real PMMA frames, issue 39's must-show command (no --out: the default folder,
# in a working folder of its own), once per session: tests/twin/test_commission.py and the bad-input sweep's
# base of that command read it. Their users share one xdist group (one worker: one run), "commission", not
# the loops' "live": the run's ~35 s of CPU on the live group's worker made that worker the suite's tail. The
# one user that runs the loop (a video, mode off: nothing timed) is in "commission" alone; a test in two
# groups is in a third of its own (xdist joins the names), whose worker would run the commissioning again.
COMMISSION = pytest.mark.xdist_group("commission")
COMMISSION_PMMA_ARGS = ["--drum-diameter-mm", "250", "--rpm", "5"]


@pytest.fixture(scope="session")
def commission_pmma(tmp_path_factory: pytest.TempPathFactory) -> tuple[CliResult, Path]:
    """``drumtwin commission tests/data/real-drum-pmma/images --drum-diameter-mm 250 --rpm 5`` in-process,
    from an empty working folder: its result and the folder it wrote there (``commission-*``; a path that
    does not exist when it wrote none)."""
    from tests.cli import cli
    from tests.learned import memoised_learning

    cwd = tmp_path_factory.mktemp("commission-pmma")
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with memoised_learning():
            r = cli("commission", TEST_DATA / "real-drum-pmma" / "images", *COMMISSION_PMMA_ARGS)
    finally:
        os.chdir(here)
    written = sorted(cwd.glob("commission-*"))
    return r, written[0] if written else cwd / "commission-none"

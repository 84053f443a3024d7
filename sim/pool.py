"""Local worker processes that die with their parent: the process pools of the what-if studies
(``sim.whatif.run_study``) and of the live twin's calibration. ``make_pool`` gives a
``ProcessPoolExecutor`` on fork-server workers (``sim.whatif`` preloaded) whose workers exit as
soon as the process that made the pool is gone, however it goes (``kill -9`` included), and
remove its multiprocessing temp directory; ``close_pool`` ends one now."""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from concurrent.futures import Executor, ProcessPoolExecutor

from sim.errors import SimError

__all__ = ["close_pool", "make_pool"]


def _mp_context():
    """Fork-server workers with ``sim`` preloaded: thread-safe like spawn, cheap like fork."""
    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(["sim.whatif"])
        return ctx
    return mp.get_context("spawn")


def _parent_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - a pid reused by another user's process
        return False
    return True


def _die_with_parent(parent_pid: int, leftover_dir: str | None) -> None:
    """Pool-worker initializer: the worker ignores SIGINT, and a daemon thread ends it (``os._exit``) as soon as
    the process that made the pool is gone, even after ``kill -9``, and then removes that
    process's multiprocessing temp directory (the fork server's listener socket lives
    there; a killed parent cannot remove it itself).

    Why not ``PR_SET_PDEATHSIG``: a fork-server worker's parent is the fork server,
    which stays alive as long as any worker does (each worker holds its "alive" pipe),
    so the signal would never come. The thread waits on a pidfd of the parent (Linux
    >= 5.3: no polling, no pid reuse) and falls back to polling ``kill(pid, 0)``.
    """
    import select
    import shutil
    import signal
    import threading

    # Ctrl-C in a terminal reaches the whole process group: it is the parent's to handle (it
    # closes the pool); a worker that took it would die with a KeyboardInterrupt traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        pidfd: int | None = os.pidfd_open(parent_pid)
    except (AttributeError, OSError):
        pidfd = None

    def watch() -> None:
        if pidfd is not None:
            select.select([pidfd], [], [])  # readable once the parent has exited
        else:
            while _parent_alive(parent_pid):
                time.sleep(0.5)
        if leftover_dir:
            shutil.rmtree(leftover_dir, ignore_errors=True)
        os._exit(0)

    if pidfd is None and not _parent_alive(parent_pid):
        watch()
    threading.Thread(target=watch, name="whatif-parent-watch", daemon=True).start()


def _new_pool(n: int) -> ProcessPoolExecutor:
    """A process pool whose workers die with this process (see ``_die_with_parent``)."""
    ctx = _mp_context()
    leftover = None
    if ctx.get_start_method() == "forkserver":
        from multiprocessing import util

        leftover = util.get_temp_dir()  # where the fork server's socket will live
    return ProcessPoolExecutor(
        max_workers=n, mp_context=ctx, initializer=_die_with_parent, initargs=(os.getpid(), leftover)
    )


def make_pool(workers: int | None = None) -> Executor:
    """A reusable local process pool for repeated studies (pass it as ``run_study(..., pool=)``).
    Its workers exit when this process dies, however it dies."""
    n = (os.cpu_count() or 1) if workers is None else int(workers)
    if n < 1:
        raise SimError(f"workers must be >= 1 (got {workers})")
    return _new_pool(n)


def close_pool(pool: Executor | None) -> None:
    """End a pool from :func:`make_pool` now: running jobs are abandoned (their worker
    processes are terminated and joined), queued ones cancelled."""
    if pool is None:
        return
    procs = list((getattr(pool, "_processes", None) or {}).values())  # shutdown() forgets them
    for p in procs:
        p.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        p.join(timeout=2.0)

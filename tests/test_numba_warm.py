"""The xdist workers wait for the controller's numba warm-up (tests/numba_warm.py)."""

from __future__ import annotations

import fcntl
import os
import threading

from tests import numba_warm


def test_no_warm_up_no_wait(monkeypatch) -> None:
    monkeypatch.delenv(numba_warm.ENV, raising=False)
    numba_warm.wait()  # returns (a hang here is the bug: the suite's timeout ends it)
    monkeypatch.setenv(numba_warm.ENV, "/nonexistent/drumtwin-numba-warm.lock")  # finished and removed
    numba_warm.wait()


def test_a_worker_waits_while_the_controller_holds_the_lock(tmp_path, monkeypatch) -> None:
    lock = tmp_path / "warm.lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)  # the controller compiling
    monkeypatch.setenv(numba_warm.ENV, str(lock))
    done = threading.Event()
    waiter = threading.Thread(target=lambda: (numba_warm.wait(), done.set()), daemon=True)
    waiter.start()
    try:
        assert not done.wait(0.5), "wait() returned while the warm-up held the lock"
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)  # the warm-up ended
        os.close(fd)
    assert done.wait(30), "wait() did not return after the warm-up released the lock"

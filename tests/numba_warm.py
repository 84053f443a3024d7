"""The numba kernels compiled once before the xdist workers run a test (a fresh clone's cost).

Every kernel is ``cache=True``: once compiled, its machine code is on disk (``__pycache__``
next to the source, or ``NUMBA_CACHE_DIR``) and every later process loads it. In a fresh
clone nothing is on disk yet, and the two workers' first whole-loop runs start at the same
moment, each with its own plant, twin and vision processes: each of them compiled the same
kernels at once (about 14 s CPU for the DEM's, 17 s for vision's, busy machine; and each
worker its first learned classes' light-tracking kernels, ~22 s CPU). Here the
xdist controller compiles them once, the sim and the vision kernels in two processes side by
side, while the workers collect; the workers' first test waits for it (``wait``). With a warm
cache the two processes only load the kernels. A failed warm-up is one line on stderr and no
more: the tests then compile as they go, as before.

``python -m tests.numba_warm sim|vision`` is one half of the warm-up.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from tests.waiting import wait_until

REPO = Path(__file__).resolve().parent.parent
ENV = "DRUMTWIN_NUMBA_WARM_LOCK"  # the lock file the controller holds while it compiles
PARTS = ("sim", "vision")
TIMEOUT_S = 600.0
_procs: list[subprocess.Popen] = []  # the controller's warm-up processes


def start() -> None:
    """In the xdist controller, before the workers start: hold the lock, compile in two
    processes, release the lock when both have ended."""
    fd, path = tempfile.mkstemp(prefix="drumtwin-numba-warm-", suffix=".lock")
    fcntl.flock(fd, fcntl.LOCK_EX)  # before any worker exists: each of them waits for it
    os.environ[ENV] = path  # the workers inherit the controller's environment
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    _procs[:] = procs = [subprocess.Popen([sys.executable, "-m", "tests.numba_warm", part], cwd=REPO, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for part in PARTS]

    def finish() -> None:
        try:
            for part, p in zip(PARTS, procs, strict=True):
                try:
                    _, err = p.communicate(timeout=TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    p.kill()
                    _, err = p.communicate()
                if p.returncode != 0:
                    last = (err or "").strip().splitlines()[-1:] or ["no output"]
                    sys.stderr.write(f"numba warm-up ({part}) failed, exit {p.returncode}: {last[0]} "
                                     "(the tests compile their kernels themselves)\n")
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
            Path(path).unlink(missing_ok=True)

    threading.Thread(target=finish, name="numba-warm-up", daemon=True).start()


def stop() -> None:
    """In the controller at its end: a warm-up still running (``--collect-only``, a failed
    start of the workers) is ended, not left behind."""
    for p in _procs:
        if p.poll() is None:
            p.kill()
            p.wait(10)


def wait() -> None:
    """In a worker: return once the controller's warm-up has ended (at once when there is none)."""
    path = os.environ.get(ENV)
    if not path:
        return
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:  # already finished and removed
        return
    def released() -> bool:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            return False

    try:
        wait_until(released, TIMEOUT_S, "the numba warm-up", poll_s=0.1)
    except AssertionError:
        pass  # a warm-up that hangs: the tests compile as they go
    finally:
        os.close(fd)


def warm_sim() -> None:
    """The DEM's and the pymunk twin's kernels, through the twins' own steps."""
    from sim.engine import make_twin
    from sim.mixer import paper_mixer

    for engine in ("dem", "pymunk"):
        twin = make_twin(paper_mixer(), engine, case="C", seed=0, rpm=5.0, settle_s=0.05)
        twin.advance(0.05)


def warm_vision() -> None:
    """The meter's kernels (moments, bed surface), through ``drumtwin mi`` of a synthetic drum,
    then the light tracking's (``warm_light``)."""
    import cv2

    from tests.cli import cli
    from vision.synthetic import drum_frame

    with tempfile.TemporaryDirectory() as d:
        img = Path(d) / "drum.png"
        cv2.imwrite(str(img), drum_frame((320, 320), mix=0.5, seed=1))
        r = cli("mi", img)
        if r.code != 0:
            raise SystemExit(f"drumtwin mi: exit {r.code}: {r.err.strip()[-300:]}")
    warm_light()


def warm_light() -> None:
    """The colour table's and the light tracking's kernels (vision.colours, vision.photometric,
    vision.moments.remapped_tables): classes learned on a synthetic drum (``suggest_classes``
    stores a light reference), frames measured with them (the meter tracks the light), the last
    in brighter light (the class table re-baked for it). ``drumtwin mi`` with its default
    classes has no light reference."""
    from vision.suggest import suggest_classes
    from vision.synthetic import light_change, particle_drum

    scenes = [particle_drum((400, 300), mix=m, seed=i, particle_r_frac=0.045) for i, m in enumerate((0.2, 0.8))]
    meter = suggest_classes([scenes[0].image], per_frame=2500).make_meter()
    for img in (scenes[0].image, scenes[1].image, light_change(scenes[1].image, 1.3)):
        meter.measure(img)


if __name__ == "__main__":
    {"sim": warm_sim, "vision": warm_vision}[sys.argv[1]]()

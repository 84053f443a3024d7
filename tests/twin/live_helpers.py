"""What the whole-loop tests share (tests/twin/test_live_*.py, test_live_modbus.py): the "live" xdist
group, the console script, the demo's speed, AUTO tuned to act within seconds with a stand-in what-if
study, a free port and a short synthetic video."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from twin.run.settings import Seams

# The whole-loop runs are heavy (a demo with its plant twin, vision and twin workers): under
# pytest-xdist they share one worker, one after another, while the other worker runs the rest
# (two groups of loops at once on the two cores made the loops' timing flaky in CI: one loop at a time).
# (the option checks run anywhere: only the tests marked @LIVE share the worker)
LIVE = pytest.mark.xdist_group("live")

DRUMTWIN = [str(Path(sys.executable).parent / "drumtwin")]
SPEED = 4.0


class Predicted:
    """A stand-in what-if result: the twin 'predicts' MI = rpm / 100 (faster is better)."""

    def __init__(self, rpm: float) -> None:
        self.plateau_mi = rpm / 100.0
        self.t_s, self.mi, self.regime = [0.0, 1.0], [0.9, rpm / 100.0], "cascading"


def predict(jobs):
    """The stand-in what-if study: one :class:`Predicted` per job."""
    return [Predicted(j.rpm) for j in jobs]


# AUTO acts within seconds in the smoke run: a bed at MI ~0.9 counts as segregated, the
# what-if study is a stand-in (the real one is tested in tests/sim), at most 15 rpm (the plant
# stays cheap to simulate). The twin's calibration is the product's (FULL_CALIBRATION): a
# "cheap" one (0.5 s spin-up, a 1 s window) measures a bed still spinning up, lands on the
# frictions' upper bounds, and the twin it makes stands at 55-70 deg against the camera's 33:
# on a loaded machine it finished before AUTO's first decision, the twin mismatch alarm put the
# supervisor in its safe hold for the rest of the run, and no decision came.
FULL_CALIBRATION: dict = {}
QUICK_AUTO = Seams(
    supervisor={"seg_level": 0.99, "clear_level": 0.995, "detect_dwell_s": 2.0, "prediction_wait_s": 20.0,
                "min_change_interval_s": 60.0},
    limits={"max_rpm": 15.0},
    calibrate=FULL_CALIBRATION,
    whatif_study=predict,
)


def col(rows: list[dict], name: str) -> np.ndarray:
    """Column ``name`` of run-log frame rows as floats (None: NaN)."""
    return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)


def free_port() -> int:
    """A TCP port of 127.0.0.1 that nothing listens on (free when closed)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def synthetic_video(path: Path, n: int = 30, size: int = 64, drum: bool = True) -> Path:
    """A short synthetic video: an empty drum (the meter finds the drum and no valid MI in
    it) or, ``drum=False``, grey noise (no drum to find: bad input)."""
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (size, size))
    rng = np.random.default_rng(0)
    for _ in range(n):
        if drum:
            img = np.full((size, size, 3), 18, np.uint8)
            cv2.circle(img, (size // 2, size // 2), int(0.46 * size), (150, 150, 150), 2, cv2.LINE_AA)
        else:
            img = rng.integers(90, 110, (size, size, 3), dtype=np.uint8)
        vw.write(img)
    vw.release()
    return path

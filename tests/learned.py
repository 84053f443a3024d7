"""``suggest_classes`` memoised for the tests: learning the classes from the 27 real frames takes
~30 s and several test files need the same result, so it is learned once per key and kept.

The key is everything the result depends on: the frames' pixels (shape, dtype, bytes), every
argument, whether the frames came as a list or a stream, and the code version (the source of
every module under ``vision/``, which ``suggest_classes`` may import from; the DESIGN's
dependency rule keeps vision free of the other packages) with the numpy, OpenCV and Python
versions (and mutmut's mutant under test). A change to any of them is a new key, so a stale
result is never returned. Results are kept in the process and as pickles under pytest's
cache dir (``.pytest_cache/d/drumtwin-learned``, shared by the xdist workers: a lock file makes
the second worker wait for the first instead of learning the same classes again). Each call
returns a fresh copy."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import pickle
import sys
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

import vision.suggest
from vision.config import MeterConfig

REPO = Path(__file__).resolve().parent.parent
CACHE_VERSION = "1"  # bump when this file changes what it stores
cache_dir: Path | None = None  # set by tests/conftest.py (pytest's cache dir); None: this process only
_memory: dict[str, bytes] = {}
_real = vision.suggest.suggest_classes
calls = {"learned": 0, "reused": 0}  # what the memo did in this process (a test checks it)


def code_version() -> str:
    """Hash of every vision/ source file and the numeric libraries' versions."""
    # (mutmut's trampolined copy holds every mutant and picks one by this variable)
    mutant = os.environ.get("MUTANT_UNDER_TEST", "")
    h = hashlib.sha256(f"{CACHE_VERSION}|{mutant}|{sys.version}|{np.__version__}|{cv2.__version__}".encode())
    for p in sorted((REPO / "vision").rglob("*.py")):
        h.update(str(p.relative_to(REPO)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def _key(frames: Sequence[np.ndarray], kind: str, args: dict[str, Any]) -> str:
    h = hashlib.sha256(code_version().encode())
    h.update(f"{kind}|{sorted(args.items())!r}".encode())  # ROIs and every option, by value
    for f in frames:
        a = np.ascontiguousarray(f)
        h.update(f"{a.shape}|{a.dtype}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def learn(frames: Iterable[np.ndarray] | np.ndarray, roi: Any = None, k: int = 2, seed: int = 0,
          per_frame: int | None = None, rois: Sequence[Any] | None = None,
          camera_rotation_deg: float | None = None, mirror: bool = False,
          n_frames: int | None = None) -> MeterConfig:
    """``vision.suggest.suggest_classes`` with the same arguments and result, learned once per key.

    A stream is read to its end first (its side effects, e.g. the CLI's ROI list, happen as
    before) and handed on as a stream, so ``n_frames`` keeps its meaning."""
    if isinstance(frames, np.ndarray):
        kind, items = "array", [frames]
    elif isinstance(frames, Sequence):
        kind, items = "frames", list(frames)
    else:
        kind, items = "stream", list(frames)
    args = {"roi": roi, "k": k, "seed": seed, "per_frame": per_frame,
            "rois": None if rois is None else list(rois), "camera_rotation_deg": camera_rotation_deg,
            "mirror": mirror, "n_frames": n_frames}

    def compute() -> MeterConfig:
        given: Any = frames if kind == "array" else (items if kind == "frames" else iter(items))
        calls["learned"] += 1
        return _real(given, roi, k=k, seed=seed, per_frame=per_frame, rois=rois,
                     camera_rotation_deg=camera_rotation_deg, mirror=mirror, n_frames=n_frames)

    key = _key(items, kind, args)
    if key in _memory:
        calls["reused"] += 1
        return pickle.loads(_memory[key])
    if cache_dir is None:
        blob = pickle.dumps(compute())
    else:
        path = cache_dir / f"{key}.pickle"
        with open(cache_dir / f"{key}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # the other worker learns it meanwhile: wait, then read
            try:
                if path.exists():
                    blob = path.read_bytes()
                    calls["reused"] += 1
                else:
                    blob = pickle.dumps(compute())
                    tmp = path.with_suffix(f".{os.getpid()}.tmp")
                    tmp.write_bytes(blob)
                    tmp.replace(path)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
    _memory[key] = blob
    return pickle.loads(blob)


@contextlib.contextmanager
def memoised_learning() -> Iterator[None]:
    """Within the block, ``vision.suggest.suggest_classes`` is :func:`learn` (for code that
    imports it at call time: the CLI commands, ``real_frame_mi``)."""
    vision.suggest.suggest_classes = learn  # type: ignore[assignment]
    try:
        yield
    finally:
        vision.suggest.suggest_classes = _real

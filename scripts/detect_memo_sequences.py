"""``vision.roi.detect_drum`` with its memo against ``_detect`` without it, on 81-frame sequences made
of the real frames of tests/data (looped; a light drift, steps, glitches, a warm cast) and of synthetic
frames: ms per frame each way and whether both give the same drum. Numbers in docs/mutation.md
("Suite time, fifth pass"). Run: ``OPENCV_FOR_THREADS_NUM=1 .venv/bin/python scripts/detect_memo_sequences.py``."""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

import vision.roi as roi
from vision.errors import VisionError
from vision.synthetic import drum_frame

N = 81


def gain(img: np.ndarray, g: float | np.ndarray) -> np.ndarray:
    return np.clip(img.astype(np.float32) * g, 0, 255).astype(np.uint8)


def looped(frames: list[np.ndarray]) -> list[np.ndarray]:
    return [frames[i % len(frames)] for i in range(N)]


def sequences() -> dict[str, list[np.ndarray]]:
    real = [cv2.imread(str(p)) for p in sorted(Path("tests/data/real-drum-pmma/images").glob("*.jpg"))]
    syn = [drum_frame(mix=m, seed=i) for i, m in enumerate(np.linspace(0.0, 1.0, 27))]
    warm = [np.array([1 - 0.15 * i / (N - 1), 1.0, 1 + 0.15 * i / (N - 1)]) for i in range(N)]
    return {
        "real steady (27 looped)": looped(real),
        "real drift x0.8 -> x1.2": [gain(f, 0.8 + 0.4 * i / (N - 1)) for i, f in enumerate(looped(real))],
        "real steps x1, x0.8, x1.15": [gain(f, (1.0, 0.8, 1.15)[i // 27]) for i, f in enumerate(looped(real))],
        "real x1.5 glitch every 9th": [gain(f, 1.5) if i % 9 == 8 else f for i, f in enumerate(looped(real))],
        "real warm cast drifting in": [gain(f, w) for f, w in zip(looped(real), warm, strict=True)],
        "synthetic steady (27 looped)": looped(syn),
        "synthetic x1.5 glitch every 9th": [gain(f, 1.5) if i % 9 == 8 else f for i, f in enumerate(looped(syn))],
    }


def detect_all(frames: list[np.ndarray], memo: bool) -> tuple[list[object], float]:
    """Each frame's drum (or its error) and the ms per frame."""
    out: list[object] = []
    t = time.perf_counter()
    for f in frames:
        try:
            out.append(roi.detect_drum(f) if memo else roi._detect(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY), 0.025))
        except VisionError as exc:
            out.append(str(exc))
    return out, (time.perf_counter() - t) / len(frames) * 1e3


def main() -> None:
    print(f"{'sequence':34s} {'frames':>6s} {'distinct':>8s} {'memo ms':>8s} {'no memo':>8s} {'same drum':>9s}")
    for name, frames in sequences().items():
        roi._memo.clear()
        a, t_memo = detect_all(frames, memo=True)
        b, t_plain = detect_all(frames, memo=False)
        distinct = len({f.tobytes() for f in frames})
        same = sum(x == y for x, y in zip(a, b, strict=True))
        print(f"{name:34s} {len(frames):6d} {distinct:8d} {t_memo:8.1f} {t_plain:8.1f} {same:6d}/{len(frames)}")


if __name__ == "__main__":
    main()

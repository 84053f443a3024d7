"""``drumtwin mi SOURCE --endpoint --json`` on recorded videos (issue 24): a real video made
from the PMMA frames of tests/data (segregated 0002, then the mixed frames), an
all-segregated one, and a synthetic one. The mp4 files are written here with OpenCV."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli import assert_one_line_error, cli
from twin.run.settings import trend_config

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "pmma-blue-white.toml"
FPS = 20  # >= 14 fps: the trend's re-init needs 8 samples in its 0.6 s window
SIZE = 320  # the 640x640 frames at half size: the same bed, a quarter of the pixels to measure
SEG_S = 4.0


def write_video(path: Path, frames: list[np.ndarray], fps: float = FPS) -> Path:
    h, w = frames[0].shape[:2]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (w, h))
    assert vw.isOpened()
    for f in frames:
        vw.write(f)
    vw.release()
    return path


@pytest.fixture(scope="module")
def real_frames(real_drum_dir):
    def load(p: Path) -> np.ndarray:
        return cv2.resize(cv2.imread(str(p)), (SIZE, SIZE), interpolation=cv2.INTER_AREA)

    imgs = sorted((real_drum_dir / "images").glob("*.jpg"))
    seg = load(imgs[0])
    mixed = [load(p) for p in imgs if p.stem >= "0013"]  # 0005, 0008: mix in progress; 0013 on: mixed
    assert imgs[0].stem == "0002" and len(mixed) >= 20
    return seg, mixed


def mi_json(video: Path, *extra: object) -> dict:
    r = cli("mi", video, "--config", CONFIG, "--endpoint", "--json", *extra)
    assert r.code == 0, r.err
    return json.loads(r.out)  # stdout is the JSON alone (no CSV)


def test_real_video_mixing_time_at_the_segregated_to_mixed_transition(real_frames, tmp_path):
    seg, mixed = real_frames
    n_seg, n_mix = int(SEG_S * FPS), 14 * FPS
    video = write_video(tmp_path / "real.mp4", [seg] * n_seg + [mixed[i % len(mixed)] for i in range(n_mix)])
    out = mi_json(video)
    assert out["frames"] == n_seg + n_mix and out["valid"] == out["frames"]
    assert out["mi_first"] < 0.5 < 0.9 < out["mi_median"]
    tc = trend_config()
    lag_s = tc.reinit_window_s + tc.settle_s  # re-init on the new level, then settle_s of accepted frames
    mt = out["mixing_time_s"]
    assert mt is not None and SEG_S <= mt <= SEG_S + lag_s + 0.2, (mt, lag_s)
    assert out["plateau_mi"] > 0.9 and [c["kind"] for c in out["endpoint_changes"]] == ["mixed"]
    assert out["endpoint"]["target_mi"] == 0.9


def test_real_all_segregated_video_never_mixes(real_frames, tmp_path):
    seg, _ = real_frames
    video = write_video(tmp_path / "seg.mp4", [seg] * (14 * FPS))
    out = mi_json(video)
    assert out["mixing_time_s"] is None and out["plateau_mi"] is None and out["endpoint_changes"] == []
    assert out["mi_max"] < 0.5
    # the same flat bed with a target below it: the plateau is found (the target is what says "segregated")
    low = mi_json(video, "--target-mi", 0.3)
    assert low["mixing_time_s"] is not None and low["mixing_time_s"] <= 2.0


def test_synthetic_video_mixes_where_the_frames_do(tmp_path):
    from vision.synthetic import drum_frame

    seg = [drum_frame((320, 240), mix=0.0, seed=i) for i in range(3)]
    mixed = [drum_frame((320, 240), mix=1.0, seed=i) for i in range(3)]
    frames = [seg[i % 3] for i in range(5 * FPS)] + [mixed[i % 3] for i in range(13 * FPS)]
    r = cli("mi", write_video(tmp_path / "syn.mp4", frames), "--endpoint", "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["mixing_time_s"] is not None and 5.0 <= out["mixing_time_s"] <= 7.5


ODD_FPS = 13  # one frame in 26: one every 2 s; the block (5 s) holds 65 frames, 2-3 of them odd
ODD_EVERY = 26


@pytest.fixture(scope="module")
def both_sets_by_mi(real_drum_dir):
    """Every real frame of the run (the blue-labelled and the white-labelled set, 42) at half size with
    its MI through the project's meter (``CONFIG``), in time order."""
    from vision.config import load_config

    meter = load_config(CONFIG).make_meter()
    files = sorted([*(real_drum_dir / "images").glob("*.jpg"),
                    *(real_drum_dir.parent / "real-drum-pmma-white" / "images").glob("*.jpg")], key=lambda p: p.stem)
    out = []
    for p in files:
        img = cv2.resize(cv2.imread(str(p)), (SIZE, SIZE), interpolation=cv2.INTER_AREA)
        r = meter.measure(img)
        assert r.valid, p
        out.append((p, img, float(r.mi)))
    assert len(out) == 42
    return out


@pytest.mark.parametrize("segregated", ["real-drum-pmma/images/0002.jpg", "real-drum-pmma-white/images/0001.jpg"])
def test_one_partly_mixed_frame_in_26_does_not_keep_a_real_batch_from_mixing(both_sets_by_mi, tmp_path, segregated):
    """Issue 38, item 3: 5 s of the real segregated frame, then the real mixed frames (MI >= 0.93)
    with one frame in 26 replaced by the real frame of a partly mixed bed (the frame whose MI is
    nearest 0.56). The block's sample sd counted those frames (0.08 > 0.05: the batch never
    mixed, although the trend sat at 0.97); the robust block sd does not, and the mixing time is
    still at the segregated -> mixed transition (5-8 s)."""
    seg = next(img for p, img, _ in both_sets_by_mi if p.as_posix().endswith(segregated))
    mixed = [img for _, img, mi in both_sets_by_mi if mi >= 0.93]
    p_odd, odd, mi_odd = min(both_sets_by_mi, key=lambda f: abs(f[2] - 0.56))
    assert 0.45 <= mi_odd <= 0.7 and len(mixed) >= 30, (p_odd, mi_odd)
    n_seg, n_mix = 5 * ODD_FPS, 17 * ODD_FPS
    tail = [odd if i % ODD_EVERY == ODD_EVERY // 2 else mixed[i % len(mixed)] for i in range(n_mix)]
    out = mi_json(write_video(tmp_path / "odd.mp4", [seg] * n_seg + tail, ODD_FPS))
    assert out["frames"] == n_seg + n_mix and out["valid"] == out["frames"]
    assert out["mi_min"] < 0.45 and 0.6 < out["mi_median"]  # the video is what it says
    assert out["mixing_time_s"] is not None and 5.0 <= out["mixing_time_s"] <= 8.0, out["endpoint_changes"]
    assert [c["kind"] for c in out["endpoint_changes"]] == ["mixed"] and out["plateau_mi"] > 0.93


def test_endpoint_bad_target_is_one_line(real_frames, tmp_path):
    seg, _ = real_frames
    video = write_video(tmp_path / "one.mp4", [seg] * 3)
    for bad in ("1.5", "-0.1", "nan"):
        assert_one_line_error(cli("mi", video, "--config", CONFIG, "--endpoint", "--target-mi", bad), "--target-mi")

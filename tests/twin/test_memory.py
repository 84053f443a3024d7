"""Peak memory: ``drumtwin bench memory`` measures a real run and its process tree, and the colour
lookup table built in chunks (for its peak) still equals the pixel classifier."""

from __future__ import annotations

import cv2
import pytest

from tests.cli import assert_one_line_error, cli
from tests.conftest import BENCH_MEMORY_ARGS, BENCHES


@BENCHES
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_bench_memory_measures_the_run_and_its_process_tree(cli_once) -> None:
    """``drumtwin bench memory --seconds 5 --json``: a real run on a 640x640 video; the tree includes
    the what-if and calibration pool processes, so it is at least the run process itself (the
    session's run, tests/conftest.py: shared with the bad-input sweep's base of ``bench memory``)."""
    import json

    r = cli_once("bench", "memory", *BENCH_MEMORY_ARGS)
    assert r.code == 0, r.err
    d = json.loads(r.out)
    assert d["processes"] >= 2 and 50 < d["main_hwm_mb"] < 2000
    assert d["tree_rss_mb"] >= d["tree_pss_mb"] > 0 and d["tree_rss_mb"] >= d["main_hwm_mb"] * 0.8
    per = d["per_process"]  # each process's own peak: their sum bounds the peak of the sum
    assert "run" in per and len(per) >= 2 and sum(per.values()) >= d["tree_pss_mb"] - 0.5
    assert not any(k == "forkserver" for k in per) or any(k.startswith("worker") for k in per)
    assert_one_line_error(cli("bench", "memory", "--seconds", "1e9"), "--seconds")


def test_chunked_colour_table_equals_the_classifier() -> None:
    """The HSV lookup table is now built in 16 chunks (peak memory): every colour still gets
    the class the pixel classifier gives it."""
    import numpy as np

    from vision.colours import DEFAULT_CLASSES, Classifier, class_lut

    lut = class_lut(DEFAULT_CLASSES)
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (64, 4096, 3), dtype=np.uint8)
    img[0, :256] = [[b, 0, 255] for b in range(256)]  # a chunk border (B = 15/16) is in there too
    h, s, v = cv2.split(cv2.cvtColor(img, cv2.COLOR_BGR2HSV))
    masks = Classifier(DEFAULT_CLASSES).class_masks(h, s, v)
    want = np.zeros(img.shape[:2], np.uint8)
    for k in range(len(masks) - 1, -1, -1):
        want[masks[k] != 0] = k + 1
    idx = (img[..., 0].astype(np.int64) << 16) | (img[..., 1].astype(np.int64) << 8) | img[..., 2]
    assert np.array_equal(lut[idx], want) and want.any()

"""``vision.stream``: frames -> readings, and the one no-drum policy that ``drumtwin mi``, the live
camera worker and ``classes suggest`` share (frame times are given, no clock)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.vision import helpers as H
from vision.errors import VisionError
from vision.meter import Meter
from vision.sources import Frame
from vision.stream import NO_DRUM_GRACE_S, DrumWatch, FrameMeter, readings, with_index

BLACK = np.zeros((480, 640, 3), np.uint8)  # no drum to find


def _frames(images: list[np.ndarray], dt_s: float = 1.0) -> list[Frame]:
    return [Frame(i, i * dt_s, img, f"f{i}.png") for i, img in enumerate(images)]


def test_frames_without_a_drum_are_flagged_rows_until_the_grace_is_over() -> None:
    """A camera warming up: black frames are invalid ``no_drum:`` readings for NO_DRUM_GRACE_S of
    camera time from the first frame; one more without a drum is the end (bad input), naming it."""
    fm = FrameMeter(Meter())
    n_ok = int(NO_DRUM_GRACE_S) + 1  # frames at 0, 1, ..., 5 s: within the grace
    for fr in _frames([BLACK] * n_ok):
        r = fm.measure(fr)
        assert not r.valid and math.isnan(r.mi) and r.flags[0].startswith("no_drum:") and "--roi" in r.flags[0]
    with pytest.raises(VisionError, match=r"no drum in 6 s of camera frames"):
        fm.measure(Frame(n_ok, float(n_ok), BLACK, "late.png"))


def test_once_a_drum_was_found_frames_without_one_stay_flagged_rows() -> None:
    """(The drum is found once per frame size: the later blank frames are of another size.)"""
    fm = FrameMeter(Meter())
    got = [fm.measure(fr) for fr in _frames([BLACK, H.half_disks(), *[np.zeros((300, 400, 3), np.uint8)] * 10])]
    assert [r.valid for r in got[:2]] == [False, True] and fm.measured == 1
    assert all(r.flags[0].startswith("no_drum:") for r in got[2:])  # flagged long after the grace
    fm.finish()  # a drum was seen: the stream was good input


def test_unreadable_frames_are_bad_frame_rows_and_the_end_says_what_the_source_lacked() -> None:
    gray = np.zeros((480, 640), np.uint8)
    fm = FrameMeter(Meter())
    bad = [fm.measure(Frame(0, 0.0, np.zeros((0, 0, 3), np.uint8), "a.jpg", "cannot decode image a.jpg")),
           fm.measure(Frame(1, 0.1, gray, "b.png"))]
    assert [r.flags for r in bad] == [("bad_frame:cannot decode image a.jpg",),
                                      ("bad_frame:b.png is a grayscale image; the mixing index needs colour frames",)]
    fm.finish()  # a run's camera giving only these: lost vision (the supervisor's), not the drum policy's
    unreadable = [Frame(0, 0.0, np.zeros((0, 0, 3), np.uint8), "a.jpg", "cannot decode image a.jpg"),
                  Frame(1, 0.1, gray, "b.png")]
    with pytest.raises(VisionError, match=r"none of the 2 frames could be read.*decode image a\.jpg"):
        list(readings(unreadable, FrameMeter(Meter())))  # a file's frames: nothing to measure is an error
    with pytest.raises(VisionError, match="gave no frames"):
        list(readings([], FrameMeter(Meter())))
    fm = FrameMeter(Meter())
    fm.measure(Frame(0, 0.0, BLACK, "black.png"))
    with pytest.raises(VisionError, match=r"no drum in any frame \(1 without one; the first, black.png: .*--roi"):
        fm.finish()


def test_readings_yields_each_frame_with_its_reading_then_applies_the_policy() -> None:
    frames = _frames([H.half_disks(), H.fine_mix(), H.half_disks()], dt_s=0.1)
    got = list(readings(frames, FrameMeter(Meter())))
    assert [f.index for f, _ in got] == [0, 1, 2] and got[1][1].mi > 0.9 > 0.1 > got[0][1].mi
    assert len(list(readings(frames, FrameMeter(Meter()), max_frames=2))) == 2
    with pytest.raises(VisionError, match="no drum in any frame"):  # raised when the source ends
        list(readings(_frames([BLACK] * 2), FrameMeter(Meter())))


def test_a_watch_without_a_time_limit_only_judges_at_the_end() -> None:
    """``classes suggest`` picks frames across a whole source: it leaves out frames without a
    drum however far apart they are, and fails only when none had one."""
    w = DrumWatch(grace_s=math.inf)
    for t in (0.0, 100.0, 1e6):
        assert w.missed(t, f"f{t:g}.png", VisionError("could not find the drum")) == "no_drum:could not find the drum"
    with pytest.raises(VisionError, match=r"3 without one; the first, f0\.png"):
        w.finish()
    w.found()
    w.finish()


def test_with_index_puts_a_baseline_in_place_of_the_centroid_mi() -> None:
    img, _ = H.tilted_bed(25.0, 0.4)
    r = Meter().measure(img)
    b = with_index(r, 0.42)
    assert b.mi == 0.42 and b.valid and b.slope_deg == r.slope_deg == pytest.approx(25.0, abs=2.0)
    assert b.classes == r.classes and b.roi == r.roi
    assert all(math.isnan(v) for v in (b.mi_sigmoid, b.mi_linear, b.d_px, b.dsigma_px))
    assert not with_index(r, math.nan).valid

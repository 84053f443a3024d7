"""The live loop's process and camera workers with fakes (tests/twin/workers_fakes.py): the frame row
and its columns, the trend, impossible MIs and frame times, a camera clock that jumps back, dropped
readings (milliseconds; no threads, no sim, no serial)."""

from __future__ import annotations

import math
import queue
import threading
from dataclasses import fields

import numpy as np
import pytest

from control.decision import Mode
from control.trend import MITrend
from tests.twin.test_mill_worker import Sink
from tests.twin.workers_fakes import Boxes, reading, sup_worker
from twin.live.camera import CameraReading, CameraWorker, ProcessWorker, put_dropping_oldest
from twin.live.snapshots import CameraInfo, Latest
from twin.state import FRAME_ROW_COLUMNS, SERIES, FrameRow, LiveState


def test_frame_row_defines_the_csv_columns_and_plot_series() -> None:
    from twin.records import FRAME_COLUMNS, FrameReading
    from twin.runlog import FRAME_COLUMNS as RUNLOG_COLUMNS

    names = [f.name for f in fields(FrameRow)]
    assert FrameRow is FrameReading and FRAME_ROW_COLUMNS is FRAME_COLUMNS is RUNLOG_COLUMNS
    assert list(FRAME_COLUMNS) == [names[0], "wall_s", *names[1:]] and set(SERIES) <= set(names)


def test_process_worker_rows_trend_moving_average_and_slopes() -> None:
    b = Boxes("auto")
    b.mill_at(5.0)
    slopes: queue.SimpleQueue = queue.SimpleQueue()
    state = LiveState()
    sink = Sink(state)
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink, slopes, ma_window=2)
    pw.process(CameraReading(0.0, 0, reading(0.8)))
    pw.process(CameraReading(0.1, 1, reading(0.6)))
    pw.process(CameraReading(0.2, 2, reading(math.nan, valid=False)))
    f = b.frames.get()
    rows = sink.rows()
    assert f.n_frames == 3 and f.last_valid_t_s == 0.1 and f.t_s == 0.2
    assert [r["ma_mi"] for r in rows] == pytest.approx([0.8, 0.7, 0.7])  # the NaN frame is skipped
    assert rows[0]["rpm_actual"] == 5.0 and rows[0]["mode"] == "auto" and rows[0]["twin_mi"] is None
    assert slopes.qsize() == 2
    assert list(rows[0]) == [c for c in FRAME_ROW_COLUMNS if c != "wall_s"]
    assert state.snapshot().history["mi"].size == 3


@pytest.mark.parametrize("bad_mi", [math.nan, math.inf, -math.inf, 1.5, -0.2])
def test_a_reading_flagged_valid_with_an_impossible_mi_is_not_vision(bad_mi: float) -> None:
    """A reading that says valid but carries NaN, inf or an MI outside [0, 1] kept the vision
    timeout fed (AUTO never went safe) or dragged the trend; and an invalid reading's MI
    reached the trend. Now both count as no valid MI: AUTO goes safe with the vision alarm."""
    b = Boxes("auto")
    b.mill_at(5.0)
    slopes: queue.SimpleQueue = queue.SimpleQueue()
    frames_sink = Sink()
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, frames_sink, slopes)
    w, sink, _sent = sup_worker(b, Mode.AUTO)
    t = 0.0
    for i in range(40):  # 4 s of good frames, then 10 s of impossible ones
        b.camera.set(CameraInfo(t, b.wall.t, None, None, i + 1, False))
        pw.process(CameraReading(t, i, reading(0.9)))
        w.tick(b.view.now_s())
        t, b.wall.t = t + 0.1, b.wall.t + 0.1
    for i in range(40, 140):
        b.camera.set(CameraInfo(t, b.wall.t, None, None, i + 1, False))
        pw.process(CameraReading(t, i, reading(bad_mi)))
        pw.process(CameraReading(t + 0.05, i, reading(0.1, valid=False)))
        w.tick(b.view.now_s())
        t, b.wall.t = t + 0.1, b.wall.t + 0.1
    f = b.frames.get()
    assert f.last_valid_t_s == pytest.approx(3.9) and f.estimate.level == pytest.approx(0.9, abs=0.02)
    rows = frames_sink.rows()
    assert slopes.qsize() == 40 and rows[-1]["valid"] is False and rows[-2]["valid"] is False
    assert "vision_lost" in sink.faults and w.safe


def test_a_frame_time_that_goes_back_or_is_not_a_number_is_dropped_with_a_fault() -> None:
    """A camera clock that jumps back (or a NaN frame time) raised in the Kalman trend and
    killed the process thread: no more rows, no more trend. Now the frame is dropped with a
    ``camera_clock`` fault, cleared when frames come in order again."""
    b = Boxes("manual")
    b.mill_at(5.0)
    sink = Sink()
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink)
    for i, t in enumerate((1.0, 1.1, 1.2)):
        pw.process(CameraReading(t, i, reading(0.9)))
    assert pw.process(CameraReading(0.5, 3, reading(0.9))) is None  # back in time
    assert pw.process(CameraReading(math.nan, 4, reading(0.9))) is None
    assert len(sink.rows()) == 3 and b.frames.get().t_s == 1.2 and b.frames.get().n_frames == 3
    assert "camera_clock" in sink.faults
    pw.process(CameraReading(1.2, 5, reading(0.8)))  # in order again (the same time is fine)
    pw.process(CameraReading(1.3, 6, reading(0.8)))
    assert len(sink.rows()) == 5 and b.frames.get().t_s == 1.3 and "camera_clock" not in sink.faults


def test_a_camera_clock_that_jumps_back_is_lost_vision_for_auto() -> None:
    """The camera's frame times jump 10 s back. Run time used to stand still until they
    caught up again (the view never goes back) while every frame was refused: AUTO saw
    neither a stopped camera nor lost vision. Now frames from the past do not count as
    frames: run time goes on, the vision alarm and the safe state come."""
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return reading(0.9)

    b = Boxes("auto")
    b.mill_at(5.0)
    q: queue.Queue = queue.Queue()
    sink = Sink()
    pw = ProcessWorker(q, MITrend(), b.frames, b.view, sink)
    w, _sink, sent = sup_worker(b, Mode.AUTO)
    w.sink = sink
    img = np.zeros((4, 4, 3), np.uint8)
    seen: list[float] = []

    def frames():
        t = 0.0
        for i in range(200):
            if i == 100:
                t -= 10.0  # the camera's clock jumps back
            b.wall.t += 0.1
            yield Frame(index=i, t_s=t, image=img)
            t += 0.1
            while not q.empty():
                pw.process(q.get_nowait())
            seen.append(b.view.now_s())
            w.tick(seen[-1])

    CameraWorker(frames(), Meter(), q, b.camera, LiveState(), monotonic=b.wall).run(threading.Event())
    assert seen[-1] == pytest.approx(19.9, abs=0.05)  # run time went on through the jump
    assert {"camera_clock", "vision_lost", "camera_stopped"} <= sink.faults and w.safe and sent == []


def test_camera_worker_never_blocks_and_marks_the_end() -> None:
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return reading(0.9)

    q: queue.Queue = queue.Queue(maxsize=3)
    box: Latest[CameraInfo] = Latest(CameraInfo())
    frames = [Frame(index=i, t_s=i * 0.1, image=np.zeros((4, 4, 3), np.uint8)) for i in range(10)]
    cw = CameraWorker(frames, Meter(), q, box, LiveState())
    cw.run(threading.Event())
    assert box.get().ended and box.get().n_frames == 10 and box.get().t_s == pytest.approx(0.9)
    assert [q.get_nowait().frame for _ in range(3)] == [7, 8, 9]  # the oldest were dropped
    put_dropping_oldest(q, 1)
    assert q.qsize() == 1


def test_readings_the_camera_drops_are_counted_in_the_frame_rows() -> None:
    """The camera drops the oldest readings when the process worker is behind (a bounded queue:
    memory stays flat on a loaded machine); they were dropped silently, now every one is counted
    in the ``frames_dropped:N`` flag of the next row."""
    from vision.sources import Frame

    class Meter:
        def measure(self, image):
            return reading(0.9)

    q: queue.Queue = queue.Queue(maxsize=3)
    b = Boxes("auto")
    b.mill_at(5.0)
    frames = [Frame(index=i, t_s=i * 0.1, image=np.zeros((4, 4, 3), np.uint8)) for i in range(10)]
    cw = CameraWorker(frames, Meter(), q, b.camera, LiveState())
    cw.run(threading.Event())
    assert cw.dropped == 7 and q.qsize() == 3
    sink = Sink(LiveState())
    pw = ProcessWorker(q, MITrend(), b.frames, b.view, sink)
    while not q.empty():
        pw.process(q.get_nowait())
    flags = [row["flags"] for row in sink.rows()]
    counts = [int(f.split(":")[1]) for fl in flags for f in fl if f.startswith("frames_dropped:")]
    assert sum(counts) == 7 and len(flags) == 3
    pw.process(CameraReading(1.0, 10, reading(0.9), dropped_total=7))  # nothing new dropped: no flag
    assert not any(f.startswith("frames_dropped") for f in sink.rows()[-1]["flags"])

"""The endpoint in the live workers (issue 24), with the workers' own fakes: the process
worker feeds the detector and emits ``mixed``/``unmixed`` with the frame row's columns; the
supervisor worker turns AUTO's endpoint decision into a stop of the mill, and OFF/MANUAL
only see the columns."""

from __future__ import annotations

import queue
from collections.abc import Mapping
from typing import Any

import pytest

from control.endpoint import EndpointConfig, EndpointDetector
from control.supervisor import Mode
from control.trend import MITrend
from tests.twin.test_mill_worker import Sink
from tests.twin.workers_fakes import Boxes, reading, sup_worker
from twin.live.camera import CameraReading, ProcessWorker
from twin.live.commands import StopMill
from twin.state import LiveState

FPS = 30.0


def feed(pw: ProcessWorker, b: Boxes, t0: float, t1: float, mi: float) -> None:
    i = int(t0 * FPS)
    while i / FPS < t1 - 1e-9:
        b.wall.t += 1 / FPS
        pw.process(CameraReading(i / FPS, i, reading(mi)))
        i += 1


class Rows:
    """The frame rows the worker published (``Sink.rows``), read at each use."""

    def __init__(self, sink: Sink) -> None:
        self.sink = sink

    def __getitem__(self, i: int) -> Mapping[str, Any]:
        return self.sink.rows()[i]


def process_worker(b: Boxes) -> tuple[ProcessWorker, Sink, Rows]:
    sink = Sink(LiveState())
    det = EndpointDetector(EndpointConfig(target_mi=0.9, dwell_s=5.0, exit_dwell_s=2.0))
    pw = ProcessWorker(queue.Queue(), MITrend(), b.frames, b.view, sink, endpoint=det)
    return pw, sink, Rows(sink)


def test_process_worker_emits_mixed_and_unmixed_with_the_frame_columns():
    b = Boxes("off")
    b.mill_at(20.0)
    pw, sink, rows = process_worker(b)
    feed(pw, b, 0.0, 3.0, 0.5)  # segregated
    feed(pw, b, 3.0, 15.0, 0.95)  # mixed from 3 s
    mixed = sink.kinds("mixed")
    assert len(mixed) == 1 and 3.0 <= mixed[0]["mixing_time_s"] <= 3.0 + 0.6 + 1.0 + 0.1
    assert mixed[0]["plateau_mi"] == pytest.approx(0.95, abs=0.01) and "target 0.9" in mixed[0]["reason"]
    f = b.frames.get()
    assert f.mixed and f.mixing_time_s == mixed[0]["mixing_time_s"]
    assert sink.state is not None and sink.state.panel.mixed  # the dashboard's banner (twin.state.Panel)
    assert rows[-1]["mixed"] is True and rows[-1]["mixing_time_s"] == f.mixing_time_s
    assert rows[0]["mixed"] is False and rows[0]["mixing_time_s"] is None
    feed(pw, b, 15.0, 20.0, 0.6)  # falls off the plateau for longer than the exit dwell
    assert len(sink.kinds("unmixed")) == 1 and not b.frames.get().mixed and rows[-1]["mixing_time_s"] is None


@pytest.mark.parametrize("mode", [Mode.AUTO, Mode.MANUAL, Mode.OFF])
def test_only_auto_stops_the_mill_at_the_endpoint(mode):
    b = Boxes(mode.value)
    b.mill_at(20.0)
    pw, _, _ = process_worker(b)
    w, sink, sent = sup_worker(b, mode, stop_at_endpoint=True, seg_level=0.4, clear_level=0.45)
    if mode is Mode.MANUAL:
        w.supervisor.set_manual_rpm(20.0)
    t = 0.0
    while t < 12.0:  # mixed bed from the start: mixed after settle + 5 s dwell
        feed(pw, b, t, t + 0.5, 0.95)
        t += 0.5
        w.tick(b.view.now_s())
    assert b.frames.get().mixed
    stops = [c for c in sent if isinstance(c, StopMill)]
    decisions = [d for d in sink.kinds("decision") if d["decision"] == "endpoint"]
    if mode is Mode.AUTO:
        assert stops == [StopMill(source="supervisor")] and len(decisions) == 1
        assert decisions[0]["action"] == "stop" and "stop at endpoint" in decisions[0]["reason"]
        assert decisions[0]["inputs"]["mixed"] is True
    else:
        assert stops == [] and decisions == []

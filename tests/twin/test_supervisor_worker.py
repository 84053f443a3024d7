"""The live loop's supervisor worker with fakes (tests/twin/workers_fakes.py): hands off in OFF, the
safe state with its alarms, the mill epoch, requests and results, mode commands, the run view's time,
and the root's controls as typed commands (milliseconds; no threads, no sim, no serial)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from control.decision import Mode, PredictionResult
from control.protocol import MillStatus
from control.supervisor import Supervisor
from tests.twin.test_mill_worker import FakeLink, Sink
from tests.twin.workers_fakes import Boxes, FakePredictions, advance, sup_worker
from twin.live.commands import Recalibrate, Reseed, SetManualRpm, SetMode, SetRpm, StopMill
from twin.live.supervise import SupervisorWorker


def test_off_is_hands_off_whatever_it_sees() -> None:
    b = Boxes("off")
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.OFF)
    advance(b, w, 0, 30, level=0.1)  # badly segregated
    b.mill_at(5.0, connected=False)
    advance(b, w, 30, 40, frames=False)  # link and vision lost
    assert sent == [] and sink.kinds("decision") == []


def test_nothing_is_decided_before_the_mill_was_read() -> None:
    b = Boxes()
    w, sink, sent = sup_worker(b, Mode.MANUAL)
    w.supervisor.set_manual_rpm(20.0)
    advance(b, w, 0, 5)
    assert sent == [] and sink.events == []


def test_vision_lost_alarm_and_safe_state_come_together() -> None:
    """Defect 4: the loop alarmed at 3 s, the supervisor went safe at 5 s and moved in between."""
    b = Boxes()
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.AUTO)
    advance(b, w, 0, 10)
    for _ in range(12):  # no frames: run time still passes
        b.wall.t += 0.5
        w.tick(b.view.now_s())
        if "vision_lost" in sink.faults:
            break
    assert "vision_lost" in sink.faults and "camera_stopped" in sink.faults
    assert w.safe  # the same tick
    i_alarm = next(i for i, (k, d) in enumerate(sink.events) if k == "fault" and d["fault"] == "vision_lost")
    i_safe = next(i for i, (k, d) in enumerate(sink.events) if k == "decision" and d["safe"])
    assert i_safe > i_alarm and i_safe - i_alarm <= 3 and sent == []


def test_a_twin_that_never_runs_is_stale_for_the_loops_auto() -> None:
    """The twin worker died (or hung) before its first step: the supervisor saw no twin time
    at all and never called it stale, so AUTO went on without it. With the loop's settings a
    twin that has not run within the twin timeout is stale: safe state."""
    from twin.run.settings import supervisor_config

    b = Boxes()
    b.mill_at(5.0)
    cfg = supervisor_config()
    assert cfg.twin_timeout_s is not None
    w = SupervisorWorker(Supervisor(cfg, mode=Mode.AUTO), b.view, Sink(), [].append, None, b.mode)
    advance(b, w, 0, cfg.twin_timeout_s - 1.0)
    assert not w.safe
    advance(b, w, cfg.twin_timeout_s - 1.0, cfg.twin_timeout_s + 2.0)
    assert w.safe and "twin stale" in w.supervisor.safe_reason


def test_camera_end_means_safe_at_once() -> None:
    b = Boxes()
    b.mill_at(5.0)
    w, sink, _sent = sup_worker(b, Mode.AUTO)
    advance(b, w, 0, 4)
    b.camera.set(replace(b.camera.get(), ended=True))
    w.tick(b.view.now_s())
    assert w.safe and "camera_ended" in sink.faults


def test_moving_the_rpm_slider_never_clears_camera_alarms() -> None:
    """Defect 8: set_manual_rpm supervised at the last frame's time and logged a recovery."""
    b = Boxes("manual")
    b.mill_at(5.0)
    w, sink, sent = sup_worker(b, Mode.MANUAL)
    advance(b, w, 0, 5)
    b.wall.t += 10.0  # the camera stalls for 10 s
    w.tick(b.view.now_s())
    assert "camera_stopped" in sink.faults
    for rpm in (8.0, 12.0, 9.0):
        b.wall.t += 1.0  # the ramp interval: each one goes out at once
        w.handle(SetManualRpm(rpm))
    assert "camera_stopped" in sink.faults and sink.kinds("recovered") == []
    assert [c.rpm for c in sent] == [8.0, 12.0, 9.0]  # MANUAL acts at once, vision or not


def test_decisions_carry_the_mill_epoch_they_were_made_on() -> None:
    b = Boxes("manual")
    b.mill_at(5.0, epoch=3)
    w, _sink, sent = sup_worker(b, Mode.MANUAL)
    advance(b, w, 0, 1)
    w.handle(SetManualRpm(15.0))
    assert sent == [SetRpm(15.0, 3)]


def test_requests_go_to_the_application_and_results_come_back() -> None:
    b = Boxes()
    b.mill_at(5.0)
    preds = FakePredictions()
    w, sink, sent = sup_worker(b, Mode.AUTO, preds, prediction_wait_s=30.0)
    advance(b, w, 0, 5, level=0.2)
    assert len(preds.requests) == 1 and sent == []
    req = preds.requests[0]
    preds.results.append(PredictionResult(req.t_s, req.horizon_s, {5.0: 0.3, 25.0: 0.9}))
    advance(b, w, 5, 6, level=0.2)
    assert sent == [SetRpm(25.0, 1)]
    moves = [d for d in sink.kinds("decision") if d["decision"] == "move"]
    assert moves and "twin predicts" in moves[0]["reason"]


def test_mode_commands_and_bad_ones() -> None:
    b = Boxes("off")
    b.mill_at(5.0)
    w, sink, _sent = sup_worker(b, Mode.OFF)
    w.handle(SetMode("manual"))
    assert b.mode.get() == "manual" and sink.kinds("decision")[0]["decision"] == "mode"
    w.handle(SetMode("turbo"))
    w.handle(SetManualRpm(math.nan))
    assert b.mode.get() == "manual" and len(sink.kinds("operator_rejected")) == 2


def test_run_view_time_passes_without_frames_and_never_goes_back() -> None:
    b = Boxes()
    assert b.view.now_s() == 0.0  # before any frame: the run clock
    b.frame(10.0)
    assert b.view.now_s() == pytest.approx(10.0)
    b.wall.t += 2.0
    assert b.view.now_s() == pytest.approx(12.0)
    b.frame(11.0)  # a late frame: run time does not go back
    assert b.view.now_s() == pytest.approx(12.0)


def test_root_controls_become_typed_commands(tmp_path) -> None:
    """The dashboard's Controls put commands on the workers' queues; nothing runs."""
    from twin.config import RunConfig
    from twin.run.loop import LiveLoop
    from twin.runlog import RunLog, read_events

    class Link(FakeLink):
        def __init__(self) -> None:
            super().__init__(MillStatus(5.0, 5.0, True, None))

    cfg = RunConfig(dashboard=False, mode="off", log_dir=tmp_path / "run").resolved()
    with RunLog(tmp_path / "run") as log:
        loop = LiveLoop(cfg, iter(()), Link(), log)
        loop.controls.set_mode("manual")
        loop.controls.set_manual_rpm(12.0)
        loop.controls.emergency_stop()
        assert loop.supervisor._inbox.get_nowait() == SetMode("manual")
        assert loop.supervisor._inbox.get_nowait() == SetManualRpm(12.0)
        assert loop.supervisor._inbox.get_nowait() == SetMode("off")
        assert loop.mill._inbox.get_nowait() == StopMill(source="emergency_stop", urgent=True)
        assert "emergency_stop" in loop.events.active()
        loop.controls.recalibrate()
        loop.controls.reseed_twin()
        assert loop.twin._requests.get_nowait() == Recalibrate()
        assert loop.twin._requests.get_nowait() == Reseed()
        loop.controls.run_whatif([5.0], math.nan)  # refused with an event, never an exception
        loop.controls.run_whatif([5.0, 25.0], 10.0)
        loop.controls.run_whatif([5.0], 10.0)  # one study at a time: refused
        ev = [e for e in read_events(tmp_path / "run") if e["kind"] in ("operator", "operator_rejected")]
        assert [e["kind"] for e in ev if e.get("action") == "whatif"] == [
            "operator_rejected", "operator", "operator", "operator_rejected",
        ]
        assert loop._threads == []  # only start() starts threads

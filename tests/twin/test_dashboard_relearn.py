"""Issue 22: frames flagged ``lighting_changed:`` -- the dashboard says so and offers to
re-learn the classes from the live bed: a button behind the control token that sends the
loop's typed relearn command (``Operator.relearn_classes``: a ``SwapClasses`` for the camera
worker, logged as an operator action). The page runs in a real chromium."""

from __future__ import annotations

import math
import queue
import threading

import numpy as np
import pytest

from tests.twin.dashboard_helpers import CLOSED_CONNECTION_OK, button, input_by_label
from tests.waiting import wait_until
from twin.dashboard import Dashboard, numbers_markdown
from twin.live.commands import SwapClasses
from twin.live.snapshots import CameraInfo, Latest
from twin.records import FrameReading, ModeSet, Record, event_fields
from twin.run.operator import Operator
from twin.state import LiveState, Panel
from vision.sources import read_image
from vision.suggest import suggest_classes
from vision.synthetic import light_change, particle_drum

pytestmark = CLOSED_CONNECTION_OK

FLAG = "lighting_changed:saturated:green"


class RelearnControls:
    """Stands in for the loop: records the relearn command (and refuses nothing else)."""

    def __init__(self) -> None:
        self.relearns = 0
        self.lock = threading.Lock()

    def relearn_classes(self) -> str:
        with self.lock:
            self.relearns += 1
        return "re-learning the classes from the live bed ..."

    def __getattr__(self, name: str):  # the other controls: no-ops
        if name.startswith("__"):
            raise AttributeError(name)
        return lambda *a, **k: None


def _flagged_frame(t: float, i: int) -> FrameReading:
    return FrameReading(
        t_s=t, frame=i, mi=math.nan, mi_sigmoid=math.nan, mi_linear=math.nan, d_px=math.nan, dsigma_px=math.nan,
        concentration=0.5,
        slope_deg=30.0, valid=False, trend_mi=0.8, trend_lo95=0.7, trend_hi95=0.9, trend_rate=0.0, ma_mi=0.8,
        twin_mi=None, twin_slope_deg=None, rpm_setpoint=5.0, rpm_actual=5.0, mode="auto", flags=(FLAG,),
    )


def test_panel_says_the_light_moved_and_where_to_relearn() -> None:
    state = LiveState()
    state.record(_flagged_frame(1.0, 1))
    assert state.panel.light_state == "changed (saturated:green)"
    md = numbers_markdown(state.panel)
    assert "no MI" in md and "**Re-learn classes** under Controls" in md
    assert "Re-learn" not in numbers_markdown(Panel(light_state="ok"))


@pytest.mark.browser  # a dashboard without a loop: not in the "live" group
@pytest.mark.timeout(120)
def test_relearn_button_behind_the_token_in_chromium(page) -> None:
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="auto"))
    state.record(_flagged_frame(1.0, 1))
    controls = RelearnControls()
    events: list[str] = []
    dash = Dashboard(state, controls, host="127.0.0.1", port=0, control_token="s3cret", update_hz=12,
                     on_event=lambda rec: events.append(rec.kind)).start()
    try:
        page.goto(dash.url)
        page.get_by_text("The light moved too far").wait_for()  # the panel says so
        relearn = button(page, "Re-learn classes")
        relearn.wait_for()
        assert relearn.is_disabled()  # read-only without the token
        relearn.click(force=True)  # a disabled control: nothing happens
        input_by_label(page, "Control token").fill("s3cret")
        button(page, "Unlock controls").click()
        wait_until(lambda: not relearn.is_disabled(), 10, "the button to enable after the token")
        assert controls.relearns == 0  # the locked click (on the same websocket, before the unlock) did nothing
        relearn.click()
        wait_until(lambda: controls.relearns == 1, 10, "the relearn command")
        page.get_by_text("re-learning the classes from the live bed").wait_for()  # told to who asked
        assert "dashboard_unlocked" in events
    finally:
        dash.stop()


class _Events:
    def __init__(self) -> None:
        self.got: list[tuple[str, dict]] = []

    def publish(self, rec: Record) -> None:
        self.got.append((rec.kind, event_fields(rec)))


class _Threads:
    """The loop's ``spawn``: starts the thread and keeps it (to join)."""

    def __init__(self) -> None:
        self.started: list[threading.Thread] = []

    def __call__(self, name: str, target) -> None:
        th = threading.Thread(target=target, name=name, daemon=True)
        self.started.append(th)
        th.start()


def _operator(image: np.ndarray | None, cfg) -> Operator:
    """The run's operator commands with what relearning uses (no workers: nothing else is called)."""
    return Operator(
        now_s=lambda: 12.5, events=_Events(), mill=None, mill_box=None, supervisor=None, twin=None,  # type: ignore[arg-type]
        whatif=None, limits=None, camera_box=Latest(CameraInfo(image=image)),  # type: ignore[arg-type]
        camera_commands=queue.SimpleQueue(), spawn=_Threads(), meter_config=cfg, classes=cfg.classes,
    )


def test_loop_relearn_swaps_a_meter_learned_on_the_live_bed_and_logs_it(real_drum_dir) -> None:
    """The loop's command: an operator event, the classes learned again off the camera
    thread from the newest frame (names kept), a ``SwapClasses`` whose meter measures the
    real frame that the old classes flag ``lighting_changed:`` (exposure x0.3)."""
    setup = read_image(real_drum_dir / "images" / "0030.jpg")[0]
    cfg = suggest_classes(setup, per_frame=4000)
    now = light_change(setup, 0.3)  # beyond the tracking's gain range
    old = cfg.make_meter().measure(now)
    assert any(f.startswith("lighting_changed:") for f in old.flags)
    op = _operator(now, cfg)
    answer = op.relearn_classes()
    assert "re-learning" in answer
    for th in op.spawn.started:
        th.join(60)
    assert [k for k, _ in op.events.got] == ["operator", "operator"]
    assert [d["action"] for _, d in op.events.got] == ["relearn_classes", "relearn_classes_swapped"]
    cmd = op.camera_commands.get_nowait()
    assert isinstance(cmd, SwapClasses)
    assert [c.name for c in cmd.meter.classes] == [c.name for c in cfg.counted]
    r = cmd.meter.measure(now)
    assert r.valid and not any(f.startswith("lighting_changed:") for f in r.flags), r.flags
    assert op.meter_config is not cfg  # the next re-learn starts from the new set-up


def test_loop_relearn_without_a_frame_is_refused_and_logged() -> None:
    cfg = suggest_classes(particle_drum((320, 240), mix=0.4, seed=3).image, per_frame=3000)
    op = _operator(None, cfg)
    assert "refused" in op.relearn_classes()
    assert op.events.got == [("operator_rejected", {"action": "relearn_classes", "error": "no camera frame yet"})]
    assert op.camera_commands.empty() and op.spawn.started == []

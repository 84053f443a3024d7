"""The viser dashboard in a real chromium, fed by a scripted LiveState (no loop):
images and plots update, controls reach the loop, a remote viewer without the
token is read-only."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from tests.twin.dashboard_helpers import (
    IMG,
    button,
    choose_mode,
    mode_selector,
    drag_slider_to,
    image_srcs,
    input_by_label,
    plot_pixels,
    slider_enabled,
    slider_value,
    wait_until,
)
from sim.drum import Particles
from twin.dashboard import Dashboard, axis_range, numbers_markdown, parse_rpm_list
from twin.dashboard.scene import ring_segments
from twin.state import LiveState, forward_fill


class RecordingControls:
    """Stands in for the loop: records every call."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple]] = []
        self.lock = threading.Lock()

    def _rec(self, name: str, *args: object) -> None:
        with self.lock:
            self.calls.append((name, args))

    def names(self) -> list[str]:
        with self.lock:
            return [c[0] for c in self.calls]

    def args_of(self, name: str) -> list[tuple]:
        with self.lock:
            return [a for n, a in self.calls if n == name]

    def set_mode(self, mode: str) -> None:
        self._rec("set_mode", mode)

    def set_manual_rpm(self, rpm: float) -> None:
        self._rec("set_manual_rpm", rpm)

    def start_mill(self) -> None:
        self._rec("start_mill")

    def stop_mill(self) -> None:
        self._rec("stop_mill")

    def emergency_stop(self) -> None:
        self._rec("emergency_stop")

    def recalibrate(self) -> None:
        self._rec("recalibrate")

    def reseed_twin(self) -> None:
        self._rec("reseed_twin")

    def run_whatif(self, rpms, duration_s) -> None:
        self._rec("run_whatif", tuple(rpms), duration_s)


class Feeder:
    """Publishes a moving frame and plot points at 20 Hz until stopped."""

    def __init__(self, state: LiveState) -> None:
        self.state = state
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self) -> None:
        i = 0
        while not self.stop.is_set():
            img = np.zeros((120, 120, 3), np.uint8)
            img[:, (i * 3) % 120] = (0, 0, 255)
            self.state.publish_camera(img)
            a = np.linspace(0, 2 * np.pi, 12, endpoint=False) + 0.1 * i
            disks = Particles(0.1 * np.cos(a), 0.1 * np.sin(a), np.full(12, 0.01), np.arange(12) % 2,
                              class_bgr=((0, 0, 220), (220, 60, 0)))
            self.state.publish_twin(img[:, ::-1].copy(), disks, 0.15)
            t = i * 0.05
            self.state.publish_point(
                {"t_s": t, "mi": 0.8 + 0.1 * np.sin(t), "trend_mi": 0.8, "trend_lo95": 0.7, "trend_hi95": 0.9,
                 "rpm_setpoint": 5.0, "rpm_actual": 5.0, "slope_deg": 30.0, "twin_slope_deg": 31.0}
            )
            self.state.update_numbers(t_s=t, mi=0.8)
            i += 1
            self.stop.wait(0.05)

    def __enter__(self) -> Feeder:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(2)


def test_pure_helpers() -> None:
    assert parse_rpm_list("5, 20;40") == [5.0, 20.0, 40.0]
    with pytest.raises(ValueError):
        parse_rpm_list("5, fast")
    with pytest.raises(ValueError):
        parse_rpm_list("500")
    md = numbers_markdown({"mi": 0.8123, "mode": "auto", "last_decision": "rpm 5 -> 20"})
    assert "0.812" in md and "auto" in md and "rpm 5 -> 20" in md
    assert axis_range(np.array([np.nan, 31.2, 44.9]), np.array([np.nan, np.nan, 38.0]), step=5.0, pad=1.0) == (30.0, 50.0)
    assert axis_range(np.array([np.nan]), step=5.0) is None
    assert axis_range(np.array([20.0, 20.0]), step=5.0) == (20.0, 25.0)
    x = forward_fill(np.array([np.nan, 1.0, np.nan, 3.0, np.nan]))
    assert np.isnan(x[0]) and list(x[1:]) == [1.0, 1.0, 3.0, 3.0]


def test_scene_geometry() -> None:
    seg = ring_segments(0.15, 96)
    assert seg.shape == (96, 2, 3) and np.allclose(np.hypot(seg[..., 0], seg[..., 1]), 0.15, atol=1e-6)
    assert np.allclose(seg[1:, 0], seg[:-1, 1])  # a connected ring


@pytest.mark.browser
@pytest.mark.timeout(120)
def test_dashboard_updates_and_controls(page, tmp_path: Path) -> None:
    state = LiveState()
    state.update_numbers(mode="auto", rpm_setpoint=5.0)
    controls = RecordingControls()
    dash = Dashboard(state, controls, port=0, update_hz=12).start()
    try:
        with Feeder(state):
            page.goto(dash.url)
            page.wait_for_selector(IMG)
            wait_until(lambda: len(image_srcs(page)) >= 2, 20, "camera and twin images")
            first_imgs, first_plots = image_srcs(page), plot_pixels(page)
            assert {"Mixing index", "Mill rpm", "Bed slope angle", "What-if MI"} <= set(first_plots)
            wait_until(lambda: image_srcs(page)[0] != first_imgs[0], 10, "a new camera frame")
            wait_until(lambda: plot_pixels(page)["Mixing index"] != first_plots["Mixing index"], 10, "the MI plot to redraw")

            assert not slider_enabled(page)  # AUTO: the operator rpm is inactive
            choose_mode(page, "MANUAL")
            wait_until(lambda: ("manual",) in controls.args_of("set_mode"), 10, "set_mode('manual')")
            wait_until(lambda: slider_enabled(page), 10, "the rpm slider to enable in MANUAL")
            drag_slider_to(page, 0.4)
            wait_until(
                lambda: controls.args_of("set_manual_rpm")
                and controls.args_of("set_manual_rpm")[-1][0] == slider_value(page),
                10,
                "set_manual_rpm with the slider's final value",
            )
            assert 15.0 < controls.args_of("set_manual_rpm")[-1][0] < 45.0

            button(page, "EMERGENCY STOP").click()
            button(page, "Re-seed twin from camera").click()
            input_by_label(page, "What-if rpm list").fill("5, 40")
            button(page, "Run what-if").click()
            wait_until(lambda: controls.args_of("run_whatif"), 10, "run_whatif")
            assert controls.args_of("run_whatif")[-1][0] == (5.0, 40.0)
            assert {"emergency_stop", "reseed_twin"} <= set(controls.names())
            page.screenshot(path=str(tmp_path / "dashboard.png"))
        assert dash.pushes > 5
        assert dash.scene.updates > 5  # the twin's particles moved in the 3D scene
        clouds = dash.scene.clouds  # one cloud per class; the Feeder's 12 disks sit on a 0.1 m circle
        assert sorted((k, len(h.points)) for k, h in clouds.items()) == [(0, 6), (1, 6)]
        for h in clouds.values():
            assert np.allclose(np.hypot(h.points[:, 0], h.points[:, 1]), 0.1, atol=1e-3)
            assert np.all(h.points[:, 2] == 0.0) and h.point_size == pytest.approx(0.01)
    finally:
        dash.stop()


@pytest.mark.browser
@pytest.mark.timeout(120)
def test_remote_viewer_without_token_is_read_only(page) -> None:
    state = LiveState()
    state.update_numbers(mode="auto")
    controls = RecordingControls()
    with pytest.raises(ValueError, match="token"):
        Dashboard(state, controls, host="127.0.0.2", port=0)
    dash = Dashboard(state, controls, host="127.0.0.2", port=0, control_token="s3cret").start()
    try:
        page.goto(dash.url)
        manual = mode_selector(page)
        manual.wait_for()
        assert manual.is_disabled() and button(page, "EMERGENCY STOP").is_disabled()
        button(page, "EMERGENCY STOP").click(force=True)
        input_by_label(page, "Control token").fill("wrong")
        button(page, "Unlock controls").click()
        page.get_by_text("wrong token").wait_for()
        assert manual.is_disabled()
        input_by_label(page, "Control token").fill("s3cret")
        button(page, "Unlock controls").click()
        wait_until(lambda: not manual.is_disabled(), 10, "controls to unlock")
        choose_mode(page, "MANUAL")
        wait_until(lambda: controls.args_of("set_mode"), 10, "set_mode after unlocking")
        assert controls.args_of("set_mode") == [("manual",)]
        assert "emergency_stop" not in controls.names()  # the locked click did nothing
    finally:
        dash.stop()

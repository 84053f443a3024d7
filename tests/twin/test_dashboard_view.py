"""The viser dashboard in a real chromium, fed by a scripted LiveState (no loop): images and plots
update, controls reach the loop, a remote viewer without the token is read-only; its pure helpers,
the scene's drawing and ``bench dashboard``'s option checks."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import viser

from control.limits import Limits
from control.supervisor import Supervisor
from tests.twin.dashboard_fakes import Feeder, RecordingControls
from tests.twin.dashboard_helpers import (
    CLOSED_CONNECTION_OK,
    IMG,
    button,
    choose_mode,
    drag_slider_to,
    image_srcs,
    input_by_label,
    mode_selector,
    plot_pixels,
    slider,
    slider_enabled,
    slider_value,
)
from tests.waiting import wait_until
from twin.dashboard import Dashboard, axis_range, numbers_markdown, parse_rpm_list
from twin.dashboard.guard import UnlockPolicy
from twin.dashboard.ratebench import check_bench_args
from twin.dashboard.scene import ring_segments
from twin.errors import TwinError
from twin.records import MillState, ModeSet
from twin.run.settings import supervisor_config
from twin.state import LiveState, Panel, forward_fill

pytestmark = CLOSED_CONNECTION_OK


def test_pure_helpers() -> None:
    assert parse_rpm_list("5, 20;40") == [5.0, 20.0, 40.0]
    with pytest.raises(ValueError):
        parse_rpm_list("5, fast")
    with pytest.raises(ValueError):
        parse_rpm_list("500")
    md = numbers_markdown(Panel(mi=0.8123, mode="auto", last_decision="rpm 5 -> 20"))
    assert "0.812" in md and "auto" in md and "rpm 5 -> 20" in md
    assert "not settled" not in md and "Re-learn" not in md
    md = numbers_markdown(Panel(trend_state="unsettled", light_state="changed (saturated:0.31)"))
    assert "| trend | unsettled | light | changed (saturated:0.31) |" in md
    assert "Trend not settled yet" in md and "Re-learn the classes" in md
    rng = axis_range(np.array([np.nan, 31.2, 44.9]), np.array([np.nan, np.nan, 38.0]), step=5.0, pad=1.0)
    assert rng == (30.0, 50.0)
    assert axis_range(np.array([np.nan]), step=5.0) is None
    assert axis_range(np.array([20.0, 20.0]), step=5.0) == (20.0, 25.0)
    x = forward_fill(np.array([np.nan, 1.0, np.nan, 3.0, np.nan]))
    assert np.isnan(x[0]) and list(x[1:]) == [1.0, 1.0, 3.0, 3.0]


def test_scene_geometry() -> None:
    seg = ring_segments(0.15, 96)
    assert seg.shape == (96, 2, 3) and np.allclose(np.hypot(seg[..., 0], seg[..., 1]), 0.15, atol=1e-6)
    assert np.allclose(seg[1:, 0], seg[:-1, 1])  # a connected ring


@pytest.mark.browser  # no loop (a scripted LiveState): not in the "live" group, whose one worker it held up 30-40 s
@pytest.mark.timeout(120)
def test_dashboard_in_chromium(page, tmp_path: Path) -> None:
    """One chromium for the whole browser check: the local dashboard (updates and
    controls), then a remote one (read-only until the token, rate-limited unlocks)."""
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="auto"))
    state.record(MillState(t_s=0.0, state="running", connected=True, setpoint_rpm=5.0, actual_rpm=5.0))
    controls = RecordingControls()
    sup = supervisor_config(critical_rpm=70.0)  # a drum of another size: 0.6 x 70 rpm = 42 rpm, not the default 45
    limits = sup.limits  # what the run's supervisor enforces
    assert limits.rpm_range[1] == pytest.approx(42.0) and Limits().rpm_range[1] == 45.0  # a hard-coded 45 fails
    dash = Dashboard(state, controls, port=0, update_hz=12, limits=limits).start()
    try:
        with Feeder(state):
            page.goto(dash.url)
            page.wait_for_selector(IMG)
            wait_until(lambda: len(image_srcs(page)) >= 2, 20, "camera and twin images")
            first_imgs, first_plots = image_srcs(page), plot_pixels(page)
            assert {"Mixing index", "Mill rpm", "Bed slope angle", "What-if MI"} <= set(first_plots)
            wait_until(lambda: image_srcs(page)[0] != first_imgs[0], 10, "a new camera frame")
            mi_plot = first_plots["Mixing index"]
            wait_until(lambda: plot_pixels(page)["Mixing index"] != mi_plot, 10, "the MI plot to redraw")

            assert not slider_enabled(page)  # AUTO: the operator rpm is inactive
            lo, hi = Supervisor(sup).config.limits.rpm_range  # the slider shows what the supervisor enforces
            assert float(slider(page).get_attribute("aria-valuemax")) == pytest.approx(hi, abs=1e-9)
            assert float(slider(page).get_attribute("aria-valuemin")) == pytest.approx(lo, abs=1e-9)
            assert Supervisor(sup).config.limits.clamp(1000.0) == hi  # the supervisor's enforced maximum
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
            drag_slider_to(page, 1.2)  # past the end of the track: the slider stops at the limit
            wait_until(lambda: controls.args_of("set_manual_rpm")[-1][0] == slider_value(page), 10, "slider max")
            assert controls.args_of("set_manual_rpm")[-1][0] <= hi

            input_by_label(page, "What-if rpm list").fill("5, 10000")  # refused, the limit shown
            button(page, "Run what-if").click()
            page.get_by_text("what-if refused").wait_for()
            assert page.get_by_text(f"outside (0, {limits.critical_rpm:.4g}] rpm").count() >= 1
            assert controls.args_of("run_whatif") == []

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
    remote_viewer_without_token_is_read_only(page)


def remote_viewer_without_token_is_read_only(page) -> None:
    """Part two of the browser test (one chromium start): a dashboard with a control
    token on loopback (the token is enforced there too). A viewer without it has
    EMERGENCY STOP and nothing else; six wrong attempts lock that viewer only: a new
    viewer with the right token operates the mill at once."""
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="auto"))
    controls = RecordingControls()
    with pytest.raises(ValueError, match="token"):
        Dashboard(state, controls, host="127.0.0.2", port=0)
    events: list[str] = []
    dash = Dashboard(state, controls, host="127.0.0.1", port=0, control_token="s3cret",
                     # no spacing between one viewer's attempts (the limiter's tests above check it): the
                     # five wrong ones go one after the other, the sixth is limited by max_failures
                     unlock_policy=UnlockPolicy(per_client_s=0.0, max_failures=5, window_s=60.0),
                     on_event=lambda rec: events.append(rec.kind)).start()
    try:
        page.goto(dash.url)
        manual = mode_selector(page)
        manual.wait_for()
        assert manual.is_disabled() and button(page, "Stop mill").is_disabled()
        assert button(page, "Run what-if").is_disabled()
        assert not button(page, "EMERGENCY STOP").is_disabled()  # a stop is always safe
        button(page, "EMERGENCY STOP").click()
        wait_until(lambda: "emergency_stop" in controls.names(), 10, "EMERGENCY STOP of a read-only viewer")
        button(page, "Stop mill").click(force=True)  # a disabled control: nothing happens
        for i in range(5):
            input_by_label(page, "Control token").fill(f"wrong ünïcode ✓ {i}")  # any input is safe
            button(page, "Unlock controls").click()
            wait_until(lambda i=i: dash.failed_unlocks == i + 1, 10, f"wrong attempt {i + 1}")
        input_by_label(page, "Control token").fill("also wrong")
        button(page, "Unlock controls").click()  # the sixth: this viewer is limited
        page.get_by_text("too many attempts").wait_for()
        input_by_label(page, "Control token").fill("s3cret")
        button(page, "Unlock controls").click()  # still limited: the limit is this viewer's
        wait_until(lambda: events.count("dashboard_unlock_limited") == 1 and dash.failed_unlocks == 5, 5,
                   "the limited viewer's attempts")

        other = page.context.new_page()  # a new viewer (same address) with the right token
        try:
            other.goto(dash.url)
            mode_selector(other).wait_for()
            input_by_label(other, "Control token").fill("s3cret")
            button(other, "Unlock controls").click()
            wait_until(lambda: not mode_selector(other).is_disabled(), 10, "the new viewer to unlock at once")
            choose_mode(other, "MANUAL")
            wait_until(lambda: controls.args_of("set_mode"), 10, "set_mode after unlocking")
            assert controls.args_of("set_mode") == [("manual",)]
        finally:
            other.close()
        # the limited viewer's right token (sent before the other viewer existed) unlocked nothing
        assert manual.is_disabled() and controls.args_of("set_mode") == [("manual",)]
        assert "stop_mill" not in controls.names()  # the locked click did nothing
        assert events[:6] == ["dashboard_unlock_failed"] * 5 + ["dashboard_unlock_limited"]
        # the new viewer's one unlock (a throttled count of the limited viewer's attempts may
        # follow it: noisy events are written once per 5 s window)
        assert events.count("dashboard_unlocked") == 1 and events.index("dashboard_unlocked") >= 6
        assert set(events[6:]) <= {"dashboard_unlocked", "dashboard_unlock_limited"}
        assert "dashboard_refused" not in events
        assert dash.failed_unlocks == 5 and dash.refused_handshakes == 0  # chromium: own origin
    finally:
        dash.stop()


@pytest.mark.parametrize(
    ("kw", "needle"),
    [({"seconds": float("nan")}, "--seconds"), ({"seconds": float("inf")}, "--seconds"),
     ({"seconds": 0.0}, "--seconds"), ({"warmup_s": float("nan")}, "--warmup"), ({"warmup_s": -1.0}, "--warmup"),
     ({"speed": float("inf")}, "--speed"), ({"speed": 0.0}, "--speed"), ({"port": 0}, "--port"),
     ({"port": 99999}, "--port")],
)
def test_bench_dashboard_options_are_checked(kw, needle) -> None:
    args = {"seconds": 20.0, "warmup_s": 15.0, "speed": 1.0, "port": 8079, **kw}
    with pytest.raises(TwinError, match=needle):
        check_bench_args(**args)


def test_bench_dashboard_defaults_pass() -> None:
    check_bench_args(20.0, 0.0, 1.0, 8079)  # raises on failure


def test_scene_draws_shaped_particles_as_turned_outlines_and_the_baffles() -> None:
    """A shaped class is drawn as its outline turned by each particle's angle (not as round points),
    and the baffles as closed polygons (``Particles.class_outline_m`` / ``baffles_m``)."""
    from types import SimpleNamespace

    from twin.dashboard.scene import TwinScene, outline_segments, polygon_segments

    square = np.array([[0.01, 0.0], [0.0, 0.01], [-0.01, 0.0], [0.0, -0.01]])
    seg = outline_segments(np.array([0.05]), np.array([0.0]), np.array([math.pi / 4]), square)
    assert seg.shape == (4, 2, 3)
    # turned by 45 deg: the corners sit on the axes' diagonals, 10 mm from the centre
    assert np.allclose(np.hypot(seg[:, 0, 0] - 0.05, seg[:, 0, 1]), 0.01, atol=1e-6)
    assert np.allclose(np.abs(seg[:, 0, 0] - 0.05), np.abs(seg[:, 0, 1]), atol=1e-6)
    assert np.allclose(seg[1:, 0], seg[:-1, 1], atol=1e-7) and np.allclose(seg[-1, 1], seg[0, 0], atol=1e-7)
    assert polygon_segments([square, square[:3]]).shape == (7, 2, 3)

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        scene = TwinScene(server)
        class Parts(SimpleNamespace):  # sim.twin_base.Particles with the pymunk engine's outline and baffle fields
            def __len__(self) -> int:
                return len(self.x_m)

        parts = Parts(
            x_m=np.array([0.0, 0.05]), y_m=np.array([0.0, -0.05]), r_m=np.array([0.01, 0.01]),
            cls=np.array([0, 1]), angle_rad=np.array([0.0, 0.3]), class_bgr=((0, 0, 220), (220, 60, 0)),
            class_outline_m=(None, square), baffles_m=(np.array([[0.1, 0.0], [0.14, 0.0], [0.14, 0.005]]),),
        )
        scene.update(parts, 0.15)  # type: ignore[arg-type]
        assert scene.clouds[0].visible and not scene.clouds[1].visible  # the square class: outlines only
        assert scene.updates == 1
    finally:
        server.stop()

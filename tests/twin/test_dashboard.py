"""The viser dashboard in a real chromium, fed by a scripted LiveState (no loop):
images and plots update, controls reach the loop, a remote viewer without the
token is read-only."""

from __future__ import annotations

import logging
import math
import threading
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import viser
import websockets

from control.limits import Limits
from control.supervisor import Supervisor
from sim.twin_base import Particles
from tests.twin.dashboard_helpers import (
    IMG,
    button,
    choose_mode,
    drag_slider_to,
    drain_callbacks,
    image_srcs,
    input_by_label,
    mode_selector,
    open_viewer,
    plot_pixels,
    send_message,
    slider,
    slider_enabled,
    slider_value,
    wait_for_label,
)
from tests.waiting import wait_until
from twin.dashboard import Dashboard, axis_range, numbers_markdown, parse_rpm_list
from twin.dashboard.guard import UnlockLimiter, UnlockPolicy, is_loopback, origin_allowed, tokens_match
from twin.dashboard.ratebench import check_bench_args
from twin.dashboard.scene import ring_segments
from twin.errors import TwinError
from twin.records import FrameReading, MillState, ModeSet, event_fields
from twin.run.settings import supervisor_config
from twin.state import LiveState, Panel, forward_fill

# viser warns when the GUI it builds for a connection that the tests close or refuse
# mid-handshake is never delivered (whichever test of the shared dashboard sees it)
pytestmark = pytest.mark.filterwarnings("ignore:Queued a GuiButtonMessage on a closed connection:UserWarning")


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

    def cancel_whatif(self) -> bool:
        self._rec("cancel_whatif")
        return False

    def relearn_classes(self) -> str:
        self._rec("relearn_classes")
        return "re-learning the classes from the live bed ..."


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
            self.state.record(FrameReading(
                t_s=t, frame=i, mi=0.8 + 0.1 * np.sin(t), mi_sigmoid=0.8, mi_linear=0.8, d_px=3.0, dsigma_px=1.0,
                concentration=0.5, slope_deg=30.0, valid=True, trend_mi=0.8, trend_lo95=0.7, trend_hi95=0.9,
                trend_rate=0.0, ma_mi=0.8, twin_mi=None, twin_slope_deg=31.0, rpm_setpoint=5.0, rpm_actual=5.0,
                mode="auto", flags=(),
            ))
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


# -- the door: origin, framing, share tunnel, many viewers (real websocket clients) ------
def test_origin_policy() -> None:
    ok = dict(bind_host="127.0.0.1", port=8080)
    assert origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080", **ok)
    assert origin_allowed("http://localhost:8080", "localhost:8080", **ok)
    assert origin_allowed("http://[::1]:8080", "[::1]:8080", **ok)
    for origin, host in [
        ("http://evil.example", "127.0.0.1:8080"),  # a hostile page in the operator's browser
        ("http://evil.example:8080", "evil.example:8080"),  # DNS rebinding to 127.0.0.1
        ("http://127.0.0.1:9999", "127.0.0.1:8080"),  # another local port's page
        ("http://127.0.0.1:8080", "127.0.0.1:9999"),
        ("null", "127.0.0.1:8080"), (None, "127.0.0.1:8080"), ("", "127.0.0.1:8080"),
        ("http://127.0.0.1:8080", None), ("http://127.0.0.1:8080/x", "127.0.0.1:8080"),
        ("ftp://127.0.0.1:8080", "127.0.0.1:8080"), ("http://127.0.0.1:99999", "127.0.0.1:8080"),
        ("http://127.0.0.1:8080", "127.0.0.1:notaport"),
    ]:
        assert not origin_allowed(origin, host, **ok), (origin, host)
    lan = dict(bind_host="0.0.0.0", port=8080)  # beyond loopback: same origin, any name
    assert origin_allowed("http://mill-pc.lan:8080", "mill-pc.lan:8080", **lan)
    assert not origin_allowed("http://evil.example:8080", "mill-pc.lan:8080", **lan)
    assert is_loopback("localhost") and is_loopback("[::1]") and not is_loopback("0.0.0.0")


def test_token_compare_is_safe_for_any_input() -> None:
    assert tokens_match("s3cret", "s3cret")
    for given in ("", "s3cre", "s3cret ", "ünïcode ✓", "\udcff", "x" * 100_000, None, 12, b"s3cret"):
        assert not tokens_match(given, "s3cret"), given
    assert tokens_match("ünïcode ✓", "ünïcode ✓")
    assert not tokens_match("anything", None) and not tokens_match("", "")


def test_unlock_limiter_is_per_viewer_and_per_address_never_global() -> None:
    lim = UnlockLimiter(UnlockPolicy(per_client_s=1.0, max_failures=3, max_failures_per_address=5, window_s=60.0))
    assert lim.wait_s(1, 0.0, "10.0.0.9") == 0.0
    lim.attempt(1, 0.0, ok=False, address="10.0.0.9")
    assert lim.wait_s(1, 0.5, "10.0.0.9") == pytest.approx(0.5) and lim.wait_s(2, 0.5, "10.0.0.9") == 0.0
    for t in (1.0, 2.0):
        lim.attempt(1, t, ok=False, address="10.0.0.9")
    assert lim.wait_s(1, 3.0, "10.0.0.9") == pytest.approx(57.0)  # viewer 1: three failures, it waits
    assert lim.wait_s(2, 3.0, "10.0.0.9") == 0.0  # another viewer of the same host does not
    assert lim.wait_s(7, 3.0, "10.0.0.1") == 0.0  # nor one elsewhere: never a global lock-out
    lim.attempt(2, 3.0, ok=False, address="10.0.0.9")
    lim.attempt(3, 3.0, ok=False, address="10.0.0.9")  # five from one address: that address waits
    assert lim.wait_s(4, 4.0, "10.0.0.9") == pytest.approx(56.0)
    assert lim.wait_s(7, 4.0, "10.0.0.1") == 0.0  # the operator's address is untouched
    lim.forget(1)  # reconnecting clears the viewer's own slot, not its address's failures
    assert lim.wait_s(1, 4.0, "10.0.0.9") == pytest.approx(56.0)
    assert lim.wait_s(4, 60.01, "10.0.0.9") == 0.0  # the oldest failures left the window
    lim.attempt(7, 61.0, ok=True, address="10.0.0.1")
    assert lim.wait_s(7, 61.5, "10.0.0.1") == pytest.approx(0.5)


@pytest.fixture(scope="module")
def local_dash() -> Iterator[tuple[Dashboard, RecordingControls, list]]:
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="off"))
    controls = RecordingControls()
    events: list = []
    dash = Dashboard(state, controls, port=0, update_hz=4,
                     on_event=lambda rec: events.append((rec.kind, event_fields(rec)))).start()
    try:
        yield dash, controls, events
    finally:
        dash.stop()


@pytest.mark.timeout(60)
def test_foreign_origins_are_refused_own_is_accepted(local_dash) -> None:
    dash, _, events = local_dash
    for origin in ("http://evil.example", None, f"http://localhost:{dash.port + 1}"):
        with pytest.raises(websockets.exceptions.InvalidStatus) as exc:
            open_viewer(dash.url, origin=origin)
        assert exc.value.response.status_code == 403
        assert exc.value.response.headers["X-Frame-Options"] == "DENY"
    assert dash.refused_handshakes == 3
    refused = [f for k, f in events if k == "dashboard_refused"]  # throttled: one per 5 s
    assert refused == [{"suppressed": 0, "origin": "http://evil.example", "host": f"127.0.0.1:{dash.port}"}]
    with open_viewer(dash.url) as ws:  # the dashboard's own page
        assert wait_for_label(ws, "EMERGENCY STOP", 20)


def test_http_responses_forbid_framing(local_dash) -> None:
    dash, _, _ = local_dash
    with urllib.request.urlopen(dash.url + "/", timeout=10) as r:
        assert r.status == 200
        assert r.headers["X-Frame-Options"] == "DENY"
        assert "frame-ancestors 'none'" in r.headers["Content-Security-Policy"]


@pytest.mark.timeout(60)
def test_a_viewer_cannot_start_the_share_tunnel(local_dash, monkeypatch) -> None:
    import viser._viser

    started: list[tuple] = []

    def no_tunnel(*args: object, **kw: object) -> None:
        started.append(args)
        raise RuntimeError("test: no tunnel")

    monkeypatch.setattr(viser._viser, "ViserTunnel", no_tunnel)
    dash, _, _ = local_dash
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
        send_message(ws, "ShareUrlRequest")
        wait_for_label(ws, "never sent", 1.0)
    assert started == [] and dash._server.request_share_url() is None and started == []


@pytest.mark.timeout(90)
def test_twenty_viewers_at_once_all_get_emergency_stop(local_dash) -> None:
    dash, _, _ = local_dash
    n = 20
    barrier = threading.Barrier(n)
    got: list[bool] = []
    errors: list[BaseException] = []
    lock = threading.Lock()

    def viewer() -> None:
        try:
            barrier.wait(20)
            with open_viewer(dash.url, timeout_s=30) as ws:
                ok = wait_for_label(ws, "EMERGENCY STOP", 40)
                with lock:
                    got.append(ok)
                barrier.wait(60)  # all still connected while the server is counted
                if ok:
                    with lock:
                        if len(got) == n:
                            got.append(dash.viewers_with_estop() >= n)
        except BaseException as exc:
            with lock:
                errors.append(exc)

    threads = [threading.Thread(target=viewer) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(80)
    assert errors == [] and got[:n] == [True] * n
    assert got[n:] == [True]  # the server built controls for every one of them




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

    import viser

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


# -- issue 26 item 10: an accurate security log; malformed messages as one line ----------
@pytest.fixture
def fresh_dash() -> Iterator[tuple[Dashboard, list]]:
    events: list = []
    dash = Dashboard(LiveState(), RecordingControls(), port=0, update_hz=4,
                     on_event=lambda rec: events.append((rec.kind, event_fields(rec)))).start()
    try:
        yield dash, events
    finally:
        dash.stop()


@pytest.mark.timeout(60)
def test_suppressed_refusals_are_counted_in_the_log(fresh_dash) -> None:
    dash, events = fresh_dash
    for _ in range(12):
        with pytest.raises(websockets.exceptions.InvalidStatus):
            open_viewer(dash.url, origin="http://evil.example")
    dash.flush_throttled(force=True)  # also done by the update thread once 5 s passed, and at stop
    refused = [f for k, f in events if k == "dashboard_refused"]
    assert len(refused) == 2 and refused[1]["summary"] is True
    assert 1 + sum(f["suppressed"] for f in refused) == 12 == dash.refused_handshakes


@pytest.mark.timeout(60)
def test_quick_disconnects_are_not_refusals(fresh_dash) -> None:
    dash, events = fresh_dash

    class Gone:  # a viewer whose websocket closed before its controls were built
        client_id = 10_000

    dash._on_connect(Gone())  # type: ignore[arg-type]
    for _ in range(8):  # real viewers that leave at once
        open_viewer(dash.url).close()
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
    drain_callbacks(dash._server)  # every viewer's connect callback has run: none was counted as refused
    assert [k for k, _ in events if k == "dashboard_refused"] == []


@pytest.mark.timeout(60)
def test_malformed_websocket_messages_are_one_log_line(fresh_dash, capfd, caplog) -> None:
    dash, events = fresh_dash
    for junk in (b"\x00\x01garbage", None):
        with open_viewer(dash.url) as ws:
            assert wait_for_label(ws, "EMERGENCY STOP", 20)
            if junk is None:
                send_message(ws, "GuiUpdateMessage", uuid=5)  # valid msgpack, wrong fields
            else:
                ws.send(junk)
            wait_until(lambda: ws.protocol.close_code is not None or dash.bad_messages > 0, 10, "the drop")
        wait_until(lambda n=(1 if junk else 2): dash.bad_messages >= n, 10, "the malformed message reported")

    def records() -> list[logging.LogRecord]:
        return [r for r in caplog.records if r.name == "websockets.server" and r.levelno >= logging.WARNING]

    wait_until(lambda: len(records()) >= 2, 10, "both records (the filter counts before the handler logs)")
    assert "Traceback" not in capfd.readouterr().err
    got = records()
    dropped = "dashboard: dropped a viewer after a malformed message"
    assert [r.getMessage().split(" (")[0] for r in got] == [dropped] * 2
    assert all(r.exc_info is None and "\n" not in r.getMessage() for r in got)  # one line, no traceback
    assert [k for k, _ in events].count("dashboard_bad_message") == 1  # throttled; the second is counted
    dash.flush_throttled(force=True)
    assert [f.get("suppressed") for k, f in events if k == "dashboard_bad_message"] == [0, 1]


def test_the_viser_internals_the_dashboard_relies_on(fresh_dash) -> None:
    """Issue 25 item 6: the versions are the checked ones, and each internal exists. (The record
    of websockets' that the one-line filter rewrites is checked by what it does:
    ``test_malformed_websocket_messages_are_one_log_line``.)"""
    import viser

    from twin.dashboard.guard import CHECKED_VERSIONS

    assert viser.__version__ in CHECKED_VERSIONS["viser"]
    assert websockets.__version__ in CHECKED_VERSIONS["websockets"]
    dash, _ = fresh_dash
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
        (cid,) = list(dash._server._websock_server._live_connections)
        assert dash._client_address(cid) == "127.0.0.1"  # the per-address unlock limit's key


def test_the_gatekeeper_is_the_dashboards_policy_without_viser() -> None:
    """The policy split out of the viser server (``twin.dashboard.guard.Gatekeeper``): a
    wrong token is refused and counted, the right one unlocks, EMERGENCY STOP follows
    ``estop_needs_token``, a noisy event is written once per window with a count of the rest."""
    from twin.dashboard.guard import EVENT_THROTTLE_S, Gatekeeper

    now = [100.0]
    events: list[tuple[str, dict]] = []
    records: list = []

    def on_event(rec) -> None:
        records.append(rec)
        events.append((rec.kind, event_fields(rec)))

    gate = Gatekeeper("s3cret", on_event=on_event, estop_needs_token=True,
                      unlock_policy=UnlockPolicy(per_client_s=0.0, max_failures=5, window_s=60.0),
                      monotonic=lambda: now[0], now_s=lambda: now[0] - 100.0)
    assert gate.token_required and not gate.estop_allowed(False) and gate.estop_allowed(True)
    assert gate.try_unlock(1, "wrong", "10.0.0.1") == (False, "**wrong token: read-only**")
    assert gate.try_unlock(1, "s3cret", "10.0.0.1")[0] and gate.failed_unlocks == 1
    assert [k for k, _ in events] == ["dashboard_unlock_failed", "dashboard_unlocked"]
    for _ in range(3):
        gate.refused("http://evil.example", "127.0.0.1:8080")
    assert gate.refused_handshakes == 3 and [k for k, _ in events].count("dashboard_refused") == 1
    now[0] += EVENT_THROTTLE_S
    gate.flush_throttled()
    assert events[-1] == ("dashboard_refused", {"suppressed": 2, "summary": True})
    assert [r.t_s for r in records] == [0.0, 0.0, 0.0, EVENT_THROTTLE_S]  # stamped with the run clock
    assert not Gatekeeper(None).token_required and Gatekeeper(None).estop_allowed(False)


@pytest.mark.timeout(60)
def test_a_locked_viewers_callbacks_are_refused_by_the_server() -> None:
    """viser runs a control's callbacks on the server for whatever a viewer's websocket
    sends: a disabled button in the browser is no defence. Every callback of a viewer without
    the token (``twin.dashboard.controls``: each re-checks its viewer) moves nothing; its
    EMERGENCY STOP still works. The callbacks are run as viser runs them (its handle's
    callbacks, with a ``GuiEvent`` from that viewer)."""
    controls = RecordingControls()
    dash = Dashboard(LiveState(), controls, port=0, update_hz=4, control_token="s3cret").start()
    try:
        with open_viewer(dash.url, timeout_s=20) as ws:
            assert wait_for_label(ws, "EMERGENCY STOP", 30)
            wait_until(lambda: dash.viewers_with_estop() == 1, 10, "the viewer's controls")
            (cid, client), = dash._server.get_clients().items()
            cc = dash.viewers._clients[cid]
            for handle in cc.handles:
                for cb in handle._impl.update_cb:
                    cb(viser.GuiEvent(client, cid, handle))
            assert controls.names() == [] and "refused" in cc.status.content
            for cb in cc.estop._impl.update_cb:
                cb(viser.GuiEvent(client, cid, cc.estop))
            assert controls.names() == ["emergency_stop"]
    finally:
        dash.stop()

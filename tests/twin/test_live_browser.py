"""The live demo's dashboard in a real chromium: images and plots update, MANUAL and the rpm slider
move the emulator's setpoint through the real serial driver; ``bench dashboard`` counts image updates."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, cli
from tests.twin.live_helpers import LIVE, free_port
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.run.main import run_live
from twin.run.settings import Seams
from twin.runlog import read_events


@LIVE
@pytest.mark.browser
@pytest.mark.timeout(300)
def test_browser_sees_live_dashboard_and_drives_the_mill(page, tmp_path: Path) -> None:
    """Chromium opens the live demo's dashboard: camera image and plots update; MANUAL and
    the rpm slider move the emulator's setpoint through the real serial driver."""
    from tests.twin.dashboard_helpers import (
        IMG,
        choose_mode,
        drag_slider_to,
        image_srcs,
        plot_pixels,
        slider,
        slider_enabled,
        slider_value,
    )
    from tests.twin.test_dashboard_history import mi_canvas, no_golden_curve
    from twin.dashboard.history import NO_HISTORY

    cfg = RunConfig(
        dashboard=True, duration_s=10_000, speed=2.0, mode="auto", port=free_port(), log_dir=tmp_path / "run"
    ).resolved()
    started: dict = {}
    done = threading.Event()

    def on_started(loop, plant, dash) -> None:
        started.update(loop=loop, plant=plant, dash=dash)

    def runner() -> None:
        try:
            run_live(cfg, Seams(on_started=on_started))
        finally:
            done.set()

    th = threading.Thread(target=runner, daemon=True)
    th.start()
    try:
        wait_until(lambda: "dash" in started or done.is_set(), 60, "the demo to start")
        assert not done.is_set(), "the run ended early"
        loop, plant, dash = started["loop"], started["plant"], started["dash"]
        page.goto(dash.url)
        page.wait_for_selector(IMG)
        wait_until(lambda: len(image_srcs(page)) >= 2, 30, "camera and twin images")
        page.get_by_text(NO_HISTORY).wait_for()  # issue 40: the rig's first run: no history, no golden curve
        assert no_golden_curve(mi_canvas(page)[0])
        imgs, plots = image_srcs(page), plot_pixels(page)
        wait_until(lambda: image_srcs(page)[0] != imgs[0], 15, "a new camera frame in the browser")
        wait_until(lambda: plot_pixels(page)["Mixing index"] != plots["Mixing index"], 15, "the MI plot to update")
        wait_until(lambda: plot_pixels(page)["Mill rpm"] != plots["Mill rpm"], 15, "the rpm plot to update")
        choose_mode(page, "MANUAL")
        wait_until(lambda: loop.mode_name == "manual", 10, "MANUAL mode in the loop")
        wait_until(lambda: slider_enabled(page), 10, "the rpm slider to enable")
        enforced = loop.supervisor.supervisor.config.limits.rpm_range  # the run's supervisor, as the loop built it
        assert float(slider(page).get_attribute("aria-valuemax")) == pytest.approx(enforced[1], abs=1e-9)
        drag_slider_to(page, 0.2)
        wait_until(lambda: abs(slider_value(page) - 5.0) > 5, 10, "the slider to move")
        wanted = slider_value(page)
        clamp = loop.supervisor.supervisor.config.limits.clamp
        wait_until(
            lambda: abs(plant.emulator.motor.setpoint_rpm - clamp(wanted)) < 0.05,
            30,
            f"the emulator's setpoint to reach {wanted} rpm",
        )
        wait_until(lambda: plant.emulator.motor.actual_rpm > 10, 30, "the drive to speed up")
        page.screenshot(path=str(tmp_path / "dashboard.png"))
        assert (tmp_path / "dashboard.png").stat().st_size > 10_000
    finally:
        if "loop" in started:
            started["loop"].stop_event.set()
        done.wait(30)
    events = read_events(tmp_path / "run")
    assert any(e["kind"] == "operator" and e.get("action") == "manual_rpm" for e in events)
    assert any(e["kind"] == "decision" and e["decision"] == "manual" for e in events)
    assert not any(e["kind"] == "slower_than_golden" for e in events)


@LIVE
@pytest.mark.browser
@pytest.mark.timeout(400)
def test_bench_dashboard_counts_image_updates_in_chromium(bench_dashboard_run) -> None:
    """`drumtwin bench dashboard` runs the demo, opens it in chromium and reports rates
    (``--seconds 2 --warmup 0 --speed 2 --json``: tests/conftest.py, shared with the bad-input sweep)."""
    p = bench_dashboard_run
    assert p.returncode == 0, p.stderr[-2000:]
    rate = json.loads(p.stdout)
    assert rate["seconds"] == 2.0
    assert rate["camera_hz"] > 1.0 and rate["twin_hz"] > 1.0  # both images moved while counting
    assert_one_line_error(cli("bench", "dashboard", "--seconds", "0"), "--seconds")

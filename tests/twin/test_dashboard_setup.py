"""The dashboard's set-up view (issue 39 item 5) in a real chromium: a press of "Commission from the live
camera" collects the running drum's frames, runs every commissioning step and shows the same checks as
``drumtwin commission``; the report is one click away (a download); EMERGENCY STOP answers while a set-up
runs; a viewer without the control token cannot start one; a stopped mill or an rpm that moves refuses.
The live camera is a rendered rig of discs (``twin.commission.rigs.disc_rig``), its run time 10x the wall's."""

from __future__ import annotations

import html
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from tests.twin.dashboard_fakes import RecordingControls
from tests.twin.dashboard_helpers import CLOSED_CONNECTION_OK, button, input_by_label
from tests.waiting import wait_until
from twin.commission.report import SECTIONS
from twin.dashboard import Dashboard
from twin.dashboard.setup import SETUP_FRAMES, SetupFeed
from twin.records import MillState, ModeSet
from twin.state import LiveState

pytestmark = CLOSED_CONNECTION_OK
SPEED = 10.0  # run seconds per wall second of the stand-in camera


class RigCamera:
    """A live camera on a rendered rig: ``frame()`` the newest frame and its run time, the mill at ``rpm``."""

    def __init__(self, frames: list[np.ndarray], rpm: float = 5.0) -> None:
        self.frames, self.rpm_now = frames, rpm
        self.t0 = time.monotonic()
        self.lock = threading.Lock()

    def frame(self) -> tuple[float | None, np.ndarray | None]:
        t = (time.monotonic() - self.t0) * SPEED
        return t, self.frames[int(t / 0.5) % len(self.frames)]

    def rpm(self) -> float:
        with self.lock:
            return self.rpm_now


@pytest.fixture(scope="module")
def rig_frames() -> list[np.ndarray]:
    from twin.commission.rigs import RigRun, disc_rig, film

    return film(disc_rig(), RigRun(size_px=480, frames=12))


def _dashboard(cam: RigCamera, out: Path, **kw: object) -> Dashboard:
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="manual"))
    state.record(MillState(t_s=0.0, state="running", connected=True, setpoint_rpm=5.0, actual_rpm=cam.rpm()))
    return Dashboard(state, kw.pop("controls", RecordingControls()), port=0,  # type: ignore[arg-type]
                     setup=SetupFeed(cam.frame, cam.rpm, out), **kw)  # type: ignore[arg-type]


@pytest.mark.browser
@pytest.mark.slow
@pytest.mark.timeout(240)
def test_setup_view_commissions_the_live_camera_and_the_report_is_one_click_away(page, rig_frames, tmp_path: Path,
                                                                                monkeypatch) -> None:
    from twin.commission import steps

    # the view's flow, not the calibration's accuracy (``drumtwin commission``'s tests): one confirming run
    monkeypatch.setitem(steps.CALIBRATE, "confirm_evals", 1)
    controls = RecordingControls()
    dash = _dashboard(RigCamera(rig_frames), tmp_path / "run", controls=controls).start()
    try:
        page.goto(dash.url)
        button(page, "Commission from the live camera").wait_for()
        input_by_label(page, "Drum diameter mm").fill("120")
        input_by_label(page, "Drum diameter mm").press("Enter")
        button(page, "Commission from the live camera").click()
        wait_until(lambda: dash.setup.busy, 10, "the set-up to start")
        button(page, "EMERGENCY STOP").click()  # a set-up runs on its own thread: the stop answers at once
        wait_until(lambda: "emergency_stop" in controls.names(), 5, "EMERGENCY STOP during a set-up")
        assert dash.setup.busy
        wait_until(lambda: not dash.setup.busy, 180, "the set-up to finish")
        status = dash.setup.result.status
        assert "check" in status and "set-up stopped" not in status, status  # a verdict (a rig this small: the
        # slope of one seed's bed wanders, so pass or fail is the calibration's; the view shows which)
        page.get_by_role("tab", name="Set-up").click()
        page.locator("#drumtwin-setup").wait_for()
        shown = page.locator("#drumtwin-setup tr").all_inner_texts()[1:]
        report = html.unescape((dash.setup.result.folder / "report.html").read_text())  # type: ignore[operator]
        assert len(shown) >= 11 and all(row.split("\t")[1] in report for row in shown)  # the command's checks
        verdicts = page.locator("#drumtwin-setup td span").all_inner_texts()
        assert len(verdicts) == len(shown) and set(verdicts) <= {"pass", "FAIL"}, verdicts
        folder = dash.setup.result.folder
        assert folder is not None and folder.parent == tmp_path / "run" and (folder / "mixer.toml").is_file()
        with page.expect_download() as dl:
            button(page, "Download the report").click()
        text = Path(dl.value.path()).read_text()
        assert all(f'data-section="{s}"' in text for s, _ in SECTIONS) and "120 mm (given" in text
    finally:
        dash.stop()


@pytest.mark.browser
@pytest.mark.timeout(120)
def test_a_viewer_without_the_token_cannot_start_a_setup_but_may_read_it(page, rig_frames, tmp_path: Path) -> None:
    dash = _dashboard(RigCamera(rig_frames), tmp_path / "run", control_token="s3cret").start()
    try:
        page.goto(dash.url)
        go = button(page, "Commission from the live camera")
        go.wait_for()
        assert go.is_disabled() and not button(page, "Download the report").is_disabled()
        go.click(force=True)  # a disabled control: nothing happens
        button(page, "Download the report").click()  # a later click's answer: the first click's turn is over
        page.get_by_text("no report yet").wait_for()
        assert not dash.setup.busy and dash.setup.result.report is None
    finally:
        dash.stop()


def test_a_setup_refuses_a_stopped_mill_and_stops_when_the_rpm_moves(rig_frames, tmp_path: Path) -> None:
    cam = RigCamera(rig_frames, rpm=0.0)
    dash = _dashboard(cam, tmp_path / "run").start()
    try:
        assert "not turning" in dash.setup.request(120.0) and not dash.setup.busy  # the view never starts the mill
        assert "diameter" in dash.setup.request(float("nan"))
        with cam.lock:
            cam.rpm_now = 5.0
        assert "queued" in dash.setup.request(120.0)
        assert "one at a time" in dash.setup.request(120.0)
        wait_until(lambda: "collecting" in dash.setup.result.status, 10, "frames being collected")
        with cam.lock:
            cam.rpm_now = 8.0  # the operator moved the mill
        wait_until(lambda: not dash.setup.busy, 20, "the set-up to stop")
        assert "rpm changed" in dash.setup.result.status and dash.setup.result.report is None
        assert not (tmp_path / "run").exists()  # nothing written
        assert SETUP_FRAMES >= 5
    finally:
        dash.stop()

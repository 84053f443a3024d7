"""The dashboard's history (issue 40) in the real chromium: the rig's runs read from a real
catalogue of run folders (``twin.catalogue.history``, as a run does at its start) are listed in
the history panel, and the golden batch's MI curve is drawn *behind* the live MI: pixels of the
MI plot's canvas have the golden colour along the golden MI's row, and not where the live trend
crosses it (drawn on top). A rig's first run: a sentence, and no golden pixel left."""

from __future__ import annotations

import base64
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.catalogue_runs import RunSpec, make_run, stamp
from tests.cli import cli
from tests.twin.dashboard_fakes import RecordingControls
from tests.waiting import wait_until
from twin.catalogue.history import load_history
from twin.dashboard import Dashboard
from twin.dashboard.history import GOLDEN_COLOUR, NO_HISTORY
from twin.live.golden import RigHistory
from twin.records import FrameReading, ModeSet
from twin.state import LiveState

GOLDEN_MI = 0.70
T_END_S = 50.0  # the live trend rises 0.5 -> 0.9 over it: it crosses the golden MI at 25 s
LEVELS = {"r0": (GOLDEN_MI, 20.0), "r1": (0.66, 24.5), "r2": (0.75, 31.0)}  # final MI, mixing time s


def live_frames(state: LiveState) -> None:
    for i, t in enumerate(np.arange(0.0, T_END_S, 0.25)):
        mi = 0.5 + 0.4 * t / T_END_S
        state.record(FrameReading(
            t_s=float(t), frame=i, mi=mi, mi_sigmoid=mi, mi_linear=mi, d_px=1.0, dsigma_px=1.0, concentration=0.5,
            slope_deg=30.0, valid=True, trend_mi=mi, trend_lo95=mi - 0.02, trend_hi95=mi + 0.02, trend_rate=0.0,
            ma_mi=mi, twin_mi=None, twin_slope_deg=None, rpm_setpoint=5.0, rpm_actual=5.0, mode="off", flags=()))


def mi_canvas(page) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The MI plot's canvas (BGRA pixels) and its plotting area (x, y, width, height) in canvas px."""
    got = page.evaluate("""() => {
        const u = [...document.querySelectorAll('.uplot')].find(e => e.querySelector('.u-title').innerText
                                                                     === 'Mixing index');
        const c = u.querySelector('canvas'), cb = c.getBoundingClientRect();
        const ob = u.querySelector('.u-over').getBoundingClientRect(), k = c.width / cb.width;
        return {png: c.toDataURL(), box: [(ob.x - cb.x) * k, (ob.y - cb.y) * k, ob.width * k, ob.height * k]}; }""")
    png = base64.b64decode(got["png"].split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED), tuple(got["box"])


def golden_pixels(img: np.ndarray) -> np.ndarray:
    """Where the canvas has the golden curve's colour (opaque, each channel within 30)."""
    rgb = tuple(int(GOLDEN_COLOUR[i:i + 2], 16) for i in (1, 3, 5))
    bgr = np.array(rgb[::-1])
    return (np.abs(img[..., :3].astype(int) - bgr).max(axis=2) < 30) & (img[..., 3] > 200)


def no_golden_curve(img: np.ndarray) -> bool:
    """No golden curve in the canvas: golden-coloured pixels in under 5 % of its columns. A drawn
    curve (4 px wide) crosses the plot; a few stray pixels of that colour (seen once in a live run's
    first batch, most likely the MA150 line's orange anti-aliased over white, which falls within the
    tolerance) are not one."""
    return bool(golden_pixels(img).any(axis=0).mean() < 0.05)


@pytest.mark.browser
@pytest.mark.timeout(120)
def test_history_panel_lists_the_runs_and_the_golden_curve_is_drawn_behind_the_live_mi(page, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    t0 = time.time() - 86400
    for i, (name, (mi, mixing_s)) in enumerate(LEVELS.items()):
        stamp(make_run(runs / name, RunSpec(rig="demo", final_mi=mi, frames=121, mixing_time_s=mixing_s)),
              t0 + 3600 * i)  # 121 rows: 0 to 60 s of run time
    assert cli("runs", "list", "--runs-dir", runs).code == 0
    assert cli("runs", "golden", "r0", "--runs-dir", runs).code == 0
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="off"))
    live_frames(state)
    state.set_rig_history(load_history(None, runs, "demo", this_run=None, floor_mi=0.05))
    dash = Dashboard(state, RecordingControls(), port=0, update_hz=12).start()
    try:
        page.goto(dash.url)
        page.get_by_text("Deviation now").wait_for()
        panel = page.locator("table", has_text="mixing time").inner_text()
        for i, (name, (mi, mixing_s)) in enumerate(LEVELS.items()):  # time, mixing time and final MI of each run
            started = time.strftime("%Y-%m-%d %H:%M", time.localtime(t0 + 3600 * i))
            row = next(ln for ln in panel.splitlines() if ln.startswith(started))
            assert row.split("\t")[2:] == [f"{mixing_s:.1f}", f"{mi:.3f}"], row
            assert ("★" in row) == (name == "r0")  # the golden batch
        assert "behind the golden batch" not in page.locator("body").inner_text()  # 0.898 now, ahead of 0.70

        def curve_drawn() -> bool:
            img, (x, y, w, h) = mi_canvas(page)
            gold = golden_pixels(img)
            row = round(y + (1 - GOLDEN_MI) * h)  # the y scale is pinned to 0..1
            band = gold[row - 3:row + 4].any(axis=0)
            x_cross = round(x + w * 25.0 / (T_END_S - 0.25))  # the live trend crosses the golden MI at 25 s
            left, right = band[round(x) + 2:x_cross - 20], band[x_cross + 20:round(x + w) - 2]
            return (gold.sum() == gold[row - 3:row + 4].sum()  # nowhere but along the golden MI's row
                    and left.mean() > 0.95 and right.mean() > 0.95  # the whole way, before and after the crossing
                    and not band[x_cross - 3:x_cross + 4].any())  # where the live trend crosses: under it

        wait_until(curve_drawn, 20, "the golden curve behind the live MI in the MI plot's pixels")
        page.screenshot(path=str(tmp_path / "history.png"))

        state.set_rig_history(RigHistory("ready", "demo"))  # a rig's first run: nothing to compare with
        page.get_by_text(NO_HISTORY).wait_for()
        wait_until(lambda: no_golden_curve(mi_canvas(page)[0]), 20, "no golden curve in the MI plot")
    finally:
        dash.stop()

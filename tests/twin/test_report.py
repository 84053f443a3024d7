"""``drumtwin report`` (issue 24): one self-contained HTML file, opened in the real chromium
(offline: every request that is not the file itself is counted and refused), every section
there for every run side by side, the plots not blank (coloured pixels of a screenshot of
each plot), a run cut short as by ``kill -9`` still rendered, bad input one line, exit 2.

The run dirs here are written with the real ``RunLog`` (an AUTO run with decisions, the
live endpoint and drive power; an OFF run without endpoint events). The whole-loop version
(real demo runs, one of them killed with SIGKILL) is ``test_report_live.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli import assert_one_line_error, cli
from twin.report import build_report, load_run
from twin.report.build import SECTIONS
from twin.runlog import RunLog
from twin.state import FRAME_ROW_COLUMNS

FPS = 10.0


def mi_curve(t: np.ndarray, tau: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(0.95 - 0.5 * np.exp(-t / tau) + rng.normal(0, 0.01, t.size), 0, 1)


def write_run(d: Path, mode: str, *, seconds: float = 120.0, power: bool = False, endpoint: bool = False,
              killed: bool = False) -> Path:
    cols = (*FRAME_ROW_COLUMNS, "power_w") if power else FRAME_ROW_COLUMNS
    t = np.arange(0.0, seconds, 1 / FPS)
    mi = mi_curve(t, 15.0 if mode == "auto" else 40.0, seed=len(mode))
    rpm = np.where((t > 20) & (mode == "auto"), 25.0, 5.0)
    with RunLog(d, columns=cols) as log:
        log.set_metadata(config={"mode": mode, "case": "C", "speed": 4.0}, versions={"python": "3.x", "numpy": "2"})
        log.event("start", 0.0, mode=mode)
        trend = mi[0]
        for i, ti in enumerate(t):
            trend += 0.1 * (mi[i] - trend)
            row = dict(t_s=ti, frame=i, mi=mi[i], trend_mi=trend, twin_mi=mi[i] + 0.01, rpm_setpoint=rpm[i],
                       rpm_actual=rpm[i], slope_deg=30.0 + rpm[i] / 5, twin_slope_deg=31.0, mode=mode, valid=True,
                       mixed=endpoint and ti >= 70.0, mixing_time_s=60.0 if endpoint and ti >= 70.0 else None)
            if power:
                row["power_w"] = 0.02 * rpm[i] ** 2
            log.frame(row)
        if mode == "auto":
            log.event("decision", 20.0, decision="move", action="set_rpm", rpm=25.0, target_rpm=25.0,
                      reason="segregation (MI 0.6 < 0.88); twin predicts MI 0.95 at 25 rpm")
            log.event("whatif", 19.0, reason="AUTO", predictions={"5.0": 0.8, "25.0": 0.95},
                      energy_to_target_j={"5.0": 150.0, "25.0": 750.0}, time_to_target_s={"5.0": 300.0, "25.0": 60.0},
                      power_w={"5.0": 0.5, "25.0": 12.5}, target_mi=0.9)
        if endpoint:
            log.event("mixed", 70.0, mixing_time_s=60.0, plateau_mi=0.95, reason="trend within +-0.02 for 10 s")
        log.event("fault", 50.0, fault="twin_mismatch", message="twin disagrees")
        if not killed:
            log.event("stop", float(t[-1]), frames=len(t))
    if killed:  # as kill -9 leaves it: a half-written last row, no stop event
        with open(d / "frames.csv", "a", encoding="utf-8") as fh:
            fh.write(f"{seconds:.1f},1700000000.0,99999,0.9")
    return d


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    return {
        "auto": write_run(root / "auto", "auto", power=True, endpoint=True),
        "off": write_run(root / "off", "off"),
        "killed": write_run(root / "killed", "auto", seconds=40.0, killed=True),
    }


def data_pixels(png: bytes) -> int:
    """Pixels of a plot screenshot in the plots' data colours (saturated, not the red of the
    'nothing logged' note): axes, ticks and text are grey or black and do not count."""
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    return int(((s > 90) & (v > 60) & (h >= 10) & (h <= 170)).sum())


def open_report(page, path: Path) -> list[str]:
    """Open the report file; every request beyond the file itself is recorded and refused."""
    outside: list[str] = []

    def guard(route) -> None:
        url = route.request.url
        if url.startswith(("file:", "data:")):
            route.continue_()
        else:
            outside.append(url)
            route.abort()

    page.route("**/*", guard)
    page.goto(path.as_uri())
    page.wait_for_load_state("load")
    return outside


def test_report_of_auto_off_and_killed_runs_in_chromium(page, runs, tmp_path):
    out = tmp_path / "report.html"
    r = cli("report", f"AUTO={runs['auto']}", f"OFF={runs['off']}", runs["killed"], "--out", out)
    assert r.code == 0, r.err
    assert "written to" in r.err
    text = out.read_text()
    assert "http://" not in text and "https://" not in text and "<script" not in text  # nothing to fetch
    outside = open_report(page, out)
    for sid, title in SECTIONS:
        assert page.locator(f"h2#{sid}").inner_text() == title
        for i in range(3):
            sec = page.locator(f'section[data-section="{sid}"][data-run="{i}"]')
            assert sec.count() == 1 and sec.is_visible(), (sid, i)
    # side by side: the three runs' MI sections share one row, left to right
    boxes = [page.locator(f'section[data-section="mi"][data-run="{i}"]').bounding_box() for i in range(3)]
    assert boxes[0]["x"] < boxes[1]["x"] < boxes[2]["x"] and abs(boxes[0]["y"] - boxes[2]["y"]) < 2
    assert page.locator('section[data-section="summary"][data-run="0"] h3').inner_text() == "AUTO"
    # plots: every run has MI, rpm, slope and events; only the AUTO run logged power
    for i in range(3):
        for sid in ("mi", "rpm", "slope", "events"):
            img = page.locator(f"img#plot-{sid}-{i}")
            assert img.evaluate("e => e.complete && e.naturalWidth > 0"), (sid, i)
            n = data_pixels(img.screenshot())
            assert n > (100 if sid == "events" else 300), (sid, i, n)  # events: a few markers
    assert page.locator("img#plot-energy-0").count() == 1 and page.locator("img#plot-energy-1").count() == 0
    assert data_pixels(page.locator("img#plot-energy-0").screenshot()) > 300
    # endpoint: the live event of the AUTO run; the OFF run logged none: its frames' mixed column
    end0 = page.locator('section[data-section="endpoint"][data-run="0"]').inner_text()
    assert "MIXED" in end0 and "60.0 s" in end0 and "source: live" in end0
    end1 = page.locator('section[data-section="endpoint"][data-run="1"]').inner_text()
    assert "mixed column" in end1 and "Not mixed" in end1
    energy0 = page.locator('section[data-section="energy"][data-run="0"]').inner_text()
    assert "150.0" in energy0 and "750.0" in energy0 and "Drive energy used" in energy0
    assert "12.50" in energy0 and "to MI 0.9" in energy0
    assert "No energy logged" in page.locator('section[data-section="energy"][data-run="1"]').inner_text()
    assert '"mode": "off"' in page.locator('section[data-section="config"][data-run="1"]').inner_text()
    assert "numpy" in page.locator('section[data-section="versions"][data-run="0"]').inner_text()
    events0 = page.locator('section[data-section="events"][data-run="0"]').inner_text()
    assert "events" in events0
    page.locator('section[data-section="events"][data-run="0"] summary').click()
    assert "twin predicts MI 0.95" in page.locator('section[data-section="events"][data-run="0"]').inner_text()
    # the killed run: what was logged, and that it did not end cleanly
    k = page.locator('section[data-section="summary"][data-run="2"]').inner_text()
    assert "did not end cleanly" in k and "400" in k  # 40 s x 10 fps rows; the half row dropped
    assert "did not end cleanly" not in page.locator('section[data-section="summary"][data-run="0"]').inner_text()
    assert outside == []


def test_blank_plot_counts_no_data_pixels(page, tmp_path):
    """The pixel check can fail: a run with no frame rows draws axes and a note only."""
    empty = tmp_path / "empty"
    with RunLog(empty, columns=FRAME_ROW_COLUMNS) as log:
        log.event("start", 0.0)
    out = build_report([empty], tmp_path / "r.html")
    open_report(page, out)
    for sid in ("mi", "rpm", "slope"):
        assert data_pixels(page.locator(f"img#plot-{sid}-0").screenshot()) < 50, sid
    assert "no frame rows" in page.locator('section[data-section="summary"][data-run="0"]').inner_text()


def test_killed_run_reads_back_what_was_logged(runs):
    run = load_run(runs["killed"])
    assert run.n_frames == 400 and not run.clean_stop
    assert math.isclose(run.frames.t_max, 39.9)
    assert "1 line of frames.csv skipped: cut off at the end (no newline: the run was writing it)" in run.notes


def test_report_bad_input_is_one_line_exit_2(runs, tmp_path):
    ok = tmp_path / "r.html"
    assert_one_line_error(cli("report", tmp_path / "nope", "--out", ok), "no such run dir")
    (tmp_path / "notarun").mkdir()
    assert_one_line_error(cli("report", tmp_path / "notarun", "--out", ok), "not a run log dir")
    (tmp_path / "file.txt").write_text("x")
    assert_one_line_error(cli("report", tmp_path / "file.txt", "--out", ok), "not a run log dir")
    assert_one_line_error(cli("report", runs["off"], "--out", "/sys/report.html"), "cannot write")
    assert_one_line_error(cli("report", runs["off"], "--out", tmp_path / "missing" / "r.html"), "does not exist")
    assert_one_line_error(cli("report", runs["off"], "--out", tmp_path), "directory")
    assert_one_line_error(cli("report", runs["off"]), "--out")
    assert not ok.exists()


def test_dashboard_numbers_show_the_endpoint_banner():
    from twin.dashboard import numbers_markdown
    from twin.state import Panel

    assert "**MIXED** since 12.3 s" in numbers_markdown(Panel(mixed=True, mixing_time_s=12.3))
    assert "MIXED" not in numbers_markdown(Panel(mixed=False, mixing_time_s=None))


def test_a_batch_that_mixed_and_left_the_band_keeps_its_mixing_time(tmp_path):
    """AUTO stops the mill at the endpoint and the bed then slumps out of the band: the
    report still gives the batch's mixing time and says when it left the band."""
    from twin.report.build import load_run, render_html

    d = write_run(tmp_path / "r", "auto", endpoint=True)
    with open(d / "events.jsonl", "a", encoding="utf-8") as fh:
        fh.write('{"kind": "unmixed", "t_s": 90.0, "reason": "trend 0.87 < 0.90 for 5 s"}\n')
    page = render_html([load_run(str(d))])
    assert "MIXED at 70.0 s" in page and ">60.0 s</b>" in page and "left the band again at 90.0 s" in page
    assert "MIXED: mixing time" not in page  # not mixed at the end


def test_the_report_compares_the_twins_time_to_mix_with_the_plants(tmp_path):
    """A constructed AUTO run: a first move at 30 s is cut short (the safe state: the mill never gets to
    45 rpm), the second at 50 s ramps 5 -> 45 rpm by 60 s and carries the twin's 16 s; the camera MI sits
    at 0.8 with a 1 s touch of 0.97 at 52 s and is 0.95 from 70 s on. The plant's time is counted from
    the decision that got the mill there, to MI that reached the target and stayed (not the touch):
    20.3 s, so the error is (16 - 20.3) / 20.3 = -21 %; the HTML shows it."""
    from twin.report import time_to_mix_check
    from twin.report.build import render_html

    d = tmp_path / "ttm"
    t = np.arange(0.0, 120.0, 1 / FPS)
    rng = np.random.default_rng(3)
    mi = np.where(t >= 70.0, 0.95, 0.8) + rng.normal(0, 0.005, t.size)
    mi[(t >= 52.0) & (t < 53.0)] = 0.97
    rpm = np.where(t < 50.0, 5.0, np.minimum(45.0, 5.0 + 4.0 * (t - 50.0)))
    with RunLog(d, columns=FRAME_ROW_COLUMNS) as log:
        log.set_metadata(config={"mode": "auto", "target_mi": 0.9})
        log.event("start", 0.0, mode="auto")
        for i, ti in enumerate(t):
            log.frame(dict(t_s=ti, frame=i, mi=mi[i], trend_mi=mi[i], rpm_setpoint=rpm[i], rpm_actual=rpm[i],
                           mode="auto", valid=True))
        log.event("whatif", 29.0, reason="AUTO", requested_t_s=20.0, predictions={"5.0": 0.8, "45.0": 0.96},
                  time_to_target_s={"5.0": math.nan, "45.0": 16.0}, target_mi=0.9)
        for t_d in (30.0, 50.0):
            log.event("decision", t_d, decision="move", action="set_rpm", rpm=9.0, target_rpm=45.0, reason="x",
                      predictions={"5.0": 0.8, "45.0": 0.96}, predicted_time_to_target_s=16.0, prediction_t_s=19.0)
        log.event("stop", 119.9, frames=len(t))
    c = time_to_mix_check(load_run(d))
    assert c is not None
    assert c["t_decision_s"] == 50.0 and c["rpm"] == 45.0 and c["t_reached_s"] == pytest.approx(59.8, abs=0.11)
    assert c["predicted_s"] == 16.0 and c["state_t_s"] == 20.0 and c["target_mi"] == 0.9
    assert c["actual_s"] == pytest.approx(20.3, abs=0.3)
    assert c["error_pct"] == pytest.approx(100 * (16.0 - c["actual_s"]) / c["actual_s"])
    assert -25 < c["error_pct"] < -18
    assert c["plant_mi_at_decision"] == pytest.approx(0.8, abs=0.01)  # the raw MI's 2 s mean there
    assert c["twin_mi_at_state"] is None  # no twin column logged
    page = render_html([load_run(d)])
    assert "Twin&#x27;s time to mix against the plant&#x27;s" in page or "Twin's time to mix" in page
    assert f'<b class="ttm-error">{c["error_pct"]:+.0f}</b>' in page
    # an older run log without the decision's field: the prediction is the study's, matched by its predictions
    lines = (d / "events.jsonl").read_text(encoding="utf-8").splitlines()
    (d / "events.jsonl").write_text("\n".join(ln.replace('"predicted_time_to_target_s": 16.0, ', "")
                                              for ln in lines) + "\n", encoding="utf-8")
    assert time_to_mix_check(load_run(d))["predicted_s"] == 16.0

"""The endpoint on the embedded demo and ``drumtwin report`` of real demo runs (issue 24).

Two demo runs (Case C, ``--speed 4``, the drive started at 45 rpm, where the plant's bed
stays mixed): AUTO with ``stop_at_endpoint`` (the endpoint is detected live, an ``endpoint``
decision stops the mill through the supervisor, the board stops), and OFF in a separate
process killed with SIGKILL once its ``mixed`` event is logged (the endpoint is only
reported: no decision, the board keeps its 45 rpm). The report of both opens in chromium
with every section and plots that are not blank.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.cli import cli
from tests.twin.test_report import data_pixels, open_report
from tests.waiting import wait_until
from twin.config import RunConfig
from twin.records import DecisionMade, FrameReading, Record
from twin.report.build import SECTIONS
from twin.run.main import run_live
from twin.run.settings import Seams
from twin.runlog import read_events, read_frames

pytestmark = [pytest.mark.xdist_group("live"), pytest.mark.slow]

SPEED = 4.0
MIXED_RPM = 45.0  # the demo plant's bed stays mixed at 45 rpm (MI ~0.95); at 5 rpm it segregates

OFF_SCRIPT = """
import sys
from twin.config import RunConfig
from twin.run.main import run_live
cfg = RunConfig(dashboard=False, duration_s=600.0, speed={speed}, case="C", seed=0, mode="off",
                start_rpm={rpm}, log_dir=sys.argv[1]).resolved()
run_live(cfg)
"""


AFTER_STOP_S = 12.0  # run time logged after the endpoint's stop (the test reads the board's rpm from 10 s on)


@pytest.fixture(scope="module")
def auto_run(tmp_path_factory) -> Path:
    """AUTO until ``AFTER_STOP_S`` after its endpoint decision (the stop came at ~13.5 s of run
    time), at most 40 s (a run that never stops ends there, and the tests fail on it)."""
    d = tmp_path_factory.mktemp("endpoint") / "auto"

    def end_after_the_stop(loop, plant, dash) -> None:
        stop_t: list[float] = []  # the endpoint decision's run time

        def on_record(rec: Record) -> None:  # on the publishing worker's thread, as records come
            if isinstance(rec, DecisionMade) and rec.decision == "endpoint":
                stop_t.append(rec.t_s)
            elif isinstance(rec, FrameReading) and stop_t and rec.t_s >= stop_t[0] + AFTER_STOP_S:
                loop.stop_event.set()

        loop.events.bus.subscribe(on_record)

    cfg = RunConfig(dashboard=False, duration_s=40.0, speed=SPEED, case="C", seed=0, mode="auto",
                    start_rpm=MIXED_RPM, stop_at_endpoint=True, log_dir=d).resolved()
    run_live(cfg, Seams(on_started=end_after_the_stop))
    return d


@pytest.fixture(scope="module")
def killed_off_run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("endpoint") / "off"
    code = OFF_SCRIPT.format(speed=SPEED, rpm=MIXED_RPM)
    proc = subprocess.Popen([sys.executable, "-c", code, str(d)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    def rows() -> int:
        return len(read_frames(d)) if (d / "frames.csv").exists() else 0

    try:
        wait_until(lambda: proc.poll() is not None or (
            (d / "events.jsonl").exists() and any(e["kind"] == "mixed" for e in read_events(d))), 240,
            "the OFF run's mixed event")
        at_mixed = rows()
        wait_until(lambda: proc.poll() is not None or rows() >= at_mixed + 20, 60, "20 more rows after the event")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    return d


@pytest.mark.timeout(400)
def test_auto_stops_the_demo_mill_at_the_endpoint(auto_run):
    ev = read_events(auto_run)
    mixed = [e for e in ev if e["kind"] == "mixed"]
    assert mixed, [e["kind"] for e in ev]
    m = mixed[0]
    assert m["mixing_time_s"] is not None and m["mixing_time_s"] < m["t_s"] and m["plateau_mi"] >= 0.9
    stops = [e for e in ev if e["kind"] == "decision" and e["decision"] == "endpoint"]
    assert len(stops) == 1 and stops[0]["action"] == "stop" and stops[0]["mode"] == "auto"
    assert stops[0]["t_s"] >= m["t_s"] and "stop at endpoint" in stops[0]["reason"]
    assert "mixing time" in stops[0]["reason"]
    sent = [e for e in ev if e["kind"] == "mill_command" and e["command"] == "stop"]
    assert sent and sent[0]["source"] == "supervisor"
    assert not [e for e in ev if e["kind"] == "mill_command" and e["command"] == "set_rpm"]
    rows = read_frames(auto_run)
    late = [r["rpm_actual"] for r in rows if r["t_s"] > stops[0]["t_s"] + 10.0 and r["rpm_actual"] is not None]
    assert late and max(late) < 1.0  # the board really stopped
    assert any(r["mixed"] == 1.0 and r["mixing_time_s"] == pytest.approx(m["mixing_time_s"]) for r in rows)


@pytest.mark.timeout(400)
def test_off_only_reports_the_endpoint(killed_off_run):
    ev = read_events(killed_off_run)
    assert any(e["kind"] == "mixed" for e in ev)
    assert not any(e["kind"] == "decision" for e in ev)
    assert [e["command"] for e in ev if e["kind"] == "mill_command"] == ["start"]  # the demo operator's
    assert not any(e["kind"] == "stop" for e in ev)  # killed: no stop event
    rpm = np.array([r["rpm_actual"] for r in read_frames(killed_off_run)[-20:]], dtype=float)
    assert np.all(rpm > MIXED_RPM - 2.0)


@pytest.mark.browser
@pytest.mark.timeout(400)
def test_report_of_real_auto_and_killed_off_runs(page, auto_run, killed_off_run, tmp_path):
    out = tmp_path / "report.html"
    r = cli("report", f"AUTO={auto_run}", f"OFF={killed_off_run}", "--out", out)
    assert r.code == 0, r.err
    outside = open_report(page, out)
    assert outside == []
    for sid, _ in SECTIONS:
        for i in range(2):
            assert page.locator(f'section[data-section="{sid}"][data-run="{i}"]').is_visible(), (sid, i)
    for i in range(2):
        for sid in ("mi", "rpm", "slope", "events"):
            n = data_pixels(page.locator(f"img#plot-{sid}-{i}").screenshot())
            assert n > (100 if sid == "events" else 300), (sid, i, n)
        end = page.locator(f'section[data-section="endpoint"][data-run="{i}"]').inner_text()
        assert "MIXED" in end and "source: live" in end
    assert "did not end cleanly" in page.locator('section[data-section="summary"][data-run="1"]').inner_text()
    assert "did not end cleanly" not in page.locator('section[data-section="summary"][data-run="0"]').inner_text()
    assert "stop at endpoint" in page.content()

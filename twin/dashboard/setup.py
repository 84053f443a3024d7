"""The dashboard's set-up view (issue 39): commissioning on the live camera, the mill turning at the rpm
the operator set. One press of **Commission from the live camera** collects ``SETUP_FRAMES`` frames of
the running drum (one every ``SETUP_EVERY_S`` of run time), runs every step of ``twin.commission.steps``
on them and shows the same checks as ``drumtwin commission`` (value, tolerance, verdict, what to do);
``mixer.toml`` and ``report.html`` are written beside the run's log, and **Download the report** hands
the report to the viewer who asks (one click).

Rules: the view never moves the mill (the operator starts it at the rpm to commission at, with the
controls); it refuses to start on a stopped mill and abandons a set-up whose rpm changes while its frames
are collected. Its button is a control (the token rule: a read-only viewer cannot start one, and every
callback re-checks); seeing the checks and downloading the report is for every viewer. The work runs on
the view's own thread (``start``/``stop`` with the dashboard's), never in a viewer's callback, so
EMERGENCY STOP answers at once while a set-up runs.
"""

from __future__ import annotations

import html
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import viser

from twin.commission.checks import failed
from twin.report.build import table

SETUP_FRAMES = 24  # frames collected from the live camera
SETUP_EVERY_S = 0.5  # run time between them (s): 12 s of the turning drum
RPM_STEADY = 0.05  # the mill's rpm may move this share (+ 0.1 rpm) while the frames are collected
DEFAULT_DIAMETER_MM = 250.0


@dataclass(frozen=True)
class SetupFeed:
    """What the set-up view reads of the run (read-only): the camera's newest raw frame (run time s and
    BGR image; None before the first), the mill's actual rpm, and the folder commissioning writes into."""

    frame: Callable[[], tuple[float | None, np.ndarray | None]]
    rpm: Callable[[], float]
    out_dir: Path


@dataclass
class _Result:
    """The newest set-up's outcome: its folder, report and checks (HTML), or why it stopped."""

    status: str = "No set-up yet: start the mill at the rpm to commission at, then press **Commission**."
    checks_html: str = ""
    report: bytes | None = None
    folder: Path | None = None


def checks_html(checks: list) -> str:
    """The checks as the report shows them (``twin.commission.report.check_rows``), for the dashboard."""
    from twin.commission.report import check_rows

    head = ("step", "check", "value", "against", "tolerance", "verdict", "what to do", "how")
    style = ('<style>.pass{color:#1b5e20;font-weight:bold}.fail{color:#b71c1c;font-weight:bold}'
             "#drumtwin-setup td,#drumtwin-setup th{border:1px solid #ddd;padding:1px 4px;font-size:11px}</style>")
    return f'{style}<div id="drumtwin-setup">{table(check_rows(checks), head)}</div>'


class SetupView:
    """The set-up tab (shared: status and checks) and each viewer's set-up controls (see module doc)."""

    def __init__(self, server: viser.ViserServer, panel: viser.PanelHandle, feed: SetupFeed | None) -> None:
        self._server = server
        self.feed = feed
        self._jobs: queue.SimpleQueue[float | None] = queue.SimpleQueue()
        self._busy = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        none = "No live camera in this run: set-up needs one (`drumtwin commission` takes files)."
        self.result = _Result() if feed is not None else _Result(status=none)
        with panel.add_tab("Set-up"):
            self._status = server.gui.add_markdown(self.result.status)
            self._checks = server.gui.add_html("")

    # -- the view's thread (started and joined with the dashboard) ------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="dashboard-setup", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._jobs.put(None)
        if self._thread is not None:
            self._thread.join(timeout=10)

    @property
    def busy(self) -> bool:
        return self._busy.is_set()

    def request(self, diameter_mm: float) -> str:
        """Queue a set-up of a drum ``diameter_mm`` across; what to tell the viewer (Markdown)."""
        if self.feed is None:
            return "**set-up needs a live camera**"
        if not (math.isfinite(diameter_mm) and 10.0 <= diameter_mm <= 1e4):
            return f"**drum diameter must be 10..10000 mm (got {diameter_mm:g})**"
        rpm = self.feed.rpm()
        if not (math.isfinite(rpm) and rpm > 0):
            return "**the mill is not turning: start it at the rpm to commission at (MANUAL, rpm, Start)**"
        if self._busy.is_set():
            return "**a set-up is running: one at a time**"
        self._busy.set()
        self._jobs.put(float(diameter_mm))
        return f"set-up queued: {SETUP_FRAMES} frames at {rpm:.1f} rpm"

    def _say(self, status: str, checks: str | None = None) -> None:
        with self._lock:
            self.result.status = status
            self._status.content = status
            if checks is not None:
                self.result.checks_html = checks
                self._checks.content = checks

    def _run(self) -> None:
        while not self._stop.is_set():
            d = self._jobs.get()
            if d is None:
                return
            try:
                self._commission(d)
            except Exception as exc:  # bad input (no drum, one colour, ...) or a failure: said, never raised
                why = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
                self._say(f"**set-up stopped:** {html.escape(why)}")
            finally:
                self._busy.clear()

    def _collect(self) -> tuple[list[tuple[str, np.ndarray]], float]:
        """``SETUP_FRAMES`` frames of the live camera, ``SETUP_EVERY_S`` of run time apart, and the
        mill's rpm over them (a ``ValueError`` when it moves, the camera stops or the view stops)."""
        assert self.feed is not None
        rpm0 = self.feed.rpm()
        got: list[tuple[str, np.ndarray]] = []
        last, idle = -math.inf, time.monotonic()
        while len(got) < SETUP_FRAMES:
            if self._stop.wait(0.02):
                raise ValueError("the dashboard stopped")
            t, img = self.feed.frame()
            rpm = self.feed.rpm()
            if not (abs(rpm - rpm0) <= RPM_STEADY * abs(rpm0) + 0.1):
                raise ValueError(f"the mill's rpm changed during set-up ({rpm0:.1f} -> {rpm:.1f}): keep it steady")
            if t is None or img is None or t < last + SETUP_EVERY_S:
                if time.monotonic() - idle > 30.0:
                    raise ValueError("no new camera frame for 30 s")
                continue
            got.append((f"live {t:.1f} s", img))
            last, idle = t, time.monotonic()
            self._say(f"collecting the live camera's frames: {len(got)} of {SETUP_FRAMES} at {rpm0:.1f} rpm")
        return got, rpm0

    def _commission(self, diameter_mm: float) -> None:
        from twin.commission.output import default_out, write_outputs
        from twin.commission.source import with_drums
        from twin.commission.steps import Given, commission

        assert self.feed is not None
        named, rpm = self._collect()
        steps: list[str] = []

        def progress(step: str, message: str) -> None:
            steps.append(f"{step}: {message}")
            self._say("  \n".join(["**set-up running**", *steps[-3:]]))

        g = Given(("live camera",), diameter_mm, rpm)
        c = commission(g, progress, with_drums(named))
        self.feed.out_dir.mkdir(parents=True, exist_ok=True)
        folder = self.feed.out_dir / default_out().name
        _, report = write_outputs(c, folder)
        bad = failed(c.checks)
        with self._lock:
            self.result.report = report.read_bytes()
            self.result.folder = folder
        verdict = (f"**every check passed ({len(c.checks)})**" if not bad else
                   f"**{len(bad)} of {len(c.checks)} checks failed**")
        self._say(f"{verdict} at {rpm:.1f} rpm: `{folder}` ({c.cpu_s:.0f} s CPU)", checks_html(c.checks))

    # -- each viewer's controls --------------------------------------------------------------------------
    def build(self, gui: viser.GuiApi, authorised: bool, guarded: Callable[[Callable[[viser.GuiEvent], None]],
                                                                           Callable[[viser.GuiEvent], None]],
              say: Callable[[str], None],
              client: viser.ClientHandle) -> tuple[viser.GuiNumberHandle[float], viser.GuiButtonHandle]:
        """One viewer's set-up controls (``guarded``: its authorisation re-checked per callback); the
        handles a read-only viewer has disabled."""
        diameter = gui.add_number("Drum diameter mm", DEFAULT_DIAMETER_MM, min=10.0, max=1e4, step=1.0,
                                  disabled=not authorised, hint="the drum's inner diameter (the camera has no scale)")
        go = gui.add_button("Commission from the live camera", icon=viser.Icon.CHECKLIST, disabled=not authorised,
                            hint=f"{SETUP_FRAMES} frames of the turning drum, then every set-up step and check")
        report = gui.add_button("Download the report", icon=viser.Icon.DOWNLOAD,
                                hint="the newest set-up's report.html (self-contained)")
        go.on_click(guarded(lambda e: say(self.request(float(diameter.value)))))

        @report.on_click
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            with self._lock:
                data, folder = self.result.report, self.result.folder
            if data is None:
                say("no report yet: press **Commission from the live camera**")
                return
            client.send_file_download(f"{folder.name if folder else 'commission'}-report.html", data,
                                      save_immediately=True)  # one click: saved, not a link to click again

        return diameter, go


__all__ = ["RPM_STEADY", "SETUP_EVERY_S", "SETUP_FRAMES", "SetupFeed", "SetupView", "checks_html"]

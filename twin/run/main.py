"""The entry point of a run, demo and hardware alike: :func:`run_live` builds the plant (demo) or
opens the camera, the mill link, the run log, the dashboard's state, the ``LiveLoop`` and the
dashboard, starts them in order (the demo's start is a small plan, :class:`DemoStart`), waits
and shuts them down. The CLI (``drumtwin run``) only parses, and calls it with its progress bar.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING

from twin.clock import RunClock
from twin.config import RunConfig
from twin.errors import RunFailed, TwinError
from twin.live.mill import MillLink
from twin.records import CatalogueUnavailable, MillState, Record
from twin.run.loop import LiveLoop, Summary
from twin.run.metadata import mixer_metadata, versions
from twin.run.settings import RunInputs, Seams, endpoint_config, mill_url, resolve_inputs
from twin.state import LiveState

if TYPE_CHECKING:
    import numpy as np

    from twin.catalogue.hook import RunIndexer
    from twin.dashboard import Dashboard
    from twin.demo import DemoPlant
    from twin.runlog import RunLog
    from vision.roi import DrumROI
    from vision.sources import Frame


def open_mill(url: str) -> MillLink:
    """The run's mill client: opened now (``ConnectionError`` when it cannot be), with no
    thread of its own (the mill worker is its one user and poller). A ``modbus:`` URL is a
    frequency inverter (``control.modbus.link.ModbusMill``: its comm-loss trip is checked
    now, a ``ControlError`` when it is unsafe and not overridden); anything else is the
    line protocol's board."""
    if url.startswith("modbus:"):
        from control.modbus.link import ModbusMill

        return ModbusMill(url, connect=True)
    from control.driver import MillClient

    return MillClient(url, heartbeat_s=None, connect=True)


class DemoStart:
    """The demo's start plan: once the mill worker has read the board (its first connected
    ``MillState`` record on the run's bus, at most ``connect_timeout_s`` wall), the plant's
    front panel spins the drive at its start rpm and the demo's operator presses Start (the
    loop then feeds the board's watchdog). A hardware run has no plan: its operator starts
    the mill from the dashboard."""

    def __init__(self, plant: DemoPlant, connect_timeout_s: float = 20.0) -> None:
        self.plant = plant
        self.connect_timeout_s = connect_timeout_s
        self._connected = threading.Event()

    def record(self, rec: Record) -> None:
        """The bus subscriber: the mill is connected."""
        if isinstance(rec, MillState) and rec.connected:
            self._connected.set()

    def execute(self, loop: LiveLoop) -> None:
        end = time.monotonic() + self.connect_timeout_s
        while not self._connected.wait(0.05) and time.monotonic() < end and not loop.stop_event.is_set():
            pass
        self.plant.start_drive()
        loop.controls.start_mill()


def _paced(frames: Iterator[Frame], clock: RunClock) -> Iterator[Frame]:
    """Replay a recording at its own speed (``frame.t_s`` on the run clock)."""
    t0 = None
    for f in frames:
        t0 = f.t_s if t0 is None else t0
        if not clock.sleep_until(f.t_s - t0):
            return
        yield f


def check_scheduler_answers(address: str, timeout_s: float = 3.0) -> None:
    """TwinError (one line) unless something accepts a TCP connection at the Dask
    scheduler ``address`` within ``timeout_s`` (a dead or garbage address is refused at
    the start of the run, not found by the first what-if study in AUTO)."""
    import socket

    from twin.config import check_scheduler

    host, port = check_scheduler(address)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        raise TwinError(f"--scheduler {address}: no Dask scheduler answers ({exc.strerror or exc})") from None


@dataclass
class _Parts:
    """What a run has opened so far (closed in reverse by :meth:`close`, whatever failed)."""

    plant: DemoPlant | None = None
    mill: MillLink | None = None
    runlog: RunLog | None = None
    loop: LiveLoop | None = None
    dash: Dashboard | None = None
    index: RunIndexer | None = None

    def open_sources(self, cfg: RunConfig, inputs: RunInputs, seams: Seams,
                     clock: RunClock) -> tuple[Iterable[Frame], MillLink, DrumROI | None]:
        """The demo's plant or the camera (video), and the mill link: opened first, so a URL
        that cannot be opened raises ``ConnectionError`` before any log or thread exists."""
        from vision.sources import open_source

        if cfg.demo:
            from twin.demo import DemoPlant, PlantConfig

            plant_cfg = PlantConfig(case=cfg.case, seed=cfg.seed, start_rpm=cfg.start_rpm, fps=cfg.camera_fps,
                                    size_px=cfg.frame_px, drive=cfg.drive)
            if seams.plant_watchdog_s is not None:
                plant_cfg = replace(plant_cfg, watchdog_s=seams.plant_watchdog_s)
            self.plant = plant = DemoPlant(plant_cfg, clock)
            self.mill = mill = open_mill(plant.url)
            return plant.frames(), mill, plant.roi
        self.mill = mill = open_mill(mill_url(cfg, inputs))
        if cfg.video is not None:
            return _paced(open_source(str(cfg.video)), clock), mill, inputs.roi
        return open_source(cfg.camera), mill, inputs.roi

    def open_log(self, cfg: RunConfig) -> RunLog:
        from twin import runlog as logs  # looked up per run (a test stands a full disk in for RunLog)

        self.runlog = runlog = logs.RunLog(cfg.log_dir or logs.default_run_dir())  # columns: twin.records.FRAME_COLUMNS
        runlog.set_metadata(config=cfg.to_metadata(), versions=versions(),
                            started=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
        if self.plant is not None:
            runlog.set_metadata(plant=asdict(self.plant.config), mill_url="emulator pty")
        return runlog

    def open_index(self, cfg: RunConfig, inputs: RunInputs, loop: LiveLoop) -> str:
        """The run in the catalogue: its rig and process in ``metadata.json``, then registered
        (running); a catalogue that cannot be written is a warning and a record, not an end.
        Returns the rig's name."""
        from twin.catalogue.hook import RunIndexer, run_metadata

        assert self.runlog is not None
        from twin.runlog import to_jsonable

        mixer = mixer_metadata(inputs.mixer) if inputs.mixer is not None else None
        meta = run_metadata(cfg.meter_config, mixer, to_jsonable(inputs.classes))
        loop.events.metadata(**meta)

        def unavailable(message: str) -> None:
            loop.events.publish(CatalogueUnavailable(t_s=loop.now_s(), message=message))

        self.index = index = RunIndexer(cfg.catalogue, self.runlog.paths.directory, unavailable)
        index.index("start")
        return str(meta["rig"]["name"])

    def open_history(self, cfg: RunConfig, seams: Seams, loop: LiveLoop, rig: str) -> None:
        """The rig's history read once on a thread of the run (``twin.catalogue.history``): the
        dashboard's panel and the golden batch, which a ``GoldenWatch`` on the run's bus compares
        each frame with (``slower_than_golden``; the spread's floor and the dwell are the
        endpoint's ``exit_band`` and ``exit_dwell_s``, ``twin.live.golden``)."""
        from twin.catalogue.history import HistoryJob
        from twin.live.golden import GoldenWatch

        assert self.runlog is not None and self.index is not None
        ends, index = endpoint_config(cfg, seams), self.index
        watch = GoldenWatch(loop.events.publish, ends.exit_dwell_s)
        loop.events.bus.subscribe(watch.record)
        job = HistoryJob(cfg.catalogue, self.runlog.paths.directory.parent, rig, lambda: index.id, ends.exit_band,
                         loop.state.set_rig_history, watch.set_golden)
        loop.run_beside("history", job.run)

    def open_dashboard(self, cfg: RunConfig, state: LiveState, loop: LiveLoop,
                       on_dashboard: Callable[[str], None] | None) -> None:
        from twin.dashboard import Dashboard
        from twin.dashboard.setup import SetupFeed

        assert self.runlog is not None  # opened before the loop
        view = loop.view

        def frame() -> tuple[float | None, np.ndarray | None]:
            cam = view.camera()  # one snapshot: the raw frame (no overlay) and its run time together
            return cam.t_s, cam.image

        setup = SetupFeed(frame=frame, rpm=lambda: view.mill().actual_rpm, out_dir=self.runlog.paths.directory)
        self.dash = dash = Dashboard(
            state, loop.controls, host=cfg.host, port=cfg.port, control_token=cfg.control_token,
            update_hz=cfg.dashboard_hz, on_event=loop.events.publish, now_s=loop.now_s,
            limits=loop.limits, estop_needs_token=cfg.estop_needs_token, setup=setup,
        ).start()
        if on_dashboard is not None:
            on_dashboard(dash.url)
        self.runlog.set_metadata(dashboard_url=dash.url)

    def close(self, clock: RunClock, wall_s: float) -> Summary | None:
        """Stop and close everything opened (the loop joins its workers, closes the what-if
        pool and the mill link); the run's summary once the loop existed."""
        clock.stop.set()
        if self.loop is not None:
            self.loop.stop()
        elif self.mill is not None:
            self.mill.close()
        if self.dash is not None:
            self.dash.stop()
        if self.plant is not None:
            self.plant.close()
        summary = None
        if self.runlog is not None:
            if self.loop is not None:
                summary = self.loop.summary(wall_s)
                self.loop.events.metadata(summary=asdict(summary))
            if self.index is not None:
                self.index.index("stop")
            self.runlog.close()
        return summary


def _wait_plain(loop: LiveLoop) -> None:
    loop.wait(loop.config.duration_s)


def run_live(
    cfg: RunConfig,
    seams: Seams | None = None,
    *,
    wait: Callable[[LiveLoop], None] = _wait_plain,
    on_dashboard: Callable[[str], None] | None = None,
) -> Summary:
    """The one composition root of a run, demo and hardware alike: builds the plant (demo)
    or opens the camera, the mill link, the run log, the dashboard's state, the loop and the
    dashboard; starts them in order (the demo's :class:`DemoStart` plan once the loop runs;
    then ``seams.on_started``); ``wait(loop)`` blocks until the run is over (the CLI's
    progress bar; default: the duration); then stops everything and returns the ``Summary``.

    The mill link is opened first: a URL that cannot be opened raises ``ConnectionError``
    before anything else starts (the CLI exits 2). A run that had to end (its log could not
    be written, an essential worker crashed: ``LiveLoop.failure``) raises ``RunFailed`` once
    it is shut down. ``on_dashboard(url)``: told the dashboard's address once it serves.
    """
    seams = seams or Seams()
    if cfg.scheduler is not None:
        check_scheduler_answers(cfg.scheduler)  # before anything starts: one line, exit 2
    cfg, inputs = resolve_inputs(cfg)
    clock = RunClock(cfg.speed)
    parts = _Parts()
    t_wall = time.monotonic()
    try:
        frames, mill, roi = parts.open_sources(cfg, inputs, seams, clock)
        runlog = parts.open_log(cfg)
        state = LiveState()
        parts.loop = loop = LiveLoop(cfg, frames, mill, runlog, state, clock=clock, roi=roi, classes=inputs.classes,
                                     mixer=inputs.mixer, meter_config=inputs.meter_config, seams=seams)
        if inputs.mixer is not None:
            runlog.set_metadata(mixer=mixer_metadata(inputs.mixer))
        parts.open_history(cfg, seams, loop, parts.open_index(cfg, inputs, loop))
        if cfg.dashboard:
            parts.open_dashboard(cfg, state, loop, on_dashboard)
        plan = DemoStart(parts.plant) if parts.plant is not None else None
        if plan is not None:
            loop.events.bus.subscribe(plan.record)
        loop.warm_up()  # compile before the clock runs, not while the camera does
        clock.restart()  # run time 0 = the workers start (the plant's first frame is due now)
        loop.start()
        if plan is not None:
            plan.execute(loop)
        if seams.on_started is not None:
            seams.on_started(loop, parts.plant, parts.dash)
        wait(loop)
    finally:
        summary = parts.close(clock, time.monotonic() - t_wall)
    if parts.loop is not None and parts.loop.failure is not None:
        loop = parts.loop
        raise RunFailed(f"the run stopped: {loop.failure} (log in {loop.runlog.paths.directory})", loop.exit_code)
    assert summary is not None  # the run log exists once the loop does
    return summary


__all__ = ["DemoStart", "check_scheduler_answers", "open_mill", "run_live"]

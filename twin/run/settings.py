"""A run's settings and their layering: what ``drumtwin run`` uses of each class's defaults, the
user's config file and options, and the typed test seams.

Layers, lowest first: the settings classes' own defaults (``SupervisorConfig``, ``Limits``,
``TrendConfig``: they ARE a run's), the run's endpoint target (:data:`LOOP_ENDPOINT`), the meter
config file's ``[endpoint]`` table and ``[drive]`` (:func:`resolve_inputs`), the command's options
(``RunConfig``), then a test's :class:`Seams`. The drum's critical speed comes from the twin's
drum (``sim.recipe``: the one formula).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from control.endpoint import EndpointConfig, endpoint_settings
from control.limits import Limits
from control.supervisor_config import SupervisorConfig
from control.trend import TrendConfig
from twin.config import RunConfig
from twin.live.faults import NO_FAULTS, FaultHooks
from twin.live.mismatch import MismatchTolerance
from twin.live.whatif import Study

if TYPE_CHECKING:
    from sim.mixer import Mixer
    from twin.dashboard import Dashboard
    from twin.demo import DemoPlant
    from twin.run.loop import LiveLoop
    from vision.colours import ColourClass
    from vision.config import MeterConfig
    from vision.roi import DrumROI

Overrides = Mapping[str, float | int | bool]
"""Field overrides of a settings dataclass (names checked by the dataclass: a typo is a TypeError)."""

# Endpoint settings of the live loop (control.endpoint; docs/endpoint.md): a mixed bed's camera MI is
# ~0.93-0.95, a radially segregated one ~0.80-0.85. ``--target-mi`` and ``Seams.endpoint`` override.
LOOP_ENDPOINT: dict[str, float | int | bool] = dict(target_mi=0.9)


@dataclass(frozen=True)
class Seams:
    """What a test (or a bench) may change about a run, typed; a production run uses the
    defaults. ``supervisor`` / ``limits`` / ``trend`` / ``endpoint``: overrides of the run's
    ``SupervisorConfig`` / ``Limits`` / ``TrendConfig`` / ``EndpointConfig``; ``calibrate``:
    keyword arguments of the twin's calibration (``sim.calibrate``); ``whatif_study``: runs
    what-if jobs instead of the process pool; ``mismatch``: the twin-against-camera tolerance;
    ``plant_watchdog_s``: the demo board's watchdog (wall s); ``on_started(loop, plant,
    dashboard)``: called once everything runs; ``faults``: faults injected into the workers at
    their named points (``twin.live.faults.FaultHooks``)."""

    supervisor: Overrides = field(default_factory=dict)
    limits: Overrides = field(default_factory=dict)
    trend: Overrides = field(default_factory=dict)
    endpoint: Overrides = field(default_factory=dict)
    calibrate: Overrides = field(default_factory=dict)
    whatif_study: Study | None = None
    mismatch: MismatchTolerance = field(default_factory=MismatchTolerance)
    plant_watchdog_s: float | None = None
    on_started: Callable[[LiveLoop, DemoPlant | None, Dashboard | None], None] | None = None
    faults: FaultHooks = NO_FAULTS


def endpoint_config(config: RunConfig | None = None, seams: Seams | None = None) -> EndpointConfig:
    """The endpoint detector's settings for a run (``RunConfig.endpoint``, ``RunConfig.target_mi``, then
    ``seams.endpoint`` override ``LOOP_ENDPOINT``, which overrides ``EndpointConfig``'s defaults)."""
    target = {} if config is None or config.target_mi is None else {"target_mi": float(config.target_mi)}
    options = {} if config is None else dict(config.endpoint)  # --endpoint-* (twin.config.endpoint_options)
    over = seams.endpoint if seams is not None else {}
    return endpoint_settings({**LOOP_ENDPOINT, **options, **target, **over})


def trend_config(seams: Seams | None = None) -> TrendConfig:
    """The Kalman trend's settings for a run: ``TrendConfig``'s defaults (the noise is estimated on
    line and re-initialisation is decided on the share of rejections, so camera MI needs no
    run-specific tuning; issue 21), ``seams.trend`` over them."""
    return TrendConfig(**(seams.trend if seams is not None else {}))  # type: ignore[arg-type]


def supervisor_config(
    seams: Seams | None = None, critical_rpm: float | None = None, config: RunConfig | None = None
) -> SupervisorConfig:
    """The supervisor's settings for a run: ``SupervisorConfig``'s and ``Limits``' defaults with
    the critical speed of the twin's drum (``critical_rpm``, the mixer's drum's; default the
    paper's: ``sim.recipe``, the one formula), AUTO's objective, target MI and stop at the
    endpoint from ``config`` (``RunConfig``), ``seams.supervisor`` / ``seams.limits`` over them."""
    from sim.recipe import PAPER_DRUM

    crit = PAPER_DRUM.critical_rpm if critical_rpm is None else float(critical_rpm)
    limits = Limits(**{"critical_rpm": crit, **(seams.limits if seams is not None else {})})
    batch: dict[str, object] = {}
    if config is not None:  # one target: the endpoint's
        batch = {"objective": config.objective, "stop_at_endpoint": config.stop_at_endpoint,
                 "target_mi": endpoint_config(config, seams).target_mi}
    overrides = seams.supervisor if seams is not None else {}
    return SupervisorConfig(limits=limits, **{**batch, **overrides})  # type: ignore[arg-type]


@dataclass(frozen=True)
class RunInputs:
    """What a run takes from the meter config file (``--config``), checked before anything
    starts: the file itself, its colour classes and drum ROI, the user's mixer (None: the
    paper's, also in the demo, whose plant and twin stay the paper's)."""

    meter_config: MeterConfig | None = None
    classes: tuple[ColourClass, ...] | None = None
    roi: DrumROI | None = None
    mixer: Mixer | None = None


def resolve_inputs(cfg: RunConfig) -> tuple[RunConfig, RunInputs]:
    """Read the meter config file of ``cfg`` and layer it under the options: its
    ``[endpoint]`` table under the ``--endpoint-*`` options; its mixer checked (a one-line error
    now) and the engine checked against it. Returns the layered ``RunConfig`` and the inputs."""
    inputs = RunInputs()
    if cfg.meter_config is not None:
        from sim.mixer import mixer_from_config
        from vision.config import load_config

        mc = load_config(cfg.meter_config)
        if mc.endpoint_table:  # [endpoint] under the --endpoint-* options
            from twin.config import config_endpoint

            cfg = replace(cfg, endpoint=config_endpoint(mc.endpoint_table, mc.source, cfg.endpoint))
        mixer = mixer_from_config(mc)  # checked in any case; the demo's plant and twin stay the paper's
        inputs = RunInputs(mc, tuple(mc.classes), mc.roi, None if cfg.demo else mixer)
    if cfg.engine is not None:
        from sim.engine import engine_for
        from sim.mixer import paper_mixer

        engine_for(paper_mixer() if inputs.mixer is None else inputs.mixer, cfg.engine)
    return cfg, inputs


def mill_url(cfg: RunConfig, inputs: RunInputs) -> str:
    """The hardware run's mill URL: ``--mill``, with the config's ``[drive]`` ``hz_per_rpm``
    written into a ``modbus:`` URL (docs/drives.md)."""
    url = str(cfg.mill)
    mc = inputs.meter_config
    if mc is None:
        return url
    from control.modbus.link import config_mill_url

    return config_mill_url(url, mc.drive_table, f"config {mc.source}")


__all__ = ["LOOP_ENDPOINT", "RunInputs", "Seams", "endpoint_config", "mill_url", "resolve_inputs",
           "supervisor_config", "trend_config"]

"""Run configuration of the live loop: one dataclass filled from the CLI; and the one reading of a
``--config`` TOML for every command (``load_checked_config``)."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from twin.errors import TwinError
from twin.runlog import default_run_dir

if TYPE_CHECKING:
    from sim.mixer import Mixer
    from vision.config import MeterConfig

MODES = ("off", "manual", "auto")
TOKEN_ENV = "DRUMTWIN_CONTROL_TOKEN"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
MAX_SPEED = 100.0  # run seconds per wall second: beyond this the demo only drops frames
MIN_SPEED = 0.01  # slower than this a demo run never gets anywhere
MAX_DURATION_S = 30 * 86400.0  # one run's --duration, s (a month; none: until Ctrl-C)


def check_host(host: str) -> str:
    """``host`` when it is an IP address or a host name (RFC 1123 syntax), else a
    one-line TwinError: ``999.1.1.1`` or ``a b`` never reach the socket layer."""
    import ipaddress
    import re

    h = str(host).strip().strip("[]")
    try:
        ipaddress.ip_address(h)
        return h
    except ValueError:
        pass
    label = r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)"
    if len(h) <= 253 and re.fullmatch(rf"{label}(\.{label})*", h) and not re.fullmatch(r"[0-9.]+", h):
        return h
    raise TwinError(f"--host must be an IP address or a host name, got {host!r}")


def check_scheduler(address: str) -> tuple[str, int]:
    """A Dask scheduler address ``tcp://HOST:PORT`` (or ``HOST:PORT``) as (host, port), else
    a one-line TwinError (the run checks that it answers before it starts)."""
    from urllib.parse import urlsplit

    text = str(address).strip()
    parts = urlsplit(text if "://" in text else "tcp://" + text)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme not in ("tcp", "tls") or not parts.hostname or port is None or port <= 0 or parts.path:
        raise TwinError(f"--scheduler must be tcp://HOST:PORT, got {address!r}")
    check_host(parts.hostname)
    return parts.hostname, port


def check_port_free(host: str, port: int) -> None:
    """A one-line TwinError when ``host:port`` is taken: the dashboard would otherwise come
    up on another port, and an operator opening the asked one reaches whatever holds it
    (another run's dashboard, another mill)."""
    import socket

    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
    except OSError as exc:
        raise TwinError(f"--port {port} on {host} is not free ({exc.strerror or exc}): choose another") from None


@dataclass(frozen=True)
class RunConfig:
    """Everything ``drumtwin run`` needs. Times are run time (the demo clock, which
    runs ``speed`` times faster than the wall clock); rates are per second of run time.

    ``camera``/``video``/``mill`` all None means the embedded demo (hidden plant +
    emulated mill on a pty).
    """

    camera: str | None = None  # camera index or stream URL
    video: Path | None = None  # recorded video to replay
    mill: str | None = None  # pyserial URL of the mill (/dev/ttyUSB0, socket://, rfc2217://)
    meter_config: Path | None = None  # vision TOML (colour classes, ROI)
    dashboard: bool = True
    duration_s: float | None = None  # None: until Ctrl-C
    log_dir: Path | None = None  # None: runs/<timestamp>
    mode: str = "auto"
    case: str = "C"  # demo plant's initial state
    speed: float = 1.0  # run clock / wall clock (demo only)
    seed: int = 0
    host: str = "127.0.0.1"
    port: int = 8080
    control_token: str | None = None
    estop_needs_token: bool = False  # True: EMERGENCY STOP only for unlocked viewers (open networks)
    scheduler: str | None = None  # Dask scheduler address for what-if studies
    start_rpm: float = 5.0
    camera_fps: float = 10.0  # demo camera frame rate (run time)
    frame_px: int = 240  # demo camera / twin render size (square)
    supervisor_period_s: float = 1.0
    whatif_horizon_s: float = 40.0  # AUTO's prediction horizon
    whatif_workers: int = 1
    dashboard_hz: float = 12.0
    engine: str | None = None  # the twin's engine ("dem" | "pymunk"); None: the mixer's
    objective: str = "plateau"  # AUTO's objective: plateau | time | energy (control.objective)
    target_mi: float | None = None  # the endpoint's and the objective's target MI (None: LOOP_ENDPOINT's)
    stop_at_endpoint: bool = False  # AUTO stops the mill once the batch is mixed (control.endpoint)
    endpoint: Mapping[str, float] = field(default_factory=dict)  # endpoint settings (control.endpoint.ENDPOINT_KEYS)
    drive: str | None = None  # demo only: the mill is this drive profile's emulator over Modbus RTU
    catalogue: str | None = None  # run catalogue: a path or postgresql:// URL (None: $DRUMTWIN_CATALOGUE, else
    #                               the SQLite file beside the run folders: twin.catalogue.store.resolve_url)

    @property
    def demo(self) -> bool:
        """True when neither a camera, a video nor a mill was given."""
        return self.camera is None and self.video is None and self.mill is None

    @property
    def remote(self) -> bool:
        """True when the dashboard binds beyond loopback."""
        return self.host not in LOCAL_HOSTS

    def resolved(self) -> RunConfig:
        """Validated copy with defaults filled (log dir, token from the environment)."""
        mode = self.mode.lower()
        if mode not in MODES:
            raise TwinError(f"--mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        from sim.params import CASES  # the one definition of the recipe's initial states

        case = self.case.upper()
        if case not in CASES:
            raise TwinError(f"--case must be one of {', '.join(CASES)}, got {self.case!r}")
        if not (math.isfinite(self.speed) and MIN_SPEED <= self.speed <= MAX_SPEED):
            raise TwinError(f"--speed must be a number in [{MIN_SPEED:g}, {MAX_SPEED:g}], got {self.speed}")
        if self.duration_s is not None and not (
            math.isfinite(self.duration_s) and 0 < self.duration_s <= MAX_DURATION_S
        ):
            raise TwinError(f"--duration must be a number in (0, {MAX_DURATION_S:g}] s, got {self.duration_s}")
        self._check_numbers()
        self._check_sources()
        if self.engine is not None and self.engine not in ("dem", "pymunk"):
            raise TwinError(f"--engine must be dem or pymunk, got {self.engine!r}")
        if self.meter_config is not None:  # the demo's plant and twin stay the paper's, the config is checked
            load_checked_config(self.meter_config, engine=self.engine, live=True)
        from control.errors import ControlError
        from control.objective import check_objective

        try:
            objective = check_objective(self.objective)
        except ControlError as exc:
            raise TwinError(f"--objective: {exc}") from None
        if self.target_mi is not None and not (math.isfinite(self.target_mi) and 0.0 <= self.target_mi <= 1.0):
            raise TwinError(f"--target-mi must be a number in [0, 1], got {self.target_mi}")
        check_endpoint_options(self.endpoint)
        if not self.demo and self.speed != 1.0:
            raise TwinError("--speed only applies to the embedded demo (real mills run in real time)")
        if self.control_token is not None and not self.control_token.strip():
            raise TwinError("--control-token must not be empty (an empty token would unlock every viewer)")
        token = self.control_token or os.environ.get(TOKEN_ENV) or None
        if self.dashboard and self.host not in LOCAL_HOSTS and not token:
            raise TwinError(
                f"binding the dashboard to {self.host} needs a control token "
                f"(--control-token or ${TOKEN_ENV})"
            )
        log_dir = self.log_dir or default_run_dir()
        return replace(self, mode=mode, case=case, control_token=token, log_dir=Path(log_dir), objective=objective)

    def _check_numbers(self) -> None:
        """The host, ports, seed and the run's positive rates and lengths."""
        check_host(self.host)
        if self.scheduler is not None:
            check_scheduler(self.scheduler)
        if not (0 < self.port < 65536):
            raise TwinError(f"--port must be 1..65535, got {self.port}")
        if not (0 <= self.seed < 2**32):
            raise TwinError(f"--seed must be in 0..{2**32 - 1}, got {self.seed}")
        for name, value in (
            ("start_rpm", self.start_rpm),
            ("camera_fps", self.camera_fps),
            ("supervisor_period_s", self.supervisor_period_s),
            ("whatif_horizon_s", self.whatif_horizon_s),
            ("dashboard_hz", self.dashboard_hz),
        ):
            if not (math.isfinite(value) and value > 0):
                raise TwinError(f"{name} must be a number > 0, got {value}")
        if self.frame_px < 32 or self.whatif_workers < 1:
            raise TwinError(
                f"frame_px must be >= 32 and whatif_workers >= 1, got {self.frame_px}, {self.whatif_workers}"
            )

    def _check_sources(self) -> None:
        """The catalogue, the mill, the camera or video: given together or not at all, and readable."""
        if self.catalogue is not None:  # a catalogue that cannot be used later is a warning; this is a typo
            from twin.catalogue.store import check_url

            check_url(self.catalogue)
        if self.mill is not None and not self.mill.strip():
            raise TwinError("--mill must not be empty")
        if self.camera is not None and self.video is not None:
            raise TwinError("give either --camera or --video, not both")
        if (self.camera is not None or self.video is not None) and self.mill is None:
            raise TwinError("a real camera or video needs --mill URL (the demo emulates both)")
        if self.mill is not None and self.camera is None and self.video is None:
            raise TwinError("--mill needs --camera or --video (the demo emulates both)")
        if self.video is not None and not Path(self.video).is_file():
            raise FileNotFoundError(f"video not found: {self.video}")
        if self.video is not None:
            from vision.sources import source_kind

            if source_kind(str(self.video)) != "video":  # an image replays as one frame of no video
                raise TwinError(f"--video {self.video} is not a video file (for images: drumtwin mi)")

    def to_metadata(self) -> dict:
        """The config as JSON data for metadata.json (the token is never written)."""
        from twin.runlog import to_jsonable

        d = to_jsonable(self)
        d["control_token"] = "***" if self.control_token else None
        if self.catalogue is not None and "://" in self.catalogue:  # a server URL's password is never written
            from twin.catalogue.store import hide_password

            d["catalogue"] = hide_password(self.catalogue)
        return d


def endpoint_options(**values: float | None) -> dict[str, float]:
    """The ``--endpoint-*`` options given (``band=``, ``dwell_s=``, ...; None: not given) as settings
    for ``control.endpoint.endpoint_settings``; checked (:func:`check_endpoint_options`)."""
    out = {k: float(v) for k, v in values.items() if v is not None}
    check_endpoint_options(out)
    return out


def config_endpoint(table: object, source: str, options: Mapping[str, float]) -> dict[str, float]:
    """The endpoint settings of a run: the config's ``[endpoint]`` table (``table``, from
    ``vision.config.MeterConfig.endpoint_table``) under the ``--endpoint-*`` ``options``
    (an option wins). A table that is not one, an unknown key or a bad value: a one-line
    TwinError naming the config ``source``."""
    from control.endpoint import endpoint_settings
    from control.errors import ControlError

    if not isinstance(table, Mapping):
        raise TwinError(f"config {source}: [endpoint] must be a table")
    try:
        endpoint_settings(table)
    except ControlError as exc:
        raise TwinError(f"config {source}: {exc}") from None
    return {**{k: v for k, v in table.items()}, **options}


def check_endpoint_options(values: Mapping[str, float]) -> None:
    """Endpoint settings from options: a one-line TwinError naming the option (``--endpoint-dwell-s``)."""
    from control.endpoint import endpoint_settings
    from control.errors import ControlError

    for key, v in values.items():
        try:
            endpoint_settings({key: v})
        except ControlError as exc:
            raise TwinError(f"--endpoint-{key.replace('_', '-')}: {exc}") from None



@dataclass(frozen=True)
class CheckedConfig:
    """A ``--config`` as every command reads it: the meter config (``vision.config``; the defaults
    without a file), the twin's mixer (``sim.mixer``; the paper's when the config has no
    ``[drum]``), whether the config gave one, and the engine that runs it."""

    meter: MeterConfig
    mixer: Mixer
    has_mixer: bool
    engine: str


def load_checked_config(path: Path | None, *, engine: str | None = None, live: bool = False) -> CheckedConfig:
    """The one validation of a ``--config`` (``run``, ``sim``, ``whatif``, ``calibrate``, ``mi``,
    ``mill``, ``bench trend``), so a config one command refuses every command refuses, in the same
    line: the meter's tables (``vision.config.load_config``), the mixer's (``sim.mixer.mixer_from_config``)
    and a twin of it (``sim.capacity.check_twin``: fits, the particle bound, the engine's step;
    ``live``: the live twin's bound), ``[endpoint]`` and ``[drive]``. ``engine``: ``--engine``."""
    from control.modbus.link import drive_hz_per_rpm
    from sim.capacity import check_twin
    from sim.mixer import mixer_from_config, paper_mixer
    from vision.config import load_config

    meter = load_config(path)
    mixer = mixer_from_config(meter) if path is not None else None
    source = f"config {meter.source}"
    name = check_twin(paper_mixer() if mixer is None else mixer, engine, live=live, source=source)
    if meter.endpoint_table:
        config_endpoint(meter.endpoint_table, meter.source, {})
    drive_hz_per_rpm(meter.drive_table, source)
    return CheckedConfig(meter, paper_mixer() if mixer is None else mixer, mixer is not None, name)

"""Run folders for the catalogue's tests, written by the real ``RunLog`` from typed records."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from twin.catalogue.summary import process_identity
from twin.records import FrameReading, MillCommandSent, Mixed, RunStart, RunStop
from twin.runlog import RunLog


@dataclass(frozen=True)
class RunSpec:
    """What a made-up run did."""

    rig: str = "pmma"
    mode: str = "auto"
    start_rpm: float = 5.0
    rpms: tuple[float, ...] = (20.0,)
    mixing_time_s: float | None = 30.0
    final_mi: float = 0.95
    stopped: bool = True
    failure: str | None = None
    frames: int = 5
    uid: str | None = None
    energy_j: float | None = None


def frame(t_s: float, mi: float, rpm: float) -> FrameReading:
    return FrameReading(t_s=t_s, frame=int(t_s * 10), mi=mi, mi_sigmoid=mi, mi_linear=mi, d_px=1.0, dsigma_px=1.0,
                        concentration=0.5, slope_deg=30.0, valid=True, trend_mi=mi, trend_lo95=mi - 0.05,
                        trend_hi95=mi + 0.05, trend_rate=0.0, ma_mi=mi, twin_mi=None, twin_slope_deg=None,
                        rpm_setpoint=rpm, rpm_actual=rpm, mode="auto", flags=())


def make_run(directory: Path, spec: RunSpec = RunSpec(), *, process: dict[str, object] | None = None) -> Path:
    """A run folder as ``drumtwin run`` leaves it (start, commands, frames, endpoint, stop)."""
    log = RunLog(directory)
    log.set_metadata(config={"mode": spec.mode, "start_rpm": spec.start_rpm, "objective": "time",
                             "meter_config": f"/lab/{spec.rig}.toml"},
                     mixer={"drum": spec.rig}, process=process or process_identity(),
                     **({"run_uid": spec.uid} if spec.uid else {}))
    log.record(RunStart(t_s=0.0, mode=spec.mode, mill="emulator"))
    rpm = spec.start_rpm
    for i, r in enumerate(spec.rpms):
        log.record(MillCommandSent(t_s=1.0 + i, command="set_rpm", source="supervisor", rpm=r))
        rpm = r
    for i in range(spec.frames):
        log.record(frame(0.5 * i, spec.final_mi, rpm))
    if spec.mixing_time_s is not None:
        log.record(Mixed(t_s=spec.mixing_time_s + 5, mixing_time_s=spec.mixing_time_s, plateau_mi=spec.final_mi))
    if spec.stopped:
        log.record(RunStop(t_s=60.0, frames=spec.frames, workers_alive=(), failure=spec.failure,
                           energy_j=spec.energy_j))
    log.close()
    return directory


def stamp(directory: Path, started_s: float) -> None:
    """Shift a made-up run's event wall times to start at ``started_s`` (unix s)."""
    p = directory / "events.jsonl"
    events = [json.loads(ln) for ln in p.read_text().splitlines()]
    p.write_text("".join(json.dumps({**e, "wall_s": started_s + float(e["t_s"])}) + "\n" for e in events))

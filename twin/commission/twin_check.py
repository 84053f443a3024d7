"""The twin against the camera: the calibrated twin of the rig run at the rig's rpm, rendered by the
synthetic camera at the camera's scale and measured by the camera's meter (``twin.commission.measure``).

The calibration settles its answer with this same run (``CheckRuns``: each confirming run of the
calibration is the check's run at that friction, and the check takes the answer's), so the check
compares the number the calibration aimed at, measured one way.

How long, how many frames (``TWIN_RUN``): the slope of a monolayer bed at 5 rpm swings by 6-9 deg from
frame to frame (avalanches) and its mean over a window wanders slowly (the packing of equal discs), so
one run's 10 s mean is good to 1.3 deg, 20 s to 0.9 deg (docs/commissioning.md, measured on the PMMA
rig's twin): too coarse for a 1 deg check. Four runs from independent mixed starts (seeds), each
spun up 3 s and filmed every 0.5 s for 15 s, put the twin's median slope within about 0.5 deg of its
long-run mean (half the tolerance) and its MI and spread ratios within 0.01, on 120 frames; the DEM
runs them in a few seconds of one core, the pymunk twin of a 180-particle shaped rig in about 20 s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from sim.calibrate_slope import CONFIRM_RUN, Measured, SlopeRun, frames_slope_deg, seeds_se_deg
from sim.mixer import Friction, Mixer
from sim.render import Renderer, size_for_radius
from twin.commission.measure import FrameMeasure, measure_frame
from vision.config import MeterConfig
from vision.roi import DrumROI

RIM_PX = 3  # the twin's rendered rim (px): thin, as a camera sees an acrylic drum's edge
TWIN_RUN = CONFIRM_RUN
"""The twin's run for the check: the calibration's confirming run (``sim.calibrate_slope.SlopeRun``)."""


def twin_meter_config(cfg: MeterConfig) -> MeterConfig:
    """The camera's meter for the twin's frames: its classes and settings, without the set-up light
    (the renderer's light does not change) and in gravity's frame (the twin is rendered upright)."""
    return replace(cfg, light_reference=None, light_reference_classes=None, camera_rotation_deg=0.0, mirror=False)


@dataclass(frozen=True)
class TwinFrames:
    """The twin's frames measured (time order, the seeds one after another), one rendered frame and its
    reading's overlay kept for the report (BGR), the drum's ROI in the rendered frames."""

    measures: tuple[FrameMeasure, ...]
    frame: np.ndarray
    roi: DrumROI


def run_twin(mixer: Mixer, rpm: float, cfg: MeterConfig, r_px: float, diameter_px: float, *,
             engine: str | None = None, run: SlopeRun = TWIN_RUN,
             progress: Callable[[int, int], None] | None = None, **twin_kwargs: Any) -> TwinFrames:
    """The twin of ``mixer`` (its friction: ``mixer.friction``, else ``twin_kwargs``) run at ``rpm`` as
    ``run`` says, rendered with the drum ``r_px`` in radius and measured by ``cfg``'s meter
    (``twin_meter_config``), particles ``diameter_px`` across."""
    from sim.engine import make_twin
    from sim.probe import probe
    from vision.overlay import draw_overlay

    tcfg = twin_meter_config(cfg)
    out: list[FrameMeasure] = []
    keep: np.ndarray | None = None
    roi: DrumROI | None = None
    per = run.per_seed
    for i, seed in enumerate(run.seeds):
        sim = make_twin(mixer, engine, case="C", seed=seed, rpm=rpm, **twin_kwargs)
        ren = Renderer(sim.drum, size_for_radius(r_px, RIM_PX), rim_px=RIM_PX)
        roi = ren.roi
        meter = tcfg.make_meter(roi=roi)
        for smp in probe(sim, per * run.every_s, run.every_s, spin_up_s=run.spin_up_at(rpm), include_start=False):
            img = ren.render(smp.particles)
            assert img is not None  # no realism: no dropped frames
            out.append(measure_frame(tcfg, meter, img, roi, diameter_px))
            if keep is None and len(out) == per // 2:
                keep = draw_overlay(img, meter.measure(img))
            if progress is not None:
                progress(len(out), run.frames)
        del sim
        if progress is not None:
            progress(per * (i + 1), run.frames)
    assert keep is not None and roi is not None
    return TwinFrames(tuple(out), keep, roi)


def seeds_spread(measures: Sequence[FrameMeasure], run: SlopeRun = TWIN_RUN) -> float:
    """The spread (sd, deg) of the seeds' own median slopes: how far one run alone would be from
    their pooled median."""
    per = run.per_seed
    meds = [frames_slope_deg([m.slope_deg for m in measures[i:i + per]]) for i in range(0, len(measures), per)]
    return float(np.std(meds)) if len(meds) > 1 else float("nan")


class CheckRuns:
    """The twin's runs for the check, as the calibration's confirming measurement (``sim.calibrate_slope.
    Measure``): ``run_twin`` of ``mixer`` with each friction asked for, its pooled median slope and
    the seeds' standard error; every run kept (``runs``) so the check takes the answer's, not a rerun."""

    def __init__(self, mixer: Mixer, rpm: float, cfg: MeterConfig, r_px: float, diameter_px: float,
                 engine: str | None = None, run: SlopeRun = TWIN_RUN) -> None:
        self.mixer, self.rpm, self.cfg, self.r_px, self.d_px, self.engine, self.run = (
            mixer, rpm, cfg, r_px, diameter_px, engine, run)
        self.runs: dict[Friction, TwinFrames] = {}

    def frames(self, friction: Friction) -> TwinFrames:
        """The check's run of the twin with ``friction`` (run once)."""
        if friction not in self.runs:
            self.runs[friction] = run_twin(replace(self.mixer, friction=friction), self.rpm, self.cfg, self.r_px,
                                           self.d_px, engine=self.engine, run=self.run)
        return self.runs[friction]

    def __call__(self, sliding: float, rolling: float, end_friction: float | None) -> Measured:
        tf = self.frames(Friction(sliding=float(sliding), rolling=float(rolling),
                                  end_plates=None if end_friction is None else float(end_friction)))
        s = [m.slope_deg for m in tf.measures]
        return Measured(abs(frames_slope_deg(s)), seeds_se_deg(s, self.run.per_seed))


__all__ = ["RIM_PX", "TWIN_RUN", "CheckRuns", "TwinFrames", "run_twin", "seeds_spread",
           "twin_meter_config"]

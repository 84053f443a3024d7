"""The twin against the camera: the calibrated twin of the rig run at the rig's rpm, rendered by the
synthetic camera at the camera's scale and measured by the camera's meter (``twin.commission.measure``).

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

from sim.mixer import Mixer
from sim.render import Renderer, size_for_radius
from twin.commission.measure import FrameMeasure, measure_frame
from vision.config import MeterConfig
from vision.roi import DrumROI

RIM_PX = 3  # the twin's rendered rim (px): thin, as a camera sees an acrylic drum's edge


@dataclass(frozen=True)
class TwinRun:
    """The twin's runs for the check: one per seed, each from a mixed start (case C), ``spin_up_s``
    before the first frame, a frame every ``every_s`` for ``window_s`` (s)."""

    seeds: tuple[int, ...] = (101, 102, 103, 104)
    spin_up_s: float = 3.0
    window_s: float = 15.0
    every_s: float = 0.5

    @property
    def frames(self) -> int:
        return len(self.seeds) * int(round(self.window_s / self.every_s))


TWIN_RUN = TwinRun()


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
             engine: str | None = None, run: TwinRun = TWIN_RUN,
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
    per = int(round(run.window_s / run.every_s))
    for i, seed in enumerate(run.seeds):
        sim = make_twin(mixer, engine, case="C", seed=seed, rpm=rpm, **twin_kwargs)
        ren = Renderer(sim.drum, size_for_radius(r_px, RIM_PX), rim_px=RIM_PX)
        roi = ren.roi
        meter = tcfg.make_meter(roi=roi)
        for smp in probe(sim, per * run.every_s, run.every_s, spin_up_s=run.spin_up_s, include_start=False):
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


def seeds_spread(measures: Sequence[FrameMeasure], run: TwinRun = TWIN_RUN) -> float:
    """The spread (sd, deg) of the seeds' own median slopes: how far one run alone would be from
    their pooled median."""
    per = int(round(run.window_s / run.every_s))
    meds = [float(np.nanmedian([m.slope_deg for m in measures[i:i + per]])) for i in range(0, len(measures), per)]
    return float(np.std(meds)) if len(meds) > 1 else float("nan")


__all__ = ["RIM_PX", "TWIN_RUN", "TwinFrames", "TwinRun", "run_twin", "seeds_spread",
           "twin_meter_config"]

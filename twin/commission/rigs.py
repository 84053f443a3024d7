"""Rigs made by the twin itself, as a camera would film them: frames of a known mixer turning at a
known rpm and friction, rendered by the synthetic camera (``sim.render``) and written as images.

They stand in for a real rig where the answer must be known: the shaped-particle rig of issue 39
(discs with a shallow notch beside round discs, about 25 discs across a quasi-2D drum) for the
census's shapes, the commissioning benchmark and its tests, and small rigs for the dashboard's
set-up view. Units: m, rpm, s, px.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sim.mixer import Mixer, ParticleKind, Shape
from sim.recipe import DrumSpec
from sim.render import Realism, Renderer

TEAL_BGR = (150, 130, 20)
WHITE_BGR = (225, 225, 220)
WALL_SHARE = 0.025  # the drum's wall in the rigs' frames, a share of its radius: an acrylic drum's (7 px at 640 px,
# 11 at 1024), which the camera's drum finder keeps out (``vision.roi.detect_drum``'s inset)
CAMERA = Realism(noise_sd=3.0, blur_px=0.8, gradient=0.08, drift_amp=0.0, glare=0, perspective=0.0,
                 jpeg_quality=92, drop_prob=0.0)
"""The rigs' camera: mild sensor noise, defocus, a lighting falloff and JPEG, no glare, tilt or
dropped frames (a set-up filmed with care)."""


@dataclass(frozen=True)
class RigRun:
    """How a rig is filmed: the drum's speed (rpm) and contact friction, the twin's seed, the spin-up
    before the first frame and the interval between frames (s), the frame size (px)."""

    rpm: float = 5.0
    friction: float = 0.1
    rolling: float = 0.02
    seed: int = 7
    spin_up_s: float = 4.0
    every_s: float = 0.5
    frames: int = 20
    size_px: int = 1024


def notched_rig(notch_deg: float = 90.0, notch_depth: float = 0.4, drum_mm: float = 250.0,
                disc_mm: float = 10.0, fill: float = 0.35) -> Mixer:
    """Issue 39's rig: a quasi-2D (monolayer) drum of ``drum_mm``, equal PMMA discs of ``disc_mm``
    (25 across at the defaults), teal ones with a V-notch of ``notch_deg`` cut to ``notch_depth``
    of the radius and round white ones, half the bed's area each, clockwise as seen."""
    notched = Shape("notched_disc", disc_mm * 1e-3, notch_deg=notch_deg, notch_depth=notch_depth)
    return Mixer(DrumSpec(drum_mm * 1e-3, disc_mm * 1e-3),
                 (ParticleKind("teal", notched, 1190.0, share=0.5, colour_bgr=TEAL_BGR),
                  ParticleKind("white", Shape("disc", disc_mm * 1e-3), 1190.0, share=0.5, colour_bgr=WHITE_BGR)),
                 fill=fill, direction=-1, monolayer=True)


def disc_rig(drum_mm: float = 120.0, disc_mm: float = 8.0, fill: float = 0.35) -> Mixer:
    """A small rig of equal round discs (teal and white, half each): a quick DEM twin (about 60
    discs at the defaults), for the dashboard's set-up view and its tests."""
    d = disc_mm * 1e-3
    return Mixer(DrumSpec(drum_mm * 1e-3, d),
                 (ParticleKind("teal", Shape("disc", d), 1190.0, share=0.5, colour_bgr=TEAL_BGR),
                  ParticleKind("white", Shape("disc", d), 1190.0, share=0.5, colour_bgr=WHITE_BGR)),
                 fill=fill, direction=-1, monolayer=True)


def film(mixer: Mixer, run: RigRun = RigRun(), camera: Realism | None = CAMERA) -> list[np.ndarray]:
    """Frames (BGR) of ``mixer`` turning as ``run`` says, from a mixed start (case C), through the
    synthetic camera ``camera`` (None: clean frames)."""
    from sim.engine import make_twin
    from sim.probe import probe

    sim = make_twin(mixer, None, case="C", seed=run.seed, rpm=run.rpm, friction=run.friction, rolling=run.rolling)
    wall_px = round(WALL_SHARE * 0.44 * run.size_px)  # the renderer's radius is 44 % of the frame, less the wall
    ren = Renderer(sim.drum, run.size_px, camera, rim_px=wall_px)
    out = []
    for smp in probe(sim, run.frames * run.every_s, run.every_s, spin_up_s=run.spin_up_s, include_start=False):
        img = ren.render(smp.particles, smp.sim_t_s)
        if img is not None:
            out.append(img)
    return out


def write_frames(frames: list[np.ndarray], folder: Path) -> list[Path]:
    """``frames`` as numbered PNGs in ``folder`` (made); their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, img in enumerate(frames):
        p = folder / f"{i:04d}.png"
        if not cv2.imwrite(str(p), img):
            raise OSError(f"cannot write {p}")
        paths.append(p)
    return paths


__all__ = ["CAMERA", "TEAL_BGR", "WHITE_BGR", "RigRun", "disc_rig", "film", "notched_rig", "write_frames"]

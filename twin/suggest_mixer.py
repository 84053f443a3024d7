"""The twin's mixer measured in a rig's frames: what ``drumtwin classes suggest --drum-diameter-mm``
writes after the colour classes.

The census of the frames (``vision.census``: each class's size, count and share, the bed's fill,
the rotation) and each class's shape (``vision.shapes`` through ``sim.mixer.shape_from_crops``)
become a ``sim.mixer.Mixer``, written as its ``[drum]`` and ``[[particles]]`` tables with every
number commented with where it came from.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from sim.errors import SimError
from sim.mixer import Mixer, ParticleKind, Shape, check_fits, mixer_to_toml, shape_area_m2, shape_from_traced
from sim.recipe import MAX_FILL, PACKING_2D, DrumSpec
from vision.census import (
    SAME_SIZE,
    ClassSize,
    MixerCensus,
    census,
    circle_census,
    class_size,
    count_particles,
    particle_body,
    particle_edges,
    run_diameter_px,
    same_size,
    single_particles,
    single_particles_at,
)
from vision.errors import VisionError
from vision.roi import roi_bbox, roi_mask
from vision.shapes import particle_shape
from vision.suggest import drum_labels

SUGGEST_DENSITY_KG_M3 = 1190.0  # PMMA: a camera cannot see density
CROPS_PER_FRAME = 4  # single particles per class and frame traced for the class's shape
ROUND_KINDS = ("disc", "notched_disc")  # shapes sized by the census's circles (a shallow notch is still a circle)


@dataclass(frozen=True)
class Traced:
    """One single particle traced for its class's shape: the frame it is in (an index into the frames
    given), its crop (boolean) and where the crop's corner lies in that frame (x, y, px)."""

    frame: int
    crop: np.ndarray
    x_px: int
    y_px: int


@dataclass(frozen=True)
class SuggestedMixer:
    """The twin's mixer measured in the frames: the ``mixer``, a comment per key (``notes``), the
    ``census`` it came from, each class's traced particles (``traced``, in the census's class order) and
    the drum's scale (``mm_per_px``)."""

    mixer: Mixer
    notes: dict[str, str]
    census: MixerCensus
    traced: tuple[tuple[Traced, ...], ...]
    mm_per_px: float


@dataclass
class _Frames:
    """Per frame: the label map, the gray drum crop, each counted class's particle body (for counts and
    runs) and its particles to its gray edges (``edges``: for their outlines), each class's pixels
    (``cpx``), the ROI's area (``rpx``), each class's single particles' run diameter, the slope."""

    labels: list[np.ndarray]
    grays: list[np.ndarray]
    bodies: list[list[np.ndarray]]
    edges: list[list[np.ndarray]]
    cpx: list[list[int]]
    rpx: list[float]
    runs: list[list[float]]
    slopes: list[float]


def _measure_frames(cfg: Any, frames: Sequence[np.ndarray], rois: Sequence[Any], counted: list) -> _Frames:
    out = _Frames([], [], [], [], [], [], [], [])
    names = [c.name for _, c in counted]
    ids = [j for j, _ in counted]
    for img, roi in zip(frames, rois, strict=True):
        lab = drum_labels(cfg, img, roi)
        x0, y0, x1, y1 = roi_bbox(roi, img.shape[:2])
        gray = cv2.cvtColor(np.ascontiguousarray(img[y0:y1, x0:x1]), cv2.COLOR_BGR2GRAY)
        body = [particle_body(lab == j, gray) for j, _ in counted]  # each class's particles without its gaps
        empty = (lab == 0) & roi_mask(roi, img.shape[:2])[y0:y1, x0:x1]  # the drum's empty part (and its gaps)
        bg = float(np.median(gray[empty])) if empty.any() else 0.0
        out.edges.append([particle_edges(lab == j, gray, np.isin(lab, ids) & (lab != j), bg) for j in ids])
        out.labels.append(lab)
        out.grays.append(gray)
        out.bodies.append(body)
        rd = cfg.make_meter(roi=roi).measure(img)
        out.cpx.append([rd.cls(n).n_px for n in names])
        out.rpx.append(roi.area_px)
        out.runs.append([run_diameter_px(single_particles(b, run_diameter_px(b))) for b in body])
        out.slopes.append(rd.slope_deg)
    return out


def _sizes_and_shapes(cfg: Any, fr: _Frames, counted: list, r_px: float, px_mm: float,
                      rois: Sequence[Any]) -> tuple[list[ClassSize], list[tuple[Shape, str]], list[tuple[Traced, ...]]]:
    """Each class's own size, shape and traced particles: its circles in the gray frames when its single
    particles at that size are round (a disc, or a disc with a notch), else the run diameter of its single
    particles (and their traced outline)."""
    runs_a = np.asarray(fr.runs, dtype=float).reshape(len(fr.labels), len(counted))
    by_runs = [class_size(np.zeros(0), runs_a[:, i]) for i in range(len(counted))]
    known = [s.diameter_px for s in by_runs if math.isfinite(s.diameter_px)]
    # round particles as circles in the gray frames, up to 1.6x the largest class's runs (a third of the drum)
    circles = (circle_census(fr.grays, fr.labels, len(cfg.classes), [j - 1 for j, _ in counted],
                             min(1.6 * max(known), 2.0 * r_px / 3.0)) if known else [np.zeros(0) for _ in counted])
    own, shapes, traced = [], [], []
    for i, (_, c) in enumerate(counted):
        cand = class_size(circles[i], runs_a[:, i])
        for size in ([cand, by_runs[i]] if cand.source == "circles" else [by_runs[i]]):
            found = [Traced(f, crop, x + _corner(rois[f])[0], y + _corner(rois[f])[1])
                     for f, edge in enumerate(fr.edges)
                     for crop, x, y in single_particles_at(edge[i], size.diameter_px, CROPS_PER_FRAME)]
            traced_shape = particle_shape([t.crop for t in found], size.diameter_px)
            shape, how = shape_from_traced(traced_shape, size.diameter_px * px_mm * 1e-3, px_mm, f"class {c.name!r}")
            if shape.kind in ROUND_KINDS or size is by_runs[i]:
                break
        if shape.kind in ROUND_KINDS and traced_shape.sized:  # clean outlines: their circle is the size
            size = ClassSize(traced_shape.diameter_px, "outlines", traced_shape.n)
        own.append(size)
        shapes.append((shape, how))
        traced.append(tuple(found))
    return own, shapes, traced


def _corner(roi: Any) -> tuple[int, int]:
    """The drum crop's corner in its frame (px): the label maps are of the drum's box only."""
    return roi_bbox(roi, (1 << 30, 1 << 30))[:2]


def _drum_notes(cen: MixerCensus, r_px: float, px_mm: float, drum_depth_mm: float | None) -> dict[str, str]:
    notes = {
        "drum.diameter_mm": f"--drum-diameter-mm (the drum is {2 * r_px:.0f} px across in the frames: "
                            f"{px_mm:.3f} mm/px)",
        "drum.fill": f"{sum(c.count for c in cen.classes):.0f} particles counted (median of {cen.frames} frames) "
                     f"x their area / ({PACKING_2D:g} packing x the drum's area)",
        "drum.rotation": (f"the free surface's median slope {cen.slope_deg:+.1f} deg "
                          f"({'rises to the right' if cen.slope_deg > 0 else 'rises to the left'})"
                          if cen.direction else "the surface is flat in the frames: direction unknown, set it"),
        "drum.density_kg_m3": "acrylic (assumed; not used by the physics)",
    }
    if drum_depth_mm is None:
        notes["drum.monolayer"] = "assumed: one particle between the plates (give --drum-depth-mm otherwise)"
    else:
        notes["drum.depth_mm"] = "--drum-depth-mm"
    return notes


def _particle_kinds(cen: MixerCensus, shapes: list[tuple[Shape, str]], counted: list, px_mm: float,
                    drum_depth_mm: float | None, notes: dict[str, str]) -> list[ParticleKind]:
    """The particle classes of the census (their notes added to ``notes``), shares summing to 1."""
    kinds = []
    for i, c in enumerate(cen.classes):
        w = f"particles.{c.name}"
        d_mm = c.diameter_px * px_mm
        why = (f"; its own {c.own.diameter_px:.1f} px, the classes within {100 * SAME_SIZE:.0f}%: one size"
               if cen.same_size else "")
        shape, how = shapes[i]
        if shape.kind in ROUND_KINDS:  # the census's size: the circles' (the classes within SAME_SIZE: one)
            shape = replace(shape, diameter_m=d_mm * 1e-3)
        src = {"circles": f"median of {c.own.count} circles in the gray frames",
               "outlines": f"median circle of {c.own.count} single particles' gray edges"}.get(
                   c.own.source, f"median horizontal run / 0.91 of its single particles, {cen.frames} frames")
        notes[f"{w}.diameter_mm"] = (f"{c.diameter_px:.1f} px ({src}){why}" if shape.kind in ROUND_KINDS else
                                     "the traced outline's circumscribed diameter")
        notes[f"{w}.shape"] = how
        notes[f"{w}.share"] = (f"{c.count:.0f} particles per frame x their area; the class's pixel share is "
                               f"{c.pixel_share:.3f}")
        notes[f"{w}.density_kg_m3"] = "PMMA (assumed: a camera cannot see density)"
        thick = None
        if drum_depth_mm is not None and drum_depth_mm < d_mm:  # flat discs: as thick as the drum is deep
            thick = drum_depth_mm * 1e-3
            notes[f"{w}.thickness_mm"] = "assumed: the drum's depth (the discs are wider than the drum is deep)"
        kinds.append(ParticleKind(c.name, shape, SUGGEST_DENSITY_KG_M3, share=round(c.share, 3), thickness_m=thick,
                                  colour_bgr=next(k.display_bgr for _, k in counted if k.name == c.name)))
    total = sum(k.share or 0.0 for k in kinds)
    if abs(total - 1.0) > 1e-9:  # rounding: the last class takes the rest
        last = kinds[-1]
        kinds[-1] = ParticleKind(last.name, last.shape, last.density_kg_m3, share=round(float(last.share or 0.0)
                                 + 1.0 - total, 3), thickness_m=last.thickness_m, colour_bgr=last.colour_bgr)
    return kinds


def suggest_mixer(cfg: Any, frames: Sequence[np.ndarray], rois: Sequence[Any], drum_diameter_mm: float,
                  drum_depth_mm: float | None) -> SuggestedMixer:
    """The twin's mixer measured in ``frames`` (the meter config ``cfg``'s classes, the drum ``rois``;
    see the module doc). A class too small to measure, or a bed that does not fit the drum, is a
    one-line ``VisionError``."""
    counted = [(j + 1, c) for j, c in enumerate(cfg.classes) if not c.reject]
    fr = _measure_frames(cfg, frames, rois, counted)
    r_px = float(np.median([r.r_px for r in rois]))
    px_mm = drum_diameter_mm / (2.0 * r_px)
    own, shapes, traced = _sizes_and_shapes(cfg, fr, counted, r_px, px_mm, rois)
    sizes, _ = same_size([s.diameter_px for s in own])
    cnt = [[count_particles(b, sizes[i], PACKING_2D) for i, b in enumerate(body)] for body in fr.bodies]
    ratios = [shape_area_m2(replace(sh, diameter_m=1.0)) / (math.pi / 4) if sh.kind in ROUND_KINDS else 1.0
              for sh, _ in shapes]
    cen = census([c.name for _, c in counted], np.asarray(fr.cpx), np.asarray(fr.rpx), own, np.asarray(cnt),
                 fr.slopes, r_px, PACKING_2D, ratios)
    if not all(math.isfinite(c.diameter_px) for c in cen.classes):
        missing = next(c.name for c in cen.classes if not math.isfinite(c.diameter_px))
        raise VisionError(f"class {missing!r}: too few particle pixels in the frames to measure a size")
    notes = _drum_notes(cen, r_px, px_mm, drum_depth_mm)
    kinds = _particle_kinds(cen, shapes, counted, px_mm, drum_depth_mm, notes)
    fill = min(max(cen.fill, 0.05), MAX_FILL) if math.isfinite(cen.fill) else 0.5
    depth_m = (drum_depth_mm if drum_depth_mm is not None else max(k.shape.diameter_m * 1e3 for k in kinds)) * 1e-3
    mixer = Mixer(DrumSpec(drum_diameter_mm * 1e-3, depth_m), tuple(kinds), fill=round(fill, 3),
                  direction=-1 if cen.direction < 0 else 1, monolayer=drum_depth_mm is None)
    try:
        check_fits(mixer, "suggested mixer")
    except SimError as exc:
        raise VisionError(str(exc)) from None
    return SuggestedMixer(mixer, notes, cen, tuple(traced), px_mm)


SUGGEST_HEAD = ("# The twin's mixer, measured in the same frames by `drumtwin classes suggest --drum-diameter-mm`;\n"
                "# edit what is wrong (shape, density, depth).\n")


def suggest_mixer_toml(cfg: Any, frames: Sequence[np.ndarray], rois: Sequence[Any], drum_diameter_mm: float,
                       drum_depth_mm: float | None) -> str:
    """``suggest_mixer``'s ``[drum]`` and ``[[particles]]`` tables as TOML, every number commented."""
    s = suggest_mixer(cfg, frames, rois, drum_diameter_mm, drum_depth_mm)
    return SUGGEST_HEAD + mixer_to_toml(s.mixer, s.notes)


__all__ = ["CROPS_PER_FRAME", "ROUND_KINDS", "SUGGEST_DENSITY_KG_M3", "SUGGEST_HEAD", "SuggestedMixer", "Traced",
           "suggest_mixer", "suggest_mixer_toml"]

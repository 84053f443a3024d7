"""Where the bed lies in each frame: gravity's frame of reference for ``classes suggest`` (pure).

The bed is where the drum is textured (particle edges); the empty drum above it is not. Per
frame, the textured pixels' centroid lies off the drum's centre towards gravity's down, so
each frame gives its own camera turn (the nearest quarter turn), and the drum's empty region
is the untextured part of its upper side in that frame's own frame of reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from vision.colourfit import DrumSamples
from vision.colours import bgr_to_lab
from vision.errors import VisionError
from vision.meter import gravity_matrix
from vision.roi import DrumROI, _mask_in_box, roi_bbox

__all__ = ["EMPTY_DENSITY", "EMPTY_HEIGHT", "FrameSamples", "density_ratio", "frame_samples", "frame_turn",
           "in_gravity", "propose_rotation_deg", "sample_drum_pixels"]

_CLIP_LEVEL = 250  # a channel at or above this is clipped (glare, specular spots)
NO_DIRECTION = 0.05
"""A frame whose textured pixels' centroid lies less than this (x R) off the drum's centre shows
no direction (a full or empty drum): it takes the other frames' turn."""
TEXTURE_WINDOW = 0.2
"""The local texture density of a pixel: the share of textured pixels in a square of this x R
around it (a few particles across for particles up to a tenth of R)."""
EMPTY_HEIGHT = 0.3
"""The empty region lies above this height (x R over the centre, the frame's own gravity) ..."""
EMPTY_DENSITY = 0.35
"""... where the texture density is under this x the bed's (its 95th percentile in the frame);
the bed region is where it is over twice that. The rule of ``vision.loro.density_rule`` (the
best balanced accuracy against the rigs' class maps) on every rig of the cross-rig bench
(docs/validation.md, section 15: checked leave-one-rig-out)."""


@dataclass(frozen=True)
class FrameSamples:
    """One frame's random drum pixels: CIELAB (N, 3), offsets from the drum centre in R (N, 2),
    clipped (N,), the local texture density (N,; :data:`TEXTURE_WINDOW`), and the frame's bed
    offset (the textured pixels' centroid from the drum centre, in R; zero for none)."""

    lab: np.ndarray
    off: np.ndarray
    clipped: np.ndarray
    density: np.ndarray
    bed_offset: np.ndarray


def sample_drum_pixels(
    frames: Sequence[np.ndarray], rois: Sequence[DrumROI], per_frame: int = 12000, seed: int = 0,
    r_max: float = 0.94, camera_rotation_deg: float = 0.0, mirror: bool = False,
) -> DrumSamples:
    """Up to ``per_frame`` random pixels inside ``r_max`` R of each frame's drum; their height
    is measured in gravity's frame (``camera_rotation_deg``, ``mirror``: see ``vision.meter.Meter``),
    the same for every frame."""
    rng = np.random.default_rng(seed)
    parts = [p for p in (frame_samples(img, roi, per_frame, rng, r_max) for img, roi in zip(frames, rois, strict=True))
             if p is not None]
    return in_gravity(parts, camera_rotation_deg, mirror, per_frame_turns=False)[0]


def frame_samples(img: np.ndarray, roi: DrumROI, per_frame: int, rng: np.random.Generator,
                  r_max: float = 0.94) -> FrameSamples | None:
    """One frame's :class:`FrameSamples` (None when the drum has no pixels in the frame)."""
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    inner = DrumROI(roi.cx_px, roi.cy_px, roi.r_px * r_max, roi.kind,
                    None if roi.half_w_px is None else roi.half_w_px * r_max,
                    None if roi.half_h_px is None else roi.half_h_px * r_max)
    yy, xx = np.nonzero(_mask_in_box(inner, box))
    if yy.size == 0:
        return None
    if yy.size > per_frame:
        pick = rng.choice(yy.size, per_frame, replace=False)
        yy, xx = yy[pick], xx[pick]
    px = img[y0:y1, x0:x1][yy, xx]
    off = np.stack([(xx + x0 - roi.cx_px) / roi.r_px, (yy + y0 - roi.cy_px) / roi.r_px], axis=1)
    textured, bed_offset = _texture(img, roi)
    k = max(3, int(TEXTURE_WINDOW * roi.r_px) | 1)
    density = cv2.blur(textured.astype(np.float32), (k, k))[yy, xx]
    return FrameSamples(bgr_to_lab(px), off, px.max(axis=1) >= _CLIP_LEVEL, density, bed_offset)


def frame_turn(bed_offset: np.ndarray) -> float | None:
    """The camera's quarter turn (0, 90, 180, 270 deg) a frame's bed offset gives: gravity's down
    lies along it, turned by at most the bed's slope; None under :data:`NO_DIRECTION`."""
    if math.hypot(*bed_offset) < NO_DIRECTION:
        return None
    # gravity's down (0, 1) turned counter-clockwise on screen by a lies along (sin a, cos a)
    a = math.degrees(math.atan2(bed_offset[0], bed_offset[1]))
    return float((round(a / 90.0) * 90) % 360)


def in_gravity(parts: Sequence[FrameSamples], camera_rotation_deg: float | None, mirror: bool,
               per_frame_turns: bool = True) -> tuple[DrumSamples, float, list[int]]:
    """The frames' samples together, each with its frame's empty region (above
    :data:`EMPTY_HEIGHT`, texture under :data:`EMPTY_DENSITY` x its bed's) and bed region.

    Heights are measured in each frame's own frame of reference, "down" being the way its
    bed lies (its bed offset: gravity's down turned by at most the bed's slope, so the empty
    region is the part of the drum facing away from the bed); a frame without a direction
    (a full or empty drum), or every frame when not ``per_frame_turns``, takes the reference
    turn's down. The reference turn is ``camera_rotation_deg``, or the quarter turn most
    frames show (:func:`_reference_turn`).
    Returns the samples, the reference turn and the indices of the frames whose bed lies
    more than 90 deg from the reference's down (on another side: a camera remounted, frames
    from another set-up, flipped copies)."""
    if not parts:
        raise VisionError("no drum pixels to learn colours from")
    offs = [p.bed_offset for p in parts]
    ref = camera_rotation_deg if camera_rotation_deg is not None else _reference_turn(offs)
    t = gravity_matrix(ref, mirror)
    ref_down = np.array([0.0, 1.0]) if t is None else t[1]  # image direction of the reference's down
    heights, empty, bed, disagree = [], [], [], []
    for i, p in enumerate(parts):
        size = math.hypot(*p.bed_offset)
        down = p.bed_offset / size if per_frame_turns and size >= NO_DIRECTION else ref_down
        if size >= NO_DIRECTION and float(p.bed_offset @ ref_down) < 0.0:
            disagree.append(i)
        h = -(p.off @ down)
        ratio = density_ratio(p)
        heights.append(h)
        empty.append((h > EMPTY_HEIGHT) & (ratio < EMPTY_DENSITY))
        bed.append(ratio > 2.0 * EMPTY_DENSITY)
    cat = np.concatenate
    return (DrumSamples(cat([p.lab for p in parts]).astype(np.float64), cat(heights), cat([p.clipped for p in parts]),
                        cat(empty), cat(bed), cat([np.hypot(p.off[:, 0], p.off[:, 1]) for p in parts])),
            float(ref), disagree)


def density_ratio(part: FrameSamples) -> np.ndarray:
    """Each sample's texture density over its frame's bed's (the 95th percentile of the frame's
    samples): under :data:`EMPTY_DENSITY` is empty drum, over twice that is bed."""
    level = float(np.percentile(part.density, 95)) if part.density.size else 0.0
    return part.density / level if level > 0 else np.full(part.density.shape, np.nan)  # (no texture: neither)


def _reference_turn(bed_offsets: Sequence[np.ndarray]) -> float:
    """The quarter turn most frames show (:func:`frame_turn` of each); a tie: the tied turn of
    the frames' mean bed offset, else the first frame's among the tied; 0 when no frame shows one."""
    turns = [t for t in (frame_turn(o) for o in bed_offsets) if t is not None]
    if not turns:
        return 0.0
    votes = {t: turns.count(t) for t in turns}  # (in the frames' order)
    top = [t for t, v in votes.items() if v == max(votes.values())]
    mean = frame_turn(np.mean(bed_offsets, axis=0))
    return mean if mean in top else top[0]


def propose_rotation_deg(frames: Sequence[np.ndarray], rois: Sequence[DrumROI]) -> float:
    """The camera's turn (0, 90, 180 or 270 deg) from where the bed lies in the drum: the
    textured pixels' centroid lies off the drum's centre towards gravity's down, turned by at
    most the bed's slope, so the nearest quarter turn to it is the camera's (:func:`frame_turn`),
    and the one most frames show is proposed (:func:`_reference_turn`); 0 when no frame shows a
    direction (a full or empty drum). Any other angle is the user's to write."""
    return _reference_turn([_texture(img, roi)[1] for img, roi in zip(frames, rois, strict=True)])


def _texture(img: np.ndarray, roi: DrumROI) -> tuple[np.ndarray, np.ndarray]:
    """The textured pixels (particle edges) of the drum's inside (to 0.94 R; bool over the ROI's
    bounding box) and their centroid's offset from the drum centre (in R, of those within
    0.85 R, where the rim's edges do not reach; zero for none)."""
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    gray = cv2.cvtColor(np.ascontiguousarray(img[y0:y1, x0:x1]), cv2.COLOR_BGR2GRAY).astype(np.float32)
    mag = np.hypot(cv2.Sobel(gray, cv2.CV_32F, 1, 0), cv2.Sobel(gray, cv2.CV_32F, 0, 1))
    inside = _mask_in_box(DrumROI(roi.cx_px, roi.cy_px, 0.94 * roi.r_px), box)
    # textured: well above the noise floor (the quietest fifth of the drum), whatever the
    # particles' contrast -- unweighted, so a bright class does not pull the centroid
    floor = float(np.percentile(mag[inside], 20)) if inside.any() else 0.0
    textured = inside & (mag > max(12.0, 4.0 * floor))
    ys, xs = np.nonzero(textured & _mask_in_box(DrumROI(roi.cx_px, roi.cy_px, 0.85 * roi.r_px), box))
    if ys.size < 50:
        return textured, np.zeros(2)
    return textured, np.array([(xs.mean() + x0 - roi.cx_px) / roi.r_px, (ys.mean() + y0 - roi.cy_px) / roi.r_px])

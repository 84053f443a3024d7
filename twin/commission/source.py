"""The rig's frames for commissioning: read from a folder, images or a video (``vision.sources``),
spread over the source in bounded memory, each with its drum found (``vision.roi.detect_drum``).

Bad input is a one-line ``VisionError`` before anything is written: no readable frame, no drum in any
frame, frames of two rigs (frames of two sizes, or drum circles apart by more than ``SAME_RIG`` of the
radius). Frames without a drum in a source that has some are left out and named (``skipped``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from vision.errors import VisionError
from vision.roi import DrumROI, detect_drum

MAX_FRAMES = 48  # frames kept, spread over the source (bounded memory and time)
SAME_RIG = 0.05  # drum circles further apart than this (radius or centre, in radii) are of two rigs


@dataclass
class RigFrames:
    """The frames kept (BGR, time order), their names, each one's drum, how many the source had, and
    the frames left out with why (``skipped``: ``"NAME: why"``)."""

    images: list[np.ndarray]
    names: list[str]
    rois: list[DrumROI]
    total: int
    skipped: list[str] = field(default_factory=list)


def _thin(kept: list, step: int, cap: int) -> tuple[list, int]:
    """Every other frame dropped (and the stride doubled) when more than ``cap`` are kept."""
    if len(kept) > cap:
        return kept[::2], step * 2
    return kept, step


def read_frames(spec: str | Sequence[str], max_frames: int = MAX_FRAMES) -> tuple[list[tuple[str, np.ndarray]], int]:
    """Up to ``max_frames`` (name, BGR image) of ``spec`` spread evenly over it (every frame read once,
    every ``step``-th kept, ``step`` doubled when full) and how many frames it had. Unreadable frames
    are left out; none readable, or a grayscale frame, is a ``VisionError``."""
    from vision.sources import open_source

    kept: list[tuple[str, np.ndarray]] = []
    bad: list[str] = []
    step, n = 1, 0
    for fr in open_source(spec, reconnect=False):
        name = fr.name or f"frame {fr.index}"
        if fr.error:
            bad.append(f"{name}: {fr.error}")
            continue
        if fr.image.ndim != 3:
            raise VisionError(f"{name} is a grayscale image: commissioning needs colour frames")
        if n % step == 0:
            kept.append((name, fr.image))
            kept, step = _thin(kept, step, max_frames)
        n += 1
    if not kept:
        raise VisionError(bad[0] if len(bad) == 1 else f"no readable frame in {spec}" + (
            f" ({len(bad)} could not be read)" if bad else ""))
    return kept, n


def same_rig(names: Sequence[str], sizes: Sequence[tuple[int, int]], rois: Sequence[DrumROI]) -> None:
    """A one-line ``VisionError`` naming the first frame of another rig: another frame size, or its drum
    circle ``SAME_RIG`` of the radius or more from the frames' median circle."""
    for nm, sz in zip(names, sizes, strict=True):
        if sz != sizes[0]:
            raise VisionError(f"frames of two rigs (or cameras): {nm} is {sz[1]}x{sz[0]} px, {names[0]} "
                              f"{sizes[0][1]}x{sizes[0][0]} px; commission one rig at a time")
    r = np.array([q.r_px for q in rois])
    cx, cy = np.array([q.cx_px for q in rois]), np.array([q.cy_px for q in rois])
    rm, mx, my = float(np.median(r)), float(np.median(cx)), float(np.median(cy))
    off = np.maximum(np.abs(r - rm), np.hypot(cx - mx, cy - my)) / rm
    if off.max() >= SAME_RIG:
        i = int(np.argmax(off >= SAME_RIG))  # the first frame of the other rig
        raise VisionError(f"frames of two rigs (or camera set-ups): the drum in {names[i]} is {100 * off[i]:.0f}% "
                          f"of its radius from the others' (radius {r[i]:.0f} px against {rm:.0f}); commission one "
                          "rig at a time")


def with_drums(named: Sequence[tuple[str, np.ndarray]], roi: DrumROI | None = None,
               total: int | None = None) -> RigFrames:
    """Frames (name, BGR image) with each one's drum (``roi`` for every frame, else found per frame);
    see the module doc for what is refused. ``total``: how many frames the source had."""
    images, names, rois, skipped = [], [], [], []
    for name, img in named:
        if not (isinstance(img, np.ndarray) and img.ndim == 3 and img.shape[2] == 3):
            raise VisionError(f"{name} is not a colour frame: commissioning needs colour frames")
        try:
            r = roi if roi is not None else detect_drum(img)
        except VisionError as exc:
            skipped.append(f"{name}: {exc}")
            continue
        images.append(img)
        names.append(name)
        rois.append(r)
    if not images:
        why = skipped[0].split(": ", 1)[1] if skipped else "no frames"
        raise VisionError(f"no drum found in any of the {len(named)} frames ({why}); pass --roi cx,cy,r if the "
                          "drum is there")
    same_rig(names, [im.shape[:2] for im in images], rois)
    return RigFrames(images, names, rois, len(named) if total is None else total, skipped)


def rig_frames(spec: str | Sequence[str], roi: DrumROI | None = None, max_frames: int = MAX_FRAMES) -> RigFrames:
    """The rig's frames of a source (``read_frames``) with each one's drum (``with_drums``)."""
    named, total = read_frames(spec, max_frames)
    return with_drums(named, roi, total)


__all__ = ["MAX_FRAMES", "SAME_RIG", "RigFrames", "read_frames", "rig_frames", "same_rig", "with_drums"]

"""``classes suggest``: learn the particle colour classes from the bed, over many frames.

1. Find where the bed lies in each frame (``vision.bedframe``): its own camera turn, from
   the textured pixels' offset, and its empty region (the untextured drum above its bed).
   Frames whose bed lies on another side than the others' are learned in their own frame
   of reference, and named in a note; the config's ``camera_rotation_deg`` is the most
   frames' turn (or the one given).
2. Sample pixels inside the drum (to 0.94 R, off the rim) from every frame, with their
   height in the frame's own gravity and whether they lie in its empty region.
3. Fit the colour model (``vision.colourfit``): a Gaussian mixture in CIELAB, background
   from the frames' empty regions (never a colour that is denser in the bed than in the
   empty drum), particle classes by the valleys between colours.
4. The light the classes were learned in (``vision.photometric``): the set-up's light reference.
5. The class opening (``[meter] opening``) is turned on when it moves a class centroid on
   the frames given by more than ``OPENING_SHIFT`` R (``needs_opening``): chroma blur
   (JPEG 4:2:0) gives the dark gaps between light particles the colour of a darker class
   of the same hue, which the opening drops while it keeps whole particles. It works on the
   meter's stride grid, so on large frames the stride is set to about a twelfth of a
   particle's diameter (``particle_diameter_px``, ``opening_stride``; halved while the
   opening would eat the particles): the blurred gaps grow with the particles. On such a
   coarse grid the opening is always on (it costs nothing there, and the gaps it drops
   need not move a centroid on the frames given -- a mixed bed -- to move one on others).
6. The island filter (``[meter] island_px``, ``vision.islands``) is turned on, at half a
   particle's area, when it moves a class centroid on the frames given by more than
   ``OPENING_SHIFT`` R (``needs_islands``): the specular highlights of glossy dark particles
   take the colour of a lighter class of the same hue, small islands inside the dark particles.

The preview of ``classes suggest --preview`` is ``vision.preview.class_preview``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np

from vision.bedframe import FrameSamples, frame_samples, in_gravity, propose_rotation_deg, sample_drum_pixels
from vision.census import run_diameter_px
from vision.colourfit import MAX_DISTANCE, DrumSamples, _fit_colour_model, colour_name, fit_colour_model
from vision.colours import class_lut, class_mean_lab, classify, counted_classes
from vision.config import MeterConfig
from vision.errors import VisionError
from vision.photometric import class_quantiles, light_quantiles, roi_sample_index, sample_labels
from vision.preview import class_preview
from vision.roi import DrumROI, _mask_in_box, detect_drum, roi_bbox

__all__ = [  # (the colour model, the bed's frame and the preview re-exported: the CLI's one import)
    "KEEP_FRAMES",
    "MAX_DISTANCE",
    "OPENING_GRID",
    "OPENING_KEEP",
    "OPENING_SHIFT",
    "SAMPLE_BUDGET",
    "DrumSamples",
    "class_preview",
    "colour_name",
    "fit_colour_model",
    "island_area_px",
    "needs_islands",
    "needs_opening",
    "opening_stride",
    "particle_diameter_px",
    "propose_rotation_deg",
    "relearn_classes",
    "sample_drum_pixels",
    "suggest_classes",
]

OPENING_SHIFT = 0.01
"""``classes suggest`` turns the class opening on when it moves a class centroid by more than
this share of R on a frame it learned from (a third of the 3% accuracy aim)."""

OPENING_KEEP = 0.5
"""... and not when it would leave a class less than this share of its pixels."""


OPENING_GRID = 12.0
"""Grid pixels across a particle for the opening's stride (``opening_stride``)."""


SAMPLE_BUDGET = 40000
"""``suggest_classes`` takes about this many colour samples from the whole source (split over
the frames expected), so the colour model's fit does not grow with ``--frames``."""
MIN_SAMPLES_PER_FRAME = 50
KEEP_FRAMES = 24
"""``suggest_classes`` keeps at most this many frames (spread evenly over the source) for the
checks that need whole frames (particle size, the class opening); of the others it keeps
only their pixel samples, so ``classes suggest --frames 500`` is bounded in memory."""


def suggest_classes(
    frames: Iterable[np.ndarray] | np.ndarray, roi: DrumROI | None = None, k: int = 2, seed: int = 0,
    per_frame: int | None = None, rois: Sequence[DrumROI] | None = None,
    camera_rotation_deg: float | None = None, mirror: bool = False, n_frames: int | None = None,
) -> MeterConfig:
    """A ``MeterConfig`` with ``k`` learned classes from one or many BGR frames, the light
    they were seen in (``light_reference``, ``vision.photometric``) and the camera's turn
    (``camera_rotation_deg``; None: proposed by :func:`propose_rotation_deg`; a mirror
    cannot be seen in the frames, so ``mirror`` is the caller's).

    ``frames`` may be a stream (any iterable, read once: each frame's pixel samples are taken
    as it comes, and at most ``KEEP_FRAMES`` frames are held; ``n_frames`` = how many to
    expect, for the samples per frame). ``roi`` fixes the drum for every frame; ``rois``
    gives each frame's (already found); with neither, it is detected in each frame. The ROI
    is not written into the config (the meter finds the drum per frame size). ``warnings``
    names classes with no valley between their colours (``vision.colourfit``, step 5) and the
    frames whose bed lies on another side than the others' (learned in their own frame of
    reference, ``vision.bedframe.in_gravity``)."""
    if isinstance(frames, np.ndarray):
        frames = [frames]
    total = len(frames) if isinstance(frames, Sequence) else n_frames
    if rois is not None and isinstance(frames, Sequence) and len(rois) != len(frames):
        raise VisionError(f"{len(rois)} drum ROIs for {len(frames)} frames")
    # a budget of colour samples for the whole source, not per frame: up to 20 frames the same
    # 2,000+ a frame as before; 500 frames held 1,000,000 samples (the EM's arrays grew with
    # them: peak RSS 723 MB at 12 frames, 811 MB at 500 of the real PMMA video)
    per = per_frame or max(MIN_SAMPLES_PER_FRAME, SAMPLE_BUDGET // max(total or 12, 1))
    parts, light_px, kept, seen = _read_frames(frames, roi, rois, per, np.random.default_rng(seed))
    samples, rot, disagree = in_gravity([p for _, p in parts], camera_rotation_deg, mirror)
    classes, notes = _fit_colour_model(samples, k, seed)
    if disagree:
        notes = (*notes, _turn_note([parts[i][0] for i in disagree], seen, rot, camera_rotation_deg is not None))
    px = np.concatenate(light_px)
    light = tuple(tuple(round(float(v), 2) for v in row) for row in light_quantiles(px))
    n_labels = len(counted_classes(classes)) + 1
    per_class = class_quantiles(px, sample_labels(class_lut(tuple(classes)), px, n_labels), n_labels)
    light_cls = tuple(tuple(round(float(v), 2) for v in row.ravel()) for row in per_class)
    cfg = MeterConfig(classes, None, "color", source="<suggested>", warnings=notes, light_reference=light,
                      light_reference_classes=light_cls, camera_rotation_deg=rot, mirror=mirror)
    kf, kr = [f for f, _ in kept], [r for _, r in kept]
    # the smallest estimate over (up to 8 of) the frames: in a segregated bed touching
    # particles of one class merge into longer runs, a mixed frame shows them one by one
    d = min((particle_diameter_px(cfg, img, r) for img, r in kept[:8]),
            key=lambda v: v if math.isfinite(v) else math.inf)
    stride = opening_stride(d)
    while stride >= 1:  # from the particle size's grid down, while the opening eats particles
        verdict = needs_opening(cfg, kf, kr, stride)
        if verdict is not None:
            # on a coarse grid the opening is always on: it costs nothing there (the grid is
            # faster than the full one), and the blurred gaps it drops may not move a centroid
            # on the frames given (a mixed bed) yet will on others (a segregated one)
            if verdict or stride > 1:
                cfg = replace(cfg, opening=True, stride=stride)
            break
        stride //= 2
    island = island_area_px(d)
    return replace(cfg, island_px=island) if island and needs_islands(cfg, kf, kr, island) else cfg


def _read_frames(frames: Iterable[np.ndarray], roi: DrumROI | None, rois: Sequence[DrumROI] | None, per: int,
                 rng: np.random.Generator) -> tuple[list[tuple[int, FrameSamples]], list[np.ndarray],
                                                    list[tuple[np.ndarray, DrumROI]], int]:
    """Each frame's samples (with the frame's index), its pixels for the light reference, up to
    ``KEEP_FRAMES`` whole frames (spread over the source) and the number of frames read."""
    parts: list[tuple[int, FrameSamples]] = []
    light_px: list[np.ndarray] = []
    kept: list[tuple[np.ndarray, DrumROI]] = []
    step = 1  # keep every step-th frame; doubled (and every other kept frame dropped) when full
    n = 0
    for i, img in enumerate(frames):
        if not (isinstance(img, np.ndarray) and img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8):
            shape = getattr(img, "shape", None)
            raise VisionError(f"classes suggest needs colour (BGR, 8-bit) frames, got shape {shape}")
        if rois is not None:
            if i >= len(rois):
                raise VisionError(f"{len(rois)} drum ROIs for more frames")
            r = rois[i]
        else:
            r = roi if roi is not None else detect_drum(img)
        part = frame_samples(img, r, per, rng)
        if part is not None:
            parts.append((i, part))
        light_px.append(np.ascontiguousarray(img).reshape(-1, 3)[roi_sample_index(r, img.shape[:2])])
        if i % step == 0:
            kept.append((img, r))
            if len(kept) > KEEP_FRAMES:
                kept = kept[::2]
                step *= 2
        n += 1
    if n == 0:
        raise VisionError("classes suggest needs at least one frame")
    return parts, light_px, kept, n


def _turn_note(frames: Sequence[int], n: int, rot: float, given: bool) -> str:
    """The note naming the frames (indices) whose bed lies on another side than the reference turn."""
    which = ", ".join(str(i + 1) for i in frames)
    ref = "the one given" if given else "the one most frames show"
    return (f"frames {which} (of {n}, counted from 1) show the bed on another side than the others: each was "
            f"learned in its own frame of reference; camera_rotation_deg = {rot:g} is {ref}")


def island_area_px(particle_diameter: float) -> int:
    """The island filter's largest island (px) for particles ``particle_diameter`` px across:
    half a particle's area (a highlight is a small part of its particle, a whole particle of
    the lighter class is never an island; ``particle_diameter_px`` reads low on glossy shaded
    discs: 8.7 px for the suite's 12.4 px green discs, whose highlights are 16-20 px islands);
    0 when the size is unknown."""
    if not (math.isfinite(particle_diameter) and particle_diameter > 0):
        return 0
    return max(1, int(round(0.5 * math.pi * (0.5 * particle_diameter) ** 2)))


def needs_islands(cfg: MeterConfig, frames: Sequence[np.ndarray], rois: Sequence[DrumROI], island_px: int) -> bool:
    """Whether the island filter (``[meter] island_px``) moves a class centroid of ``cfg`` by
    more than ``OPENING_SHIFT`` R on any of these frames."""
    plain, filtered = replace(cfg, island_px=0), replace(cfg, island_px=island_px)
    for img, roi in zip(frames, rois, strict=True):
        a, b = plain.make_meter(roi).measure(img), filtered.make_meter(roi).measure(img)
        for sa, sb in zip(a.classes, b.classes, strict=True):
            if float(np.hypot(sa.cx_px - sb.cx_px, sa.cy_px - sb.cy_px)) / roi.r_px > OPENING_SHIFT:
                return True  # (NaN, a class too small on a frame: no vote)
    return False


def relearn_classes(
    cfg: MeterConfig, frames: Iterable[np.ndarray] | np.ndarray, rois: Sequence[DrumROI] | None = None,
    seed: int = 0, per_frame: int | None = None,
) -> MeterConfig:
    """``cfg`` with its classes learned again from recent frames of the live bed (when the
    light has moved beyond what ``vision.photometric`` maps back: ``lighting_changed:``),
    keeping the names, the order and the display colours of its counted classes, so the
    MI's first and second class stay the same particles: :func:`suggest_classes` on the
    frames (as many classes, the same camera turn and mirror), each new class taking the
    name of the old one nearest in colour (CIELAB means; the assignment with the smallest
    total distance). The light reference is the frames' (the new set-up); every other
    meter setting (stride, opening, validity) stays ``cfg``'s. A pure function: the caller
    builds the meter (``make_meter``, 1-3 s) and swaps it in between frames."""
    old = cfg.counted
    new = suggest_classes(frames, k=len(old), seed=seed, per_frame=per_frame, rois=rois,
                          camera_rotation_deg=cfg.camera_rotation_deg, mirror=cfg.mirror)
    fresh = new.counted
    if len(fresh) != len(old):
        raise VisionError(f"re-learning found {len(fresh)} particle classes in the frames, not {len(old)}")
    a = [class_mean_lab(c) for c in old]
    b = [class_mean_lab(c) for c in fresh]
    perm = min(itertools.permutations(range(len(old))),
               key=lambda p: sum(float(np.linalg.norm(a[i] - b[j])) for i, j in enumerate(p)))
    classes = tuple(replace(fresh[j], name=old[i].name, display_bgr=old[i].display_bgr) for i, j in enumerate(perm))
    taken = {c.name for c in classes}
    rejects = tuple(c if c.name not in taken else replace(c, name=f"{c.name}_reject")
                    for c in new.classes if c.reject)
    rows = new.light_reference_classes
    assert rows is not None  # (suggest_classes always writes it)
    return replace(cfg, classes=classes + rejects, light_reference=new.light_reference,
                   light_reference_classes=(rows[0], *(rows[1 + j] for j in perm)), warnings=new.warnings,
                   source=f"{cfg.source} (classes re-learned)")



def particle_diameter_px(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> float:
    """A particle's diameter (px) in ``frame``, from the classified drum: each counted class's
    ``vision.census.run_diameter_px`` (for the chords of a disc at uniform offsets it is d),
    the smallest over the classes (a class whose particles merge through gaps of its colour
    gives longer runs). NaN when no class has runs."""
    sizes = class_diameters_px(cfg, frame, roi)
    finite = [d for d in sizes if math.isfinite(d)]
    return float(min(finite)) if finite else float("nan")


def drum_labels(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> np.ndarray:
    """The class map (0 = none, ``j + 1`` = ``cfg.classes[j]``) of the ROI's bounding box of
    ``frame``, 0 outside the drum."""
    box = roi_bbox(roi, frame.shape[:2])
    x0, y0, x1, y1 = box
    lab = classify(np.ascontiguousarray(frame[y0:y1, x0:x1]), cfg.classes)
    lab[~_mask_in_box(roi, box)] = 0
    return lab


def class_diameters_px(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> list[float]:
    """``vision.census.run_diameter_px`` of every class of ``cfg`` in the drum of ``frame``
    (NaN for a reject class or one without runs), in the config's class order."""
    lab = drum_labels(cfg, frame, roi)
    return [float("nan") if cls.reject else run_diameter_px(lab == c)
            for c, cls in enumerate(cfg.classes, start=1)]


def opening_stride(diameter_px: float) -> int:
    """The meter's stride for the class opening: a power of two, at most ``diameter_px /
    OPENING_GRID`` (so a particle spans that many grid pixels and the cross fits in it, while
    the gaps between particles, their colour blurred in, shrink to a grid pixel or two), at
    most 8; 1 for an unknown or small diameter."""
    s = 1
    while math.isfinite(diameter_px) and s < 8 and 2 * s <= diameter_px / OPENING_GRID:
        s *= 2
    return s


def needs_opening(
    cfg: MeterConfig, frames: Sequence[np.ndarray], rois: Sequence[DrumROI], stride: int = 1
) -> bool | None:
    """Whether the class opening (``[meter] opening`` on the grid of ``stride``) changes what
    ``cfg`` measures on these frames: a class centroid moving by more than ``OPENING_SHIFT`` R
    on any frame (thin rims and gaps in a class's colour: JPEG chroma blur between particles of
    one hue). None when it would leave a class less than ``OPENING_KEEP`` of its pixels
    (particles too small for the grid)."""
    plain, opened = replace(cfg, opening=False), replace(cfg, opening=True, stride=stride)
    moved = False
    for img, roi in zip(frames, rois, strict=True):
        a, b = plain.make_meter(roi).measure(img), opened.make_meter(roi).measure(img)
        for sa, sb in zip(a.classes, b.classes, strict=True):
            if sa.n_px > 0 and sb.n_px < OPENING_KEEP * sa.n_px:
                return None
            shift = float(np.hypot(sa.cx_px - sb.cx_px, sa.cy_px - sb.cy_px)) / roi.r_px
            moved = moved or shift > OPENING_SHIFT  # (NaN, a class too small on a frame: no vote)
    return moved


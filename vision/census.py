"""What the camera says about the mixer: each class's particle size and share, the bed's fill
level, the rotation direction (``drumtwin classes suggest`` writes the twin's tables from it).

Pure functions of label maps and meter readings (no I/O). Units: px in the image; ``fill``
and ``share`` are fractions; the rotation is +1 counter-clockwise as the camera sees it
(the free surface rises to the right: the bed climbs the right-hand wall), -1 clockwise.

- **Size**: round particles are circles in the gray image (``circle_diameters_px``: OpenCV's
  gradient Hough transform; each circle belongs to the class that covers its core): the
  median circle of a class over the frames. The gray edge of a particle sets its size, not
  the class map, whose edges move with the light (a class that takes the dark gaps between
  its particles merges them into one blob; one that loses its shaded rim shrinks). Where a
  class has too few circles, or its single particles are not round, the run-length diameter
  of ``run_diameter_px`` (the length of the horizontal runs of a class that half of its
  pixels lie in, over the median chord of a disc) over the class's single particles
  (``single_particles``: the blobs with one distance-transform peak), the median over frames.
  Classes whose sizes agree within ``SAME_SIZE`` are one size, their mean (``same_size``).
- **Count**: the particles of a class in a frame (``count_particles``): per blob of its map,
  the peaks of its distance transform (touching particles keep separate centres) or, when
  more, as many particles as the blob's area holds at the bed's packing (a class that takes
  the gaps between its particles makes one blob of them, with few peaks); the median over frames.
- **Share**: each class's share of the bed's solid area, ``n_k a_k / sum n_j a_j`` with ``a_k`` its
  particle's area (``d_k^2`` times its shape's ratio to a disc; as ``sim.mixer`` counts it); the
  pixel share (the class's pixels over all classified pixels) beside it as a cross-check.
- **Fill**: the counted particles' area over the bed's packing fraction (the caller's
  ``packing``: ``sim.recipe.PACKING_2D``) and the drum's area.
- **Rotation**: the sign of the median free-surface slope.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

CHORD_MEDIAN = 0.91  # pixel-weighted median chord of a disc / its diameter: L = d sqrt(1 - u^2), weighted by L
MIN_RUNS = 20  # fewer horizontal runs of a class: no size
MIN_SLOPE_DEG = 2.0  # a flatter median surface says nothing about the direction
SAME_SIZE = 0.10  # diameters this close (relative to the smallest) are one size
PEAK_MIN_R = 0.3  # a distance-transform peak counts as a particle centre from this many diameters deep
PEAK_SPACING = 0.6  # peaks closer than this many diameters are one particle

CROP_PAD_PX = 2  # background pixels around a particle's crop
CROP_OPEN_D = 0.12  # a crop's opening (spurs, bridges to neighbours off), in particle diameters (0.25 rounded a
# notch's rim corners away: a 90-degree notch read 118 deg; docs/commissioning.md)
CROP_AREA = (0.4, 1.3)  # a single particle's blob: this many times a disc of the measured diameter

BODY_GRAY = 0.5  # a class's pixels darker than this times its median gray are gaps it took, not particle

CIRCLES_MIN = 12  # fewer circles of a class over the frames: its size from its runs
CIRCLE_CORE = 0.7  # a circle's core: the disc of this many of its radii ...
CIRCLE_COVER = 0.6  # ... of which its class covers at least this share
CIRCLE_GAPS = 0.05  # ... and at most this share is gap (``BODY_GRAY``): a circle round a ring of particles is none
CIRCLE_EDGE = 100.0  # Canny's upper threshold of the circle search (gray levels)
CIRCLE_SCORE = 0.6  # how round an edge must be to be a circle (OpenCV's HOUGH_GRADIENT_ALT param2)
CIRCLE_FINE_PX = 12.0  # a search for circles smaller than this (px) runs on the gray image upsampled x2
CIRCLE_FRAMES = 8  # frames the circle census searches (100 and more circles a frame)
CIRCLE_SCALE_FRAMES = 2  # ... of which the first search for the particles' scale
CIRCLE_SCALE_MIN = 5  # circles a class needs in that search (fewer: searched again upsampled)

__all__ = [
    "BODY_GRAY",
    "CHORD_MEDIAN",
    "CIRCLES_MIN",
    "CROP_AREA",
    "CROP_OPEN_D",
    "CROP_PAD_PX",
    "EDGE_REACH_PX",
    "ClassCensus",
    "ClassSize",
    "MixerCensus",
    "census",
    "circle_census",
    "circle_diameters_px",
    "class_size",
    "count_particles",
    "particle_body",
    "particle_edges",
    "rotation_from_slope",
    "run_diameter_px",
    "same_size",
    "single_particle_crops",
    "single_particles",
    "single_particles_at",
]


def _lit(values: np.ndarray) -> np.ndarray:
    """Which gray ``values`` (a class's or a circle's pixels) are particle, not gap: at least
    ``BODY_GRAY`` times their median."""
    v = np.asarray(values, dtype=float)
    return v >= BODY_GRAY * float(np.median(v))


def particle_body(mask: np.ndarray, gray: np.ndarray) -> np.ndarray:
    """The pixels of one class's boolean map that are particle, not gap: at least ``BODY_GRAY``
    times the class's median gray level in ``gray`` (same shape). Colour bleeding gives a
    class the dark gaps between its particles (dark, of its hue), which join its particles into
    blobs and square their outlines; the particles' own pixels are lighter. A class without
    pixels: the map as it is."""
    m = np.asarray(mask, dtype=bool)
    g = np.asarray(gray)
    if g.shape != m.shape:
        raise ValueError(f"mask and gray must be one (h, w) crop (got {m.shape}, {g.shape})")
    if not m.any():
        return m
    out = np.zeros_like(m)
    out[m] = _lit(g[m])
    return out


EDGE_REACH_PX = 2  # a class's outline may reach this far past its colour map, to its gray edge


def particle_edges(mask: np.ndarray, gray: np.ndarray, others: np.ndarray, background_gray: float) -> np.ndarray:
    """One class's particles bounded by their gray edges, for tracing their outlines: the pixels within
    ``EDGE_REACH_PX`` of the class's boolean map that are on the particles' side of the midpoint between
    the class's median gray and ``background_gray`` (the drum's empty part), less the pixels of the other
    classes (``others``). A class map's edges are ragged where colour was blurred (a camera's chroma is
    coarser than its luma: JPEG, Bayer); the gray edge is the particle's own, a neighbour of another
    colour stays out. Same shapes in and out."""
    m = np.asarray(mask, dtype=bool)
    g = np.asarray(gray, dtype=float)
    if not m.any():
        return m
    med = float(np.median(g[m]))
    thr = 0.5 * (med + float(background_gray))
    k = 2 * EDGE_REACH_PX + 1
    near = cv2.dilate(m.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))).astype(bool)
    lit = g >= thr if med >= background_gray else g <= thr
    return np.asarray(near & lit & ~np.asarray(others, dtype=bool))


def run_diameter_px(mask: np.ndarray) -> float:
    """A particle's diameter (px) from a boolean map of one class: the length of the horizontal
    runs that half of its pixels lie in, over ``CHORD_MEDIAN`` (fragments of a few pixels --
    noise, highlights -- hardly count). NaN with fewer than ``MIN_RUNS`` runs."""
    m = np.pad(np.asarray(mask, dtype=bool), ((0, 0), (1, 1)))
    starts = np.nonzero(m[:, 1:] & ~m[:, :-1])
    ends = np.nonzero(~m[:, 1:] & m[:, :-1])
    if starts[0].size < MIN_RUNS:
        return math.nan
    lengths = np.sort(ends[1] - starts[1])
    cum = np.cumsum(lengths)
    return float(lengths[np.searchsorted(cum, 0.5 * cum[-1])]) / CHORD_MEDIAN


def _peaks(mask: np.ndarray, diameter_px: float) -> np.ndarray:
    """Particle centres of one class: a boolean map of its distance transform's peaks at least
    ``PEAK_MIN_R`` diameters deep, one blob per ``PEAK_SPACING`` diameters."""
    m = np.pad(np.asarray(mask, dtype=np.uint8), 1)
    dt = cv2.distanceTransform(m, cv2.DIST_L2, 5)[1:-1, 1:-1]
    k = int(round(PEAK_SPACING * diameter_px)) | 1
    top = cv2.dilate(dt, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    return np.asarray((dt >= top) & (dt >= PEAK_MIN_R * diameter_px))


def count_particles(mask: np.ndarray, diameter_px: float, packing: float) -> int:
    """Particles of one class in a boolean map: per blob, the peaks of its distance transform
    (touching particles of one colour keep separate centres) or, when more, the discs of
    ``diameter_px`` its area holds at the 2D ``packing`` fraction (a class that takes the gaps
    between its particles -- colour bleeding -- makes one blob of them, with peaks only along
    its middle). 0 for an unknown diameter."""
    if not (math.isfinite(diameter_px) and diameter_px > 2):
        return 0
    m = np.asarray(mask, dtype=bool)
    blobs, per_blob = _peaks_per_blob(m, diameter_px)
    area = np.bincount(blobs.ravel(), minlength=per_blob.size).astype(float)
    by_area = np.floor(area * float(packing) / (0.25 * math.pi * diameter_px ** 2) + 0.5)
    n = np.maximum(per_blob, by_area)
    return int(n[1:].sum())


def circle_diameters_px(gray: np.ndarray, labels: np.ndarray, n_classes: int, d_lo_px: float,
                        d_hi_px: float) -> list[np.ndarray]:
    """Each class's round particles found as circles in a gray image: their diameters (px).

    ``gray`` (h, w) uint8 and ``labels`` (h, w) the same crop (``labels`` 0 = no class or
    outside the drum, ``k + 1`` = class k of ``n_classes``); circles of ``d_lo_px`` to
    ``d_hi_px`` across. OpenCV's gradient Hough transform (``HOUGH_GRADIENT_ALT``: Canny
    edges at ``CIRCLE_EDGE``, roundness ``CIRCLE_SCORE``; the image upsampled x2 below
    ``CIRCLE_FINE_PX``); a circle belongs to class k when that class covers ``CIRCLE_COVER``
    of its core (``CIRCLE_CORE`` of its radius) and at most ``CIRCLE_GAPS`` of the core is gap
    (darker than ``BODY_GRAY`` times its median gray): circles across two particles, round a
    ring of them, in a gap or outside the drum belong to none. The gray edge sets the size,
    not the class map's."""
    g = np.asarray(gray)
    lab = np.asarray(labels)
    if g.shape != lab.shape or g.ndim != 2:
        raise ValueError(f"gray and labels must be one (h, w) crop (got {g.shape}, {lab.shape})")
    out: list[list[float]] = [[] for _ in range(n_classes)]
    if not (math.isfinite(d_lo_px) and math.isfinite(d_hi_px) and 2.0 <= d_lo_px < d_hi_px):
        return [np.zeros(0) for _ in range(n_classes)]
    up = 2 if d_lo_px < CIRCLE_FINE_PX else 1
    src = cv2.resize(g, None, fx=up, fy=up, interpolation=cv2.INTER_CUBIC) if up > 1 else g
    r_lo = max(1, int(math.floor(0.5 * d_lo_px * up)))
    r_hi = max(r_lo + 1, int(math.ceil(0.5 * d_hi_px * up)))
    found = cv2.HoughCircles(np.ascontiguousarray(src, dtype=np.uint8), cv2.HOUGH_GRADIENT_ALT, dp=1.0,
                             minDist=max(2.0, r_lo), param1=CIRCLE_EDGE, param2=CIRCLE_SCORE,
                             minRadius=r_lo, maxRadius=r_hi)
    if found is None:
        return [np.zeros(0) for _ in range(n_classes)]
    h, w = lab.shape
    for x, y, r in np.asarray(found, dtype=float).reshape(-1, 3) / up:
        rc = CIRCLE_CORE * r
        x0, x1 = int(math.floor(x - rc)), int(math.ceil(x + rc)) + 1
        y0, y1 = int(math.floor(y - rc)), int(math.ceil(y + rc)) + 1
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        inside = (xx - x) ** 2 + (yy - y) ** 2 <= rc * rc
        core = lab[y0:y1, x0:x1][inside]
        if core.size == 0:
            continue
        cnt = np.bincount(core.astype(np.int64), minlength=n_classes + 1)[1:n_classes + 1]
        k = int(np.argmax(cnt))
        gaps = 1.0 - float(np.mean(_lit(g[y0:y1, x0:x1][inside])))
        if cnt[k] >= CIRCLE_COVER * core.size and gaps <= CIRCLE_GAPS:  # one particle, not a ring of several
            out[k].append(2.0 * float(r))
    return [np.asarray(v, dtype=float) for v in out]


def circle_census(grays: Sequence[np.ndarray], labels: Sequence[np.ndarray], n_classes: int,
                  classes: Sequence[int], d_hi_px: float) -> list[np.ndarray]:
    """The circles (diameters, px) of each class of ``classes`` (indices into the map's
    ``n_classes``) over up to ``CIRCLE_FRAMES`` of the frames (spread through them), searched
    from 0.6 times the smallest class's scale to ``d_hi_px``. The scale: the median circle of
    each class in a first search of ``CIRCLE_SCALE_FRAMES`` frames from ``CIRCLE_FINE_PX`` at
    the frames' resolution, or upsampled from half that when a class has fewer than
    ``CIRCLE_SCALE_MIN`` circles there (small particles; a class that is not round); the
    search's upper end then 1.6 times the largest class's scale when every class has one. A class's
    run length cannot set the lower bound: a class packed into blobs has long runs whatever
    its particles' size. Empty arrays when no class has circles."""
    if len(grays) != len(labels):
        raise ValueError(f"one class map per gray frame ({len(grays)} frames, {len(labels)} maps)")
    pick = np.unique(np.linspace(0, len(grays) - 1, min(CIRCLE_FRAMES, len(grays))).round().astype(int))
    none = [np.zeros(0) for _ in classes]
    if pick.size == 0:
        return none

    def search(frames: np.ndarray, lo: float, hi: float) -> list[np.ndarray]:
        found = [circle_diameters_px(grays[f], labels[f], n_classes, lo, hi) for f in frames]
        return [np.concatenate([fd[k] for fd in found]) for k in classes]

    first = pick[:CIRCLE_SCALE_FRAMES]
    scale = search(first, CIRCLE_FINE_PX, d_hi_px)
    if any(c.size < CIRCLE_SCALE_MIN for c in scale):
        scale = search(first, 0.5 * CIRCLE_FINE_PX, d_hi_px)
    meds = [float(np.median(c)) for c in scale if c.size >= CIRCLE_SCALE_MIN]
    if not meds:
        return none
    hi = min(d_hi_px, 1.6 * max(meds)) if len(meds) == len(classes) else d_hi_px
    return search(pick, max(0.5 * CIRCLE_FINE_PX, 0.6 * min(meds)), hi)


def _peaks_per_blob(m: np.ndarray, diameter_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The blobs of a boolean map (labels, 0 the background) and the particle centres
    (``_peaks``' plateaus) each holds."""
    n, blobs = cv2.connectedComponents(m.astype(np.uint8))
    # a peak is a small plateau: count each blob's peak plateaus, not its peak pixels; plateaus closer
    # than PEAK_SPACING diameters are one particle's (tied maxima: a notched disc's either side of its notch)
    k = max(1, int(round(0.5 * PEAK_SPACING * diameter_px))) | 1
    pk = cv2.dilate(_peaks(m, diameter_px).astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    npk, plateaus = cv2.connectedComponents(pk & m.astype(np.uint8))
    per_blob = np.zeros(n, dtype=np.int64)
    if npk > 1:
        first = np.zeros(npk, dtype=np.int64)
        ys, xs = np.nonzero(plateaus)
        first[plateaus[ys, xs]] = blobs[ys, xs]
        per_blob = np.bincount(first[1:], minlength=n)
    return blobs, per_blob


def single_particles(mask: np.ndarray, diameter_px: float) -> np.ndarray:
    """The blobs of a boolean map that hold exactly one particle centre (``count_particles``'s
    peaks), for a size that touching particles do not lengthen. ``diameter_px``: a first guess."""
    m = np.asarray(mask, dtype=bool)
    if not (math.isfinite(diameter_px) and diameter_px > 2):
        return m
    blobs, per_blob = _peaks_per_blob(m, diameter_px)
    one = per_blob == 1
    one[0] = False
    return np.asarray(one[blobs])


def single_particles_at(mask: np.ndarray, diameter_px: float, max_n: int = 12) -> list[tuple[np.ndarray, int, int]]:
    """Boolean crops of up to ``max_n`` single particles of a boolean class map and where each crop's
    corner lies in the map (x, y, px): blobs of at most one ``_peaks`` centre and ``CROP_AREA`` of a
    disc of ``diameter_px``, ``CROP_PAD_PX`` of background around each, opened by ``CROP_OPEN_D``
    (the largest piece kept), holes filled; those whose area is nearest the median single blob's
    first; blobs touching the map's border are left out. For tracing the particles' outline
    (``vision.shapes.particle_shape``) and drawing it where it was found."""
    m = np.asarray(mask, dtype=bool)
    if not (math.isfinite(diameter_px) and diameter_px > 2):
        return []
    blobs, per_blob = _peaks_per_blob(m, diameter_px)
    # one particle: at most one centre (a cut disc is too thin for a disc's centre) and about one
    # particle's area
    disc_px = math.pi / 4 * diameter_px ** 2
    n, _, stats, _ = cv2.connectedComponentsWithStats(m.astype(np.uint8))
    h, w = m.shape
    keep = [j for j in range(1, n)
            if per_blob[j] <= 1 and CROP_AREA[0] * disc_px <= stats[j, cv2.CC_STAT_AREA] <= CROP_AREA[1] * disc_px
            and stats[j, cv2.CC_STAT_LEFT] > 0 and stats[j, cv2.CC_STAT_TOP] > 0
            and stats[j, cv2.CC_STAT_LEFT] + stats[j, cv2.CC_STAT_WIDTH] < w
            and stats[j, cv2.CC_STAT_TOP] + stats[j, cv2.CC_STAT_HEIGHT] < h]
    if not keep:
        return []
    areas = np.array([stats[j, cv2.CC_STAT_AREA] for j in keep], dtype=float)
    order = np.argsort(np.abs(areas - np.median(areas)), kind="stable")[:max_n]
    out = []
    p = CROP_PAD_PX
    k = max(3, int(round(CROP_OPEN_D * diameter_px)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    for i in order:
        j = keep[int(i)]
        x, y = stats[j, cv2.CC_STAT_LEFT], stats[j, cv2.CC_STAT_TOP]
        bw, bh = stats[j, cv2.CC_STAT_WIDTH], stats[j, cv2.CC_STAT_HEIGHT]
        crop = np.zeros((bh + 2 * p, bw + 2 * p), np.uint8)
        crop[p:p + bh, p:p + bw] = (blobs[y:y + bh, x:x + bw] == j)
        # spurs and bridges to a neighbour's pixels off (an opening), the largest piece kept
        crop = cv2.morphologyEx(crop, cv2.MORPH_OPEN, kernel)
        nc, pieces, pst, _ = cv2.connectedComponentsWithStats(crop)
        if nc < 2:
            continue
        crop = (pieces == 1 + int(np.argmax(pst[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
        # holes (highlights, print lines) filled: the outline is the outer boundary
        cnts, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(crop, cnts, -1, 1, thickness=cv2.FILLED)
        out.append((crop.astype(bool), int(x) - p, int(y) - p))
    return out


def single_particle_crops(mask: np.ndarray, diameter_px: float, max_n: int = 12) -> list[np.ndarray]:
    """The crops of ``single_particles_at`` (without where they lie)."""
    return [c for c, _, _ in single_particles_at(mask, diameter_px, max_n)]


def same_size(diameters_px: Sequence[float]) -> tuple[list[float], bool]:
    """The classes' diameters, all set to their mean when every one is within ``SAME_SIZE`` of
    the smallest (one size, measured per class); True if they were."""
    d = [float(v) for v in diameters_px]
    if not d or not all(math.isfinite(v) for v in d):
        return d, False
    lo = min(d)
    if max(d) > lo * (1.0 + SAME_SIZE):
        return d, False
    mean = float(np.mean(d))
    return [mean] * len(d), True


def rotation_from_slope(slope_deg: float) -> int:
    """+1 (counter-clockwise as seen) when the free surface rises to the right, -1 when it rises
    to the left, 0 when it is flatter than ``MIN_SLOPE_DEG`` or unknown."""
    if not math.isfinite(slope_deg) or abs(slope_deg) < MIN_SLOPE_DEG:
        return 0
    return 1 if slope_deg > 0 else -1


@dataclass(frozen=True)
class ClassSize:
    """One class's own particle diameter (px) and where it came from: ``"circles"`` (the median
    of ``count`` circles, ``circle_diameters_px``), ``"outlines"`` (the median circle of ``count``
    clean traced outlines, ``vision.shapes.particle_shape``) or ``"runs"`` (the median over ``count``
    frames of ``run_diameter_px``); NaN when none measured it."""

    diameter_px: float
    source: str
    count: int


def class_size(circles_px: np.ndarray, runs_px: Sequence[float] | np.ndarray) -> ClassSize:
    """A class's size from its circles over the frames (``circle_diameters_px``, pooled) when it
    has at least ``CIRCLES_MIN`` of them, else from its per-frame run-length diameters (NaN:
    none). The caller uses the circles only for round particles (a cut disc's or a pellet's
    circles are not its size)."""
    c = np.asarray(circles_px, dtype=float)
    c = c[np.isfinite(c)]
    if c.size >= CIRCLES_MIN:
        return ClassSize(float(np.median(c)), "circles", int(c.size))
    r = np.asarray(runs_px, dtype=float)
    r = r[np.isfinite(r)]
    return ClassSize(float(np.median(r)) if r.size else math.nan, "runs", int(r.size))


@dataclass(frozen=True)
class ClassCensus:
    """One colour class: particle diameter (px; after ``same_size``), share of the bed's solid
    area, particles per frame, pixel share, and its own measured size (``ClassSize``)."""

    name: str
    diameter_px: float
    share: float
    count: float
    pixel_share: float
    own: ClassSize


@dataclass(frozen=True)
class MixerCensus:
    """The bed as the camera sees it (see the module doc); ``drum_r_px`` the drum's radius (px)."""

    classes: tuple[ClassCensus, ...]
    fill: float
    slope_deg: float
    direction: int
    drum_r_px: float
    frames: int
    same_size: bool = False  # the classes' sizes were set to their mean (``same_size``)
    frame_counts: tuple[float, ...] = ()  # particles per frame, every class together

    def diameter_mm(self, k: int, drum_diameter_mm: float) -> float:
        """Class ``k``'s particle diameter (mm), scaled by the drum's diameter."""
        return self.classes[k].diameter_px / (2.0 * self.drum_r_px) * float(drum_diameter_mm)


def census(
    names: Sequence[str],
    class_px: np.ndarray,
    roi_px: np.ndarray,
    sizes: Sequence[ClassSize],
    counts: np.ndarray,
    slopes_deg: Sequence[float],
    drum_r_px: float,
    packing: float,
    area_ratios: Sequence[float] | None = None,
) -> MixerCensus:
    """The census of ``len(roi_px)`` frames (see the module doc).

    Per class its own measured size (``sizes``: ``class_size``); per frame and class:
    ``class_px`` its pixels in the drum, ``counts`` its ``count_particles`` (at the size
    after ``same_size``); per frame ``roi_px`` the drum's pixels and ``slopes_deg`` the
    meter's free-surface slope; ``drum_r_px`` the drum's radius (px); ``packing`` the bed's
    2D packing fraction; ``area_ratios`` per class its particle's area over a disc of its size
    (a notched disc's less than 1; None: discs), for the shares and the fill.
    """
    shape = (len(roi_px), len(names))
    cpx = np.asarray(class_px, dtype=float).reshape(shape)
    cnt = np.asarray(counts, dtype=float).reshape(shape)
    if len(sizes) != len(names):
        raise ValueError(f"one size per class: {len(sizes)} sizes for {len(names)} classes")
    diameters, merged = same_size([s.diameter_px for s in sizes])
    n = [float(np.median(cnt[:, k])) for k in range(len(names))]
    ratios = [1.0] * len(names) if area_ratios is None else [float(a) for a in area_ratios]
    solid = [nk * dk * dk * ak if math.isfinite(dk) else 0.0 for nk, dk, ak in zip(n, diameters, ratios, strict=True)]
    total = sum(solid)
    pix = float(cpx.sum())
    out = tuple(
        ClassCensus(str(name), diameters[k], solid[k] / total if total > 0 else math.nan, n[k],
                    float(cpx[:, k].sum()) / pix if pix > 0 else math.nan, sizes[k])
        for k, name in enumerate(names)
    )
    drum_area = math.pi * float(drum_r_px) ** 2
    fill = 0.25 * math.pi * total / (float(packing) * drum_area) if drum_area > 0 else math.nan
    s = np.asarray([v for v in slopes_deg if math.isfinite(v)], dtype=float)
    slope = float(np.median(s)) if s.size else math.nan
    return MixerCensus(out, fill, slope, rotation_from_slope(slope), float(drum_r_px), int(len(roi_px)), merged,
                       tuple(float(v) for v in cnt.sum(axis=1)))

"""What the camera says about the mixer: each class's particle size and share, the bed's fill
level, the rotation direction (``drumtwin classes suggest`` writes the twin's tables from it).

Pure functions of label maps and meter readings (no I/O). Units: px in the image; ``fill``
and ``share`` are fractions; the rotation is +1 counter-clockwise as the camera sees it
(the free surface rises to the right: the bed climbs the right-hand wall), -1 clockwise.

- **Size**: the run-length diameter of ``run_diameter_px`` (the length of the horizontal
  runs of a class that half of its pixels lie in, over the median chord of a disc) over
  the class's single particles (``single_particles``: the blobs with one distance-transform
  peak; touching particles of one colour merge into longer runs), the median over frames.
  Classes whose sizes agree within ``SAME_SIZE`` are one size, their mean (``same_size``).
- **Count**: the particles of a class in a frame are the peaks of its distance transform
  (``count_particles``: touching particles keep separate centres), the median over frames.
- **Share**: each class's share of the bed's solid area, ``n_k d_k^2 / sum n_j d_j^2`` (as
  ``sim.mixer`` counts it); the pixel share (the class's pixels over all classified pixels)
  beside it as a cross-check.
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
CROP_OPEN_D = 0.25  # a crop's opening (spurs, bridges to neighbours off), in particle diameters
CROP_AREA = (0.4, 1.3)  # a single particle's blob: this many times a disc of the measured diameter

__all__ = ["CHORD_MEDIAN", "CROP_AREA", "CROP_OPEN_D", "CROP_PAD_PX", "ClassCensus", "MixerCensus", "census",
           "count_particles", "rotation_from_slope", "run_diameter_px", "same_size", "single_particle_crops",
           "single_particles"]


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


def count_particles(mask: np.ndarray, diameter_px: float) -> int:
    """Particles of one class in a boolean map: the peaks of its distance transform (touching
    particles of one colour keep separate centres). 0 for an unknown diameter."""
    if not (math.isfinite(diameter_px) and diameter_px > 2):
        return 0
    n, _ = cv2.connectedComponents(_peaks(mask, diameter_px).astype(np.uint8))
    return int(n - 1)


def _peaks_per_blob(m: np.ndarray, diameter_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The blobs of a boolean map (labels, 0 the background) and the particle centres
    (``_peaks``' plateaus) each holds."""
    n, blobs = cv2.connectedComponents(m.astype(np.uint8))
    # a peak is a small plateau: count each blob's peak plateaus, not its peak pixels
    npk, plateaus = cv2.connectedComponents(_peaks(m, diameter_px).astype(np.uint8))
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


def single_particle_crops(mask: np.ndarray, diameter_px: float, max_n: int = 12) -> list[np.ndarray]:
    """Boolean crops (``CROP_PAD_PX`` of background around each) of up to ``max_n`` single particles
    of a boolean class map (blobs of at most one ``_peaks`` centre and ``CROP_AREA`` of a disc of
    ``diameter_px``; opened by ``CROP_OPEN_D``, holes filled), those whose area is nearest
    the median single blob's first; blobs touching the map's border are left out. For tracing the
    particles' outline (the caller's: ``sim.mixer.shape_from_crops``)."""
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
        out.append(crop.astype(bool))
    return out


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
class ClassCensus:
    """One colour class: particle diameter (px; ``run_diameter_px`` its own runs' before
    ``same_size``), share of the bed's solid area, particles per frame, pixel share."""

    name: str
    diameter_px: float
    share: float
    count: float
    pixel_share: float
    run_diameter_px: float


@dataclass(frozen=True)
class MixerCensus:
    """The bed as the camera sees it (see the module doc); ``drum_r_px`` the drum's radius (px)."""

    classes: tuple[ClassCensus, ...]
    fill: float
    slope_deg: float
    direction: int
    drum_r_px: float
    frames: int
    same_size: bool = False  # the classes' sizes were set to the smallest (``same_size``)

    def diameter_mm(self, k: int, drum_diameter_mm: float) -> float:
        """Class ``k``'s particle diameter (mm), scaled by the drum's diameter."""
        return self.classes[k].diameter_px / (2.0 * self.drum_r_px) * float(drum_diameter_mm)


def census(
    names: Sequence[str],
    class_px: np.ndarray,
    roi_px: np.ndarray,
    diameters_px: np.ndarray,
    counts: np.ndarray,
    slopes_deg: Sequence[float],
    drum_r_px: float,
    packing: float,
) -> MixerCensus:
    """The census of ``len(roi_px)`` frames (see the module doc).

    Per frame and class: ``class_px`` its pixels in the drum, ``diameters_px`` its
    ``run_diameter_px`` (NaN: unknown), ``counts`` its ``count_particles``; per frame
    ``roi_px`` the drum's pixels and ``slopes_deg`` the meter's free-surface slope;
    ``drum_r_px`` the drum's radius (px); ``packing`` the bed's 2D packing fraction.
    """
    shape = (len(roi_px), len(names))
    cpx = np.asarray(class_px, dtype=float).reshape(shape)
    dia = np.asarray(diameters_px, dtype=float).reshape(shape)
    cnt = np.asarray(counts, dtype=float).reshape(shape)
    own = [float(np.median(dia[:, k][np.isfinite(dia[:, k])])) if np.isfinite(dia[:, k]).any() else math.nan
           for k in range(len(names))]
    sizes, merged = same_size(own)
    n = [float(np.median(cnt[:, k])) for k in range(len(names))]
    solid = [nk * dk * dk if math.isfinite(dk) else 0.0 for nk, dk in zip(n, sizes, strict=True)]
    total = sum(solid)
    pix = float(cpx.sum())
    out = tuple(
        ClassCensus(str(name), sizes[k], solid[k] / total if total > 0 else math.nan, n[k],
                    float(cpx[:, k].sum()) / pix if pix > 0 else math.nan, own[k])
        for k, name in enumerate(names)
    )
    drum_area = math.pi * float(drum_r_px) ** 2
    fill = 0.25 * math.pi * total / (float(packing) * drum_area) if drum_area > 0 else math.nan
    s = np.asarray([v for v in slopes_deg if math.isfinite(v)], dtype=float)
    slope = float(np.median(s)) if s.size else math.nan
    return MixerCensus(out, fill, slope, rotation_from_slope(slope), float(drum_r_px), int(len(roi_px)), merged)

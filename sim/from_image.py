"""Seed a twin from what the camera sees: sample its particles from the observed class map.

Each particle class of the mixer (or 2D disk class of the recipe) is matched to a vision
colour class by name (else by order); a shaped particle is placed as its circumscribed
disc. The disks are placed, largest first, at pixels of that class inside the drum ROI
(mapped to the drum frame: metres, origin at the axis, y up), by random sequential
addition at 80 % size with no overlaps. Of ``_CANDIDATES`` random pixels of its class, a
disk takes the free one deepest inside the class's region (its distance to the region's
edge, capped at the disk's radius): a disk centred on the edge of a blob of its colour
half covers the other class, and the seeded bed came out more mixed than the camera's
(the paper bed's camera MI against the seeded twin's, 3 seeds x 10/30/60 s at 5 rpm:
bias +0.07, rms 0.08 with the first free pixel; +0.01, 0.03 this way; the real PMMA frames
of tests/data seeded into configs/pmma-rig.toml, every 3rd frame: rms 0.011 -> 0.003, largest
0.028 -> 0.006). A disk that finds
no free pixel of its class is placed near its class (a wider and wider jitter about its
pixels), then anywhere in the drum. The disks are then
inflated and settled exactly as a fresh ``DrumSim`` is, so the twin starts from the
bed the camera shows (a what-if from "now" starts from the live state). A mixer that needs
the pymunk engine is seeded through ``PymunkDrumSim.from_placement`` (the mixer, centres,
classes, angles: what ``DrumSim.from_placement`` takes through its state).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from sim.drum import DrumSim, SimState
from sim.engine import from_placement
from sim.errors import SimError
from sim.mixer import Mixer, resolve
from sim.params import SimParams, check_params, check_rpm
from sim.placement import SHRINK, DiscGrid, disc_arrays
from sim.recipe import PAPER_DRUM, PAPER_RECIPE, DiskClass, DrumSpec, Recipe, slice_2d

_TRIES_PER_DISK = 400  # random candidates per try of the fallbacks
_CANDIDATES = 2000  # random class pixels a disk chooses the deepest free one of


def pixels_to_drum_m(xs_px: np.ndarray, ys_px: np.ndarray, roi, drum: DrumSpec) -> np.ndarray:
    """(n, 2) drum-frame positions (m, y up) of image pixels, given the drum ROI (px)."""
    scale = drum.radius_m / float(roi.r_px)
    return np.column_stack(((xs_px - roi.cx_px) * scale, -(ys_px - roi.cy_px) * scale))


def place_from_labels(
    labels: np.ndarray,
    roi,
    classes: Sequence[DiskClass],
    label_names: Sequence[str],
    drum: DrumSpec,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Disk centres (n, 2, m) and class indices (n,) sampled from a label map.

    ``labels``: uint8 map, 0 = none, ``j + 1`` = vision class ``label_names[j]``.
    """
    if labels.ndim != 2:
        raise SimError(f"label map must be 2D, got shape {labels.shape}")
    names = list(label_names)
    radius_m = drum.radius_m
    m_per_px = radius_m / float(roi.r_px)
    any_ys, any_xs = np.nonzero(labels)
    any_pts = pixels_to_drum_m(any_xs.astype(float), any_ys.astype(float), roi, drum)
    per_class: list[np.ndarray] = []
    depth_m: list[np.ndarray] = []  # each class pixel's distance to its region's edge (m)
    for k, c in enumerate(classes):
        j = names.index(c.name) + 1 if c.name in names else k + 1
        mask = (labels == j).astype(np.uint8)
        ys, xs = np.nonzero(mask)
        per_class.append(pixels_to_drum_m(xs.astype(float), ys.astype(float), roi, drum))
        depth_m.append(cv2.distanceTransform(mask, cv2.DIST_L2, 3)[ys, xs] * m_per_px)
    radii, cls, order, gap = disc_arrays(classes)
    small_r = radii * SHRINK
    pos = np.zeros((radii.size, 2))
    grid = DiscGrid(radius_m, small_r, gap)

    def first_free(p: np.ndarray, r: float, lim: float) -> np.ndarray | None:
        """The first candidate point inside the wall and clear of the placed disks (None: none is)."""
        k = grid.first_free(p, r, np.hypot(p[:, 0], p[:, 1]) <= lim)
        return None if k < 0 else p[k]

    def deepest_free(k: int, i: int, r: float, lim: float) -> np.ndarray | None:
        """The free candidate deepest inside class ``k``'s region (depth capped at the radius)."""
        pool = per_class[k]
        if len(pool) == 0:
            return None
        idx = rng.integers(0, len(pool), size=_CANDIDATES)
        cand = pool[idx] + rng.normal(0.0, 0.1 * radii[i], size=(_CANDIDATES, 2))  # sub-pixel jitter
        by_depth = np.argsort(-np.minimum(depth_m[k][idx], radii[i]), kind="stable")
        return first_free(cand[by_depth], r, lim)

    for i in order:
        r = small_r[i]
        lim = radius_m - radii[i] - gap
        found = deepest_free(int(cls[i]), int(i), r, lim)
        pool = per_class[cls[i]] if len(per_class[cls[i]]) else any_pts
        for spread in (0.5, 1.0, 2.0, 4.0, 8.0):  # near its class: a wider and wider jitter
            if found is not None or len(pool) == 0:
                break
            cand = pool[rng.integers(0, len(pool), size=_TRIES_PER_DISK)]
            found = first_free(cand + rng.normal(0.0, spread * radii[i], size=cand.shape), r, lim)
        if found is None:  # anywhere in the drum (random sequential addition)
            for _ in range(50):
                found = first_free(rng.uniform(-lim, lim, size=(_TRIES_PER_DISK, 2)), r, lim)
                if found is not None:
                    break
        if found is None:
            raise SimError(f"could not place {radii.size} disks from the image; the recipe does not fit the drum")
        pos[i] = found
        grid.add(i, found[0], found[1], r)
    return pos, cls


def seed_from_labels(
    labels: np.ndarray,
    roi,
    label_names: Sequence[str],
    *,
    drum: DrumSpec = PAPER_DRUM,
    recipe: Recipe = PAPER_RECIPE,
    rpm: float = 5.0,
    seed: int = 0,
    friction: float | None = None,
    rolling: float | None = None,
    settle_s: float = 0.3,
    mixer: Mixer | None = None,
    engine: str | None = None,
) -> Any:
    """A new twin whose particles are sampled from ``labels`` (see module doc): a ``DrumSim`` of
    ``drum`` + ``recipe``, or of ``mixer`` on ``engine`` (``sim.engine.engine_for``)."""
    if mixer is not None:
        drum = mixer.drum
    rpm = check_rpm(rpm, drum)
    base = SimParams()
    params = SimParams(
        friction=base.friction if friction is None else float(friction),
        rolling=base.rolling if rolling is None else float(rolling),
    )
    check_params(params)
    classes = tuple(slice_2d(recipe, drum)) if mixer is None else tuple(
        DiskClass(k.name, k.radius_m, k.count, k.density_kg_m3, k.colour_bgr) for k in resolve(mixer))
    rng = np.random.default_rng(seed)
    pos, cls = place_from_labels(labels, roi, classes, label_names, drum, rng)
    n = cls.size
    angles = rng.uniform(0, 2 * math.pi, n)
    if mixer is not None:  # the mixer's engine (engine_for), placed the same way on either
        return from_placement(mixer, pos, cls, angles, rpm, settle_s, engine=engine, seed=int(seed),
                              friction=params.friction, rolling=params.rolling)
    state = SimState(
        drum=drum, recipe=recipe, classes=classes, case="image", seed=int(seed),
        params=params, t_s=0.0, rpm_target=0.0, rpm_actual=0.0, drum_angle_rad=0.0, cls=cls, pos_m=pos,
        vel_m_s=np.zeros((n, 2)), angle_rad=angles, omega_rad_s=np.zeros(n), mixer=None,
    )
    return DrumSim.from_placement(state, rpm, settle_s)  # same construction as DrumSim.__init__


def seed_from_frame(image_bgr: np.ndarray, meter, **kwargs) -> Any:
    """Seed from a camera frame measured by a vision ``Meter`` (its classes and ROI)."""
    from vision.colours import classify
    from vision.roi import detect_drum, roi_mask

    roi = meter.roi if meter.roi is not None else detect_drum(image_bgr)
    mask = roi_mask(roi, image_bgr.shape[:2])
    labels = classify(image_bgr, meter.classes, mask)
    return seed_from_labels(labels, roi, [c.name for c in meter.classes], **kwargs)

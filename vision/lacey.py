"""Baseline: the Lacey mixing index on a grid of cells inside the drum ROI.

``M = (s0^2 - s^2) / (s0^2 - sr^2)`` with ``s^2`` the pixel-weighted variance of the
class-1 share over the cells, ``s0^2 = P (1 - P)`` (fully segregated) and ``sr^2`` the
same variance after *pixel randomization* (the particle pixels' labels shuffled within
the ROI; the standard fully-mixed reference for images). Counts per cell are vectorised
(reshape + sum); the randomization is one permutation per frame, seeded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vision.colours import DEFAULT_CLASSES, ColourClass, check_class_set, class_lut, counted_classes
from vision.moments import kernel_labels
from vision.roi import DrumROI, _mask_in_box, roi_bbox

__all__ = ["LaceyMeter", "LaceyResult", "lacey_from_labels"]


@dataclass(frozen=True, slots=True)
class LaceyResult:
    """Lacey index ``m`` (NaN when undefined) and its variances; ``n_cells`` cells used."""

    m: float
    s2: float
    s0_2: float
    sr_2: float
    n_cells: int


def _cell_counts(a: np.ndarray, b: np.ndarray, cell: int) -> tuple[np.ndarray, np.ndarray]:
    h, w = a.shape
    ny, nx = h // cell, w // cell
    a = a[: ny * cell, : nx * cell].reshape(ny, cell, nx, cell)
    b = b[: ny * cell, : nx * cell].reshape(ny, cell, nx, cell)
    return a.sum(axis=(1, 3), dtype=np.int32).ravel(), b.sum(axis=(1, 3), dtype=np.int32).ravel()


def _weighted_var(na: np.ndarray, nb: np.ndarray, p: float) -> float:
    n = na + nb
    share = na / n
    return float(np.sum(n * (share - p) ** 2) / np.sum(n))


def lacey_from_labels(
    labels: np.ndarray, inside: np.ndarray, cell_px: int, rng: np.random.Generator, min_fill: float = 0.25
) -> LaceyResult:
    """Lacey index from a label map (1 = class 1, 2 = class 2) and the ROI mask (bool).

    Cells lie on a ``cell_px`` grid; a cell counts when it is fully inside the ROI and at
    least ``min_fill`` of it is particle pixels.
    """
    nan = float("nan")
    a = labels == 1
    b = labels == 2
    na, nb = _cell_counts(a, b, cell_px)
    cover, _ = _cell_counts(inside, np.zeros_like(inside), cell_px)
    keep = (cover == cell_px * cell_px) & ((na + nb) >= min_fill * cell_px * cell_px)
    if keep.sum() < 2:
        return LaceyResult(nan, nan, nan, nan, int(keep.sum()))
    p = float(na[keep].sum() / (na[keep] + nb[keep]).sum())
    s0 = p * (1.0 - p)
    if s0 <= 0:
        return LaceyResult(nan, nan, s0, nan, int(keep.sum()))
    s2 = _weighted_var(na[keep], nb[keep], p)
    # pixel randomization: same particle pixels, labels shuffled among them
    particle = a | b
    idx = np.flatnonzero(particle.ravel())
    shuffled = rng.permutation(labels.ravel()[idx])
    ra_flat = np.zeros(labels.size, dtype=bool)
    ra_flat[idx[shuffled == 1]] = True
    ra = ra_flat.reshape(labels.shape)
    rb = particle & ~ra
    rna, rnb = _cell_counts(ra, rb, cell_px)
    sr = _weighted_var(rna[keep], rnb[keep], p)
    denom = s0 - sr
    m = (s0 - s2) / denom if denom > 0 else nan
    return LaceyResult(float(m), s2, s0, sr, int(keep.sum()))


class LaceyMeter:
    """Per-frame Lacey index with the same classes and ROI as the centroid meter.

    ``cell_px`` defaults to ``R / 5`` (about 78 cells in a full disc). Class 1 and 2 are
    the first two classes. ``opening`` applies the centroid meter's class opening
    (``vision.moments.open_labels``, through ``kernel_labels``), so both see the same pixels.
    """

    def __init__(
        self,
        classes: tuple[ColourClass, ...] | list[ColourClass] = DEFAULT_CLASSES,
        roi: DrumROI | None = None,
        cell_px: int | None = None,
        seed: int = 0,
        opening: bool = False,
    ) -> None:
        self.colour_classes = check_class_set(classes)
        self.classes = counted_classes(self.colour_classes)
        self._lut = class_lut(self.colour_classes)  # the centroid meter's exact classification
        self.roi = roi
        self.cell_px = cell_px
        self.rng = np.random.default_rng(seed)
        self.opening = bool(opening)
        self._key: tuple | None = None

    def measure(self, image_bgr: np.ndarray) -> LaceyResult:
        """Lacey index of one BGR frame (detects the drum when no ROI was given)."""
        if self.roi is None:
            from vision.roi import detect_drum

            self.roi = detect_drum(image_bgr)
        shape = image_bgr.shape[:2]
        if self._key != shape:
            box = roi_bbox(self.roi, shape)
            inside = _mask_in_box(self.roi, box)
            self._box, self._inside = box, inside
            self._cell = int(self.cell_px or max(4, round(self.roi.r_px / 5)))
            self._key = shape
        x0, y0, x1, y1 = self._box
        crop = np.ascontiguousarray(image_bgr[y0:y1, x0:x1])
        labels = kernel_labels(crop, self._lut, self._inside, self.opening)
        return lacey_from_labels(labels, self._inside, self._cell, self.rng)

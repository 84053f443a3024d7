"""Baseline: a GLCM texture mixing index (scikit-image ``graycomatrix``/``graycoprops``).

The ROI's gray image is quantized to ``levels`` gray levels; pixels outside the ROI get
an extra level that is dropped from the co-occurrence matrix. The index is the GLCM
contrast (mean over distances and 4 angles) divided by its value for a pixel-randomized
image, ``2 Var(level)`` (independent neighbours): near 0 for large uniform regions
(segregated), towards 1 when neighbouring pixels are as different as random ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vision.errors import VisionError
from vision.roi import DrumROI, _mask_in_box, detect_drum, roi_bbox

__all__ = ["GLCMMeter", "GLCMResult"]


@dataclass(frozen=True, slots=True)
class GLCMResult:
    """GLCM index ``m``, the raw mean ``contrast`` and ``homogeneity``."""

    m: float
    contrast: float
    homogeneity: float


class GLCMMeter:
    """Per-frame GLCM index inside the drum ROI."""

    def __init__(self, roi: DrumROI | None = None, levels: int = 16, distances: tuple[int, ...] = (1, 2, 4, 8)) -> None:
        try:
            from skimage.feature import graycomatrix, graycoprops
        except ImportError as exc:  # pragma: no cover - scikit-image is in the bench/test extras
            raise VisionError("the GLCM baseline needs scikit-image (pip install 'drumtwin[bench]')") from exc
        if not 2 <= levels <= 255:
            raise VisionError(f"GLCM levels must be within 2..255, got {levels}")
        self._gcm, self._gcp = graycomatrix, graycoprops
        self.roi = roi
        self.levels = int(levels)
        self.distances = tuple(int(d) for d in distances)
        self._key: tuple | None = None
        # gray -> level 1..levels (0 is "outside the ROI")
        self._lut = (1 + (np.arange(256) * self.levels) // 256).astype(np.uint8).reshape(256, 1)

    def measure(self, image_bgr: np.ndarray) -> GLCMResult:
        """GLCM index of one BGR frame (detects the drum when no ROI was given)."""
        if self.roi is None:
            self.roi = detect_drum(image_bgr)
        shape = image_bgr.shape[:2]
        if self._key != shape:
            self._box = roi_bbox(self.roi, shape)
            self._mask_u8 = np.where(_mask_in_box(self.roi, self._box), 255, 0).astype(np.uint8)
            self._key = shape
        x0, y0, x1, y1 = self._box
        gray = cv2.cvtColor(image_bgr[y0:y1, x0:x1], cv2.COLOR_BGR2GRAY)
        q = cv2.bitwise_and(cv2.LUT(gray, self._lut), self._mask_u8)
        angles = (0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4)
        p = self._gcm(q, self.distances, angles, levels=self.levels + 1, symmetric=True, normed=False)
        p = p[1:, 1:, :, :].astype(np.float64)
        tot = p.sum(axis=(0, 1), keepdims=True)
        tot[tot == 0] = 1.0
        p /= tot
        contrast = float(self._gcp(p, "contrast").mean())
        homog = float(self._gcp(p, "homogeneity").mean())
        vals = q[self._mask_u8 > 0].astype(np.float64)
        ref = 2.0 * float(vals.var()) if vals.size else 0.0
        m = contrast / ref if ref > 0 else float("nan")
        return GLCMResult(m, contrast, homog)

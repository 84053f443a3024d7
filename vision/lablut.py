"""The learned colour model's exact BGR lookup table (``vision.colours.class_lut``; pure, numba).

Every 8-bit BGR colour has one OpenCV 8-bit CIELAB value (about 2.1 M distinct ones); each
goes to the component with the highest likelihood and counts for its class when that class
is not a reject class and the colour lies within its ``max_distance`` (Mahalanobis).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from vision.colours import ColourClass, _every_bgr

__all__ = ["lab_lut"]


@lru_cache(maxsize=1)
def _every_lab8() -> tuple[np.ndarray, np.ndarray]:
    """OpenCV 8-bit CIELAB of every BGR colour as the distinct Lab values (n, 3) uint8
    (about 2.1 M) and, per BGR colour, the index of its Lab value (2^24 int32); built once."""
    lab = cv2.cvtColor(_every_bgr(), cv2.COLOR_BGR2Lab).reshape(-1, 3)
    lab32 = lab.astype(np.int32)
    key = (lab32[:, 0] << 16) | (lab32[:, 1] << 8) | lab32[:, 2]
    used = np.zeros(1 << 24, np.bool_)
    used[key] = True
    index = np.cumsum(used, dtype=np.int32) - 1
    values = np.nonzero(used)[0].astype(np.int32)
    uniq = np.stack([(values >> 16) & 255, (values >> 8) & 255, values & 255], axis=1).astype(np.uint8)
    return uniq, index[key]


def _lab_lut_py(lab8, means, precs, offsets, max_d2, labels, out):  # pragma: no cover - compiled
    n_comp = means.shape[0]
    for i in range(lab8.shape[0]):
        x0 = lab8[i, 0] * (100.0 / 255.0)
        x1 = lab8[i, 1] - 128.0
        x2 = lab8[i, 2] - 128.0
        best = 1e30
        best_j = 0
        best_d2 = 0.0
        for j in range(n_comp):
            d0 = x0 - means[j, 0]
            d1 = x1 - means[j, 1]
            d2 = x2 - means[j, 2]
            p = precs[j]
            q = (p[0] * d0 * d0 + p[3] * d1 * d1 + p[5] * d2 * d2
                 + 2.0 * (p[1] * d0 * d1 + p[2] * d0 * d2 + p[4] * d1 * d2))
            sc = q + offsets[j]
            if sc < best:
                best = sc
                best_j = j
                best_d2 = q
        out[i] = labels[best_j] if best_d2 <= max_d2[best_j] else 0


_lab_kernel = None


def lab_lut(classes: tuple[ColourClass, ...]) -> np.ndarray:
    """Learned model -> class per BGR colour (0 = none/reject, k = k-th counted class)."""
    global _lab_kernel
    means, precs, offsets, max_d2, labels = [], [], [], [], []
    k = 0
    for c in classes:
        label = 0
        if not c.reject:
            k += 1
            label = k
        for comp in c.lab:
            cov = comp.matrix()
            p = np.linalg.inv(cov)
            means.append(comp.mean_lab)
            precs.append((p[0, 0], p[0, 1], p[0, 2], p[1, 1], p[1, 2], p[2, 2]))
            offsets.append(float(np.log(np.linalg.det(cov)) - 2.0 * np.log(comp.weight)))
            max_d2.append(c.max_distance ** 2)
            labels.append(label)
    if _lab_kernel is None:
        import numba  # imported here: the CLI starts fast when no table is built

        _lab_kernel = numba.njit(nogil=True, cache=True, boundscheck=False)(_lab_lut_py)
    uniq, inverse = _every_lab8()
    per_lab = np.zeros(uniq.shape[0], np.uint8)
    _lab_kernel(uniq, np.array(means, np.float64), np.array(precs, np.float64), np.array(offsets, np.float64),
                np.array(max_d2, np.float64), np.array(labels, np.uint8), per_lab)
    return np.take(per_lab, inverse)

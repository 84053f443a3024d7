"""The class preview of ``classes suggest --preview``: a frame beside its class map (pure)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from vision.colours import ColourClass, classify, counted_classes
from vision.roi import DrumROI, _mask_in_box

__all__ = ["class_preview"]

_NO_CLASS_BGR = ((45, 45, 45), (150, 150, 150), (110, 30, 110))  # candidates, the first preferred


def _no_class_bgr(class_bgr: Sequence[tuple[int, int, int]]) -> tuple[int, int, int]:
    """The preview's colour for *no class*: dark grey, unless a class is shown in about that
    colour (black particles), then the candidate farthest from every class colour."""
    def gap(c: tuple[int, int, int]) -> float:
        return min((float(np.abs(np.subtract(c, k)).max()) for k in class_bgr), default=255.0)

    first = _NO_CLASS_BGR[0]
    return first if gap(first) >= 60 else max(_NO_CLASS_BGR, key=gap)


def class_preview(image_bgr: np.ndarray, classes: Sequence[ColourClass], roi: DrumROI) -> np.ndarray:
    """The frame beside its class map (each class in its display colour; no class dark grey,
    or, when a class is shown about that colour, another colour the legend shows), with the
    drum circle and a legend: a check at a glance."""
    img = np.asarray(image_bgr)
    h, w = img.shape[:2]
    labels = classify(img, tuple(classes))
    counted = counted_classes(classes)
    cmap = np.empty((len(counted) + 1, 3), np.uint8)
    cmap[0] = none_bgr = _no_class_bgr([c.display_bgr for c in counted])
    for i, c in enumerate(counted):
        cmap[i + 1] = c.display_bgr
    painted = cmap[labels]
    left, right = img.copy(), painted
    th = max(1, int(round(min(h, w) / 300)))
    for pane in (left, right):
        cv2.circle(pane, (int(round(roi.cx_px)), int(round(roi.cy_px))), int(round(roi.r_px)), (0, 255, 255), th,
                   cv2.LINE_AA)
    out = np.hstack([left, right])
    fs = max(0.4, min(h, w) / 900.0)
    lh = int(30 * fs) + 6
    inside = _mask_in_box(roi, (0, 0, w, h))
    n_in = max(int(inside.sum()), 1)
    lines: list[tuple[str, tuple[int, int, int] | None]] = [
        (f"{c.name}  {100 * float(((labels == i + 1) & inside).sum()) / n_in:.1f}% of drum", c.display_bgr)
        for i, c in enumerate(counted)
    ]
    lines.append(("no class (background, rim, glare, shadow)", none_bgr))
    width = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, fs, 1)[0][0] for t, _ in lines) + lh + 20
    panel = out[0: lh * len(lines) + 10, w: min(2 * w, w + width)]
    panel[...] = (panel * 0.3).astype(np.uint8)
    y = lh
    for text, colour in lines:
        x = w + 10
        if colour is not None:
            cv2.rectangle(out, (x, y - lh + 8), (x + lh - 8, y), colour, -1)
            cv2.rectangle(out, (x, y - lh + 8), (x + lh - 8, y), (255, 255, 255), 1)
        cv2.putText(out, text, (x + lh, y - 4), cv2.FONT_HERSHEY_SIMPLEX, fs, (255, 255, 255), 1, cv2.LINE_AA)
        y += lh
    return out

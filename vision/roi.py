"""The drum region of interest: a circle (front view) or a rectangle (top view).

``detect_drum`` finds the drum circle automatically (Hough on a downscaled image, then
a least-squares refinement on the rim edges); ``DrumROI`` given by hand overrides it.
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from vision.errors import VisionError

__all__ = ["DrumROI", "detect_drum", "parse_roi", "roi_bbox", "roi_mask"]


MAX_ROI_PX = 1e6  # no camera frame is larger: beyond this an ROI is a typo, not a drum


@dataclass(frozen=True, slots=True)
class DrumROI:
    """Drum region in image pixels.

    ``kind="circle"``: centre ``(cx_px, cy_px)`` and radius ``r_px``.
    ``kind="rect"``: centre and half sizes ``half_w_px``/``half_h_px``; ``r_px`` is the
    length used for the characteristic distance ``d_c`` (default ``min`` half size).
    """

    cx_px: float
    cy_px: float
    r_px: float
    kind: str = "circle"
    half_w_px: float | None = None
    half_h_px: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("circle", "rect"):
            raise VisionError(f"ROI kind must be 'circle' or 'rect', got {self.kind!r}")
        vals = [self.cx_px, self.cy_px, self.r_px]
        if not all(isinstance(v, (int, float, np.floating, np.integer)) and math.isfinite(v) for v in vals):
            raise VisionError(f"ROI needs finite cx, cy, r in px, got {vals}")
        if not all(abs(v) <= MAX_ROI_PX for v in vals):  # 1e308: finite, but cx + r overflows
            raise VisionError(f"ROI cx, cy, r must be within +-{MAX_ROI_PX:g} px, got {vals}")
        if self.r_px <= 0:
            raise VisionError(f"ROI radius must be > 0 px, got {self.r_px}")
        if self.kind == "rect":
            hw = self.r_px if self.half_w_px is None else self.half_w_px
            hh = self.r_px if self.half_h_px is None else self.half_h_px
            if not (0 < hw <= MAX_ROI_PX and 0 < hh <= MAX_ROI_PX):
                raise VisionError(f"rectangular ROI needs half sizes in (0, {MAX_ROI_PX:g}] px, got {hw}, {hh}")
            object.__setattr__(self, "half_w_px", float(hw))
            object.__setattr__(self, "half_h_px", float(hh))

    @property
    def area_px(self) -> float:
        """The region's area, px^2 (in the image or not)."""
        if self.kind == "circle":
            return math.pi * self.r_px**2
        assert self.half_w_px is not None and self.half_h_px is not None  # set for a rect by __post_init__
        return 4.0 * self.half_w_px * self.half_h_px

    def scaled(self, factor: float) -> DrumROI:
        """The same ROI in an image scaled by ``factor``."""
        f = float(factor)
        return DrumROI(
            self.cx_px * f, self.cy_px * f, self.r_px * f, self.kind,
            None if self.half_w_px is None else self.half_w_px * f,
            None if self.half_h_px is None else self.half_h_px * f,
        )


def parse_roi(text: str) -> DrumROI:
    """Parse ``"cx,cy,r"`` (px) into a circular ROI; a clear error otherwise."""
    try:
        parts = [float(p) for p in str(text).replace(" ", "").split(",")]
    except ValueError:
        parts = []
    if len(parts) != 3:
        raise VisionError(f"--roi must be 'cx,cy,r' in pixels, got {text!r}")
    return DrumROI(parts[0], parts[1], parts[2])


def roi_bbox(roi: DrumROI, shape_hw: tuple[int, int]) -> tuple[int, int, int, int]:
    """Bounding box ``(x0, y0, x1, y1)`` (half-open, clipped to the image) of the ROI."""
    h, w = int(shape_hw[0]), int(shape_hw[1])
    if roi.kind == "circle":
        hw = hh = roi.r_px
    else:
        hw, hh = roi.half_w_px, roi.half_h_px  # type: ignore[assignment]
    x0 = max(0, int(math.floor(roi.cx_px - hw)))
    y0 = max(0, int(math.floor(roi.cy_px - hh)))
    x1 = min(w, int(math.ceil(roi.cx_px + hw)) + 1)
    y1 = min(h, int(math.ceil(roi.cy_px + hh)) + 1)
    if x1 <= x0 or y1 <= y0:
        raise VisionError(f"the drum ROI (centre {roi.cx_px:g}, {roi.cy_px:g}, radius {roi.r_px:g} px) lies outside "
                          f"the {w}x{h} image")
    return x0, y0, x1, y1


def _mask_in_box(roi: DrumROI, box: tuple[int, int, int, int]) -> np.ndarray:
    x0, y0, x1, y1 = box
    ys = (np.arange(y0, y1, dtype=np.float64) - roi.cy_px)[:, None]
    xs = (np.arange(x0, x1, dtype=np.float64) - roi.cx_px)[None, :]
    if roi.kind == "circle":
        return xs * xs + ys * ys <= roi.r_px * roi.r_px
    return (np.abs(xs) <= roi.half_w_px) & (np.abs(ys) <= roi.half_h_px)


def roi_mask(roi: DrumROI, shape_hw: tuple[int, int]) -> np.ndarray:
    """Boolean mask (``shape_hw``) of the pixels inside the ROI (pixel centres at integers)."""
    h, w = int(shape_hw[0]), int(shape_hw[1])
    out = np.zeros((h, w), dtype=bool)
    try:
        x0, y0, x1, y1 = roi_bbox(roi, (h, w))
    except VisionError:
        return out
    out[y0:y1, x0:x1] = _mask_in_box(roi, (x0, y0, x1, y1))
    return out


def _edge_points(gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    edges = cv2.Canny(cv2.GaussianBlur(gray, (5, 5), 0), 20, 60)
    ys, xs = np.nonzero(edges)
    return ys, xs


def _rim_coverage(pts: tuple[np.ndarray, np.ndarray], cx: float, cy: float, r: float) -> int:
    """Degrees of the circle (0..360) with an edge pixel within 1.5% of its radius (a rim
    is a whole circle; the edge of a bed or a particle only an arc)."""
    ys, xs = pts
    rr = np.hypot(xs - cx, ys - cy)
    near = np.abs(rr - r) <= max(1.5, 0.015 * r)
    ang = (np.degrees(np.arctan2(ys[near] - cy, xs[near] - cx)) + 180.0).astype(np.int64) % 360
    return int(np.unique(ang).size)


def _in_frame_degrees(shape_hw: tuple[int, int], cx: float, cy: float, r: float) -> int:
    """Degrees of the circle (0..360) that lie inside the image."""
    a = np.radians(np.arange(360) + 0.5 - 180.0)
    x, y = cx + r * np.cos(a), cy + r * np.sin(a)
    return int(((x >= 0) & (x <= shape_hw[1] - 1) & (y >= 0) & (y <= shape_hw[0] - 1)).sum())


def _looks_like_a_rim(pts: tuple[np.ndarray, np.ndarray], shape_hw: tuple[int, int], cx: float, cy: float,
                      r: float) -> bool:
    """A drum's rim is a (nearly) whole circle of edges where the frame shows it, or at least an
    arc that stands out from the edges 10% inside and outside it (by >= 120 degrees, on the
    calmer side). The best circle through a scene without a drum (clutter, a photo) is a
    broken arc no clearer than its surroundings."""
    cover = _rim_coverage(pts, cx, cy, r)
    if cover >= 0.8 * _in_frame_degrees(shape_hw, cx, cy, r):
        return True
    around = min(_rim_coverage(pts, cx, cy, 0.9 * r), _rim_coverage(pts, cx, cy, 1.1 * r))
    return cover - around >= 120


def _refine_circle(
    pts: tuple[np.ndarray, np.ndarray], cx: float, cy: float, r: float
) -> tuple[float, float, float]:
    """Least-squares circle (Kasa, Tukey-reweighted) through the rim: per degree of angle, the
    outermost edge pixel within 6% (then 3%) of the coarse circle, so the edges of particles
    lying against the wall inside do not pull the circle in."""
    ys_all, xs_all = pts
    for band in (0.06, 0.03):
        rr = np.hypot(xs_all - cx, ys_all - cy)
        sel = np.abs(rr - r) < band * r
        if sel.sum() < 50:
            break
        xs, ys, rs = xs_all[sel], ys_all[sel], rr[sel]
        ang = (np.degrees(np.arctan2(ys - cy, xs - cx)) + 180.0).astype(np.int64) % 360
        order = np.lexsort((-rs, ang))  # per angle bin, the largest radius first
        first = np.ones(order.size, bool)
        first[1:] = ang[order][1:] != ang[order][:-1]
        pick = order[first]
        if pick.size < 30:
            break
        x = xs[pick].astype(np.float64)
        y = ys[pick].astype(np.float64)
        wts = np.ones_like(x)
        sol = None
        for _ in range(3):
            a = np.column_stack([x, y, np.ones_like(x)]) * wts[:, None]
            b = (x * x + y * y) * wts
            sol, *_ = np.linalg.lstsq(a, b, rcond=None)
            ncx, ncy = sol[0] / 2.0, sol[1] / 2.0
            nr2 = sol[2] + ncx * ncx + ncy * ncy
            if nr2 <= 0:
                break
            res = np.hypot(x - ncx, y - ncy) - math.sqrt(nr2)
            scale = max(1.4826 * float(np.median(np.abs(res))), 0.5)
            t = res / (4.685 * scale)
            wts = np.where(np.abs(t) < 1, (1 - t * t) ** 2, 0.0)
        assert sol is not None
        ncx, ncy = sol[0] / 2.0, sol[1] / 2.0
        nr2 = sol[2] + ncx * ncx + ncy * ncy
        if nr2 <= 0 or math.hypot(ncx - cx, ncy - cy) > 0.1 * r:
            break
        cx, cy, r = ncx, ncy, math.sqrt(nr2)
    return cx, cy, r


DETECT_MEMO = 64
"""Frames whose detection ``detect_drum`` remembers (by content): the same frame is often looked at
again (``classes suggest`` samples a frame, then sizes its particles and previews it; a new meter on
frames already seen), and a detection costs 10-50 ms against 1 ms to hash a VGA frame."""
_memo: OrderedDict[tuple, DrumROI | str] = OrderedDict()
_memo_lock = threading.Lock()


def detect_drum(image_bgr: np.ndarray, *, inset: float = 0.025) -> DrumROI:
    """Find the drum circle in a front-view frame (px of the original image).

    Hough transform on a copy downscaled to <= 400 px (median-filtered, then Gaussian-blurred
    if that finds no whole rim; at three vote thresholds each), a
    least-squares circle fit on the rim's outer edge for each candidate, and the candidate
    with the most complete rim wins. The radius is shrunk by ``inset`` (fraction) to keep the rim out.
    Raises ``VisionError`` when no circle is found, or the best one does not look like a rim
    (a scene without a drum; pass ``--roi cx,cy,r`` then).
    """
    img = np.asarray(image_bgr)
    if img.ndim == 3 and img.shape[2] == 3:
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    elif img.ndim == 2:
        gray = img
    else:
        raise VisionError(f"cannot detect a drum in an image of shape {img.shape}")
    if gray.dtype != np.uint8:
        raise VisionError(f"expected an 8-bit image, got dtype {gray.dtype}")
    # a pure function of the pixels: a frame seen before gets its answer (or its error) again
    key = (gray.shape, float(inset), hashlib.sha1(np.ascontiguousarray(gray).data).digest())
    with _memo_lock:
        seen = _memo.get(key)
        if seen is not None:
            _memo.move_to_end(key)
    if seen is None:
        try:
            seen = _detect(gray, inset)
        except VisionError as exc:
            seen = str(exc)
        with _memo_lock:
            _memo[key] = seen
            while len(_memo) > DETECT_MEMO:
                _memo.popitem(last=False)
    if isinstance(seen, str):
        raise VisionError(seen)
    return seen


def _detect(gray: np.ndarray, inset: float) -> DrumROI:
    """``detect_drum`` of an 8-bit gray frame, without the memo."""
    h, w = gray.shape
    s = min(1.0, 400.0 / max(h, w))
    small = cv2.resize(gray, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1.0 else gray.copy()
    sh, sw = small.shape
    pts = _edge_points(gray)
    best: tuple[int, tuple[float, float, float]] | None = None
    # the median keeps the rim and drops the particles' texture, but it erases a rim that the
    # downscaling made a line of a pixel or less (large frames): a Gaussian blur keeps that one
    for blurred in (cv2.medianBlur(small, 5), cv2.GaussianBlur(small, (5, 5), 0)):
        for acc in (30, 20, 12):
            circles = cv2.HoughCircles(
                blurred, cv2.HOUGH_GRADIENT, dp=1, minDist=max(sh, sw), param1=80, param2=acc,
                minRadius=int(0.25 * min(sh, sw)), maxRadius=int(0.6 * max(sh, sw)),
            )
            if circles is None:
                continue
            fit = _refine_circle(pts, *(float(v) / s for v in circles[0][0][:3]))
            cover = _rim_coverage(pts, *fit)
            if best is None or cover > best[0]:
                best = (cover, fit)
            if cover >= 300:  # a (nearly) whole rim: done; in a small frame the strongest circle can be the bed's edge
                break
        if best is not None and best[0] >= 300:
            break
    if best is None:
        raise VisionError("could not find the drum circle; pass --roi cx,cy,r (px)")
    cx, cy, r = best[1]
    if not _looks_like_a_rim(pts, (h, w), cx, cy, r):
        raise VisionError("could not find the drum circle (no circle of edges stands out as a rim: is the drum "
                          "in the picture?); pass --roi cx,cy,r (px)")
    return DrumROI(float(cx), float(cy), float(r * (1.0 - inset)))

"""Bed slope: the angle of the bed's free surface, its shape, and the principal-axis angle.

Free surface (``slope_deg``): the bed is counted into square cells (the meter's one pass
fills an occupancy grid; :func:`bed_surface` does it from a mask). For each column of
cells, scanning up from the drum wall, the bed's upper boundary is where the cell fill
drops below half the bed's interior fill (gaps of up to four cells are holes in the bed,
not its surface; a column whose bed reaches the wall above has no free surface), with a
sub-cell position from the fill of the boundary cells. A robust (Tukey-weighted,
orthogonal) line through those points over the central chord -- +-0.5 R along the
surface around its midpoint -- gives the angle. A cubic through all surface points gives
the shape: ``surface_curvature`` = minus the cubic coefficient of the profile ``v(u)``
(``u`` uphill along the central line, ``v`` out of the bed, both in units of R): 0 for
a flat surface, > 0 for the S-shape of a cascading bed (steeper in the middle, flatter
at both ends), < 0 for the reverse.

Principal axis (``slope_axis_deg``, :func:`slope_from_moments`): of the two principal
axes of the bed's pixels, the one more perpendicular to the offset from the drum centre
to the bed centroid. Exact for a flat surface (a circular segment), flatter than the
free surface for an S-shaped one.

Sign: angle against the image horizontal, in (-90, 90] degrees, positive when the
surface rises towards +x (to the right in the image, y up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vision.roi import DrumROI, _mask_in_box, roi_bbox

__all__ = [
    "SurfaceFit",
    "bed_slope_deg",
    "bed_surface",
    "cell_areas",
    "fit_surface_points",
    "occupancy_shift",
    "slope_from_moments",
    "surface_from_occupancy",
]

_NAN = float("nan")
CENTRAL_HALF_CHORD = 0.5
"""Half length of the central chord used for the angle, in units of the drum radius R."""


@dataclass(frozen=True, slots=True)
class SurfaceFit:
    """The free surface of one frame: angle (deg), S-shape (see module doc), points used."""

    slope_deg: float
    curvature: float
    n_points: int
    mid_px: tuple[float, float] = (_NAN, _NAN)
    """A point of the fitted central line (its weighted centre), image px."""


def slope_from_moments(
    m00: float, m10: float, m01: float, m20: float, m11: float, m02: float,
    cx_px: float, cy_px: float, min_px: float = 1.0,
) -> float:
    """Principal-axis angle (deg) from raw image moments of the bed (px units) and drum centre.

    NaN when the bed has fewer than ``min_px`` pixels or is isotropic (full drum).
    """
    if not (m00 >= min_px) or not math.isfinite(m00):
        return _NAN
    xb, yb = m10 / m00, m01 / m00
    mu20 = m20 / m00 - xb * xb
    mu02 = m02 / m00 - yb * yb
    mu11 = m11 / m00 - xb * yb
    if not (math.isfinite(mu20) and math.isfinite(mu02) and math.isfinite(mu11)):
        return _NAN
    theta = 0.5 * math.atan2(2.0 * mu11, mu20 - mu02)  # major axis, image coords (y down)
    ux, uy = math.cos(theta), math.sin(theta)
    ox, oy = xb - cx_px, yb - cy_px
    onorm = math.hypot(ox, oy)
    spread = math.sqrt(max(mu20 + mu02, 0.0))
    if onorm > 0.02 * spread:
        # the surface direction is the principal axis most perpendicular to the offset
        if abs(ux * ox + uy * oy) > abs(-uy * ox + ux * oy):
            ux, uy = -uy, ux
    elif abs(mu20 - mu02) < 1e-9 and abs(mu11) < 1e-9:
        return _NAN
    return _fold(math.degrees(math.atan2(-uy, ux)))  # y up


def _fold(ang: float) -> float:
    if ang <= -90.0:
        ang += 180.0
    elif ang > 90.0:
        ang -= 180.0
    return ang


def occupancy_shift(r_px: float, step: int = 1) -> int:
    """log2 of the occupancy cell size (px): cells of about R / 24, at least 2 grid pixels."""
    cell = max(2.0 * step, r_px / 24.0)
    return max(1, int(round(math.log2(cell))))


def cell_areas(inside: np.ndarray, step: int, shift: int, offset_xy: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Grid pixels of the ROI per occupancy cell: ``inside`` is the ROI mask of the box
    sampled at ``step`` (as the meter visits it), the cells starting ``offset_xy`` px left
    of and above its first pixel; float64, one entry per cell."""
    h, w = inside.shape
    ys = (np.arange(h) * step + offset_xy[1]) >> shift
    xs = (np.arange(w) * step + offset_xy[0]) >> shift
    out = np.zeros((int(ys[-1]) + 1 if h else 1, int(xs[-1]) + 1 if w else 1), np.float64)
    np.add.at(out, (ys[:, None], xs[None, :]), inside.astype(np.float64))
    return out


def _col_fill_py(occ, area, full_area, i, j, cols):  # pragma: no cover - compiled
    """Bed fill of cell row ``i`` over the columns j-1..j+1 (cells at least half in the ROI)."""
    s = 0.0
    a = 0.0
    for jj in range(max(0, j - 1), min(cols, j + 2)):
        if area[i, jj] >= 0.5 * full_area:
            s += occ[i, jj]
            a += area[i, jj]
    return s / a if a > 0 else 0.0


def _surface_py(occ, area, full_area, x0, y0, cs, r_px, pts_x, pts_y, res):  # pragma: no cover - compiled
    """Free-surface angle and S-shape from an occupancy grid; fills res = (deg, curvature, n)."""
    rows, cols = area.shape
    res[0] = np.nan
    res[1] = np.nan
    res[2] = 0.0
    res[3] = np.nan
    res[4] = np.nan
    # interior fill of the bed: the 85th percentile of the fill of well-covered cells (histogram)
    hist = np.zeros(129, np.int64)
    nv = 0
    half = 0.5 * full_area
    for i in range(rows):
        for j in range(cols):
            o = occ[i, j]
            if o > 0 and area[i, j] >= half:  # (empty cells first: no division for them)
                f = o / area[i, j]
                if f > 0.1:
                    b = int(f * 128.0)
                    hist[b if b < 128 else 128] += 1
                    nv += 1
    if nv < 8:
        return
    target = 0.85 * nv
    acc = 0
    rho = 1.0
    for b in range(129):
        acc += hist[b]
        if acc >= target:
            rho = (b + 0.5) / 128.0
            break
    tau = 0.5 * rho
    # per column: ROI span (top..bot) and the fill smoothed over the neighbouring columns
    fcol = np.zeros(rows)
    npts = 0
    for j in range(cols):
        top = 0  # the column's span of cells at least half in the ROI (convex: one span)
        while top < rows and area[top, j] < half:
            top += 1
        bot = rows - 1
        while bot > top and area[bot, j] < half:
            bot -= 1
        if top >= rows or bot - top < 3:
            continue
        # the fill is computed row by row going up from the wall, only as far as needed
        fcol[bot] = _col_fill(occ, area, full_area, bot, j, cols)
        fcol[bot - 1] = _col_fill(occ, area, full_area, bot - 1, j, cols)
        if fcol[bot] < tau and fcol[bot - 1] < tau:
            continue  # no bed at the bottom of this column
        it = bot if fcol[bot] >= tau else bot - 1
        gap = 0
        i = it - 1
        while i >= top:
            if i < bot - 1:
                fcol[i] = _col_fill(occ, area, full_area, i, j, cols)
            if fcol[i] >= tau:
                it = i
                gap = 0
            else:
                gap += 1
                if gap > 4:
                    break
            i -= 1
        if it <= top + 1:
            continue  # the bed reaches the wall above: no free surface in this column
        fill = (fcol[it] + fcol[it - 1]) / rho
        if fill > 2.0:
            fill = 2.0
        pts_x[npts] = x0 + j * cs + 0.5 * (cs - 1)
        pts_y[npts] = y0 + (it + 1) * cs - 0.5 - cs * fill
        npts += 1
    if npts < 5:
        return
    _fit_points(pts_x[:npts], pts_y[:npts], 0.25 * cs, r_px, res)


# Over 80 lines because it is a numba kernel (the exception to the 80-line rule), not a Python twin of
# one: ``_surface_fn`` compiles this very function (``_fit_points``), called by the surface kernel and
# by ``fit_surface_points``; scalar loops with no temporaries per iteration, as the module's kernels are.
def _fit_points_py(px, py, floor, r_px, res):  # pragma: no cover - compiled
    """The free surface through its points (image px, y down; 5 or more): robust line over the central chord,
    cubic S-shape; fills res as ``_surface_py`` (``floor``: least residual scale, px)."""
    npts = px.shape[0]
    w = np.ones(npts)
    base = np.empty(npts)
    ar = np.empty(npts)
    # robust orthogonal line over all points, then over the central chord (scalar loops:
    # no temporaries per iteration)
    ux = 1.0
    uy = 0.0
    mx = 0.0
    my = 0.0
    for stage in range(2):
        if stage == 1:
            umin = np.inf
            umax = -np.inf
            for k in range(npts):
                uk = (px[k] - mx) * ux + (py[k] - my) * uy
                umin = min(umin, uk)
                umax = max(umax, uk)
            mid = 0.5 * (umin + umax)
            nsel = 0
            for k in range(npts):
                uk = (px[k] - mx) * ux + (py[k] - my) * uy
                w[k] = 1.0 if abs(uk - mid) <= CENTRAL_HALF_CHORD * r_px else 0.0
                if w[k] > 0:
                    nsel += 1
            if nsel < 4:
                return
        for k in range(npts):
            base[k] = w[k]
        th_prev = np.inf
        for _ in range(6):
            sw = 0.0
            smx = 0.0
            smy = 0.0
            for k in range(npts):
                sw += w[k]
                smx += w[k] * px[k]
                smy += w[k] * py[k]
            if sw <= 0:
                return
            mx = smx / sw
            my = smy / sw
            sxx = 0.0
            syy = 0.0
            sxy = 0.0
            for k in range(npts):
                dx = px[k] - mx
                dy = py[k] - my
                sxx += w[k] * dx * dx
                syy += w[k] * dy * dy
                sxy += w[k] * dx * dy
            th = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
            ux = math.cos(th)
            uy = math.sin(th)
            if abs(th - th_prev) < 1e-9:
                break  # converged: the weights would not change any more
            th_prev = th
            na = 0
            for k in range(npts):
                if base[k] > 0:
                    ar[na] = abs(-(px[k] - mx) * uy + (py[k] - my) * ux)
                    na += 1
            scale = 1.4826 * np.median(ar[:na])
            lim = 4.685 * max(scale, floor)
            for k in range(npts):
                if base[k] > 0:
                    t = (-(px[k] - mx) * uy + (py[k] - my) * ux) / lim
                    w[k] = (1.0 - t * t) ** 2 if abs(t) < 1.0 else 0.0
                else:
                    w[k] = 0.0
    ang = math.degrees(math.atan2(-uy, ux))
    if ang <= -90.0:
        ang += 180.0
    elif ang > 90.0:
        ang -= 180.0
    res[0] = ang
    res[2] = npts
    res[3] = mx
    res[4] = my
    # shape: cubic v(u) over all points; u uphill, v out of the bed (up), in units of R
    if ux < 0:
        ux = -ux
        uy = -uy
    sgn = 1.0 if ang >= 0 else -1.0  # uphill is +x for a surface rising to the right
    umin = np.inf
    umax = -np.inf
    for k in range(npts):
        uk = sgn * ((px[k] - mx) * ux + (py[k] - my) * uy) / r_px
        umin = min(umin, uk)
        umax = max(umax, uk)
    mid = 0.5 * (umin + umax)
    ata = np.zeros((4, 4))
    atb = np.zeros(4)
    for k in range(npts):
        uk = sgn * ((px[k] - mx) * ux + (py[k] - my) * uy) / r_px - mid
        vk = -(-(px[k] - mx) * uy + (py[k] - my) * ux) / r_px  # image y is down: flip to "up"
        pm = 1.0
        for m in range(4):
            atb[m] += pm * vk
            pq = pm * pm
            for q in range(m, 4):
                ata[m, q] += pq
                pq *= uk
            pm *= uk
    for m in range(4):
        for q in range(m):
            ata[m, q] = ata[q, m]
    if abs(np.linalg.det(ata)) < 1e-12:
        return
    c = np.linalg.solve(ata, atb)
    res[1] = -c[3]


_surface_kernel = None
_col_fill = _col_fill_py  # replaced by its compiled form before _surface_py is compiled
_fit_points = _fit_points_py  # likewise


def _surface_fn():
    global _surface_kernel, _col_fill, _fit_points
    if _surface_kernel is None:
        import numba

        _col_fill = numba.njit(nogil=True, cache=True, inline="always")(_col_fill_py)
        _fit_points = numba.njit(nogil=True, cache=True)(_fit_points_py)
        _surface_kernel = numba.njit(nogil=True, cache=True)(_surface_py)
    return _surface_kernel


def fit_surface_points(x: np.ndarray, y: np.ndarray, r: float, floor: float) -> SurfaceFit:
    """The free surface through surface points ``x``, ``y`` (any length unit, y down as in an image) of a drum
    of radius ``r``: the meter's robust line over the central chord and its cubic S-shape (module doc);
    ``floor`` = least residual scale of the robust weights. ``mid_px`` in the points' unit."""
    res = np.full(5, np.nan)
    if len(x) >= 5:
        _surface_fn()
        _fit_points(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64), float(floor),
                    float(r), res)
    return SurfaceFit(float(res[0]), float(res[1]), int(np.nan_to_num(res[2])), (float(res[3]), float(res[4])))


def surface_from_occupancy(
    occ: np.ndarray, area: np.ndarray, full_area: float, origin_xy: tuple[float, float], shift: int, r_px: float,
    work: np.ndarray | None = None,
) -> SurfaceFit:
    """Free surface from bed pixels per cell ``occ`` and ROI pixels per cell ``area``.

    ``full_area`` = grid pixels of a whole cell; cells of ``2^shift`` px from ``origin_xy``;
    ``r_px`` = drum radius. ``work`` (float64, >= 2 x columns + 5) avoids allocations.
    """
    rows, cols = area.shape
    if work is None or work.shape[0] < 2 * cols + 5:
        work = np.empty(2 * cols + 5, np.float64)
    res = work[2 * cols: 2 * cols + 5]
    _surface_fn()(occ[:rows, :cols], area, float(full_area), float(origin_xy[0]), float(origin_xy[1]),
                  float(1 << shift), float(r_px), work[:cols], work[cols: 2 * cols], res)
    return SurfaceFit(float(res[0]), float(res[1]), int(res[2]), (float(res[3]), float(res[4])))


def bed_surface(bed_mask: np.ndarray, roi: DrumROI) -> SurfaceFit:
    """The free surface of the bed in ``bed_mask`` (bool/uint8, image-sized; only pixels in ``roi``)."""
    m = np.asarray(bed_mask) != 0
    box = roi_bbox(roi, m.shape[:2])
    x0, y0, x1, y1 = box
    inside = _mask_in_box(roi, box)
    bed = m[y0:y1, x0:x1] & inside
    shift = occupancy_shift(roi.r_px)
    area = cell_areas(inside, 1, shift)
    occ = np.zeros(area.shape, np.int32)
    ys, xs = np.nonzero(bed)
    np.add.at(occ, (ys >> shift, xs >> shift), 1)
    return surface_from_occupancy(occ, area, float(1 << (2 * shift)), (x0, y0), shift, roi.r_px)


def bed_slope_deg(bed_mask: np.ndarray, roi: DrumROI) -> float:
    """Free-surface angle (deg) of the bed in ``bed_mask`` (bool/uint8, image-sized); NaN if none."""
    return bed_surface(bed_mask, roi).slope_deg

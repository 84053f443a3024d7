"""Per-class pixel moments of a BGR frame in one pass: the meter's hot loop.

A class set (HSV boxes or a learned CIELAB model) is compiled once into lookup tables over BGR colours:
a 6-bit table (64^3 bins, 256 KB, stays in cache) answers for every bin whose 64 colours
all fall in the same class, and a full 24-bit table (16 MB) answers the few pixels whose
bin straddles a class boundary. Both come from ``vision.colours.class_lut``, which runs the
classifier itself on every BGR colour, so the result is exact, pixel for pixel. A compiled
(numba) loop then visits the ROI's pixels row span by row span and sums, per class, n,
x, y, x^2, y^2 and xy (integers, exact), plus the same for dark pixels
(V = max(B, G, R) <= ``dark_v_max``) for a backlit bed. Within a row it follows runs of
one class: a pixel that continues the run costs one table look-up and one compare, and
a run's sums are added from prefix sums of x and x^2 when it ends; its pixels per
free-surface occupancy cell are two marks (+1 at its start, -1 past its end) that go into
the cells once per cell row (one walk over the columns, not one per run and cell). The
optional class opening (``opening``: a one-pixel erosion, then a dilation back inside the
class) classifies each row into a label row first and is a
separate compiled kernel, so the plain one carries none of it. Clipped light gets a label
of its own (``GLARE_MIN``): its moments and cells tell the meter where to fill it in
(``vision.glare``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from vision.colours import Classifier, ColourClass, class_lut, class_mean_lab, counted_classes, lut_labels
from vision.errors import VisionError

__all__ = ["GLARE_MIN", "MOMENT_FIELDS", "ClassTables", "class_tables", "frame_moments", "kernel_labels", "open_labels",
           "remapped_tables", "row_spans"]

MOMENT_FIELDS = ("n", "sx", "sy", "sxx", "syy", "sxy")
"""Columns of :func:`frame_moments`'s result: pixel count and raw sums in px, px^2."""

_AMBIGUOUS = 255  # 6-bit table: this bin straddles a class boundary, ask the 24-bit table

GLARE_MIN = 250
"""A colour with every channel at or above this is *glare* (clipped light: the tables give
it the label ``n_classes + 1``, see ``vision.glare``) unless an achromatic class claims it:
an HSV class, or a learned class whose mean colour has a CIELAB chroma of at most
``GLARE_CHROMA`` (white or grey particles clip too). A coloured class's learned spread
may reach white through its particles' highlights, but clipped white carries no hue."""
GLARE_CHROMA = 12.0


@dataclass(frozen=True, eq=False)
class ClassTables:
    """The two BGR lookup tables of one class set: ``coarse`` (64^3) and ``fine`` (256^3).

    Values: 0 = no class, k = the k-th class (1-based), ``n_classes + 1`` = glare (every
    channel >= ``GLARE_MIN`` and no counted class); ``coarse`` uses 255 for a bin that the
    fine table must decide.
    """

    coarse: np.ndarray
    fine: np.ndarray
    n_classes: int


def _coarse_py(fine, out):  # pragma: no cover - compiled
    """out[bin] = the class of a 4x4x4 BGR bin when all its colours agree, else 255."""
    for b in range(64):
        for g in range(64):
            for r in range(64):
                first = fine[((b * 4) << 16) | ((g * 4) << 8) | (r * 4)]
                same = True
                for db in range(4):
                    for dg in range(4):
                        base = (((b * 4 + db) << 16) | ((g * 4 + dg) << 8)) + r * 4
                        for dr in range(4):
                            if fine[base + dr] != first:
                                same = False
                out[(b << 12) | (g << 6) | r] = first if same else _AMBIGUOUS


_coarse_kernel = None


def _remap_py(base, mb, mg, mr, out):  # pragma: no cover - compiled
    """out[b, g, r] = base[mb[b], mg[g], mr[r]] over every BGR colour (2^24 entries)."""
    for b in range(256):
        ib = np.int64(mb[b]) << 16
        for g in range(256):
            ig = ib | (np.int64(mg[g]) << 8)
            o = (b << 16) | (g << 8)
            for r in range(256):
                out[o | r] = base[ig | mr[r]]


_remap_kernel = None


@lru_cache(maxsize=8)
def _tables(classes: tuple[ColourClass, ...]) -> ClassTables:
    # (the cached table stays as it is: Lacey and classify share it)
    return _finish_tables(class_lut(classes).copy(), classes)


def remapped_tables(classes: Sequence[ColourClass], maps_bgr: np.ndarray) -> ClassTables:
    """The lookup tables of a class set read through per-channel maps: a colour (b, g, r) of
    the frame gets the class of (maps[0][b], maps[1][g], maps[2][r]) -- the colour it had in
    the reference light (``vision.photometric``). Glare is judged on the frame's own values.
    ``maps_bgr``: uint8 (3, 256). One re-bake of the 2^24 table (~0.1 s; ``drumtwin bench
    vision`` measures it)."""
    global _remap_kernel
    maps = np.ascontiguousarray(maps_bgr, np.uint8)
    if maps.shape != (3, 256):
        raise VisionError(f"channel maps must be 3 x 256, got {maps.shape}")
    classes = tuple(classes)
    if _remap_kernel is None:
        import numba

        _remap_kernel = numba.njit(nogil=True, cache=True, boundscheck=False)(_remap_py)
    fine = np.empty(1 << 24, np.uint8)
    _remap_kernel(class_lut(classes), maps[0], maps[1], maps[2], fine)
    return _finish_tables(fine, classes)


def _finish_tables(fine: np.ndarray, classes: tuple[ColourClass, ...]) -> ClassTables:
    """The glare label and the coarse table over a fine class table (changed in place)."""
    global _coarse_kernel
    counted = counted_classes(classes)
    sat = np.arange(GLARE_MIN, 256, dtype=np.int64)
    idx = ((sat[:, None, None] << 16) | (sat[None, :, None] << 8) | sat[None, None, :]).ravel()
    keep = [k + 1 for k, c in enumerate(counted) if not c.lab or _chroma(c) <= GLARE_CHROMA]
    fine[idx[~np.isin(fine[idx], keep)]] = len(counted) + 1
    if _coarse_kernel is None:
        import numba

        _coarse_kernel = numba.njit(nogil=True, cache=True, boundscheck=False)(_coarse_py)
    coarse = np.empty(1 << 18, np.uint8)
    _coarse_kernel(fine, coarse)
    return ClassTables(coarse, fine, len(counted))


def _chroma(c: ColourClass) -> float:
    """CIELAB chroma of a learned class's mean colour (its components' weighted mean)."""
    return float(np.hypot(*class_mean_lab(c)[1:]))


def class_tables(classes: Sequence[ColourClass] | Classifier) -> ClassTables:
    """The lookup tables of a class set (HSV or learned; built once per class set, ~1-3 s; cached)."""
    if isinstance(classes, Classifier):
        classes = classes.classes
    return _tables(tuple(classes))


def row_spans(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and one-past-last nonzero column of each row of a convex ``mask`` (H, W).

    Rows with nothing set get an empty span (0, 0). Returns two int64 arrays of length H.
    """
    m = np.asarray(mask) != 0
    any_ = m.any(axis=1)
    first = np.where(any_, m.argmax(axis=1), 0)
    last = np.where(any_, m.shape[1] - m[:, ::-1].argmax(axis=1), 0)
    return first.astype(np.int64), last.astype(np.int64)


def open_labels(labels: np.ndarray) -> np.ndarray:
    """The class opening of ``frame_moments(..., opening=True)`` on a label map (H, W; 0 =
    no class), with the 4-neighbour cross: a pixel survives the erosion when its four
    neighbours have its class (pixels off the map count as 0), and keeps its class when it
    or one of its four neighbours survived. Thin rims and gaps (one or two pixels wide)
    lose their class; a particle keeps every pixel it can fit the cross into, so its
    centroid does not move (an erosion alone would shift it away from holes and edges).
    Returns a new array."""
    lab = np.asarray(labels)
    p = np.pad(lab, 1)
    core = (p[1:-1, :-2] == lab) & (p[1:-1, 2:] == lab) & (p[:-2, 1:-1] == lab) & (p[2:, 1:-1] == lab) & (lab != 0)
    q = np.pad(core, 1)
    keep = core | q[1:-1, :-2] | q[1:-1, 2:] | q[:-2, 1:-1] | q[2:, 1:-1]
    return np.where(keep, lab, 0).astype(lab.dtype)


def kernel_labels(image_bgr: np.ndarray, lut: np.ndarray, inside: np.ndarray, opening: bool = False) -> np.ndarray:
    """The labels the moments kernel counts, as a map (uint8, H x W): ``lut``'s label of each pixel
    of a BGR image (``ClassTables.fine``, or a ``class_lut`` without the glare label), 0 outside
    ``inside`` (bool, H x W), then the class opening (:func:`open_labels`) when ``opening``."""
    labels = lut_labels(image_bgr, lut)
    labels[~inside] = 0
    return open_labels(labels) if opening else labels


def _add_run_py(hist, c, j0, j1, s1, s2):  # pragma: no cover - compiled
    """Adds the run of grid columns [j0, j1) to class c's row sums: n, sum x, sum x^2, from
    the prefix sums ``s1``, ``s2`` of the grid columns' x and x^2 (exact integers)."""
    hist[c, 0] += j1 - j0
    hist[c, 1] += s1[j1] - s1[j0]
    hist[c, 2] += s2[j1] - s2[j0]


def _flush_cells_py(dcol, gdcol, colcell, orow, grow, width):  # pragma: no cover - compiled
    """Adds the bed and glare runs marked in ``dcol``/``gdcol`` (+1 at a run's first grid
    column, -1 past its last) to the cells of one cell row (``colcell``: each grid column's
    cell), and clears the marks."""
    pd = 0
    pg = 0
    for j in range(width + 1):
        pd += dcol[j]
        pg += gdcol[j]
        dcol[j] = 0
        gdcol[j] = 0
        q = colcell[j]
        orow[q] += pd
        grow[q] += pg


_add_run = _add_run_py  # replaced by their compiled forms before a kernel is compiled
_flush_cells = _flush_cells_py


# Over 80 lines because it is a numba kernel (the exception to the 80-line rule): ``kernel`` is the
# source ``numba.njit`` compiles in ``_compiled``, one pass over the row spans whose stages share the
# row buffers (label rows, prefix sums, cell columns); its self-contained pieces are already helpers
# that numba inlines (``_add_run``, ``_flush_cells``).
def _make_kernel(opening: bool):
    """The moments kernel, with or without the class opening (``opening`` is a compile-time
    constant of the closure, so the plain kernel carries none of its code)."""

    def kernel(  # pragma: no cover - compiled
        img, rs, y0, x0, step, first, last, coarse, fine, n_classes, dark_v_max, out, occ, occ_shift, occ_dark, gocc,
        occ_ox, occ_oy,
    ):
        """``img``: the frame's bytes (flat uint8, B G R per pixel, ``rs`` bytes per image row);
        offsets into it are unsigned (no negative-index wrap-around per access: the plain pass
        costs 0.78 of the 3-D ``img[y][x, c]`` form). Sums into ``out`` (n_classes + 2, 6)
        int64; row k-1 is class k, row n_classes glare (label n_classes + 1), the last row
        dark pixels.

        ``occ`` (cells of 2^occ_shift px from (x0 - occ_ox, y0 - occ_oy)): bed pixels per cell -- the
        classified pixels (before any opening), or the dark pixels when ``occ_dark``; ``gocc``
        the same cells' glare pixels (after any opening). With
        ``opening``, grid row i + 2 is classified into a label row (five kept, zero outside
        the spans), row i + 1 eroded (a pixel keeps its class when its four grid neighbours
        have it; three kept) and a pixel of row i counts for its class when it or one of its
        four neighbours survived the erosion."""
        out[:, :] = 0
        occ[:, :] = 0
        gocc[:, :] = 0
        one = np.uint64(1)
        two = np.uint64(2)
        step3 = np.uint64(3 * step)
        hist = np.zeros((n_classes + 2, 3), np.int64)
        nrows = first.shape[0]
        width = 0
        for i in range(nrows):
            width = max(width, last[i])
        s1 = np.empty(width + 1, np.int64)  # prefix sums of the grid columns' x and x^2 (px)
        s2 = np.empty(width + 1, np.int64)
        s1[0] = 0
        s2[0] = 0
        for j in range(width):
            x = x0 + j * step
            s1[j + 1] = s1[j] + x
            s2[j + 1] = s2[j] + x * x
        dcol = np.zeros(1 if opening else width + 1, np.int64)  # plain kernel: +1 at a bed run's start, -1 past its end
        gdcol = np.zeros(1 if opening else width + 1, np.int64)  # the same for glare runs
        colcell = np.empty(width + 1, np.int64)  # occupancy cell of each grid column
        for j in range(width + 1):
            colcell[j] = min((j * step + occ_ox) >> occ_shift, occ.shape[1] - 1)
        pending = False
        pci = 0
        lbuf = np.zeros((5, width + 2 if opening else 1), np.uint8)  # label rows: the opening only
        ebuf = np.zeros((3, width + 2 if opening else 1), np.uint8)  # eroded rows
        for i in range(-2 if opening else 0, nrows):
            if opening:
                # classify grid row i + 2 into its label row
                k = i + 2
                dst = lbuf[k % 5]
                if k >= 5:  # the slot held row k - 5: clear its span
                    for j in range(first[k - 5], last[k - 5]):
                        dst[j + 1] = 0
                if k < nrows and last[k] > first[k]:
                    kp = np.uint64((y0 + k * step) * rs + (x0 + first[k] * step) * 3)
                    for j in range(first[k], last[k]):
                        bb = np.int64(img[kp])
                        gg = np.int64(img[kp + one])
                        rr = np.int64(img[kp + two])
                        kp += step3
                        c = coarse[((bb >> 2) << 12) | ((gg >> 2) << 6) | (rr >> 2)]
                        if c == 255:
                            c = fine[(bb << 16) | (gg << 8) | rr]
                        dst[j + 1] = c
                # erode grid row e = i + 1 (needs label rows e - 1, e, e + 1)
                e = i + 1
                if e >= 0:
                    edst = ebuf[e % 3]
                    if e >= 3:  # the slot held row e - 3
                        for j in range(first[e - 3], last[e - 3]):
                            edst[j + 1] = 0
                    if e < nrows:
                        lc = lbuf[e % 5]
                        lu = lbuf[(e + 4) % 5]  # row e - 1 (zeros for e = 0)
                        ld = lbuf[(e + 1) % 5]
                        for j in range(first[e], last[e]):
                            c = lc[j + 1]
                            if c != 0 and lc[j] == c and lc[j + 2] == c and lu[j + 1] == c and ld[j + 1] == c:
                                edst[j + 1] = c
                if i < 0:
                    continue
            a = first[i]
            b = last[i]
            if b <= a:
                continue
            y = y0 + i * step
            rp = np.uint64(y * rs + (x0 + a * step) * 3)  # byte offset of the span's first pixel
            ci = (i * step + occ_oy) >> occ_shift
            orow = occ[ci]
            grow = gocc[ci]
            if not opening and pending and ci != pci:  # the marks of the last cell row into its cells
                _flush_cells(dcol, gdcol, colcell, occ[pci], gocc[pci], width)
                pending = False
            pci = ci
            hist[:, :] = 0
            if opening:
                cur = lbuf[i % 5]
                ec = ebuf[i % 3]
                eu = ebuf[(i + 2) % 3]  # eroded row i - 1 (zeros for i = 0)
                ed = ebuf[(i + 1) % 3]  # eroded row i + 1 (zeros past the last row)
            # runs of one class: a run's n, sum x and sum x^2 added in closed form at its end
            # (and, without the opening, its pixels to the occupancy cells it covers)
            rc = 0  # class of the current run
            rj = a  # its first grid column
            if opening:
                for j in range(a, b):
                    c = np.int64(cur[j + 1])
                    if c != 0:
                        if not occ_dark and c <= n_classes:  # the bed before the opening
                            orow[(j * step + occ_ox) >> occ_shift] += 1
                        # kept when it or a neighbour survived the erosion (only its own class can)
                        if ec[j + 1] == 0 and ec[j] == 0 and ec[j + 2] == 0 and eu[j + 1] == 0 and ed[j + 1] == 0:
                            c = 0
                        elif c > n_classes:
                            grow[(j * step + occ_ox) >> occ_shift] += 1
                    if c != rc:
                        if rc > 0:
                            _add_run(hist, rc, rj, j, s1, s2)
                        rc = c
                        rj = j
                if rc > 0:
                    _add_run(hist, rc, rj, b, s1, s2)
            else:
                p = rp
                for j in range(a, b):
                    bb = np.int64(img[p])
                    gg = np.int64(img[p + one])
                    rr = np.int64(img[p + two])
                    p += step3
                    c = np.int64(coarse[((bb >> 2) << 12) | ((gg >> 2) << 6) | (rr >> 2)])
                    if c == rc:
                        continue  # the run goes on (rc is never 255): the fast path
                    if c == 255:
                        c = np.int64(fine[(bb << 16) | (gg << 8) | rr])
                        if c == rc:
                            continue
                    if rc > 0:
                        _add_run(hist, rc, rj, j, s1, s2)
                        if rc > n_classes:
                            gdcol[rj] += 1
                            gdcol[j] -= 1
                        elif not occ_dark:
                            dcol[rj] += 1
                            dcol[j] -= 1
                        pending = True
                    rc = c
                    rj = j
                if rc > 0:
                    _add_run(hist, rc, rj, b, s1, s2)
                    if rc > n_classes:
                        gdcol[rj] += 1
                        gdcol[b] -= 1
                    elif not occ_dark:
                        dcol[rj] += 1
                        dcol[b] -= 1
                    pending = True
            nd = 0
            sxd = 0
            sxxd = 0
            if dark_v_max >= 0:  # a second pass, only for a backlit (dark) bed
                p = rp
                for x in range(x0 + a * step, x0 + b * step, step):
                    v0 = img[p]
                    v1 = img[p + one]
                    v2 = img[p + two]
                    p += step3
                    if v0 <= dark_v_max and v1 <= dark_v_max and v2 <= dark_v_max:
                        nd += 1
                        sxd += x
                        sxxd += x * x
                        if occ_dark:
                            orow[(x - x0 + occ_ox) >> occ_shift] += 1
            for kk in range(1, n_classes + 2):
                n = hist[kk, 0]
                if n:
                    out[kk - 1, 0] += n
                    out[kk - 1, 1] += hist[kk, 1]
                    out[kk - 1, 2] += n * y
                    out[kk - 1, 3] += hist[kk, 2]
                    out[kk - 1, 4] += n * y * y
                    out[kk - 1, 5] += hist[kk, 1] * y
            if nd:
                out[n_classes + 1, 0] += nd
                out[n_classes + 1, 1] += sxd
                out[n_classes + 1, 2] += nd * y
                out[n_classes + 1, 3] += sxxd
                out[n_classes + 1, 4] += nd * y * y
                out[n_classes + 1, 5] += sxd * y

        if not opening and pending:
            _flush_cells(dcol, gdcol, colcell, occ[pci], gocc[pci], width)

    return kernel


_kernels: dict[bool, object] = {}


def _compiled(opening: bool = False):
    global _add_run, _flush_cells
    k = _kernels.get(opening)
    if k is None:
        import numba  # imported here: the CLI starts fast when no frame is measured

        _add_run = numba.njit(nogil=True, cache=True, boundscheck=False, inline="always")(_add_run_py)
        _flush_cells = numba.njit(nogil=True, cache=True, boundscheck=False, inline="always")(_flush_cells_py)
        k = _kernels[opening] = numba.njit(nogil=True, cache=True, boundscheck=False)(_make_kernel(opening))
    return k


def frame_moments(
    image_bgr: np.ndarray,
    tables: ClassTables,
    origin_xy: tuple[int, int],
    first: np.ndarray,
    last: np.ndarray,
    step: int = 1,
    dark_v_max: int = -1,
    out: np.ndarray | None = None,
    occupancy: np.ndarray | None = None,
    occ_shift: int = 3,
    opening: bool = False,
    glare_cells: np.ndarray | None = None,
    cell_offset_xy: tuple[int, int] = (0, 0),
) -> np.ndarray:
    """Moments of every class (and of glare and dark pixels) over the ROI's row spans.

    Row ``i`` of the spans is image row ``y0 + i * step``; its span ``[first[i], last[i])``
    counts grid columns ``x0 + j * step``. ``dark_v_max`` < 0 skips the dark sums.
    Returns ``out``, an int64 array (n_classes + 2, 6) with columns :data:`MOMENT_FIELDS`
    in original image px: row k is class k+1, row n_classes the glare (``GLARE_MIN``), the
    last row the dark pixels. ``glare_cells`` (like ``occupancy``) receives the glare
    pixels per cell.

    ``opening``: the class opening of :func:`open_labels` on the grid -- drops the thin
    rims and gaps that chroma blur (JPEG) or anti-aliasing give the wrong class, and
    keeps whole particles (at least 3 grid pixels across). ``occupancy`` (int32, at least
    ``ceil(box_h / 2^occ_shift)`` x ``ceil(box_w / 2^occ_shift)``) receives the bed pixels per square cell of
    ``2^occ_shift`` px, counted from ``origin_xy`` minus ``cell_offset_xy`` (px, each
    within 0 .. 2^occ_shift - 1: the cells may start left of and above the grid's first
    pixel): the classified pixels (before the opening), or the dark pixels when
    ``dark_v_max`` >= 0 (see ``vision.slope``).
    """
    ox, oy = int(cell_offset_xy[0]), int(cell_offset_xy[1])
    if not (0 <= ox < (1 << occ_shift) and 0 <= oy < (1 << occ_shift)):
        raise VisionError(f"cell offset {cell_offset_xy} must be within 0..{(1 << occ_shift) - 1} px")
    if out is None:
        out = np.empty((tables.n_classes + 2, 6), np.int64)
    x0, y0 = origin_xy
    if occupancy is None:
        rows = ((len(first) * step + oy) >> occ_shift) + 1
        cols = ((int(np.max(last, initial=0)) * step + ox) >> occ_shift) + 1
        occupancy = np.empty((rows, cols), np.int32)
    if glare_cells is None:
        glare_cells = np.empty_like(occupancy)
    img = image_bgr if image_bgr.flags.c_contiguous else np.ascontiguousarray(image_bgr)  # a view: one copy
    _compiled(bool(opening))(img.reshape(-1), img.shape[1] * 3, int(y0), int(x0), int(step), first, last,
                             tables.coarse, tables.fine, tables.n_classes, int(dark_v_max), out, occupancy,
                             int(occ_shift), bool(dark_v_max >= 0), glare_cells, ox, oy)
    return out

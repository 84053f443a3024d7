"""The DEM's Verlet neighbour list (numba; the "Neighbours" of ``sim.dem``'s doc): ``rebuild_list``
builds it, ``list_skin`` chooses each build's skin, ``neighbour_slots`` sizes its arrays.

These kernels are compiled into ``sim.dem.run``. Numba's cache keys ``run`` on sim/dem.py's own
time stamp: after editing this file, touch sim/dem.py (or delete the ``*.nbi``/``*.nbc`` files under
sim/__pycache__), or ``run`` keeps the old list code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SKIN_STEPS = 40.0  # a list build's skin is chosen to last about this many steps at the fastest disk's speed
SKIN_MAX_R = 1.5  # widest Verlet skin, small radii


def neighbour_slots(r_max: float, r_min: float, skin: float) -> int:
    """Neighbour-list slots per disk: half (pairs are listed once) of an area bound on the disks of
    radius ``r_min`` whose centres lie within ``r_max + r_min + skin`` of a disk of radius ``r_max``."""
    reach = r_max + 2.0 * r_min + skin
    return int(math.ceil(0.65 * (reach * reach - r_max * r_max) / (r_min * r_min))) + 2


@njit(cache=True)
def list_skin(vel, dt, skin_min, r_min):
    """Skin (m) of a new Verlet list: twice the distance the fastest disk (``vel``, m/s) covers in
    ``SKIN_STEPS`` steps of ``dt`` (s), at least ``skin_min`` and at most ``SKIN_MAX_R * r_min`` (m).
    Only the cost depends on it (a wider list is rebuilt less often but holds more pairs)."""
    v2 = 0.0
    for i in range(vel.shape[0]):
        v2 = max(v2, vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1])
    return min(max(2.0 * SKIN_STEPS * math.sqrt(v2) * dt, skin_min), max(SKIN_MAX_R * r_min, skin_min))


@njit(cache=True, error_model="numpy")
def rebuild_list(pos, rad, nb_start, nb_j, nb_xi, new_j, new_xi, ref, skin, r_drum, r_max) -> bool:
    """New Verlet list (compressed rows: pairs j > i of disk i at ``nb_start[i]:nb_start[i + 1]``,
    sorted by j), springs carried over; False if the list does not fit its arrays. Long on purpose (a numba
    kernel): one compiled pass whose stages (cells, pairs, rows, springs) share their scratch arrays."""
    n = pos.shape[0]
    cap = nb_j.size
    cs = 2.0 * r_max + skin
    # cells over the disks' bounding box (inside the drum; capped so a stray disk cannot blow it up)
    lo_x = hi_x = pos[0, 0]
    lo_y = hi_y = pos[0, 1]
    for i in range(n):
        lo_x = min(lo_x, pos[i, 0])
        hi_x = max(hi_x, pos[i, 0])
        lo_y = min(lo_y, pos[i, 1])
        hi_y = max(hi_y, pos[i, 1])
    lo_x = max(lo_x, -r_drum)
    lo_y = max(lo_y, -r_drum)
    ncx = min(int((min(hi_x, r_drum) - lo_x) / cs) + 1, 4096)
    ncy = min(int((min(hi_y, r_drum) - lo_y) / cs) + 1, 4096)
    # the disks counted into their cells (a counting sort): a cell's disks lie together, in index
    # order, their coordinates beside them (read sequentially)
    ncell = ncx * ncy
    cell_start = np.zeros(ncell + 1, dtype=np.int64)
    cell = np.empty(n, dtype=np.int64)
    for i in range(n):
        a = min(max(int((pos[i, 0] - lo_x) / cs), 0), ncx - 1)
        b = min(max(int((pos[i, 1] - lo_y) / cs), 0), ncy - 1)
        c = b * ncx + a
        cell[i] = c
        cell_start[c + 1] += 1
    for c in range(ncell):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:ncell].copy()
    sx = np.empty(n)
    sy = np.empty(n)
    sr = np.empty(n)
    sid = np.empty(n, dtype=np.int64)
    for i in range(n):
        k = fill[cell[i]]
        fill[cell[i]] = k + 1
        sx[k] = pos[i, 0]
        sy[k] = pos[i, 1]
        sr[k] = rad[i]
        sid[k] = i
    # the pairs, cell by cell, into new_j in visiting order with their row (the smaller index)
    # counted; then laid out in rows and sorted by j within each row
    row_n = np.zeros(n + 1, dtype=np.int64)
    pair_i = np.empty(cap, dtype=np.int64)
    m = 0
    for b in range(ncy):
        for a in range(ncx):
            c = b * ncx + a
            c1 = cell_start[c + 1]
            for p in range(cell_start[c], c1):
                x = sx[p]
                y = sy[p]
                ri = sr[p] + skin
                ip = sid[p]
                # each pair once (a half stencil): the later disks of the own cell and the next cell
                # of the row (together in the sorted order), then the three cells of the row above
                for half in range(2):
                    if half == 0:
                        q0 = p + 1
                        q1 = cell_start[c + 2] if a + 1 < ncx else c1
                    elif b + 1 < ncy:
                        q0 = cell_start[(b + 1) * ncx + max(a - 1, 0)]
                        q1 = cell_start[(b + 1) * ncx + min(a + 1, ncx - 1) + 1]
                    else:
                        break
                    for q in range(q0, q1):
                        dx = sx[q] - x
                        dy = sy[q] - y
                        reach = ri + sr[q]
                        if dx * dx + dy * dy < reach * reach:
                            if m >= cap:
                                return False
                            jq = sid[q]
                            i = min(ip, jq)
                            pair_i[m] = i
                            new_j[m] = max(ip, jq)
                            m += 1
                            row_n[i + 1] += 1
    starts = np.empty(n + 1, dtype=np.int64)
    starts[0] = 0
    for i in range(n):
        starts[i + 1] = starts[i] + row_n[i + 1]
    put = starts[:n].copy()
    rows_j = np.empty(m, dtype=np.int64)
    for k in range(m):
        i = pair_i[k]
        j = new_j[k]
        # insertion sort by j within the row
        first = starts[i]
        t = put[i]
        while t > first and rows_j[t - 1] > j:
            rows_j[t] = rows_j[t - 1]
            t -= 1
        rows_j[t] = j
        put[i] += 1
    # carry the tangential springs over (both rows sorted by j)
    for i in range(n):
        ko = nb_start[i]
        end = nb_start[i + 1]
        for k in range(starts[i], starts[i + 1]):
            j = rows_j[k]
            while ko < end and nb_j[ko] < j:
                ko += 1
            new_xi[k] = nb_xi[ko] if ko < end and nb_j[ko] == j else 0.0
    for k in range(m):
        nb_j[k] = rows_j[k]
        nb_xi[k] = new_xi[k]
    for i in range(n + 1):
        nb_start[i] = starts[i]
    for i in range(n):
        ref[i, 0] = pos[i, 0]
        ref[i, 1] = pos[i, 1]
    return True


__all__ = ["SKIN_MAX_R", "SKIN_STEPS", "list_skin", "neighbour_slots", "rebuild_list"]

"""Per-step contact pass of the twin (compiled): rolling friction and contact statistics.

Pure functions of arrays (no pymunk): ``sim.drum`` reads the step's contacts from
pymunk's batch API, calls :func:`contact_pass`, and writes the angular velocities back.

Rolling friction is the "constant directional torque" model of DEM codes (EDEM's
rolling friction CDT; Ai, Chen, Rotter & Ooi, Powder Technol. 206, 2011, type A): at
a contact with normal force ``F_n`` disk ``i`` feels a torque of magnitude
``mu_r * r_i * F_n`` against the contact's relative rotation ``omega_i - omega_j``
(``omega_j`` is the drum's rate for a wall contact). Over a step of length ``h`` that
is an angular impulse ``mu_r r_i J_n`` with ``J_n`` the contact's normal impulse,
capped so it cannot reverse the relative rotation (the cap is what makes the model
a friction, not a drive). Contacts are applied one after another with the updated
spins, so a disk with several contacts cannot be pushed past rest either.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["STAT_AIRBORNE", "STAT_CONTACTS", "STAT_OVERLAP_MAX", "STAT_WALL_MAX", "contact_pass"]

# slots of the ``acc`` statistics array
STAT_OVERLAP_MAX = 0  # largest disk-disk overlap, small radii
STAT_WALL_MAX = 1  # deepest wall penetration, m
STAT_CONTACTS = 2  # disk-disk contacts counted
STAT_AIRBORNE = 3  # fraction of disks without any contact in the last step


@njit(cache=True)
def _lookup(ids_sorted: np.ndarray, ids_order: np.ndarray, body_id: np.uint64) -> int:
    k = np.searchsorted(ids_sorted, body_id)
    if k < ids_sorted.size and ids_sorted[k] == body_id:
        return int(ids_order[k])
    return -1


@njit(cache=True)
def contact_pass(
    ids: np.ndarray,  # (m, 2) uint64 body ids of each contact
    fl: np.ndarray,  # (m, 5) total impulse x, y, normal x, y, distance (negative = overlap)
    ids_sorted: np.ndarray,  # body ids of the disks, sorted
    ids_order: np.ndarray,  # disk index of each sorted id
    r: np.ndarray,  # disk radii, m
    inv_i: np.ndarray,  # 1 / moment of inertia of each disk
    slot: np.ndarray,  # position of each disk in ``w_space``
    w_space: np.ndarray,  # angular velocities in the space's body order (updated in place)
    w_wall: float,  # drum rate, rad/s
    mu_r: float,  # rolling friction coefficient
    r_min: float,  # small radius, m (unit of the overlap histogram)
    hist: np.ndarray,  # overlap histogram (bins of 2 / (hist.size - 1) small radii, last = overflow)
    acc: np.ndarray,  # statistics (STAT_* slots), updated
) -> None:
    n = r.size
    m = ids.shape[0]
    nbins = hist.size - 1
    touched = np.zeros(n, dtype=np.bool_)
    # pymunk hands out contacts in hash-set order, which follows memory addresses: put them in
    # (lower disk, higher disk) order so the sequential pass is the same in every run
    pa = np.empty(m, dtype=np.int64)
    pb = np.empty(m, dtype=np.int64)
    key = np.empty(m, dtype=np.float64)
    for c in range(m):
        ia = _lookup(ids_sorted, ids_order, ids[c, 0])
        ib = _lookup(ids_sorted, ids_order, ids[c, 1])
        if ia > ib:
            ia, ib = ib, ia
        pa[c] = ia
        pb[c] = ib
        # a disk can touch two wall segments: the normal's direction breaks the tie
        key[c] = (ia + 1) * (n + 1) + (ib + 1) + 0.5 + 0.15 * math.atan2(fl[c, 3], fl[c, 2]) / math.pi
    for c in np.argsort(key, kind="mergesort"):
        ia = pa[c]
        ib = pb[c]
        if ia < 0 and ib < 0:
            continue
        ov = -fl[c, 4]
        if ia < 0 or ib < 0:
            if ov > acc[STAT_WALL_MAX]:
                acc[STAT_WALL_MAX] = ov
        else:
            o = max(ov, 0.0) / r_min
            if o > acc[STAT_OVERLAP_MAX]:
                acc[STAT_OVERLAP_MAX] = o
            hist[min(int(o * nbins / 2.0), nbins)] += 1
            acc[STAT_CONTACTS] += 1.0
        if ia >= 0:
            touched[ia] = True
        if ib >= 0:
            touched[ib] = True
        if mu_r <= 0.0:
            continue
        jn = abs(fl[c, 0] * fl[c, 2] + fl[c, 1] * fl[c, 3])
        wa = w_space[slot[ia]] if ia >= 0 else w_wall
        wb = w_space[slot[ib]] if ib >= 0 else w_wall
        ia_inv = inv_i[ia] if ia >= 0 else 0.0
        ib_inv = inv_i[ib] if ib >= 0 else 0.0
        w_rel = wa - wb
        if w_rel == 0.0:
            continue
        s = 1.0 if w_rel > 0.0 else -1.0
        # each side's angular impulse, scaled together so the relative spin stops at most
        ja = mu_r * r[ia] * jn if ia >= 0 else 0.0
        jb = mu_r * r[ib] * jn if ib >= 0 else 0.0
        change = ja * ia_inv + jb * ib_inv
        if change <= 0.0:
            continue
        f = min(1.0, abs(w_rel) / change)
        if ia >= 0:
            w_space[slot[ia]] = wa - s * f * ja * ia_inv
        if ib >= 0:
            w_space[slot[ib]] = wb + s * f * jb * ib_inv
    n_free = 0
    for i in range(n):
        if not touched[i]:
            n_free += 1
    acc[STAT_AIRBORNE] = n_free / max(1, n)

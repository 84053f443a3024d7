"""The pymunk twin's contacts: Chipmunk's settings, and the compiled pass after each Chipmunk step
(numba): contact statistics, rolling friction and end-plate friction, from one batch read of the
step's contacts and one of the bodies.

* **Contacts**: Chipmunk's impulse solver (``iterations`` per step, ``collision_slop`` 1 % of the
  smallest radius, overlaps pushed out at 10 % per 4 ms: pymunk's default, 10 % per 1/60 s, left
  the deep bed sunk 0.13 small radii into itself at the 99th percentile, this 0.05),
  Coulomb friction: a shape's coefficient is ``sqrt(friction)`` so the
  particle-particle product is ``friction``, the wall's ``wall_mu / sqrt(friction)``; restitution
  the same way (``sqrt(e)`` on every shape).
* **Rolling friction** (contacts between round shapes: disc-disc, disc-wall): after each step, a
  velocity constraint per contact solved like Chipmunk's own (projected Gauss-Seidel, ``ROLL_SWEEPS``
  sweeps): an angular-impulse couple against the pair's relative spin, at most ``mu_r r_eff F_n dt``
  (the DEM's "constant directional torque"; ``F_n`` the contact's normal impulse / dt), with the
  tangential impulse at the contact that keeps the contact from slipping. So it stops the rolling
  mode (spin and the translation rolling with it): a disc holds on a slope up to ``tan = mu_r`` and
  does not creep (a couple on the spin alone let a held disc creep at a speed proportional to dt).
* **End plates** (monolayer and thin drums; Taberlet et al. 2003, as ``sim.dem``): after each step
  every particle's velocity relative to the plates (turning with the drum) loses
  ``mu_end r sum(F_n) / depth * dt / m``, capped so it cannot reverse. ``depth`` is the drum's
  depth (``sim.mixer.parse_mixer`` makes a monolayer drum's its thickest particle's thickness).

``sim.pymunk_twin.PymunkDrumSim`` reads the batches (``ARBITER_FIELDS``, ``BODY_FIELDS``), calls
``post_step`` and writes ``VELOCITY_FIELDS`` back.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pymunk.batch as pbatch
from numba import njit

from sim.params import SimParams

ROLL_SWEEPS = 10  # Gauss-Seidel sweeps of the rolling-friction constraints per step (as Chipmunk's iterations)

# per contact: body ids and point count (ints); impulse, normal, point on shape a, depth (floats, in bit order)
ARBITER_FIELDS = (pbatch.ArbiterFields.BODY_A_ID | pbatch.ArbiterFields.BODY_B_ID
                  | pbatch.ArbiterFields.TOTAL_IMPULSE | pbatch.ArbiterFields.NORMAL
                  | pbatch.ArbiterFields.CONTACT_COUNT | pbatch.ArbiterFields.POINT_A_1
                  | pbatch.ArbiterFields.DISTANCE_1)
BODY_FIELDS = (pbatch.BodyFields.POSITION | pbatch.BodyFields.VELOCITY | pbatch.BodyFields.ANGULAR_VELOCITY)
VELOCITY_FIELDS = pbatch.BodyFields.VELOCITY | pbatch.BodyFields.ANGULAR_VELOCITY
OVERLAP_LEFT_PER_S = 0.9 ** (1 / 0.004)  # Chipmunk collision_bias: 10 % of an overlap corrected per 4 ms
SLOP_R = 0.01  # collision slop, in the smallest radius


def solver_settings(space: pymunk.Space, iterations: int, r_min_m: float) -> None:
    """Chipmunk's solver for the twin: ``iterations`` per step, slop and overlap correction (module doc)."""
    space.iterations = iterations
    space.collision_slop = SLOP_R * r_min_m
    space.collision_bias = OVERLAP_LEFT_PER_S  # the same correction rate in time whatever the step
    space.collision_persistence = 1  # the contact cache holds this step's contacts only (statistics, F_n)
    # broad phase: Chipmunk's bounding-box tree. Its spatial hash costs 25 % less CPU per step on the
    # cut-disc rig but orders its cells' contents by the shapes' memory addresses: two copies of one
    # snapshot then solve their contacts in different orders and part by 1e-17 m (not bit-exact)


def set_coefficients(params: SimParams, drum_shapes: tuple[pymunk.Shape, ...], bodies: list[pymunk.Body]) -> None:
    """Friction and restitution on every shape: each side of a contact ``sqrt`` of the pair's
    (``params.friction``; the drum's shapes ``wall_mu / sqrt(friction)``; ``sqrt(restitution)``)."""
    p = params
    su = math.sqrt(p.friction)
    wall_u = p.wall_mu / su if su > 0 else 0.0
    se = math.sqrt(p.restitution)
    for s in drum_shapes:
        s.friction, s.elasticity = wall_u, se
    for b in bodies:
        for s in b.shapes:
            s.friction, s.elasticity = su, se


@njit(cache=True)
def _counting_sort(keys: np.ndarray, items: np.ndarray, n: int) -> np.ndarray:
    """``items`` (indices into ``keys``, values 0..n) stably reordered by ``keys[item]``: one
    counting-sort pass, O(len(items) + n)."""
    cnt = np.zeros(n + 2, np.int64)
    for t in range(items.size):
        cnt[keys[items[t]] + 1] += 1
    for p in range(n + 1):
        cnt[p + 1] += cnt[p]
    out = np.empty(items.size, np.int64)
    for t in range(items.size):
        o = items[t]
        out[cnt[keys[o]]] = o
        cnt[keys[o]] += 1
    return out


def batch_index(space: pymunk.Space, drum: pymunk.Body,
                bodies: list[pymunk.Body]) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Where ``post_step`` finds each body: per particle ``i`` (``bodies[i]``) its row in the space's
    body batches (``batch_of``), the ``id_table`` from body ids to particle index (the drum's body and
    the wall: ``len(bodies)``) as keys and values, and the number of rows of a body batch."""
    buf = pbatch.Buffer()
    pbatch.get_space_bodies(space, pbatch.BodyFields.BODY_ID, buf)
    ids = np.frombuffer(buf.int_buf(), dtype=np.uintp).copy()
    index = {int(v): j for j, v in enumerate(ids.tolist())}
    n = len(bodies)
    # batch order -> particle index (the drum: n)
    batch_of = np.array([index[b.id] for b in bodies], dtype=np.int64)  # particle -> batch row
    part_of_id = {b.id: i for i, b in enumerate(bodies)}
    part_of_id[drum.id] = n
    part_of_id[space.static_body.id] = n  # the wall
    all_ids = np.append(ids, space.static_body.id).astype(np.int64)
    id_keys, id_part = id_table(all_ids, np.array([part_of_id[int(v)] for v in all_ids.tolist()]))
    return batch_of, id_keys, id_part, int(ids.size)


def id_table(ids: np.ndarray, parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An open-addressing table from body ids (Chipmunk's addresses) to particle indices: keys and values
    (``_lookup``), a power of two at least 4 times the ids."""
    size = 1 << max(4, int(4 * ids.size - 1).bit_length())
    keys = np.full(size, -1, np.int64)
    vals = np.zeros(size, np.int64)
    for v, p in zip(ids.tolist(), parts.tolist(), strict=True):
        h = _slot(int(v), size - 1)
        while keys[h] != -1:
            h = (h + 1) & (size - 1)
        keys[h], vals[h] = v, p
    return keys, vals


@njit(cache=True)
def _slot(v: int, mask: int) -> int:
    """The home slot of body id ``v`` in an ``_id_table`` of ``mask + 1`` slots."""
    return ((v >> 4) ^ (v >> 13)) & mask


@njit(cache=True)
def _lookup(keys: np.ndarray, vals: np.ndarray, v: int) -> int:
    """The value of key ``v`` in an ``_id_table`` (every looked-up id is in it)."""
    mask = keys.size - 1
    h = _slot(v, mask)
    while keys[h] != v:
        h = (h + 1) & mask
    return vals[h]


@njit(cache=True)
def _later(fl: np.ndarray, u: int, v: int) -> bool:
    """Contact row ``u`` after row ``v`` of one particle pair: by the normal up to its sign (the batch's
    sign follows Chipmunk's order of the pair, which follows memory layout), then the impulse's size,
    then the depth."""
    su = 1.0 if fl[u, 2] > 0.0 or (fl[u, 2] == 0.0 and fl[u, 3] >= 0.0) else -1.0
    sv = 1.0 if fl[v, 2] > 0.0 or (fl[v, 2] == 0.0 and fl[v, 3] >= 0.0) else -1.0
    ux, uy, vx, vy = su * fl[u, 2], su * fl[u, 3], sv * fl[v, 2], sv * fl[v, 3]
    if ux != vx:
        return ux > vx
    if uy != vy:
        return uy > vy
    ju = fl[u, 0] * fl[u, 0] + fl[u, 1] * fl[u, 1]
    jv = fl[v, 0] * fl[v, 0] + fl[v, 1] * fl[v, 1]
    return ju > jv or (ju == jv and fl[u, 6] > fl[v, 6])


@njit(cache=True, error_model="numpy")
def post_step(ints: np.ndarray, fl: np.ndarray, id_keys: np.ndarray, id_part: np.ndarray,
               batch_of: np.ndarray, rows: np.ndarray, vel_rows: np.ndarray, round_x: np.ndarray,
               inv_m_x: np.ndarray, inv_i_x: np.ndarray, r_x: np.ndarray, r_over_m: np.ndarray, h: float,
               w_drum: float, end_k: float, mu_r: float, inv_r_min: float, hist: np.ndarray,
               acc: np.ndarray) -> bool:
    """One step's contacts (the batch rows of ``pymunk.batch.get_space_arbiters``: body ids ``ints``
    (m, 3), impulse, normal, point on shape a, distance ``fl`` (m, 7)) -> overlap statistics into ``hist``/``acc``, and
    the bodies' new velocities (``rows``: x, y, vx, vy, omega per batch row) into ``vel_rows`` after
    rolling friction (``mu_r``) and end-plate friction (``end_k``, s). True if
    ``vel_rows`` was written. ``inv_m_x``, ``inv_i_x``, ``r_x``: 1 / mass, 1 / moment, radius per
    particle and the drum (index n: 0, 0, 0).

    The contacts are taken in a canonical order (particle pair as (lower, higher) index, then
    ``_later``): Chipmunk's contact cache is a hash set keyed by memory addresses, and the sums must
    not depend on where a twin or a restored copy lives in memory (bit-exact branches and runs).
    Long on purpose (a numba kernel): one compiled pass, its stages sharing the contacts' canonical order."""
    n = batch_of.size
    nbins = hist.size - 1
    m_all = ints.shape[0]
    a_ = np.empty(m_all, np.int64)
    b_ = np.empty(m_all, np.int64)
    keep = np.empty(m_all, np.int64)
    m = 0
    for k in range(m_all):
        if fl[k, 6] < 0.0:  # touching
            ia = _lookup(id_keys, id_part, ints[k, 0])
            ib = _lookup(id_keys, id_part, ints[k, 1])
            # the pair as (lower, higher) index: which body Chipmunk calls a depends on memory layout
            a_[m], b_[m] = (ia, ib) if ia < ib else (ib, ia)
            keep[m] = k
            m += 1
    # stable order by (a, b) in O(m + n): two counting-sort passes (by b, then by a), the order a stable
    # sort of a * (n + 1) + b gives
    order = _counting_sort(a_, _counting_sort(b_, np.arange(m), n), n)
    key = a_[:m] * (n + 1) + b_[:m]
    # ties (one particle pair, several convex pieces): by ``_later``, insertion sort within each run
    i = 0
    while i < m:
        j = i + 1
        while j < m and key[order[j]] == key[order[i]]:
            j += 1
        for p in range(i + 1, j):
            q = p
            while q > i:
                if _later(fl, keep[order[q - 1]], keep[order[q]]):
                    order[q - 1], order[q] = order[q], order[q - 1]
                    q -= 1
                else:
                    break
        i = j
    ov_max = 0.0
    wall_max = 0.0
    touched = np.zeros(n + 1, np.bool_)
    fn = np.empty(m)
    for t in range(m):
        o = order[t]
        k = keep[o]
        a, b = a_[o], b_[o]
        fn[t] = abs(fl[k, 0] * fl[k, 2] + fl[k, 1] * fl[k, 3]) / h  # normal force, N
        depth = -fl[k, 6]
        touched[a] = True
        touched[b] = True
        if b == n:  # a < b: the drum (n) is only ever b
            wall_max = max(wall_max, depth)
        else:
            ov = depth * inv_r_min
            ov_max = max(ov_max, ov)
            hist[min(int(ov * (nbins / 2.0)), nbins)] += 1
    n_touched = 0
    for p in range(n):
        if touched[p]:
            n_touched += 1
    acc[0] = m
    acc[1] = ov_max
    acc[2] = wall_max
    acc[3] = 1.0 - n_touched / n if n else np.nan
    acc[4] = 0.0
    if m == 0 or rows.shape[0] == 0 or (end_k <= 0.0 and mu_r <= 0.0):
        return False
    vel_rows[:, :] = rows[:, 2:5]
    if mu_r > 0.0:
        # rolling friction as a velocity constraint per round-round contact, solved like Chipmunk's contacts
        # (projected Gauss-Seidel, ``ROLL_SWEEPS``): an angular impulse couple stops the pair's relative spin,
        # up to mu_r r_eff F_n dt in all, with the tangential impulse at the contact that keeps it from slipping
        ca = np.empty(m, np.int64)
        cb = np.empty(m, np.int64)
        cf = np.empty((m, 8))  # tx, ty, rolling-mode inverse moment, couple limit, tangential impulse per couple,
        # the couple so far, the contact point (x, y)
        nr = 0
        for t in range(m):
            o = order[t]
            a, b = a_[o], b_[o]
            if not (round_x[a] and round_x[b]):
                continue
            k = keep[o]
            nx, ny = fl[k, 2], fl[k, 3]
            # the normal from a to b (the batch's sign follows Chipmunk's order of the pair): between two
            # particles by their centres; against the drum (b: wall or baffle) by the contact point, which lies
            # towards the drum from a's centre whichever shape the batch took it on
            if b != n:
                d = (nx * (rows[batch_of[b], 0] - rows[batch_of[a], 0])
                     + ny * (rows[batch_of[b], 1] - rows[batch_of[a], 1]))
            else:
                d = nx * (fl[k, 4] - rows[batch_of[a], 0]) + ny * (fl[k, 5] - rows[batch_of[a], 1])
            if d < 0.0:
                nx, ny = -nx, -ny
            pa, pb = r_x[a], r_x[b]
            r_eff = pa if b == n else pa * pb / (pa + pb + 1e-300)  # a < b: the drum (n) is only ever b
            # the contact's tangential inverse mass and the rolling mode's inverse moment (no slip kept)
            k_t = inv_m_x[a] + pa * pa * inv_i_x[a] + inv_m_x[b] + pb * pb * inv_i_x[b]
            c = pa * inv_i_x[a] - pb * inv_i_x[b]
            k_roll = inv_i_x[a] + inv_i_x[b] - (c * c / k_t if k_t > 0.0 else 0.0)
            if k_roll <= 0.0:
                continue
            ca[nr], cb[nr] = a, b
            cf[nr, 0], cf[nr, 1], cf[nr, 2] = -ny, nx, k_roll
            cf[nr, 3] = mu_r * h * r_eff * fn[t]
            cf[nr, 4] = -c / k_t if k_t > 0.0 else 0.0
            cf[nr, 5] = 0.0  # the couple so far (N m s, on b; on a: minus)
            cf[nr, 6], cf[nr, 7] = fl[k, 4], fl[k, 5]
            nr += 1
        for _ in range(ROLL_SWEEPS):
            for q in range(nr):
                a, b = ca[q], cb[q]
                wa = vel_rows[batch_of[a], 2]
                wb = w_drum if b == n else vel_rows[batch_of[b], 2]
                acc_l = cf[q, 5]
                new_l = min(cf[q, 3], max(-cf[q, 3], acc_l + (wa - wb) / cf[q, 2]))
                lb = new_l - acc_l
                if lb == 0.0:
                    continue
                cf[q, 5] = new_l
                pt = lb * cf[q, 4]
                tx, ty = cf[q, 0], cf[q, 1]
                if b == n:  # the reaction on the drum: the couple, and the impulse's moment at the contact
                    acc[4] += lb + pt * (cf[q, 6] * ty - cf[q, 7] * tx)
                else:
                    row = batch_of[b]
                    vel_rows[row, 0] += pt * tx * inv_m_x[b]
                    vel_rows[row, 1] += pt * ty * inv_m_x[b]
                    vel_rows[row, 2] += (lb - pt * r_x[b]) * inv_i_x[b]
                row = batch_of[a]
                vel_rows[row, 0] -= pt * tx * inv_m_x[a]
                vel_rows[row, 1] -= pt * ty * inv_m_x[a]
                vel_rows[row, 2] += (-lb - pt * r_x[a]) * inv_i_x[a]
    if end_k > 0.0:
        sfn = np.zeros(n + 1)
        for t in range(m):
            o = order[t]
            sfn[a_[o]] += fn[t]
            sfn[b_[o]] += fn[t]
        for p in range(n):
            row = batch_of[p]
            x, y = rows[row, 0], rows[row, 1]
            ux = vel_rows[row, 0] + w_drum * y
            uy = vel_rows[row, 1] - w_drum * x
            u = math.hypot(ux, uy)
            if u > 0.0:
                s = min(end_k * r_over_m[p] * sfn[p], u) / u
                vel_rows[row, 0] -= s * ux
                vel_rows[row, 1] -= s * uy
                # the plates (the drum) take the opposite impulse at the particle's centre
                acc[4] += s * (x * uy - y * ux) / inv_m_x[p]
    return True


__all__ = [
    "ARBITER_FIELDS", "BODY_FIELDS", "OVERLAP_LEFT_PER_S", "ROLL_SWEEPS", "SLOP_R", "VELOCITY_FIELDS", "batch_index",
    "id_table", "post_step", "set_coefficients", "solver_settings",
]

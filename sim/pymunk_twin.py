"""The pymunk twin: the user's mixer (any particle shape, baffles) in Chipmunk2D through pymunk.

Same interface and statistics as ``sim.drum.DrumSim`` (advance/step, particles, snapshot/restore/
from_state, set_rpm, rpm_actual, t_s, set_friction, stats/reset_stats, critical_rpm), for the
mixers the compiled DEM cannot hold (``sim.mixer.Mixer.all_round`` False).

Frame and units as ``sim.drum``: origin at the drum axis, x right, y up, metres, seconds, kg.
The drum turns at ``direction * rpm_actual`` (``Mixer.direction``: +1 counter-clockwise as the
camera sees it); ``rpm_actual`` follows ``set_rpm`` at the acceleration limit.

Model:

* **Drum**: the wall is a ring of ``WALL_SEGMENTS`` static segments whose inner surface is the
  circle of radius ``R`` (to ``R * (1 - cos(pi/N)) / cos``, 0.02 mm on a 250 mm drum), its surface
  moving at the drum's ``w x p`` (Chipmunk's ``surface_velocity``: a round wall turning about its
  centre is the same surface; a static one is not re-indexed by the broad phase every step); baffles
  are boxes on one KINEMATIC body turning about the axis, from the wall inwards.
* **Particles**: one DYNAMIC body each; discs are ``Circle``; convex outlines (regular polygon,
  pellet) one ``Poly`` with a corner radius ``CORNER_R`` of the particle's radius (the vertices
  pulled in by it, so the outer size stays); non-convex outlines one body of several convex
  ``Poly`` pieces (a cut disc or a notched disc: two or three fans from the notch's apex, each
  seeing less than 144 deg of the rim; vertices:
  ``pymunk.autogeometry.convex_decomposition``). Counts and masses from ``sim.mixer.resolve``
  (``density * area * slab``) and the flat particle's own moment of inertia (2D is the real
  physics of a monolayer).
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
* **Time step**: one fixed internal step ``dt_s`` (``default_dt_s``: 1 ms for a bed at least half
  not round, 0.5 ms for a bed mostly of discs; the study in docs/validation.md section 10),
  independent of how the caller slices time: ``advance`` runs every whole step that fits and
  carries the remainder.

Snapshots: pymunk pickles a Space without its contact cache (the warm-start impulses), so a
restored copy does not continue bit-identically to the space it was taken from, but two copies of
the same pickle do. ``snapshot()`` therefore re-bases the live twin on its own snapshot: the live
run and every branch restored from it continue bit-identically (the live run loses one step's warm
start, a perturbation far below the step's own error).
"""

from __future__ import annotations

import math
import pickle
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk
import pymunk.autogeometry
import pymunk.batch as pbatch
from numba import njit

from sim.drum import (
    _OVERLAP_BINS,
    CASES,
    DEFAULT_ACCEL_RPM_S,
    DEFAULT_FRICTION,
    DEFAULT_RESTITUTION,
    DEFAULT_ROLLING,
    ContactStats,
    FixedStepTwin,
    Particles,
    SimParams,
    _check_params,
    check_rpm,
    rpm_to_rad_s,
)
from sim.errors import SimError
from sim.mixer import Mixer, Shape, resolve, shape_outline_m
from sim.placement import SHRINK, place_random
from sim.recipe import G_M_S2, DiskClass, DrumSpec

DEFAULT_DT_S = 0.001  # a bed at least half not round (cut-disc rig): 1 ms = 0.5 ms, 2 ms 1.1 deg low (validation.md 10)
ROUND_BED_DT_S = 0.0005  # a bed mostly of discs: 0.5 ms 0.8 deg below 0.25 ms, 2 ms 3.6 deg (validation.md 10)
DEFAULT_ITERATIONS = 10  # Chipmunk solver iterations per step
WALL_SEGMENTS = 180
CORNER_R = 0.02  # corner radius of polygon shapes, in the particle's radius
PIECE_SEGMENTS = 16  # round parts of a polygon piece: vertices per full turn (cost of Chipmunk's poly contacts)
OVERLAP_LEFT_PER_S = 0.9 ** (1 / 0.004)  # Chipmunk collision_bias: 10 % of an overlap corrected per 4 ms
SLOP_R = 0.01  # collision slop, in the smallest radius
ROLL_SWEEPS = 10  # Gauss-Seidel sweeps of the rolling-friction constraints per step (as Chipmunk's iterations)
_INFLATE_S = 0.1
_SETTLE_DAMPING = 0.1  # velocity kept after one second while settling (pymunk Space.damping)

# per contact: body ids and point count (ints); impulse, normal, point on shape a, depth (floats, in bit order)
_ARB = (pbatch.ArbiterFields.BODY_A_ID | pbatch.ArbiterFields.BODY_B_ID | pbatch.ArbiterFields.TOTAL_IMPULSE
        | pbatch.ArbiterFields.NORMAL | pbatch.ArbiterFields.CONTACT_COUNT | pbatch.ArbiterFields.POINT_A_1
        | pbatch.ArbiterFields.DISTANCE_1)
_BOD = (pbatch.BodyFields.POSITION | pbatch.BodyFields.VELOCITY | pbatch.BodyFields.ANGULAR_VELOCITY)
_VEL = pbatch.BodyFields.VELOCITY | pbatch.BodyFields.ANGULAR_VELOCITY


@dataclass(frozen=True)
class PymunkState:
    """A pymunk twin's whole state (picklable; sent to what-if workers). ``space`` is the pickled
    (Space, drum body, particle bodies) of ``pymunk``."""

    mixer: Mixer
    case: str
    seed: int
    params: SimParams  # ``dt_s`` always set; ``stiffness_n_m`` is not used (Chipmunk's contacts are rigid)
    iterations: int
    t_s: float
    rpm_target: float
    rpm_actual: float
    n_steps: int
    acc_s: float
    cls: np.ndarray
    space: bytes

    @property
    def drum(self) -> DrumSpec:
        return self.mixer.drum


def default_dt_s(mixer: Mixer) -> float:
    """The pymunk engine's converged step for ``mixer`` (s): ``DEFAULT_DT_S`` when at least half its
    particles are not round, ``ROUND_BED_DT_S`` otherwise (a bed of discs needs the shorter step:
    its slope rests on rolling contacts, whose overlaps grow with the step; docs/validation.md 10)."""
    res = resolve(mixer)
    n = sum(k.count for k in res)
    n_round = sum(k.count for k, kind in zip(res, mixer.particles, strict=True) if kind.shape.is_round)
    return ROUND_BED_DT_S if n_round > 0.5 * n else DEFAULT_DT_S


def _check_iterations(iterations: int) -> int:
    if not (1 <= int(iterations) <= 1000):
        raise SimError(f"solver iterations must be in [1, 1000] (got {iterations})")
    return int(iterations)


def _is_convex(v: np.ndarray) -> bool:
    d = np.roll(v, -1, axis=0) - v
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    return bool(np.all(cross >= -1e-15) or np.all(cross <= 1e-15))


def convex_pieces(shape: Shape) -> list[np.ndarray]:
    """The shape's outline (body frame, m, about its centroid) as convex polygons (k, 2); [] for a disc."""
    if shape.kind == "disc":
        return []
    outline = shape_outline_m(shape, segments=PIECE_SEGMENTS)
    if shape.kind in ("cut_disc", "notched_disc"):
        return _fan_pieces(outline[0], outline[1:])
    if _is_convex(outline):
        return [outline]
    closed = [tuple(p) for p in outline] + [tuple(outline[0])]
    hulls = pymunk.autogeometry.convex_decomposition(closed, 1e-3 * shape.radius_m)
    return [np.asarray([(p.x, p.y) for p in h[:-1]]) for h in hulls]


def _fan_pieces(apex: np.ndarray, arc: np.ndarray) -> list[np.ndarray]:
    """A disc with a wedge or notch cut out (the apex inside the disc, the rim's ``arc`` around it) as
    convex fans sharing the apex, each seeing less than 144 deg of the arc from the apex (convex, few
    pairs): a cut disc's sectors (the apex at the centre), a notched disc's pieces."""
    seen = np.unwrap(np.arctan2(arc[:, 1] - apex[1], arc[:, 0] - apex[0]))
    cum = np.abs(seen - seen[0])
    k = max(1, math.ceil(float(cum[-1]) / (0.8 * math.pi) - 1e-9))
    idx = np.rint(np.interp(np.linspace(0.0, float(cum[-1]), k + 1), cum, np.arange(len(arc)))).astype(int)
    return [np.vstack([apex, arc[idx[j]: idx[j + 1] + 1]]) for j in range(k)]


def _moment_kg_m2(shape: Shape, mass_kg: float) -> float:
    """Polar moment of inertia of the flat particle about its centroid (kg m^2)."""
    if shape.kind == "disc":
        return 0.5 * mass_kg * shape.radius_m ** 2
    v = shape_outline_m(shape, segments=96)
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    j = (cross * (x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1)).sum() / 12.0
    return float(mass_kg * j / area)


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


def _id_table(ids: np.ndarray, parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
def _post_step(ints: np.ndarray, fl: np.ndarray, id_keys: np.ndarray, id_part: np.ndarray,
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
    not depend on where a twin or a restored copy lives in memory (bit-exact branches and runs)."""
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


class PymunkDrumSim(FixedStepTwin):
    """The pymunk drum twin of a ``Mixer`` (see the module doc). Seeded and reproducible."""

    _hist: np.ndarray
    _ov_max: float
    _wall_max: float
    _contacts: int
    _stat_steps: int
    _airborne: float

    def __init__(
        self,
        mixer: Mixer,
        case: str = "C",
        seed: int = 0,
        rpm: float = 5.0,
        friction: float = DEFAULT_FRICTION,
        rolling: float = DEFAULT_ROLLING,
        *,
        restitution: float = DEFAULT_RESTITUTION,
        wall_friction: float | None = None,
        end_friction: float | None = None,
        accel_rpm_s: float = DEFAULT_ACCEL_RPM_S,
        dt_s: float | None = None,
        iterations: int = DEFAULT_ITERATIONS,
        settle_s: float = 1.0,
    ) -> None:
        case = str(case).upper()
        if case not in CASES:
            raise SimError(f"case must be one of {', '.join(CASES)} (got {case!r})")
        rpm = self._configure(mixer, case, seed, rpm, friction, rolling, restitution=restitution,
                              wall_friction=wall_friction, end_friction=end_friction, accel_rpm_s=accel_rpm_s,
                              dt_s=dt_s, iterations=iterations)
        disks = [DiskClass(k.name, k.radius_m, k.count, k.density_kg_m3, k.colour_bgr) for k in resolve(mixer)]
        rng = np.random.default_rng(seed)
        pos, cls = place_random(disks, case, mixer.drum.radius_m, rng)
        angles = rng.uniform(0, 2 * math.pi, cls.size)
        self._start(pos, cls, angles, rpm, 0.0 if case == "B" else settle_s)

    def _configure(self, mixer: Mixer, case: str, seed: int, rpm: float, friction: float, rolling: float, *,
                   restitution: float = DEFAULT_RESTITUTION, wall_friction: float | None = None,
                   end_friction: float | None = None, accel_rpm_s: float = DEFAULT_ACCEL_RPM_S,
                   dt_s: float | None = None, iterations: int = DEFAULT_ITERATIONS) -> float:
        """Check and keep the run's parameters (one-line SimErrors); the checked rpm."""
        params = SimParams(float(friction), float(rolling), float(restitution),
                           None if wall_friction is None else float(wall_friction), float(accel_rpm_s),
                           default_dt_s(mixer) if dt_s is None else float(dt_s),
                           end_friction=None if end_friction is None else float(end_friction))
        _check_params(params)
        self.iterations = _check_iterations(iterations)
        if not mixer.particles:
            raise SimError("the mixer has no particle classes")
        rpm = check_rpm(rpm, mixer.drum)
        self.mixer, self.case, self.seed, self.params = mixer, case, int(seed), params
        return rpm

    @classmethod
    def from_placement(
        cls,
        mixer: Mixer,
        pos_m: np.ndarray,
        classes: np.ndarray,
        angle_rad: np.ndarray,
        rpm: float,
        settle_s: float = 0.3,
        *,
        seed: int = 0,
        friction: float = DEFAULT_FRICTION,
        rolling: float = DEFAULT_ROLLING,
        **kwargs: Any,
    ) -> PymunkDrumSim:
        """A twin of ``mixer`` whose particles are placed by the caller (``sim.from_image``: where the
        camera sees each class): centroids ``pos_m`` (n, 2; m, drum frame) at ``SHRINK`` of their
        size without overlaps, class indices ``classes`` (n,), angles ``angle_rad`` (n,; rad). Inflated,
        settled for ``settle_s`` with the drum at rest and started at ``rpm``, as ``__init__`` does;
        ``kwargs`` as ``__init__``'s (``end_friction``, ``dt_s``, ``iterations``, ...). Case "image"."""
        pos = np.asarray(pos_m, dtype=np.float64)
        k = np.asarray(classes)
        ang = np.asarray(angle_rad, dtype=np.float64)
        n = k.size
        if pos.shape != (n, 2) or ang.shape != (n,) or k.ndim != 1:
            raise SimError(f"a placement needs (n, 2) centres, n classes and n angles (got {pos.shape}, "
                           f"{k.shape}, {ang.shape})")
        if n == 0:
            raise SimError("a placement needs at least one particle")
        if not (np.issubdtype(k.dtype, np.integer) and 0 <= int(k.min()) and int(k.max()) < len(mixer.particles)):
            raise SimError(f"placement classes must be indices 0..{len(mixer.particles) - 1} of the mixer's classes")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(ang))):
            raise SimError("placement centres and angles must be finite")
        if float(np.hypot(pos[:, 0], pos[:, 1]).max()) >= mixer.drum.radius_m:
            raise SimError(f"a placed particle lies outside the {mixer.drum.diameter_m * 1e3:g} mm drum")
        sim = cls.__new__(cls)
        rpm = sim._configure(mixer, "image", seed, rpm, friction, rolling, **kwargs)
        sim._start(pos, k.astype(np.int64), ang, rpm, max(0.0, float(settle_s)))
        return sim

    def _start(self, pos: np.ndarray, cls: np.ndarray, angles: np.ndarray, rpm: float, settle_s: float) -> None:
        """Build the space from placed particles (``SHRINK`` size), inflate and settle, start at ``rpm``."""
        self._cls = cls
        self._set_tables()
        self._new_space(pos, angles)
        self.t_s, self.n_steps, self._acc_s = 0.0, 0, 0.0
        self._rpm_target = self._rpm_actual = 0.0
        self.reset_stats()
        self._settle(settle_s)
        self.reset_stats()
        self._rpm_target = self._rpm_actual = rpm  # the drum starts at full speed

    # ------------------------------------------------------------------ build
    @property
    def drum(self) -> DrumSpec:
        return self.mixer.drum

    def _set_tables(self) -> None:
        """Per-class and per-particle constants (pure functions of the mixer)."""
        kinds = self.mixer.particles
        res = resolve(self.mixer)
        self._r_cls = np.array([k.radius_m for k in res])
        self._area_cls = np.array([k.area_m2 for k in res])
        self._mass_cls = np.array([k.mass_kg for k in res])
        self._moment_cls = np.array([_moment_kg_m2(k.shape, m) for k, m in zip(kinds, self._mass_cls, strict=True)])
        self._round_cls = np.array([k.shape.is_round for k in kinds])
        self._r = self._r_cls[self._cls]
        self._m = self._mass_cls[self._cls]
        self._inertia = self._moment_cls[self._cls]
        self._round = self._round_cls[self._cls]
        # per particle and one more entry for the drum (index n): round, 1 / moment, radius
        self._round_x = np.append(self._round, True)
        self._inv_i_x = np.append(1.0 / self._inertia, 0.0)
        self._inv_m_x = np.append(1.0 / self._m, 0.0)
        self._r_x = np.append(self._r_cls[self._cls], 0.0)
        self._r_over_m = self._r_cls[self._cls] / self._m
        self._r_min = float(self._r_cls.min())
        self._depth = self.mixer.drum.depth_m  # the end plates' distance (a monolayer's: its thickest particle)
        self._outlines = tuple(shape_outline_m(k.shape) for k in kinds)

    def _new_space(self, pos: np.ndarray, angles: np.ndarray) -> None:
        space = pymunk.Space()
        space.gravity = (0.0, -G_M_S2)
        drum = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        space.add(drum)
        R = self.drum.radius_m
        seg_r = 0.5 * self._r_min
        rv = (R + seg_r) / math.cos(math.pi / WALL_SEGMENTS)
        a = 2 * math.pi * np.arange(WALL_SEGMENTS) / WALL_SEGMENTS
        pts = [(rv * math.cos(t), rv * math.sin(t)) for t in a]
        wall = space.static_body  # the round wall turns in place: static, its surface moving (``_turn_wall``)
        for i in range(WALL_SEGMENTS):
            space.add(pymunk.Segment(wall, pts[i], pts[(i + 1) % WALL_SEGMENTS], seg_r))
        for poly in self.baffle_polygons_m(0.0):
            space.add(pymunk.Poly(drum, [tuple(p) for p in poly], radius=0.0))
        bodies = []
        self._shapes_of: list[list[pymunk.Shape]] = []  # each body's shapes in piece order (inflation)
        for i in range(self._cls.size):
            k = int(self._cls[i])
            body = pymunk.Body(float(self._mass_cls[k]), float(self._moment_cls[k]))
            body.position = (float(pos[i, 0]), float(pos[i, 1]))
            body.angle = float(angles[i])
            shape = self.mixer.particles[k].shape
            pieces = convex_pieces(shape)
            shapes: list[pymunk.Shape]
            if not pieces:
                shapes = [pymunk.Circle(body, shape.radius_m * SHRINK)]
            else:
                c = CORNER_R * shape.radius_m
                pull = (shape.radius_m - c) / shape.radius_m
                shapes = [pymunk.Poly(body, [tuple(p) for p in piece * pull * SHRINK], radius=c * SHRINK)
                          for piece in pieces]
            space.add(body, *shapes)
            self._shapes_of.append(shapes)
            bodies.append(body)
        self._install(space, drum, bodies)
        self._scale_shapes(SHRINK)

    def _install(self, space: pymunk.Space, drum: pymunk.Body, bodies: list[pymunk.Body]) -> None:
        """Use this space: solver settings, contact coefficients, the batch order of the bodies."""
        space.iterations = self.iterations
        space.collision_slop = SLOP_R * self._r_min
        space.collision_bias = OVERLAP_LEFT_PER_S  # the same correction rate in time whatever the step
        space.collision_persistence = 1  # the contact cache holds this step's contacts only (statistics, F_n)
        # broad phase: Chipmunk's bounding-box tree. Its spatial hash costs 25 % less CPU per step on the
        # cut-disc rig but orders its cells' contents by the shapes' memory addresses: two copies of one
        # snapshot then solve their contacts in different orders and part by 1e-17 m (not bit-exact)
        self._space, self._drum, self._bodies = space, drum, bodies
        buf = pbatch.Buffer()
        pbatch.get_space_bodies(space, pbatch.BodyFields.BODY_ID, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp).copy()
        index = {int(v): j for j, v in enumerate(ids.tolist())}
        n = len(bodies)
        # batch order -> particle index (the drum: n)
        self._batch_of = np.array([index[b.id] for b in bodies], dtype=np.int64)  # particle -> batch row
        part_of_id = {b.id: i for i, b in enumerate(bodies)}
        part_of_id[drum.id] = n
        part_of_id[space.static_body.id] = n  # the wall
        all_ids = np.append(ids, space.static_body.id).astype(np.int64)
        self._id_keys, self._id_part = _id_table(all_ids, np.array([part_of_id[int(v)] for v in all_ids.tolist()]))
        # the wall's segments and their tangential speed per rad/s of the drum (m/rad): w x p at the midpoint
        self._wall = tuple(space.static_body.shapes)
        tang = []
        for seg in self._wall:
            assert isinstance(seg, pymunk.Segment)
            mx, my = 0.5 * (seg.a.x + seg.b.x), 0.5 * (seg.a.y + seg.b.y)
            k = self.drum.radius_m / math.hypot(mx, my)  # the contact surface: radius R
            tang.append((-my * k, mx * k))
        self._wall_tang = tuple(tang)
        self._wall_w = math.nan  # the drum speed the wall's surface velocity is set for (rad/s)
        self._abuf = pbatch.Buffer()
        self._bbuf = pbatch.Buffer()
        self._vel_rows = np.zeros((ids.size, 3))  # vx, vy, omega per batch row, written back after a step
        self._sbuf = pbatch.Buffer()
        self._sbuf.set_float_buf(self._vel_rows)
        self._no_rows = np.zeros((0, 5))
        self._acc_stats = np.zeros(5)  # one step's contacts, max overlap (small radii), max wall depth (m), airborne,
        # and the angular impulse of rolling and end-plate friction on the drum (N m s, counter-clockwise)
        self._set_coefficients()

    def _set_coefficients(self) -> None:
        p = self.params
        su = math.sqrt(p.friction)
        wall_u = p.wall_mu / su if su > 0 else 0.0
        se = math.sqrt(p.restitution)
        for s in (*self._wall, *self._drum.shapes):
            s.friction, s.elasticity = wall_u, se
        for b in self._bodies:
            for s in b.shapes:
                s.friction, s.elasticity = su, se

    def _scale_shapes(self, scale: float) -> None:
        """Set every particle's shapes to ``scale`` times full size (inflation)."""
        for i, shapes in enumerate(self._shapes_of):
            shape = self.mixer.particles[int(self._cls[i])].shape
            if self._round[i]:
                for s in shapes:
                    assert isinstance(s, pymunk.Circle)
                    s.unsafe_set_radius(shape.radius_m * scale)
                continue
            c = CORNER_R * shape.radius_m
            pull = (shape.radius_m - c) / shape.radius_m
            for s, piece in zip(shapes, convex_pieces(shape), strict=True):
                assert isinstance(s, pymunk.Poly)
                s.unsafe_set_vertices([tuple(q) for q in piece * pull * scale])
                s.unsafe_set_radius(c * scale)

    def baffle_polygons_m(self, drum_angle_rad: float | None = None) -> list[np.ndarray]:
        """The baffles as (4, 2) polygons (m, drum frame) at the drum's angle (now, if None)."""
        bf = self.mixer.baffles
        if bf is None or bf.count <= 0:
            return []
        ang = self._drum.angle if drum_angle_rad is None else drum_angle_rad
        R = self.drum.radius_m
        r_out = R + 0.5 * self._r_min
        box = np.array([[R - bf.height_m, -0.5 * bf.thickness_m], [r_out, -0.5 * bf.thickness_m],
                        [r_out, 0.5 * bf.thickness_m], [R - bf.height_m, 0.5 * bf.thickness_m]])
        out = []
        for j in range(bf.count):
            t = ang - 0.5 * math.pi + 2 * math.pi * j / bf.count
            c, s = math.cos(t), math.sin(t)
            out.append(box @ np.array([[c, s], [-s, c]]))
        return out

    def _settle(self, settle_s: float) -> None:
        """Inflate the particles to full size without gravity, then settle with the drum at rest."""
        h = self.substep_s()
        sp = self._space
        sp.gravity = (0.0, 0.0)
        sp.damping = _SETTLE_DAMPING ** 10
        n_grow = 10
        per = max(1, int(round(_INFLATE_S / n_grow / h)))
        for j in range(n_grow):
            self._scale_shapes(SHRINK + (1.0 - SHRINK) * (j + 1) / n_grow)
            self._run(per, count=False)
        sp.gravity = (0.0, -G_M_S2)
        sp.damping = _SETTLE_DAMPING
        self._run(int(round(settle_s / h)), count=False)
        sp.damping = 1.0
        for b in self._bodies:
            b.velocity = (0.0, 0.0)
            b.angular_velocity = 0.0

    # ------------------------------------------------------------- controls
    @property
    def rpm_actual(self) -> float:
        """Drum speed now (rpm), following the setpoint at the acceleration limit."""
        return self._rpm_actual

    @property
    def rpm_target(self) -> float:
        return self._rpm_target

    @property
    def critical_rpm(self) -> float:
        """Critical speed of this drum (rpm), ``DrumSpec.critical_rpm``."""
        return self.drum.critical_rpm

    def set_rpm(self, rpm: float) -> None:
        """New rpm setpoint; the drum ramps to it at ``accel_rpm_s``. Above critical speed: SimError."""
        self._rpm_target = check_rpm(rpm, self.drum)

    def _params_changed(self) -> None:
        self._set_coefficients()

    def _run(self, n_steps: int, count: bool = True, clock: np.ndarray | None = None) -> None:
        """``n_steps`` steps; ``clock`` (2,): CPU seconds of Chipmunk's steps and of the post-step pass added."""
        p = self.params
        h = self.substep_s()
        dv_max = p.accel_rpm_s * h
        end_k = p.end_mu / self._depth * h  # end-plate velocity loss per (r sum F_n / m), s
        for _ in range(n_steps):
            if count:
                d = self._rpm_target - self._rpm_actual
                self._rpm_actual += max(-dv_max, min(dv_max, d))
            w = self.mixer.direction * rpm_to_rad_s(self._rpm_actual) if count else 0.0
            self._drum.angular_velocity = w
            if w != self._wall_w:
                self._turn_wall(w)
            if clock is None:
                self._space.step(h)
                self._after_step(h, w, end_k if count else 0.0, p.rolling if count else 0.0)
            else:
                t0 = time.process_time()
                self._space.step(h)
                t1 = time.process_time()
                self._after_step(h, w, end_k if count else 0.0, p.rolling if count else 0.0)
                clock += (t1 - t0, time.process_time() - t1)
            if count:
                self.n_steps += 1

    def _turn_wall(self, w: float) -> None:
        """Set the wall's surface velocity to the drum's ``w`` (rad/s): a round wall turning about its
        centre is the same surface, moving at ``w x p`` (Chipmunk's ``surface_velocity``, used by friction;
        the wall's normal velocity is zero either way). A static wall is not re-indexed by the broad phase
        every step as shapes on the turning kinematic body are."""
        for seg, (tx, ty) in zip(self._wall, self._wall_tang, strict=True):
            seg.surface_velocity = (w * tx, w * ty)
        self._wall_w = w

    def _after_step(self, h: float, w_drum: float, end_k: float, mu_r: float) -> None:
        """Contact statistics, rolling friction and end-plate friction of the step just taken
        (``_post_step``, compiled: one batch read of the contacts, one of the bodies, one write)."""
        ab = self._abuf
        ab.clear()
        pbatch.get_space_arbiters(self._space, _ARB, ab)
        ints = np.frombuffer(ab.int_buf(), dtype=np.int64).reshape(-1, 3)  # addresses: below 2**63
        fl = np.frombuffer(ab.float_buf(), dtype=np.float64).reshape(-1, 7)
        friction = ints.shape[0] > 0 and (end_k > 0.0 or mu_r > 0.0)
        if friction:
            bb = self._bbuf
            bb.clear()
            pbatch.get_space_bodies(self._space, _BOD, bb)
            rows = np.frombuffer(bb.float_buf(), dtype=np.float64).reshape(-1, 5)
        else:
            rows = self._no_rows
        acc = self._acc_stats
        write = _post_step(ints, fl, self._id_keys, self._id_part, self._batch_of, rows, self._vel_rows,
                           self._round_x, self._inv_m_x, self._inv_i_x, self._r_x, self._r_over_m, h, w_drum,
                           end_k, mu_r, 1.0 / self._r_min, self._hist, acc)
        self._stat_steps += 1
        self._contacts += int(acc[0])
        self._ov_max = max(self._ov_max, float(acc[1]))
        self._wall_max = max(self._wall_max, float(acc[2]))
        self._airborne = float(acc[3])
        if write and friction:
            pbatch.set_space_bodies(self._space, _VEL, self._sbuf)

    def cost_profile(self, duration_s: float) -> dict[str, float]:
        """Advance ``duration_s`` (whole steps) and say what a step costs: shapes and bodies in the space,
        solver iterations, contacts per step, and the shares of this process's CPU time in Chipmunk's
        step and in the post-step pass (rolling and end-plate friction, statistics). Counts do not depend
        on the machine's load; the shares are of one run."""
        n = max(1, int(round(duration_s / self.substep_s())))
        clock = np.zeros(2)
        c0, s0 = self._contacts, self._stat_steps
        self._run(n, clock=clock)
        self.t_s += n * self.substep_s()
        total = float(clock.sum())
        return {"shapes": float(len(self._space.shapes)), "bodies": float(len(self._space.bodies)),
                "iterations": float(self.iterations), "steps": float(n),
                "contacts_per_step": (self._contacts - c0) / max(1, self._stat_steps - s0),
                "chipmunk_share": float(clock[0]) / total if total > 0 else math.nan,
                "post_share": float(clock[1]) / total if total > 0 else math.nan,
                "cpu_ms_per_step": 1e3 * total / n}

    # ------------------------------------------------------------ statistics
    def reset_stats(self) -> None:
        """Start counting contact statistics (``stats()``) afresh."""
        self._hist = np.zeros(_OVERLAP_BINS + 1, dtype=np.int64)
        self._ov_max = 0.0
        self._wall_max = 0.0
        self._contacts = 0
        self._stat_steps = 0
        self._airborne = float("nan")

    def stats(self) -> ContactStats:
        """Overlap percentiles (small radii), wall penetration (mm) and airborne fraction since ``reset_stats``."""
        total = int(self._hist.sum())
        if total:
            k = int(np.searchsorted(np.cumsum(self._hist), 0.99 * total))
            p99 = min((k + 1) * 2.0 / _OVERLAP_BINS, self._ov_max)
        else:
            p99 = 0.0
        return ContactStats(self._stat_steps, self._contacts, float(p99), self._ov_max, 1e3 * self._wall_max,
                            self._airborne)

    def drum_torque_nm(self) -> float:
        """Torque of the bed on the drum about its axis (N m, the 2D slice), positive in the sense the drum
        turns at positive rpm: the wall's and baffles' contact impulses of the last step
        (``Body.each_arbiter``, ``Arbiter.total_impulse`` at the mean of its contact points), the
        reaction of rolling friction at the wall (its couples and contact impulses) and of the end
        plates' friction at each particle's centre, over the step -- one step's sample, not a mean
        (the space keeps only this step's contacts). NaN before the first step."""
        if self.n_steps == 0:
            return float("nan")
        tq = [0.0]

        def one(arb: pymunk.Arbiter) -> None:
            pts = arb.contact_point_set.points
            if not pts:
                return
            x = sum(p.point_a.x + p.point_b.x for p in pts) / (2 * len(pts))
            y = sum(p.point_a.y + p.point_b.y for p in pts) / (2 * len(pts))
            j = arb.total_impulse  # each_arbiter turns the arbiter to the drum's side: the impulse on the drum
            tq[0] += x * j.y - y * j.x

        self._drum.each_arbiter(one)
        self._space.static_body.each_arbiter(one)
        return self.mixer.direction * (tq[0] + float(self._acc_stats[4])) / self.substep_s()

    # ----------------------------------------------------------------- read
    def particles(self) -> Particles:
        """Centroids (m), circumscribed radii (m), classes, angles, outlines and the baffles now."""
        bb = pbatch.Buffer()
        pbatch.get_space_bodies(self._space, pbatch.BodyFields.POSITION | pbatch.BodyFields.ANGLE, bb)
        rows = np.frombuffer(bb.float_buf(), dtype=np.float64).reshape(-1, 3)[self._batch_of]
        kinds = self.mixer.particles
        return Particles(
            x_m=rows[:, 0].copy(), y_m=rows[:, 1].copy(), r_m=self._r.copy(), cls=self._cls.copy(),
            angle_rad=rows[:, 2].copy(), class_names=tuple(k.name for k in kinds),
            class_bgr=tuple(k.colour_bgr for k in kinds),
            class_outline_m=tuple(None if k.shape.is_round else o for k, o in zip(kinds, self._outlines, strict=True)),
            baffles_m=tuple(self.baffle_polygons_m()),
        )

    def kinetic_energy_j(self) -> float:
        """Translational kinetic energy of the particles (J)."""
        return float(sum(0.5 * b.mass * b.velocity.get_length_sqrd() for b in self._bodies))

    def snapshot(self) -> PymunkState:
        """The whole state now. The live twin is re-based on it (module doc), so the live run and every
        ``restore``/``from_state`` of it continue bit-identically."""
        blob = pickle.dumps((self._space, self._drum, self._bodies), protocol=pickle.HIGHEST_PROTOCOL)
        state = PymunkState(self.mixer, self.case, self.seed, self.params, self.iterations, self.t_s, self._rpm_target,
                            self._rpm_actual, self.n_steps, self._acc_s, self._cls.copy(), blob)
        self.restore(state)
        return state

    def restore(self, state: PymunkState) -> None:
        """Go back to ``state`` (bit-identical continuation)."""
        self.mixer, self.case, self.seed, self.params = state.mixer, state.case, state.seed, state.params
        self.iterations = int(state.iterations)
        self._cls = np.asarray(state.cls, dtype=np.int64).copy()
        self._set_tables()
        space, drum, bodies = pickle.loads(state.space)
        self._install(space, drum, list(bodies))
        self.t_s, self.n_steps, self._acc_s = float(state.t_s), int(state.n_steps), float(state.acc_s)
        self._rpm_target, self._rpm_actual = float(state.rpm_target), float(state.rpm_actual)
        if not hasattr(self, "_hist"):
            self.reset_stats()

    @classmethod
    def from_state(cls, state: PymunkState) -> PymunkDrumSim:
        """A new twin that continues from ``state``."""
        sim = cls.__new__(cls)
        sim.restore(state)
        return sim


def radial_spread_m(particles: Particles, areas_m2: np.ndarray | None = None) -> tuple[float, ...]:
    """Each class's spread about the whole bed's centroid (m): ``sqrt(mean |p_i - c_bed|^2)`` over
    its particles, ``c_bed`` area-weighted (``areas_m2`` per class; None: ``pi r^2``)."""
    a = np.pi * particles.r_m ** 2 if areas_m2 is None else np.asarray(areas_m2)[particles.cls]
    cx = float(np.dot(a, particles.x_m) / a.sum())
    cy = float(np.dot(a, particles.y_m) / a.sum())
    d2 = (particles.x_m - cx) ** 2 + (particles.y_m - cy) ** 2
    k_max = int(particles.cls.max()) + 1 if len(particles) else 0
    return tuple(float(np.sqrt(d2[particles.cls == k].mean())) if np.any(particles.cls == k) else float("nan")
                 for k in range(k_max))


__all__ = [
    "DEFAULT_DT_S",
    "DEFAULT_ITERATIONS",
    "ROUND_BED_DT_S",
    "PymunkDrumSim",
    "PymunkState",
    "convex_pieces",
    "default_dt_s",
    "radial_spread_m",
]

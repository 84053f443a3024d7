"""The 2D physics twin: a pymunk slice of the rotating drum.

Frame: origin at the drum axis, x to the right, y up (as the camera sees the front
face, before the renderer flips y for the image). Positive rpm turns the drum
counter-clockwise as seen by the camera, so the bed climbs the right-hand wall
and its free surface rises to the right (positive slope angle).

Model (all contacts are pymunk/Chipmunk2D impulses):

* **Wall**: a kinematic body of ``WALL_SEGMENTS`` thick segments (each as thick as
  two large particles) whose inner surface is the drum circle; it turns at
  ``rpm_actual``, which follows ``set_rpm`` at the mill's acceleration limit.
* **Particles**: disks of equal mass per area (a slab ``4/3 r_max`` thick, so the
  large disk weighs what its ball weighs) with a ball's moment ``I = 2/5 m r^2``.
* **Sliding friction** ``friction`` (particle-particle, and particle-wall unless
  ``wall_friction`` is given) and **restitution** are set per contact pair
  (Chipmunk multiplies the two shapes' values, so each shape holds the square root).
* **Rolling friction** ``rolling`` (coefficient mu_r): at every contact, after each
  solver step, a torque ``mu_r * r_i * F_n`` on each disk opposing the contact's
  relative rotation ``omega_i - omega_j`` (the drum's rate for a wall contact), with
  ``F_n`` the contact's normal impulse / step. It is capped so that it cannot reverse
  the relative rotation within a step: the "constant directional torque" model of
  DEM codes (EDEM's rolling friction CDT; Ai et al. 2011, type A). No contact, no
  torque: a disk in free flight keeps its spin.
* **Time step**: one fixed internal step ``dt_s`` (chosen by the convergence study in
  docs/validation.md), independent of how the caller slices time: ``advance(d)``
  adds ``d`` to an accumulator and runs whole steps; the remainder (< one step) waits
  for the next call. Contacts are stiff (``collision_slop``, ``collision_bias`` and
  ``iterations`` set for small overlaps), walls never let a disk sink in.

Initial states (paper Fig. 1): Case A large/small split left-right, Case B
split top-bottom (large above), Case C random; placed by random sequential
addition at 80 % size over the whole drum, inflated, and (A, C) settled with the
drum at rest, all from ``numpy.random.default_rng(seed)`` -- same seed, same run.
Case B starts as generated (large in the upper half of the drum, small in the
lower half) and falls as the drum starts, like a DEM generation: a settled
top-bottom layering of a half-full drum already reads MI ~0.65, because the
two layers' centroids are only 0.44 d_c apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import pymunk
import pymunk.batch

from sim.contacts import STAT_AIRBORNE, STAT_CONTACTS, STAT_OVERLAP_MAX, STAT_WALL_MAX, contact_pass
from sim.errors import SimError
from sim.recipe import G_M_S2, PAPER_DRUM, PAPER_RECIPE, DiskClass, DrumSpec, Recipe, slice_2d

CASES = ("A", "B", "C")
WALL_SEGMENTS = 72
# The paper's Hertz-Mindlin parameters (tables 1-2, ball-ball = ball-vessel) are the defaults.
PAPER_CONTACT = {"friction": 0.25, "rolling": 0.10, "restitution": 0.5}
DEFAULT_FRICTION = PAPER_CONTACT["friction"]  # particle-particle sliding friction
DEFAULT_WALL_FRICTION: float | None = None  # particle-wall: None = same as particle-particle
DEFAULT_ROLLING = PAPER_CONTACT["rolling"]  # rolling friction coefficient mu_r (torque mu_r r F_n)
DEFAULT_RESTITUTION = PAPER_CONTACT["restitution"]
DEFAULT_ACCEL_RPM_S = 20.0  # mill acceleration limit
DEFAULT_DT_S = 0.0005  # converged internal step (docs/validation.md, convergence study)
DEFAULT_ITERATIONS = 4
DEFAULT_BIAS = 1e-4  # fraction of an overlap left after 1 s of position correction
SLOP_R = 0.002  # allowed overlap before correction, in small radii
_SETTLE_DT_S = 0.002
_SETTLE_FINE_S = 0.1
_OVERLAP_BINS = 1000  # overlap histogram: bins of 0.002 small radii up to 2
_HASH_ABOVE = 500
_SHRINK = 0.8  # placement size before inflation


@dataclass(frozen=True)
class SimParams:
    """Contact and integration parameters of the twin (the knobs calibration turns)."""

    friction: float = DEFAULT_FRICTION
    rolling: float = DEFAULT_ROLLING
    restitution: float = DEFAULT_RESTITUTION
    wall_friction: float | None = DEFAULT_WALL_FRICTION  # None: same as ``friction``
    accel_rpm_s: float = DEFAULT_ACCEL_RPM_S
    dt_s: float = DEFAULT_DT_S
    iterations: int = DEFAULT_ITERATIONS
    bias: float = DEFAULT_BIAS


@dataclass(frozen=True)
class ContactStats:
    """Contact quality since the last ``reset_stats()``: overlaps and wall penetration.

    ``overlap_p99_r``: 99th percentile of disk-disk overlap over all contacts of all
    steps, in small radii; ``overlap_max_r`` the largest; ``wall_max_mm`` the deepest
    any disk got into the wall; ``airborne`` the fraction of disks without a contact
    in the last step.
    """

    steps: int
    contacts: int
    overlap_p99_r: float
    overlap_max_r: float
    wall_max_mm: float
    airborne: float


@dataclass(frozen=True)
class Particles:
    """Positions (m, drum frame, y up), radii (m) and class index of every disk."""

    x_m: np.ndarray
    y_m: np.ndarray
    r_m: np.ndarray
    cls: np.ndarray
    angle_rad: np.ndarray | None = None
    class_names: tuple[str, ...] = ()
    class_bgr: tuple[tuple[int, int, int], ...] = ()

    def __len__(self) -> int:
        return int(self.x_m.shape[0])


@dataclass(frozen=True)
class SimState:
    """Everything needed to rebuild a running twin (picklable; sent to what-if workers)."""

    drum: DrumSpec
    recipe: Recipe
    classes: tuple[DiskClass, ...]
    case: str
    seed: int
    params: SimParams
    t_s: float
    rpm_target: float
    rpm_actual: float
    drum_angle_rad: float
    cls: np.ndarray
    pos_m: np.ndarray  # (n, 2)
    vel_m_s: np.ndarray  # (n, 2)
    angle_rad: np.ndarray
    omega_rad_s: np.ndarray
    n_steps: int = 0
    extra: dict = field(default_factory=dict)


def rpm_to_rad_s(rpm: float) -> float:
    return float(rpm) * 2.0 * math.pi / 60.0


def check_rpm(rpm: float, drum: DrumSpec) -> float:
    """The rpm as a float, or SimError if it is not finite or above the critical speed."""
    try:
        rpm = float(rpm)
    except (TypeError, ValueError):
        raise SimError(f"rpm must be a number (got {rpm!r})") from None
    if not math.isfinite(rpm):
        raise SimError(f"rpm must be finite (got {rpm})")
    if abs(rpm) > drum.critical_rpm:
        raise SimError(
            f"{abs(rpm):g} rpm is above the critical speed {drum.critical_rpm:.1f} rpm "
            f"of a {drum.diameter_m * 1e3:g} mm drum"
        )
    return rpm


def _check_params(p: SimParams) -> None:
    if not (0.0 <= p.friction <= 5.0) or not math.isfinite(p.friction):
        raise SimError(f"friction must be in [0, 5] (got {p.friction})")
    if not (0.0 <= p.rolling <= 5.0) or not math.isfinite(p.rolling):
        raise SimError(f"rolling resistance must be in [0, 5] (got {p.rolling})")
    if not (0.0 <= p.restitution <= 1.0):
        raise SimError(f"restitution must be in [0, 1] (got {p.restitution})")
    if p.wall_friction is not None and not (0.0 <= p.wall_friction <= 5.0):
        raise SimError(f"wall friction must be in [0, 5] (got {p.wall_friction})")
    if not (1e-5 <= p.dt_s <= 0.02) or not math.isfinite(p.dt_s):
        raise SimError(f"time step must be in [0.01, 20] ms (got {p.dt_s * 1e3:g} ms)")
    if not (0.0 < p.bias < 1.0):
        raise SimError(f"collision bias must be in (0, 1) (got {p.bias})")
    if p.accel_rpm_s <= 0:
        raise SimError(f"acceleration limit must be positive (got {p.accel_rpm_s} rpm/s)")
    if not (1 <= p.iterations <= 200):
        raise SimError(f"solver iterations must be in [1, 200] (got {p.iterations})")


def _place(
    classes: list[DiskClass], case: str, radius_m: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 2) and class indices by random sequential addition at ``_SHRINK`` size."""
    radii = np.concatenate([np.full(c.count, c.radius_m) for c in classes])
    cls = np.concatenate([np.full(c.count, k, dtype=np.int64) for k, c in enumerate(classes)])
    order = np.argsort(-radii, kind="stable")  # largest first
    small_r = radii * _SHRINK
    pos = np.zeros((radii.size, 2))
    placed = np.zeros(radii.size, dtype=bool)
    gap = 0.02 * radii.max()
    for i in order:
        r = small_r[i]
        k = cls[i]
        lim = radius_m - radii[i] - gap
        for _ in range(20000):
            x, y = rng.uniform(-lim, lim, size=2)
            if x * x + y * y > lim * lim:
                continue
            if case == "A" and len(classes) >= 2 and ((x > -r) if k == 0 else (x < r)):
                continue  # class 0 (large) left, the others right
            if case == "B" and len(classes) >= 2 and ((y < r) if k == 0 else (y > -r)):
                continue  # class 0 (large) on top, the others below
            if placed.any():
                d2 = (pos[placed, 0] - x) ** 2 + (pos[placed, 1] - y) ** 2
                if np.any(d2 < (small_r[placed] + r + gap) ** 2):
                    continue
            pos[i] = (x, y)
            placed[i] = True
            break
        else:
            raise SimError(
                f"recipe does not fit: could not place {radii.size} disks in the drum "
                f"(case {case}); lower the fill level or the counts"
            )
    return pos, cls


class DrumSim:
    """The 2D drum twin (see the module doc). Seeded and reproducible."""

    def __init__(
        self,
        drum: DrumSpec = PAPER_DRUM,
        recipe: Recipe = PAPER_RECIPE,
        case: str = "C",
        seed: int = 0,
        rpm: float = 5.0,
        friction: float = DEFAULT_FRICTION,
        rolling: float = DEFAULT_ROLLING,
        *,
        restitution: float = DEFAULT_RESTITUTION,
        wall_friction: float | None = DEFAULT_WALL_FRICTION,
        accel_rpm_s: float = DEFAULT_ACCEL_RPM_S,
        dt_s: float = DEFAULT_DT_S,
        iterations: int = DEFAULT_ITERATIONS,
        bias: float = DEFAULT_BIAS,
        settle_s: float = 1.0,
    ) -> None:
        case = str(case).upper()
        if case not in CASES:
            raise SimError(f"case must be one of {', '.join(CASES)} (got {case!r})")
        params = SimParams(float(friction), float(rolling), float(restitution),
                           None if wall_friction is None else float(wall_friction),
                           float(accel_rpm_s), float(dt_s), int(iterations), float(bias))
        _check_params(params)
        rpm = check_rpm(rpm, drum)
        classes = tuple(slice_2d(recipe, drum))
        rng = np.random.default_rng(seed)
        pos, cls = _place(list(classes), case, drum.radius_m, rng)
        n = cls.size
        state = SimState(
            drum=drum, recipe=recipe, classes=classes, case=case, seed=int(seed), params=params,
            t_s=0.0, rpm_target=0.0, rpm_actual=0.0, drum_angle_rad=0.0, cls=cls, pos_m=pos,
            vel_m_s=np.zeros((n, 2)), angle_rad=rng.uniform(0, 2 * math.pi, n), omega_rad_s=np.zeros(n),
        )
        self._build(state, radius_scale=_SHRINK)
        self._settle(0.0 if case == "B" else settle_s)
        self.t_s = 0.0
        self.n_steps = 0
        self._acc_s = 0.0
        self.reset_stats()
        self._rpm_target = rpm
        self._set_rpm_actual(rpm)

    # ----------------------------------------------------------------- build
    def _build(self, st: SimState, radius_scale: float = 1.0) -> None:
        self.drum = st.drum
        self.recipe = st.recipe
        self.classes = st.classes
        self.case = st.case
        self.seed = st.seed
        self.params = st.params
        self.t_s = st.t_s
        self.n_steps = st.n_steps
        self._acc_s = float(st.extra.get("acc_s", 0.0))
        space = pymunk.Space()
        space.gravity = (0.0, -G_M_S2)
        r_max = max(c.radius_m for c in st.classes)
        r_min = min(c.radius_m for c in st.classes)
        self._r_min = r_min
        space.collision_slop = SLOP_R * r_min
        # only this step's contacts stay cached, so the batch arbiter read sees live contacts only
        space.collision_persistence = 1
        space.sleep_time_threshold = float("inf")
        self._space = space
        # The drum is round, so its turning is all in the surface velocity of a static wall:
        # static shapes are never re-indexed, and contacts see the same relative velocity.
        wall = space.static_body
        self._wall = wall
        self._drum_angle_rad = float(st.drum_angle_rad)
        seg_r = 2.0 * r_max
        big_r = (st.drum.radius_m + seg_r) / math.cos(math.pi / WALL_SEGMENTS)
        self._wall_shapes = []
        self._wall_tangent = []
        for i in range(WALL_SEGMENTS):
            a0 = 2 * math.pi * i / WALL_SEGMENTS
            a1 = 2 * math.pi * (i + 1) / WALL_SEGMENTS
            seg = pymunk.Segment(
                wall, (big_r * math.cos(a0), big_r * math.sin(a0)), (big_r * math.cos(a1), big_r * math.sin(a1)), seg_r
            )
            space.add(seg)
            self._wall_shapes.append(seg)
            am = 0.5 * (a0 + a1)
            self._wall_tangent.append((-math.sin(am), math.cos(am)))  # counter-clockwise
        self._cls = np.asarray(st.cls, dtype=np.int64)
        self._r = np.array([st.classes[k].radius_m for k in self._cls])
        self._bodies: list[pymunk.Body] = []
        self._shapes: list[pymunk.Circle] = []
        slab = 4.0 / 3.0 * r_max
        for i, k in enumerate(self._cls):
            c = st.classes[k]
            m = c.mass_kg(slab)
            b = pymunk.Body(m, 0.4 * m * c.radius_m**2)
            b.position = (float(st.pos_m[i, 0]), float(st.pos_m[i, 1]))
            b.velocity = (float(st.vel_m_s[i, 0]), float(st.vel_m_s[i, 1]))
            b.angle = float(st.angle_rad[i])
            b.angular_velocity = float(st.omega_rad_s[i])
            s = pymunk.Circle(b, c.radius_m * radius_scale)
            space.add(b, s)
            self._bodies.append(b)
            self._shapes.append(s)
        self._masses = np.array([st.classes[k].mass_kg(slab) for k in self._cls])
        self._inertia = 0.4 * self._masses * self._r**2
        if self._cls.size >= _HASH_ABOVE:  # large beds: the spatial hash beats the bounding-box tree
            space.use_spatial_hash(2.5 * r_max, 10 * self._cls.size)
        self._rpm_target = st.rpm_target
        self._rpm_actual = math.nan  # unset: the next _set_rpm_actual always applies
        self._apply_params()
        self._set_rpm_actual(st.rpm_actual)
        self._buf = pymunk.batch.Buffer()
        self._abuf = pymunk.batch.Buffer()
        self._wbuf = pymunk.batch.Buffer()
        ids = np.array([b.id for b in self._bodies], dtype=np.uint64)
        self._ids_order = np.argsort(ids)
        self._ids_sorted = ids[self._ids_order]
        self._inv_i = 1.0 / self._inertia
        self._slot = self._space_slots()
        self._w_dummy = np.zeros(self._n_space_bodies)
        if not hasattr(self, "_hist"):
            self.reset_stats()

    def _apply_params(self) -> None:
        p = self.params
        mu_p = math.sqrt(max(p.friction, 0.0))
        mu_w = p.friction if p.wall_friction is None else p.wall_friction
        e = math.sqrt(p.restitution)
        for s in self._shapes:
            s.friction = mu_p
            s.elasticity = e
        for seg in self._wall_shapes:
            seg.friction = (mu_w / mu_p) if mu_p > 0 else 0.0
            seg.elasticity = e
        self._space.iterations = p.iterations
        self._space.collision_bias = p.bias

    def _settle(self, settle_s: float) -> None:
        """Inflate the disks to full size (no gravity), then let the bed settle with the drum at rest."""
        space = self._space
        space.damping = 0.3
        space.gravity = (0.0, 0.0)
        h = _SETTLE_DT_S  # settling is damped and never measured: a coarse step is enough
        n_grow = 40
        for j in range(n_grow):
            scale = _SHRINK + (1.0 - _SHRINK) * (j + 1) / n_grow
            for s, r in zip(self._shapes, self._r, strict=False):
                s.unsafe_set_radius(float(r * scale))
            space.step(h)
        space.gravity = (0.0, -G_M_S2)
        for _ in range(int(round(settle_s / h))):
            space.step(h)
        fine_s = _SETTLE_FINE_S if settle_s > 0 else 0.0  # case B starts as generated: no settling at all
        for _ in range(int(round(fine_s / self.params.dt_s))):  # relax the coarse steps' overlaps
            space.step(self.params.dt_s)
        space.damping = 1.0
        for b in self._bodies:
            b.velocity = (0.0, 0.0)
            b.angular_velocity = 0.0

    # ------------------------------------------------------------- controls
    @property
    def rpm_actual(self) -> float:
        """Drum speed now (rpm), following the setpoint at the acceleration limit."""
        return float(self._rpm_actual)

    @property
    def rpm_target(self) -> float:
        """The rpm setpoint."""
        return float(self._rpm_target)

    @property
    def critical_rpm(self) -> float:
        """Critical speed of this drum (rpm), ``DrumSpec.critical_rpm``."""
        return self.drum.critical_rpm

    def set_rpm(self, rpm: float) -> None:
        """New rpm setpoint; the drum ramps to it at ``accel_rpm_s``. Above critical speed: SimError."""
        self._rpm_target = check_rpm(rpm, self.drum)

    def set_friction(self, mu: float, rolling: float | None = None) -> None:
        """Change sliding friction (and rolling friction) at run time."""
        rolling = self.params.rolling if rolling is None else float(rolling)
        params = replace(self.params, friction=float(mu), rolling=rolling)
        _check_params(params)
        self.params = params
        self._apply_params()

    def _set_rpm_actual(self, rpm: float) -> None:
        if rpm == self._rpm_actual:
            return
        self._rpm_actual = float(rpm)
        self._omega_wall = rpm_to_rad_s(rpm)
        v = self._omega_wall * self.drum.radius_m
        for s, (tx, ty) in zip(self._wall_shapes, self._wall_tangent, strict=True):
            s.surface_velocity = (v * tx, v * ty)  # the drum's tangential velocity at this segment

    def substep_s(self) -> float:
        """The fixed internal step (s)."""
        return self.params.dt_s

    # ---------------------------------------------------------------- time
    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` seconds (same as ``advance``; kept for callers of the old API)."""
        if not (dt_s > 0) or not math.isfinite(dt_s):
            raise SimError(f"step must be a positive number of seconds (got {dt_s})")
        self.advance(dt_s)

    def advance(self, duration_s: float) -> None:
        """Advance the clock by ``duration_s`` s, running every whole fixed step that fits.

        The physics runs in steps of exactly ``dt_s``; what is left over (less than a
        step) is carried to the next call, so any way of slicing the same time runs
        the same steps.
        """
        if duration_s < 0 or not math.isfinite(duration_s):
            raise SimError(f"duration must be >= 0 s (got {duration_s})")
        h = self.params.dt_s
        self._acc_s += duration_s
        n = int(math.floor(self._acc_s / h + 1e-9))
        self.t_s += duration_s
        if n <= 0:
            return
        self._acc_s = max(0.0, self._acc_s - n * h)
        accel = self.params.accel_rpm_s * h
        space = self._space
        for _ in range(n):
            if self._rpm_actual != self._rpm_target:
                diff = self._rpm_target - self._rpm_actual
                step_rpm = diff if abs(diff) <= accel else math.copysign(accel, diff)
                self._set_rpm_actual(self._rpm_actual + step_rpm)
            space.step(h)
            self._drum_angle_rad += self._omega_wall * h
            self._after_step()
        self.n_steps += n

    # ------------------------------------------------- contacts: rolling friction and statistics
    def _index(self, ids: np.ndarray) -> np.ndarray:
        """Insertion index of each body id; -1 for the wall (or anything else)."""
        pos = np.minimum(np.searchsorted(self._ids_sorted, ids), self._ids_sorted.size - 1)
        return np.where(self._ids_sorted[pos] == ids, self._ids_order[pos], -1)

    def _space_slots(self) -> np.ndarray:
        """Position of each disk in the space's body iteration order (stable: bodies never leave)."""
        buf = self._wbuf
        buf.clear()
        pymunk.batch.get_space_bodies(self._space, pymunk.batch.BodyFields.BODY_ID, buf)
        order = self._index(np.frombuffer(buf.int_buf(), dtype=np.uint64))
        slot = np.empty(self._r.size, dtype=np.int64)
        slot[order[order >= 0]] = np.nonzero(order >= 0)[0]
        self._n_space_bodies = order.size
        return slot

    def _read_contacts(self) -> tuple[np.ndarray, np.ndarray]:
        """This step's contacts: (m, 2) body ids and (m, 5) impulse x, y, normal x, y, distance."""
        buf = self._abuf
        buf.clear()
        f = pymunk.batch.ArbiterFields
        pymunk.batch.get_space_arbiters(
            self._space, f.BODY_A_ID | f.BODY_B_ID | f.TOTAL_IMPULSE | f.NORMAL | f.DISTANCE_1, buf
        )
        ids = np.frombuffer(buf.int_buf(), dtype=np.uint64).reshape(-1, 2)
        fl = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(-1, 5)
        return ids, fl

    def _after_step(self) -> None:
        """Rolling friction and contact statistics from the step just taken (``sim.contacts``)."""
        ids, fl = self._read_contacts()
        mu_r = self.params.rolling
        if mu_r > 0:
            buf = self._wbuf
            buf.clear()
            pymunk.batch.get_space_bodies(self._space, pymunk.batch.BodyFields.ANGULAR_VELOCITY, buf)
            w_space = np.frombuffer(buf.float_buf(), dtype=np.float64)  # writable view of the batch buffer
            if w_space.size != self._n_space_bodies:
                self._slot = self._space_slots()
                return self._after_step()
        else:
            w_space = self._w_dummy
        self._stat_steps += 1
        contact_pass(ids, fl, self._ids_sorted, self._ids_order, self._r, self._inv_i, self._slot, w_space,
                     self._omega_wall, mu_r, self._r_min, self._hist, self._acc)
        if mu_r > 0:  # the spins were changed in place: write them back
            pymunk.batch.set_space_bodies(self._space, pymunk.batch.BodyFields.ANGULAR_VELOCITY, self._wbuf)

    def reset_stats(self) -> None:
        """Start counting contact statistics (``stats()``) afresh."""
        self._hist = np.zeros(_OVERLAP_BINS + 1, dtype=np.int64)
        self._acc = np.zeros(4)
        self._acc[STAT_AIRBORNE] = np.nan
        self._stat_steps = 0

    def stats(self) -> ContactStats:
        """Overlap percentiles, wall penetration and airborne fraction since ``reset_stats()``."""
        total = int(self._hist.sum())
        acc = self._acc
        if total:
            k = int(np.searchsorted(np.cumsum(self._hist), 0.99 * total))
            p99 = min((k + 1) * 2.0 / _OVERLAP_BINS, float(acc[STAT_OVERLAP_MAX]))
        else:
            p99 = 0.0
        return ContactStats(self._stat_steps, int(acc[STAT_CONTACTS]), float(p99), float(acc[STAT_OVERLAP_MAX]),
                            1e3 * float(acc[STAT_WALL_MAX]), float(acc[STAT_AIRBORNE]))

    def contact_counts(self) -> np.ndarray:
        """Number of contacts (with disks or the wall) of each disk in the last step."""
        ids, _ = self._read_contacts()
        a = self._index(ids[:, 0])
        b = self._index(ids[:, 1])
        n = self._r.size
        return (np.bincount(a[a >= 0], minlength=n) + np.bincount(b[b >= 0], minlength=n)).astype(np.int64)

    # ----------------------------------------------------------------- read
    def _body_arrays(self) -> np.ndarray:
        """(n, 6) array x, y, angle, vx, vy, w of the particles, in insertion order."""
        buf = self._buf
        buf.clear()
        fields = (
            pymunk.batch.BodyFields.BODY_ID
            | pymunk.batch.BodyFields.POSITION
            | pymunk.batch.BodyFields.ANGLE
            | pymunk.batch.BodyFields.VELOCITY
            | pymunk.batch.BodyFields.ANGULAR_VELOCITY
        )
        pymunk.batch.get_space_bodies(self._space, fields, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uint64)
        arr = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(-1, 6)
        # map the space's body order to insertion order by body id
        pos = np.searchsorted(self._ids_sorted, ids)
        pos = np.minimum(pos, self._ids_sorted.size - 1)
        ours = self._ids_sorted[pos] == ids
        out = np.empty((len(self._bodies), 6))
        out[self._ids_order[pos[ours]]] = arr[ours]
        return out
    def particles(self) -> Particles:
        """Positions (m), radii (m), classes of all disks now."""
        a = self._body_arrays()
        return Particles(
            x_m=a[:, 0], y_m=a[:, 1], r_m=self._r.copy(), cls=self._cls.copy(), angle_rad=a[:, 2],
            class_names=tuple(c.name for c in self.classes), class_bgr=tuple(c.colour_bgr for c in self.classes),
        )

    def kinetic_energy_j(self) -> float:
        a = self._body_arrays()
        return float(0.5 * np.sum(self._masses * (a[:, 3] ** 2 + a[:, 4] ** 2)))

    def snapshot(self, exact: bool = True) -> SimState:
        """The whole state now (arrays are copies).

        pymunk keeps contact impulses between steps that a state cannot carry, so with
        ``exact`` (default) this twin is rebuilt from the snapshot too: its own future and
        every ``restore``/``from_state`` branch of the snapshot are then bit-identical.
        """
        st = self._state_now()
        if exact:
            self._build(st)
        return st

    def _state_now(self) -> SimState:
        a = self._body_arrays()
        return SimState(
            drum=self.drum, recipe=self.recipe, classes=self.classes, case=self.case, seed=self.seed,
            params=self.params, t_s=self.t_s, rpm_target=self._rpm_target, rpm_actual=self._rpm_actual,
            drum_angle_rad=self._drum_angle_rad, cls=self._cls.copy(), pos_m=a[:, 0:2].copy(),
            vel_m_s=a[:, 3:5].copy(), angle_rad=a[:, 2].copy(), omega_rad_s=a[:, 5].copy(), n_steps=self.n_steps,
            extra={"acc_s": self._acc_s},
        )

    def restore(self, state: SimState) -> None:
        """Go back to ``state`` (the pymunk space is rebuilt, so restores are repeatable)."""
        self._build(state)

    @classmethod
    def from_state(cls, state: SimState) -> DrumSim:
        """A new twin that continues from ``state``."""
        sim = cls.__new__(cls)
        sim._build(state)
        return sim


__all__ = [
    "CASES",
    "DEFAULT_DT_S",
    "DEFAULT_FRICTION",
    "DEFAULT_ROLLING",
    "ContactStats",
    "DrumSim",
    "Particles",
    "SimParams",
    "SimState",
    "check_rpm",
    "rpm_to_rad_s",
]

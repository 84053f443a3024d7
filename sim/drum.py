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
* **Rolling resistance** ``rolling``: each disk has a ``SimpleMotor`` to the drum
  frame's angular velocity whose torque is capped at ``rolling * m * g * r`` -- a
  Coulomb-like rolling friction torque, solved inside the contact solver.
* **Time step**: ``dt_s`` up to 15 rpm, shrinking as ``15 / rpm`` above, so that
  particles never move more than a fraction of a small radius per step.

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

from sim.errors import SimError
from sim.recipe import G_M_S2, PAPER_DRUM, PAPER_RECIPE, DiskClass, DrumSpec, Recipe, slice_2d

CASES = ("A", "B", "C")
WALL_SEGMENTS = 72
# 2D-effective contact parameters, tuned so the slice shows the paper's radial size
# segregation at 5 rpm and its weakening towards cataracting (docs/validation.md).
# The paper's 3D Hertz-Mindlin values (table 2: sliding 0.25, rolling 0.1,
# restitution 0.5) are PAPER_CONTACT; in 2D they give a much weaker segregation.
DEFAULT_FRICTION = 0.5  # particle-particle sliding friction
DEFAULT_WALL_FRICTION = 0.8  # particle-wall: also stands for the end plates' grip a slice lacks
DEFAULT_ROLLING = 0.0  # rolling resistance coefficient (torque cap rolling * m g r)
DEFAULT_RESTITUTION = 0.05
PAPER_CONTACT = {"friction": 0.25, "rolling": 0.10, "restitution": 0.5}
DEFAULT_ACCEL_RPM_S = 20.0  # mill acceleration limit
DEFAULT_DT_S = 0.01
DEFAULT_ITERATIONS = 6
_RPM_FULL_DT = 15.0  # below this rpm the full dt_s is used
_MIN_STEP_S = 1e-5
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
    if not (0.0 < p.dt_s <= 0.05):
        raise SimError(f"time step must be in (0, 0.05] s (got {p.dt_s})")
    if p.accel_rpm_s <= 0:
        raise SimError(f"acceleration limit must be positive (got {p.accel_rpm_s} rpm/s)")
    if p.iterations < 1:
        raise SimError(f"solver iterations must be >= 1 (got {p.iterations})")


def _place(classes: list[DiskClass], case: str, radius_m: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
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
        settle_s: float = 1.0,
    ) -> None:
        case = str(case).upper()
        if case not in CASES:
            raise SimError(f"case must be one of {', '.join(CASES)} (got {case!r})")
        params = SimParams(float(friction), float(rolling), float(restitution), wall_friction,
                           float(accel_rpm_s), float(dt_s), int(iterations))
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
        space = pymunk.Space()
        space.gravity = (0.0, -G_M_S2)
        space.iterations = st.params.iterations
        r_max = max(c.radius_m for c in st.classes)
        r_min = min(c.radius_m for c in st.classes)
        space.collision_slop = 0.02 * r_min
        space.sleep_time_threshold = float("inf")
        self._space = space
        wall = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        wall.angle = st.drum_angle_rad
        space.add(wall)
        self._wall = wall
        seg_r = 2.0 * r_max
        big_r = (st.drum.radius_m + seg_r) / math.cos(math.pi / WALL_SEGMENTS)
        self._wall_shapes = []
        for i in range(WALL_SEGMENTS):
            a0 = 2 * math.pi * i / WALL_SEGMENTS
            a1 = 2 * math.pi * (i + 1) / WALL_SEGMENTS
            seg = pymunk.Segment(
                wall, (big_r * math.cos(a0), big_r * math.sin(a0)), (big_r * math.cos(a1), big_r * math.sin(a1)), seg_r
            )
            space.add(seg)
            self._wall_shapes.append(seg)
        self._cls = np.asarray(st.cls, dtype=np.int64)
        self._r = np.array([st.classes[k].radius_m for k in self._cls])
        self._bodies: list[pymunk.Body] = []
        self._shapes: list[pymunk.Circle] = []
        self._motors: list[pymunk.SimpleMotor] = []
        self._motors_in_space = False
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
            mo = pymunk.SimpleMotor(b, space.static_body, 0.0)
            space.add(b, s)  # the rolling-resistance motors join the space in _apply_params
            self._bodies.append(b)
            self._shapes.append(s)
            self._motors.append(mo)
        self._masses = np.array([st.classes[k].mass_kg(slab) for k in self._cls])
        if self._cls.size >= _HASH_ABOVE:  # large beds: the spatial hash beats the bounding-box tree
            space.use_spatial_hash(2.5 * r_max, 10 * self._cls.size)
        self._rpm_target = st.rpm_target
        self._rpm_actual = None
        self._apply_params()
        self._set_rpm_actual(st.rpm_actual)
        self._buf = pymunk.batch.Buffer()
        ids = np.array([b.id for b in self._bodies], dtype=np.uintp)
        self._ids_order = np.argsort(ids)
        self._ids_sorted = ids[self._ids_order]

    def _apply_params(self) -> None:
        p = self.params
        mu_p = math.sqrt(max(p.friction, 0.0))
        mu_w = p.friction if p.wall_friction is None else p.wall_friction
        e = math.sqrt(p.restitution)
        for s in self._shapes:
            s.friction = mu_p
            s.elasticity = e
        for s in self._wall_shapes:
            s.friction = (mu_w / mu_p) if mu_p > 0 else 0.0
            s.elasticity = e
        torque_cap = p.rolling * self._masses * G_M_S2 * self._r
        for mo, cap in zip(self._motors, torque_cap):
            mo.max_force = float(cap)
        # A motor capped at zero torque applies no impulse: leave it out of the solver (~10% faster).
        want = p.rolling > 0
        have = self._motors_in_space
        if want and not have:
            self._space.add(*self._motors)
        elif have and not want:
            self._space.remove(*self._motors)
        self._motors_in_space = want
        self._space.iterations = p.iterations

    def _settle(self, settle_s: float) -> None:
        """Inflate the disks to full size (no gravity), then let the bed settle with the drum at rest."""
        space = self._space
        space.damping = 0.3
        space.gravity = (0.0, 0.0)
        h = min(self.params.dt_s, 0.005)
        n_grow = 40
        for j in range(n_grow):
            scale = _SHRINK + (1.0 - _SHRINK) * (j + 1) / n_grow
            for s, r in zip(self._shapes, self._r):
                s.unsafe_set_radius(float(r * scale))
            space.step(h)
        space.gravity = (0.0, -G_M_S2)
        for _ in range(int(round(settle_s / h))):
            space.step(h)
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
        return self.drum.critical_rpm

    def set_rpm(self, rpm: float) -> None:
        """New rpm setpoint; the drum ramps to it at ``accel_rpm_s``. Above critical speed: SimError."""
        self._rpm_target = check_rpm(rpm, self.drum)

    def set_friction(self, mu: float, rolling: float | None = None) -> None:
        """Change sliding friction (and rolling resistance) at run time."""
        params = replace(self.params, friction=float(mu), rolling=self.params.rolling if rolling is None else float(rolling))
        _check_params(params)
        self.params = params
        self._apply_params()

    def _set_rpm_actual(self, rpm: float) -> None:
        if rpm == self._rpm_actual:
            return
        self._rpm_actual = float(rpm)
        w = rpm_to_rad_s(rpm)
        self._wall.angular_velocity = w
        for mo in self._motors:
            mo.rate = w

    def substep_s(self) -> float:
        """Largest internal step (s) at the current speed."""
        rpm = max(abs(self._rpm_actual), abs(self._rpm_target))
        return self.params.dt_s * min(1.0, _RPM_FULL_DT / max(rpm, 1e-9))

    # ---------------------------------------------------------------- time
    def step(self, dt_s: float) -> None:
        """Advance by ``dt_s`` seconds (split into equal substeps no longer than ``substep_s()``)."""
        if not (dt_s > 0) or not math.isfinite(dt_s):
            raise SimError(f"step must be a positive number of seconds (got {dt_s})")
        if dt_s < _MIN_STEP_S:  # the contact solver divides by dt: never take a sliver of a step
            self.t_s += dt_s
            return
        n = max(1, math.ceil(dt_s / self.substep_s() - 1e-9))
        h = dt_s / n
        accel = self.params.accel_rpm_s * h
        space = self._space
        for _ in range(n):
            if self._rpm_actual != self._rpm_target:
                diff = self._rpm_target - self._rpm_actual
                self._set_rpm_actual(self._rpm_target if abs(diff) <= accel else self._rpm_actual + math.copysign(accel, diff))
            space.step(h)
        self.t_s += dt_s
        self.n_steps += n

    def advance(self, duration_s: float) -> None:
        """Advance by ``duration_s`` seconds in equal steps no longer than ``dt_s``."""
        if duration_s < 0 or not math.isfinite(duration_s):
            raise SimError(f"duration must be >= 0 s (got {duration_s})")
        n = math.ceil(duration_s / self.params.dt_s - 1e-6)
        if n <= 0 or duration_s < _MIN_STEP_S:
            self.t_s += duration_s
            return
        h = duration_s / n
        for _ in range(n):
            self.step(h)

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
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp)
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
            drum_angle_rad=float(self._wall.angle), cls=self._cls.copy(), pos_m=a[:, 0:2].copy(),
            vel_m_s=a[:, 3:5].copy(), angle_rad=a[:, 2].copy(), omega_rad_s=a[:, 5].copy(), n_steps=self.n_steps,
        )

    def restore(self, state: SimState) -> None:
        """Go back to ``state`` (the pymunk space is rebuilt, so restores are repeatable)."""
        self._build(state)

    @classmethod
    def from_state(cls, state: SimState) -> "DrumSim":
        """A new twin that continues from ``state``."""
        sim = cls.__new__(cls)
        sim._build(state)
        return sim


__all__ = [
    "CASES",
    "DEFAULT_FRICTION",
    "DEFAULT_ROLLING",
    "DrumSim",
    "Particles",
    "SimParams",
    "SimState",
    "check_rpm",
    "rpm_to_rad_s",
]

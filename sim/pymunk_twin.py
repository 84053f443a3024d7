"""The pymunk twin: the user's mixer (any particle shape, baffles) in Chipmunk2D through pymunk.

Same interface and statistics as ``sim.drum.DrumSim`` (advance/step, particles, snapshot/restore/
from_state, set_rpm, rpm_actual, t_s, set_friction, stats/reset_stats, critical_rpm), for the
mixers the compiled DEM cannot hold (``sim.mixer.Mixer.all_round`` False).

Frame and units as ``sim.drum``: origin at the drum axis, x right, y up, metres, seconds, kg.
The drum turns at ``direction * rpm_actual`` (``Mixer.direction``: +1 counter-clockwise as the
camera sees it); ``rpm_actual`` follows ``set_rpm`` at the acceleration limit.

Model:

* **Drum** (``sim.pymunk_drum``): a static ring of segments whose surface moves with the drum;
  baffles on one KINEMATIC body turning about the axis.
* **Particles** (``sim.pymunk_shapes``): one DYNAMIC body each, discs as circles, convex outlines as
  one rounded poly, non-convex ones as convex pieces of one body. Counts and masses from
  ``sim.mixer.resolve`` (``density * area * slab``).
* **Contacts** (``sim.pymunk_contacts``): Chipmunk's impulse solver, Coulomb friction and
  restitution split between the two shapes of a contact.
* **Rolling friction** (round contacts) and **end plates** (Taberlet et al. 2003, as ``sim.dem``):
  after each step, the compiled pass of ``sim.pymunk_contacts``.
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
import pymunk.batch as pbatch

from sim.errors import SimError
from sim.mixer import Mixer, resolve, shape_outline_m
from sim.params import (
    CASES,
    DEFAULT_ACCEL_RPM_S,
    DEFAULT_FRICTION,
    DEFAULT_RESTITUTION,
    DEFAULT_ROLLING,
    SimParams,
    check_params,
    check_rpm,
    rpm_to_rad_s,
)
from sim.placement import SHRINK, check_placement, place_random
from sim.pymunk_contacts import (
    ARBITER_FIELDS,
    BODY_FIELDS,
    VELOCITY_FIELDS,
    batch_index,
    post_step,
    set_coefficients,
    solver_settings,
)
from sim.pymunk_drum import add_wall, baffle_polygons_m, contact_impulse_moment, wall_tangents
from sim.pymunk_shapes import moment_kg_m2, particle_body, scale_particle
from sim.recipe import G_M_S2, DiskClass, DrumSpec
from sim.twin_base import OVERLAP_BINS, ContactStats, FixedStepTwin, Particles, overlap_p99_r

DEFAULT_DT_S = 0.001  # a bed at least half not round (cut-disc rig): 1 ms = 0.5 ms, 2 ms 1.1 deg low (validation.md 10)
ROUND_BED_DT_S = 0.0005  # a bed mostly of discs: 0.5 ms 0.8 deg below 0.25 ms, 2 ms 3.6 deg (validation.md 10)
DEFAULT_ITERATIONS = 10  # Chipmunk solver iterations per step
_INFLATE_S = 0.1
_SETTLE_DAMPING = 0.1  # velocity kept after one second while settling (pymunk Space.damping)


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
        check_params(params)
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
        pos, k, ang = check_placement(pos_m, classes, angle_rad, len(mixer.particles), mixer.drum)
        sim = cls.__new__(cls)
        rpm = sim._configure(mixer, "image", seed, rpm, friction, rolling, **kwargs)
        sim._start(pos, k, ang, rpm, max(0.0, float(settle_s)))
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
        self._moment_cls = np.array([moment_kg_m2(k.shape, m) for k, m in zip(kinds, self._mass_cls, strict=True)])
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
        """A new space: the wall, the baffles, the particles at ``SHRINK`` size (``pos`` m, ``angles`` rad)."""
        space = pymunk.Space()
        space.gravity = (0.0, -G_M_S2)
        drum = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        space.add(drum)
        add_wall(space, self.drum.radius_m, self._r_min)
        for poly in self.baffle_polygons_m(0.0):
            space.add(pymunk.Poly(drum, [tuple(p) for p in poly], radius=0.0))
        bodies = []
        self._shapes_of: list[list[pymunk.Shape]] = []  # each body's shapes in piece order (inflation)
        for i in range(self._cls.size):
            k = int(self._cls[i])
            body, shapes = particle_body(self.mixer.particles[k].shape, float(self._mass_cls[k]),
                                         float(self._moment_cls[k]), (float(pos[i, 0]), float(pos[i, 1])),
                                         float(angles[i]), SHRINK)
            space.add(body, *shapes)
            self._shapes_of.append(shapes)
            bodies.append(body)
        self._install(space, drum, bodies)
        self._scale_shapes(SHRINK)

    def _install(self, space: pymunk.Space, drum: pymunk.Body, bodies: list[pymunk.Body]) -> None:
        """Use this space: solver settings, contact coefficients, the batch order of the bodies."""
        solver_settings(space, self.iterations, self._r_min)
        self._space, self._drum, self._bodies = space, drum, bodies
        self._batch_of, self._id_keys, self._id_part, n_rows = batch_index(space, drum, bodies)
        # the wall's segments and their tangential speed per rad/s of the drum (m/rad): w x p at the midpoint
        self._wall = tuple(space.static_body.shapes)
        self._wall_tang = wall_tangents(self._wall, self.drum.radius_m)
        self._wall_w = math.nan  # the drum speed the wall's surface velocity is set for (rad/s)
        self._abuf = pbatch.Buffer()
        self._bbuf = pbatch.Buffer()
        self._vel_rows = np.zeros((n_rows, 3))  # vx, vy, omega per batch row, written back after a step
        self._sbuf = pbatch.Buffer()
        self._sbuf.set_float_buf(self._vel_rows)
        self._no_rows = np.zeros((0, 5))
        self._acc_stats = np.zeros(5)  # one step's contacts, max overlap (small radii), max wall depth (m), airborne,
        # and the angular impulse of rolling and end-plate friction on the drum (N m s, counter-clockwise)
        self._params_changed()

    def _scale_shapes(self, scale: float) -> None:
        """Set every particle's shapes to ``scale`` times full size (inflation)."""
        for i, shapes in enumerate(self._shapes_of):
            scale_particle(shapes, self.mixer.particles[int(self._cls[i])].shape, bool(self._round[i]), scale)

    def baffle_polygons_m(self, drum_angle_rad: float | None = None) -> list[np.ndarray]:
        """The baffles as (4, 2) polygons (m, drum frame) at the drum's angle (now, if None)."""
        ang = self._drum.angle if drum_angle_rad is None else drum_angle_rad
        return baffle_polygons_m(self.mixer.baffles, self.drum.radius_m, self._r_min, ang)

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
        set_coefficients(self.params, (*self._wall, *self._drum.shapes), self._bodies)

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
        (``post_step``, compiled: one batch read of the contacts, one of the bodies, one write)."""
        ab = self._abuf
        ab.clear()
        pbatch.get_space_arbiters(self._space, ARBITER_FIELDS, ab)
        ints = np.frombuffer(ab.int_buf(), dtype=np.int64).reshape(-1, 3)  # addresses: below 2**63
        fl = np.frombuffer(ab.float_buf(), dtype=np.float64).reshape(-1, 7)
        friction = ints.shape[0] > 0 and (end_k > 0.0 or mu_r > 0.0)
        if friction:
            bb = self._bbuf
            bb.clear()
            pbatch.get_space_bodies(self._space, BODY_FIELDS, bb)
            rows = np.frombuffer(bb.float_buf(), dtype=np.float64).reshape(-1, 5)
        else:
            rows = self._no_rows
        acc = self._acc_stats
        write = post_step(ints, fl, self._id_keys, self._id_part, self._batch_of, rows, self._vel_rows,
                          self._round_x, self._inv_m_x, self._inv_i_x, self._r_x, self._r_over_m, h, w_drum,
                          end_k, mu_r, 1.0 / self._r_min, self._hist, acc)
        self._stat_steps += 1
        self._contacts += int(acc[0])
        self._ov_max = max(self._ov_max, float(acc[1]))
        self._wall_max = max(self._wall_max, float(acc[2]))
        self._airborne = float(acc[3])
        if write and friction:
            pbatch.set_space_bodies(self._space, VELOCITY_FIELDS, self._sbuf)

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
        self._hist = np.zeros(OVERLAP_BINS + 1, dtype=np.int64)
        self._ov_max = 0.0
        self._wall_max = 0.0
        self._contacts = 0
        self._stat_steps = 0
        self._airborne = float("nan")

    def stats(self) -> ContactStats:
        """Overlap percentiles (small radii), wall penetration (mm) and airborne fraction since ``reset_stats``."""
        p99 = overlap_p99_r(self._hist, self._ov_max)
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
        tq = contact_impulse_moment(self._space, self._drum)
        return self.mixer.direction * (tq + float(self._acc_stats[4])) / self.substep_s()

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


__all__ = [
    "DEFAULT_DT_S",
    "DEFAULT_ITERATIONS",
    "ROUND_BED_DT_S",
    "PymunkDrumSim",
    "PymunkState",
    "default_dt_s",
]

"""The 2D physics twin: a soft-sphere DEM slice of the rotating drum.

Frame: origin at the drum axis, x to the right, y up (as the camera sees the front
face, before the renderer flips y for the image). Positive rpm turns the drum
counter-clockwise as seen by the camera, so the bed climbs the right-hand wall
and its free surface rises to the right (positive slope angle) -- for a twin of a
``sim.mixer.Mixer`` (``mixer=``), the mixer's ``direction``: -1 turns it clockwise at
positive rpm (``rpm_actual``/``rpm_target`` are the mixer's; ``SimState`` keeps the DEM's sign).

Model (the compiled step loop and its contact laws are in ``sim.dem``):

* **Wall**: the drum is the exact circle of radius ``R``, a rigid boundary turning
  at ``rpm_actual``, which follows ``set_rpm`` at the mill's acceleration limit.
* **Particles**: disks of equal mass per area (a slab ``4/3 r_max`` thick, so the
  large disk weighs what its ball weighs) with a ball's moment ``I = 2/5 m r^2``.
* **Contacts**: linear spring-dashpot normal force (stiffness ``stiffness_n_m``,
  damping from the ``restitution``), Cundall-Strack tangential spring capped by
  Coulomb sliding ``friction`` (particle-particle, and particle-wall unless
  ``wall_friction`` is given), and contact **rolling friction** ``rolling`` (mu_r):
  a torque ``mu_r r_eff F_n`` against the contact's relative rotation, capped so it
  cannot reverse it within a step (the "constant directional torque" model). No
  contact, no torque: a disk in free flight keeps its spin.
* **End plates**: the drum's two end walls (``DrumSpec.depth_m`` apart) brake each disk by
  ``end_friction r sum(F_n) / depth`` against its motion relative to them (``end_friction``
  None: the wall friction; 0: no end plates).
* **Time step**: one fixed internal step ``dt_s``, by default a fixed fraction of the
  contact time (the same for every pair; ``STEPS_PER_CONTACT`` steps per contact; the
  convergence study in docs/validation.md), independent of how the caller slices
  time: ``advance(d)`` adds ``d`` to an accumulator and runs whole steps in one
  compiled call; the remainder (< one step) waits for the next call.

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

from sim import dem, dem_contact, dem_neighbours
from sim.errors import SimError
from sim.mixer import Mixer, disk_classes
from sim.params import (
    CASES,
    DEFAULT_ACCEL_RPM_S,
    DEFAULT_END_FRICTION,
    DEFAULT_FRICTION,
    DEFAULT_RESTITUTION,
    DEFAULT_ROLLING,
    DEFAULT_STIFFNESS_N_M,
    DEFAULT_WALL_FRICTION,
    SimParams,
    check_params,
    check_rpm,
)
from sim.placement import SHRINK, place_random
from sim.recipe import G_M_S2, PAPER_DRUM, PAPER_RECIPE, DiskClass, DrumSpec, Recipe, slice_2d
from sim.twin_base import OVERLAP_BINS, ContactStats, FixedStepTwin, Particles, overlap_p99_r

STEPS_PER_CONTACT = 8  # default step = the contact time (every pair's) / this: converged over the calibration box
MIN_STEPS_PER_CONTACT = 3  # a longer step is unstable (symplectic Euler: omega_0 dt < ~1.5)
SKIN_R = 0.4  # Verlet skin, in small radii
SORT_EVERY = 1000  # steps between spatial re-sorts of the disks in memory
_SETTLE_DAMP_S = 2.0  # velocity damping rate while settling, 1/s
_INFLATE_S = 0.1  # time to inflate the disks from placement size to full size


def _slab_m(classes) -> float:
    return 4.0 / 3.0 * max(c.radius_m for c in classes)


def bed_contact_time_s(classes, stiffness_n_m: float, restitution: float) -> float:
    """Contact time (s) of the bed's contacts: the lightest disk pair's, which every pair shares
    (``sim.dem_contact.contact_tables``)."""
    slab = _slab_m(classes)
    m = min(c.mass_kg(slab) for c in classes)
    return dem_contact.contact_time_s(stiffness_n_m, 0.5 * m, restitution)


def default_dt_s(classes, stiffness_n_m: float = DEFAULT_STIFFNESS_N_M,
                 restitution: float = DEFAULT_RESTITUTION) -> float:
    """The default step (s): the bed's contact time over ``STEPS_PER_CONTACT``."""
    return bed_contact_time_s(classes, stiffness_n_m, restitution) / STEPS_PER_CONTACT


DEFAULT_DT_S = default_dt_s(slice_2d(PAPER_RECIPE, PAPER_DRUM))  # the paper bed's step


@dataclass(frozen=True)
class SimState:
    """Everything needed to rebuild a running twin (picklable; sent to what-if workers)."""

    drum: DrumSpec
    recipe: Recipe | None  # the 3D recipe sliced into ``classes``; None when built from a ``mixer``
    classes: tuple[DiskClass, ...]
    case: str
    seed: int
    params: SimParams
    t_s: float
    rpm_target: float  # the DEM's own sign (counter-clockwise positive; ``DrumSim.rpm_target`` is the mixer's)
    rpm_actual: float  # the same sign as ``rpm_target``
    drum_angle_rad: float
    cls: np.ndarray
    pos_m: np.ndarray  # (n, 2)
    vel_m_s: np.ndarray  # (n, 2)
    angle_rad: np.ndarray
    omega_rad_s: np.ndarray
    n_steps: int = 0
    extra: dict = field(default_factory=dict)
    mixer: Mixer | None = None  # the user's mixer the twin was built from (None: ``drum`` + ``recipe``)

    @property
    def direction(self) -> int:
        """+1: the drum turns counter-clockwise as the camera sees it at positive rpm, -1 clockwise."""
        return 1 if self.mixer is None else int(self.mixer.direction)


class DrumSim(FixedStepTwin):
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
        dt_s: float | None = None,
        stiffness_n_m: float = DEFAULT_STIFFNESS_N_M,
        end_friction: float | None = DEFAULT_END_FRICTION,
        settle_s: float = 1.0,
        mixer: Mixer | None = None,
    ) -> None:
        """``mixer``: the user's mixer (all classes round; its drum, discs and rotation direction
        replace ``drum`` and ``recipe``); positive ``rpm`` then turns the drum the mixer's way."""
        case = str(case).upper()
        if case not in CASES:
            raise SimError(f"case must be one of {', '.join(CASES)} (got {case!r})")
        params = SimParams(float(friction), float(rolling), float(restitution),
                           None if wall_friction is None else float(wall_friction),
                           float(accel_rpm_s), None if dt_s is None else float(dt_s), float(stiffness_n_m),
                           None if end_friction is None else float(end_friction))
        check_params(params)
        if mixer is not None:
            drum, recipe_used, classes = mixer.drum, None, disk_classes(mixer)
        else:
            recipe_used, classes = recipe, tuple(slice_2d(recipe, drum))
        rpm = check_rpm(rpm, drum)
        rng = np.random.default_rng(seed)
        pos, cls = place_random(classes, case, drum.radius_m, rng)
        n = cls.size
        state = SimState(
            drum=drum, recipe=recipe_used, classes=classes, case=case, seed=int(seed), params=params,
            t_s=0.0, rpm_target=0.0, rpm_actual=0.0, drum_angle_rad=0.0, cls=cls, pos_m=pos,
            vel_m_s=np.zeros((n, 2)), angle_rad=rng.uniform(0, 2 * math.pi, n), omega_rad_s=np.zeros(n),
            mixer=mixer,
        )
        self._start(state, rpm, 0.0 if case == "B" else settle_s)

    @classmethod
    def from_placement(cls, state: SimState, rpm: float, settle_s: float) -> DrumSim:
        """A twin from disks placed at ``SHRINK`` size (``state``): inflated, settled for
        ``settle_s`` with the drum at rest, then started at ``rpm`` (what ``__init__`` does)."""
        sim = cls.__new__(cls)
        sim._start(state, check_rpm(rpm, state.drum), settle_s)
        return sim

    def _start(self, state: SimState, rpm: float, settle_s: float) -> None:
        self._build(state, radius_scale=SHRINK)
        self._settle(settle_s)
        self.t_s = 0.0
        self.n_steps = 0
        self._acc_s = 0.0
        self._sort()
        self.reset_stats()
        self._ds[dem.DS_TARGET] = self.direction * rpm
        self._ds[dem.DS_RPM] = self.direction * rpm  # the drum starts at full speed

    # ----------------------------------------------------------------- build
    def _build(self, st: SimState, radius_scale: float = 1.0) -> None:
        self.drum = st.drum
        self.recipe = st.recipe
        self.mixer = st.mixer
        self.direction = st.direction
        self.classes = st.classes
        self.case = st.case
        self.seed = st.seed
        params = st.params
        t_c = bed_contact_time_s(st.classes, params.stiffness_n_m, params.restitution)
        if params.dt_s is None:
            params = replace(params, dt_s=t_c / STEPS_PER_CONTACT)
        check_params(params)
        assert params.dt_s is not None
        if params.dt_s > t_c / MIN_STEPS_PER_CONTACT:
            raise SimError(
                f"time step {params.dt_s * 1e3:g} ms is too long for this bed's contacts, which last "
                f"{t_c * 1e3:.2f} ms: at most {t_c / MIN_STEPS_PER_CONTACT * 1e3:.3f} ms"
            )
        self.params = params
        self.t_s = float(st.t_s)
        self.n_steps = int(st.n_steps)
        self._acc_s = float(st.extra.get("acc_s", 0.0))
        # disks are stored in a spatial order (``_perm``: internal index -> disk), re-sorted every
        # ``SORT_EVERY`` steps for memory locality; the public arrays are in the disks' own order
        n = int(np.asarray(st.cls).size)
        self._perm = np.asarray(st.extra.get("order", np.arange(n)), dtype=np.int64).copy()
        self._inv_perm = np.argsort(self._perm)
        p = self._perm
        self._cls = np.ascontiguousarray(np.asarray(st.cls, dtype=np.int64)[p])
        self._r = np.array([st.classes[k].radius_m for k in self._cls], dtype=np.float64)
        self._rad = self._r * radius_scale  # the radii the contacts see (smaller while inflating)
        self._r_min = min(c.radius_m for c in st.classes)
        slab = _slab_m(st.classes)
        self._cls_mass = np.array([c.mass_kg(slab) for c in st.classes])
        self._set_masses()
        self._pos = np.array(st.pos_m, dtype=np.float64).reshape(-1, 2)[p]
        self._vel = np.array(st.vel_m_s, dtype=np.float64).reshape(-1, 2)[p]
        self._ang = np.array(st.angle_rad, dtype=np.float64)[p]
        self._omg = np.array(st.omega_rad_s, dtype=np.float64)[p]
        self._ds = np.array([st.rpm_actual, st.rpm_target, st.drum_angle_rad], dtype=np.float64)
        self._skin = SKIN_R * self._r_min
        cap = n * self._list_slots()
        self._nb_start = np.zeros(n + 1, dtype=np.int64)
        self._nb_j = np.zeros(cap, dtype=np.int64)
        self._nb_xi = np.zeros(cap)
        self._ref = np.zeros((n, 2))
        self._wall_xi = np.zeros(n)
        self._ncont = np.zeros(n, dtype=np.int64)
        springs = st.extra.get("springs")
        if springs is not None:  # the contacts' tangential springs: disk pairs, xi, the wall's (disk order)
            pairs, xis, wall_xi = springs
            self._wall_xi[:] = np.asarray(wall_xi, dtype=np.float64)[p]
            self._set_springs(self._inv_perm[np.asarray(pairs, dtype=np.int64).reshape(-1, 2)], np.asarray(xis))
        self._rebuild = True
        self._set_prm()
        if not hasattr(self, "_hist"):
            self.reset_stats()

    def _set_prm(self, gravity: bool = True, damp_s: float = 0.0) -> None:
        p = self.params
        assert p.dt_s is not None
        prm = np.zeros(dem.P_N)
        prm[dem.P_DT] = p.dt_s
        prm[dem.P_MU] = p.friction
        prm[dem.P_MU_W] = p.wall_mu
        prm[dem.P_MU_R] = p.rolling
        prm[dem.P_G] = G_M_S2 if gravity else 0.0
        prm[dem.P_R] = self.drum.radius_m
        prm[dem.P_SKIN] = self._skin
        prm[dem.P_DAMP] = damp_s
        prm[dem.P_ACCEL] = p.accel_rpm_s
        prm[dem.P_RMIN] = self._r_min
        prm[dem.P_END] = p.end_mu / self.drum.depth_m
        self._prm = prm
        self._c_pair, self._c_wall = dem_contact.contact_tables(
            self._cls_mass, np.array([c.radius_m for c in self.classes]), p.stiffness_n_m, p.restitution)

    def _list_slots(self) -> int:
        """Neighbour-list slots per disk for the widest skin ``dem_neighbours.list_skin`` may choose."""
        widest = max(self._skin, dem_neighbours.SKIN_MAX_R * self._r_min)
        return dem_neighbours.neighbour_slots(float(self._r.max()), self._r_min, widest)

    def _set_masses(self) -> None:
        self._masses = self._cls_mass[self._cls]
        self._inv_m = 1.0 / self._masses
        self._inv_i = 1.0 / (0.4 * self._masses * self._r**2)

    def _springs(self) -> tuple[np.ndarray, np.ndarray]:
        """The listed pairs with a tangential spring: (m, 2) internal indices (i < j) and xi (m)."""
        m = int(self._nb_start[-1])
        rows = np.repeat(np.arange(self._cls.size), np.diff(self._nb_start))
        keep = self._nb_xi[:m] != 0.0
        return np.column_stack([rows[keep], self._nb_j[:m][keep]]), self._nb_xi[:m][keep].copy()

    def _set_springs(self, pairs: np.ndarray, xis: np.ndarray) -> None:
        """Load springs of internal pairs (either orientation: a pair's spring does not depend on it)."""
        pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
        order = np.lexsort((pairs[:, 1], pairs[:, 0]))
        pairs, xis = pairs[order], np.asarray(xis, dtype=np.float64)[order]
        n = self._cls.size
        if len(pairs) > self._nb_j.size:
            self._nb_j = np.zeros(2 * len(pairs), dtype=np.int64)
            self._nb_xi = np.zeros(2 * len(pairs))
        self._nb_start[0] = 0
        self._nb_start[1:] = np.cumsum(np.bincount(pairs[:, 0], minlength=n))
        self._nb_j[: len(pairs)] = pairs[:, 1]
        self._nb_xi[: len(pairs)] = xis
        self._rebuild = True

    def _sort(self) -> None:
        """Re-order the disks in memory along the cells of the neighbour grid (locality of the contact loop)."""
        cs = 2.0 * float(self._r.max()) + self._skin
        r = self.drum.radius_m
        nc = int(2.0 * r / cs) + 2
        cell = np.clip(((self._pos + r) / cs).astype(np.int64), 0, nc - 1)
        order = np.argsort(cell[:, 1] * nc + cell[:, 0], kind="stable")
        pairs, xis = self._springs()
        inv = np.empty_like(order)
        inv[order] = np.arange(order.size)
        for name in ("_cls", "_r", "_rad", "_pos", "_vel", "_ang", "_omg", "_wall_xi", "_ncont", "_ref", "_perm"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name)[order]))
        self._inv_perm = np.argsort(self._perm)
        self._set_masses()
        self._set_springs(inv[pairs], xis)

    def _run(self, n_steps: int, count: bool = True) -> None:
        """``n_steps`` fixed steps in the compiled loop; with ``count`` they are the twin's own steps
        (``n_steps`` counts them, and every ``SORT_EVERY`` of them the disks are re-sorted)."""
        while n_steps > 0:
            chunk = min(n_steps, SORT_EVERY - self.n_steps % SORT_EVERY) if count else n_steps
            self._run_steps(chunk)
            n_steps -= chunk
            if count:
                self.n_steps += chunk
                if self.n_steps % SORT_EVERY == 0:
                    self._sort()

    def _run_steps(self, n_steps: int) -> None:
        """``n_steps`` steps of ``dem.run`` (the neighbour list grows if it must)."""
        while n_steps > 0:
            done = dem.run(n_steps, self._prm, self._ds, self._pos, self._vel, self._ang, self._omg, self._rad,
                           self._cls, self._inv_m, self._inv_i, self._c_pair, self._c_wall, self._nb_start,
                           self._nb_j, self._nb_xi, self._wall_xi, self._ref, self._rebuild, self._hist, self._acc,
                           self._ncont)
            self._rebuild = False
            self._stat_steps += done
            n_steps -= done
            if n_steps > 0:  # the neighbour list did not fit: more room, same rows
                n = self._cls.size
                if self._nb_j.size > 16 * n * self._list_slots():
                    raise SimError("the bed has blown up (disks pile into each other): lower the step")
                self._nb_j = np.concatenate([self._nb_j, np.zeros_like(self._nb_j)])
                self._nb_xi = np.concatenate([self._nb_xi, np.zeros_like(self._nb_xi)])
                self._rebuild = True

    def _settle(self, settle_s: float) -> None:
        """Inflate the disks to full size (no gravity), then let the bed settle with the drum at rest."""
        h = self.params.dt_s
        assert h is not None
        n_grow = 20
        per = max(1, int(round(_INFLATE_S / n_grow / h)))
        self._set_prm(gravity=False, damp_s=10 * _SETTLE_DAMP_S)
        for j in range(n_grow):
            self._rad = self._r * (SHRINK + (1.0 - SHRINK) * (j + 1) / n_grow)
            self._rebuild = True
            self._run(per, count=False)
        self._rad = self._r.copy()
        self._set_prm(gravity=True, damp_s=_SETTLE_DAMP_S)
        self._run(int(round(settle_s / h)), count=False)
        self._set_prm()
        self._vel[:] = 0.0
        self._omg[:] = 0.0

    # ------------------------------------------------------------- controls
    @property
    def rpm_actual(self) -> float:
        """Drum speed now (rpm, positive: the mixer's direction), following the setpoint at the
        acceleration limit."""
        return self.direction * float(self._ds[dem.DS_RPM])

    @property
    def rpm_target(self) -> float:
        """The rpm setpoint (positive: the mixer's direction)."""
        return self.direction * float(self._ds[dem.DS_TARGET])

    @property
    def critical_rpm(self) -> float:
        """Critical speed of this drum (rpm), ``DrumSpec.critical_rpm``."""
        return self.drum.critical_rpm

    def set_rpm(self, rpm: float) -> None:
        """New rpm setpoint; the drum ramps to it at ``accel_rpm_s``. Above critical speed: SimError."""
        self._ds[dem.DS_TARGET] = self.direction * check_rpm(rpm, self.drum)

    def _params_changed(self) -> None:
        self._set_prm()

    # ------------------------------------------------------------ statistics
    def reset_stats(self) -> None:
        """Start counting contact statistics (``stats()``) afresh."""
        self._hist = np.zeros(OVERLAP_BINS + 1, dtype=np.int64)
        self._acc = np.zeros(dem.ACC_N)
        self._acc[dem.ACC_AIRBORNE] = np.nan
        self._stat_steps = 0

    def stats(self) -> ContactStats:
        """Overlap percentiles, wall penetration and airborne fraction since ``reset_stats()``."""
        acc = self._acc
        p99 = overlap_p99_r(self._hist, float(acc[dem.ACC_OVERLAP_MAX]))
        return ContactStats(self._stat_steps, int(acc[dem.ACC_CONTACTS]), float(p99),
                            float(acc[dem.ACC_OVERLAP_MAX]), 1e3 * float(acc[dem.ACC_WALL_MAX]),
                            float(acc[dem.ACC_AIRBORNE]))

    def drum_torque_nm(self) -> float:
        """Torque of the bed on the drum about its axis (N m, the 2D slice as simulated), the mean over
        the steps since the last call (or ``reset_stats``); positive in the sense the drum turns at
        positive rpm, so a bed that the drum lifts gives a negative mean. Wall contacts (tangential
        force x R, rolling friction) and end-plate friction (``sim.dem``); NaN if no step ran."""
        acc = self._acc
        steps = float(acc[dem.ACC_TORQUE_STEPS])
        mean = self.direction * float(acc[dem.ACC_TORQUE]) / steps if steps > 0 else float("nan")
        acc[dem.ACC_TORQUE] = 0.0
        acc[dem.ACC_TORQUE_STEPS] = 0.0
        return mean

    def contact_counts(self) -> np.ndarray:
        """Number of contacts (with disks or the wall) of each disk in the last step."""
        return self._ncont[self._inv_perm]

    # ----------------------------------------------------------------- read
    def particles(self) -> Particles:
        """Positions (m), radii (m), classes of all disks now."""
        q = self._inv_perm
        return Particles(
            x_m=self._pos[q, 0], y_m=self._pos[q, 1], r_m=self._r[q], cls=self._cls[q],
            angle_rad=self._ang[q], class_names=tuple(c.name for c in self.classes),
            class_bgr=tuple(c.colour_bgr for c in self.classes),
        )

    def kinetic_energy_j(self) -> float:
        """Translational kinetic energy of the disks (J)."""
        return float(0.5 * np.sum(self._masses * (self._vel[:, 0] ** 2 + self._vel[:, 1] ** 2)))

    def snapshot(self) -> SimState:
        """The whole state now (arrays are copies), contact springs included: every
        ``restore``/``from_state`` of it continues bit-identically to this twin."""
        pairs, xis = self._springs()
        q = self._inv_perm
        return SimState(
            drum=self.drum, recipe=self.recipe, classes=self.classes, case=self.case, seed=self.seed,
            params=self.params, t_s=self.t_s, rpm_target=float(self._ds[dem.DS_TARGET]),
            rpm_actual=float(self._ds[dem.DS_RPM]),
            drum_angle_rad=float(self._ds[dem.DS_ANGLE]), cls=self._cls[q], pos_m=self._pos[q],
            vel_m_s=self._vel[q], angle_rad=self._ang[q], omega_rad_s=self._omg[q], n_steps=self.n_steps,
            extra={"acc_s": self._acc_s, "springs": (self._perm[pairs], xis, self._wall_xi[q]),
                   "order": self._perm.copy()},
            mixer=self.mixer,
        )

    def restore(self, state: SimState) -> None:
        """Go back to ``state`` (bit-identical continuation)."""
        self._build(state)


__all__ = [
    "DEFAULT_DT_S",
    "MIN_STEPS_PER_CONTACT",
    "STEPS_PER_CONTACT",
    "DrumSim",
    "SimState",
    "bed_contact_time_s",
    "default_dt_s",
]

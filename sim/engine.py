"""One twin interface, two engines: the compiled DEM (``sim.drum.DrumSim``) for round
particles in a plain round drum, pymunk (``sim.pymunk_twin.PymunkDrumSim``) for any shape
and for baffles.

``Twin`` is the interface ``DrumSim`` has (and the pymunk engine implements): a fixed
internal step independent of how the caller slices time (``advance``), the particles
now, bit-exact ``snapshot``/``restore``/``from_state``, the rpm setpoint and the drum's
actual speed, run-time friction, contact statistics. ``make_twin`` builds the one the
mixer needs (``engine_for``), or the one asked for.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol, runtime_checkable

from sim.errors import SimError
from sim.mixer import Mixer
from sim.recipe import DrumSpec

ENGINES: tuple[str, ...] = ("dem", "pymunk")

__all__ = ["ENGINES", "Twin", "check_engine", "engine_for", "from_placement", "from_state", "make_twin", "twin_class"]


@runtime_checkable
class Twin(Protocol):
    """What every engine of the twin offers (units: s, rpm, m; positive rpm turns the drum in
    the mixer's ``direction``)."""

    t_s: float
    n_steps: int
    mixer: Mixer | None

    @property
    def drum(self) -> DrumSpec:
        """The drum (diameter, depth)."""
        ...

    @property
    def rpm_actual(self) -> float:
        """Drum speed now (rpm)."""
        ...

    @property
    def rpm_target(self) -> float:
        """The rpm setpoint."""
        ...

    @property
    def critical_rpm(self) -> float:
        """Critical (centrifuging) speed of the drum (rpm)."""
        ...

    def advance(self, duration_s: float) -> None:
        """Advance the clock by ``duration_s`` s in whole fixed internal steps (the rest carries over)."""
        ...

    def step(self, dt_s: float) -> None:
        """``advance`` for a positive ``dt_s``."""
        ...

    def substep_s(self) -> float:
        """The fixed internal step (s)."""
        ...

    def set_rpm(self, rpm: float) -> None:
        """New setpoint; the drum ramps to it at the acceleration limit. Above critical: SimError."""
        ...

    def set_friction(self, mu: float, rolling: float | None = None) -> None:
        """Sliding (and rolling) friction at run time."""
        ...

    def particles(self) -> Any:
        """Positions (m, drum frame, y up), radii, classes and angles now (``sim.twin_base.Particles``)."""
        ...

    def snapshot(self) -> Any:
        """The whole state (picklable); ``restore``/``from_state`` of it continue bit-identically."""
        ...

    def restore(self, state: Any) -> None:
        """Go back to ``state``."""
        ...

    def stats(self) -> Any:
        """Contact statistics since ``reset_stats`` (``sim.twin_base.ContactStats``)."""
        ...

    def reset_stats(self) -> None:
        """Start the contact statistics afresh."""
        ...

    def kinetic_energy_j(self) -> float:
        """Translational kinetic energy of the particles (J)."""
        ...

    def drum_torque_nm(self) -> float:
        """Torque of the bed on the drum about its axis (N m, the 2D slice as simulated; positive in the
        sense the drum turns at positive rpm, so negative while it lifts the bed): the DEM's mean over
        the steps since the last call (wall, rolling friction at the wall, end plates); pymunk's the
        last step's (wall and baffles). ``sim.power`` scales it to the drum and makes it a power."""
        ...


def check_engine(engine: str | None) -> str | None:
    """``engine`` if it is None or one of ``ENGINES``, else a one-line SimError."""
    if engine is not None and engine not in ENGINES:
        raise SimError(f"engine must be one of {', '.join(ENGINES)} (got {engine!r})")
    return engine


def engine_for(mixer: Mixer, engine: str | None = None) -> str:
    """The engine that runs ``mixer``: ``engine`` if given (the DEM only for round particles in a
    drum without baffles: else a one-line SimError), else "dem" when ``mixer.all_round``, else "pymunk"."""
    check_engine(engine)
    if engine is None:
        return "dem" if mixer.all_round else "pymunk"
    if engine == "dem" and not mixer.all_round:
        what = "baffles" if mixer.baffles is not None else "particles that are not discs"
        raise SimError(f"the compiled DEM cannot run a mixer with {what}: use --engine pymunk")
    return engine


def twin_class(engine: str) -> Any:
    """The class of an engine ("dem": ``DrumSim``; "pymunk": ``PymunkDrumSim``, imported lazily)."""
    check_engine(engine)
    if engine == "dem":
        from sim.drum import DrumSim

        return DrumSim
    try:
        mod = importlib.import_module("sim.pymunk_twin")
    except ModuleNotFoundError as exc:
        if exc.name == "sim.pymunk_twin":
            raise SimError("the pymunk engine is not in this build (sim/pymunk_twin.py is missing)") from None
        raise SimError(f"the pymunk engine cannot start: {exc}") from None
    return mod.PymunkDrumSim


def make_twin(
    mixer: Mixer,
    engine: str | None = None,
    *,
    case: str = "C",
    seed: int = 0,
    rpm: float = 5.0,
    friction: float | None = None,
    rolling: float | None = None,
    **kwargs: Any,
) -> Twin:
    """A fresh twin of ``mixer`` on ``engine`` (``engine_for``): placed by ``case`` (A/B/C) from
    ``seed``, turning at ``rpm``; ``friction``/``rolling`` None: the mixer's calibrated friction
    (``mixer.friction``), else the engine's defaults. ``kwargs`` go to the engine (e.g. ``settle_s``,
    ``dt_s``, ``end_friction``)."""
    name = engine_for(mixer, engine)
    cls = twin_class(name)
    friction, rolling = _calibrated(mixer, friction, rolling, kwargs)
    if friction is not None:
        kwargs["friction"] = float(friction)
    if rolling is not None:
        kwargs["rolling"] = float(rolling)
    twin: Twin = cls(case=case, seed=seed, rpm=rpm, mixer=mixer, **kwargs)
    return twin


def _calibrated(mixer: Mixer, friction: float | None, rolling: float | None,
                kwargs: dict[str, Any]) -> tuple[float | None, float | None]:
    """The friction a twin of ``mixer`` takes: what the caller gave, else the mixer's calibrated
    (``mixer.friction``; its end plates' into ``kwargs`` unless given there)."""
    cal = mixer.friction
    if cal is None:
        return friction, rolling
    if cal.end_plates is not None:
        kwargs.setdefault("end_friction", cal.end_plates)
    return (cal.sliding if friction is None else friction), (cal.rolling if rolling is None else rolling)


def from_state(state: Any) -> Twin:
    """A twin that continues from ``state`` on the engine that made it."""
    from sim.drum import DrumSim, SimState

    if isinstance(state, SimState):
        return DrumSim.from_state(state)
    twin: Twin = twin_class("pymunk").from_state(state)
    return twin


def from_placement(
    mixer: Mixer,
    pos_m: Any,
    classes: Any,
    angle_rad: Any,
    rpm: float,
    settle_s: float = 0.3,
    *,
    engine: str | None = None,
    seed: int = 0,
    friction: float | None = None,
    rolling: float | None = None,
    end_friction: float | None = None,
) -> Twin:
    """A twin of ``mixer`` on ``engine`` (``engine_for``) whose particles the caller placed
    (``sim.from_image``: where the camera sees each class): centres ``pos_m`` (n, 2; m, drum frame)
    at the engines' placement size (``sim.placement.SHRINK``) without overlaps, class indices
    ``classes`` (n,), angles ``angle_rad`` (n,; rad); inflated, settled for ``settle_s`` with the
    drum at rest and started at ``rpm``, as a fresh twin is. ``friction``/``rolling``/``end_friction``
    None: the mixer's (``[drum.friction]``), else the engines' defaults (the plates: the wall's)."""
    import numpy as np

    from sim.drum import DrumSim, SimState
    from sim.params import SimParams, check_params

    name = engine_for(mixer, engine)
    base = SimParams()
    ends: dict[str, Any] = {} if end_friction is None else {"end_friction": end_friction}
    friction, rolling = _calibrated(mixer, friction, rolling, ends)
    params = SimParams(friction=base.friction if friction is None else float(friction),
                       rolling=base.rolling if rolling is None else float(rolling),
                       end_friction=ends.get("end_friction", base.end_friction))
    check_params(params)
    if name == "pymunk":
        twin: Twin = twin_class(name).from_placement(mixer, pos_m, classes, angle_rad, rpm, settle_s, seed=int(seed),
                                                     friction=params.friction, rolling=params.rolling,
                                                     end_friction=params.end_friction)
        return twin
    from sim.mixer import disk_classes

    cls = np.asarray(classes, dtype=np.int64)
    n = cls.size
    state = SimState(
        drum=mixer.drum, recipe=None, classes=disk_classes(mixer), case="image", seed=int(seed), params=params,
        t_s=0.0, rpm_target=0.0, rpm_actual=0.0, drum_angle_rad=0.0, cls=cls,
        pos_m=np.asarray(pos_m, dtype=np.float64), vel_m_s=np.zeros((n, 2)),
        angle_rad=np.asarray(angle_rad, dtype=np.float64), omega_rad_s=np.zeros(n), mixer=mixer,
    )
    return DrumSim.from_placement(state, rpm, settle_s)  # same construction as DrumSim.__init__

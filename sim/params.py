"""The contact and integration parameters both twin engines take (``sim.drum.DrumSim``, the
pymunk twin): the defaults (the paper's materials), ``SimParams`` and its checks, the rpm's check.

One definition of each: the engines, calibration, the what-if studies and the CLI import them
from here. Units: friction coefficients dimensionless, rpm, s, N/m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.errors import SimError
from sim.recipe import DrumSpec

CASES = ("A", "B", "C")
# The paper's Hertz-Mindlin parameters (tables 1-2, ball-ball = ball-vessel) are the defaults.
PAPER_CONTACT = {"friction": 0.25, "rolling": 0.10, "restitution": 0.5}
DEFAULT_FRICTION = PAPER_CONTACT["friction"]  # particle-particle sliding friction
DEFAULT_WALL_FRICTION: float | None = None  # particle-wall: None = same as particle-particle
DEFAULT_END_FRICTION: float | None = None  # particle-end plate: None = same as particle-wall
DEFAULT_ROLLING = PAPER_CONTACT["rolling"]  # rolling friction coefficient mu_r (torque mu_r r_eff F_n)
DEFAULT_RESTITUTION = PAPER_CONTACT["restitution"]
DEFAULT_ACCEL_RPM_S = 20.0  # mill acceleration limit
MIN_RESTITUTION = 0.05  # below, the dashpot is so strong that contacts (and steps) become very short
DEFAULT_STIFFNESS_N_M = 2800.0  # normal stiffness of the lightest pair (docs/validation.md, section 2)


@dataclass(frozen=True)
class SimParams:
    """Contact and integration parameters of the twin (the knobs calibration turns: friction, rolling).

    ``dt_s`` None: the default step of the bed (``default_dt_s``), resolved when the twin is built.
    """

    friction: float = DEFAULT_FRICTION
    rolling: float = DEFAULT_ROLLING
    restitution: float = DEFAULT_RESTITUTION
    wall_friction: float | None = DEFAULT_WALL_FRICTION  # None: same as ``friction``
    accel_rpm_s: float = DEFAULT_ACCEL_RPM_S
    dt_s: float | None = None
    stiffness_n_m: float = DEFAULT_STIFFNESS_N_M
    end_friction: float | None = DEFAULT_END_FRICTION  # None: same as the wall; 0: no end plates

    @property
    def wall_mu(self) -> float:
        """Particle-wall sliding friction in effect (``wall_friction``, else ``friction``)."""
        return self.friction if self.wall_friction is None else self.wall_friction

    @property
    def end_mu(self) -> float:
        """Friction of the drum's end plates in effect (``end_friction``, else the wall's)."""
        return self.wall_mu if self.end_friction is None else self.end_friction



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


def check_params(p: SimParams) -> None:
    """SimError (one line) for a parameter outside its range."""
    if not (0.0 <= p.friction <= 5.0) or not math.isfinite(p.friction):
        raise SimError(f"friction must be in [0, 5] (got {p.friction})")
    if not (0.0 <= p.rolling <= 5.0) or not math.isfinite(p.rolling):
        raise SimError(f"rolling resistance must be in [0, 5] (got {p.rolling})")
    if not (MIN_RESTITUTION <= p.restitution <= 1.0):
        raise SimError(f"restitution must be in [{MIN_RESTITUTION:g}, 1] (got {p.restitution})")
    if p.wall_friction is not None and not (0.0 <= p.wall_friction <= 5.0):
        raise SimError(f"wall friction must be in [0, 5] (got {p.wall_friction})")
    if p.end_friction is not None and not (0.0 <= p.end_friction <= 5.0):
        raise SimError(f"end-plate friction must be in [0, 5] (got {p.end_friction})")
    if p.dt_s is not None and (not (1e-5 <= p.dt_s <= 0.02) or not math.isfinite(p.dt_s)):
        raise SimError(f"time step must be in [0.01, 20] ms (got {p.dt_s * 1e3:g} ms)")
    if not (1.0 <= p.stiffness_n_m <= 1e9) or not math.isfinite(p.stiffness_n_m):
        raise SimError(f"contact stiffness must be in [1, 1e9] N/m (got {p.stiffness_n_m})")
    if p.accel_rpm_s <= 0:
        raise SimError(f"acceleration limit must be positive (got {p.accel_rpm_s} rpm/s)")


__all__ = [
    "CASES",
    "DEFAULT_ACCEL_RPM_S",
    "DEFAULT_END_FRICTION",
    "DEFAULT_FRICTION",
    "DEFAULT_RESTITUTION",
    "DEFAULT_ROLLING",
    "DEFAULT_STIFFNESS_N_M",
    "DEFAULT_WALL_FRICTION",
    "MIN_RESTITUTION",
    "PAPER_CONTACT",
    "SimParams",
    "check_params",
    "check_rpm",
    "rpm_to_rad_s",
]

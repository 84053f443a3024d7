"""What every twin engine shares beyond the parameters (``sim.params``): what it reads out
(``Particles``, ``ContactStats``, the overlap histogram's ``OVERLAP_BINS``) and its clock
(``FixedStepTwin``: one fixed internal step whatever the caller's slicing, run-time friction).
``sim.engine.Twin`` is the interface; ``sim.drum.DrumSim`` and ``sim.pymunk_twin.PymunkDrumSim``
are built on this.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Self

import numpy as np

from sim.errors import SimError
from sim.params import SimParams, check_params

OVERLAP_BINS = 1000  # overlap histogram: bins of 0.002 small radii up to 2


def overlap_p99_r(hist: np.ndarray, overlap_max_r: float) -> float:
    """The 99th percentile of the overlaps counted in ``hist`` (``OVERLAP_BINS`` bins of 2 /
    ``OVERLAP_BINS`` small radii and an overflow bin), at most the largest ``overlap_max_r``; 0 with none."""
    total = int(hist.sum())
    if not total:
        return 0.0
    k = int(np.searchsorted(np.cumsum(hist), 0.99 * total))
    return min((k + 1) * 2.0 / OVERLAP_BINS, overlap_max_r)


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
    """Positions (m, drum frame, y up), radii (m) and class index of every disk (for a shaped particle:
    its centroid and circumscribed radius; its outline in ``class_outline_m``, turned by ``angle_rad``)."""

    x_m: np.ndarray
    y_m: np.ndarray
    r_m: np.ndarray
    cls: np.ndarray
    angle_rad: np.ndarray | None = None
    class_names: tuple[str, ...] = ()
    class_bgr: tuple[tuple[int, int, int], ...] = ()
    class_outline_m: tuple[np.ndarray | None, ...] = ()  # per class: outline (k, 2) about the centroid, None: disc
    baffles_m: tuple[np.ndarray, ...] = ()  # the drum's baffles now, polygons (k, 2) in the drum frame

    def __len__(self) -> int:
        return int(self.x_m.shape[0])



class FixedStepTwin:
    """The clock and contact knobs every engine shares: one fixed internal step ``params.dt_s``
    whatever the caller's slicing (the remainder carried), and run-time friction. An engine
    provides ``_run(n_steps)`` and ``_params_changed()``."""

    params: SimParams
    t_s: float
    _acc_s: float

    def _run(self, n_steps: int, count: bool = True) -> None:
        raise NotImplementedError

    def _params_changed(self) -> None:
        raise NotImplementedError

    def restore(self, state: Any) -> None:
        """Go back to ``state``, the engine's ``snapshot()`` (bit-identical continuation)."""
        raise NotImplementedError

    @classmethod
    def from_state(cls, state: Any) -> Self:
        """A new twin that continues from ``state`` (the engine's ``snapshot()``)."""
        sim = cls.__new__(cls)
        sim.restore(state)
        return sim

    def set_friction(self, friction: float, rolling: float | None = None, end_friction: float | None = None) -> None:
        """Change sliding friction (and rolling friction, and the end plates' friction: a calibration's
        ``sim.calibrate.Calibration.twin_kwargs``) at run time; None keeps that one as it is."""
        rolling = self.params.rolling if rolling is None else float(rolling)
        end = self.params.end_friction if end_friction is None else float(end_friction)
        params = replace(self.params, friction=float(friction), rolling=rolling, end_friction=end)
        check_params(params)
        self.params = params
        self._params_changed()

    def substep_s(self) -> float:
        """The fixed internal step (s)."""
        assert self.params.dt_s is not None
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
        h = self.substep_s()
        self._acc_s += duration_s
        n = int(math.floor(self._acc_s / h + 1e-9))
        self.t_s += duration_s
        if n <= 0:
            return
        self._acc_s = max(0.0, self._acc_s - n * h)
        self._run(n)



__all__ = ["OVERLAP_BINS", "ContactStats", "FixedStepTwin", "Particles", "overlap_p99_r"]

"""The supervisor's settings (pure): its rpm limits (``control.limits.Limits``, the one set),
segregation thresholds, AUTO tuning and safe-state policy.

The defaults are the ones a run uses (``drumtwin run``): the application hands in only the
drum's critical speed (in ``limits``) and the batch's objective, target and endpoint stop;
tests and benches that want other values say so. Camera MI of a well-mixed bed is
~0.93-0.95; radial segregation at 5 rpm brings it to ~0.80-0.85 (the demo plant's vision
MI): the thresholds sit between.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from control.errors import ControlError
from control.limits import Limits
from control.objective import check_objective


class SafeAction(StrEnum):
    HOLD = "hold"
    RAMP = "ramp"
    STOP = "stop"


@dataclass(frozen=True)
class SupervisorConfig:
    """Limits, detection thresholds, AUTO tuning and safe-state policy (units in names)."""

    # limits: the rpm range, the ramp rate and the drum's critical speed (control.limits)
    limits: Limits = field(default_factory=Limits)
    ramp_interval_s: float = 1.0
    min_change_interval_s: float = 30.0
    # segregation detection (MI units; rate in MI/s)
    seg_level: float = 0.88
    clear_level: float = 0.91
    seg_rate_per_s: float = -0.004
    radial_min: float = 0.5
    radial_clear: float = 0.6
    detect_dwell_s: float = 5.0
    clear_dwell_s: float = 5.0
    # AUTO
    n_candidates: int = 3  # 5, 25, 45 rpm (+ the current speed)
    horizon_s: float = 40.0
    move_penalty_per_rpm: float = 0.0002  # 40 rpm up costs 0.008 MI
    min_gain: float = 0.01
    prediction_max_age_s: float = 150.0  # a study takes 10-30 s wall: up to ~120 s of run time at --speed 4
    prediction_wait_s: float = 150.0
    fallback_step_rpm: float = 5.0
    # objective and endpoint (issue 24)
    objective: str = "plateau"  # plateau | time | energy (control.objective)
    target_mi: float | None = None  # the target of "time"/"energy" (None: the endpoint's, from the application)
    objective_min_rel_gain: float = 0.1  # "time"/"energy": move when the best saves this share vs staying
    stop_at_endpoint: bool = False  # AUTO stops the mill once the batch is mixed
    # safe state
    safe_action: SafeAction = SafeAction.HOLD
    safe_rpm: float = 5.0
    vision_timeout_s: float = 5.0  # the one vision timeout (run s): alarm and safe state together
    twin_timeout_s: float | None = 60.0
    require_twin: bool = True  # a twin that never ran (died or hung before its first step) is stale too
    recover_s: float = 5.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.vision_timeout_s) and self.vision_timeout_s > 0):
            raise ControlError(f"vision_timeout_s must be > 0, got {self.vision_timeout_s}")
        if self.clear_level < self.seg_level:
            raise ControlError("clear_level must be >= seg_level (hysteresis)")
        check_objective(self.objective)
        if self.target_mi is not None and not (math.isfinite(self.target_mi) and 0.0 <= self.target_mi <= 1.0):
            raise ControlError(f"target_mi must be in [0, 1], got {self.target_mi}")
        if self.objective != "plateau" and self.target_mi is None:
            raise ControlError(f"objective {self.objective} needs a target_mi")

    def vision_lost(self, now_s: float, last_valid_mi_s: float | None) -> bool:
        """True when no valid MI has been seen for more than ``vision_timeout_s`` (the one
        vision timeout of supervisor and application; None = never seen: not lost yet)."""
        return last_valid_mi_s is not None and now_s - last_valid_mi_s > self.vision_timeout_s

    def candidates(self, current: float | None = None) -> tuple[float, ...]:
        """Evenly spaced candidate rpms over the limits (plus ``current``), rounded to 0.1."""
        lo, hi = self.limits.rpm_range
        n = max(2, self.n_candidates)
        c = {round(lo + (hi - lo) * i / (n - 1), 1) for i in range(n)}
        if current is not None:
            c.add(round(self.limits.clamp(current), 1))
        return tuple(sorted(c))


__all__ = ["SafeAction", "SupervisorConfig"]

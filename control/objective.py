"""AUTO's objective: which rpm, given the twin's per-rpm predictions (issue 24, pure).

``objective``:

- ``"plateau"``: the highest predicted MI (the supervisor's own scoring, with its move
  penalty and minimum gain: ``control.supervisor``; this module only names it).
- ``"time"``: the rpm that reaches the target MI soonest (``time_to_target_s``).
- ``"energy"``: the rpm that reaches it with the least drive energy (``energy_j``: power x
  time to target, from the twin's torque; see the what-if results).

Only rpms inside the limits count, and only rows that reach the target within the study
(finite time / energy) *and stay there* (plateau MI at least the target: a noisy MI that
touches the target once is not a mixed batch) can win "time" or "energy"; when none does,
the highest plateau wins and the reason says so. :func:`choose` serves "time" and
"energy"; "plateau" is the supervisor's own scoring. Ties (within ``tie_rel``) go to the other quantity, then to
the lower drive power (a bed already at the target costs 0 J at every rpm: holding it
costs the power), then to the smaller move. A move is made when the best beats staying at the current rpm by at
least ``min_rel_gain`` (relative), or when the current rpm does not reach the target.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from control.errors import ControlError

OBJECTIVES = ("plateau", "time", "energy")


def check_objective(objective: str) -> str:
    """``objective`` lower-cased when it is one of :data:`OBJECTIVES`, else a one-line ControlError."""
    o = str(objective).strip().lower()
    if o not in OBJECTIVES:
        raise ControlError(f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    return o


@dataclass(frozen=True)
class RpmPrediction:
    """The twin's prediction at one rpm: plateau MI, time to reach the target MI (s; None
    or inf: not within the study), drive power (W) and energy to the target (J), with
    their seed spreads (sd, same units; None: one seed)."""

    rpm: float
    plateau_mi: float
    time_to_target_s: float | None = None
    energy_j: float | None = None
    power_w: float | None = None
    time_sd_s: float | None = None
    energy_sd_j: float | None = None

    def value(self, objective: str) -> float:
        """The quantity ``objective`` minimises (s or J; inf when the target is not reached),
        or minus the plateau MI for "plateau"."""
        if objective == "plateau":
            return -self.plateau_mi if math.isfinite(self.plateau_mi) else math.inf
        v = self.time_to_target_s if objective == "time" else self.energy_j
        return float(v) if v is not None and math.isfinite(v) and v >= 0 else math.inf


@dataclass(frozen=True)
class Choice:
    """The objective's pick. ``rpm``: the best rpm (None: no row inside the limits);
    ``move``: go there (else stay at the current rpm); ``values``: rpm -> the minimised
    quantity (s, J, or -MI); ``reason``: names the objective and the numbers."""

    objective: str
    rpm: float | None
    move: bool
    values: Mapping[float, float]
    reason: str


def stale_start(rows: Iterable[RpmPrediction], level: float | None, target_mi: float | None,
                segregated: bool = False) -> str:
    """Why a study's times to the target do not describe the bed now ("" when they do): the study's
    twin bed was at the target at once (a row of 0 s: its MI held the target from the start) while
    the trend ``level`` now is below it, or the segregation detector says the bed segregated
    (``segregated``: a trend that overshoots to the target is no proof of a mixed bed). The bed
    segregated while the study waited or ran, or the twin's bed was more mixed than the plant's."""
    if target_mi is None:
        return ""
    below = level is not None and math.isfinite(level) and level < target_mi
    if not (below or segregated):
        return ""
    at_once = [float(r.rpm) for r in rows if r.time_to_target_s is not None and r.time_to_target_s == 0.0]
    if not at_once:
        return ""
    now = f"the trend is {level:.3f} now" if below else "the bed segregated"
    return (f"the study's twin bed was at the target {target_mi:g} at once ({', '.join(f'{r:g}' for r in at_once)}"
            f" rpm: 0 s), {now}")


def _power(r: RpmPrediction) -> float:
    """The drive power of a row (W; inf when unknown): the last tie-break but the move."""
    return float(r.power_w) if r.power_w is not None and math.isfinite(r.power_w) else math.inf


def _fmt(objective: str, v: float) -> str:
    if not math.isfinite(v):
        return "never"
    if objective == "time":
        return f"{v:.0f} s"
    if objective == "energy":
        return f"{v:.1f} J"
    return f"MI {-v:.3f}"


def choose(
    rows: Iterable[RpmPrediction],
    objective: str,
    current_rpm: float,
    limits: tuple[float, float],
    target_mi: float | None = None,
    *,
    min_rel_gain: float = 0.1,
    tie_rel: float = 0.02,
) -> Choice:
    """The rpm ``objective`` picks among ``rows`` inside ``limits`` (see module doc)."""
    obj = check_objective(objective)
    if obj == "plateau":
        raise ControlError("objective plateau is the supervisor's own scoring (control.supervisor), not choose()")
    lo, hi = limits
    inside = [r for r in rows if lo - 1e-9 <= float(r.rpm) <= hi + 1e-9 and math.isfinite(r.plateau_mi)]
    if not inside:
        return Choice(obj, None, False, {}, f"objective {obj}: no prediction inside {lo:g}..{hi:g} rpm")
    values = {float(r.rpm): r.value(obj) for r in inside}
    other = "energy" if obj == "time" else "time"
    target = "" if target_mi is None else f" to MI {target_mi:g}"
    reaching = [r for r in inside if math.isfinite(values[float(r.rpm)])
                and (target_mi is None or r.plateau_mi >= target_mi)]
    if not reaching:  # nobody reaches the target: the best plateau, said so
        best_row = max(inside, key=lambda r: (r.plateau_mi, -abs(r.rpm - current_rpm)))
        best = float(best_row.rpm)
        return Choice(obj, best, abs(best - current_rpm) > 1e-6, values,
                      f"objective {obj}: no rpm reaches the target{target} within the study; highest plateau "
                      f"MI {best_row.plateau_mi:.3f} at {best:g} rpm")
    values = {rpm: (v if any(float(r.rpm) == rpm for r in reaching) else math.inf) for rpm, v in values.items()}
    vmin = min(values[float(r.rpm)] for r in reaching)
    tied = [r for r in reaching if values[float(r.rpm)] <= vmin + tie_rel * abs(vmin)]
    best_row = min(tied, key=lambda r: (r.value(other), _power(r), abs(r.rpm - current_rpm)))
    best = float(best_row.rpm)
    vb = values[best]
    watts = {float(r.rpm): _power(r) for r in inside}
    listing = ", ".join(f"{rpm:g} rpm {_fmt(obj, v)}" + (f" at {watts[rpm]:.2f} W" if math.isfinite(watts[rpm]) else "")
                        for rpm, v in sorted(values.items()))
    near = [rpm for rpm in values if abs(rpm - current_rpm) <= 0.5]
    stay = values[min(near, key=lambda x: abs(x - current_rpm))] if near else math.inf
    versus = _versus(reaching, obj, other, best, current_rpm)
    if abs(best - current_rpm) < 1e-6 or (math.isfinite(stay) and stay - vb < min_rel_gain * abs(stay)):
        return Choice(obj, best, False, values,
                      f"objective {obj}{target}: best {best:g} rpm {_fmt(obj, vb)} vs {_fmt(obj, stay)} staying at "
                      f"{current_rpm:g} rpm (gain < {min_rel_gain:.0%}) -> stay ({listing}); {versus}")
    return Choice(obj, best, True, values,
                  f"objective {obj}{target}: {best:g} rpm {_fmt(obj, vb)} vs {_fmt(obj, stay)} at {current_rpm:g} "
                  f"rpm ({listing}); {versus}")


def _versus(reaching: list[RpmPrediction], obj: str, other: str, best: float, current_rpm: float) -> str:
    """What the other objective would pick among the same rows: the same rpm, or which and at what."""
    finite = [r for r in reaching if math.isfinite(r.value(other))]
    if not finite:
        return f"{other}: no finite values to compare"
    alt = min(finite, key=lambda r: (r.value(other), abs(r.rpm - current_rpm)))
    if abs(float(alt.rpm) - best) < 1e-6:
        return f"{other} picks {best:g} rpm too"
    b = next(r for r in reaching if float(r.rpm) == best)
    return (f"{other} would pick {float(alt.rpm):g} rpm ({_fmt(other, alt.value(other))} vs "
            f"{_fmt(other, b.value(other))} at {best:g} rpm; {_fmt(obj, alt.value(obj))} there)")

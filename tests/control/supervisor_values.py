"""The supervisor settings the control tests' expectations were worked out on by hand.

``SupervisorConfig``'s defaults are a run's (``control.supervisor_config``); these tests
were written against a gentler set (MI thresholds 0.5/0.6, seven candidates over 2-45 rpm,
a 60 s horizon ...), and they say so: :func:`worked_config` is ``SupervisorConfig`` on
:data:`WORKED` and :data:`WORKED_LIMITS`, with a test's own values over them.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from control.limits import Limits
from control.supervisor_config import SupervisorConfig

WORKED: dict[str, Any] = dict(
    seg_level=0.5, clear_level=0.6, seg_rate_per_s=-0.01, n_candidates=7, horizon_s=60.0,
    move_penalty_per_rpm=0.002, min_gain=0.02, prediction_max_age_s=30.0, prediction_wait_s=20.0,
    require_twin=False,
)
WORKED_LIMITS: dict[str, Any] = dict(min_rpm=2.0, max_rpm=45.0, max_critical_frac=0.6, max_rate_rpm_per_s=2.0)
LIMIT_FIELDS = frozenset(f.name for f in fields(Limits))


def worked_limits(**kw: Any) -> Limits:
    """``Limits`` on :data:`WORKED_LIMITS`, ``kw`` over them."""
    return Limits(**{**WORKED_LIMITS, **kw})


def worked_config(**kw: Any) -> SupervisorConfig:
    """``SupervisorConfig`` on the worked values, ``kw`` over them (``Limits``' fields, e.g.
    ``min_rpm`` or ``critical_rpm``, go into its ``limits``)."""
    lim = {k: kw.pop(k) for k in list(kw) if k in LIMIT_FIELDS}
    return SupervisorConfig(limits=worked_limits(**lim), **{**WORKED, **kw})

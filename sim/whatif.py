"""What-if studies: run the twin for a list of rpm values (seeds, cases, fill levels).

Each ``WhatIfJob`` is a pure description (picklable, so it travels to a process pool
or a Dask worker); ``run_job`` runs one and returns a ``WhatIfResult`` with the MI
curve, the plateau MI and the regime. ``run_study`` runs many: in this process
(``workers=1``), on a local process pool (default: all cores; ``sim.pool``: its workers die
with this process), or on an existing Dask cluster (``scheduler="tcp://host:port"``, a dead
address is a SimError within seconds).

Time to mix and drive power (issue 24): a job with a ``target_mi`` reports the time the twin
takes to reach it from the start state (``time_to_target``: the first time a centred moving
average of MI over ``TARGET_SMOOTH_S`` reaches it and stays there to the end of the run, at least
``TARGET_DWELL_S``; 0 if the start is already there; NaN if the run never gets there), the drive
power over the plateau part (``sim.power``: the bed's torque on the drum times its speed, scaled from
the slice to the drum's depth) and the energy up to the target. ``target_mi`` None: no target (those
fields NaN); the application passes its
config's endpoint target (``control.endpoint``), which is the one definition of it.

Regime from the flow (``flow_regime``): the fraction of disks without any contact
(airborne) and the S-shape of the free surface decide rolling / cascading /
cataracting; the Froude number ``Fr = omega^2 R / g`` is reported beside it (and
``froude_regime`` keeps Mellmann's (2001) Froude thresholds for comparison).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sim.drum import DrumSim, SimState
from sim.engine import from_state, make_twin
from sim.errors import SimError
from sim.mixer import Mixer
from sim.params import check_rpm, rpm_to_rad_s
from sim.pool import close_pool, make_pool
from sim.power import depth_scale, drive_power_w
from sim.probe import probe
from sim.recipe import G_M_S2, PAPER_DRUM, PAPER_RECIPE, DrumSpec, Recipe, with_fill

__all__ = [
    "AIRBORNE_CATARACTING",
    "CURVATURE_CASCADING",
    "DEFAULT_CONNECT_TIMEOUT_S",
    "TARGET_DWELL_S",
    "TARGET_SMOOTH_S",
    "WhatIfJob",
    "WhatIfResult",
    "close_pool",
    "energy_to",
    "flow_regime",
    "froude",
    "froude_regime",
    "make_pool",
    "plateau",
    "regime",
    "run_job",
    "run_study",
    "summarize",
    "time_to_target",
]

DEFAULT_CONNECT_TIMEOUT_S = 5.0
TARGET_SMOOTH_S = 2.0  # window of the centred moving average of MI that must reach the target (s)
TARGET_DWELL_S = 5.0  # ... and stay there to the end, at least this long (s): a noisy touch is not "there"
_REGIMES = ((1e-4, "slumping"), (1e-2, "rolling"), (1e-1, "cascading"), (1.0, "cataracting"))


def froude(rpm: float, drum: DrumSpec = PAPER_DRUM) -> float:
    """Froude number ``omega^2 R / g`` of the drum at ``rpm``."""
    w = rpm_to_rad_s(rpm)
    return w * w * drum.radius_m / G_M_S2


def froude_regime(rpm: float, drum: DrumSpec = PAPER_DRUM) -> str:
    """Bed regime by Froude number alone (Mellmann 2001): slumping ... centrifuging."""
    fr = froude(rpm, drum)
    for limit, name in _REGIMES:
        if fr < limit:
            return name
    return "centrifuging"


# Flow-based regime thresholds (docs/validation.md, section "regime from the flow")
AIRBORNE_CATARACTING = 0.23  # mean fraction of disks without any contact (docs/validation.md, section 6)
CURVATURE_CASCADING = 0.06  # mean S-shape of the free surface (sim.measure.FreeSurface.curvature)


def flow_regime(airborne: float, curvature: float) -> str:
    """Regime from the flow: ``cataracting`` if at least ``AIRBORNE_CATARACTING`` of the disks fly,
    else ``cascading`` if the free surface is S-shaped (curvature >= ``CURVATURE_CASCADING``),
    else ``rolling`` (a flat surface). ``unknown`` without data."""
    if not math.isfinite(airborne):
        return "unknown"
    if airborne >= AIRBORNE_CATARACTING:
        return "cataracting"
    if math.isfinite(curvature) and curvature >= CURVATURE_CASCADING:
        return "cascading"
    return "rolling"


def regime(rpm: float, drum: DrumSpec = PAPER_DRUM) -> str:
    """Froude-number regime (kept for callers that have no flow data; prefer ``flow_regime``)."""
    return froude_regime(rpm, drum)


@dataclass(frozen=True)
class WhatIfJob:
    """One twin run: rpm (setpoint from t=0), duration (s), start state or a fresh bed."""

    rpm: float
    duration_s: float
    case: str = "C"
    seed: int = 0
    fill: float | None = None  # None: the recipe's fill
    start: SimState | None = None  # branch from this state instead of a fresh bed
    sample_s: float = 0.5
    sim_kwargs: dict = field(default_factory=dict)  # friction, rolling, restitution, ...
    drum: DrumSpec = PAPER_DRUM
    recipe: Recipe = PAPER_RECIPE
    tag: str = ""
    mixer: Mixer | None = None  # the user's mixer (replaces ``drum`` and ``recipe``); ``fill`` overrides its fill
    engine: str | None = None  # "dem" | "pymunk"; None: the mixer's (``sim.engine.engine_for``)
    target_mi: float | None = None  # MI to reach (time/energy to it); None: no target (module doc)
    ramp_rpm_s: float | None = None  # from ``start``: the drum ramps to ``rpm`` at most this fast (rpm/s; the
    # supervisor's rate limit, as the plant will); None: the twin's own acceleration limit

    @property
    def bed_drum(self) -> DrumSpec:
        """The drum this job runs in (the start state's, the mixer's, else ``drum``)."""
        if self.start is not None:
            return self.start.drum
        return self.mixer.drum if self.mixer is not None else self.drum


@dataclass(frozen=True)
class WhatIfResult:
    """MI curve (particle level, eq. 4 and eq. 3) and its summary for one job."""

    job: WhatIfJob
    t_s: np.ndarray
    mi: np.ndarray
    mi_sigmoid: np.ndarray
    slope_deg: np.ndarray
    rpm_actual: np.ndarray
    plateau_mi: float
    plateau_mi_sd: float
    t_plateau_s: float
    regime: str  # from the flow (flow_regime), over the last third of the run
    froude: float
    wall_s: float
    airborne: np.ndarray = field(default_factory=lambda: np.zeros(0))  # fraction of disks without contact
    curvature: np.ndarray = field(default_factory=lambda: np.zeros(0))  # free-surface S-shape
    froude_regime: str = ""
    torque_nm: np.ndarray = field(default_factory=lambda: np.zeros(0))  # drive torque, N m, whole drum, per sample
    power_w: np.ndarray = field(default_factory=lambda: np.zeros(0))  # drive power, W, whole drum, per sample
    time_to_target_s: float = math.nan  # s from the start to ``job.target_mi`` (NaN: not reached / no target)
    energy_to_target_j: float = math.nan  # drive energy up to the target, J, whole drum

    @property
    def plateau_power_w(self) -> float:
        """Mean drive power over the plateau part (the last third) of the run, W, whole drum."""
        return _tail_mean(self.power_w)

    @property
    def plateau_torque_nm(self) -> float:
        """Mean drive torque over the plateau part of the run, N m, whole drum."""
        return _tail_mean(self.torque_nm)

    def summary(self) -> dict:
        """The run in numbers (MI, s, W, J, N m; power and torque for the whole drum)."""
        j = self.job
        return {
            "rpm": j.rpm, "case": j.case, "seed": j.seed, "fill": j.fill, "tag": j.tag,
            "plateau_mi": self.plateau_mi, "plateau_mi_sd": self.plateau_mi_sd, "t_plateau_s": self.t_plateau_s,
            "regime": self.regime, "froude": self.froude, "froude_regime": self.froude_regime,
            "airborne": _tail_mean(self.airborne), "curvature": _tail_mean(self.curvature),
            "mi_start": float(self.mi[0]) if self.mi.size else math.nan, "wall_s": self.wall_s,
            "target_mi": j.target_mi, "time_to_target_s": self.time_to_target_s,
            "power_w": self.plateau_power_w, "energy_to_target_j": self.energy_to_target_j,
            "torque_nm": self.plateau_torque_nm,
        }


def _tail_mean(a: np.ndarray, tail: float = 1.0 / 3.0) -> float:
    """Mean of the finite values in the last ``tail`` of ``a`` (NaN if none)."""
    a = np.asarray(a, float)
    a = a[-max(1, int(round(tail * a.size))):] if a.size else a
    a = a[np.isfinite(a)]
    return float(np.mean(a)) if a.size else math.nan


def plateau(t_s: np.ndarray, mi: np.ndarray, tail: float = 1.0 / 3.0) -> tuple[float, float, float]:
    """(plateau MI, its sd, time to plateau s) of an MI curve.

    Plateau = mean over the last ``tail`` of the run; time to plateau = first time the
    curve's running mean (window = 10 % of the run) comes within max(0.02, sd) of it.
    """
    t = np.asarray(t_s, float)
    y = np.asarray(mi, float)
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    if y.size == 0:
        return math.nan, math.nan, math.nan
    n_tail = max(1, int(round(tail * y.size)))
    p = float(np.mean(y[-n_tail:]))
    sd = float(np.std(y[-n_tail:]))
    w = max(1, int(round(0.1 * y.size)))
    sm = np.convolve(y, np.ones(w) / w, mode="valid")
    ts = t[w - 1:]
    near = np.nonzero(np.abs(sm - p) <= max(0.02, sd))[0]
    tp = float(ts[near[0]] - t[0]) if near.size else float(t[-1] - t[0])
    return p, sd, tp


def time_to_target(t_s: np.ndarray, mi: np.ndarray, target: float | None,
                   smooth_s: float = TARGET_SMOOTH_S, dwell_s: float = TARGET_DWELL_S) -> float:
    """Time (s, from ``t_s[0]``) from which MI is at ``target`` to the end of the series: the first centre
    time of a moving average over ``smooth_s`` (NaN samples left out) after which that average never falls
    below ``target`` again, held for at least ``dwell_s`` before the series ends; 0 when that holds from
    the first window on. NaN if it never does (a plateau at the target that dips below it is not there)
    or ``target`` is None. Both the twin's curves (the study's horizon) and the plant's logged camera MI
    (``twin.report``: the same horizon after the decision) are measured with it."""
    t = np.asarray(t_s, float)
    y = np.asarray(mi, float)
    if target is None or t.size == 0:
        return math.nan
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    w = max(1, int(round(smooth_s / dt))) if dt > 0 else 1
    w = min(w, t.size)
    ok = np.isfinite(y)
    num = np.convolve(np.where(ok, y, 0.0), np.ones(w), mode="valid")
    den = np.convolve(ok.astype(float), np.ones(w), mode="valid")
    sm = np.divide(num, den, out=np.full(num.size, np.nan), where=den > 0)
    tc = np.convolve(t, np.ones(w) / w, mode="valid")
    below = np.nonzero(~(sm >= target))[0]  # NaN compares False: a gap is not "there"
    i = 0 if below.size == 0 else int(below[-1]) + 1
    if i >= sm.size or tc[-1] - tc[i] < dwell_s - 1e-9:
        return math.nan
    return 0.0 if i == 0 else float(tc[i] - t[0])


def energy_to(t_s: np.ndarray, power_w: np.ndarray, t_end_s: float) -> float:
    """Energy (J) of a power series up to ``t_end_s`` (from ``t_s[0]``): each sample's power is the mean
    over the slice that ended at it (``sim.probe``), so the energy is the sum of power x slice over the
    slices up to ``t_end_s`` (the last one in part); NaN when ``t_end_s`` is NaN."""
    if not math.isfinite(t_end_s):
        return math.nan
    t = np.asarray(t_s, float) - float(t_s[0])
    p = np.asarray(power_w, float)
    e = 0.0
    for k in range(1, t.size):
        lo, hi = t[k - 1], min(t[k], t_end_s)
        if hi <= lo:
            break
        if math.isfinite(p[k]):
            e += p[k] * (hi - lo)
    return float(e)


def _ramped(state: Any, ramp_rpm_s: float | None) -> Any:
    """``state`` whose drum follows its setpoint at most ``ramp_rpm_s`` (rpm/s): the lower of that and its own
    acceleration limit (``SimParams.accel_rpm_s``, both engines); None: ``state`` unchanged."""
    if ramp_rpm_s is None:
        return state
    params = state.params
    return replace(state, params=replace(params, accel_rpm_s=min(float(params.accel_rpm_s), float(ramp_rpm_s))))


def run_job(job: WhatIfJob) -> WhatIfResult:
    """Run one what-if job in this process (pure: same job, same result)."""
    t0 = time.perf_counter()
    if job.duration_s <= 0 or not math.isfinite(job.duration_s):
        raise SimError(f"what-if duration must be > 0 s (got {job.duration_s})")
    sim: Any
    if job.start is not None:
        sim = from_state(_ramped(job.start, job.ramp_rpm_s))
        sim.set_rpm(job.rpm)
        drum = sim.drum
    elif job.mixer is not None:
        mixer = job.mixer if job.fill is None else replace(job.mixer, fill=float(job.fill))
        sim = make_twin(mixer, job.engine, case=job.case, seed=job.seed, rpm=job.rpm, **job.sim_kwargs)
        drum = mixer.drum
    else:
        recipe = job.recipe if job.fill is None else with_fill(job.recipe, job.fill)
        sim = DrumSim(job.drum, recipe, case=job.case, seed=job.seed, rpm=job.rpm, **job.sim_kwargs)
        drum = job.drum
    scale = depth_scale(sim)
    ts, mis, sigs, slopes, rpms, air, curv, tq = [], [], [], [], [], [], [], []
    for s in probe(sim, job.duration_s, job.sample_s):
        ts.append(s.t_s)
        mis.append(s.mi.mi)
        sigs.append(s.mi.mi_sigmoid)
        slopes.append(s.surface.slope_deg)
        curv.append(s.surface.curvature)
        air.append(s.airborne)
        rpms.append(s.rpm_actual)
        tq.append(s.bed_torque_nm)
    t_arr, mi_arr = np.array(ts), np.array(mis)
    p, sd, tp = plateau(t_arr, mi_arr)
    air_arr, curv_arr = np.array(air), np.array(curv)
    rpm_arr = np.array(rpms)
    bed_tq = np.array(tq) * scale  # the bed's torque on the whole drum, N m
    power = drive_power_w(bed_tq, rpm_arr)
    t_target = time_to_target(t_arr, mi_arr, job.target_mi)
    return WhatIfResult(
        job=job, t_s=t_arr, mi=mi_arr, mi_sigmoid=np.array(sigs), slope_deg=np.array(slopes),
        rpm_actual=np.array(rpms), plateau_mi=p, plateau_mi_sd=sd, t_plateau_s=tp,
        regime=flow_regime(_tail_mean(air_arr), _tail_mean(curv_arr)), froude=froude(job.rpm, drum),
        wall_s=time.perf_counter() - t0, airborne=air_arr, curvature=curv_arr,
        froude_regime=froude_regime(job.rpm, drum), torque_nm=-bed_tq, power_w=power,
        time_to_target_s=t_target, energy_to_target_j=energy_to(t_arr, power, t_target),
    )


def _check_jobs(jobs: Sequence[WhatIfJob]) -> list[WhatIfJob]:
    jobs = list(jobs)
    if not jobs:
        raise SimError("a what-if study needs at least one job")
    for j in jobs:
        if not isinstance(j, WhatIfJob):
            raise SimError(f"what-if jobs must be WhatIfJob (got {type(j).__name__})")
        check_rpm(j.rpm, j.bed_drum)
        if not (j.duration_s > 0) or not math.isfinite(j.duration_s):
            raise SimError(f"what-if duration must be > 0 s (got {j.duration_s})")
        if j.target_mi is not None and not (math.isfinite(j.target_mi) and 0.0 <= j.target_mi <= 1.0):
            raise SimError(f"target MI must be in [0, 1] (got {j.target_mi})")
        if j.ramp_rpm_s is not None and not (math.isfinite(j.ramp_rpm_s) and j.ramp_rpm_s > 0):
            raise SimError(f"what-if ramp must be > 0 rpm/s (got {j.ramp_rpm_s})")
        if not (0 < j.sample_s <= j.duration_s):
            raise SimError(f"sample interval must be in (0, duration] (got {j.sample_s} s)")
        if j.start is None and j.fill is not None and j.mixer is not None and any(
                p.count is not None for p in j.mixer.particles):
            raise SimError("a fill level needs a mixer whose classes are given by share (its counts fix the bed)")
    return jobs


def _connect(scheduler: str, timeout_s: float):
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - dask is a declared dependency of the cluster extra
        raise SimError("running on a Dask cluster needs dask[distributed] installed") from None
    addr = str(scheduler).strip()
    if "://" not in addr:
        addr = "tcp://" + addr
    proto, _, rest = addr.partition("://")
    host, _, port = rest.rpartition(":")
    if proto not in ("tcp", "tls", "inproc", "ws", "wss") or not host or not port.isdigit():
        raise SimError(f"scheduler address must look like tcp://HOST:PORT (got {scheduler!r})")
    try:
        return Client(addr, timeout=f"{timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise SimError(f"no Dask scheduler answers at {addr} within {timeout_s:g} s ({type(exc).__name__})") from None


def run_study(
    jobs: Sequence[WhatIfJob],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    *,
    connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    pool: Executor | None = None,
) -> list[WhatIfResult]:
    """Run ``jobs``; results in job order.

    ``scheduler``: address of a running Dask scheduler (``dask scheduler`` + ``dask worker``).
    Otherwise ``workers`` local processes (default: all cores; 1 = in this process), or
    the caller's own ``pool`` (``make_pool()``; kept open for the next study).
    ``progress(done, total)`` is called as jobs finish.
    """
    jobs = _check_jobs(jobs)
    total = len(jobs)
    results: list[WhatIfResult | None] = [None] * total
    done = 0
    if scheduler:
        client = _connect(scheduler, connect_timeout_s)
        try:
            from distributed import as_completed as dask_completed

            futs = client.map(run_job, jobs, pure=False)
            index = {f.key: i for i, f in enumerate(futs)}
            for fut in dask_completed(futs, loop=client.loop):
                results[index[fut.key]] = fut.result()
                done += 1
                if progress:
                    progress(done, total)
        finally:
            client.close()
        return results  # type: ignore[return-value]
    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if n_workers < 1:
        raise SimError(f"workers must be >= 1 (got {workers})")
    n_workers = min(n_workers, total)
    if n_workers == 1 and pool is None:
        for i, j in enumerate(jobs):
            results[i] = run_job(j)
            done += 1
            if progress:
                progress(done, total)
        return results  # type: ignore[return-value]
    own = pool is None
    if pool is None:
        pool = make_pool(n_workers)
    try:
        futs = {pool.submit(run_job, j): i for i, j in enumerate(jobs)}
        for fut in as_completed(futs):
            results[futs[fut]] = fut.result()
            done += 1
            if progress:
                progress(done, total)
    finally:
        if own:
            pool.shutdown(wait=True, cancel_futures=True)
    return results  # type: ignore[return-value]


def _mean_sd(vals: Sequence[float]) -> tuple[float, float]:
    """Mean and sample sd (ddof 1) of the finite values (NaN when none; sd NaN below two)."""
    a = np.asarray(vals, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return math.nan, math.nan
    return float(np.mean(a)), float(np.std(a, ddof=1)) if a.size > 1 else math.nan


def summarize(results: Sequence[WhatIfResult]) -> list[dict]:
    """One entry per rpm (seeds and cases pooled): plateau MI mean, sd across runs and within, regime; the
    seed mean and sd of the time to target (s; ``time_to_target_reached``: runs that got there, the mean
    over those), drive power (W), energy to target (J) and torque (N m)."""
    by_rpm: dict[float, list[WhatIfResult]] = {}
    for r in results:
        by_rpm.setdefault(float(r.job.rpm), []).append(r)
    out = []
    for rpm in sorted(by_rpm):
        rs = by_rpm[rpm]
        p = np.array([r.plateau_mi for r in rs])
        within = np.array([r.plateau_mi_sd for r in rs])
        sd = float(np.sqrt(np.nanmean(within**2) + (np.nanvar(p) if p.size > 1 else 0.0)))
        regimes = [r.regime for r in rs]
        out.append({
            "rpm": rpm, "plateau_mi": float(np.nanmean(p)), "plateau_mi_sd": sd,
            "plateau_mi_sem": float(np.nanstd(p, ddof=1) / math.sqrt(p.size)) if p.size > 1 else math.nan,
            "t_plateau_s": float(np.nanmean([r.t_plateau_s for r in rs])),
            "regime": max(set(regimes), key=regimes.count), "froude": rs[0].froude,
            "froude_regime": rs[0].froude_regime, "airborne": float(np.nanmean([_tail_mean(r.airborne) for r in rs])),
            "curvature": float(np.nanmean([_tail_mean(r.curvature) for r in rs])), "runs": len(rs),
        })
        row = out[-1]
        for key, sd_key, vals in (
            ("time_to_target_s", "time_to_target_sd_s", [r.time_to_target_s for r in rs]),
            ("power_w", "power_sd_w", [r.plateau_power_w for r in rs]),
            ("energy_to_target_j", "energy_to_target_sd_j", [r.energy_to_target_j for r in rs]),
            ("torque_nm", "torque_sd_nm", [r.plateau_torque_nm for r in rs]),
        ):
            row[key], row[sd_key] = _mean_sd(vals)
        row["time_to_target_reached"] = int(np.sum(np.isfinite([r.time_to_target_s for r in rs])))
    return out

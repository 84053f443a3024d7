"""Regenerate the pymunk twin's numbers and plots of docs/validation.md (section 10).

``python -m sim.validation_pymunk SECTION [OUT_DIR]`` with SECTION one of ``convergence``,
``segregation``, ``baffles``, ``dem``, ``calibration``, ``all``. The rig is the worked example
``configs/pmma-cutdisc.toml`` (blue discs and white 90-degree cut discs, 10 mm, in a 250 mm
monolayer drum) and its disc/disc twin (the white class made a disc). Every run is seeded; each
section prints a JSON summary on stdout and writes its plot to OUT_DIR (default ``docs/img``).
Run it with ``nice`` on a shared machine: it is serial (one core).
"""

from __future__ import annotations

import json
import math
import sys
import time
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from sim import calibrate as cal
from sim.engine import make_twin
from sim.errors import SimError
from sim.measure import free_surface, particle_mi, radial_spread_m
from sim.mixer import Baffles, Mixer, Shape, parse_mixer, resolve

SECTIONS = ("convergence", "segregation", "baffles", "dem", "calibration")
RIG_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "pmma-cutdisc.toml"
RIG_BAFFLES = Baffles(count=4, height_m=0.020, thickness_m=0.004)  # 4 lifters, 2 disc diameters high
RIG_TALL_BAFFLES = Baffles(count=4, height_m=0.050, thickness_m=0.004)  # 4 lifters, 5 disc diameters high
# The studies' contacts: the paper's friction and rolling friction, no end-plate friction. With the
# Taberlet plate model at the monolayer's gap (3 mm, r / W = 1.7) the bed stands at 49-64 deg at
# 10 rpm over the whole calibration search (against 32 deg in the real frames): a monolayer is not
# the thick quasi-2D flow that model describes (docs/validation.md section 10).
# The studies run each engine at its default step (pymunk's ``default_dt_s``: 1 ms for the cut-disc rig,
# 0.5 ms for the disc/disc rig; section 10), except ``convergence``, which sets its own.
CONTACT: dict[str, Any] = {"end_friction": 0.0}


def rig(cut: bool = True, baffles: Baffles | None = None, wedge_deg: float | None = None) -> Mixer:
    """The worked example's mixer (``configs/pmma-cutdisc.toml``); ``cut`` False: the white class a
    disc of the same diameter (the disc/disc bed); ``baffles``: lifters on the wall; ``wedge_deg``:
    the cut's angle instead of the config's 90 deg (a variant)."""
    table = tomllib.loads(RIG_CONFIG.read_text())
    m = parse_mixer(table, [c["name"] for c in table["classes"]], source=str(RIG_CONFIG))
    if not cut:
        m = replace(m, particles=tuple(replace(p, shape=Shape("disc", p.shape.diameter_m)) for p in m.particles))
    elif wedge_deg is not None:
        m = replace(m, particles=tuple(replace(p, shape=replace(p.shape, wedge_deg=float(wedge_deg)))
                                       if p.shape.kind == "cut_disc" else p for p in m.particles))
    return replace(m, baffles=baffles)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def series(mixer: Mixer, rpm: float, seed: int, duration_s: float, *, engine: str | None = None, case: str = "C",
           every_s: float = 0.5, spin_up_s: float = 0.0, **kw) -> dict:
    """One run: time, particle MI (eq. 4), the spread ratio (class 1 over class 0, about the bed's
    centroid), free-surface slope (deg) every ``every_s``; contact stats and the CPU real-time factor."""
    twin = make_twin(mixer, engine, case=case, seed=seed, rpm=rpm, **kw)
    areas = np.array([k.area_m2 for k in resolve(mixer)])
    if spin_up_s:
        twin.advance(spin_up_s)
    twin.reset_stats()
    out: dict = {"t": [], "mi": [], "ratio": [], "slope": []}
    t0 = time.process_time()
    for _ in range(int(round(duration_s / every_s))):
        twin.advance(every_s)
        p = twin.particles()
        s0, s1 = radial_spread_m(p, areas)[:2]
        out["t"].append(twin.t_s)
        out["mi"].append(particle_mi(p, mixer.drum).mi)
        out["ratio"].append(s1 / s0)
        out["slope"].append(free_surface(p, mixer.drum).slope_deg)
    cpu = time.process_time() - t0
    res: dict[str, Any] = {k: np.asarray(v, float) for k, v in out.items()}
    st = twin.stats()
    res["rtf"] = duration_s / max(cpu, 1e-9)
    res["overlap_p99_r"] = st.overlap_p99_r
    res["wall_max_mm"] = st.wall_max_mm
    res["dt_ms"] = twin.substep_s() * 1e3
    return res


SEGREGATION_SD = 3.0  # the test: a spread ratio this many seed standard deviations from 1 segregates


def sd_from_one(ratios) -> float:
    """How far the seeds' mean spread ratio is from 1, in seed standard deviations (``ddof=1``:
    the scatter of one seed's run, not the standard error of the mean); inf for no scatter."""
    v = np.asarray(ratios, dtype=float)
    if v.size < 2:
        raise SimError("the seed scatter needs at least two seeds")
    sd = float(np.std(v, ddof=1))
    return abs(float(np.mean(v)) - 1.0) / sd if sd > 0 else math.inf


def segregates(ratios) -> bool:
    """The issue's criterion: the spread ratio differs from 1 by more than ``SEGREGATION_SD`` seed sd."""
    return sd_from_one(ratios) > SEGREGATION_SD


def difference_in_se(a, b) -> float:
    """|mean(a) - mean(b)| over its standard error (Welch): how measurable a change between two sets
    of seeded runs is (a baffled drum against a plain one); inf for no scatter."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.size < 2 or y.size < 2:
        raise SimError("a difference of seeded runs needs at least two seeds each")
    se = math.sqrt(float(np.var(x, ddof=1)) / x.size + float(np.var(y, ddof=1)) / y.size)
    d = abs(float(np.mean(x)) - float(np.mean(y)))
    return d / se if se > 0 else (math.inf if d > 0 else 0.0)


def _late(a: np.ndarray, frac: float = 1 / 3) -> float:
    k = max(1, int(round(len(a) * frac)))
    return float(np.nanmean(a[-k:]))


def _ms(values) -> dict:
    v = np.asarray(values, float)
    return {"mean": float(np.mean(v)), "sd": float(np.std(v, ddof=1)) if v.size > 1 else math.nan,
            "n": int(v.size), "values": [float(x) for x in v]}


def convergence(out_dir: Path, seeds=(0, 1, 2, 3), steps_ms=(4.0, 3.0, 2.0, 1.0, 0.5), iterations=(10, 20, 40),
                iter_steps_ms=(2.0, 4.0), rpm: float = 10.0, spin_up_s: float = 2.0, window_s: float = 8.0) -> dict:
    """Slope, MI (eq. 4) and spread ratio at 10 rpm on the cut-disc rig against the step (at 10
    iterations) and the solver iterations (at each of ``iter_steps_ms``), several seeds."""
    m = rig(True)
    runs = []
    grid = [(h, 10) for h in steps_ms] + [(h, it) for h in iter_steps_ms for it in iterations if it != 10]
    for h, it in grid:
        for s in seeds:
            r = series(m, rpm, s, window_s, spin_up_s=spin_up_s, every_s=0.25,
                       **{**CONTACT, "dt_s": h * 1e-3, "iterations": it})
            runs.append({"dt_ms": h, "iterations": it, "seed": s, "slope_deg": float(np.nanmean(r["slope"])),
                         "mi": float(np.nanmean(r["mi"])), "ratio": float(np.nanmean(r["ratio"])),
                         "overlap_p99_r": r["overlap_p99_r"], "wall_max_mm": r["wall_max_mm"], "rtf": r["rtf"]})
            print(json.dumps(runs[-1]), file=sys.stderr, flush=True)

    def cell(sel: list[dict]) -> dict:
        return {"slope": _ms([r["slope_deg"] for r in sel]), "mi": _ms([r["mi"] for r in sel]),
                "ratio": _ms([r["ratio"] for r in sel]),
                "overlap_p99_r": float(np.mean([r["overlap_p99_r"] for r in sel])),
                "rtf": float(np.mean([r["rtf"] for r in sel]))}

    summary: dict = {"by_step": {}, "by_iterations": {}}
    for h in steps_ms:
        summary["by_step"][f"{h:g}"] = cell([r for r in runs if r["dt_ms"] == h and r["iterations"] == 10])
    for h in iter_steps_ms:
        for it in iterations:
            summary["by_iterations"][f"{h:g}/{it}"] = cell([r for r in runs if r["dt_ms"] == h
                                                             and r["iterations"] == it])
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=True)
    mean = [summary["by_step"][f"{x:g}"]["slope"]["mean"] for x in steps_ms]
    sd = [summary["by_step"][f"{x:g}"]["slope"]["sd"] for x in steps_ms]
    axes[0].errorbar(steps_ms, mean, yerr=sd, marker="o", capsize=3)
    axes[0].set_xlabel("step (ms), 10 iterations")
    for h in iter_steps_ms:
        mean = [summary["by_iterations"][f"{h:g}/{it}"]["slope"]["mean"] for it in iterations]
        sd = [summary["by_iterations"][f"{h:g}/{it}"]["slope"]["sd"] for it in iterations]
        axes[1].errorbar(iterations, mean, yerr=sd, marker="o", capsize=3, label=f"{h:g} ms step")
    axes[1].set_xlabel("solver iterations")
    axes[1].legend(fontsize=8)
    for ax in axes:
        ax.set_xscale("log", base=2)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"slope at {rpm:g} rpm (deg)")
    fig.suptitle(f"pymunk twin, cut-disc rig: slope vs step and iterations ({len(seeds)} seeds, mean +- sd)")
    fig.tight_layout()
    fig.savefig(out_dir / "pymunk_convergence.png", dpi=110)
    plt.close(fig)
    return {"runs": runs, **summary}


def segregation(out_dir: Path, seeds=(0, 1, 2, 3), rpms=(5.0, 10.0, 20.0), duration_s: float = 30.0) -> dict:
    """Radial segregation (spread ratio white/blue) and MI against rpm for the disc/disc and the
    cut-disc/disc beds, case C, the late third of each run."""
    out: dict = {}
    curves: dict = {}
    for name, cut in (("disc/disc", False), ("cut/disc", True)):
        m = rig(cut)
        out[name] = {}
        for rpm in rpms:
            rs = [series(m, rpm, s, duration_s, engine="pymunk", **CONTACT) for s in seeds]
            curves[(name, rpm)] = rs
            ratio = _ms([_late(r["ratio"]) for r in rs])
            out[name][f"{rpm:g}"] = {
                "ratio": ratio, "mi": _ms([_late(r["mi"]) for r in rs]),
                "slope_deg": _ms([_late(r["slope"]) for r in rs]),
                "ratio_minus_1_over_sd": sd_from_one(ratio["values"]),
                "rtf": float(np.mean([r["rtf"] for r in rs])),
            }
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for name, col in (("disc/disc", "C0"), ("cut/disc", "C3")):
        for j, key in enumerate(("ratio", "mi")):
            mean = [out[name][f"{r:g}"][key]["mean"] for r in rpms]
            sd = [out[name][f"{r:g}"][key]["sd"] for r in rpms]
            axes[j].errorbar(rpms, mean, yerr=sd, marker="o", capsize=3, color=col, label=name)
        rs = curves[(name, rpms[len(rpms) // 2])]
        arr = np.array([r["ratio"] for r in rs])
        axes[2].plot(rs[0]["t"], arr.mean(0), color=col, label=f"{name}, {rpms[len(rpms) // 2]:g} rpm")
        axes[2].fill_between(rs[0]["t"], arr.min(0), arr.max(0), color=col, alpha=0.15)
    axes[0].axhline(1.0, color="k", lw=0.8)
    axes[0].set_ylabel("spread ratio white / blue")
    axes[1].set_ylabel("MI (eq. 4, particles)")
    axes[2].set_ylabel("spread ratio white / blue")
    axes[2].set_xlabel("t (s)")
    for ax in axes[:2]:
        ax.set_xlabel("rpm")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"PMMA rig on pymunk: late third of {duration_s:g} s, {len(seeds)} seeds (mean +- sd)")
    fig.tight_layout()
    fig.savefig(out_dir / "pymunk_segregation.png", dpi=110)
    plt.close(fig)
    return out


def long_runs(cut: bool, seeds, duration_s: float, path: Path, rpm: float = 10.0) -> list[dict]:
    """Long seeded runs of one bed (``cut``: the cut-disc/disc bed, else disc/disc; case C, ``CONTACT``):
    each seed's time series (t, spread ratio, MI, slope every 0.5 s) appended to ``path`` (JSON lines)
    as it finishes, so a run cut short keeps its finished seeds."""
    m = rig(cut)
    out = []
    for s in seeds:
        r = series(m, rpm, s, duration_s, engine="pymunk", **CONTACT)
        row = {"bed": "cut/disc" if cut else "disc/disc", "rpm": rpm, "seed": int(s), "duration_s": duration_s,
               **{k: [float(x) for x in r[k]] for k in ("t", "ratio", "mi", "slope")}, "rtf": r["rtf"]}
        with path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        out.append(row)
    return out


def window_mean(row: dict, key: str, from_s: float) -> float:
    """The mean of one run's ``key`` series (``long_runs``' rows) over ``t >= from_s``."""
    t, v = np.asarray(row["t"], float), np.asarray(row[key], float)
    return float(np.nanmean(v[t >= from_s]))


BAFFLE_TARGET_MI = 0.85  # the baffles study's time to mix: to this MI (``sim.whatif.time_to_target``)
BAFFLE_LATE_S = 40.0  # ... and its plateau: the MI from this time on


def baffle_summary(runs: list[dict], target_mi: float = BAFFLE_TARGET_MI, late_s: float = BAFFLE_LATE_S) -> dict:
    """One arm of the baffles study (``series`` rows from a case-A start): each run's time to mix,
    ``sim.whatif.time_to_target`` of its MI at ``target_mi`` (the what-if studies' definition: a
    2 s moving average that reaches it and stays there), and its plateau, the mean MI from
    ``late_s`` on; mean and seed sd of each (``_ms``), the spread ratio over the same late window."""
    from sim.whatif import time_to_target

    return {"t_mix_s": _ms([time_to_target(r["t"], r["mi"], target_mi) for r in runs]),
            "plateau_mi": _ms([window_mean(r, "mi", late_s) for r in runs]),
            "ratio": _ms([window_mean(r, "ratio", late_s) for r in runs]),
            "rtf": float(np.mean([r["rtf"] for r in runs])), "target_mi": target_mi, "late_s": late_s}


def plot_baffles(curves: dict[str, list[dict]], path: Path, rpm: float, target_mi: float = BAFFLE_TARGET_MI) -> None:
    """MI against time, seed mean and 10-90 % band per arm, and each seed's time to ``target_mi``."""
    from sim.whatif import time_to_target

    plt = _plt()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [3, 1]})
    for x, ((name, rs), col) in enumerate(zip(curves.items(), ("C0", "C3"), strict=False)):
        arr = np.array([r["mi"] for r in rs])
        ax.plot(rs[0]["t"], arr.mean(0), color=col, label=f"{name} ({len(rs)} seeds)")
        ax.fill_between(rs[0]["t"], np.percentile(arr, 10, 0), np.percentile(arr, 90, 0), color=col, alpha=0.15)
        tm = np.array([time_to_target(r["t"], r["mi"], target_mi) for r in rs])
        bx.scatter(np.full(tm.size, x) + np.linspace(-0.15, 0.15, tm.size), tm, color=col, s=12)
        bx.errorbar([x + 0.3], [np.nanmean(tm)], yerr=[np.nanstd(tm, ddof=1)], color=col, capsize=4, fmt="o")
    ax.axhline(target_mi, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("MI (eq. 4, particles)")
    ax.set_title(f"cut-disc rig from a left/right split, {rpm:g} rpm (band: 10-90 % of seeds)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    bx.set_xticks(range(len(curves)), [n.replace(" lifters ", " lifters\n") for n in curves])
    bx.set_ylabel(f"time to MI {target_mi:g} (s)")
    bx.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def baffles(out_dir: Path, seeds=tuple(range(16)), rpm: float = 10.0, duration_s: float = 60.0,
            lifters: Baffles = RIG_TALL_BAFFLES) -> dict:
    """The cut-disc rig from case A (blue left, white right) at ``rpm``, plain and with ``lifters``,
    one run per seed each: ``baffle_summary`` of each arm and how many standard errors apart the
    arms' times to mix and plateaus are (``difference_in_se``); the plot ``pymunk_baffles.png``."""
    curves = {}
    label = f"{lifters.count} lifters {lifters.height_m * 1e3:g} mm"
    for name, bf in (("plain", None), (label, lifters)):
        curves[name] = [series(rig(True, bf), rpm, s, duration_s, case="A", every_s=0.25, **CONTACT) for s in seeds]
    out: dict = {name: baffle_summary(rs) for name, rs in curves.items()}
    plain, lift = out["plain"], out[label]
    out["t_mix_se"] = difference_in_se(plain["t_mix_s"]["values"], lift["t_mix_s"]["values"])
    out["plateau_se"] = difference_in_se(plain["plateau_mi"]["values"], lift["plateau_mi"]["values"])
    plot_baffles(curves, out_dir / "pymunk_baffles.png", rpm)
    return out


def dem(seeds=(0, 1, 2), rpm: float = 10.0, duration_s: float = 20.0) -> dict:
    """The disc/disc rig on both engines at their default steps: slope, plateau MI, speed."""
    m = rig(False)
    out = {}
    for engine in ("dem", "pymunk"):
        rs = [series(m, rpm, s, duration_s, engine=engine, spin_up_s=2.0, **CONTACT) for s in seeds]
        out[engine] = {"slope_deg": _ms([float(np.nanmean(r["slope"])) for r in rs]),
                       "plateau_mi": _ms([_late(r["mi"]) for r in rs]),
                       "ratio": _ms([_late(r["ratio"]) for r in rs]),
                       "rtf": _ms([r["rtf"] for r in rs]), "dt_ms": rs[0]["dt_ms"],
                       "overlap_p99_r": float(np.mean([r["overlap_p99_r"] for r in rs]))}
    return out


def calibration(rpm: float = 10.0, targets=(25.0, 32.0, 45.0)) -> dict:
    """``sim.calibrate.calibrate`` on the cut-disc rig (pymunk, its plates searched: a monolayer) at
    ``rpm``: for each target the fit, or the one-line error naming the range, and the CPU time."""
    m = rig(True)
    out: dict = {"fits": {}}
    for target in targets:
        t0 = time.process_time()
        try:
            out["fits"][f"{target:g}"] = cal.calibrate(target, rpm, mixer=m, engine="pymunk").as_dict()
        except SimError as exc:
            out["fits"][f"{target:g}"] = {"error": str(exc), "exit": 2}
        out["fits"][f"{target:g}"]["cpu_s"] = time.process_time() - t0
    return out


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in (*SECTIONS, "all"):
        raise SystemExit(f"usage: python -m sim.validation_pymunk {{{'|'.join(SECTIONS)}|all}} [OUT_DIR]")
    out_dir = Path(args[1] if len(args) > 1 else "docs/img")
    out_dir.mkdir(parents=True, exist_ok=True)
    todo = SECTIONS if args[0] == "all" else (args[0],)
    summary: dict = {}
    for s in todo:
        t0 = time.perf_counter()
        try:
            if s == "convergence":
                summary[s] = convergence(out_dir)
            elif s == "segregation":
                summary[s] = segregation(out_dir)
            elif s == "baffles":
                summary[s] = baffles(out_dir)
            elif s == "dem":
                summary[s] = dem()
            else:
                summary[s] = calibration()
        except SimError as exc:
            raise SystemExit(f"error: {exc}") from None
        summary[s]["wall_s"] = time.perf_counter() - t0
    print(json.dumps(summary, indent=1, default=float))


if __name__ == "__main__":
    main()


__all__ = [
    "BAFFLE_LATE_S",
    "BAFFLE_TARGET_MI",
    "CONTACT",
    "RIG_BAFFLES",
    "RIG_CONFIG",
    "RIG_TALL_BAFFLES",
    "SECTIONS",
    "SEGREGATION_SD",
    "baffle_summary",
    "baffles",
    "calibration",
    "convergence",
    "dem",
    "difference_in_se",
    "long_runs",
    "main",
    "plot_baffles",
    "rig",
    "sd_from_one",
    "segregates",
    "segregation",
    "series",
    "window_mean",
]

"""Regenerate the numbers and plots of docs/validation.md.

``python -m sim.validation SECTION [OUT_DIR]`` with SECTION one of ``convergence``, ``step-box``,
``cases``, ``case-a-seeds``, ``case-a-long``, ``plateau``, ``calibration``, ``reach``, ``transfer``, ``branch``,
``power``, ``all``. Every run is
seeded; each section prints a JSON summary on stdout and writes its plot(s) to OUT_DIR
(default ``docs/img``). Run it with ``nice`` and one worker on a shared machine.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from sim.drum import DrumSim
from sim.errors import SimError
from sim.measure import particle_mi, twin_meter
from sim.probe import probe
from sim.recipe import PAPER_DRUM, PAPER_RECIPE
from sim.render import Renderer
from sim.whatif import WhatIfJob, run_study, summarize

SECTIONS = ("convergence", "step-box", "cases", "case-a-seeds", "case-a-long", "plateau", "calibration", "reach",
            "transfer", "branch", "power")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def slope_run(rpm: float, seed: int, duration_s: float = 20.0, spin_up_s: float = 2.0, **sim_kwargs) -> dict:
    """Mean free-surface slope (after ``spin_up_s``), MI (eq. 4) over the second half, overlap p99,
    wall depth and speed of one case C run."""
    sim = DrumSim(case="C", seed=seed, rpm=rpm, **sim_kwargs)
    t0 = time.perf_counter()
    slopes, mis = [], []
    n = int(round(duration_s / 0.1))
    for i, smp in enumerate(probe(sim, n * 0.1, 0.1, spin_up_s=spin_up_s)):
        if i == 0:  # the start, after the spin-up: the clock starts here
            t0 = time.perf_counter()
            continue
        slopes.append(smp.surface.slope_deg)
        if i > n // 2:
            mis.append(smp.mi.mi)
    wall = time.perf_counter() - t0
    st = sim.stats()
    return {"rpm": rpm, "seed": seed, "dt_ms": sim.substep_s() * 1e3,
            "slope_deg": float(np.nanmean(slopes)), "mi_late": float(np.nanmean(mis)),
            "overlap_p99_r": st.overlap_p99_r, "overlap_max_r": st.overlap_max_r, "wall_max_mm": st.wall_max_mm,
            "rtf": duration_s / wall}


def convergence(seeds=(0, 1, 2, 3), steps_per_contact=(3, 4, 5, 8, 10, 20, 40), stiffness_x=(0.5, 2.0),
                duration_s: float = 30.0) -> dict:
    """Case C at 5 rpm: slope, late MI, overlap and wall depth against the step (fractions of the
    contact time) and, at the default step fraction, against the contact stiffness."""
    from sim.drum import STEPS_PER_CONTACT, bed_contact_time_s
    from sim.params import DEFAULT_STIFFNESS_N_M
    from sim.recipe import PAPER_RECIPE, slice_2d

    t_c = bed_contact_time_s(slice_2d(PAPER_RECIPE, PAPER_DRUM), DEFAULT_STIFFNESS_N_M, 0.5)
    by_step = [{**slope_run(5.0, s, duration_s, dt_s=t_c / k), "steps_per_contact": k}
               for k in steps_per_contact for s in seeds]
    by_stiffness = []
    for x in stiffness_x:
        k_n = x * DEFAULT_STIFFNESS_N_M
        h = bed_contact_time_s(slice_2d(PAPER_RECIPE, PAPER_DRUM), k_n, 0.5) / STEPS_PER_CONTACT
        by_stiffness += [{**slope_run(5.0, s, duration_s, dt_s=h, stiffness_n_m=k_n), "stiffness_n_m": k_n}
                         for s in seeds]
    return {"contact_time_ms": t_c * 1e3, "by_step": by_step, "by_stiffness": by_stiffness}


def step_box(points=((0.25, 0.1), (0.154, 0.489), (1.0, 0.0), (0.5, 1.0)), seeds=tuple(range(12)),
             steps_per_contact=(4, 8, 16), rpm: float = 5.0, window_s: float = 10.0) -> list[dict]:
    """The step's convergence over the calibration's box, not only at the paper's materials: the mean slope
    (and its standard error over ``seeds``) at the contact time over each of ``steps_per_contact``, at each
    (sliding, rolling) point, for the paper bed and for a monolayer of discs without plate friction
    (``configs/pmma-cutdisc.toml`` with round discs, the plates' friction 0: the plane a monolayer is searched in)."""
    from sim.calibrate import twin_surface
    from sim.drum import STEPS_PER_CONTACT
    from sim.engine import make_twin
    from sim.validation_pymunk import rig

    beds: dict[str, tuple[dict[str, Any], float]] = {
        "paper": ({}, DrumSim(settle_s=0.0).substep_s()),
            "monolayer": ({"mixer": rig(cut=False), "end_friction": 0.0},
                          make_twin(rig(cut=False), settle_s=0.0).substep_s())}
    out = []
    for bed, (kw, dt) in beds.items():
        t_c = dt * STEPS_PER_CONTACT  # the bed's contact time, s
        for f, r in points:
            for k in steps_per_contact:
                v = [abs(twin_surface(f, r, rpm, seed=s, window_s=window_s, dt_s=t_c / k, **kw)[0]) for s in seeds]
                out.append({"bed": bed, "friction": f, "rolling": r, "steps_per_contact": k, "dt_ms": t_c / k * 1e3,
                            "slope_deg": float(np.mean(v)), "sem_deg": float(np.std(v, ddof=1) / np.sqrt(len(v)))})
    return out


def case_curves(case: str, seed: int, duration_s: float, rpm: float = 5.0, every_s: float = 1.0) -> dict:
    """Particle eq. 1 / 3 / 4 and vision eq. 4 against time for one case and seed."""
    sim = DrumSim(case=case, seed=seed, rpm=rpm)
    r = Renderer(sim, 360)
    meter = twin_meter(r)
    out: dict = {"t": [], "mi": [], "mi_sig": [], "mi_lin": [], "mi_vision": []}
    d0 = None
    for smp in probe(sim, int(round(duration_s / every_s)) * every_s, every_s):
        p = smp.particles
        m = particle_mi(p, PAPER_DRUM, d0)
        if d0 is None:
            d0 = m.d_px
            m = particle_mi(p, PAPER_DRUM, d0)
        frame = r.render(p)
        assert frame is not None  # a renderer without realism never drops a frame
        rd = meter.measure(frame)
        out["t"].append(smp.sim_t_s)
        out["mi"].append(m.mi)
        out["mi_sig"].append(m.mi_sigmoid)
        out["mi_lin"].append(m.mi_linear)
        out["mi_vision"].append(rd.mi)
    return {k: np.asarray(v, float) for k, v in out.items()}


def snapshots(case: str, times_s: tuple[float, ...], path: Path, seed: int = 0) -> None:
    """Rendered frames of one run side by side, labelled with case and time."""
    import cv2

    sim = DrumSim(case=case, seed=seed, rpm=5.0)
    r = Renderer(sim, 300)
    imgs = []
    for t in times_s:
        sim.advance(t - sim.t_s)
        img = r.render(sim.particles())
        assert img is not None
        cv2.putText(img, f"{case} t={t:g}s", (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
        imgs.append(img)
    cv2.imwrite(str(path), np.hstack(imgs))


def cases(out_dir: Path, seeds=tuple(range(8)), duration_s: float = 60.0, last_s: float = 20.0) -> dict:
    """Paper Fig. 5/6 through the same meter: cases A, B, C at 5 rpm, means over the last ``last_s`` (and their
    standard errors over ``seeds``: one seed's 20 s mean scatters by about 0.1, docs/validation.md section 4)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    summary = {}
    for ax, case in zip(axes, "ABC", strict=True):
        runs = [case_curves(case, s, duration_s) for s in seeds]
        t = runs[0]["t"]
        tail = t >= duration_s - last_s
        for key, lab, col in (("mi", "eq. 4", "C0"), ("mi_sig", "eq. 3", "C1"), ("mi_lin", "eq. 1", "C2"),
                              ("mi_vision", "eq. 4 vision", "C3")):
            arr = np.array([r[key] for r in runs])
            ax.plot(t, arr.mean(0), color=col, lw=1.3, label=lab, ls="--" if key == "mi_vision" else "-")
            ax.fill_between(t, arr.min(0), arr.max(0), color=col, alpha=0.12)
        ax.set_title(f"case {case}, 5 rpm ({len(seeds)} seeds)")
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
        summary[case] = {
            k: float(np.mean([np.nanmean(r[k][tail]) for r in runs])) for k in ("mi", "mi_sig", "mi_lin", "mi_vision")
        }
        summary[case].update({f"{k}_sem": float(np.std([np.nanmean(r[k][tail]) for r in runs], ddof=1)
                                                 / np.sqrt(len(runs))) for k in ("mi", "mi_sig", "mi_lin")})
        summary[case]["mi_start"] = float(np.mean([r["mi"][0] for r in runs]))
        summary[case]["mi_sig_start"] = float(np.mean([r["mi_sig"][0] for r in runs]))
    axes[0].set_ylabel("MI")
    axes[0].set_ylim(-0.2, 1.02)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(out_dir / "validation-cases.png", dpi=110)
    plt.close(fig)
    snapshots("C", (0.0, 20.0, 40.0, duration_s), out_dir / "validation-snapshots-C.png")
    snapshots("A", (0.0, 10.0, 30.0, duration_s), out_dir / "validation-snapshots-A.png")
    return summary


def case_a_seeds(seeds=tuple(range(16)), duration_s: float = 60.0, last_s: float = 20.0) -> dict:
    """Case A at 5 rpm, many seeds: each seed's eq. 4 / 3 / 1 over the last ``last_s`` (particles, 1 s samples),
    their mean and standard error, and the means of consecutive seed pairs (what a two-seed run reports)."""
    keys = ("mi", "mi_sig", "mi_lin")
    per = {}
    for seed in seeds:
        sim = DrumSim(case="A", seed=seed, rpm=5.0)
        rows, d0 = [], None
        for smp in probe(sim, duration_s, 1.0):
            m = particle_mi(smp.particles, PAPER_DRUM, d0)
            if d0 is None:
                d0 = m.d_px
                m = particle_mi(smp.particles, PAPER_DRUM, d0)
            rows.append((smp.t_s, m.mi, m.mi_sigmoid, m.mi_linear))
        a = np.asarray(rows)
        tail = a[:, 0] >= duration_s - last_s
        per[seed] = {k: float(np.nanmean(a[tail, i + 1])) for i, k in enumerate(keys)}
    v = np.array([[per[s][k] for k in keys] for s in seeds])
    pairs = [float(np.mean(v[i:i + 2, 0])) for i in range(len(seeds) - 1)]
    return {"seeds": per, "mean": dict(zip(keys, v.mean(0).tolist(), strict=True)),
            "sem": dict(zip(keys, (v.std(0, ddof=1) / np.sqrt(len(seeds))).tolist(), strict=True)),
            "pair_means_eq4": pairs}


def case_a_long(seeds=(0, 1, 2, 3), duration_s: float = 120.0, last_s: float = 20.0) -> dict:
    """Case A at 5 rpm run twice as long as the paper: eq. 4 / 3 / 1 over the last ``last_s`` per seed."""
    out: dict = {}
    for seed in seeds:
        r = case_curves("A", seed, duration_s, every_s=0.5)
        tail = r["t"] >= duration_s - last_s
        out[seed] = {k: float(np.nanmean(r[k][tail])) for k in ("mi", "mi_sig", "mi_lin")}
    out["mean"] = {k: float(np.mean([out[s][k] for s in seeds])) for k in ("mi", "mi_sig", "mi_lin")}
    return out


def plateau(out_dir: Path, rpms=(5, 10, 20, 30, 40, 50, 60), seeds=(0, 1, 2), duration_s: float = 60.0) -> list[dict]:
    """Plateau MI (last third) against rpm, case C, several seeds; regime from the flow."""
    plt = _plt()
    jobs = [WhatIfJob(rpm=float(r), duration_s=duration_s, case="C", seed=s, sample_s=0.5) for r in rpms for s in seeds]
    results = run_study(jobs, workers=1)
    summ = summarize(results)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 3.8))
    x = [e["rpm"] for e in summ]
    y = [e["plateau_mi"] for e in summ]
    ax1.errorbar(x, y, yerr=[e["plateau_mi_sem"] for e in summ], fmt="o-", capsize=3, label="mean, +-1 s.e. (seeds)")
    for r in results:
        ax1.plot(r.job.rpm, r.plateau_mi, ".", color="0.6")
    for e in summ:
        ax1.annotate(e["regime"][:4], (e["rpm"], e["plateau_mi"]), textcoords="offset points", xytext=(0, 8),
                     fontsize=7, ha="center")
    ax1.set_xlabel("rpm")
    ax1.set_ylabel("plateau MI (eq. 4, particles)")
    ax1.set_title(f"case C, last {duration_s / 3:g} s, {len(seeds)} seeds (grey: each seed)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=8)
    cmap = plt.get_cmap("viridis")
    for i, rpm in enumerate(rpms):
        r = next(rr for rr in results if rr.job.rpm == rpm)
        ax2.plot(r.t_s, r.mi, color=cmap(i / max(1, len(rpms) - 1)), lw=0.9, label=f"{rpm} rpm")
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("MI (eq. 4), seed 0")
    ax2.legend(fontsize=7, ncol=2)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "validation-plateau-rpm.png", dpi=110)
    plt.close(fig)
    return summ


def power(out_dir: Path, rpms=(2, 5, 10, 20, 30, 40, 50, 60), seeds=(0, 1, 2), duration_s: float = 30.0,
          target_mi: float = 0.6) -> list[dict]:
    """Drive power, torque and time to ``target_mi`` against rpm for the paper bed from a segregated start
    (case A), with the seed spread; beside each rpm the torque of a rigid bed held at the measured slope
    (``sim.power.rigid_bed_torque_nm``: the 3D bed's weight x the lever arm of a circular segment's
    centroid) and the flowing bed's own weight moment; a plot of power against rpm."""
    from sim.power import class_masses_kg, depth_scale, gravity_torque_nm, rigid_bed_torque_nm

    plt = _plt()
    jobs = [WhatIfJob(rpm=float(r), duration_s=duration_s, case="A", seed=s, sample_s=0.25, target_mi=target_mi)
            for r in rpms for s in seeds]
    results = run_study(jobs, workers=1)
    rows = summarize(results)
    sim = DrumSim(case="C", seed=0, rpm=5.0, settle_s=0.2)
    mass = class_masses_kg(sim)[0][sim.particles().cls]
    bed_kg = float(mass.sum()) * depth_scale(sim)
    for row in rows:
        rs = [r for r in results if r.job.rpm == row["rpm"]]
        slope = float(np.nanmean([np.nanmean(r.slope_deg[-max(1, r.slope_deg.size // 3):]) for r in rs]))
        row["slope_deg"] = slope
        row["rigid_torque_nm"] = rigid_bed_torque_nm(bed_kg, PAPER_RECIPE.fill, PAPER_DRUM.radius_m, slope)
        row["torque_over_rigid"] = row["torque_nm"] / row["rigid_torque_nm"]
    # the flowing bed against its own weight moment (angular momentum balance), seed 0 at each rpm
    for row in rows:
        twin = DrumSim(case="A", seed=0, rpm=row["rpm"])
        samples = list(probe(twin, 10.0, 0.1, spin_up_s=5.0, include_start=False))
        tq = float(np.mean([s.bed_torque_nm for s in samples]))
        wm = float(np.mean([gravity_torque_nm(s.particles, mass) for s in samples]))
        row["torque_over_weight_moment"] = tq / wm
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 3.8))
    x = [e["rpm"] for e in rows]
    ax1.errorbar(x, [e["power_w"] for e in rows], yerr=[e["power_sd_w"] for e in rows], fmt="o-", capsize=3,
                 label="twin (mean +- sd of seeds)")
    ax1.plot(x, [e["rigid_torque_nm"] * e["rpm"] * 2 * np.pi / 60 for e in rows], "s--", color="0.5",
             label="rigid bed at the twin's slope")
    ax1.set_xlabel("rpm")
    ax1.set_ylabel("drive power (W, 300 x 100 mm drum)")
    ax1.set_title(f"paper bed, plateau part of {duration_s:g} s, {len(seeds)} seeds")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=8)
    ax2.errorbar(x, [e["time_to_target_s"] for e in rows], yerr=[e["time_to_target_sd_s"] for e in rows],
                 fmt="o-", capsize=3, label=f"time to MI {target_mi:g}")
    ax2b = ax2.twinx()
    ax2b.plot(x, [e["energy_to_target_j"] for e in rows], "^-", color="C1", label="energy to it")
    ax2.set_xlabel("rpm")
    ax2.set_ylabel("time to target (s), from case A")
    ax2b.set_ylabel("energy to target (J)", color="C1")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8, loc="upper center")
    fig.tight_layout()
    fig.savefig(out_dir / "validation-power-rpm.png", dpi=110)
    plt.close(fig)
    return rows


def calibration(rpm: float = 10.0, targets=(20.0, 30.0, 40.0, 45.0, 75.0)) -> list[dict]:
    """Calibration reach at ``rpm``: each target's fit, or the out-of-range error."""
    from sim.calibrate import calibrate

    out = []
    for tgt in targets:
        t0 = time.perf_counter()
        try:
            cal = calibrate(tgt, rpm)
            out.append({**cal.as_dict(), "wall_s": time.perf_counter() - t0})
        except SimError as exc:
            out.append({"target_slope_deg": tgt, "error": str(exc), "wall_s": time.perf_counter() - t0})
    return out


def reach(rpms=(2.0, 5.0, 10.0, 20.0)) -> list[dict]:
    """The reachable range per rpm (``sim.calibrate.reachable_range``, seed 0, default windows) of a deep drum
    (the paper's bed) and of monolayers (the disc/disc variant of ``configs/pmma-cutdisc.toml``, 3 mm discs, and
    ``configs/pmma-rig.toml``, discs as thick as wide), with the CPU time of each."""
    import tomllib

    from sim.calibrate import reachable_range
    from sim.mixer import paper_mixer, parse_mixer
    from sim.validation_pymunk import rig

    table = tomllib.loads(Path("configs/pmma-rig.toml").read_text())
    beds = {"paper": paper_mixer(), "discs 3 mm": rig(cut=False),
            "pmma-rig": parse_mixer(table, [c["name"] for c in table["classes"]])}
    out = []
    for name, mixer in beds.items():
        for rpm in rpms:
            t0 = time.process_time()
            lo, hi = reachable_range(rpm, mixer=mixer)
            out.append({"bed": name, "rpm": rpm, "range_deg": [lo, hi], "cpu_s": time.process_time() - t0})
    return out


def transfer(cal_rpm: float = 10.0, other_rpms=(5.0, 20.0, 40.0), plant: tuple[float, float] = (0.6, 0.3),
             seeds=(0, 1)) -> dict:
    """Calibrate at ``cal_rpm`` to a plant twin with other parameters; compare slopes at other rpm."""
    from sim.calibrate import calibrate, twin_slope_deg

    def slope(f: float, r: float, rpm: float) -> float:
        return float(np.mean([twin_slope_deg(f, r, rpm, seed=100 + s, window_s=8.0) for s in seeds]))

    target = slope(*plant, cal_rpm)
    cal = calibrate(target, cal_rpm)
    rows = [{"rpm": rpm, "plant_slope_deg": slope(*plant, rpm), "twin_slope_deg": slope(cal.friction, cal.rolling, rpm)}
            for rpm in (cal_rpm, *other_rpms)]
    return {"plant": {"friction": plant[0], "rolling": plant[1]}, "target_slope_deg": target,
            "fit": cal.as_dict(), "rows": rows}


def branch(out_dir: Path, seeds=(0, 1), pre_s: float = 60.0, post_s: float = 40.0, rpms=(5.0, 20.0, 45.0)) -> dict:
    """From a bed segregated at 5 rpm, branch: stay at 5 rpm (OFF) or go faster (what AUTO does)."""
    plt = _plt()
    curves: dict = {r: [] for r in rpms}
    for seed in seeds:
        sim = DrumSim(case="C", seed=seed, rpm=5.0)
        sim.advance(pre_s)
        state = sim.snapshot()
        res = run_study([WhatIfJob(rpm=r, duration_s=post_s, start=state, sample_s=0.5) for r in rpms], workers=1)
        for r, rr in zip(rpms, res, strict=True):
            curves[r].append((rr.t_s, rr.mi))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    out = {}
    for r, col in zip(rpms, ("C3", "C1", "C2"), strict=False):
        t = curves[r][0][0]
        y = np.mean([c[1] for c in curves[r]], axis=0)
        ax.plot(t, y, color=col, label=f"{r:g} rpm" + (" (OFF)" if r == 5.0 else ""))
        vals = [float(np.mean(c[1][t >= post_s / 2])) for c in curves[r]]
        out[r] = {"mean": float(np.mean(vals)), "seeds": vals}
    ax.set_xlabel(f"t after {pre_s:g} s at 5 rpm (s)")
    ax.set_ylabel("MI (eq. 4, particles)")
    ax.set_title(f"branching a segregated bed ({len(seeds)} seeds, mean)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "validation-branch.png", dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] not in (*SECTIONS, "all"):
        raise SystemExit(f"usage: python -m sim.validation {{{'|'.join(SECTIONS)}|all}} [OUT_DIR]")
    section = args[0]
    out_dir = Path(args[1] if len(args) > 1 else "docs/img")
    out_dir.mkdir(parents=True, exist_ok=True)
    todo = SECTIONS if section == "all" else (section,)
    summary: dict = {}
    for s in todo:
        t0 = time.perf_counter()
        if s == "convergence":
            summary[s] = convergence()
        elif s == "step-box":
            summary[s] = step_box()
        elif s == "case-a-seeds":
            summary[s] = case_a_seeds()
        elif s == "reach":
            summary[s] = reach()
        elif s == "cases":
            summary[s] = cases(out_dir)
        elif s == "case-a-long":
            summary[s] = case_a_long()
        elif s == "plateau":
            summary[s] = plateau(out_dir)
        elif s == "calibration":
            summary[s] = calibration()
        elif s == "power":
            summary[s] = power(out_dir)
        elif s == "transfer":
            # plants at both ends of the (sliding, rolling) plane and one near the top of the range
            summary[s] = [transfer(plant=p) for p in ((0.5, 0.05), (0.15, 0.6), (0.6, 0.3))]
        elif s == "branch":
            summary[s] = branch(out_dir)
        summary[f"{s}_wall_s"] = time.perf_counter() - t0
        print(json.dumps({s: summary[s]}, default=float), flush=True)


if __name__ == "__main__":
    main()


__all__ = ["SECTIONS", "branch", "calibration", "case_a_long", "case_a_seeds", "case_curves", "cases", "convergence",
           "main", "plateau", "power", "reach", "slope_run", "snapshots", "step_box", "transfer"]

"""Regenerate the numbers and plots of docs/validation.md: ``python -m sim.validation docs/img``.

Runs (seeded): cases A/B/C at 5 rpm (particle-level eq. 3/4 and the vision meter on
rendered frames), plateau MI against rpm (case C, several seeds), snapshots, and
the what-if speed-up on 2 workers against 1. Prints a JSON summary on stdout.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from sim.drum import DrumSim
from sim.measure import particle_mi, twin_meter
from sim.recipe import PAPER_DRUM
from sim.render import Renderer
from sim.whatif import WhatIfJob, run_study, summarize


def case_curves(case: str, seed: int, duration_s: float, rpm: float = 5.0, every_s: float = 1.0) -> dict:
    """Particle eq. 4 / eq. 3 and vision eq. 4 against time for one case and seed."""
    sim = DrumSim(case=case, seed=seed, rpm=rpm)
    r = Renderer(sim, 360)
    meter = twin_meter(r)
    out = {"t": [], "mi": [], "mi_sig": [], "mi_vision": [], "mi_sig_vision": []}
    n = int(round(duration_s / every_s))
    for i in range(n + 1):
        if i:
            sim.advance(every_s)
        p = sim.particles()
        m = particle_mi(p, PAPER_DRUM)
        rd = meter.measure(r.render(p))
        out["t"].append(sim.t_s)
        out["mi"].append(m.mi)
        out["mi_sig"].append(m.mi_sigmoid)
        out["mi_vision"].append(rd.mi)
        out["mi_sig_vision"].append(rd.mi_sigmoid)
    return {k: np.asarray(v) for k, v in out.items()}


def snapshots(case: str, times_s: list[float], path: Path, seed: int = 0) -> None:
    import cv2

    sim = DrumSim(case=case, seed=seed, rpm=5.0)
    r = Renderer(sim, 300)
    imgs = []
    for t in times_s:
        sim.advance(t - sim.t_s)
        img = r.render(sim.particles())
        cv2.putText(img, f"{case} t={t:g}s", (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
        imgs.append(img)
    cv2.imwrite(str(path), np.hstack(imgs))


def branch_plot(path: Path, seeds=(0, 1, 2), pre_s: float = 90.0, post_s: float = 60.0) -> dict:
    """From a bed segregated at 5 rpm, branch: stay at 5 rpm (OFF) or go to 30/50 rpm (AUTO)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves: dict = {5.0: [], 30.0: [], 50.0: []}
    for seed in seeds:
        sim = DrumSim(case="C", seed=seed, rpm=5.0)
        sim.advance(pre_s)
        state = sim.snapshot()
        for rpm in curves:
            b = DrumSim.from_state(state)
            b.set_rpm(rpm)
            ts, ys = [], []
            for _ in range(int(post_s / 0.5)):
                b.advance(0.5)
                ts.append(b.t_s - pre_s)
                ys.append(particle_mi(b.particles(), PAPER_DRUM).mi)
            curves[rpm].append((np.array(ts), np.array(ys)))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    out = {}
    for rpm, col in zip(curves, ("C3", "C1", "C2")):
        t = curves[rpm][0][0]
        y = np.mean([c[1] for c in curves[rpm]], axis=0)
        ax.plot(t, y, color=col, label=f"{rpm:g} rpm" + (" (OFF)" if rpm == 5.0 else " (AUTO)"))
        out[rpm] = float(np.mean([c[1][t >= post_s / 2].mean() for c in curves[rpm]]))
    ax.set_xlabel(f"t after {pre_s:g} s at 5 rpm (s)")
    ax.set_ylabel("MI (eq. 4, particles)")
    ax.set_title(f"branching a segregated bed ({len(seeds)} seeds, mean)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    args = sys.argv[1:] if argv is None else argv
    out_dir = Path(args[0] if args else "docs/img")
    quick = "--quick" in args
    out_dir.mkdir(parents=True, exist_ok=True)
    dur = 60.0 if quick else 180.0
    seeds = [0, 1] if quick else [0, 1, 2]
    summary: dict = {"cases": {}}

    # 1. cases A/B/C at 5 rpm
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for ax, case in zip(axes, "ABC"):
        runs = [case_curves(case, s, dur) for s in seeds]
        t = runs[0]["t"]
        tail = t >= 2 * dur / 3
        for key, lab, col in (("mi", "eq. 4 particles", "C0"), ("mi_sig", "eq. 3 particles", "C1"),
                              ("mi_vision", "eq. 4 vision", "C2")):
            arr = np.array([r[key] for r in runs])
            ax.plot(t, arr.mean(0), color=col, lw=1.4, label=lab)
            ax.fill_between(t, arr.min(0), arr.max(0), color=col, alpha=0.15)
        ax.set_title(f"case {case}, 5 rpm ({len(seeds)} seeds)")
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
        summary["cases"][case] = {
            "mi_start": float(np.mean([r["mi"][0] for r in runs])),
            "mi_end_eq4": float(np.mean([r["mi"][tail].mean() for r in runs])),
            "mi_end_eq3": float(np.mean([r["mi_sig"][tail].mean() for r in runs])),
            "mi_end_vision_eq4": float(np.mean([r["mi_vision"][tail].mean() for r in runs])),
            "mi_end_vision_eq3": float(np.mean([r["mi_sig_vision"][tail].mean() for r in runs])),
            "max_abs_vision_minus_particles": float(max(np.max(np.abs(r["mi_vision"] - r["mi"])) for r in runs)),
        }
    axes[0].set_ylabel("MI")
    axes[0].set_ylim(0, 1.02)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(out_dir / "validation-cases.png", dpi=110)
    plt.close(fig)

    snapshots("C", [0, 30, 90, dur], out_dir / "validation-snapshots-C.png")
    snapshots("A", [0, 10, 60, dur], out_dir / "validation-snapshots-A.png")

    # 2. plateau MI against rpm
    rpms = [2, 5, 10, 20, 30, 40, 50, 60, 70] if not quick else [5, 20, 40, 60]
    jobs = [WhatIfJob(rpm=float(r), duration_s=120.0 if not quick else 60.0, case="C", seed=s, sample_s=0.5)
            for r in rpms for s in seeds]
    t0 = time.perf_counter()
    results = run_study(jobs, workers=None)
    summary["study_wall_s"] = time.perf_counter() - t0
    summ = summarize(results)
    summary["plateau"] = summ
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 3.8))
    x = [e["rpm"] for e in summ]
    ax1.errorbar(x, [e["plateau_mi"] for e in summ], yerr=[e["plateau_mi_sd"] for e in summ], fmt="o-", capsize=3)
    for e in summ:
        ax1.annotate(e["regime"][:4], (e["rpm"], e["plateau_mi"]), textcoords="offset points", xytext=(0, 8),
                     fontsize=7, ha="center")
    ax1.set_xlabel("rpm")
    ax1.set_ylabel("plateau MI (eq. 4, particles)")
    ax1.set_title("case C, last third of the run")
    ax1.grid(alpha=0.3)
    cmap = plt.get_cmap("viridis")
    for i, rpm in enumerate(rpms):
        r = next(rr for rr in results if rr.job.rpm == rpm)
        ax2.plot(r.t_s, r.mi, color=cmap(i / max(1, len(rpms) - 1)), lw=0.9, label=f"{rpm} rpm")
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("MI (eq. 4)")
    ax2.legend(fontsize=7, ncol=2)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / "validation-plateau-rpm.png", dpi=110)
    plt.close(fig)

    summary["branch_mi_second_half"] = branch_plot(out_dir / "validation-branch.png")

    # 3. what-if speed-up, 2 workers against 1
    sjobs = [WhatIfJob(rpm=5.0, duration_s=40.0, seed=s) for s in range(4)]
    t0 = time.perf_counter()
    run_study(sjobs, workers=1)
    t1 = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_study(sjobs, workers=2)
    t2 = time.perf_counter() - t0
    summary["speedup_2_vs_1"] = t1 / t2
    summary["study_1_worker_s"] = t1
    summary["study_2_workers_s"] = t2
    print(json.dumps(summary, indent=1, default=float))


if __name__ == "__main__":
    main()

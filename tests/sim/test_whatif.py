"""What-if studies: local pool, Froude regimes, and a real Dask scheduler + worker on loopback."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sim.errors import SimError
from sim.whatif import WhatIfJob, flow_regime, froude, froude_regime, regime, run_study, summarize
from tests.waiting import wait_until

DASK = Path(sys.executable).with_name("dask")


def test_regimes_by_froude_number():
    assert froude(5.0) == pytest.approx((5 * 2 * np.pi / 60) ** 2 * 0.15 / 9.81)
    assert [froude_regime(r) for r in (0.5, 5.0, 20.0, 40.0, 77.0)] == [
        "slumping", "rolling", "cascading", "cataracting", "cataracting"]
    assert froude_regime(80.0) == "centrifuging" == regime(80.0)


def test_regime_from_a_synthetic_flow():
    # flat surface, nothing flying: rolling; S-shaped surface: cascading; disks in flight: cataracting
    assert flow_regime(0.0, 0.0) == "rolling"
    assert flow_regime(0.01, 0.2) == "cascading"
    assert flow_regime(0.3, 0.2) == "cataracting"
    assert flow_regime(0.3, float("nan")) == "cataracting"
    assert flow_regime(0.2, 0.2) == "cascading"  # disks between contacts in a dense flowing layer do not fly
    assert flow_regime(float("nan"), 0.0) == "unknown"


@pytest.mark.timeout(120)
def test_local_pool_gives_the_same_results_as_in_process_and_branches_from_a_state():
    from sim.drum import DrumSim

    jobs = [WhatIfJob(rpm=r, duration_s=1.0, seed=1, sample_s=0.5) for r in (5.0, 30.0)]
    one = run_study(jobs, workers=1)
    two = run_study(jobs, workers=2)
    for a, b in zip(one, two, strict=False):
        assert np.array_equal(a.mi, b.mi)
        assert a.t_s[-1] == pytest.approx(1.0)
        assert a.airborne.shape == a.mi.shape and np.all((a.airborne[1:] >= 0) & (a.airborne[1:] <= 1))
    assert one[1].rpm_actual[-1] == pytest.approx(30.0)
    summ = summarize(one)
    assert [e["rpm"] for e in summ] == [5.0, 30.0]
    assert {"plateau_mi", "plateau_mi_sd", "t_plateau_s", "regime", "froude", "airborne", "curvature"} <= set(summ[0])
    assert summ[0]["regime"] in ("rolling", "cascading", "cataracting") and summ[0]["froude_regime"] == "rolling"
    # branching from "now": the what-if starts at the live twin's state and ramps
    sim = DrumSim(rpm=5.0, case="A")
    sim.advance(0.5)
    state = sim.snapshot()
    res = run_study([WhatIfJob(rpm=25.0, duration_s=1.0, start=state, sample_s=0.25)], workers=1)[0]
    assert res.rpm_actual[0] == pytest.approx(5.0)
    assert 5.0 < res.rpm_actual[-1] <= 25.0
    sim.set_rpm(25.0)
    for _ in range(4):
        sim.advance(0.25)
    assert res.mi[-1] == pytest.approx(sim_mi(sim), abs=1e-12)


def sim_mi(sim):
    from sim.measure import particle_mi

    return particle_mi(sim.particles(), sim.drum).mi


def test_bad_study_input():
    with pytest.raises(SimError, match="critical"):
        run_study([WhatIfJob(rpm=100.0, duration_s=1.0)])
    with pytest.raises(SimError):
        run_study([])
    with pytest.raises(SimError, match="tcp://"):
        run_study([WhatIfJob(rpm=5.0, duration_s=1.0)], scheduler="nonsense")


@pytest.mark.timeout(30)
def test_dead_dask_address_is_a_clear_error_within_seconds():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(SimError, match="no Dask scheduler"):
        run_study([WhatIfJob(rpm=5.0, duration_s=1.0)], scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=2.0)
    assert time.monotonic() - t0 < 15.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.timeout(180)
def test_study_on_a_real_dask_scheduler_and_worker():
    from distributed import Client

    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    procs = []
    try:
        # scheduler and worker start together: the worker retries until the scheduler listens
        procs.append(subprocess.Popen(
            [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen(
            [str(DASK), "worker", addr, "--nthreads", "1", "--no-nanny", "--no-dashboard",
             "--host", "127.0.0.1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        def listening() -> bool:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                return True
            except OSError:
                return False

        wait_until(listening, 60, "the Dask scheduler to listen")
        with Client(addr, timeout="30s", set_as_default=False) as c:
            c.wait_for_workers(1, timeout=90)
        jobs = [WhatIfJob(rpm=r, duration_s=0.5, seed=0, sample_s=0.25) for r in (5.0, 20.0)]
        seen = []
        remote = run_study(jobs, scheduler=addr, progress=lambda d, t: seen.append((d, t)))
        local = run_study(jobs, workers=1)
        assert seen[-1] == (2, 2)
        for a, b in zip(remote, local, strict=False):
            assert a.job.rpm == b.job.rpm
            assert np.array_equal(a.mi, b.mi)
    finally:
        # the worker first, then the scheduler; a worker that outlives its scheduler sometimes
        # retries it for ~20 s before it exits, so what is not gone 3 s after the SIGTERM is killed
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=3)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

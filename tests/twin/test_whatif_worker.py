"""The live loop's what-if worker with fakes (tests/twin/workers_fakes.py): requests answered once the
twin runs, an AUTO study from the camera's bed, and its process pool under a long $TMPDIR."""

from __future__ import annotations

from pathlib import Path

import pytest

from control.decision import PredictionRequest
from tests.twin.test_mill_worker import Sink
from tests.twin.workers_fakes import Boxes
from twin.live.commands import RunStudy
from twin.live.snapshots import TwinInfo
from twin.live.whatif import WhatIfWorker
from twin.state import LiveState


class _Result:
    def __init__(self, rpm: float) -> None:
        self.plateau_mi = rpm / 100.0
        self.t_s = [0.0, 1.0]
        self.mi = [0.5, rpm / 100.0]
        self.regime = "cascading"


def test_whatif_worker_answers_requests_once_the_twin_runs() -> None:
    b = Boxes()
    jobs_seen: list = []

    def study(jobs):
        jobs_seen.append([j.rpm for j in jobs])
        return [_Result(j.rpm) for j in jobs]

    state = LiveState()
    w = WhatIfWorker(b.view, Sink(), state, study=study)
    w.request(PredictionRequest(1.0, (5.0, 25.0), 40.0))
    assert not w.serve_once() and w.poll() is None  # no twin yet: the request waits
    b.twin.set(TwinInfo(updated_s=1.0, state=object()))
    w.request(PredictionRequest(2.0, (5.0, 45.0), 40.0))  # supersedes the waiting one
    assert w.serve_once()
    res = w.poll()
    assert res is not None and res.t_s == 2.0 and res.predictions == {5.0: 0.05, 45.0: 0.45}
    assert w.poll() is None and jobs_seen == [[5.0, 45.0]]
    assert w.submit(RunStudy((10.0,), 20.0)) and not w.submit(RunStudy((12.0,), 20.0))  # one at a time
    assert w.serve_once() and state.snapshot().whatif.rpms == (10.0,)


@pytest.mark.timeout(120)
def test_the_whatif_pool_starts_under_a_long_tmpdir(tmp_path) -> None:
    """With a long ``$TMPDIR`` the fork server's socket path was too long (``OSError: AF_UNIX path
    too long``): every AUTO study and calibration of the run failed. The pool now makes its private
    temp directory under a short base itself (``short_pool_tempdir``)."""
    import os
    import subprocess
    import sys

    long_tmp = tmp_path / ("t" * 60) / ("u" * 60)
    long_tmp.mkdir(parents=True)
    code = (
        "import tempfile\n"
        "from tests.twin.workers_fakes import Boxes\n"
        "from tests.twin.test_mill_worker import Sink\n"
        "from twin.live.whatif import WhatIfWorker\n"
        "from twin.state import LiveState\n"
        "from sim.whatif import froude\n"
        "w = WhatIfWorker(Boxes('auto').view, Sink(), LiveState())\n"
        "try:\n"
        "    print(len(tempfile.gettempdir()), round(w._get_pool().submit(froude, 5.0).result(timeout=90), 6))\n"
        "finally:\n"
        "    w.close()\n"
    )
    env = {**os.environ, "TMPDIR": str(long_tmp)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=110, env=env,
                       cwd=Path(__file__).resolve().parents[2])
    assert p.returncode == 0, p.stderr[-1500:]
    n, fr = p.stdout.split()
    assert int(n) > 110  # the temp directory really was long
    from sim.recipe import PAPER_DRUM
    from sim.whatif import froude

    assert float(fr) == pytest.approx(froude(5.0, PAPER_DRUM), abs=1e-6)
    assert list(long_tmp.iterdir()) == []  # nothing left behind


def test_an_auto_study_from_the_bed_waits_for_the_twin_seeded_from_the_camera(monkeypatch) -> None:
    """``PredictionRequest.from_bed`` (objective time/energy): the what-if worker asks the twin to
    seed itself from the camera's bed and starts the study from that new state, not from the
    running twin's (which may have drifted from the plant); a plain request does not re-seed,
    and a twin that never seeds itself leaves the study to the running twin's state."""
    import twin.live.whatif as whatif_mod

    b = Boxes()
    drifted, from_bed = object(), object()
    b.twin.set(TwinInfo(updated_s=1.0, state=drifted, seeds=1))
    asked: list[int] = []
    states: list = []

    def reseed() -> None:
        asked.append(1)
        b.twin.set(TwinInfo(updated_s=1.0, state=from_bed, seeds=2))

    def study(jobs):
        states.append({id(j.start) for j in jobs})
        return [_Result(j.rpm) for j in jobs]

    w = WhatIfWorker(b.view, Sink(), LiveState(), study=study, reseed_twin=reseed)
    w.request(PredictionRequest(1.0, (5.0, 25.0), 40.0))
    assert w.serve_once() and asked == [] and states[-1] == {id(drifted)}
    w.request(PredictionRequest(2.0, (5.0, 25.0), 40.0, 0.9, from_bed=True))
    assert w.serve_once() and asked == [1] and states[-1] == {id(from_bed)}
    monkeypatch.setattr(whatif_mod, "RESEED_WAIT_S", 0.2)
    mute = WhatIfWorker(b.view, Sink(), LiveState(), study=study, reseed_twin=lambda: asked.append(2))
    w2_state = b.twin.get().state
    mute.request(PredictionRequest(3.0, (5.0,), 40.0, 0.9, from_bed=True))
    assert mute.serve_once() and asked == [1, 2] and states[-1] == {id(w2_state)} and mute.poll() is not None

"""Where the test suite's time goes: the whole machine's CPU, by process kind and by test.

The suite's wall time on 2 cores is bounded below by the CPU it needs: this runs pytest as
``scripts/test.sh`` does (``-n 3 --dist loadgroup``, one thread per numeric library) with a
per-test CPU plugin (each test's own and its reaped children's CPU), samples every process of the
machine meanwhile (``/proc``, every 0.25 s: chromium, servers and pools that pytest never reaps),
and prints the wall time, how many of the cores were busy, the CPU by process kind, and the
modules and tests that cost most::

    .venv/bin/python -m scripts.suite_profile                 # the whole suite
    .venv/bin/python -m scripts.suite_profile -n 4 tests/twin # other workers, a part of it

It does not lint, type-check or warm numba (run ``scripts/test.sh`` once first). History of the
numbers: docs/mutation.md, "Suite time".
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PLUGIN = '''
import json, os, resource, time
import pytest

def _cpu():
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime

@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    c0, w0 = _cpu(), time.monotonic()
    yield
    with open(os.path.join(os.environ["SUITE_PROFILE_DIR"], f"tests-{os.getpid()}.jsonl"), "a") as f:
        f.write(json.dumps({"id": item.nodeid, "cpu": _cpu() - c0, "wall": time.monotonic() - w0}) + "\\n")
'''
KINDS = (("chromium", r"chrom"), ("playwright driver", r"playwright/driver"), ("postgres", r"postgres"),
         ("pool worker (sim.whatif)", r"forkserver|multiprocessing"), ("dask", r"dask"),
         ("drumtwin subprocess", r"drumtwin|twin\.cli"), ("pytest worker", r"-u -c import sys;exec"),
         ("pytest controller", r"-m pytest"))


def _stat() -> tuple[int, int]:
    """(busy, total) jiffies of the machine since boot."""
    f = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    return sum(f) - f[3] - f[4], sum(f)


def _sample(seen: dict[int, tuple[float, str]], stop: threading.Event, me: int) -> None:
    """Each new process's command line and its CPU (s) as last seen."""
    tick = os.sysconf("SC_CLK_TCK")
    while not stop.wait(0.25):
        for d in Path("/proc").iterdir():
            if not d.name.isdigit() or int(d.name) == me:
                continue
            try:
                f = (d / "stat").read_text().rsplit(")", 1)[1].split()
                cpu = (int(f[11]) + int(f[12])) / tick
                cmd = seen[int(d.name)][1] if int(d.name) in seen else \
                    (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except (OSError, IndexError, ValueError):
                continue
            seen[int(d.name)] = (cpu, cmd)


def _kind(cmd: str) -> str:
    return next((k for k, pat in KINDS if re.search(pat, cmd)), "other")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scripts.suite_profile", description=(__doc__ or "").split("\n")[0])
    ap.add_argument("-n", type=int, default=int(os.environ.get("DRUMTWIN_TEST_WORKERS", "3")), help="xdist workers")
    ap.add_argument("--top", type=int, default=25, help="modules and tests listed")
    args, rest = ap.parse_known_args(argv)
    with tempfile.TemporaryDirectory(prefix="suite-profile-") as tmp:
        (Path(tmp) / "suite_profile_plugin.py").write_text(PLUGIN)
        env = {**os.environ, "SUITE_PROFILE_DIR": tmp, "PYTHONPATH": os.pathsep.join([tmp, str(REPO)]),
               "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENCV_FOR_THREADS_NUM": "1"}
        before = {int(d.name) for d in Path("/proc").iterdir() if d.name.isdigit()}
        seen: dict[int, tuple[float, str]] = {}
        stop = threading.Event()
        sampler = threading.Thread(target=_sample, args=(seen, stop, os.getpid()), daemon=True)
        sampler.start()
        b0, t0, w0 = *_stat(), time.monotonic()
        code = subprocess.call([str(REPO / ".venv/bin/python"), "-m", "pytest", "-n", str(args.n), "--dist",
                                "loadgroup", "-p", "suite_profile_plugin", "-q", *rest], cwd=REPO, env=env)
        b1, t1, wall = *_stat(), time.monotonic() - w0
        stop.set()
        sampler.join()
        tests = [json.loads(line) for p in Path(tmp).glob("tests-*.jsonl") for line in p.read_text().splitlines()]
    cores = os.cpu_count() or 1
    busy_s = (b1 - b0) / os.sysconf("SC_CLK_TCK")
    print(f"\npytest exit {code}: {wall:.0f} s wall, {args.n} workers; the machine {cores * (b1 - b0) / (t1 - t0):.2f} "
          f"of {cores} cores busy ({busy_s:.0f} s of CPU: at least {busy_s / cores:.0f} s of wall on {cores} cores)")
    kinds: dict[str, float] = collections.defaultdict(float)
    for pid, (cpu, cmd) in seen.items():
        if pid not in before:
            kinds[_kind(cmd)] += cpu
    print("CPU by process kind (processes started during the run; s):")
    for k, v in sorted(kinds.items(), key=lambda kv: -kv[1]):
        print(f"  {v:7.1f}  {k}")
    mods: dict[str, float] = collections.defaultdict(float)
    for t in tests:
        mods[t["id"].split("::")[0]] += t["cpu"]
    print(f"CPU by test module ({sum(mods.values()):.0f} s in {len(tests)} tests; own and reaped children's):")
    for m, v in sorted(mods.items(), key=lambda kv: -kv[1])[:args.top]:
        print(f"  {v:7.1f}  {m}")
    print("the costliest tests (CPU s, wall s):")
    for t in sorted(tests, key=lambda t: -t["cpu"])[:args.top]:
        print(f"  {t['cpu']:6.1f} {t['wall']:6.1f}  {t['id'][:150]}")
    return code


if __name__ == "__main__":
    sys.exit(main())

"""``drumtwin bench catalogue``: the catalogue at a lab's scale.

Generates N run folders from a real one (the run log shipped in the repository, or any run
folder given): each with its own uid, rig, mode, start time, rpm and endpoint in its
``metadata.json`` and ``events.jsonl`` (``frames.csv`` hard-linked: the index reads only its
last rows). Then it times ``rebuild`` (folders per second) and ``runs list`` with a filter
(open, reconcile against the folders, query), the way the command does it.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from twin.catalogue.store import Catalogue, RunFilter, rebuild
from twin.catalogue.summary import EVENTS_FILE, FRAMES_FILE, METADATA_FILE

RIGS = ("pmma", "glass", "steel-balls", "rice", "demo")
MODES = ("auto", "off", "manual")


def _variants(template: Path, n: int, rng: random.Random) -> list[list[dict[str, Any]]]:
    """``n`` event streams from the template's: the endpoint kept or dropped, rpm commands scaled."""
    base = [json.loads(ln) for ln in (template / EVENTS_FILE).read_text().splitlines() if ln.strip()]
    out = []
    for _ in range(n):
        keep_mixed = rng.random() < 0.7
        scale = rng.choice((0.5, 1.0, 1.5))
        events = []
        for e in base:
            if e.get("kind") in ("mixed", "unmixed") and not keep_mixed:
                continue
            e = dict(e)
            if e.get("kind") == "mill_command" and isinstance(e.get("rpm"), (int, float)):
                e["rpm"] = round(e["rpm"] * scale, 1)
            events.append(e)
        out.append(events)
    return out


def generate(template: Path, root: Path, n: int, seed: int = 0, progress: Callable[[int], None] | None = None) -> None:
    """``n`` run folders under ``root`` made from the run folder ``template``."""
    rng = random.Random(seed)
    meta = json.loads((template / METADATA_FILE).read_text())
    variants = _variants(template, 16, rng)
    t0 = time.time() - n * 3600.0
    for i in range(n):
        d = root / f"run-{i:05d}"
        d.mkdir(parents=True)
        os.link(template / FRAMES_FILE, d / FRAMES_FILE)
        start = t0 + i * 3600.0 + rng.uniform(0, 600)
        events = variants[i % len(variants)]
        first = float(events[0]["wall_s"])
        mode = rng.choice(MODES)
        with open(d / EVENTS_FILE, "w") as fh:
            for e in events:
                e2 = {**e, "wall_s": start + (float(e["wall_s"]) - first)}
                if e2.get("kind") == "start":
                    e2["mode"] = mode
                fh.write(json.dumps(e2) + "\n")
        m = {**meta, "run_uid": f"bench{seed:02d}{i:07d}", "process": {"pid": 1, "host": "bench", "start": "0"},
             "config": {**meta.get("config", {}), "mode": mode, "start_rpm": rng.choice((5.0, 10.0, 20.0))},
             "rig": {"name": rng.choice(RIGS), "hash": "bench"}}
        (d / METADATA_FILE).write_text(json.dumps(m))
        if progress is not None and (i + 1) % 1000 == 0:
            progress(i + 1)


def run_bench(runs: int, template: Path, workdir: Path | None = None, repeats: int = 5,
              progress: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    """Generate, rebuild and list; the numbers as a dict."""
    base = Path(tempfile.mkdtemp(prefix="drumtwin-catbench-", dir=workdir))
    try:
        root = base / "runs"
        t = time.perf_counter()
        generate(template, root, runs, progress=lambda i: progress(f"{i} folders generated"))
        gen_s = time.perf_counter() - t
        t = time.perf_counter()
        n, _moved = rebuild(None, root)
        rebuild_s = time.perf_counter() - t
        progress(f"rebuilt: {n} runs in {rebuild_s:.1f} s")
        times, found = [], 0
        for _ in range(repeats):
            t = time.perf_counter()
            with Catalogue.open(None, root) as cat:
                cat.reconcile()
                found = len(cat.list(RunFilter(rig="pmma", mixed=True, rpm_lo=15.0, last=50)))
            times.append(time.perf_counter() - t)
        db = root / "catalogue.sqlite"
        return {
            "runs": n, "generate_s": round(gen_s, 2), "rebuild_s": round(rebuild_s, 2),
            "rebuild_folders_per_s": round(n / rebuild_s, 1),
            "list_filtered_s_median": round(statistics.median(times), 3), "list_filtered_s_max": round(max(times), 3),
            "list_found": found, "catalogue_mb": round(db.stat().st_size / 1e6, 2),
        }
    finally:
        shutil.rmtree(base, ignore_errors=True)

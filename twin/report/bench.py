"""``drumtwin bench report``: wall time and peak memory of ``drumtwin report`` on generated logs.

It writes ``runs`` run folders of ``rows`` frame rows each in a temporary directory (the run
log's own writer, ``twin.runlog.RunLog``, for the metadata, the events and the header; the
frame rows in bulk, formatted as the writer formats them, because a million ``RunLog.frame``
calls take longer than the report), then runs the real ``drumtwin report`` on them in a
subprocess and reports its wall time and its peak resident set (``ru_maxrss`` of that child,
from ``os.wait4``: the same number as ``/usr/bin/time -v``'s "Maximum resident set size").

The rows look like a real AUTO run at 10 fps: MI rising to a plateau with noise, a one-frame
spike every 5,000 rows, an invalid frame (NaN, flagged) every 97, the twin from row 100 on,
an rpm move every 6,000 rows (a decision and the what-if study behind it in events.jsonl),
the endpoint reached at 90 s.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twin.errors import TwinError
from twin.records import DecisionMade, Mixed, Record, RunStart, RunStop, WhatIfResult
from twin.runlog import RunLog

FPS = 10.0
BLOCK = 50_000  # rows formatted per write


@dataclass(frozen=True)
class ReportBench:
    """One measured ``drumtwin report``: ``wall_s`` of the subprocess, its peak RSS (MB =
    2^20 bytes), the HTML's size (MB), the logs' size on disk (MB) and the time it took to
    write them (s)."""

    rows: int
    runs: int
    wall_s: float
    peak_rss_mb: float
    html_mb: float
    logs_mb: float
    generate_s: float
    exit_code: int


def _frame_block(i0: int, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Columns of rows ``i0 .. i0 + n`` (numbers; NaN: an empty cell or an invalid MI)."""
    i = np.arange(i0, i0 + n)
    t = i / FPS
    mi = np.clip(0.95 - 0.5 * np.exp(-t / 40.0) + rng.normal(0, 0.01, n), 0, 1)
    mi[i % 5000 == 4999] = 0.2  # a one-frame spike: the decimated plot must still show it
    invalid = i % 97 == 96
    mi[invalid] = math.nan
    trend = 0.95 - 0.5 * np.exp(-t / 42.0)
    rpm = np.where((i // 6000) % 2 == 1, 25.0, 5.0)
    twin = np.where(i >= 100, trend + 0.01, math.nan)
    return {"t_s": t, "wall_s": 1.7e9 + t, "frame": i.astype(float), "mi": mi, "mi_sigmoid": mi, "mi_linear": mi,
            "d_px": 3.0 + 2 * (1 - mi), "dsigma_px": 3.5 + (1 - mi), "concentration": 0.45 + 0 * t,
            "slope_deg": 30.0 + rpm / 5 + rng.normal(0, 1.0, n), "valid": (~invalid).astype(float),
            "trend_mi": trend, "trend_lo95": trend - 0.05, "trend_hi95": np.minimum(trend + 0.05, 1.0),
            "trend_rate": np.exp(-t / 42.0) / 84.0, "ma_mi": trend, "twin_mi": twin,
            "twin_slope_deg": np.where(i >= 100, 31.0, math.nan), "rpm_setpoint": rpm, "rpm_actual": rpm,
            "mixed": (t >= 90.0).astype(float), "mixing_time_s": np.where(t >= 90.0, 80.0, math.nan),
            "_invalid": invalid}


def _cells(name: str, col: np.ndarray, invalid: np.ndarray) -> list[str]:
    """One column as the run log writes its cells (``twin.runlog``: 13 significant digits,
    bools 0/1, None empty)."""
    if name == "mode":
        return ["auto"] * invalid.size
    if name == "flags":
        return ["few_pixels:red" if b else "" for b in invalid]
    if name in ("frame", "valid", "mixed"):
        return [str(int(v)) for v in col]
    empty_nan = name in ("twin_mi", "twin_slope_deg", "mixing_time_s")
    return ["" if (empty_nan and v != v) else ("nan" if v != v else f"{v:.13g}") for v in col.tolist()]


def write_frames(path: Path, columns: tuple[str, ...], rows: int, seed: int, extra: dict[str, str]) -> None:
    """Append ``rows`` generated rows to ``path`` (its header already written), in
    ``columns`` order; ``extra``: constant cells by column (e.g. the run uid)."""
    rng = np.random.default_rng(seed)
    with open(path, "a", encoding="utf-8", newline="") as fh:
        for i0 in range(0, rows, BLOCK):
            n = min(BLOCK, rows - i0)
            cols = _frame_block(i0, n, rng)
            inv = cols["_invalid"]
            cells = [[extra[c]] * n if c in extra else _cells(c, cols.get(c, np.full(n, math.nan)), inv)
                     for c in columns]
            fh.write("".join(",".join(r) + "\n" for r in zip(*cells, strict=True)))


def write_run(d: Path, rows: int, seed: int = 0) -> Path:
    """One generated run folder (see the module doc)."""
    with RunLog(d) as log:
        log.set_metadata(config={"mode": "auto", "case": "C", "speed": 1.0, "camera_fps": FPS},
                         versions={"python": sys.version.split()[0], "numpy": np.__version__}, bench=True)
        for rec in _records(rows):
            log.record(rec)
        columns, extra = log.columns, {"run_uid": log.run_uid}
    write_frames(d / "frames.csv", columns, rows, seed, extra)
    return d


def _records(rows: int) -> list[Record]:
    """The events of a generated run: an rpm move every 6,000 rows and the study behind it,
    the endpoint at 90 s, start and stop."""
    out: list[Record] = [RunStart(t_s=0.0, mode="auto", mill="bench")]
    for k in range(6000, rows, 6000):
        t = k / FPS
        target = 25.0 if (k // 6000) % 2 == 1 else 5.0
        pred = {"5.0": 0.9, "25.0": 0.95}
        out.append(WhatIfResult(t_s=t - 1.0, reason="AUTO", requested_t_s=t - 5, duration_s=40.0, predictions=pred,
                                took_s=1.0, target_mi=0.9, time_to_target_s={"5.0": 60.0, "25.0": 20.0},
                                power_w={"5.0": 0.5, "25.0": 12.5}, energy_to_target_j={"5.0": 30.0, "25.0": 250.0}))
        out.append(DecisionMade(t_s=t, decision="move", mode="auto", action="set_rpm", reason="bench", rpm=target,
                                target_rpm=target, safe=False, level=0.9, rate=0.0, predictions=pred, inputs={}))
    if rows > 900:
        out.append(Mixed(t_s=90.0, mixing_time_s=80.0, plateau_mi=0.95, reason="bench"))
    out.append(RunStop(t_s=rows / FPS, frames=rows, workers_alive=(), failure=None))
    return out


def _du_mb(root: Path) -> float:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file()) / 2**20


def run_report(dirs: list[Path], out: Path) -> tuple[float, float, int]:
    """``drumtwin report DIRS --out OUT`` in a subprocess: (wall s, peak RSS MB, exit code)."""
    cmd = [sys.executable, "-c", "from twin.cli import main; main()", "report", *map(str, dirs), "--out", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode("utf-8", "replace") if proc.stderr else ""
    if proc.stderr:
        proc.stderr.close()
    if proc.returncode != 0:
        raise TwinError(f"drumtwin report failed (exit {proc.returncode}): {err.strip()[-300:]}")
    return wall, usage.ru_maxrss / 1024.0, proc.returncode


def bench_report(rows: int, runs: int, keep: Path | None = None) -> ReportBench:
    """Generate ``runs`` logs of ``rows`` rows each, report them, measure (module doc)."""
    root = Path(tempfile.mkdtemp(prefix="drumtwin-bench-report-")) if keep is None else keep
    try:
        t0 = time.perf_counter()
        dirs = [write_run(root / f"run{i:04d}", rows, seed=i) for i in range(runs)]
        gen = time.perf_counter() - t0
        out = root / "report.html"
        wall, rss, code = run_report(dirs, out)
        return ReportBench(rows, runs, round(wall, 2), round(rss, 1), round(out.stat().st_size / 2**20, 2),
                           round(_du_mb(root) - out.stat().st_size / 2**20, 1), round(gen, 1), code)
    finally:
        if keep is None:
            shutil.rmtree(root, ignore_errors=True)


__all__ = ["ReportBench", "bench_report", "write_run"]

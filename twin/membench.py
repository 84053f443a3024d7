"""Peak memory of a live run without the dashboard (``drumtwin bench memory``).

Runs the real ``drumtwin run --video V --mill PTY --no-dashboard`` in a subprocess on a
generated 640x640, 30 fps video of the synthetic drum and the mill emulator on a pty,
and samples ``/proc`` of its whole process tree (the run, the fork server and the pool
workers of the what-if studies and of the twin's calibration) every ``sample_s``:

- ``main_hwm_mb``: the run process's own peak resident set (``VmHWM``);
- ``tree_rss_mb``: the highest sum of ``VmRSS`` over the tree (pages shared between the
  fork server and its workers counted once per process: an upper bound);
- ``tree_pss_mb``: the highest sum of ``Pss`` (shared pages split between the sharers:
  what the run really costs the machine);
- ``per_process``: each process's own peak ``Pss`` (MB) by role (``run``, ``forkserver``,
  ``resource_tracker``, ``worker N``): where the memory goes.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from twin.errors import TwinError


@dataclass(frozen=True)
class MemoryResult:
    """Peaks over one run (MB = 2^20 bytes), the number of processes seen, seconds run."""

    main_hwm_mb: float
    tree_rss_mb: float
    tree_pss_mb: float
    processes: int
    seconds: float
    per_process: dict[str, float] = field(default_factory=dict)


def _kb(path: str, key: str) -> int:
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith(key):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _tree(pid: int) -> list[int]:
    """``pid`` and all its descendants (from /proc/*/stat)."""
    children: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text(encoding="ascii", errors="replace")
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(d))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children.get(p, ()))
    return out


def _role(pid: int, main_pid: int, workers: dict[int, str]) -> str:
    """What process ``pid`` of the run's tree is, from its command line."""
    if pid == main_pid:
        return "run"
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        cmd = ""
    try:
        ppid = int(Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace").rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        ppid = -1
    for role in ("forkserver", "resource_tracker"):
        if f"multiprocessing.{role}" in cmd and ppid == main_pid:  # a forked worker has the same command line
            return role
    return workers.setdefault(pid, f"worker {len(workers) + 1}")


def write_video(path: Path, seconds: float, size_px: int = 640, fps: float = 30.0) -> Path:
    """An MJPG video of the synthetic drum (mix varying), ``size_px`` square."""
    import cv2
    import numpy as np

    from vision.synthetic import drum_frame

    frames = [drum_frame((size_px, size_px), mix=float(0.5 + 0.5 * np.sin(i / 5)), seed=i) for i in range(30)]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (size_px, size_px))
    for i in range(int(seconds * fps) + int(fps)):
        vw.write(frames[i % len(frames)])
    vw.release()
    return path


def measure_run_memory(seconds: float = 30.0, sample_s: float = 0.25) -> MemoryResult:
    """Peak memory of one ``drumtwin run`` without the dashboard (see module doc)."""
    from control.device import DeviceConfig
    from control.emulator import MillEmulator

    if not os.path.isdir("/proc/self"):
        raise TwinError("bench memory reads /proc (Linux only)")
    with tempfile.TemporaryDirectory(prefix="drumtwin-membench-") as tmp, MillEmulator(
        DeviceConfig(watchdog_s=0.0)
    ) as emu:
        url = emu.open_pty()
        video = write_video(Path(tmp) / "drum640.avi", seconds)
        cmd = [sys.executable, "-c", "from twin.cli import main; main()", "run", "--video", str(video),
               "--mill", url, "--no-dashboard", "--duration", f"{seconds:g}", "--mode", "auto",
               "--log", str(Path(tmp) / "run")]
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        hwm = rss = pss = 0
        n = 0
        workers: dict[int, str] = {}
        peaks: dict[str, int] = {}
        try:
            while proc.poll() is None and time.monotonic() - t0 < seconds + 120:
                pids = _tree(proc.pid)
                hwm = max(hwm, _kb(f"/proc/{proc.pid}/status", "VmHWM"))
                rss = max(rss, sum(_kb(f"/proc/{p}/status", "VmRSS") for p in pids))
                each = {p: _kb(f"/proc/{p}/smaps_rollup", "Pss:") for p in pids}
                pss = max(pss, sum(each.values()))
                for p, kb in each.items():
                    role = _role(p, proc.pid, workers)
                    peaks[role] = max(peaks.get(role, 0), kb)
                n = max(n, len(pids))
                time.sleep(sample_s)
        finally:
            if proc.poll() is None:
                proc.kill()
            _, err = proc.communicate(timeout=30)
        if proc.returncode != 0:
            last = (err or "").strip().splitlines()[-1:] or ["no output"]
            raise TwinError(f"bench memory: the run failed ({last[0][:200]})")
        return MemoryResult(hwm / 1024, rss / 1024, pss / 1024, n, time.monotonic() - t0,
                            {k: round(v / 1024, 1) for k, v in peaks.items()})

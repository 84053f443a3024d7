"""Serial-link benchmark: the real driver against the emulator on a pty and on TCP.

Round trip of one ``STATUS`` request (frame out, ACK with the status back, decoded)
through :class:`control.driver.MillClient`, with the heartbeat thread off so only the
measured requests are on the line.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from control.driver import MillClient
from control.emulator import MillEmulator

__all__ = ["LinkTiming", "run_link_bench", "time_link"]


@dataclass(frozen=True)
class LinkTiming:
    """Round-trip times of ``n`` status requests over one transport (ms)."""

    transport: str
    n: int
    median_ms: float
    p99_ms: float
    max_ms: float
    resends: int

    @property
    def requests_per_s(self) -> float:
        return 1000.0 / self.median_ms if self.median_ms > 0 else float("nan")


def time_link(url: str, n: int, transport: str) -> LinkTiming:
    """Time ``n`` status requests of a fresh driver on ``url`` (after 10 warm-up requests)."""
    with MillClient(url, heartbeat_s=None, timeout_s=0.5, retries=3) as client:
        for _ in range(10):
            client.status()
        rtt = np.empty(n)
        for i in range(n):
            t0 = time.perf_counter()
            client.status()
            rtt[i] = time.perf_counter() - t0
        resends = client.stats["resends"]
    ms = rtt * 1000.0
    return LinkTiming(transport, n, float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max()), resends)


def run_link_bench(n: int = 500, progress: Callable[[str], None] | None = None) -> list[LinkTiming]:
    """Round trips over a real pty and over TCP loopback, each with its own emulator."""
    say = progress or (lambda s: None)
    out = []
    with MillEmulator() as emu:
        say("pty ...")
        out.append(time_link(emu.open_pty(), n, "pty"))
    with MillEmulator() as emu:
        say("tcp ...")
        emu.open_tcp(0)
        out.append(time_link(emu.url, n, "tcp"))
    return out

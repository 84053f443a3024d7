"""Serial-link benchmark: the real driver against the emulator on a pty and on TCP.

Round trip of one ``STATUS`` request (frame out, ACK with the status back, decoded)
through :class:`control.driver.MillClient`, with the heartbeat thread off so only the
measured requests are on the line; beside it the Modbus link (``ModbusMill.status()``:
the profile's status registers read with pymodbus, decoded) against the drive emulator.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from control.driver import MillClient
from control.emulator import MillEmulator

MODBUS_BENCH_PROFILE = "delta-ms300"
"""The drive the Modbus round trip is timed on (its four status registers are one read)."""

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
    """Time ``n`` status requests of a fresh driver on ``url`` (after 10 warm-up requests);
    a ``modbus:`` URL is timed through ``ModbusMill`` (its ``resends``: pymodbus's)."""
    if url.startswith("modbus:"):
        from control.modbus.link import ModbusMill

        with ModbusMill(url, timeout_s=0.5, retries=3) as mill:
            return _time_status(mill.status, n, transport, lambda: mill.stats["resends"])
    with MillClient(url, heartbeat_s=None, timeout_s=0.5, retries=3) as client:
        return _time_status(client.status, n, transport, lambda: client.stats["resends"])


def _time_status(status: Callable[[], object], n: int, transport: str, resends: Callable[[], int]) -> LinkTiming:
    """Round trips of ``n`` calls of ``status`` (after 10 warm-up calls)."""
    for _ in range(10):
        status()
    rtt = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        status()
        rtt[i] = time.perf_counter() - t0
    ms = rtt * 1000.0
    return LinkTiming(transport, n, float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max()), resends())


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
    from control.modbus.emulator import DriveEmulator
    from control.modbus.profile import load_profile

    for kind in ("pty", "tcp"):
        with DriveEmulator(load_profile(MODBUS_BENCH_PROFILE)) as drive:
            say(f"modbus {kind} ...")
            if kind == "pty":
                drive.open_pty()
            else:
                drive.open_tcp(0)
            out.append(time_link(drive.mill_url(), n, f"modbus_{kind}"))
    return out

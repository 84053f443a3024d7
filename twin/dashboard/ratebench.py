"""Benchmark: how often the dashboard's camera and twin images change in a real browser.

A headless chromium (driven by Playwright) opens the dashboard, waits until both images
are live (each changed once: the twin's first frame comes after its seeding, seconds after
the camera's on a busy machine) and then the warm-up, and counts the changes of each GUI
image's ``src`` (viser swaps a new blob URL in for every pushed frame) with a
``MutationObserver`` for a fixed window. This is what
a viewer sees, after the server's encoding, the websocket and the browser's decoding,
with the 3D scene rendering beside it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.errors import TwinError

__all__ = [
    "CHROMIUM", "FIRST_IMAGE_S", "IMG_SELECTOR", "LIVE_S",
    "DashboardRate", "check_bench_args", "count_image_updates", "measure_dashboard_rate",
]

CHROMIUM = Path("/usr/bin/chromium")
IMG_SELECTOR = 'img[src^="blob:"]'  # the GUI images, in panel order: camera, then twin
FIRST_IMAGE_S = 120.0  # budget (s) for the page to load, and then for its first image
LIVE_S = 60.0  # budget (s) for both images to change once (past it, what changes is counted: 0 is a result)

_LIVE_JS = """([sel, ms]) => new Promise(resolve => {
  const imgs = Array.from(document.querySelectorAll(sel)).slice(0, 2);
  const seen = imgs.map(() => false);
  let obs = [];
  const timer = setTimeout(() => { obs.forEach(o => o.disconnect()); resolve(seen); }, ms);
  obs = imgs.map((im, i) => {
    const o = new MutationObserver(() => {
      seen[i] = true;
      if (seen.every(Boolean)) { clearTimeout(timer); obs.forEach(o => o.disconnect()); resolve(seen); }
    });
    o.observe(im, {attributes: true, attributeFilter: ['src']});
    return o;
  });
})"""

_COUNT_JS = """([sel, ms]) => new Promise(resolve => {
  const imgs = Array.from(document.querySelectorAll(sel));
  const counts = imgs.map(() => 0);
  const obs = imgs.map((im, i) => {
    const o = new MutationObserver(() => counts[i]++);
    o.observe(im, {attributes: true, attributeFilter: ['src']});
    return o;
  });
  setTimeout(() => { obs.forEach(o => o.disconnect()); resolve(counts); }, ms);
})"""


def check_bench_args(seconds: float, warmup_s: float, speed: float, port: int) -> None:
    """Validate ``drumtwin bench dashboard``'s options before anything starts (TwinError,
    one line naming the option): finite seconds in (0, 3600], warm-up in [0, 600], speed
    in (0, 100], port in 1..65535."""
    for name, value, lo_open, lo, hi in (
        ("--seconds", seconds, True, 0.0, 3600.0),
        ("--warmup", warmup_s, False, 0.0, 600.0),
        ("--speed", speed, True, 0.0, 100.0),
    ):
        v = float(value)
        if not (math.isfinite(v) and (v > lo if lo_open else v >= lo) and v <= hi):
            rng = f"{'>' if lo_open else '>='} {lo:g} and <= {hi:g}"
            raise TwinError(f"{name} must be a finite number {rng} (got {value})")
    if not 1 <= int(port) <= 65535:
        raise TwinError(f"--port must be in 1..65535 (got {port})")


@dataclass(frozen=True)
class DashboardRate:
    """Image updates per second seen by the browser over ``seconds`` (s)."""

    camera_hz: float
    twin_hz: float
    seconds: float

    def as_dict(self) -> dict[str, float]:
        return {"camera_hz": self.camera_hz, "twin_hz": self.twin_hz, "seconds": self.seconds}


def measure_dashboard_rate(url: str, seconds: float = 20.0, warmup_s: float = 15.0,
                           chromium: Path = CHROMIUM) -> DashboardRate:
    """Open ``url`` in headless chromium and count image updates for ``seconds`` (s)."""
    try:
        from playwright.sync_api import Error as PlaywrightError
        from playwright.sync_api import sync_playwright
    except ImportError as exc:
        raise TwinError("bench dashboard needs Playwright: pip install 'drumtwin[test]'") from exc
    if not chromium.exists():
        raise TwinError(f"bench dashboard needs {chromium}: apt-get install chromium")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(chromium), headless=True,
                                        args=["--no-sandbox", "--no-first-run"])
            try:
                page = browser.new_page(viewport={"width": 1600, "height": 1000})
                return count_image_updates(page, url, seconds, warmup_s)
            finally:
                browser.close()
    except PlaywrightError as exc:
        raise TwinError(f"bench dashboard: the browser failed: {str(exc).splitlines()[0]}") from exc


def count_image_updates(page: Any, url: str, seconds: float, warmup_s: float) -> DashboardRate:
    """Open ``url`` in the Playwright ``page`` (sync API); once both images are live (or after
    ``LIVE_S``) and ``warmup_s`` (s) more, count their updates for ``seconds`` (s)."""
    # generous budgets: on a loaded 2-core machine chromium can take tens of
    # seconds to load and run viser's client bundle before the first image
    page.goto(url, timeout=FIRST_IMAGE_S * 1000)
    page.wait_for_selector(IMG_SELECTOR, timeout=FIRST_IMAGE_S * 1000)
    deadline = time.monotonic() + 30.0
    while len(page.query_selector_all(IMG_SELECTOR)) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    page.evaluate(_LIVE_JS, [IMG_SELECTOR, int(LIVE_S * 1000)])  # both moving (or the budget)
    time.sleep(max(0.0, warmup_s))
    counts = [*page.evaluate(_COUNT_JS, [IMG_SELECTOR, int(seconds * 1000)]), 0, 0]
    return DashboardRate(camera_hz=counts[0] / seconds, twin_hz=counts[1] / seconds, seconds=seconds)

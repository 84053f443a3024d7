"""Fixtures of the twin tests: a headless Debian chromium driven by Playwright, a mill emulator on TCP."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from twin.dashboard.ratebench import CHROMIUM

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """One headless chromium for the session; fails (never skips) when chromium is missing."""
    from playwright.sync_api import sync_playwright

    if not CHROMIUM.exists():
        raise FileNotFoundError(f"{CHROMIUM} missing: install Debian's chromium (apt-get install chromium)")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def page(browser) -> Iterator[object]:
    """A fresh page (1600x1000, its own browser context) in the session's chromium."""
    ctx = browser.new_context(viewport={"width": 1600, "height": 1000})
    try:
        pg = ctx.new_page()
        pg.set_default_timeout(90_000)  # a loaded 2-core CI machine loads viser slowly
        yield pg
    finally:
        ctx.close()


@pytest.fixture
def tcp_mill():
    """The mill emulator on a TCP port, its watchdog short; the drive was running and
    its watchdog has stopped it (fault WDOG) before the run connects (test_live_video.py,
    test_live_process.py)."""
    from control.device import DeviceConfig
    from control.emulator import MillEmulator
    from tests.waiting import wait_until

    emu = MillEmulator(DeviceConfig(watchdog_s=0.3), seed=1)
    port = emu.open_tcp(0)
    emu.set_motor(setpoint_rpm=13.0, actual_rpm=13.0, running=True)
    wait_until(lambda: emu.motor.fault == "WDOG", 5, "the board's watchdog")
    try:
        yield emu, f"socket://127.0.0.1:{port}"
    finally:
        emu.close()

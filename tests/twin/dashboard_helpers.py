"""Reading the viser dashboard from a Playwright page (selectors found by inspecting
viser 1.1's React/Mantine DOM in chromium)."""

from __future__ import annotations

import threading
import time

import pytest

from twin.dashboard.ratebench import IMG_SELECTOR as IMG  # camera and twin frames, in panel order

# viser warns when the GUI it builds for a connection that the tests close or refuse mid-handshake is never
# delivered (whichever test of a shared dashboard sees it): the dashboard tests' module mark
CLOSED_CONNECTION_OK = pytest.mark.filterwarnings(
    "ignore:Queued a GuiButtonMessage on a closed connection:UserWarning")


def image_srcs(page) -> list[str]:
    """The blob URLs of the GUI images (they change on every pushed frame)."""
    return page.eval_on_selector_all(IMG, "els => els.map(e => e.src)")


def plot_pixels(page) -> dict[str, str]:
    """A fingerprint of every uPlot chart's canvas (length and hash of its PNG), by title."""
    return dict(
        page.eval_on_selector_all(
            ".uplot",
            """els => els.map(e => { const t = e.querySelector('.u-title');
                const c = e.querySelector('canvas'); const s = c ? c.toDataURL() : '';
                let h = 0; for (let i = 0; i < s.length; i++) { h = (h * 31 + s.charCodeAt(i)) | 0; }
                return [t ? t.innerText : '', s.length + ':' + h]; })""",
        )
    )


def slider(page):
    return page.locator('[role="slider"]').first


def slider_value(page) -> float:
    return float(slider(page).get_attribute("aria-valuenow"))


def slider_enabled(page) -> bool:
    return slider(page).get_attribute("aria-disabled") != "true"


def drag_slider_to(page, fraction: float) -> None:
    """Press the rpm slider's track at ``fraction`` of its width (0..1) and release."""
    track = page.locator(".mantine-Slider-track").first
    box = track.bounding_box()
    assert box is not None, "rpm slider not visible"
    x = box["x"] + fraction * box["width"]
    y = box["y"] + box["height"] / 2
    thumb = slider(page).bounding_box()
    page.mouse.move(thumb["x"] + thumb["width"] / 2, thumb["y"] + thumb["height"] / 2)
    page.mouse.down()
    page.mouse.move(x, y, steps=8)
    page.mouse.up()


def button(page, name: str):
    return page.get_by_role("button", name=name, exact=True)


def input_by_label(page, label: str):
    """The text/number input on the GUI row labelled ``label`` (viser's <label for> does
    not point at the Mantine input, so get_by_label cannot find it)."""
    return page.locator(".mantine-Flex-root", has_text=label).locator("input").first


def choose_mode(page, mode: str) -> None:
    """Pick ``mode`` (OFF/MANUAL/AUTO) in the Mode selector."""
    input_by_label(page, "Mode").click()
    page.get_by_role("option", name=mode, exact=True).click()


def mode_selector(page):
    return input_by_label(page, "Mode")


# -- a viser viewer without a browser: the websocket protocol of viser 1.1 -------------------
def open_viewer(http_url: str, origin: str | None = "same", timeout_s: float = 10.0):
    """Open the dashboard's websocket as viser's page does (subprotocol ``viser-v<version>``).

    ``origin="same"`` sends the dashboard's own origin (``http_url``), ``None`` none at all,
    anything else that Origin. Raises ``websockets.exceptions.InvalidStatus`` when refused.
    """
    import viser
    from websockets.sync.client import connect
    from websockets.typing import Origin

    sent = http_url.rstrip("/") if origin == "same" else origin
    ws = connect(
        "ws://" + http_url.split("://", 1)[1].rstrip("/"),
        origin=None if sent is None else Origin(sent),
        subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
        open_timeout=timeout_s,
        max_size=None,
        compression=None,
    )
    # viser counts a viewer as connected (and builds its per-client GUI) on its first
    # camera message, which the page sends once its 3D view is up
    send_message(ws, "ViewerCameraMessage", wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 0.0, -1.0), fov=1.0,
                 near=0.01, far=100.0, image_height=480, image_width=640, look_at=(0.0, 0.0, 0.0),
                 up_direction=(0.0, -1.0, 0.0))
    return ws


def decode_window(data: bytes) -> list[dict]:
    """The messages of one server->client websocket frame (zstd msgpack + binary tail)."""
    import msgspec
    import zstandard

    n_inner = int.from_bytes(data[:8], "little")
    n_comp = int.from_bytes(data[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(data[16:16 + n_comp], max_output_size=n_inner)
    return list(msgspec.msgpack.decode(inner)["messages"])


def _mentions(obj: object, text: str) -> bool:
    if isinstance(obj, str):
        return obj == text
    if isinstance(obj, dict):
        return any(_mentions(v, text) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return any(_mentions(v, text) for v in obj)
    return False


def wait_for_label(ws, label: str, timeout_s: float) -> bool:
    """Read the viewer's websocket until a message carrying ``label`` arrives (True) or
    ``timeout_s`` passes (False)."""
    end = time.monotonic() + timeout_s
    while (left := end - time.monotonic()) > 0:
        try:
            data = ws.recv(timeout=left)
        except TimeoutError:
            return False
        if isinstance(data, bytes) and any(_mentions(m, label) for m in decode_window(data)):
            return True
    return False


def send_message(ws, message_type: str, **fields: object) -> None:
    """Send one client->server viser message (msgpack ``{"type": ..., **fields}``)."""
    import msgspec

    ws.send(msgspec.msgpack.encode({"type": message_type, **fields}))



def drain_callbacks(server, timeout_s: float = 20.0) -> None:
    """Return once every callback viser queued on its thread pool before this call (a viewer's
    connect and disconnect) has run to its end: a task on every one of the pool's threads at once
    (a barrier) means no earlier task still runs. An event, not a guessed wait."""
    pool = server._thread_executor
    barrier = threading.Barrier(pool._max_workers + 1, timeout=timeout_s)
    for _ in range(pool._max_workers):
        pool.submit(barrier.wait)
    barrier.wait()

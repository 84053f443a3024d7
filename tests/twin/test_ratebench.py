"""``twin.dashboard.ratebench.count_image_updates`` (``bench dashboard``'s count) in the real
chromium (the session's) on a page of its own: two GUI-like images (blob URLs swapped every
100 ms), the second starting late, as the twin's does when its seeding takes seconds on a
busy machine.

Defect (a fresh clone's suite, `bench dashboard --warmup 0`): counting began as soon as both
image elements existed, so a twin image that started moving late read 0.5 updates/s over 2 s."""

from __future__ import annotations

import http.server
import threading
from collections.abc import Iterator

import pytest

from twin.dashboard.ratebench import count_image_updates

PAGE = """<!doctype html><html><body><img id=a><img id=b><script>
const blob = (n) => URL.createObjectURL(new Blob(
  [`<svg xmlns="http://www.w3.org/2000/svg" width="8" height="8"><text y="8">${n}</text></svg>`],
  {type: "image/svg+xml"}));
let n = 0;
const a = document.getElementById("a"), b = document.getElementById("b");
a.src = blob(n); b.src = blob(n);
setInterval(() => { a.src = blob(++n); }, 100);
setTimeout(() => setInterval(() => { b.src = blob(++n); }, 100), %(late_ms)d);
</script></body></html>"""


@pytest.fixture
def late_twin_page() -> Iterator[str]:
    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = (PAGE % {"late_ms": 3000}).encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}/"
    finally:
        srv.shutdown()
        srv.server_close()


@pytest.mark.browser
@pytest.mark.timeout(300)
def test_counting_starts_once_both_images_move(page, late_twin_page: str) -> None:
    """With no warm-up, a 1 s window counts both images at their 10 Hz, the late one too."""
    rate = count_image_updates(page, late_twin_page, seconds=1.0, warmup_s=0.0)
    assert rate.seconds == 1.0
    assert rate.camera_hz >= 5.0 and rate.twin_hz >= 5.0, rate

"""The dashboard's door (real websocket clients, no browser): the origin policy, no framing, the share
tunnel only for the operator, twenty viewers at once, per-viewer unlock limits, a locked viewer's
callbacks refused by the server, and an accurate security log (malformed messages as one line)."""

from __future__ import annotations

import logging
import threading
import urllib.request
from collections.abc import Iterator

import pytest
import viser
import websockets

from tests.twin.dashboard_fakes import RecordingControls
from tests.twin.dashboard_helpers import (
    CLOSED_CONNECTION_OK,
    drain_callbacks,
    open_viewer,
    send_message,
    wait_for_label,
)
from tests.waiting import wait_until
from twin.dashboard import Dashboard
from twin.dashboard.guard import UnlockLimiter, UnlockPolicy, is_loopback, origin_allowed, tokens_match
from twin.records import ModeSet, event_fields
from twin.state import LiveState

pytestmark = CLOSED_CONNECTION_OK


# -- the door: origin, framing, share tunnel, many viewers (real websocket clients) ------
def test_origin_policy() -> None:
    ok = dict(bind_host="127.0.0.1", port=8080)
    assert origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080", **ok)
    assert origin_allowed("http://localhost:8080", "localhost:8080", **ok)
    assert origin_allowed("http://[::1]:8080", "[::1]:8080", **ok)
    for origin, host in [
        ("http://evil.example", "127.0.0.1:8080"),  # a hostile page in the operator's browser
        ("http://evil.example:8080", "evil.example:8080"),  # DNS rebinding to 127.0.0.1
        ("http://127.0.0.1:9999", "127.0.0.1:8080"),  # another local port's page
        ("http://127.0.0.1:8080", "127.0.0.1:9999"),
        ("null", "127.0.0.1:8080"), (None, "127.0.0.1:8080"), ("", "127.0.0.1:8080"),
        ("http://127.0.0.1:8080", None), ("http://127.0.0.1:8080/x", "127.0.0.1:8080"),
        ("ftp://127.0.0.1:8080", "127.0.0.1:8080"), ("http://127.0.0.1:99999", "127.0.0.1:8080"),
        ("http://127.0.0.1:8080", "127.0.0.1:notaport"),
    ]:
        assert not origin_allowed(origin, host, **ok), (origin, host)
    lan = dict(bind_host="0.0.0.0", port=8080)  # beyond loopback: same origin, any name
    assert origin_allowed("http://mill-pc.lan:8080", "mill-pc.lan:8080", **lan)
    assert not origin_allowed("http://evil.example:8080", "mill-pc.lan:8080", **lan)
    assert is_loopback("localhost") and is_loopback("[::1]") and not is_loopback("0.0.0.0")


def test_token_compare_is_safe_for_any_input() -> None:
    assert tokens_match("s3cret", "s3cret")
    for given in ("", "s3cre", "s3cret ", "ünïcode ✓", "\udcff", "x" * 100_000, None, 12, b"s3cret"):
        assert not tokens_match(given, "s3cret"), given
    assert tokens_match("ünïcode ✓", "ünïcode ✓")
    assert not tokens_match("anything", None) and not tokens_match("", "")


def test_unlock_limiter_is_per_viewer_and_per_address_never_global() -> None:
    lim = UnlockLimiter(UnlockPolicy(per_client_s=1.0, max_failures=3, max_failures_per_address=5, window_s=60.0))
    assert lim.wait_s(1, 0.0, "10.0.0.9") == 0.0
    lim.attempt(1, 0.0, ok=False, address="10.0.0.9")
    assert lim.wait_s(1, 0.5, "10.0.0.9") == pytest.approx(0.5) and lim.wait_s(2, 0.5, "10.0.0.9") == 0.0
    for t in (1.0, 2.0):
        lim.attempt(1, t, ok=False, address="10.0.0.9")
    assert lim.wait_s(1, 3.0, "10.0.0.9") == pytest.approx(57.0)  # viewer 1: three failures, it waits
    assert lim.wait_s(2, 3.0, "10.0.0.9") == 0.0  # another viewer of the same host does not
    assert lim.wait_s(7, 3.0, "10.0.0.1") == 0.0  # nor one elsewhere: never a global lock-out
    lim.attempt(2, 3.0, ok=False, address="10.0.0.9")
    lim.attempt(3, 3.0, ok=False, address="10.0.0.9")  # five from one address: that address waits
    assert lim.wait_s(4, 4.0, "10.0.0.9") == pytest.approx(56.0)
    assert lim.wait_s(7, 4.0, "10.0.0.1") == 0.0  # the operator's address is untouched
    lim.forget(1)  # reconnecting clears the viewer's own slot, not its address's failures
    assert lim.wait_s(1, 4.0, "10.0.0.9") == pytest.approx(56.0)
    assert lim.wait_s(4, 60.01, "10.0.0.9") == 0.0  # the oldest failures left the window
    lim.attempt(7, 61.0, ok=True, address="10.0.0.1")
    assert lim.wait_s(7, 61.5, "10.0.0.1") == pytest.approx(0.5)


@pytest.fixture(scope="module")
def local_dash() -> Iterator[tuple[Dashboard, RecordingControls, list]]:
    state = LiveState()
    state.record(ModeSet(t_s=0.0, mode="off"))
    controls = RecordingControls()
    events: list = []
    dash = Dashboard(state, controls, port=0, update_hz=4,
                     on_event=lambda rec: events.append((rec.kind, event_fields(rec)))).start()
    try:
        yield dash, controls, events
    finally:
        dash.stop()


@pytest.mark.timeout(60)
def test_foreign_origins_are_refused_own_is_accepted(local_dash) -> None:
    dash, _, events = local_dash
    for origin in ("http://evil.example", None, f"http://localhost:{dash.port + 1}"):
        with pytest.raises(websockets.exceptions.InvalidStatus) as exc:
            open_viewer(dash.url, origin=origin)
        assert exc.value.response.status_code == 403
        assert exc.value.response.headers["X-Frame-Options"] == "DENY"
    assert dash.refused_handshakes == 3
    refused = [f for k, f in events if k == "dashboard_refused"]  # throttled: one per 5 s
    assert refused == [{"suppressed": 0, "origin": "http://evil.example", "host": f"127.0.0.1:{dash.port}"}]
    with open_viewer(dash.url) as ws:  # the dashboard's own page
        assert wait_for_label(ws, "EMERGENCY STOP", 20)


def test_http_responses_forbid_framing(local_dash) -> None:
    dash, _, _ = local_dash
    with urllib.request.urlopen(dash.url + "/", timeout=10) as r:
        assert r.status == 200
        assert r.headers["X-Frame-Options"] == "DENY"
        assert "frame-ancestors 'none'" in r.headers["Content-Security-Policy"]


@pytest.mark.timeout(60)
def test_a_viewer_cannot_start_the_share_tunnel(local_dash, monkeypatch) -> None:
    import viser._viser

    started: list[tuple] = []

    def no_tunnel(*args: object, **kw: object) -> None:
        started.append(args)
        raise RuntimeError("test: no tunnel")

    monkeypatch.setattr(viser._viser, "ViserTunnel", no_tunnel)
    dash, _, _ = local_dash
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
        send_message(ws, "ShareUrlRequest")
        wait_for_label(ws, "never sent", 1.0)
    assert started == [] and dash._server.request_share_url() is None and started == []


@pytest.mark.timeout(90)
def test_twenty_viewers_at_once_all_get_emergency_stop(local_dash) -> None:
    dash, _, _ = local_dash
    n = 20
    barrier = threading.Barrier(n)
    got: list[bool] = []
    errors: list[BaseException] = []
    lock = threading.Lock()

    def viewer() -> None:
        try:
            barrier.wait(20)
            with open_viewer(dash.url, timeout_s=30) as ws:
                ok = wait_for_label(ws, "EMERGENCY STOP", 40)
                with lock:
                    got.append(ok)
                barrier.wait(60)  # all still connected while the server is counted
                if ok:
                    with lock:
                        if len(got) == n:
                            got.append(dash.viewers_with_estop() >= n)
        except BaseException as exc:
            with lock:
                errors.append(exc)

    threads = [threading.Thread(target=viewer) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(80)
    assert errors == [] and got[:n] == [True] * n
    assert got[n:] == [True]  # the server built controls for every one of them


# -- issue 26 item 10: an accurate security log; malformed messages as one line ----------
@pytest.fixture
def fresh_dash() -> Iterator[tuple[Dashboard, list]]:
    events: list = []
    dash = Dashboard(LiveState(), RecordingControls(), port=0, update_hz=4,
                     on_event=lambda rec: events.append((rec.kind, event_fields(rec)))).start()
    try:
        yield dash, events
    finally:
        dash.stop()


@pytest.mark.timeout(60)
def test_suppressed_refusals_are_counted_in_the_log(fresh_dash) -> None:
    dash, events = fresh_dash
    for _ in range(12):
        with pytest.raises(websockets.exceptions.InvalidStatus):
            open_viewer(dash.url, origin="http://evil.example")
    dash.flush_throttled(force=True)  # also done by the update thread once 5 s passed, and at stop
    refused = [f for k, f in events if k == "dashboard_refused"]
    assert len(refused) == 2 and refused[1]["summary"] is True
    assert 1 + sum(f["suppressed"] for f in refused) == 12 == dash.refused_handshakes


@pytest.mark.timeout(60)
def test_quick_disconnects_are_not_refusals(fresh_dash) -> None:
    dash, events = fresh_dash

    class Gone:  # a viewer whose websocket closed before its controls were built
        client_id = 10_000

    dash._on_connect(Gone())  # type: ignore[arg-type]
    for _ in range(8):  # real viewers that leave at once
        open_viewer(dash.url).close()
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
    drain_callbacks(dash._server)  # every viewer's connect callback has run: none was counted as refused
    assert [k for k, _ in events if k == "dashboard_refused"] == []


@pytest.mark.timeout(60)
def test_malformed_websocket_messages_are_one_log_line(fresh_dash, capfd, caplog) -> None:
    dash, events = fresh_dash
    for junk in (b"\x00\x01garbage", None):
        with open_viewer(dash.url) as ws:
            assert wait_for_label(ws, "EMERGENCY STOP", 20)
            if junk is None:
                send_message(ws, "GuiUpdateMessage", uuid=5)  # valid msgpack, wrong fields
            else:
                ws.send(junk)
            wait_until(lambda: ws.protocol.close_code is not None or dash.bad_messages > 0, 10, "the drop")
        wait_until(lambda n=(1 if junk else 2): dash.bad_messages >= n, 10, "the malformed message reported")

    def records() -> list[logging.LogRecord]:
        return [r for r in caplog.records if r.name == "websockets.server" and r.levelno >= logging.WARNING]

    wait_until(lambda: len(records()) >= 2, 10, "both records (the filter counts before the handler logs)")
    assert "Traceback" not in capfd.readouterr().err
    got = records()
    dropped = "dashboard: dropped a viewer after a malformed message"
    assert [r.getMessage().split(" (")[0] for r in got] == [dropped] * 2
    assert all(r.exc_info is None and "\n" not in r.getMessage() for r in got)  # one line, no traceback
    assert [k for k, _ in events].count("dashboard_bad_message") == 1  # throttled; the second is counted
    dash.flush_throttled(force=True)
    assert [f.get("suppressed") for k, f in events if k == "dashboard_bad_message"] == [0, 1]


def test_the_viser_internals_the_dashboard_relies_on(fresh_dash) -> None:
    """Issue 25 item 6: the versions are the checked ones, and each internal exists. (The record
    of websockets' that the one-line filter rewrites is checked by what it does:
    ``test_malformed_websocket_messages_are_one_log_line``.)"""
    import viser

    from twin.dashboard.guard import CHECKED_VERSIONS

    assert viser.__version__ in CHECKED_VERSIONS["viser"]
    assert websockets.__version__ in CHECKED_VERSIONS["websockets"]
    dash, _ = fresh_dash
    with open_viewer(dash.url) as ws:
        assert wait_for_label(ws, "EMERGENCY STOP", 20)
        (cid,) = list(dash._server._websock_server._live_connections)
        assert dash._client_address(cid) == "127.0.0.1"  # the per-address unlock limit's key


def test_the_gatekeeper_is_the_dashboards_policy_without_viser() -> None:
    """The policy split out of the viser server (``twin.dashboard.guard.Gatekeeper``): a
    wrong token is refused and counted, the right one unlocks, EMERGENCY STOP follows
    ``estop_needs_token``, a noisy event is written once per window with a count of the rest."""
    from twin.dashboard.guard import EVENT_THROTTLE_S, Gatekeeper

    now = [100.0]
    events: list[tuple[str, dict]] = []
    records: list = []

    def on_event(rec) -> None:
        records.append(rec)
        events.append((rec.kind, event_fields(rec)))

    gate = Gatekeeper("s3cret", on_event=on_event, estop_needs_token=True,
                      unlock_policy=UnlockPolicy(per_client_s=0.0, max_failures=5, window_s=60.0),
                      monotonic=lambda: now[0], now_s=lambda: now[0] - 100.0)
    assert gate.token_required and not gate.estop_allowed(False) and gate.estop_allowed(True)
    assert gate.try_unlock(1, "wrong", "10.0.0.1") == (False, "**wrong token: read-only**")
    assert gate.try_unlock(1, "s3cret", "10.0.0.1")[0] and gate.failed_unlocks == 1
    assert [k for k, _ in events] == ["dashboard_unlock_failed", "dashboard_unlocked"]
    for _ in range(3):
        gate.refused("http://evil.example", "127.0.0.1:8080")
    assert gate.refused_handshakes == 3 and [k for k, _ in events].count("dashboard_refused") == 1
    now[0] += EVENT_THROTTLE_S
    gate.flush_throttled()
    assert events[-1] == ("dashboard_refused", {"suppressed": 2, "summary": True})
    assert [r.t_s for r in records] == [0.0, 0.0, 0.0, EVENT_THROTTLE_S]  # stamped with the run clock
    assert not Gatekeeper(None).token_required and Gatekeeper(None).estop_allowed(False)


@pytest.mark.timeout(60)
def test_a_locked_viewers_callbacks_are_refused_by_the_server() -> None:
    """viser runs a control's callbacks on the server for whatever a viewer's websocket
    sends: a disabled button in the browser is no defence. Every callback of a viewer without
    the token (``twin.dashboard.controls``: each re-checks its viewer) moves nothing; its
    EMERGENCY STOP still works. The callbacks are run as viser runs them (its handle's
    callbacks, with a ``GuiEvent`` from that viewer)."""
    controls = RecordingControls()
    dash = Dashboard(LiveState(), controls, port=0, update_hz=4, control_token="s3cret").start()
    try:
        with open_viewer(dash.url, timeout_s=20) as ws:
            assert wait_for_label(ws, "EMERGENCY STOP", 30)
            wait_until(lambda: dash.viewers_with_estop() == 1, 10, "the viewer's controls")
            (cid, client), = dash._server.get_clients().items()
            cc = dash.viewers._clients[cid]
            for handle in cc.handles:
                for cb in handle._impl.update_cb:
                    cb(viser.GuiEvent(client, cid, handle))
            assert controls.names() == [] and "refused" in cc.status.content
            for cb in cc.estop._impl.update_cb:
                cb(viser.GuiEvent(client, cid, cc.estop))
            assert controls.names() == ["emergency_stop"]
    finally:
        dash.stop()

"""The dashboard's front door: who may open its websocket, what its pages may be framed
by, how control-token unlocks are compared and rate-limited.

Threat model: a hostile web page open in the operator's browser (any tab) can make the
browser open a websocket to ``ws://127.0.0.1:8080``; the browser then sends the
*page's* ``Origin``. So the websocket handshake is refused (HTTP 403) unless its
``Origin`` is the dashboard's own, i.e. the same scheme/host/port as the ``Host`` the
browser connected to; a missing or ``null`` Origin is refused too (browsers always send
one; a script must send the dashboard's). On a loopback bind the ``Host`` must also be a
loopback name (``127.0.0.1``, ``localhost``, ``[::1]``), which defeats DNS rebinding (an
attacker's name re-pointed at 127.0.0.1 has the attacker's name as ``Host``).

Decision: a dashboard started without a control token (allowed on loopback only)
authorises every client that gets through this door; with ``--control-token`` the token
is enforced on any host, loopback included. EMERGENCY STOP is enabled for every viewer
(a stop is always safe) unless the dashboard is told otherwise (``estop_needs_token``,
for open networks). Token attempts are limited per viewer and per client address,
never globally, so nobody can lock the operator out (:class:`UnlockLimiter`).

Every HTTP response (the page, its scripts, the refused handshake) carries
``X-Frame-Options: DENY`` and ``Content-Security-Policy: frame-ancestors 'none'`` so the
dashboard cannot be framed for click-jacking.

viser 1.1 serves its page and websocket with the ``websockets`` library and offers no
hook for the handshake, so :func:`install_handshake_guard` wraps the running
``websockets`` server's ``process_request``/``process_response`` (read on every new
connection) and refuses to start when it cannot find it (fail closed).
"""

from __future__ import annotations

import gc
import hashlib
import hmac
import http
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from twin.config import LOCAL_HOSTS
from twin.errors import TwinError
from twin.records import (
    DashboardBadMessage,
    DashboardEvent,
    DashboardRefused,
    DashboardUnlocked,
    DashboardUnlockFailed,
    DashboardUnlockLimited,
    Record,
    event_fields,
    kind_of,
)

if TYPE_CHECKING:
    from viser import ViserServer

CHECKED_VERSIONS: dict[str, tuple[str, ...]] = {"viser": ("1.1.1",), "websockets": ("16.1.1",)}
"""Versions whose internals the dashboard relies on were checked against (the websocket
server found by :func:`install_handshake_guard`, ``_live_connections`` and a connection's
``remote_address`` for the per-address unlock limit, the ``websockets.server`` log record
of a failed handler for :class:`OneLineConnectionErrors`); ``tests/twin/test_dashboard_door.py``
tests each assumption and fails on a version not listed here."""

LOOPBACK_HOSTS = frozenset(LOCAL_HOSTS)  # the one list: twin.config.LOCAL_HOSTS
FRAME_HEADERS: tuple[tuple[str, str], ...] = (
    ("X-Frame-Options", "DENY"),
    ("Content-Security-Policy", "frame-ancestors 'none'"),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),
)


def is_loopback(host: str) -> bool:
    """True for a loopback bind address or host name (``127.0.0.1``, ``localhost``, ``::1``)."""
    return host.strip("[]").lower() in LOOPBACK_HOSTS


def _host_port(authority: str) -> tuple[str, int | None] | None:
    """``"host:port"`` / ``"[::1]:8080"`` -> (host, port), None when malformed."""
    try:
        parts = urlsplit("//" + authority)
        return (parts.hostname or "").lower(), parts.port
    except ValueError:
        return None


def origin_allowed(origin: str | None, host_header: str | None, *, bind_host: str, port: int) -> bool:
    """May a browser page from ``origin`` open the dashboard's websocket?

    True only when ``origin`` is ``http://<Host header>`` (same origin, the dashboard's
    own page), the Host names our ``port``, and, on a loopback bind, the Host is a
    loopback name (no DNS rebinding). Pure: the handshake hook calls it per request.
    """
    if not origin or not host_header or origin == "null":
        return False
    o = urlsplit(origin)
    if o.scheme not in ("http", "https") or o.path not in ("", "/") or o.query or o.fragment:
        return False
    try:
        o_host, o_port = (o.hostname or "").lower(), o.port
    except ValueError:
        return False
    hp = _host_port(host_header)
    if hp is None or not o_host:
        return False
    h_host, h_port = hp
    default = 443 if o.scheme == "https" else 80
    if (o_host, o_port or default) != (h_host, h_port or default):
        return False
    if (h_port or default) != port:
        return False
    return not is_loopback(bind_host) or is_loopback(h_host)


def tokens_match(given: object, expected: str | None) -> bool:
    """Constant-time token compare that is safe for any input (any unicode, any length,
    non-strings): both sides are UTF-8 encoded and hashed, then ``hmac.compare_digest``."""
    if not expected:
        return False
    try:
        g = str(given).encode("utf-8", "surrogatepass")
    except Exception:
        return False
    e = expected.encode("utf-8", "surrogatepass")
    return hmac.compare_digest(hashlib.sha256(g).digest(), hashlib.sha256(e).digest())


@dataclass(frozen=True)
class UnlockPolicy:
    """Limits on token guessing, per viewer and per client address, never global (one
    viewer's or one host's failures never lock out another with the right token):
    one attempt per ``per_client_s`` per viewer; a viewer with ``max_failures`` failed
    attempts within ``window_s`` waits, and so does every viewer of an address with
    ``max_failures_per_address`` failures within ``window_s`` (opening many viewers from
    one host does not help)."""

    per_client_s: float = 1.0
    max_failures: int = 5
    max_failures_per_address: int = 20
    window_s: float = 60.0


class UnlockLimiter:
    """Rate limiter of control-token attempts (pure: the caller passes the time, s).
    Keys: the viewer (``client_id``) and its client address (``address``, any string)."""

    def __init__(self, policy: UnlockPolicy | None = None) -> None:
        self.policy = policy or UnlockPolicy()
        self._last_try: dict[int, float] = {}
        self._by_client: dict[int, deque[float]] = {}
        self._by_address: dict[str, deque[float]] = {}

    def _recent(self, failures: deque[float] | None, now_s: float) -> deque[float]:
        if failures is None:
            return deque()
        while failures and now_s - failures[0] >= self.policy.window_s:
            failures.popleft()
        return failures

    def wait_s(self, client_id: int, now_s: float, address: str = "") -> float:
        """Seconds ``client_id`` (at ``address``) must wait before its next attempt (0: may try now)."""
        p = self.policy
        wait = 0.0
        last = self._last_try.get(client_id)
        if last is not None:
            wait = max(wait, p.per_client_s - (now_s - last))
        for failures, limit in (
            (self._recent(self._by_client.get(client_id), now_s), p.max_failures),
            (self._recent(self._by_address.get(address), now_s), p.max_failures_per_address),
        ):
            if len(failures) >= limit:
                wait = max(wait, p.window_s - (now_s - failures[-limit]))
        if not self._by_address.get(address):
            self._by_address.pop(address, None)  # no empty entries left behind
        return max(0.0, wait)

    def attempt(self, client_id: int, now_s: float, ok: bool, address: str = "") -> None:
        """Record an attempt that was allowed (``wait_s`` was 0) and its outcome."""
        self._last_try[client_id] = now_s
        if not ok:
            self._by_client.setdefault(client_id, deque()).append(now_s)
            self._by_address.setdefault(address, deque()).append(now_s)

    def forget(self, client_id: int) -> None:
        """A viewer left: its own slots are dropped (its address keeps its failures, so
        reconnecting does not reset the address limit)."""
        self._last_try.pop(client_id, None)
        self._by_client.pop(client_id, None)


def _find_ws_server(port: int) -> Any:
    """The ``websockets.asyncio.server.Server`` listening on ``port`` in this process."""
    from websockets.asyncio.server import Server

    for obj in gc.get_objects():
        if type(obj) is Server:
            try:
                socks = obj.server.sockets
            except (AttributeError, RuntimeError):
                continue
            if any(s.getsockname()[1] == port for s in socks):
                return obj
    return None


def install_handshake_guard(
    port: int,
    bind_host: str,
    on_refused: Callable[[str | None, str | None], None] | None = None,
) -> None:
    """Wrap the handshake of the websockets server on ``port``: refuse foreign Origins
    (403) and add :data:`FRAME_HEADERS` to every response. Raises TwinError when the
    server cannot be found (the dashboard then does not start without its guard)."""
    server = _find_ws_server(port)
    if server is None:
        raise TwinError(f"dashboard: cannot guard the websocket on port {port} (viser changed?)")
    inner_request = server.process_request
    inner_response = server.process_response

    def process_request(connection: Any, request: Any) -> Any:
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin, host = request.headers.get("Origin"), request.headers.get("Host")
            if not origin_allowed(origin, host, bind_host=bind_host, port=port):
                if on_refused is not None:
                    on_refused(origin, host)
                return connection.respond(http.HTTPStatus.FORBIDDEN, "websocket origin not allowed\n")
        return inner_request(connection, request) if inner_request is not None else None

    def process_response(connection: Any, request: Any, response: Any) -> Any:
        if inner_response is not None:
            response = inner_response(connection, request, response) or response
        for name, value in FRAME_HEADERS:
            response.headers[name] = value
        return response

    server.process_request = process_request
    server.process_response = process_response


_HANDLER_FAILURES = ("connection handler failed", "opening handshake failed")


class OneLineConnectionErrors(logging.Filter):
    """Turns the ``websockets`` server's traceback for a connection whose handler failed
    (viser raises on a malformed message from a viewer: msgpack junk, a wrong field) into
    one log line, and reports it to ``on_error(detail)``. Only records of the
    connections on ``port`` are touched (the logger is shared by every server)."""

    def __init__(self, port: int, on_error: Callable[[str], None] | None = None) -> None:
        super().__init__()
        self.port = port
        self.on_error = on_error

    def filter(self, record: logging.LogRecord) -> bool:
        if not record.exc_info or record.msg not in _HANDLER_FAILURES:
            return True
        ws = getattr(record, "websocket", None)
        try:
            local = ws.local_address if ws is not None else None
        except Exception:
            local = None
        if not (isinstance(local, tuple) and len(local) >= 2 and local[1] == self.port):
            return True
        exc = record.exc_info[1]
        detail = f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0][:200]}"
        record.msg, record.args = "dashboard: dropped a viewer after a malformed message (%s)", (detail,)
        record.exc_info, record.exc_text, record.levelno, record.levelname = None, None, logging.WARNING, "WARNING"
        if self.on_error is not None:
            try:
                self.on_error(detail)
            except Exception:
                pass
        return True


def install_connection_error_filter(
    port: int, on_error: Callable[[str], None] | None = None
) -> Callable[[], None]:
    """Install :class:`OneLineConnectionErrors` on the ``websockets.server`` logger; returns
    the function that removes it again (the dashboard calls it when it stops)."""
    flt = OneLineConnectionErrors(port, on_error)
    logger = logging.getLogger("websockets.server")
    logger.addFilter(flt)
    return lambda: logger.removeFilter(flt)


# -- the policy: token, unlock limits, security events ----------------------------------------
EVENT_THROTTLE_S = 5.0  # noisy security events (refused handshakes, limited unlocks): at most one per 5 s
RecordSink = Callable[[Record], None]
"""``on_event(record)``: where the dashboard reports its records (the run's ``EventSink.publish``)."""
_log = logging.getLogger("drumtwin.dashboard")


class Gatekeeper:
    """The dashboard's security policy, without viser: whether a token is needed, token
    attempts under :class:`UnlockLimiter`, who may press EMERGENCY STOP, and the security
    events (typed records to ``on_event`` at run time ``now_s()``, noisy ones throttled to one
    per ``EVENT_THROTTLE_S`` per kind with a count of the ones suppressed). Thread-safe."""

    def __init__(
        self,
        control_token: str | None,
        *,
        on_event: RecordSink | None = None,
        unlock_policy: UnlockPolicy | None = None,
        estop_needs_token: bool = False,
        monotonic: Callable[[], float] = time.monotonic,
        now_s: Callable[[], float] = lambda: 0.0,
    ) -> None:
        self._token = control_token
        self.token_required = bool(control_token)  # on any host, loopback too
        self.estop_needs_token = bool(estop_needs_token)
        self._on_event = on_event
        self._limiter = UnlockLimiter(unlock_policy)
        self._lock = threading.Lock()
        self._throttle: dict[type[DashboardEvent], tuple[float, int]] = {}  # kind -> (last reported, suppressed)
        self._monotonic = monotonic
        self.now_s = now_s
        self.refused_handshakes = 0
        self.failed_unlocks = 0
        self.bad_messages = 0

    def publish(self, rec: Record) -> None:
        """Report a record to ``on_event`` (default: the ``drumtwin.dashboard`` log)."""
        if self._on_event is not None:
            try:
                self._on_event(rec)
                return
            except Exception:
                _log.exception("dashboard event sink failed")
        _log.warning("%s %s", kind_of(rec), event_fields(rec))

    def publish_throttled(self, rec: DashboardEvent) -> None:
        """Like :meth:`publish`, at most once per ``EVENT_THROTTLE_S`` per kind (a hostile page
        can retry a refused handshake in a loop); ``suppressed`` counts the ones not sent."""
        now = self._monotonic()
        kind = type(rec)
        with self._lock:
            last, suppressed = self._throttle.get(kind, (-math.inf, 0))
            if now - last < EVENT_THROTTLE_S:
                self._throttle[kind] = (last, suppressed + 1)
                return
            self._throttle[kind] = (now, 0)
        self.publish(replace(rec, suppressed=suppressed))

    def flush_throttled(self, force: bool = False) -> None:
        """Write the counts of throttled events suppressed since their last report once
        their window has passed (``force``: now, e.g. when the dashboard stops), so the
        log says how many refused handshakes or limited unlocks there were."""
        now = self._monotonic()
        due: list[tuple[type[DashboardEvent], int]] = []
        with self._lock:
            for kind, (last, suppressed) in self._throttle.items():
                if suppressed and (force or now - last >= EVENT_THROTTLE_S):
                    due.append((kind, suppressed))
                    self._throttle[kind] = (now, 0)
        for kind, suppressed in due:
            self.publish(kind(t_s=self.now_s(), suppressed=suppressed, summary=True))

    def bad_message(self, detail: str) -> None:
        self.bad_messages += 1
        self.publish_throttled(DashboardBadMessage(t_s=self.now_s(), error=detail))

    def refused(self, origin: str | None, host: str | None) -> None:
        self.refused_handshakes += 1
        self.publish_throttled(DashboardRefused(t_s=self.now_s(), origin=origin, host=host))

    def try_unlock(self, client_id: int, given: object, address: str = "") -> tuple[bool, str]:
        """Check a token attempt under the per-viewer and per-address rate limits;
        returns (authorised, message)."""
        now = self._monotonic()
        with self._lock:
            wait = self._limiter.wait_s(client_id, now, address)
            ok = wait <= 0 and tokens_match(given, self._token)
            if wait <= 0:
                self._limiter.attempt(client_id, now, ok, address)
        if wait > 0:
            self.publish_throttled(DashboardUnlockLimited(t_s=self.now_s(), client=client_id, address=address,
                                                        wait_s=round(wait, 1)))
            return False, f"**too many attempts: wait {math.ceil(wait)} s**"
        if not ok:
            self.failed_unlocks += 1
            self.publish(DashboardUnlockFailed(t_s=self.now_s(), client=client_id, address=address))
            return False, "**wrong token: read-only**"
        self.publish(DashboardUnlocked(t_s=self.now_s(), client=client_id))
        return True, "controls unlocked"

    def estop_allowed(self, authorised: bool) -> bool:
        """EMERGENCY STOP for every viewer (a stop is always safe) unless ``estop_needs_token``."""
        return authorised or not self.estop_needs_token

    def forget(self, client_id: int) -> None:
        with self._lock:
            self._limiter.forget(client_id)


# -- viser internals (pinned: CHECKED_VERSIONS) -------------------------------------------------
def disable_share_tunnel(server: ViserServer) -> None:
    """No share URL: viser's tunnel would publish the dashboard on the internet. viser 1.1
    registers the share handlers on its websocket server; the public ``request_share_url``
    is replaced by a no-op too."""
    from viser import _messages

    ws = server._websock_server
    for msg in (_messages.ShareUrlRequest, _messages.ShareUrlDisconnect):
        if msg in ws._incoming_handlers:
            ws.unregister_handler(msg)

    def no_share(verbose: bool = True) -> None:
        return None

    server.request_share_url = no_share  # type: ignore[method-assign]


def _connection(server: ViserServer, client_id: int) -> Any:
    return server._websock_server._live_connections.get(client_id)


def client_headers(server: ViserServer, client_id: int) -> tuple[str | None, str | None] | None:
    """(Origin, Host) of a viewer's websocket handshake; None when the viewer has already
    disconnected; (None, None) when its request is unknown."""
    conn = _connection(server, client_id)
    if conn is None:
        return None
    request = getattr(conn, "request", None)
    if request is None:
        return (None, None)
    h = request.headers
    return (h.get("Origin"), h.get("Host"))


def client_address(server: ViserServer, client_id: int) -> str:
    """The viewer's client address (IP), "" when unknown."""
    conn = _connection(server, client_id)
    try:
        addr = conn.remote_address if conn is not None else None
    except Exception:
        addr = None
    return str(addr[0]) if isinstance(addr, tuple) and addr else ""


def close_client(server: ViserServer, client_id: int) -> None:
    """Drop one viewer's websocket (viser reconnects it; the handshake guard refuses it then)."""
    ws = server._websock_server
    conn = ws._live_connections.get(client_id)
    loop = ws._background_event_loop
    if conn is not None and loop is not None:
        import asyncio

        asyncio.run_coroutine_threadsafe(conn.close(), loop)

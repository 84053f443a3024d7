"""The viser dashboard: camera against twin, plots, numbers, controls, what-if.

Three parts, each in its own module, composed here:

* the door and the policy (``twin.dashboard.guard``): websocket handshakes from a foreign
  ``Origin`` are refused, every response forbids framing, viser's share-URL tunnel is
  disabled; the control token (required beyond loopback, enforced on loopback too), its
  rate-limited unlock attempts and the security events (:class:`Gatekeeper`);
* the shared layout (``twin.dashboard.layout``): images, plots, numbers, alarms, what-if
  results, shared by all viewers and pushed by one update thread from
  ``LiveState.snapshot()``: it polls at twice ``update_hz`` so no image published at
  ``update_hz`` is missed, and redraws the plots at a quarter of that poll rate (uPlot
  redraws cost the browser more than images); it never touches the loop's threads;
* each viewer's controls (``twin.dashboard.controls``): built per viser client, one at a
  time, so every viewer gets them and EMERGENCY STOP however many connect at once; without
  the token a viewer has EMERGENCY STOP only (``estop_needs_token``: not even that);
* the set-up view (``twin.dashboard.setup``): commissioning on the live camera (``setup``:
  what it reads of the run), its checks in a tab, its report one click away.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import viser

from control.limits import Limits
from twin.dashboard.controls import Viewers
from twin.dashboard.guard import (
    Gatekeeper,
    RecordSink,
    UnlockPolicy,
    client_address,
    client_headers,
    close_client,
    disable_share_tunnel,
    install_connection_error_filter,
    install_handshake_guard,
    is_loopback,
    origin_allowed,
)
from twin.dashboard.layout import Layout, alarms_html, axis_range, numbers_markdown, parse_rpm_list
from twin.dashboard.setup import SetupFeed, SetupView
from twin.records import DashboardRefused
from twin.state import Controls, LiveState

_log = logging.getLogger("drumtwin.dashboard")

__all__ = ["Dashboard", "alarms_html", "axis_range", "numbers_markdown", "parse_rpm_list"]


class Dashboard:
    """viser server showing ``state`` and forwarding operator actions to ``controls``."""

    def __init__(
        self,
        state: LiveState,
        controls: Controls,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        control_token: str | None = None,
        update_hz: float = 12.0,
        title: str = "drumtwin",
        on_event: RecordSink | None = None,
        unlock_policy: UnlockPolicy | None = None,
        limits: Limits | None = None,
        estop_needs_token: bool = False,
        now_s: Callable[[], float] | None = None,
        setup: SetupFeed | None = None,
    ) -> None:
        if not is_loopback(host) and not control_token:
            raise ValueError(f"binding the dashboard to {host} needs a control token")
        self.limits = limits or Limits()
        self.gate = Gatekeeper(control_token, on_event=on_event, unlock_policy=unlock_policy,
                               estop_needs_token=estop_needs_token,
                               now_s=now_s if now_s is not None else lambda: state.panel.t_s or 0.0)
        self._build_lock = threading.Lock()  # one viewer's controls built at a time
        self.state = state
        self.controls = controls
        self.host = host
        self.update_hz = float(update_hz)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.pushes = 0  # display updates pushed (images or plots), for the fps readout
        self._server = viser.ViserServer(host=host, port=port, label=title, verbose=False)
        self.port = int(self._server.get_port())
        try:
            install_handshake_guard(self.port, host, on_refused=self.gate.refused)
        except Exception:
            self._server.stop()
            raise
        self._remove_error_filter = install_connection_error_filter(self.port, self.gate.bad_message)
        disable_share_tunnel(self._server)
        self.layout = Layout(self._server, title)
        self.scene = self.layout.scene
        self.setup = SetupView(self._server, self.layout.plots_panel, setup)
        self.viewers = Viewers(self._server, self.layout, self.gate, controls, state, self.limits, self.setup)
        self._server.on_client_connect(self._on_connect)
        self._server.on_client_disconnect(self._on_disconnect)

    # -- the policy's counters (tests, benches) --------------------------------------
    @property
    def refused_handshakes(self) -> int:
        return self.gate.refused_handshakes

    @property
    def failed_unlocks(self) -> int:
        return self.gate.failed_unlocks

    @property
    def bad_messages(self) -> int:
        return self.gate.bad_messages

    def flush_throttled(self, force: bool = False) -> None:
        """See :meth:`Gatekeeper.flush_throttled`."""
        self.gate.flush_throttled(force)

    def _client_address(self, client_id: int) -> str:
        return client_address(self._server, client_id)

    # -- viewers -----------------------------------------------------------------------
    def _client_origin_ok(self, client: viser.ClientHandle) -> bool | None:
        """Second check of a viewer's handshake headers (the guard refuses foreign Origins
        at the door; this covers the moment before the guard was installed). None when
        the viewer has already disconnected (a quick reload, a closed tab)."""
        headers = client_headers(self._server, client.client_id)
        if headers is None:
            return None
        origin, host = headers
        return origin_allowed(origin, host, bind_host=self.host, port=self.port)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        ok = self._client_origin_ok(client)
        if ok is None:  # the viewer left before its controls were built: not a refusal
            return
        if not ok:
            self.gate.publish(DashboardRefused(t_s=self.gate.now_s(), client=client.client_id,
                                               origin="(after connect)"))
            close_client(self._server, client.client_id)
            return
        with self._build_lock:  # viser's shared folder context admits one builder at a time
            try:
                self.viewers.build(client)
            except Exception:
                _log.exception("building the controls of viewer %s failed", client.client_id)
        # viser drops the connection before it queues the disconnect callback, so a viewer that left
        # while it was being built is seen here even if its callback ran before the build registered it
        if client_headers(self._server, client.client_id) is None:
            self._on_disconnect(client)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        self.viewers.forget(client.client_id)
        self.gate.forget(client.client_id)

    def viewers_with_estop(self) -> int:
        """How many connected viewers have their controls (with EMERGENCY STOP) built."""
        return self.viewers.with_estop()

    # -- updates ---------------------------------------------------------------------
    def start(self) -> Dashboard:
        """Start the update thread; returns self."""
        self._thread = threading.Thread(target=self._run, name="dashboard", daemon=True)
        self._thread.start()
        self.setup.start()
        return self

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"http://{host}:{self.port}"

    def _run(self) -> None:
        period = 0.5 / self.update_hz
        seen: dict[str, int | str | None] = {"camera": -1, "twin": -1, "hist": -1, "mode": None}
        next_t = time.monotonic()
        tick = 0
        while not self._stop.is_set():
            try:
                self._push(seen, plots=(tick % 4 == 0))
            except Exception:  # a viewer closing mid-push must not kill the thread
                if self._stop.is_set():
                    break
            tick += 1
            if tick % 8 == 0:
                self.gate.flush_throttled()
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:
                next_t = time.monotonic()
                delay = 0
            self._stop.wait(delay)

    def _push(self, seen: dict[str, int | str | None], plots: bool) -> None:
        snap = self.state.snapshot()
        if self.layout.push(snap, seen, plots):
            self.pushes += 1
        mode = snap.panel.mode or "off"
        if mode != seen["mode"]:
            seen["mode"] = mode
            self.viewers.sync_mode(mode)

    def stop(self) -> None:
        """Stop the update thread and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.setup.stop()
        self.gate.flush_throttled(force=True)
        self._remove_error_filter()
        self._server.stop()

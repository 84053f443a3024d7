"""The viser dashboard: camera against twin, plots, numbers, controls, what-if.

Display elements (images, plots, numbers) are shared by all viewers and pushed by
one update thread from ``LiveState.snapshot()``: it polls at twice ``update_hz`` so
no image published at ``update_hz`` is missed, and redraws the plots at a quarter of
that poll rate (uPlot redraws cost the browser more than images); it never touches
the loop's threads. Controls are built per viewer (per viser client), one viewer at a
time (a lock: viser's shared folder context admits one builder), so every viewer gets
them and EMERGENCY STOP however many connect at once. With a control token (required
beyond loopback, enforced on loopback too) a viewer must enter it before its controls
are enabled; without it a viewer has EMERGENCY STOP only (``estop_needs_token``: not
even that). Token attempts are rate-limited per viewer and per address and failures
are reported as events. Every control callback re-checks that its viewer is authorised.
The rpm slider spans the run's limits (``control.limits``); a clamped rpm or a refused
what-if is told to the viewer who asked.

Security (see ``twin.dashboard.guard``): websocket handshakes from a foreign ``Origin``
are refused, every response forbids framing, and viser's share-URL tunnel is disabled
(no button, and the server ignores a viewer's request for one).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import viser

from control.errors import ControlError
from control.limits import WHATIF_MAX_RUNS, WHATIF_MAX_S, Limits
from twin.dashboard.guard import (
    UnlockLimiter,
    UnlockPolicy,
    install_connection_error_filter,
    install_handshake_guard,
    origin_allowed,
    tokens_match,
)
from twin.dashboard.scene import TwinScene
from twin.state import Controls, LiveState, Snapshot, WhatIfView, forward_fill

MODE_LABELS = ("OFF", "MANUAL", "AUTO")
_BLANK = np.full((240, 240, 3), 24, dtype=np.uint8)
_log = logging.getLogger("drumtwin.dashboard")
EVENT_THROTTLE_S = 5.0  # noisy security events (refused handshakes, limited unlocks): at most one per 5 s
EventSink = Callable[[str, dict[str, Any]], None]
"""``on_event(kind, fields)``: where the dashboard reports security events (e.g. the run log)."""
_WHATIF_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


DISPLAY_PX = 400  # frames are scaled to this width for the panel


def _rgb(image_bgr: np.ndarray) -> np.ndarray:
    """RGB copy for viser, scaled to ``DISPLAY_PX`` wide (small demo frames are enlarged)."""
    h, w = image_bgr.shape[:2]
    if w != DISPLAY_PX and w > 0:
        size = (DISPLAY_PX, max(1, round(h * DISPLAY_PX / w)))
        image_bgr = cv2.resize(image_bgr, size, interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(image_bgr[..., ::-1])


def whatif_table_md(w: WhatIfView) -> str:
    """The what-if table (markdown): per rpm the plateau MI, regime, time and energy to the target MI
    and the drive power (whole drum)."""
    target = "target" if w.target_mi is None else f"MI {w.target_mi:g}"
    lines = [f"| rpm | plateau MI | regime | time to {target} (s) | power (W) | energy (J) |",
             "|---:|---:|---|---:|---:|---:|"]
    lines += [
        f"| {r:g} | {_fmt(p)} | {g} | {_fmt(_at(w.time_to_target_s, i), '.1f')} | "
        f"{_fmt(_at(w.power_w, i), '.2f')} | {_fmt(_at(w.energy_to_target_j, i), '.0f')} |"
        for i, (r, p, g) in enumerate(zip(w.rpms, w.plateau_mi, w.regime, strict=True))
    ]
    return "\n".join(lines)


def _at(values: tuple[float, ...], i: int) -> float:
    """``values[i]``, NaN past its end (a study without that column)."""
    return values[i] if i < len(values) else float("nan")


def _fmt(value: Any, spec: str = ".3f") -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return "–" if not math.isfinite(value) else format(value, spec)
    return str(value)


def parse_rpm_list(text: str, limits: Limits | None = None) -> list[float]:
    """``"5, 20,40"`` -> ``[5.0, 20.0, 40.0]``; raises ValueError on junk, and on a list the
    what-if limits refuse (``control.limits``: the ``whatif`` command's caps), naming them."""
    try:
        rpms = [float(p) for p in str(text).replace(";", ",").split(",") if p.strip()]
    except ValueError:
        raise ValueError(f"rpm list must be numbers separated by commas (got {str(text)[:40]!r})") from None
    try:
        return (limits or Limits()).check_whatif(rpms, 1.0)[0]
    except ControlError as exc:
        raise ValueError(str(exc)) from None


def numbers_markdown(numbers: dict[str, Any]) -> str:
    """The numbers panel as a markdown table."""
    n = numbers
    rows = [
        ("MI (eq. 4)", _fmt(n.get("mi")), "trend", _fmt(n.get("trend_mi"))),
        ("d px", _fmt(n.get("d_px"), ".1f"), "dσ px", _fmt(n.get("dsigma_px"), ".1f")),
        ("concentration", _fmt(n.get("concentration")), "twin MI", _fmt(n.get("twin_mi"))),
        ("slope °", _fmt(n.get("slope_deg"), ".1f"), "twin slope °", _fmt(n.get("twin_slope_deg"), ".1f")),
        ("rpm set", _fmt(n.get("rpm_setpoint"), ".1f"), "rpm actual", _fmt(n.get("rpm_actual"), ".1f")),
        ("camera fps", _fmt(n.get("camera_fps"), ".1f"), "twin fps", _fmt(n.get("twin_fps"), ".1f")),
        ("mill", _fmt(n.get("mill_state")), "mode", _fmt(n.get("mode"))),
        ("run time s", _fmt(n.get("t_s"), ".1f"), "friction", _fmt(n.get("friction"))),
        ("trend", _fmt(n.get("trend_state")), "light", _fmt(n.get("light_state"))),
    ]
    lines = ["| | | | |", "|---|---:|---|---:|"]
    lines += [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    decision = n.get("last_decision")
    reason = n.get("last_reason")
    lines.append("")
    if str(n.get("light_state", "")).startswith("changed"):
        lines.append("**The light moved too far to map back to the set-up's: no MI.** Re-learn the classes "
                     "from the live bed (`drumtwin classes suggest`, then restart with the new config).  ")
    if n.get("trend_state") == "unsettled":
        lines.append("*Trend not settled yet: no segregation decision until it is.*  ")
    lines.append(f"**Last decision:** {decision or '–'}  \n{reason or ''}")
    return "\n".join(lines)


def axis_range(*series: np.ndarray, step: float, pad: float = 0.0) -> tuple[float, float] | None:
    """Y-axis range over the finite values of ``series``, padded and widened to multiples of ``step``.

    uPlot's own auto-range turns NaN (a twin not started yet) into an empty plot, so the
    dashboard sets the range itself; the step keeps it from changing on every update.
    None when no value is finite.
    """
    vals = np.concatenate([np.asarray(x, float).ravel() for x in series]) if series else np.zeros(0)
    vals = vals[np.isfinite(vals)]
    if vals.size == 0:
        return None
    lo = math.floor((float(vals.min()) - pad) / step) * step
    hi = math.ceil((float(vals.max()) + pad) / step) * step
    return (lo, hi) if hi > lo else (lo, lo + step)


def alarms_html(alarms: Sequence[str]) -> str:
    """A red banner per alarm, or a quiet OK line."""
    if not alarms:
        return '<div id="drumtwin-alarms" style="color:#2e7d32;font-weight:600">✔ no alarms</div>'
    items = "".join(f"<div>⚠ {a}</div>" for a in alarms)
    return (
        '<div id="drumtwin-alarms" style="background:#c62828;color:white;padding:6px 8px;'
        f'border-radius:4px;font-weight:600">ALARM{items}</div>'
    )


@dataclass
class _ClientControls:
    """One viewer's control handles."""

    authorised: bool
    handles: list[Any] = field(default_factory=list)
    mode: Any = None
    rpm: Any = None
    status: Any = None
    estop: Any = None


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
        on_event: EventSink | None = None,
        unlock_policy: UnlockPolicy | None = None,
        limits: Limits | None = None,
        estop_needs_token: bool = False,
    ) -> None:
        local = host in ("127.0.0.1", "localhost", "::1")
        if not local and not control_token:
            raise ValueError(f"binding the dashboard to {host} needs a control token")
        self.limits = limits or Limits()
        self.estop_needs_token = bool(estop_needs_token)
        self._on_event = on_event
        self._limiter = UnlockLimiter(unlock_policy)
        self._limiter_lock = threading.Lock()
        self._build_lock = threading.Lock()  # one viewer's controls built at a time
        self.refused_handshakes = 0
        self.failed_unlocks = 0
        self._throttle: dict[str, tuple[float, int]] = {}  # kind -> (last reported, suppressed since)
        self.state = state
        self.controls = controls
        self.host = host
        self.update_hz = float(update_hz)
        self._token = control_token
        self._token_required = bool(control_token)  # on any host, loopback too
        self._clients: dict[int, _ClientControls] = {}
        self._clients_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._y_ranges: dict[int, tuple[float, float]] = {}  # per plot: the y range last sent
        self.pushes = 0  # display updates pushed (images or plots), for the fps readout
        self._server = viser.ViserServer(host=host, port=port, label=title, verbose=False)
        self.port = int(self._server.get_port())
        try:
            install_handshake_guard(self.port, host, on_refused=self._refused)
        except Exception:
            self._server.stop()
            raise
        self.bad_messages = 0
        self._remove_error_filter = install_connection_error_filter(self.port, self._bad_message)
        self._disable_share_tunnel()
        self._build_shared(title)
        self.scene = TwinScene(self._server)
        self._server.on_client_connect(self._on_connect)
        self._server.on_client_disconnect(self._on_disconnect)

    # -- security ----------------------------------------------------------------------
    def _event(self, kind: str, **fields: Any) -> None:
        """Report a security event to ``on_event`` (default: the ``drumtwin.dashboard`` log)."""
        if self._on_event is not None:
            try:
                self._on_event(kind, fields)
                return
            except Exception:
                _log.exception("dashboard event sink failed")
        _log.warning("%s %s", kind, fields)

    def _event_throttled(self, kind: str, **fields: Any) -> None:
        """Like ``_event``, at most once per ``EVENT_THROTTLE_S`` per kind (a hostile page
        can retry a refused handshake in a loop); ``suppressed`` counts the ones not sent."""
        now = time.monotonic()
        with self._limiter_lock:
            last, suppressed = self._throttle.get(kind, (-math.inf, 0))
            if now - last < EVENT_THROTTLE_S:
                self._throttle[kind] = (last, suppressed + 1)
                return
            self._throttle[kind] = (now, 0)
        self._event(kind, suppressed=suppressed, **fields)

    def flush_throttled(self, force: bool = False) -> None:
        """Write the counts of throttled events suppressed since their last report once
        their window has passed (``force``: now, e.g. when the dashboard stops), so the
        log says how many refused handshakes or limited unlocks there were."""
        now = time.monotonic()
        due: list[tuple[str, int]] = []
        with self._limiter_lock:
            for kind, (last, suppressed) in self._throttle.items():
                if suppressed and (force or now - last >= EVENT_THROTTLE_S):
                    due.append((kind, suppressed))
                    self._throttle[kind] = (now, 0)
        for kind, suppressed in due:
            self._event(kind, suppressed=suppressed, summary=True)

    def _bad_message(self, kind: str, detail: str) -> None:
        self.bad_messages += 1
        self._event_throttled(kind, error=detail)

    def _refused(self, origin: str | None, host: str | None) -> None:
        self.refused_handshakes += 1
        self._event_throttled("dashboard_refused", origin=origin, host=host)

    def _disable_share_tunnel(self) -> None:
        """No share URL: viser's tunnel would publish the dashboard on the internet."""
        from viser import _messages

        ws = self._server._websock_server  # viser 1.1 registers the share handlers here
        for msg in (_messages.ShareUrlRequest, _messages.ShareUrlDisconnect):
            if msg in ws._incoming_handlers:
                ws.unregister_handler(msg)

        def no_share(verbose: bool = True) -> None:
            return None

        self._server.request_share_url = no_share  # type: ignore[method-assign]

    def _client_origin_ok(self, client: viser.ClientHandle) -> bool | None:
        """Second check of a viewer's handshake headers (the guard refuses foreign Origins
        at the door; this covers the moment before the guard was installed). None when
        the viewer has already disconnected (a quick reload, a closed tab)."""
        conn = self._server._websock_server._live_connections.get(client.client_id)
        if conn is None:
            return None
        request = getattr(conn, "request", None)
        if request is None:
            return False
        h = request.headers
        return origin_allowed(h.get("Origin"), h.get("Host"), bind_host=self.host, port=self.port)

    def _client_address(self, client_id: int) -> str:
        """The viewer's client address (IP), "" when unknown."""
        conn = self._server._websock_server._live_connections.get(client_id)
        try:
            addr = conn.remote_address if conn is not None else None
        except Exception:
            addr = None
        return str(addr[0]) if isinstance(addr, tuple) and addr else ""

    def _try_unlock(self, client_id: int, given: object, address: str = "") -> tuple[bool, str]:
        """Check a token attempt under the per-viewer and per-address rate limits;
        returns (authorised, message)."""
        now = time.monotonic()
        with self._limiter_lock:
            wait = self._limiter.wait_s(client_id, now, address)
            ok = wait <= 0 and tokens_match(given, self._token)
            if wait <= 0:
                self._limiter.attempt(client_id, now, ok, address)
        if wait > 0:
            self._event_throttled("dashboard_unlock_limited", client=client_id, address=address,
                                  wait_s=round(wait, 1))
            return False, f"**too many attempts: wait {math.ceil(wait)} s**"
        if not ok:
            self.failed_unlocks += 1
            self._event("dashboard_unlock_failed", client=client_id, address=address)
            return False, "**wrong token: read-only**"
        self._event("dashboard_unlocked", client=client_id)
        return True, "controls unlocked"

    # -- layout ------------------------------------------------------------------------
    def _build_shared(self, title: str) -> None:
        gui = self._server.gui
        gui.configure_theme(show_share_button=False, brand_color=(33, 90, 160))
        self._live_panel = gui.add_panel()
        with self._live_panel.add_tab("Camera vs twin"):
            self._alarm = gui.add_html(alarms_html(()))
            self._camera_img = gui.add_image(_BLANK, label="camera (live, with overlay)", jpeg_quality=80)
            self._twin_img = gui.add_image(_BLANK, label="twin (rendered)", jpeg_quality=80)
        self._live_panel.dock_left()
        self._live_panel.set_width(420)

        self._plots_panel = gui.add_panel()
        with self._plots_panel.add_tab("Plots"):
            self._numbers = gui.add_markdown(numbers_markdown({}))
            z = np.zeros(1)
            self._mi_plot = gui.add_uplot(
                (z,) * 7,
                (
                    {"label": "t s"},
                    {"label": "MI raw", "stroke": "#9e9e9e", "width": 1},
                    {"label": "trend", "stroke": "#1565c0", "width": 2},
                    {"label": "lo95", "stroke": "rgba(21,101,192,0.3)", "width": 1},
                    {"label": "hi95", "stroke": "rgba(21,101,192,0.3)", "width": 1},
                    {"label": "MA150", "stroke": "#ef6c00", "width": 1.5},
                    {"label": "twin MI", "stroke": "#2e7d32", "width": 2},
                ),
                title="Mixing index",
                bands=({"series": (4, 3), "fill": "rgba(21,101,192,0.15)"},),
                scales={"x": {"time": False}, "y": {"auto": False, "range": (0.0, 1.0)}},
                aspect=1.8,
            )
            self._rpm_plot = gui.add_uplot(
                (z,) * 3,
                (
                    {"label": "t s"},
                    {"label": "setpoint rpm", "stroke": "#6a1b9a", "width": 2},
                    {"label": "actual rpm", "stroke": "#00897b", "width": 2},
                ),
                title="Mill rpm",
                scales={"x": {"time": False}},
                aspect=2.6,
            )
            self._slope_plot = gui.add_uplot(
                (z,) * 3,
                (
                    {"label": "t s"},
                    {"label": "slope °", "stroke": "#5d4037", "width": 1.5},
                    {"label": "twin slope °", "stroke": "#2e7d32", "width": 1.5},
                ),
                title="Bed slope angle",
                scales={"x": {"time": False}},
                aspect=2.6,
            )
        self._plots_panel.dock_right()
        self._plots_panel.set_width(520)

        self._server.gui.main_panel.dock_right()
        self._server.gui.main_panel.set_width(340)
        self._controls_folder = gui.add_folder("Controls")
        self._whatif_folder = gui.add_folder("What-if")
        with self._whatif_folder:
            self._whatif_status = gui.add_markdown("No study yet.")
            self._whatif_plot = gui.add_uplot(
                (np.zeros(1), np.zeros(1)),
                ({"label": "t s"}, {"label": "–"}),
                title="What-if MI",
                scales={"x": {"time": False}, "y": {"auto": False, "range": (0.0, 1.0)}},
                aspect=1.5,
            )
            self._whatif_table = gui.add_markdown("")
        self._whatif_seq = -1

    def _on_connect(self, client: viser.ClientHandle) -> None:
        ok = self._client_origin_ok(client)
        if ok is None:  # the viewer left before its controls were built: not a refusal
            return
        if not ok:
            self._event("dashboard_refused", client=client.client_id, origin="(after connect)")
            self._close(client)
            return
        with self._build_lock:  # viser's shared folder context admits one builder at a time
            try:
                self._build_client_controls(client)
            except Exception:
                _log.exception("building the controls of viewer %s failed", client.client_id)

    def _close(self, client: viser.ClientHandle) -> None:
        """Drop one viewer's websocket (viser reconnects it; the guard refuses it then)."""
        ws = self._server._websock_server
        conn = ws._live_connections.get(client.client_id)
        loop = ws._background_event_loop
        if conn is not None and loop is not None:
            import asyncio

            asyncio.run_coroutine_threadsafe(conn.close(), loop)

    def _build_client_controls(self, client: viser.ClientHandle) -> None:
        cc = _ClientControls(authorised=not self._token_required)
        with self._clients_lock:
            self._clients[client.client_id] = cc
        gui = client.gui
        numbers = self.state.numbers
        mode_now = str(numbers.get("mode", "off")).upper()
        with self._controls_folder:
            if self._token_required:
                token = gui.add_text("Control token", "", hint="controls stay read-only without it")
                unlock = gui.add_button("Unlock controls", icon=viser.Icon.LOCK_OPEN)

                @unlock.on_click
                def _(event: viser.GuiEvent) -> None:
                    if event.client is None:
                        return
                    address = self._client_address(client.client_id)
                    ok, message = self._try_unlock(client.client_id, token.value, address)
                    cc.authorised = ok
                    for h in cc.handles:
                        h.disabled = not ok
                    if cc.estop is not None:
                        cc.estop.disabled = not self._estop_allowed(cc)
                    self._sync_rpm_enabled(cc, str(self.state.numbers.get("mode", "off")))
                    cc.status.content = message

            cc.status = gui.add_markdown("" if cc.authorised else "*read-only viewer*")
            cc.mode = gui.add_dropdown(
                "Mode", MODE_LABELS, initial_value=mode_now if mode_now in MODE_LABELS else "OFF",
                disabled=not cc.authorised,
            )
            lo, hi = self.limits.rpm_range  # the slider shows what the supervisor allows
            cc.rpm = gui.add_slider(
                "rpm (MANUAL)",
                min=lo,
                max=hi,
                step=0.5,
                initial_value=self.limits.clamp(float(numbers.get("rpm_setpoint") or lo)),
                disabled=not cc.authorised or mode_now != "MANUAL",
                hint=f"limits {self.limits.describe()}",
            )
            start = gui.add_button("Start mill", icon=viser.Icon.PLAYER_PLAY, disabled=not cc.authorised)
            stop = gui.add_button("Stop mill", icon=viser.Icon.PLAYER_STOP, disabled=not cc.authorised)
            estop = gui.add_button(  # a stop is always safe: every viewer has it unless configured off
                "EMERGENCY STOP", color="red", icon=viser.Icon.ALERT_OCTAGON, disabled=not self._estop_allowed(cc)
            )
            recal = gui.add_button("Recalibrate twin", icon=viser.Icon.ADJUSTMENTS, disabled=not cc.authorised)
            reseed = gui.add_button("Re-seed twin from camera", icon=viser.Icon.CAMERA, disabled=not cc.authorised)
        with self._whatif_folder:
            rpms = gui.add_text("What-if rpm list", "5, 20, 40, 60", disabled=not cc.authorised, order=-2)
            dur = gui.add_number(
                "What-if duration s", 60.0, min=1.0, max=WHATIF_MAX_S, step=5.0, disabled=not cc.authorised,
                order=-1.6, hint=f"at most {WHATIF_MAX_S:g} s, {WHATIF_MAX_RUNS} rpm values",
            )
            run = gui.add_button("Run what-if", icon=viser.Icon.CHART_LINE, disabled=not cc.authorised, order=-1.5)
            cancel = gui.add_button("Cancel what-if", icon=viser.Icon.X, disabled=not cc.authorised, order=-1)
        cc.handles = [cc.mode, start, stop, recal, reseed, rpms, dur, run, cancel]
        cc.estop = estop

        def guarded(fn):
            def cb(event: viser.GuiEvent) -> None:
                if event.client is None:  # a server-side value sync, not an operator
                    return
                if not cc.authorised:
                    cc.status.content = "*read-only viewer: action refused*"
                    return
                fn(event)

            return cb

        @cc.mode.on_update
        @guarded
        def _(event: viser.GuiEvent) -> None:
            mode = str(cc.mode.value).lower()
            self.controls.set_mode(mode)
            self.state.update_numbers(mode=mode)
            with self._clients_lock:
                clients = list(self._clients.values())
            for other in clients:
                self._sync_rpm_enabled(other, mode)

        @cc.rpm.on_update
        @guarded
        def _(event: viser.GuiEvent) -> None:
            try:
                check = self.limits.check_rpm(cc.rpm.value)
            except ControlError as exc:
                cc.status.content = f"**rpm refused: {exc}**"
                return
            if check.clamped:  # the person who asked is told (the supervisor clamps the same way)
                cc.status.content = f"**{check.message}**"
                self._event("operator_clamped", client=client.client_id, requested=check.requested, rpm=check.rpm)
            self.controls.set_manual_rpm(check.rpm)

        @estop.on_click
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            if not self._estop_allowed(cc):
                cc.status.content = "*read-only viewer: action refused*"
                return
            self.controls.emergency_stop()

        start.on_click(guarded(lambda e: self.controls.start_mill()))
        stop.on_click(guarded(lambda e: self.controls.stop_mill()))
        cancel.on_click(guarded(lambda e: self._cancel_whatif(cc)))
        recal.on_click(guarded(lambda e: self.controls.recalibrate()))
        reseed.on_click(guarded(lambda e: self.controls.reseed_twin()))

        @run.on_click
        @guarded
        def _(event: viser.GuiEvent) -> None:
            try:
                rpm_list = parse_rpm_list(str(rpms.value), self.limits)
                rpm_list, duration = self.limits.check_whatif(rpm_list, dur.value)
            except (ValueError, ControlError) as exc:  # refused, with the limit, to the person who asked
                cc.status.content = f"**what-if refused: {exc}**"
                self._event("operator_rejected", client=client.client_id, action="whatif", error=str(exc))
                return
            cc.status.content = f"what-if queued: {len(rpm_list)} rpm x {duration:g} s"
            self.controls.run_whatif(rpm_list, duration)

    def _estop_allowed(self, cc: _ClientControls) -> bool:
        """EMERGENCY STOP for every viewer (a stop is always safe) unless ``estop_needs_token``."""
        return cc.authorised or not self.estop_needs_token

    def _cancel_whatif(self, cc: _ClientControls) -> None:
        cancel = getattr(self.controls, "cancel_whatif", None)
        if cancel is None:
            cc.status.content = "**cancel: not supported by this loop**"
            return
        cc.status.content = "what-if cancelled" if cancel() else "no what-if to cancel"

    def _sync_rpm_enabled(self, cc: _ClientControls, mode: str) -> None:
        """Show ``mode`` in the viewer's selector; the rpm slider is live only in MANUAL."""
        if cc.mode is not None and mode.upper() in MODE_LABELS:
            cc.mode.value = mode.upper()
        if cc.rpm is not None:
            cc.rpm.disabled = not (cc.authorised and mode.lower() == "manual")

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._clients_lock:
            self._clients.pop(client.client_id, None)
        with self._limiter_lock:
            self._limiter.forget(client.client_id)

    def viewers_with_estop(self) -> int:
        """How many connected viewers have their controls (with EMERGENCY STOP) built."""
        with self._clients_lock:
            return sum(1 for cc in self._clients.values() if cc.estop is not None)

    # -- updates ---------------------------------------------------------------------
    def start(self) -> Dashboard:
        """Start the update thread; returns self."""
        self._thread = threading.Thread(target=self._run, name="dashboard", daemon=True)
        self._thread.start()
        return self

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"http://{host}:{self.port}"

    def _run(self) -> None:
        period = 0.5 / self.update_hz
        seen = {"camera": -1, "twin": -1, "hist": -1, "mode": None}
        next_t = time.monotonic()
        tick = 0
        while not self._stop.is_set():
            try:
                self._push(self.state.snapshot(), seen, plots=(tick % 4 == 0))
            except Exception:  # a viewer closing mid-push must not kill the thread
                if self._stop.is_set():
                    break
            tick += 1
            if tick % 8 == 0:
                self.flush_throttled()
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:
                next_t = time.monotonic()
                delay = 0
            self._stop.wait(delay)

    def _push(self, snap: Snapshot, seen: dict, plots: bool) -> None:
        pushed = False
        if snap.camera_image is not None and snap.camera_seq != seen["camera"]:
            self._camera_img.image = _rgb(snap.camera_image)
            seen["camera"] = snap.camera_seq
            pushed = True
        if snap.twin_image is not None and snap.twin_seq != seen["twin"]:
            self._twin_img.image = _rgb(snap.twin_image)
            if snap.twin_particles is not None and snap.twin_drum_r_m:
                self.scene.update(snap.twin_particles, snap.twin_drum_r_m)
            seen["twin"] = snap.twin_seq
        self._alarm.content = alarms_html(snap.alarms)
        self._numbers.content = numbers_markdown(snap.numbers)
        if plots and snap.history_seq != seen["hist"] and len(snap.history["t_s"]) >= 2:
            h = {k: forward_fill(v) for k, v in snap.history.items()}
            t = h["t_s"]
            self._mi_plot.data = (
                t, h["mi"], h["trend_mi"], h["trend_lo95"], h["trend_hi95"], h["ma_mi"], h["twin_mi"]
            )
            for plot, ys in (
                (self._rpm_plot, (h["rpm_setpoint"], h["rpm_actual"])),
                (self._slope_plot, (h["slope_deg"], h["twin_slope_deg"])),
            ):
                rng = axis_range(*ys, step=5.0, pad=1.0)  # rpm and degrees alike
                if rng is not None and rng != self._y_ranges.get(id(plot)):
                    plot.scales = {"x": {"time": False}, "y": {"auto": False, "range": rng}}
                    self._y_ranges[id(plot)] = rng
                plot.data = (t, *ys)
            seen["hist"] = snap.history_seq
            pushed = True
        mode = str(snap.numbers.get("mode", "off"))
        if mode != seen["mode"]:
            seen["mode"] = mode
            with self._clients_lock:
                clients = list(self._clients.values())
            for cc in clients:
                self._sync_rpm_enabled(cc, mode)
        if snap.whatif.seq != self._whatif_seq:
            self._push_whatif(snap)
        if pushed:
            self.pushes += 1

    def _push_whatif(self, snap: Snapshot) -> None:
        w = snap.whatif
        self._whatif_seq = w.seq
        self._whatif_status.content = f"**status:** {w.status}"
        if not w.rpms:
            return
        # one x axis for all curves: the union of the time grids, each curve interpolated
        t = np.unique(np.concatenate([np.asarray(x, float) for x in w.t_s]))
        ys = tuple(np.interp(t, np.asarray(x, float), np.asarray(y, float)) for x, y in zip(w.t_s, w.mi, strict=True))
        series: tuple[Any, ...] = (
            {"label": "t s"},
            *({"label": f"{r:g} rpm", "stroke": _WHATIF_COLOURS[i % len(_WHATIF_COLOURS)], "width": 2}
              for i, r in enumerate(w.rpms)),
        )
        with self._server.atomic():
            self._whatif_plot.series = series
            # pin x to this study's horizon (uPlot otherwise keeps a wider range from an earlier study)
            self._whatif_plot.scales = {
                "x": {"time": False, "auto": False, "range": (float(t[0]), float(max(t[-1], t[0] + 1.0)))},
                "y": {"auto": False, "range": (0.0, 1.0)},
            }
            self._whatif_plot.data = (t, *ys)
        self._whatif_table.content = whatif_table_md(w)

    def stop(self) -> None:
        """Stop the update thread and the server."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.flush_throttled(force=True)
        self._remove_error_filter()
        self._server.stop()

"""Each viewer's own controls: mode, rpm slider, start/stop, EMERGENCY STOP, twin and
what-if buttons, built per viser client (one at a time: viser's shared folder context admits
one builder), so every viewer gets them however many connect at once. Every callback
re-checks that its viewer is authorised (``twin.dashboard.guard.Gatekeeper``); the rpm
slider spans the run's limits (``control.limits``); a clamped rpm or a refused what-if is
told to the viewer who asked."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import viser

from control.errors import ControlError
from control.limits import WHATIF_MAX_RUNS, WHATIF_MAX_S, Limits
from twin.dashboard.guard import Gatekeeper, client_address
from twin.dashboard.layout import MODE_LABELS, Layout, parse_rpm_list
from twin.records import ModeSet, OperatorClamped, OperatorRejected
from twin.state import Controls, LiveState


class Disableable(Protocol):
    """A viser control that can be disabled (every control handle)."""

    disabled: bool


@dataclass
class ClientControls:
    """One viewer's control handles (None until its controls are built)."""

    authorised: bool
    handles: list[Disableable] = field(default_factory=list)
    mode: viser.GuiDropdownHandle[str] | None = None
    rpm: viser.GuiSliderHandle[float] | None = None
    status: viser.GuiMarkdownHandle | None = None
    estop: viser.GuiButtonHandle | None = None

    def say(self, text: str) -> None:
        """Tell this viewer ``text`` (Markdown) in its status line."""
        if self.status is not None:
            self.status.content = text


class Viewers:
    """The connected viewers' controls (see module doc), keyed by viser client id."""

    def __init__(
        self, server: viser.ViserServer, layout: Layout, gate: Gatekeeper, controls: Controls, state: LiveState,
        limits: Limits,
    ) -> None:
        self._server = server
        self.layout = layout
        self.gate = gate
        self.controls = controls
        self.state = state
        self.limits = limits
        self._clients: dict[int, ClientControls] = {}
        self._lock = threading.Lock()

    def build(self, client: viser.ClientHandle) -> None:
        """Build one viewer's controls (the caller holds the build lock)."""
        cc = ClientControls(authorised=not self.gate.token_required)
        with self._lock:
            self._clients[client.client_id] = cc
        gui = client.gui
        mode_now = (self.state.panel.mode or "off").upper()
        with self.layout.controls_folder:
            if self.gate.token_required:
                token = gui.add_text("Control token", "", hint="controls stay read-only without it")
                unlock = gui.add_button("Unlock controls", icon=viser.Icon.LOCK_OPEN)

                @unlock.on_click
                def _(event: viser.GuiEvent) -> None:
                    if event.client is None:
                        return
                    address = client_address(self._server, client.client_id)
                    ok, message = self.gate.try_unlock(client.client_id, token.value, address)
                    cc.authorised = ok
                    for h in cc.handles:
                        h.disabled = not ok
                    if cc.estop is not None:
                        cc.estop.disabled = not self.gate.estop_allowed(cc.authorised)
                    self._sync_rpm_enabled(cc, self.state.panel.mode or "off")
                    cc.say(message)

            cc.status = gui.add_markdown("" if cc.authorised else "*read-only viewer*")
            mode_select = cc.mode = gui.add_dropdown(
                "Mode", MODE_LABELS, initial_value=mode_now if mode_now in MODE_LABELS else "OFF",
                disabled=not cc.authorised,
            )
            lo, hi = self.limits.rpm_range  # the slider shows what the supervisor allows
            rpm_slider = cc.rpm = gui.add_slider(
                "rpm (MANUAL)",
                min=lo,
                max=hi,
                step=0.5,
                initial_value=self.limits.clamp(float(self.state.panel.rpm_setpoint or lo)),
                disabled=not cc.authorised or mode_now != "MANUAL",
                hint=f"limits {self.limits.describe()}",
            )
            start = gui.add_button("Start mill", icon=viser.Icon.PLAYER_PLAY, disabled=not cc.authorised)
            stop = gui.add_button("Stop mill", icon=viser.Icon.PLAYER_STOP, disabled=not cc.authorised)
            estop = gui.add_button(  # a stop is always safe: every viewer has it unless configured off
                "EMERGENCY STOP", color="red", icon=viser.Icon.ALERT_OCTAGON,
                disabled=not self.gate.estop_allowed(cc.authorised),
            )
            recal = gui.add_button("Recalibrate twin", icon=viser.Icon.ADJUSTMENTS, disabled=not cc.authorised)
            reseed = gui.add_button("Re-seed twin from camera", icon=viser.Icon.CAMERA, disabled=not cc.authorised)
            relearn = gui.add_button(  # issue 22: after lighting_changed:, the classes from the live bed
                "Re-learn classes", icon=viser.Icon.REFRESH, disabled=not cc.authorised,
                hint="learn the colour classes again from the live bed (when the light moved too far)",
            )
        with self.layout.whatif_folder:
            rpms = gui.add_text("What-if rpm list", "5, 20, 40, 60", disabled=not cc.authorised, order=-2)
            dur = gui.add_number(
                "What-if duration s", 60.0, min=1.0, max=WHATIF_MAX_S, step=5.0, disabled=not cc.authorised,
                order=-1.6, hint=f"at most {WHATIF_MAX_S:g} s, {WHATIF_MAX_RUNS} rpm values",
            )
            run = gui.add_button("Run what-if", icon=viser.Icon.CHART_LINE, disabled=not cc.authorised, order=-1.5)
            cancel = gui.add_button("Cancel what-if", icon=viser.Icon.X, disabled=not cc.authorised, order=-1)
        cc.handles = [mode_select, start, stop, recal, reseed, relearn, rpms, dur, run, cancel]
        cc.estop = estop

        def guarded(fn: Callable[[viser.GuiEvent], None]) -> Callable[[viser.GuiEvent], None]:
            def cb(event: viser.GuiEvent) -> None:
                if event.client is None:  # a server-side value sync, not an operator
                    return
                if not cc.authorised:
                    cc.say("*read-only viewer: action refused*")
                    return
                fn(event)

            return cb

        @mode_select.on_update
        @guarded
        def _(event: viser.GuiEvent) -> None:
            mode = str(mode_select.value).lower()
            self.controls.set_mode(mode)
            self.state.record(ModeSet(t_s=self.gate.now_s(), mode=mode))
            self.sync_mode(mode)

        @rpm_slider.on_update
        @guarded
        def _(event: viser.GuiEvent) -> None:
            try:
                check = self.limits.check_rpm(rpm_slider.value)
            except ControlError as exc:
                cc.say(f"**rpm refused: {exc}**")
                return
            if check.clamped:  # the person who asked is told (the supervisor clamps the same way)
                cc.say(f"**{check.message}**")
                self.gate.publish(OperatorClamped(t_s=self.gate.now_s(), client=client.client_id,
                                                requested=check.requested, rpm=check.rpm))
            self.controls.set_manual_rpm(check.rpm)

        @estop.on_click
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            if not self.gate.estop_allowed(cc.authorised):
                cc.say("*read-only viewer: action refused*")
                return
            self.controls.emergency_stop()

        start.on_click(guarded(lambda e: self.controls.start_mill()))
        stop.on_click(guarded(lambda e: self.controls.stop_mill()))
        cancel.on_click(guarded(lambda e: self._cancel_whatif(cc)))
        recal.on_click(guarded(lambda e: self.controls.recalibrate()))
        reseed.on_click(guarded(lambda e: self.controls.reseed_twin()))
        relearn.on_click(guarded(lambda e: self._relearn(cc)))

        @run.on_click
        @guarded
        def _(event: viser.GuiEvent) -> None:
            try:
                rpm_list = parse_rpm_list(str(rpms.value), self.limits)
                rpm_list, duration = self.limits.check_whatif(rpm_list, dur.value)
            except (ValueError, ControlError) as exc:  # refused, with the limit, to the person who asked
                cc.say(f"**what-if refused: {exc}**")
                self.gate.publish(OperatorRejected(t_s=self.gate.now_s(), client=client.client_id, action="whatif",
                                                 error=str(exc)))
                return
            cc.say(f"what-if queued: {len(rpm_list)} rpm x {duration:g} s")
            self.controls.run_whatif(rpm_list, duration)

    def _cancel_whatif(self, cc: ClientControls) -> None:
        cancel = getattr(self.controls, "cancel_whatif", None)
        if cancel is None:
            cc.say("**cancel: not supported by this loop**")
            return
        cc.say("what-if cancelled" if cancel() else "no what-if to cancel")

    def _relearn(self, cc: ClientControls) -> None:
        """The loop's typed relearn command (``relearn_classes``: a ``SwapClasses`` for the camera
        worker, logged as an operator action); what it answered goes to the viewer who asked."""
        relearn = getattr(self.controls, "relearn_classes", None)
        if relearn is None:
            cc.say("**re-learn: not supported by this loop**")
            return
        answer = relearn()
        cc.say(answer if isinstance(answer, str) else "re-learning the classes from the live bed ...")

    def _sync_rpm_enabled(self, cc: ClientControls, mode: str) -> None:
        """Show ``mode`` in the viewer's selector; the rpm slider is live only in MANUAL."""
        if cc.mode is not None and mode.upper() in MODE_LABELS:
            cc.mode.value = mode.upper()  # type: ignore[misc]  # viser 1.1 declares the setter on its generic base
        if cc.rpm is not None:
            cc.rpm.disabled = not (cc.authorised and mode.lower() == "manual")

    def sync_mode(self, mode: str) -> None:
        """Show ``mode`` in every viewer's selector (the rpm slider is live only in MANUAL)."""
        with self._lock:
            clients = list(self._clients.values())
        for cc in clients:
            self._sync_rpm_enabled(cc, mode)

    def forget(self, client_id: int) -> None:
        with self._lock:
            self._clients.pop(client_id, None)

    def with_estop(self) -> int:
        """How many connected viewers have their controls (with EMERGENCY STOP) built."""
        with self._lock:
            return sum(1 for cc in self._clients.values() if cc.estop is not None)

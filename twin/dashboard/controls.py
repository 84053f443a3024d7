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
from twin.dashboard.setup import SetupView
from twin.records import ModeSet, OperatorClamped, OperatorRejected
from twin.state import Controls, LiveState


class Disableable(Protocol):
    """A viser control that can be disabled (every control handle)."""

    disabled: bool


@dataclass
class ClientControls:
    """One viewer's control handles (None until its controls are built)."""

    authorised: bool
    handles: list[Disableable] = field(default_factory=list)  # disabled for a read-only viewer
    mode: viser.GuiDropdownHandle[str] | None = None
    rpm: viser.GuiSliderHandle[float] | None = None
    status: viser.GuiMarkdownHandle | None = None
    estop: viser.GuiButtonHandle | None = None

    def say(self, text: str) -> None:
        """Tell this viewer ``text`` (Markdown) in its status line."""
        if self.status is not None:
            self.status.content = text


@dataclass
class _Handles:
    """One viewer's control handles while they are built and wired."""

    mode: viser.GuiDropdownHandle[str]
    rpm: viser.GuiSliderHandle[float]
    start: viser.GuiButtonHandle
    stop: viser.GuiButtonHandle
    estop: viser.GuiButtonHandle
    recal: viser.GuiButtonHandle
    reseed: viser.GuiButtonHandle
    relearn: viser.GuiButtonHandle


@dataclass
class _WhatIfForm:
    """One viewer's what-if form."""

    rpms: viser.GuiTextHandle
    dur: viser.GuiNumberHandle[float]
    run: viser.GuiButtonHandle
    cancel: viser.GuiButtonHandle


class Viewers:
    """The connected viewers' controls (see module doc), keyed by viser client id."""

    def __init__(
        self, server: viser.ViserServer, layout: Layout, gate: Gatekeeper, controls: Controls, state: LiveState,
        limits: Limits, setup: SetupView | None = None,
    ) -> None:
        self._server = server
        self.setup = setup
        self.layout = layout
        self.gate = gate
        self.controls = controls
        self.state = state
        self.limits = limits
        self._clients: dict[int, ClientControls] = {}
        self._lock = threading.Lock()

    def build(self, client: viser.ClientHandle) -> None:
        """Build one viewer's controls (the caller holds the build lock). The viewer gets them in one
        message batch once every callback is wired: a button shown before its ``on_click`` was attached
        dropped an early click ("Start mill" pressed as the page opened on a loaded machine: nothing)."""
        with client.atomic():
            self._build(client)

    def _build(self, client: viser.ClientHandle) -> None:
        cc = ClientControls(authorised=not self.gate.token_required)
        with self._lock:
            self._clients[client.client_id] = cc
        with self.layout.controls_folder:
            if self.gate.token_required:
                self._add_unlock(client, cc)
            h = self._add_controls(client.gui, cc)
        with self.layout.whatif_folder:
            w = self._add_whatif(client.gui, cc)
        cc.handles = [h.mode, h.start, h.stop, h.recal, h.reseed, h.relearn, w.rpms, w.dur, w.run, w.cancel]
        if self.setup is not None:
            with self.layout.setup_folder:
                cc.handles += list(self.setup.build(client.gui, cc.authorised, self._guarded(cc), cc.say, client))
        cc.estop = h.estop
        self._wire(client, cc, h, w)

    def _add_unlock(self, client: viser.ClientHandle, cc: ClientControls) -> None:
        """The token field and its button: a right token enables this viewer's controls."""
        token = client.gui.add_text("Control token", "", hint="controls stay read-only without it")
        unlock = client.gui.add_button("Unlock controls", icon=viser.Icon.LOCK_OPEN)

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

    def _add_controls(self, gui: viser.GuiApi, cc: ClientControls) -> _Handles:
        """The mode, rpm, mill and twin controls (disabled for a read-only viewer)."""
        locked = not cc.authorised
        mode_now = (self.state.panel.mode or "off").upper()
        cc.status = gui.add_markdown("" if cc.authorised else "*read-only viewer*")
        cc.mode = gui.add_dropdown("Mode", MODE_LABELS, initial_value=mode_now if mode_now in MODE_LABELS else "OFF",
                                   disabled=locked)
        lo, hi = self.limits.rpm_range  # the slider shows what the supervisor allows
        cc.rpm = gui.add_slider(
            "rpm (MANUAL)", min=lo, max=hi, step=0.5,
            initial_value=self.limits.clamp(float(self.state.panel.rpm_setpoint or lo)),
            disabled=locked or mode_now != "MANUAL", hint=f"limits {self.limits.describe()}",
        )
        return _Handles(
            mode=cc.mode, rpm=cc.rpm,
            start=gui.add_button("Start mill", icon=viser.Icon.PLAYER_PLAY, disabled=locked),
            stop=gui.add_button("Stop mill", icon=viser.Icon.PLAYER_STOP, disabled=locked),
            estop=gui.add_button(  # a stop is always safe: every viewer has it unless configured off
                "EMERGENCY STOP", color="red", icon=viser.Icon.ALERT_OCTAGON,
                disabled=not self.gate.estop_allowed(cc.authorised),
            ),
            recal=gui.add_button("Recalibrate twin", icon=viser.Icon.ADJUSTMENTS, disabled=locked),
            reseed=gui.add_button("Re-seed twin from camera", icon=viser.Icon.CAMERA, disabled=locked),
            relearn=gui.add_button(  # issue 22: after lighting_changed:, the classes from the live bed
                "Re-learn classes", icon=viser.Icon.REFRESH, disabled=locked,
                hint="learn the colour classes again from the live bed (when the light moved too far)",
            ),
        )

    def _add_whatif(self, gui: viser.GuiApi, cc: ClientControls) -> _WhatIfForm:
        """The what-if form: rpm list, duration, run, cancel."""
        locked = not cc.authorised
        return _WhatIfForm(
            rpms=gui.add_text("What-if rpm list", "5, 20, 40, 60", disabled=locked, order=-2),
            dur=gui.add_number(
                "What-if duration s", 60.0, min=1.0, max=WHATIF_MAX_S, step=5.0, disabled=locked,
                order=-1.6, hint=f"at most {WHATIF_MAX_S:g} s, {WHATIF_MAX_RUNS} rpm values",
            ),
            run=gui.add_button("Run what-if", icon=viser.Icon.CHART_LINE, disabled=locked, order=-1.5),
            cancel=gui.add_button("Cancel what-if", icon=viser.Icon.X, disabled=locked, order=-1),
        )

    @staticmethod
    def _guarded(cc: ClientControls) -> Callable[[Callable[[viser.GuiEvent], None]], Callable[[viser.GuiEvent], None]]:
        """A callback of ``cc``'s viewer wrapped so that its authorisation is re-checked on every event."""

        def guarded(fn: Callable[[viser.GuiEvent], None]) -> Callable[[viser.GuiEvent], None]:
            def cb(event: viser.GuiEvent) -> None:
                if event.client is None:  # a server-side value sync, not an operator
                    return
                if not cc.authorised:
                    cc.say("*read-only viewer: action refused*")
                    return
                fn(event)

            return cb

        return guarded

    def _wire(self, client: viser.ClientHandle, cc: ClientControls, h: _Handles, w: _WhatIfForm) -> None:
        """Each control's callback: authorisation re-checked, then the loop's ``Controls``."""
        guarded = self._guarded(cc)

        @h.mode.on_update
        @guarded
        def _(event: viser.GuiEvent) -> None:
            mode = str(h.mode.value).lower()
            self.controls.set_mode(mode)
            self.state.record(ModeSet(t_s=self.gate.now_s(), mode=mode))
            self.sync_mode(mode)

        @h.estop.on_click
        def _(event: viser.GuiEvent) -> None:
            if event.client is None:
                return
            if not self.gate.estop_allowed(cc.authorised):
                cc.say("*read-only viewer: action refused*")
                return
            self.controls.emergency_stop()

        h.rpm.on_update(guarded(lambda e: self._manual_rpm(client, cc, h.rpm.value)))
        h.start.on_click(guarded(lambda e: self.controls.start_mill()))
        h.stop.on_click(guarded(lambda e: self.controls.stop_mill()))
        h.recal.on_click(guarded(lambda e: self.controls.recalibrate()))
        h.reseed.on_click(guarded(lambda e: self.controls.reseed_twin()))
        h.relearn.on_click(guarded(lambda e: cc.say(self.controls.relearn_classes())))
        w.run.on_click(guarded(lambda e: self._run_whatif(client, cc, str(w.rpms.value), w.dur.value)))
        w.cancel.on_click(guarded(lambda e: cc.say("what-if cancelled" if self.controls.cancel_whatif()
                                                   else "no what-if to cancel")))

    def _manual_rpm(self, client: viser.ClientHandle, cc: ClientControls, value: float) -> None:
        """The slider's rpm, clamped into the limits (the viewer who asked is told; the
        supervisor clamps the same way)."""
        try:
            check = self.limits.check_rpm(value)
        except ControlError as exc:
            cc.say(f"**rpm refused: {exc}**")
            return
        if check.clamped:
            cc.say(f"**{check.message}**")
            self.gate.publish(OperatorClamped(t_s=self.gate.now_s(), client=client.client_id,
                                              requested=check.requested, rpm=check.rpm))
        self.controls.set_manual_rpm(check.rpm)

    def _run_whatif(self, client: viser.ClientHandle, cc: ClientControls, rpms: str, duration_s: float) -> None:
        """A what-if study from the form, or its refusal (with the limit) to the viewer who asked."""
        try:
            rpm_list = parse_rpm_list(rpms, self.limits)
            rpm_list, duration = self.limits.check_whatif(rpm_list, duration_s)
        except (ValueError, ControlError) as exc:
            cc.say(f"**what-if refused: {exc}**")
            self.gate.publish(OperatorRejected(t_s=self.gate.now_s(), client=client.client_id, action="whatif",
                                               error=str(exc)))
            return
        cc.say(f"what-if queued: {len(rpm_list)} rpm x {duration:g} s")
        self.controls.run_whatif(rpm_list, duration)

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

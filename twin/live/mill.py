"""The mill worker: the one thread that talks to the mill, and the safety rules of the link.

Shape (after pyserial's ``serial.threaded``): the protocol and transport live in
``control.driver.MillClient`` (built with ``heartbeat_s=None``: no thread of its own);
this worker owns the only thread that uses it. Each :meth:`MillWorker.cycle` sends what
is pending, then polls the board and publishes one :class:`MillSnapshot`.

Rules (each has a test in ``tests/twin/test_mill_worker.py``):

- **Nothing moves unless asked.** The worker sends only commands it was given in this
  run; it never starts the motor by itself: connecting, reconnecting or finding a
  watchdog trip changes nothing on the board. Nor does it keep a motor running that this
  run never commanded: until its first command goes through it polls with ``status()``
  (STA, which does not feed the board's watchdog), so a mill left running by a host that
  is gone stops on its own watchdog; from then on with ``heartbeat()`` (HB: this run
  controls the motor and keeps its watchdog fed).
- **Read before writing.** After the link comes back the first exchange is a read; the
  snapshot's ``epoch`` grows, and only then are commands sent.
- **No stale commands.** Commands queued before the newest read (an older ``epoch``)
  are dropped with an event, never re-sent; of several pending set-rpm commands only
  the newest is sent; a command that failed on a lost link is dropped, not re-queued
  (a stop is the exception: stopping is always safe, so a failed stop is retried).
- **A refusal is not a lost link.** ``MillRefused`` (NAK) is an event; the command is
  dropped and the board is re-read (new epoch) so the supervisor resyncs to it. A
  set-rpm the board acknowledges but does not report as its setpoint at the next read is
  a ``mill_mismatch`` event and a re-read too. Both count in ``MillSnapshot.refused``
  (the supervisor's safe state).
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable
from typing import Protocol

from control.errors import ControlError, MillRefused
from control.protocol import MillStatus
from twin.live.commands import MillCommand, SetRpm, StartMill, StopMill, drain
from twin.live.events import EventSink
from twin.live.faults import NO_FAULTS, FaultHooks, at
from twin.live.snapshots import Latest, MillSnapshot
from twin.records import (
    FaultCleared,
    FaultRaised,
    MillChangedElsewhere,
    MillCommandDropped,
    MillCommandSent,
    MillState,
    MillSynced,
)
from twin.records import MillMismatch as MillMismatchRecord
from twin.records import (
    MillRefused as MillRefusedRecord,
)

MILL_POLL_S = 0.1  # wall seconds between polls


class MillLink(Protocol):
    """What the worker needs of ``control.driver.MillClient``."""

    url: str

    def set_rpm(self, rpm: float) -> None: ...
    def start(self) -> None: ...
    def stop(self) -> None: ...
    def status(self) -> MillStatus: ...
    def heartbeat(self) -> MillStatus: ...
    def close(self) -> None: ...


def _command(cmd: MillCommand) -> tuple[str, float | None]:
    """The command's name in the records and its setpoint (rpm; None but for a set-rpm)."""
    if isinstance(cmd, SetRpm):
        return "set_rpm", cmd.rpm
    return ("start" if isinstance(cmd, StartMill) else "stop"), None


class MillWorker:
    """The one poller of the mill (see module doc). ``submit`` from any thread; ``run``
    (or, in tests, ``cycle``) on the worker's own thread only."""

    def __init__(
        self,
        link: MillLink,
        sink: EventSink,
        box: Latest[MillSnapshot],
        now_s: Callable[[], float],
        poll_s: float = MILL_POLL_S,
        faults: FaultHooks = NO_FAULTS,
    ) -> None:
        self.link = link
        self.faults = faults
        self.sink = sink
        self.box = box
        self.now_s = now_s
        self.poll_s = float(poll_s)
        self._inbox: queue.SimpleQueue[MillCommand] = queue.SimpleQueue()
        self._wake = threading.Event()
        # pending, owned by the worker thread
        self._rpm: SetRpm | None = None
        self._run: StartMill | StopMill | None = None
        self._refused = 0  # refusals and set-rpms not taken, so far
        self._expect_rpm: float | None = None  # the setpoint an ACKed set-rpm must show
        self._sent_run = False  # a start/stop went out since the last poll (running may change)
        self._controlling = False  # a command of this run went through: feed the watchdog

    # -- any thread ------------------------------------------------------------------------
    @property
    def controlling(self) -> bool:
        """A command of this run went through to the mill (this run has moved or stopped it)."""
        return self._controlling

    def submit(self, cmd: MillCommand) -> None:
        """Queue a command (never blocks)."""
        self._inbox.put(cmd)
        self._wake.set()

    # -- the worker thread -----------------------------------------------------------------
    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self.cycle()
            self._wake.wait(self.poll_s)
            self._wake.clear()

    def cycle(self) -> MillSnapshot:
        """Take new commands, send what is due, poll; returns the published snapshot."""
        at(self.faults.mill_cycle, self.now_s())
        snap = self.box.get()
        self._take_commands()
        if snap.connected:
            due = self._due(snap.epoch)
            for i, cmd in enumerate(due):
                try:
                    self._send(cmd)
                except MillRefused as exc:
                    self._refused += 1
                    name, rpm = _command(cmd)
                    self.sink.publish(MillRefusedRecord(t_s=self.now_s(), command=name, source=cmd.source, rpm=rpm,
                                                        reason=exc.reason))
                    for rest in due[i + 1 :]:
                        self._drop(rest, "an earlier command was refused: the board is read again first")
                    return self._poll(snap, new_epoch=True)
                except (OSError, ControlError) as exc:  # TimeoutError, ConnectionError, serial errors
                    for failed in due[i:]:
                        if isinstance(failed, StopMill) and self._run is None:
                            self._run = failed  # a stop is always safe: try again once the link is back
                        else:
                            self._drop(failed, f"link lost: {exc}")
                    return self._lost(snap, exc)
                name, rpm = _command(cmd)
                self.sink.publish(MillCommandSent(t_s=self.now_s(), command=name, source=cmd.source, rpm=rpm))
                self._controlling = True
        return self._poll(snap, new_epoch=not snap.connected)

    def _take_commands(self) -> None:
        for cmd in drain(self._inbox):
            if isinstance(cmd, SetRpm):
                if self._rpm is not None:
                    self._drop(self._rpm, "superseded by a newer set-rpm")
                self._rpm = cmd
            else:
                if isinstance(cmd, StopMill) and cmd.urgent and self._rpm is not None:
                    self._drop(self._rpm, "emergency stop")
                    self._rpm = None
                if self._run is not None:
                    self._drop(self._run, "superseded by a newer start/stop")
                self._run = cmd

    def _due(self, epoch: int) -> list[MillCommand]:
        """The pending commands to send now, stop/start first; stale ones dropped."""
        out: list[MillCommand] = []
        for cmd in (self._run, self._rpm):
            if cmd is None:
                continue
            if isinstance(cmd, (SetRpm, StartMill)) and cmd.epoch != epoch:
                self._drop(cmd, f"decided on mill state {cmd.epoch}, the board was read again since ({epoch})")
            else:
                out.append(cmd)
        self._run = self._rpm = None
        return out

    def _send(self, cmd: MillCommand) -> None:
        if isinstance(cmd, SetRpm):
            self.link.set_rpm(cmd.rpm)
            self._expect_rpm = cmd.rpm
        elif isinstance(cmd, StartMill):
            self.link.start()
            self._sent_run = True
        else:
            self.link.stop()
            self._sent_run = True

    def _drop(self, cmd: MillCommand, why: str) -> None:
        name, rpm = _command(cmd)
        self.sink.publish(MillCommandDropped(t_s=self.now_s(), command=name, source=cmd.source, rpm=rpm, reason=why))

    def _poll(self, snap: MillSnapshot, new_epoch: bool) -> MillSnapshot:
        try:
            st = self.link.heartbeat() if self._controlling else self.link.status()
        except (OSError, ControlError) as exc:
            return self._lost(snap, exc)
        t = self.now_s()
        expect, self._expect_rpm = self._expect_rpm, None
        sent_run, self._sent_run = self._sent_run, False
        if expect is not None and abs(st.setpoint_rpm - round(expect, 2)) > 0.011:
            self._refused += 1
            new_epoch = True
            self.sink.publish(MillMismatchRecord(t_s=t, rpm=expect, setpoint_rpm=st.setpoint_rpm,
                                                 actual_rpm=st.actual_rpm, running=st.running, fault=st.fault))
        elif expect is None and snap.connected and snap.status is not None and (
            abs(st.setpoint_rpm - snap.status.setpoint_rpm) > 0.011
            or (not sent_run and st.running != snap.status.running)
        ):  # the board changed without us (another host, its front panel): read it again, as after a loss
            new_epoch = True
            self.sink.publish(MillChangedElsewhere(t_s=t, was=snap.status.as_dict(), setpoint_rpm=st.setpoint_rpm,
                                                   actual_rpm=st.actual_rpm, running=st.running, fault=st.fault))
        epoch = snap.epoch + 1 if new_epoch else snap.epoch
        new = MillSnapshot(status=st, connected=True, epoch=epoch, polled=True, refused=self._refused)
        self.box.set(new)
        if not snap.connected:
            self.sink.publish(FaultCleared(t_s=t, fault="mill_link", message="mill link restored", url=self.link.url))
            self.sink.publish(MillSynced(t_s=t, epoch=epoch, setpoint_rpm=st.setpoint_rpm, actual_rpm=st.actual_rpm,
                                         running=st.running, fault=st.fault))
        if st.fault:
            if snap.fault and snap.fault != st.fault:  # another fault: an event of its own
                self.sink.publish(FaultCleared(t_s=t, fault="mill_fault",
                                               message=f"mill fault {snap.fault} replaced by {st.fault}"))
            self.sink.publish(FaultRaised(t_s=t, fault="mill_fault", message=f"mill reports fault {st.fault}",
                                          mill_fault=st.fault))
        else:
            self.sink.publish(FaultCleared(t_s=t, fault="mill_fault", message="mill fault cleared"))
        self._publish(new)
        return new

    def _lost(self, snap: MillSnapshot, exc: BaseException) -> MillSnapshot:
        new = MillSnapshot(status=snap.status, connected=False, epoch=snap.epoch, polled=True, refused=self._refused)
        self._expect_rpm = None  # the board is read again when the link is back
        if self._rpm is not None:  # decided on a board we can no longer see
            self._drop(self._rpm, f"link lost: {exc}")
            self._rpm = None
        if isinstance(self._run, StartMill):
            self._drop(self._run, f"link lost: {exc}")
            self._run = None
        # the fault (logged, shown as an alarm) before the snapshot says "disconnected": whoever
        # sees the link down (the supervisor, the dashboard) also sees why
        self.sink.publish(FaultRaised(t_s=self.now_s(), fault="mill_link", message=f"mill link lost: {exc}",
                                      url=self.link.url))
        self.box.set(new)
        self._publish(new)
        return new

    def _publish(self, snap: MillSnapshot) -> None:
        sp, act = snap.setpoint_rpm, snap.actual_rpm
        self.sink.publish(MillState(
            t_s=self.now_s(), state=snap.state, connected=snap.connected,
            setpoint_rpm=sp if math.isfinite(sp) else None,
            actual_rpm=act if math.isfinite(act) else None,
        ))

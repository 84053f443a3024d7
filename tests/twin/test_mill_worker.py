"""The mill worker's safety rules, on a fake link (milliseconds, no threads)."""

from __future__ import annotations

import pytest

from control.errors import MillRefused
from control.protocol import MillStatus
from tests.waiting import wait_until
from twin.live.commands import SetRpm, StartMill, StopMill
from twin.live.mill import MillWorker
from twin.live.snapshots import Latest, MillSnapshot
from twin.records import FaultCleared, FaultRaised, FrameReading, Record, UntypedEvent, event_fields, kind_of
from twin.state import LiveState


class FakeLink:
    """A board behind a link that can be unplugged and can refuse commands."""

    url = "fake://mill"

    def __init__(self, status: MillStatus) -> None:
        self.board = status
        self.up = True
        self.refuse: dict[str, str] = {}  # command -> NAK reason
        self.sent: list[tuple[str, float | None]] = []
        self.polls = 0  # heartbeats (feed the board's watchdog)
        self.reads = 0  # status reads (do not)

    def _check(self, cmd: str) -> None:
        if not self.up:
            raise TimeoutError("no answer")
        if cmd in self.refuse:
            raise MillRefused(cmd, self.refuse[cmd])

    def set_rpm(self, rpm: float) -> None:
        self._check("set_rpm")
        self.sent.append(("set_rpm", rpm))
        self.board = MillStatus(rpm, self.board.actual_rpm, self.board.running, self.board.fault)

    def start(self) -> None:
        self._check("start")
        self.sent.append(("start", None))
        self.board = MillStatus(self.board.setpoint_rpm, self.board.actual_rpm, True, None)

    def stop(self) -> None:
        self._check("stop")
        self.sent.append(("stop", None))
        self.board = MillStatus(self.board.setpoint_rpm, self.board.actual_rpm, False, self.board.fault)

    def heartbeat(self) -> MillStatus:
        self._check("heartbeat")
        self.polls += 1
        return self.board

    def status(self) -> MillStatus:
        self._check("status")
        self.reads += 1
        return self.board

    def close(self) -> None:
        pass


class Sink:
    """A test's event sink: every record published (``records``), the logged ones as
    (kind, fields) (``events``); faults as (kind, {fault, message}), a clear only of an active
    fault (``faults``). ``state``: a ``LiveState`` subscribed to the records, as in a run."""

    def __init__(self, state: LiveState | None = None) -> None:
        self.events: list[tuple[str, dict]] = []
        self.records: list[Record] = []
        self.faults: set[str] = set()
        self.state = state

    def publish(self, rec: Record) -> None:
        assert not isinstance(rec, UntypedEvent), f"unregistered record: {rec}"
        if isinstance(rec, FaultRaised):
            self.faults.add(rec.fault)
            self.events.append(("fault", {"fault": rec.fault, "message": rec.message}))
            return
        if isinstance(rec, FaultCleared):
            if rec.fault in self.faults:
                self.faults.discard(rec.fault)
                self.events.append(("recovered", {"fault": rec.fault}))
            return
        self.records.append(rec)
        if self.state is not None:
            self.state.record(rec)
        if rec.logged and not isinstance(rec, FrameReading):
            self.events.append((kind_of(rec), event_fields(rec)))

    def metadata(self, **data) -> None:
        pass

    def rows(self) -> list[dict]:
        """The frame readings published, as CSV rows."""
        return [r.as_dict() for r in self.records if isinstance(r, FrameReading)]

    def kinds(self, kind: str) -> list[dict]:
        return [d for k, d in self.events if k == kind]


def make(status: MillStatus) -> tuple[MillWorker, FakeLink, Sink, Latest[MillSnapshot]]:
    link, sink, box = FakeLink(status), Sink(), Latest(MillSnapshot())
    return MillWorker(link, sink, box, now_s=lambda: 0.0), link, sink, box


STOPPED_WDOG = MillStatus(13.0, 0.0, False, "WDOG")
RUNNING = MillStatus(5.0, 5.0, True, None)


def test_connecting_reads_and_never_restarts_a_stopped_mill() -> None:
    """Defect 1: the first connection started a stopped mill (and cleared a watchdog trip)."""
    w, link, sink, box = make(STOPPED_WDOG)
    for _ in range(20):
        w.cycle()
    assert link.sent == [] and link.reads == 20 and link.polls == 0  # only reads, no command
    snap = box.get()
    assert snap.connected and snap.epoch == 1 and snap.status == STOPPED_WDOG
    assert snap.state == "fault WDOG" and "mill_fault" in sink.faults
    assert not link.board.running and link.board.fault == "WDOG"


def test_a_lost_link_is_an_alarm_before_anyone_can_see_the_link_down() -> None:
    """The fault is published while the box still says "connected": the supervisor and the
    dashboard, which read the box, never see the link down without its alarm (a CI run read
    the safe state and found no "mill link" alarm yet)."""
    w, link, sink, box = make(RUNNING)
    w.cycle()
    seen: list[bool] = []
    publish = sink.publish

    def publish_and_look(rec: Record) -> None:
        if isinstance(rec, FaultRaised) and rec.fault == "mill_link":
            seen.append(box.get().connected)
        publish(rec)

    sink.publish = publish_and_look  # type: ignore[method-assign]
    link.up = False
    w.cycle()
    assert seen == [True] and not box.get().connected


def test_a_watchdog_trip_after_a_link_loss_stays_stopped_until_commanded() -> None:
    w, link, sink, box = make(RUNNING)
    w.cycle()
    link.up = False
    w.cycle()
    assert not box.get().connected and "mill_link" in sink.faults
    link.board = STOPPED_WDOG  # the board's watchdog stopped the drive meanwhile
    link.up = True
    for _ in range(5):
        w.cycle()
    assert box.get().connected and box.get().epoch == 2 and "mill_link" not in sink.faults
    assert link.sent == [] and not link.board.running
    assert sink.kinds("mill_synced")[-1]["running"] is False
    w.submit(StartMill(epoch=2))  # the operator starts it: now it runs
    w.cycle()
    assert link.sent == [("start", None)] and link.board.running


def test_commands_decided_before_a_reread_are_dropped_not_resent() -> None:
    """Defect 5: the oldest failed set-rpm was re-sent after the link came back."""
    w, link, sink, box = make(RUNNING)
    w.cycle()
    w.submit(SetRpm(9.0, epoch=1))
    w.cycle()
    assert link.sent == [("set_rpm", 9.0)]
    link.up = False
    w.submit(SetRpm(13.0, epoch=1))  # fails on the dead link
    w.cycle()
    w.submit(SetRpm(17.0, epoch=1))  # queued while the link is down
    w.submit(StartMill(epoch=1))
    w.cycle()
    link.up = True
    w.cycle()  # read first: epoch 2
    w.cycle()
    assert link.sent == [("set_rpm", 9.0)]  # nothing decided on the old board state went out
    dropped = [d["command"] for d in sink.kinds("mill_command_dropped")]
    assert dropped.count("set_rpm") == 2 and "start" in dropped
    w.submit(SetRpm(11.0, epoch=box.get().epoch))  # decided on the re-read board
    w.cycle()
    assert link.sent[-1] == ("set_rpm", 11.0)


def test_newest_set_rpm_supersedes_older_pending_ones() -> None:
    w, link, sink, _box = make(RUNNING)
    w.cycle()
    for rpm in (6.0, 7.0, 8.0):
        w.submit(SetRpm(rpm, epoch=1))
    w.cycle()
    assert link.sent == [("set_rpm", 8.0)]
    assert [d["rpm"] for d in sink.kinds("mill_command_dropped")] == [6.0, 7.0]


def test_a_failed_stop_is_kept_and_sent_once_the_link_is_back() -> None:
    w, link, _sink, _box = make(RUNNING)
    w.cycle()
    link.up = False
    w.submit(StopMill())
    w.cycle()
    link.up = True
    w.cycle()  # re-read
    w.cycle()
    assert link.sent == [("stop", None)] and not link.board.running


def test_a_refusal_is_an_event_the_command_is_dropped_and_the_link_stays_up() -> None:
    """Defect 6: a NAK was treated as a lost link and re-queued forever."""
    w, link, sink, box = make(RUNNING)
    w.cycle()
    link.refuse["start"] = "FAULT"
    w.submit(StartMill(epoch=1))
    for _ in range(10):
        w.cycle()
    refused = sink.kinds("mill_refused")
    assert len(refused) == 1 and refused[0]["command"] == "start" and refused[0]["reason"] == "FAULT"
    assert box.get().connected and "mill_link" not in sink.faults
    assert box.get().epoch == 2  # the board is re-read: the supervisor resyncs to it
    assert link.sent == []


def test_emergency_stop_drops_pending_commands_and_stops() -> None:
    w, link, sink, _box = make(RUNNING)
    w.cycle()
    w.submit(SetRpm(30.0, epoch=1))
    w.submit(StartMill(epoch=1))
    w.submit(StopMill(source="emergency_stop", urgent=True))
    w.cycle()
    assert link.sent == [("stop", None)]
    assert {d["command"] for d in sink.kinds("mill_command_dropped")} == {"set_rpm", "start"}


@pytest.mark.parametrize("status", [RUNNING, STOPPED_WDOG])
def test_the_worker_feeds_the_watchdog_only_once_this_run_commanded_the_mill(status: MillStatus) -> None:
    """Until a command of this run goes through the poller only reads (STA: a mill left running
    by another host is not kept alive); from then on it heartbeats (HB). No other request goes
    out unless commanded; a refused command does not make the run the controller."""
    w, link, _sink, box = make(status)
    for _ in range(3):
        w.cycle()
    assert link.reads == 3 and link.polls == 0 and link.sent == [] and box.get().status == status
    link.refuse["set_rpm"] = "FAULT"
    w.submit(SetRpm(rpm=7.0, epoch=box.get().epoch))
    w.cycle()
    assert link.polls == 0 and link.reads == 4
    del link.refuse["set_rpm"]
    w.submit(SetRpm(rpm=7.0, epoch=box.get().epoch))
    for _ in range(3):
        w.cycle()
    assert link.sent == [("set_rpm", 7.0)] and link.polls == 3 and link.reads == 4


def test_a_mill_left_running_by_another_host_stops_on_its_watchdog_over_tcp() -> None:
    """Defect: the run's poller fed the watchdog from its first poll, so a mill left running
    (a crashed earlier run, a front panel) kept turning although nobody asked this run to
    move it. Now it only reads until the operator or AUTO commands: the board's watchdog
    stops the motor, and the worker reports the WDOG fault."""

    from control.device import DeviceConfig
    from control.driver import MillClient
    from control.emulator import MillEmulator

    emu = MillEmulator(DeviceConfig(watchdog_s=0.5), seed=3)
    port = emu.open_tcp(0)
    try:
        emu.set_motor(setpoint_rpm=30.0, actual_rpm=30.0, running=True)
        link = MillClient(f"socket://127.0.0.1:{port}", heartbeat_s=None, timeout_s=0.5, retries=1,
                          reconnect_wait_s=0.2)
        sink, box = Sink(), Latest(MillSnapshot())
        w = MillWorker(link, sink, box, now_s=lambda: 0.0)
        wait_until(lambda: w.cycle().fault == "WDOG", 5, "the board's watchdog to trip, read by the worker")
        assert box.get().connected and box.get().fault == "WDOG" and not emu.motor.running
        assert emu.applied == [] and "mill_fault" in sink.faults
    finally:
        emu.close()


def test_the_rules_end_to_end_against_the_emulator_over_tcp() -> None:
    """The same worker on the real driver and the emulator's board over a TCP link."""

    from control.device import DeviceConfig
    from control.driver import MillClient
    from control.emulator import MillEmulator

    # link timeout and board watchdog leave room for a loaded machine (the suite runs on two
    # workers beside the whole-loop demos): a 0.1 s reply timeout failed there once in five runs
    emu = MillEmulator(DeviceConfig(watchdog_s=1.0), seed=2)
    port = emu.open_tcp(0)
    try:
        emu.set_motor(setpoint_rpm=8.0, actual_rpm=8.0, running=True)
        wait_until(lambda: emu.motor.fault == "WDOG", 5, "the board's watchdog to trip (nobody feeds it)")
        link = MillClient(f"socket://127.0.0.1:{port}", heartbeat_s=None, timeout_s=0.5, retries=1,
                          reconnect_wait_s=0.2)
        sink, box = Sink(), Latest(MillSnapshot())
        w = MillWorker(link, sink, box, now_s=lambda: 0.0)
        for _ in range(5):  # connecting: reads only, the tripped board stays stopped
            w.cycle()
        assert box.get().connected and box.get().fault == "WDOG" and not emu.motor.running
        assert emu.applied == []
        w.submit(StartMill(epoch=box.get().epoch))  # the operator
        w.cycle()
        assert emu.motor.running and [a.cmd for a in emu.applied] == ["RUN"]
        w.submit(SetRpm(1000.0, epoch=box.get().epoch))  # beyond the board's range: NAK
        snap = w.cycle()
        assert snap.connected and snap.epoch == 2 and sink.kinds("mill_refused")[0]["reason"] == "RANGE"
        assert "mill_link" not in sink.faults and emu.motor.setpoint_rpm == 8.0
        emu.disconnect()
        old_epoch = box.get().epoch
        for _ in range(3):
            w.cycle()
        assert not box.get().connected and "mill_link" in sink.faults
        w.submit(SetRpm(20.0, epoch=old_epoch))  # decided before the link came back
        emu.reconnect()
        wait_until(lambda: w.cycle().connected, 10, "the worker to read the board again")
        w.cycle()
        assert box.get().connected and box.get().epoch == old_epoch + 1
        assert emu.motor.setpoint_rpm == 8.0 and "SET" not in [a.cmd for a in emu.applied]
        link.close()
    finally:
        emu.close()


def test_commands_behind_a_refused_or_failed_one_are_dropped_with_an_event() -> None:
    w, link, sink, _box = make(RUNNING)
    w.cycle()
    link.refuse["start"] = "FAULT"
    w.submit(StartMill(epoch=1))
    w.submit(SetRpm(9.0, epoch=1))
    w.cycle()
    assert link.sent == [] and [d["command"] for d in sink.kinds("mill_command_dropped")] == ["set_rpm"]
    link.refuse.clear()
    link.up = False
    w.submit(StopMill())
    w.submit(SetRpm(9.0, epoch=2))
    w.cycle()
    assert [d["command"] for d in sink.kinds("mill_command_dropped")] == ["set_rpm", "set_rpm"]
    link.up = True
    w.cycle()
    w.cycle()
    assert link.sent == [("stop", None)]  # the stop was kept for the link's return


def test_a_board_reporting_rpm_no_board_can_have_is_a_lost_link_over_tcp() -> None:
    """The board answers HB with a checksum-valid status whose rpm is NaN: the worker used to
    publish it as a connected board (the supervisor had nothing to ramp from and jumped to
    its target); it is a bad answer: link fault, no status published."""
    import math

    from control.device import DeviceConfig
    from control.driver import MillClient
    from control.emulator import MillEmulator

    emu = MillEmulator(DeviceConfig(watchdog_s=0.0), seed=3)
    emu.device.status = lambda: MillStatus(math.nan, math.nan, True, None)  # type: ignore[method-assign]
    port = emu.open_tcp(0)
    try:
        link = MillClient(f"socket://127.0.0.1:{port}", heartbeat_s=None, timeout_s=0.5, retries=0,
                          reconnect_wait_s=0.0)
        sink, box = Sink(), Latest(MillSnapshot())
        w = MillWorker(link, sink, box, now_s=lambda: 0.0)
        for _ in range(3):
            snap = w.cycle()
        assert not snap.connected and snap.status is None and "mill_link" in sink.faults
        assert "malformed mill status" in sink.kinds("fault")[0]["message"]
        link.close()
    finally:
        emu.close()


def test_a_refusal_and_a_setpoint_the_board_did_not_take_are_counted_for_the_supervisor() -> None:
    """The supervisor goes safe on a refused command: the worker counts refusals in the
    snapshot (``refused``). A set-rpm the board ACKs but does not report as its setpoint is
    counted too (a ``mill_mismatch`` event), and the board is read again (new epoch)."""
    w, link, sink, _box = make(RUNNING)
    w.cycle()
    link.refuse["set_rpm"] = "RANGE"
    w.submit(SetRpm(50.0, epoch=1))
    snap = w.cycle()
    assert snap.refused == 1 and snap.epoch == 2 and snap.connected
    link.refuse.clear()
    real_set = link.set_rpm
    link.set_rpm = lambda rpm: real_set(rpm + 5.0)  # type: ignore[method-assign]  # ACKs, takes another
    w.submit(SetRpm(9.0, epoch=2))
    snap = w.cycle()
    assert snap.refused == 2 and snap.epoch == 3 and snap.connected and snap.setpoint_rpm == 14.0
    mismatch = sink.kinds("mill_mismatch")
    assert len(mismatch) == 1 and mismatch[0]["rpm"] == 9.0 and mismatch[0]["setpoint_rpm"] == 14.0
    link.set_rpm = real_set  # type: ignore[method-assign]
    w.submit(SetRpm(11.0, epoch=3))
    for _ in range(3):
        snap = w.cycle()
    assert snap.refused == 2 and snap.epoch == 3 and snap.setpoint_rpm == 11.0


def test_a_refused_command_puts_the_supervisor_in_its_safe_state_over_tcp() -> None:
    """Every refused command ends in the safe state: MANUAL asks for 40 rpm, the board's drive
    tops out at 20 rpm and answers NAK,RANGE; the supervisor used to resync and try again,
    never safe. Now: a ``mill_refused`` event and a safe decision naming the refusal."""
    from control.decision import Mode
    from control.device import DeviceConfig
    from control.driver import MillClient
    from control.emulator import MillEmulator
    from control.motor import MotorConfig
    from tests.twin.workers_fakes import Boxes, sup_worker
    from twin.live.commands import SetManualRpm

    emu = MillEmulator(DeviceConfig(watchdog_s=0.0, motor=MotorConfig(max_rpm=20.0)), seed=4)
    port = emu.open_tcp(0)
    try:
        emu.set_motor(setpoint_rpm=10.0, actual_rpm=10.0, running=True)
        link = MillClient(f"socket://127.0.0.1:{port}", heartbeat_s=None, timeout_s=0.5, retries=1,
                          reconnect_wait_s=0.2)
        b = Boxes("manual")
        sup, sink, _sent = sup_worker(b, Mode.MANUAL)
        mill = MillWorker(link, sink, b.mill, now_s=lambda: 0.0)
        sup.send = mill.submit
        mill.cycle()
        b.frame(0.0)
        sup.tick(b.view.now_s())
        sup.handle(SetManualRpm(40.0))
        assert not sup.safe
        mill.cycle()
        b.wall.t += 0.5
        sup.tick(b.view.now_s())
        assert sink.kinds("mill_refused")[0]["reason"] == "RANGE" and sup.safe
        safe = [d for d in sink.kinds("decision") if d["decision"] == "safe"]
        assert len(safe) == 1 and "refused" in safe[0]["reason"]
        assert emu.motor.setpoint_rpm == 10.0 and emu.motor.running
        link.close()
    finally:
        emu.close()


def test_a_new_board_fault_is_logged_even_while_another_one_is_active() -> None:
    """The board's fault changed from WDOG to DRIVE: the ``mill_fault`` fault was already
    raised (the run's sink logs a fault once until cleared), so the DRIVE fault left no
    event. Each new fault code is an event."""
    from twin.live.events import RunEvents
    from twin.state import LiveState

    class Log:
        def __init__(self) -> None:
            self.events: list[dict] = []

        def event(self, kind: str, t_s: float, **data) -> None:
            self.events.append({"kind": kind, **data})

    log = Log()
    link, box = FakeLink(STOPPED_WDOG), Latest(MillSnapshot())
    w = MillWorker(link, RunEvents(log, LiveState()), box, now_s=lambda: 0.0)
    w.cycle()
    link.board = MillStatus(13.0, 0.0, False, "DRIVE")
    w.cycle()
    w.cycle()
    assert [e.get("mill_fault") for e in log.events if e["kind"] == "fault"] == ["WDOG", "DRIVE"]
    link.board = MillStatus(13.0, 0.0, False, None)
    w.cycle()
    assert log.events[-1]["kind"] == "recovered" and log.events[-1]["fault"] == "mill_fault"

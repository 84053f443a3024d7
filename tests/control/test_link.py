"""The real pyserial driver against the emulator over a real pty and over TCP."""

from __future__ import annotations

import os
import random
import threading
import time

import pytest
import serial

from control import protocol as p
from control.device import DeviceConfig, MillDevice
from control.driver import MillClient
from control.emulator import Faults, MillEmulator
from control.errors import ControlError, MillRefused
from control.motor import MotorConfig
from tests.waiting import wait_until

FAST_MOTOR = MotorConfig(max_rpm=60.0, accel_rpm_per_s=40.0, tau_s=0.2)
QUICK_MOTOR = MotorConfig(max_rpm=60.0, accel_rpm_per_s=200.0, tau_s=0.05)  # settles in ~0.3 s


@pytest.fixture(params=["pty", "tcp"])
def kind(request) -> str:
    return request.param


def make_emulator(kind: str, **kw) -> MillEmulator:
    emu = MillEmulator(kw.pop("config", DeviceConfig(watchdog_s=2.0, motor=FAST_MOTOR)), **kw)
    if kind == "pty":
        path = emu.open_pty()
        assert os.path.islink(path) and os.ttyname(os.open(path, os.O_RDWR | os.O_NOCTTY)).startswith("/dev/pts")
    else:
        emu.open_tcp(0)
        assert emu.url.startswith("socket://127.0.0.1:")
    return emu


@pytest.mark.timeout(30)
def test_set_rpm_converges_start_stop(kind):
    with (
        make_emulator(kind, config=DeviceConfig(watchdog_s=2.0, motor=QUICK_MOTOR)) as emu,
        MillClient(emu.url, timeout_s=0.2, heartbeat_s=0.1) as c,
    ):
        st = c.status()
        assert st == p.MillStatus(0.0, 0.0, False, None) and c.connected
        c.set_rpm(15.0)
        c.start()
        wait_until(lambda: abs(c.status().actual_rpm - 15.0) < 0.1, 5.0, "the motor at 15 rpm")
        assert emu.motor.running and emu.motor.setpoint_rpm == 15.0
        c.set_rpm(25.5)
        wait_until(lambda: abs(emu.motor.actual_rpm - 25.5) < 0.1, 5.0, "the motor at 25.5 rpm")
        wait_until(lambda: c.last_status is not None and c.last_status.setpoint_rpm == 25.5, 3.0,
                   "a heartbeat to read the new setpoint")
        c.stop()
        wait_until(lambda: c.status().actual_rpm == 0.0, 5.0, "the motor to stop")
        st = c.status()
        assert not st.running and st.setpoint_rpm == 25.5
        with pytest.raises(MillRefused, match="RANGE"):
            c.set_rpm(61.0)  # above the board's max rpm: NAK, not retried
        assert [a.cmd for a in emu.applied] == [p.SET, p.RUN, p.SET, p.STP]


@pytest.mark.timeout(60)
def test_corrupted_line_every_command_once(kind):
    faults = Faults(corrupt_p=0.03)
    with make_emulator(kind, faults=faults, seed=11) as emu, MillClient(
        emu.url, timeout_s=0.05, retries=300, heartbeat_s=None
    ) as c:
        sent = []
        for i in range(12):
            rpm = 5.0 + 2.5 * i
            c.set_rpm(rpm)
            sent.append((p.SET, (f"{rpm:.2f}",)))
            if i == 3:
                c.start()
                sent.append((p.RUN, ()))
            if i % 4 == 0:
                assert c.status().setpoint_rpm == rpm
        c.stop()
        sent.append((p.STP, ()))
        applied = emu.applied
        assert [(a.cmd, a.args) for a in applied] == sent  # all through, in order, none twice
        assert len({a.seq for a in applied}) == len(applied)
        assert c.stats["resends"] > 0 and emu.counters["bad_crc"] > 0  # the faults were real
        assert emu.motor.setpoint_rpm == 32.5 and not emu.motor.running


@pytest.mark.timeout(30)
def test_unplug_and_reconnect(kind):
    with make_emulator(kind) as emu, MillClient(
        emu.url, timeout_s=0.1, retries=2, heartbeat_s=0.05, backoff_s=0.02, backoff_max_s=0.2
    ) as c:
        c.set_rpm(10.0)
        c.start()
        assert c.connected
        emu.disconnect()
        wait_until(lambda: not c.connected, 3.0, "the client to see the unplug")
        with pytest.raises((ConnectionError, TimeoutError)):
            c.status()
        emu.reconnect()
        wait_until(lambda: c.connected, 5.0, "the heartbeat thread to reconnect")
        assert c.stats["reconnects"] >= 2 and c.stats["link_errors"] >= 1
        st = c.status()
        assert st.setpoint_rpm == 10.0 and st.running  # the board kept its state
        c.set_rpm(12.0)
        assert emu.motor.setpoint_rpm == 12.0


@pytest.mark.timeout(30)
def test_tcp_connection_drop_reconnects():
    with make_emulator("tcp") as emu, MillClient(emu.url, timeout_s=0.1, retries=3, heartbeat_s=None) as c:
        c.set_rpm(4.0)
        emu.drop_client()  # server side closes the connection, keeps listening
        c.set_rpm(6.0)  # the request itself reconnects
        assert emu.motor.setpoint_rpm == 6.0 and emu.connections == 2


@pytest.mark.timeout(30)
def test_watchdog_stops_motor_when_host_is_silent():
    cfg = DeviceConfig(watchdog_s=0.4, motor=FAST_MOTOR)
    with make_emulator("tcp", config=cfg) as emu:
        c = MillClient(emu.url, timeout_s=0.1, heartbeat_s=0.05)
        c.set_rpm(20.0)
        c.start()
        time.sleep(0.8)  # real time: > the board's 0.4 s watchdog, which the heartbeat must keep fed
        assert emu.motor.running and emu.motor.fault is None
        c.close()  # host goes quiet
        wait_until(lambda: not emu.motor.running, 2.0, "the watchdog to stop the motor")
        assert emu.motor.fault == p.FAULT_WATCHDOG
        wait_until(lambda: emu.motor.actual_rpm == 0.0, 3.0, "the motor to spin down")
        with MillClient(emu.url, timeout_s=0.1, heartbeat_s=0.05) as c2:
            assert c2.status().fault == p.FAULT_WATCHDOG
            c2.start()  # explicit start clears the fault
            st = c2.status()
            assert st.running and st.fault is None


@pytest.mark.timeout(30)
def test_garbage_to_emulator_never_moves_motor(kind):
    with make_emulator(kind) as emu:
        rng = random.Random(5)
        port = serial.serial_for_url(emu.url, timeout=0.05)
        try:
            for _ in range(50):
                port.write(bytes(rng.randrange(256) for _ in range(rng.randint(1, 500))))
            port.write(b"$1,SET," + b"7" * 300 + b"\n")  # over-long
            port.write(b"$2,RUN*0000\n$3,SET,30.00*FFFF\n")  # wrong checksums
            port.write(p.encode_frame(4, "ZAP") + p.encode_frame(5, p.SET, "-3") + p.encode_frame(6, p.RUN, "now"))
            # a status request last: its answer says the board has read everything before it
            # (a fixed 0.3 s wait saw no NAK yet on a loaded machine)
            port.write(p.encode_frame(7, p.STA))
            decoder, seqs, end = p.FrameDecoder(), [], time.monotonic() + 20.0
            while 7 not in seqs and time.monotonic() < end:
                seqs += [f.seq for f in decoder.feed(port.read(4096)) if isinstance(f, p.Frame)]
            assert 7 in seqs, "the board never answered the status request after the garbage"
        finally:
            port.close()
        st = emu.motor
        assert emu.applied == [] and not st.running and st.setpoint_rpm == 0.0 and st.actual_rpm == 0.0
        assert emu.counters["nak"] >= 3
        with MillClient(emu.url, timeout_s=0.2, heartbeat_s=None) as c:  # still serving
            c.set_rpm(3.0)
            assert emu.motor.setpoint_rpm == 3.0


class GarbageDevice:
    """A board on a raw pty that answers correctly but sprays garbage around its replies."""

    def __init__(self, answer: bool) -> None:
        self.master, slave = os.openpty()
        import tty

        tty.setraw(slave)
        self.slave = slave
        self.path = os.ttyname(slave)
        self.answer = answer
        self.device = MillDevice(DeviceConfig(watchdog_s=0.0))
        self.rng = random.Random(9)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def junk(self) -> bytes:
        r = self.rng
        choices = [
            bytes(r.randrange(256) for _ in range(r.randint(1, 200))),
            b"$" + b"A" * 300 + b"\n",
            p.encode_frame(r.randrange(1, 60000), p.ACK),  # valid frame, wrong seq
            b"$5,ACK*0000\n",
        ]
        return r.choice(choices)

    def run(self) -> None:
        import select

        t0 = time.monotonic()
        while not self.stop.is_set():
            if select.select([self.master], [], [], 0.01)[0]:
                data = os.read(self.master, 4096)
                reply = self.device.receive(data, time.monotonic() - t0)
                os.write(self.master, self.junk() + (reply if self.answer else b"") + self.junk())

    def close(self) -> None:
        self.stop.set()
        self.thread.join(1)
        os.close(self.master)
        os.close(self.slave)


@pytest.mark.timeout(30)
def test_garbage_to_driver_never_crashes_it():
    dev = GarbageDevice(answer=False)
    try:
        with MillClient(dev.path, timeout_s=0.05, retries=3, heartbeat_s=0.02) as c:
            with pytest.raises(TimeoutError):
                c.status()
            assert not c.connected and c._hb_thread is not None and c._hb_thread.is_alive()
            dev.answer = True
            assert c.status() == p.MillStatus(0.0, 0.0, False, None)
            c.set_rpm(9.0)
            assert dev.device.motor.setpoint_rpm == 9.0 and c.stats["bad_frames"] > 0
            assert [a.cmd for a in dev.device.applied] == [p.SET]
    finally:
        dev.close()


def test_bad_url_is_a_clear_error():
    with pytest.raises(ConnectionError, match="cannot open mill link"):
        MillClient("/nonexistent/ttyUSB9", heartbeat_s=None)
    with pytest.raises(ControlError):
        MillClient("", heartbeat_s=None)
    c = MillClient("/nonexistent/ttyUSB9", heartbeat_s=None, connect=False, retries=1, backoff_s=0.01)
    with pytest.raises(ConnectionError):
        c.status()
    assert not c.connected
    c.close()


def test_fault_spec_parsing():
    f = Faults.parse("corrupt=0.05, drop=0.01,delay=0.02,disconnect=10:1.5")
    assert f == Faults(drop_p=0.01, corrupt_p=0.05, delay_s=0.02, disconnect_every_s=10.0, disconnect_for_s=1.5)
    assert Faults.parse("") == Faults()
    bad_specs = ("corrupt=2", "drop=x", "melt=1", "delay=-1", "delay=nan", "corrupt=nan",
                 "disconnect=inf:1", "disconnect=5:0")
    for bad in bad_specs:
        with pytest.raises(ControlError):
            Faults.parse(bad)


@pytest.mark.timeout(60)
def test_flaky_line_with_drops_delays_and_periodic_unplugs(kind):
    faults = Faults(drop_p=0.01, corrupt_p=0.01, delay_s=0.01, disconnect_every_s=0.6, disconnect_for_s=0.2)
    with make_emulator(kind, faults=faults, seed=4) as emu, MillClient(
        emu.url, timeout_s=0.08, retries=60, heartbeat_s=None, backoff_s=0.02, backoff_max_s=0.1, reconnect_wait_s=2.0
    ) as c:
        sent: list[str] = []
        end = time.monotonic() + 30.0  # a hang guard: commands go on until the line was unplugged twice
        while (emu.connections < 3 or c.stats["reconnects"] < 2) and time.monotonic() < end:
            rpm = float(1 + len(sent) % 40)
            c.set_rpm(rpm)
            sent.append(f"{rpm:.2f}")
        applied = [a.args[0] for a in emu.applied]
        assert applied == sent  # every command once, in order, across unplugs
        assert emu.connections >= 3 and c.stats["reconnects"] >= 2  # the unplugs really happened


@pytest.mark.timeout(30)
def test_client_is_thread_safe(kind):
    with make_emulator(kind) as emu, MillClient(emu.url, timeout_s=1.0, heartbeat_s=0.01) as c:
        errors = []

        def worker(k: int) -> None:
            try:
                for j in range(15):
                    c.set_rpm(k * 10 + j * 0.25)
                    st = c.status()
                    assert isinstance(st.actual_rpm, float)
            except Exception as exc:
                errors.append(exc)

        threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(20)
        assert errors == []
        sets = [a for a in emu.applied if a.cmd == p.SET]
        assert len(sets) == 60 and len({a.seq for a in sets}) == 60
        assert c.stats["resends"] == 0  # a clean line: no frame got mixed up


@pytest.mark.timeout(20)
def test_front_panel_preset_is_not_a_command():
    with make_emulator("tcp", config=DeviceConfig(watchdog_s=0.8, motor=FAST_MOTOR)) as emu:
        with MillClient(emu.url, timeout_s=0.2, heartbeat_s=0.05) as c:
            st = emu.set_motor(setpoint_rpm=7.0, actual_rpm=7.0, running=True)
            assert st.running and st.actual_rpm == 7.0 and emu.applied == []
            time.sleep(1.2)  # real time: > the board's 0.8 s watchdog, which the heartbeat must keep fed
            assert c.status() == p.MillStatus(7.0, 7.0, True, None)
        wait_until(lambda: emu.motor.fault == p.FAULT_WATCHDOG, 2.0, "the watchdog trip")  # silence -> stop


class _PtySerial(serial.Serial):
    """pyserial port on a pty, which has no modem lines (the RFC 2217 server asks for them)."""

    cts = dsr = ri = cd = False

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass


class Rfc2217Server:
    """A minimal RFC 2217 serial server (like ser2net) in front of the emulator's pty."""

    def __init__(self, path: str) -> None:
        import socket

        import serial.rfc2217

        self.ser = _PtySerial(path, timeout=0.05)
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen(1)
        self.port = self.srv.getsockname()[1]
        self.alive = True
        self.lock = threading.Lock()
        self.conn = None
        self._mod = serial.rfc2217
        threading.Thread(target=self.serve, daemon=True).start()

    def write(self, data: bytes) -> None:  # called by PortManager
        with self.lock:
            self.conn.sendall(data)

    def serve(self) -> None:
        self.conn, _ = self.srv.accept()
        self.manager = self._mod.PortManager(self.ser, self)

        def reader() -> None:
            while self.alive:
                try:
                    data = self.ser.read(self.ser.in_waiting or 1)
                    if data:
                        self.write(b"".join(self.manager.escape(data)))
                except Exception:
                    return

        threading.Thread(target=reader, daemon=True).start()
        while self.alive:
            try:
                data = self.conn.recv(1024)
            except OSError:
                return
            if not data:
                return
            self.ser.write(b"".join(self.manager.filter(data)))

    def close(self) -> None:
        self.alive = False
        for x in (self.conn, self.srv, self.ser):
            try:
                x.close()
            except Exception:
                pass


@pytest.mark.timeout(30)
@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # inside pyserial's rfc2217 client
def test_rfc2217_url_works():
    with make_emulator("pty") as emu:
        srv = Rfc2217Server(emu.url)
        try:
            with MillClient(f"rfc2217://127.0.0.1:{srv.port}", timeout_s=0.3, heartbeat_s=None) as c:
                c.set_rpm(11.0)
                c.start()
                st = c.status()
                assert st.setpoint_rpm == 11.0 and st.running
                assert [a.cmd for a in emu.applied] == [p.SET, p.RUN]
        finally:
            srv.close()


@pytest.mark.timeout(20)
def test_refusals_raise_mill_refused_once_and_keep_the_link():
    """A NAK is not a lost link: one frame on the line, no resend, the link stays up."""
    with make_emulator("tcp") as emu, MillClient(emu.url, timeout_s=0.2, heartbeat_s=None) as c:
        c.set_rpm(5.0)
        frames0 = emu.counters["frames"]
        with pytest.raises(MillRefused) as exc:
            c.set_rpm(61.0)  # above max_rpm
        assert (exc.value.command, exc.value.reason) == ("SET 61.0", p.NAK_RANGE)
        emu.set_drive_fault()
        with pytest.raises(MillRefused) as exc:
            c.start()
        assert (exc.value.command, exc.value.reason) == ("RUN", p.NAK_FAULT)
        assert emu.counters["frames"] == frames0 + 2 and c.stats["resends"] == 0
        assert c.stats["naks"] == 2 and c.connected and c.last_error is None
        assert c.status().fault == p.FAULT_DRIVE and not emu.motor.running
        emu.set_drive_fault(False)
        c.start()
        assert emu.motor.running and [a.cmd for a in emu.applied] == [p.SET, p.RUN]


@pytest.mark.timeout(20)
def test_a_status_poller_does_not_keep_the_motor_running_after_its_controller_died():
    cfg = DeviceConfig(watchdog_s=0.4, motor=FAST_MOTOR)
    with make_emulator("tcp", config=cfg) as emu:
        with MillClient(emu.url, timeout_s=0.2, heartbeat_s=0.05) as controller:
            controller.set_rpm(12.0)
            controller.start()
            time.sleep(0.6)  # real time: > the board's 0.4 s watchdog; the controller's heartbeat feeds it
            assert emu.motor.running
        # the controlling host is gone; a monitor keeps reading the status
        with MillClient(emu.url, timeout_s=0.2, heartbeat_s=None) as monitor:
            wait_until(lambda: monitor.status().fault is not None, 3.0, "the watchdog trip while a monitor reads")
            st = monitor.status()
        assert not st.running and st.fault == p.FAULT_WATCHDOG and emu.counters["watchdog_trips"] == 1


def test_each_client_starts_its_sequence_numbers_at_a_random_value():
    with make_emulator("tcp", config=DeviceConfig(watchdog_s=0.0)) as emu:
        for _ in range(3):
            with MillClient(emu.url, timeout_s=0.2, heartbeat_s=None) as c:
                c.set_rpm(3.0)
        seqs = [a.seq for a in emu.applied]
    assert len(seqs) == 3 and len(set(seqs)) == 3  # 1 in ~2e9 to collide by chance


@pytest.mark.parametrize(
    ("kw", "needle"),
    [({"timeout_s": float("nan")}, "timeout_s"), ({"timeout_s": 0.0}, "timeout_s"),
     ({"retries": -1}, "retries"), ({"heartbeat_s": float("inf")}, "heartbeat_s"),
     ({"backoff_s": -0.1}, "backoff_s"), ({"reconnect_wait_s": float("nan")}, "reconnect_wait_s")],
)
def test_bad_client_settings_are_refused(kw, needle):
    with pytest.raises(ControlError, match=needle):
        MillClient("socket://127.0.0.1:9", connect=False, **{"heartbeat_s": None, **kw})

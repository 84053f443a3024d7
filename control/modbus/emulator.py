"""The drive emulator: a ``DriveModel`` served by pymodbus's own server (RTU framing) on a
real pty or a TCP port (RTU frames over TCP, what ``socket://`` carries).

Usage (in-process, e.g. a test or the demo plant)::

    emu = DriveEmulator(load_profile("delta-ms300"), unit=1)
    url = emu.open_pty()        # a stable symlink to the host's pty -> "modbus:" + url + "?profile=..."
    # or: emu.open_tcp(0); emu.url -> "socket://127.0.0.1:PORT"
    emu.faults = DriveFaults(delay_s=0.5)   # slow replies; corrupt_p: CRC errors; mute: no answer
    emu.set_drive_fault()                   # the power stage trips
    emu.close()

On a pty there are two: pymodbus's ``ModbusSerialServer`` opens the drive's end, the host
opens the other, and a small relay thread between the two masters is the RS-485 cable
(``disconnect()`` unplugs it). Requests to any other unit id are not answered (a drive
only answers its own address). The server runs in its own asyncio loop in a thread, with
the framer and decoder of ``control.modbus.server`` (exception codes by the book).
"""

from __future__ import annotations

import asyncio
import logging
import os
import random
import select
import tempfile
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from control.errors import ControlError
from control.modbus.drive import DriveModel, DriveWrite
from control.modbus.profile import DriveProfile, read_blocks
from control.motor import MotorState


@dataclass
class DriveFaults:
    """What the emulator injects on the line: ``delay_s`` before each reply (slow replies),
    ``corrupt_p`` probability that a reply's CRC is wrong, ``mute``: no replies at all;
    ``rewrite``: a drive that answers wrongly (another function code, byte count or echo):
    called with each reply without its CRC, what it returns is sent with a valid CRC."""

    delay_s: float = 0.0
    corrupt_p: float = 0.0
    mute: bool = False
    rewrite: Callable[[bytes], bytes] | None = None


class DriveEmulator:
    """A drive (profile) behind pymodbus on a pty or TCP; thread-safe accessors."""

    def __init__(
        self,
        profile: DriveProfile,
        *,
        unit: int = 1,
        comm_loss_s: float = 2.0,
        comm_loss_safe: bool = True,
        hz_per_rpm: float | None = None,
        speed: float = 1.0,
        faults: DriveFaults | None = None,
        seed: int | None = None,
        tick_s: float = 0.01,
    ) -> None:
        if not 1 <= unit <= 247:
            raise ControlError(f"unit id must be in 1..247 (got {unit})")
        self.profile = profile
        self.unit = unit
        self.hz_per_rpm = profile.hz_per_rpm if hz_per_rpm is None else float(hz_per_rpm)
        self.faults = faults or DriveFaults()
        self.tick_s = tick_s
        self._speed = float(speed)
        self._rng = random.Random(seed)
        self._lock = threading.RLock()
        self._t0 = time.monotonic()
        self.model = DriveModel(profile, comm_loss_s=comm_loss_s, now_s=0.0)
        self.model.commission(comm_loss_s, comm_loss_safe)
        if speed != 1.0:  # the demo's clock: the motor ramps in run time
            m = self.model.motor
            m.config = type(m.config)(m.config.max_rpm, m.config.accel_rpm_per_s * speed, m.config.tau_s / speed)
        self.replies = 0
        self._kind: str | None = None
        self._port = 0
        self._tmpdir: tempfile.TemporaryDirectory[str] | None = None
        self._link_path: Path | None = None
        self._fds: dict[str, int | None] = {"drive_m": None, "drive_s": None, "host_m": None, "host_s": None}
        self._plugged = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._relay: threading.Thread | None = None
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None

    # -- state (thread-safe) ------------------------------------------------------------------
    def now_s(self) -> float:
        return time.monotonic() - self._t0

    @property
    def motor(self) -> MotorState:
        """The motor as drum rpm (output Hz / ``hz_per_rpm``), like ``MillEmulator.motor``."""
        with self._lock:
            self.model.tick(self.now_s())
            m = self.model.motor
            k = self.hz_per_rpm
            fault = self.profile.fault_name(self.model.fault_code) if self.model.fault_code else None
            return MotorState(m.setpoint_rpm / k, m.actual_rpm / k, m.running, fault)

    @property
    def output_hz(self) -> float:
        with self._lock:
            self.model.tick(self.now_s())
            return self.model.motor.actual_rpm

    @property
    def fault_code(self) -> int:
        with self._lock:
            self.model.tick(self.now_s())
            return self.model.fault_code

    @property
    def writes(self) -> list[DriveWrite]:
        """Copy of the register writes the drive applied."""
        with self._lock:
            return list(self.model.writes)

    @property
    def counters(self) -> dict[str, int]:
        with self._lock:
            return {**self.model.counters, "replies": self.replies}

    @property
    def trip_times_s(self) -> list[float]:
        """When each comm-loss trip stopped the motor, on this emulator's clock (:meth:`now_s`)."""
        with self._lock:
            self.model.tick(self.now_s())
            return list(self.model.trip_times_s)

    def registers(self, address: int, count: int = 1) -> list[int]:
        """The drive's registers as a Modbus read would see them now."""
        with self._lock:
            out = self.model.read(address, count, self.now_s())
        if isinstance(out, int):
            raise ControlError(f"registers {address}..{address + count - 1} are not mapped")
        return out

    def commission(self, comm_loss_s: float, safe: bool = True) -> None:
        """Set the drive's comm-loss parameters (as at its keypad)."""
        with self._lock:
            self.model.commission(comm_loss_s, safe)

    def set_drive_fault(self, active: bool = True) -> None:
        """The power stage trips with the profile's drive fault (or that fault is cleared)."""
        with self._lock:
            self.model.set_fault(self.profile.drive_fault_code if active else None)

    def set_motor(self, *, setpoint_rpm: float | None = None, running: bool | None = None,
                  actual_rpm: float | None = None) -> MotorState:
        """The front panel / another host: preset the motor (drum rpm) without a bus write.
        Starting it restarts the comm-loss time, as that host's run command did."""
        with self._lock:
            m = self.model.motor
            now = self.now_s()
            self.model.tick(now)
            if setpoint_rpm is not None:
                m.setpoint_rpm = min(float(setpoint_rpm) * self.hz_per_rpm, self.profile.max_hz)
            if actual_rpm is not None:
                m.actual_rpm = min(max(float(actual_rpm) * self.hz_per_rpm, 0.0), self.profile.max_hz)
            if running is not None:
                m.running = bool(running)
                if running:
                    self.model.feed(now)
            self.model.tick(now)
        return self.motor

    @property
    def url(self) -> str:
        """What the host opens: the pty link path or ``socket://127.0.0.1:PORT``."""
        if self._kind == "pty":
            return str(self._link_path)
        if self._kind == "tcp":
            return f"socket://127.0.0.1:{self._port}"
        raise ControlError("the drive emulator is not open (call open_pty or open_tcp)")

    def mill_url(self, **extra: object) -> str:
        """The ``modbus:`` mill URL of this drive (``extra`` adds query keys). Parity N: a Linux
        pty refuses a parity flag (EINVAL) and a socket has none."""
        q = {"profile": self.profile.name, "unit": self.unit, "hz_per_rpm": self.hz_per_rpm, "parity": "N", **extra}
        return f"modbus:{self.url}?" + "&".join(f"{k}={v}" for k, v in q.items())

    # -- opening ----------------------------------------------------------------------------
    def open_pty(self, link: str | os.PathLike[str] | None = None) -> str:
        """Serve on a pty; return the stable path (symlink) of the host's end."""
        if self._kind is not None:
            raise ControlError("the drive emulator is already open")
        if link is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix="drumtwin-drive-")
            link = Path(self._tmpdir.name) / "drive"
        self._link_path = Path(link)
        self._kind = "pty"
        dm, ds = os.openpty()
        tty.setraw(ds)
        os.set_blocking(dm, False)
        self._fds["drive_m"], self._fds["drive_s"] = dm, ds
        self._plug_host()
        self._relay = threading.Thread(target=self._relay_loop, name="drive-cable", daemon=True)
        self._relay.start()
        self._start_server(port=os.ttyname(ds))
        return str(self._link_path)

    def open_tcp(self, port: int = 0) -> int:
        """Serve RTU frames on TCP ``127.0.0.1:port`` (0: a free port); return the port."""
        if self._kind is not None:
            raise ControlError("the drive emulator is already open")
        self._kind = "tcp"
        self._start_server(tcp_port=port)
        return self._port

    def _plug_host(self) -> None:
        hm, hs = os.openpty()
        tty.setraw(hs)
        os.set_blocking(hm, False)
        self._fds["host_m"], self._fds["host_s"] = hm, hs
        assert self._link_path is not None
        tmp = self._link_path.with_name(self._link_path.name + ".new")
        tmp.unlink(missing_ok=True)
        os.symlink(os.ttyname(hs), tmp)
        os.replace(tmp, self._link_path)
        self._plugged = True

    def disconnect(self) -> None:
        """Pty only: unplug the cable (the host's port errors); the drive keeps running
        until its comm-loss trip stops it."""
        with self._lock:
            for k in ("host_m", "host_s"):
                fd = self._fds[k]
                if fd is not None:
                    os.close(fd)
                self._fds[k] = None
            if self._link_path is not None:
                self._link_path.unlink(missing_ok=True)
            self._plugged = False

    def reconnect(self) -> None:
        """Plug the cable back in (a new pty behind the same link path)."""
        with self._lock:
            if not self._plugged and self._kind == "pty":
                self._plug_host()

    def _relay_loop(self) -> None:
        """The cable: bytes between the host's pty and the drive's pty."""
        while not self._stop.is_set():
            with self._lock:
                hm, dm = self._fds["host_m"], self._fds["drive_m"]
            fds = [fd for fd in (hm, dm) if fd is not None]
            try:
                ready = select.select(fds, [], [], 0.05)[0]
            except (OSError, ValueError):
                continue
            with self._lock:
                for fd in ready:
                    if fd not in (self._fds["host_m"], self._fds["drive_m"]):
                        continue
                    try:
                        data = os.read(fd, 4096)
                    except (BlockingIOError, InterruptedError):
                        continue
                    except OSError:  # the other end is not open (yet)
                        time.sleep(0.01)
                        continue
                    other = self._fds["drive_m"] if fd == self._fds["host_m"] else self._fds["host_m"]
                    if other is not None and data:
                        try:
                            os.write(other, data)
                        except OSError:
                            pass  # nobody on the other end: the bytes are lost, as on a real line

    # -- the pymodbus server -------------------------------------------------------------------
    def _start_server(self, *, port: str = "", tcp_port: int | None = None) -> None:
        self._thread = threading.Thread(target=self._serve, args=(port, tcp_port), name="drive-emulator", daemon=True)
        self._thread.start()
        if not self._ready.wait(10.0) or self._error is not None:
            self.close()
            raise ControlError(f"the drive emulator did not start: {self._error or 'timeout'}")

    def _serve(self, port: str, tcp_port: int | None) -> None:
        try:
            asyncio.run(self._amain(port, tcp_port))
        except BaseException as exc:  # reported to the opener
            self._error = exc
            self._ready.set()

    async def _amain(self, port: str, tcp_port: int | None) -> None:
        from pymodbus.framer import FramerType
        from pymodbus.server import ModbusSerialServer, ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        from control.modbus.server import by_the_book

        self._loop = asyncio.get_running_loop()
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # requests to other unit ids: no log spam
        simdata = [
            SimData(start, count=count, values=0, datatype=DataType.REGISTERS)
            for start, count in read_blocks(self.profile.all_registers)
        ]
        device = SimDevice(self.unit, simdata=simdata, action=self._action)
        common: dict[str, Any] = {"framer": FramerType.RTU, "ignore_missing_devices": True,
                                  "trace_packet": self._trace_packet}
        if tcp_port is not None:
            import socket

            s = socket.socket()  # pick the free port now, so it is known before serving
            s.bind(("127.0.0.1", tcp_port))
            self._port = s.getsockname()[1]
            s.close()
            self._server = by_the_book(ModbusTcpServer(device, address=("127.0.0.1", self._port), **common))
        else:
            self._server = by_the_book(ModbusSerialServer(device, port=port, baudrate=115200, **common))
        ticker = asyncio.create_task(self._ticker())
        await self._server.serve_forever(background=True)
        self._ready.set()
        while not self._stop.is_set():
            await asyncio.sleep(0.05)
        ticker.cancel()
        await self._server.shutdown()

    async def _ticker(self) -> None:
        while True:
            with self._lock:
                self.model.tick(self.now_s())
            await asyncio.sleep(self.tick_s)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None) -> Any:
        from pymodbus.constants import ExcCodes

        if self.faults.delay_s > 0:
            await asyncio.sleep(self.faults.delay_s)
        with self._lock:
            now = self.now_s()
            if set_values is not None and function_code in (6, 16):
                err = self.model.write(address, [int(v) for v in set_values], now)
                if err is not None:
                    return ExcCodes(err)
            out = self.model.read(address, count, now)
            if isinstance(out, int):
                return ExcCodes(out)
            if set_values is None:  # a read: serve the live registers
                off = address - start_address
                registers[off:off + count] = out
        return None

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            return data
        f = self.faults
        if f.mute or not data or data[0] != self.unit:  # a drive answers its own unit id only
            return b""
        self.replies += 1
        if f.rewrite is not None:
            from pymodbus.framer import FramerRTU

            body = f.rewrite(data[:-2])
            data = body + FramerRTU.compute_CRC(body).to_bytes(2, "big")
        if f.corrupt_p > 0 and self._rng.random() < f.corrupt_p and data:
            return data[:-1] + bytes([data[-1] ^ 0xFF])  # the CRC's last byte: a CRC error
        return data

    # -- closing -------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the server and the cable, release the ptys (idempotent)."""
        self._stop.set()
        for t in (self._thread, self._relay):
            if t is not None and t is not threading.current_thread():
                t.join(5.0)
        with self._lock:
            for k, fd in self._fds.items():
                if fd is not None:
                    try:
                        os.close(fd)
                    except OSError:
                        pass
                self._fds[k] = None
        if self._link_path is not None:
            self._link_path.unlink(missing_ok=True)
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None

    def __enter__(self) -> DriveEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["DriveEmulator", "DriveFaults"]

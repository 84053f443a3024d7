"""The mill emulator: the board's firmware (``control.device``) on a pty or a TCP port.

Usage (in-process, e.g. the demo plant or a test)::

    emu = MillEmulator(DeviceConfig(watchdog_s=1.0), faults=Faults(corrupt_p=0.05))
    url = emu.open_pty()            # a stable symlink to the pty slave -> MillClient(url)
    # or: port = emu.open_tcp(0); url = emu.url   ("socket://127.0.0.1:PORT")
    emu.motor.actual_rpm            # thread-safe snapshot of the motor
    emu.disconnect(); emu.reconnect()   # unplug / plug the cable back in
    emu.close()

One background thread serves the link, runs the motor and the watchdog every
``tick_s`` and applies the fault injection (dropped/corrupted bytes in both directions,
reply delay, periodic disconnects).
"""

from __future__ import annotations

import os
import random
import select
import socket
import tempfile
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from control import protocol as p
from control.device import Applied, DeviceConfig, MillDevice
from control.errors import ControlError, check_number
from control.motor import MotorState
from control.protocol import MillStatus


@dataclass(frozen=True)
class Faults:
    """Line faults the emulator injects.

    ``drop_p``/``corrupt_p``: probability per byte (both directions) of losing it or
    replacing it with a different random byte; ``delay_s``: extra latency before each
    reply; ``disconnect_every_s``/``disconnect_for_s``: unplug the link periodically.
    """

    drop_p: float = 0.0
    corrupt_p: float = 0.0
    delay_s: float = 0.0
    disconnect_every_s: float | None = None
    disconnect_for_s: float = 1.0

    @classmethod
    def parse(cls, text: str | None) -> Faults:
        """From ``"corrupt=0.05,drop=0.01,delay=0.02,disconnect=10:1"`` (empty: none)."""
        f = cls()
        if not text:
            return f
        for item in text.split(","):
            item = item.strip()
            if not item:
                continue
            key, _, val = item.partition("=")
            try:
                if key == "drop":
                    f = replace(f, drop_p=float(val))
                elif key == "corrupt":
                    f = replace(f, corrupt_p=float(val))
                elif key == "delay":
                    f = replace(f, delay_s=float(val))
                elif key == "disconnect":
                    every, _, dur = val.partition(":")
                    f = replace(f, disconnect_every_s=float(every), disconnect_for_s=float(dur or 1.0))
                else:
                    raise ControlError(
                        f"unknown fault {key!r} (use drop=P, corrupt=P, delay=S, disconnect=EVERY:FOR)"
                    )
            except ValueError as exc:
                if isinstance(exc, ControlError):
                    raise
                raise ControlError(f"bad fault value in {item!r}") from None
        for name in ("drop_p", "corrupt_p"):
            check_number(f"fault {name}", getattr(f, name), at_least=0.0, at_most=1.0)
        check_number("fault delay", f.delay_s, at_least=0.0, at_most=60.0)
        if f.disconnect_every_s is not None:
            check_number("fault disconnect EVERY", f.disconnect_every_s, above=0.0)
            check_number("fault disconnect FOR", f.disconnect_for_s, above=0.0)
        return f


PTY_DIR_PREFIX = "drumtwin-mill-"
OWNER_FILE = "owner"  # "<pid> <start time in clock ticks>" of the emulator's process


def _owner_id(pid: int) -> str | None:
    """``"<pid> <start ticks>"`` of a live process (the start time tells a reused pid
    apart), None when there is no such process."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[-1].split()
    return f"{pid} {fields[19]}" if len(fields) > 19 else None


def owner_pid(text: str) -> int | None:
    """The pid in an owner file's text (``OWNER_FILE``), None when it names none (not written yet)."""
    first = text.split()[:1]
    return int(first[0]) if first and first[0].isdigit() else None


def remove_stale_pty_dirs(tmp: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove ``drumtwin-mill-*`` directories in ``tmp`` (default: the temp directory)
    whose owner process is gone (a ``kill -9`` leaves them with a dangling pty link).
    A directory is only touched when it is ours (same uid), holds nothing but the link
    and the owner file, and its owner file names a dead process, or (older emulators
    wrote none) its link dangles. Returns the directories removed."""
    base = Path(tmp if tmp is not None else tempfile.gettempdir())
    removed: list[Path] = []
    for d in base.glob(PTY_DIR_PREFIX + "*"):
        try:
            if not d.is_dir() or d.is_symlink() or d.lstat().st_uid != os.getuid():
                continue
            names = {e.name for e in d.iterdir()}
            if not names <= {"mill", "mill.new", OWNER_FILE}:
                continue
            owner = d / OWNER_FILE
            text = owner.read_text(encoding="ascii", errors="replace").strip() if owner.exists() else ""
            pid = owner_pid(text)
            if pid is not None and pid > 0:
                if _owner_id(pid) == text:
                    continue  # its owner still runs
            elif (d / "mill").exists() or time.time() - d.lstat().st_mtime < 60.0:
                # no owner (or an owner file being written: it is created empty first): an old
                # emulator whose pty is alive, or one starting now
                continue
            for name in names:
                (d / name).unlink(missing_ok=True)
            d.rmdir()
            removed.append(d)
        except (OSError, ValueError):
            continue  # raced with its owner or another start: leave it
    return removed


class MillEmulator:
    """The board's firmware behind a real pty or TCP port, in a background thread."""

    def __init__(
        self,
        config: DeviceConfig | None = None,
        faults: Faults | None = None,
        *,
        seed: int | None = None,
        tick_s: float = 0.005,
    ) -> None:
        self.config = config or DeviceConfig()
        self.faults = faults or Faults()
        self.tick_s = tick_s
        self._rng = random.Random(seed)
        self._lock = threading.RLock()
        self._t0 = time.monotonic()
        self.device = MillDevice(self.config, now_s=0.0)
        self._kind: str | None = None
        self._link_path: Path | None = None
        self._tmpdir: tempfile.TemporaryDirectory[str] | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._host = "127.0.0.1"
        self._port = 0
        self._plugged = False
        self._pending: deque[tuple[float, bytes]] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._next_disconnect: float | None = None
        self._reconnect_at: float | None = None
        self.connections = 0
        self.slave_path: str | None = None

    # -- clock and state -----------------------------------------------------------------
    def now_s(self) -> float:
        return time.monotonic() - self._t0

    @property
    def motor(self) -> MotorState:
        """Thread-safe snapshot of the motor (``.actual_rpm``, ``.setpoint_rpm``, ...)."""
        with self._lock:
            self.device.tick(self.now_s())
            return self.device.motor.state()

    def status(self) -> MillStatus:
        with self._lock:
            self.device.tick(self.now_s())
            return self.device.status()

    def set_motor(
        self, *, setpoint_rpm: float | None = None, actual_rpm: float | None = None, running: bool | None = None
    ) -> MotorState:
        """The board's front panel: preset the motor (e.g. already spinning when a demo
        starts) without a command on the line. Not recorded in :attr:`applied`."""
        with self._lock:
            m = self.device.motor
            if setpoint_rpm is not None:
                m.setpoint_rpm = min(float(setpoint_rpm), m.config.max_rpm)
            if actual_rpm is not None:
                m.actual_rpm = min(max(float(actual_rpm), 0.0), m.config.max_rpm)
            if running is not None:
                m.running = bool(running)
                if running:
                    m.fault = None
                    self.device.feed_watchdog(self.now_s())
            return m.state()

    def set_drive_fault(self, active: bool = True) -> None:
        """The power stage reports a fault (``DRIVE``: motor stops, ``RUN`` is refused) or
        the fault was cleared on the board."""
        with self._lock:
            m = self.device.motor
            if active:
                m.fault, m.running = p.FAULT_DRIVE, False
            elif m.fault == p.FAULT_DRIVE:
                m.fault = None

    @property
    def applied(self) -> list[Applied]:
        """Copy of the state-changing commands applied so far."""
        with self._lock:
            return list(self.device.applied)

    @property
    def counters(self) -> dict[str, int]:
        with self._lock:
            return dict(self.device.counters)

    @property
    def url(self) -> str:
        """What ``MillClient``/``serial_for_url`` opens: the pty link or ``socket://``."""
        if self._kind == "pty":
            return str(self._link_path)
        if self._kind == "tcp":
            return f"socket://{self._host}:{self._port}"
        raise ControlError("the mill emulator is not open (call open_pty or open_tcp)")

    @property
    def plugged(self) -> bool:
        return self._plugged

    # -- opening ---------------------------------------------------------------------------
    def open_pty(self, link: str | os.PathLike[str] | None = None) -> str:
        """Open a pty; return a stable path (a symlink to the slave) the driver opens.

        The symlink survives :meth:`disconnect`/:meth:`reconnect` (a new pty each time),
        like a udev ``/dev/serial/by-id`` name for a re-plugged USB adapter.
        """
        if self._kind is not None:
            raise ControlError("the mill emulator is already open")
        if link is None:
            remove_stale_pty_dirs()  # the leftovers of emulators killed with -9
            self._tmpdir = tempfile.TemporaryDirectory(prefix=PTY_DIR_PREFIX)
            (Path(self._tmpdir.name) / OWNER_FILE).write_text(_owner_id(os.getpid()) or "", encoding="ascii")
            link = Path(self._tmpdir.name) / "mill"
        self._link_path = Path(link)
        self._kind = "pty"
        self._plug_pty()
        self._start_thread()
        return str(self._link_path)

    def open_tcp(self, port: int = 0, host: str = "127.0.0.1") -> int:
        """Listen on ``host:port`` (0 picks a free port); return the port."""
        if self._kind is not None:
            raise ControlError("the mill emulator is already open")
        self._host, self._port = host, port
        self._kind = "tcp"
        self._plug_tcp()
        self._start_thread()
        return self._port

    def _plug_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.slave_path = os.ttyname(slave)
        tmp = self._link_path.with_name(self._link_path.name + ".new")  # type: ignore[union-attr]
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        os.symlink(self.slave_path, tmp)
        os.replace(tmp, self._link_path)  # type: ignore[arg-type]
        self._plugged = True
        self.connections += 1

    def _plug_tcp(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self._host, self._port))
        except OSError as exc:
            s.close()
            raise ControlError(f"cannot listen on {self._host}:{self._port}: {exc.strerror}") from None
        s.listen(1)
        s.setblocking(False)
        self._port = s.getsockname()[1]
        self._listener = s
        self._plugged = True

    def _start_thread(self) -> None:
        if self.faults.disconnect_every_s:
            self._next_disconnect = self.now_s() + self.faults.disconnect_every_s
        self._thread = threading.Thread(target=self._run, name="mill-emulator", daemon=True)
        self._thread.start()

    # -- unplug / replug -------------------------------------------------------------------
    def disconnect(self) -> None:
        """Unplug: close the pty (the driver's port errors) or drop the TCP connection
        and stop listening. The motor keeps running; its watchdog will stop it."""
        with self._lock:
            self._unplug()

    def reconnect(self) -> None:
        """Plug back in: a new pty behind the same link path, or listen on the same port."""
        with self._lock:
            if self._plugged:
                return
            if self._kind == "pty":
                self._plug_pty()
            elif self._kind == "tcp":
                self._plug_tcp()
            self.device.decoder = type(self.device.decoder)()

    def drop_client(self) -> None:
        """TCP only: close the current connection but keep listening (a dropped link)."""
        with self._lock:
            if self._client is not None:
                self._client.close()
                self._client = None

    def _unplug(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
        if self._kind == "pty" and self._link_path is not None:
            try:
                self._link_path.unlink()
            except FileNotFoundError:
                pass
        for s in (self._client, self._listener):
            if s is not None:
                s.close()
        self._client = self._listener = None
        self._pending.clear()
        self._plugged = False

    def close(self) -> None:
        """Stop the thread and release the pty/socket (idempotent)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(2.0)
        with self._lock:
            self._unplug()
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None

    def __enter__(self) -> MillEmulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the loop --------------------------------------------------------------------------
    def _mangle(self, data: bytes) -> bytes:
        f = self.faults
        if not data or (f.drop_p <= 0 and f.corrupt_p <= 0):
            return data
        out = bytearray()
        for b in data:
            if f.drop_p and self._rng.random() < f.drop_p:
                continue
            if f.corrupt_p and self._rng.random() < f.corrupt_p:
                b ^= self._rng.randrange(1, 256)
            out.append(b)
        return bytes(out)

    def _read_fds(self) -> list[Any]:
        fds: list[Any] = []
        if self._master is not None:
            fds.append(self._master)
        if self._listener is not None:
            fds.append(self._listener)
        if self._client is not None:
            fds.append(self._client)
        return fds

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                fds = self._read_fds()
            try:
                ready = select.select(fds, [], [], self.tick_s)[0] if fds else []
            except (OSError, ValueError):  # an fd closed under us by disconnect()
                ready = []
            if not fds:
                self._stop.wait(self.tick_s)
            with self._lock:
                now = self.now_s()
                for r in ready:
                    self._service(r, now)
                self._flush(now)
                self.device.tick(now)
                self._scheduled_faults(now)

    def _service(self, r: object, now: float) -> None:
        data = b""
        if r is self._listener and self._listener is not None:
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return
            if self._client is not None:  # one host at a time: the newest wins
                self._client.close()
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client = conn
            self.connections += 1
            self.device.decoder = type(self.device.decoder)()
            return
        if r is self._client and self._client is not None:
            try:
                data = self._client.recv(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:  # host closed the connection
                self._client.close()
                self._client = None
                return
        elif r == self._master and self._master is not None:
            try:
                data = os.read(self._master, 4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
        else:
            return
        reply = self.device.receive(self._mangle(data), now)
        if reply:
            self._pending.append((now + self.faults.delay_s, self._mangle(reply)))

    def _flush(self, now: float) -> None:
        while self._pending and self._pending[0][0] <= now:
            _, data = self._pending.popleft()
            self._write(data)

    def _write(self, data: bytes) -> None:
        if not data:
            return
        try:
            if self._master is not None:
                os.write(self._master, data)
            elif self._client is not None:
                self._client.sendall(data)
        except (BlockingIOError, InterruptedError):
            pass  # nobody reading the line: the bytes are lost, as on a real UART
        except OSError:
            if self._client is not None:
                self._client.close()
                self._client = None

    def _scheduled_faults(self, now: float) -> None:
        f = self.faults
        if self._next_disconnect is not None and now >= self._next_disconnect and self._plugged:
            self._unplug()
            self._reconnect_at = now + f.disconnect_for_s
            self._next_disconnect = None
        if self._reconnect_at is not None and now >= self._reconnect_at:
            self._reconnect_at = None
            self.reconnect()
            if f.disconnect_every_s:
                self._next_disconnect = now + f.disconnect_every_s

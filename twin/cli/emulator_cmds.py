"""``drumtwin mill-emulator``: the motor board's emulator (line protocol) or a drive's
(``--modbus PROFILE``) on a pty or a TCP port, until Ctrl-C, SIGTERM or ``--duration``."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable

import typer

from control.device import DeviceConfig
from control.emulator import Faults, MillEmulator
from control.errors import ControlError, check_number
from control.motor import MotorConfig
from twin.cli.app import app, say


@app.command("mill-emulator")
def mill_emulator(
    pty: bool = typer.Option(False, "--pty", help="Serve on a pseudo-terminal (default)."),
    tcp: int | None = typer.Option(None, "--tcp", help="Serve on this TCP port instead (0: any free port)."),
    host: str = typer.Option("127.0.0.1", "--host", help="TCP address to listen on."),
    link: str | None = typer.Option(None, "--link", help="Path of the stable symlink to the pty slave."),
    faults: str = typer.Option("", "--faults", help="e.g. 'corrupt=0.05,drop=0.01,delay=0.02,disconnect=10:1'."),
    watchdog_s: float = typer.Option(
        1.0, "--watchdog", help="Stop the motor after this long without HB/SET/RUN/STP (s; 0 disables it)."
    ),
    max_rpm: float = typer.Option(60.0, "--max-rpm", help="Top speed of the drive (rpm)."),
    accel: float = typer.Option(10.0, "--accel", help="Acceleration limit (rpm/s)."),
    tau_s: float = typer.Option(0.5, "--tau", help="Speed-loop time constant (s)."),
    duration_s: float | None = typer.Option(None, "--duration", help="Exit after this many seconds (default: Ctrl-C)."),
    seed: int | None = typer.Option(None, "--seed", help="Seed of the fault injection."),
    modbus: str | None = typer.Option(
        None, "--modbus", help="Emulate this drive profile over Modbus RTU instead (delta-ms300, abb-acs, ...)."
    ),
    unit: int = typer.Option(1, "--unit", help="--modbus: the drive's unit id (1..247)."),
    comm_loss_s: float = typer.Option(
        2.0, "--comm-loss", help="--modbus: comm-loss trip time (s; 0 disables it, to test the refusal)."
    ),
) -> None:
    """Run the motor-board emulator on a pty (prints its path) or a TCP port; with
    --modbus PROFILE a frequency inverter's emulator (prints its modbus: URL)."""
    _check_emulator_options(tcp, host, link, unit, comm_loss_s, seed)
    if modbus is not None:
        _drive_emulator(modbus, unit, comm_loss_s, tcp, link, faults, duration_s, seed)
        return
    if pty and tcp is not None:
        raise ControlError("choose one of --pty and --tcp")
    if tcp is not None and not 0 <= tcp <= 65535:
        raise ControlError(f"--tcp must be a port in 0..65535 (0: any free port), got {tcp}")
    check_number("--watchdog", watchdog_s, at_least=0.0, at_most=3600.0)
    check_number("--max-rpm", max_rpm, above=0.0, at_most=1000.0)
    check_number("--accel", accel, above=0.0, at_most=1e4)
    check_number("--tau", tau_s, at_least=0.0, at_most=60.0)
    if duration_s is not None:
        check_number("--duration", duration_s, above=0.0, at_most=30 * 86400.0)  # 1e308 would never end
    cfg = DeviceConfig(watchdog_s=watchdog_s, motor=MotorConfig(max_rpm=max_rpm, accel_rpm_per_s=accel, tau_s=tau_s))
    emu = MillEmulator(cfg, Faults.parse(faults), seed=seed)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())  # before the path is printed: clean exit
    try:
        if tcp is not None:
            emu.open_tcp(tcp, host)
        else:
            emu.open_pty(link)
        print(emu.url, flush=True)
        say(f"mill emulator on {emu.url} (watchdog {watchdog_s:g} s); Ctrl-C to stop")

        def board() -> tuple[object, str]:
            st = emu.status()
            return ((round(st.setpoint_rpm, 1), round(st.actual_rpm, 1), st.running, st.fault),
                    f"setpoint {st.setpoint_rpm:6.2f}  actual {st.actual_rpm:6.2f} rpm  "
                    f"{'running' if st.running else 'stopped'}  fault {st.fault or 'none'}")

        _report_until(done, duration_s, 0.5, board)
    finally:
        emu.close()


def _report_until(done: threading.Event, duration_s: float | None, period_s: float,
                  state: Callable[[], tuple[object, str]]) -> None:
    """Say the emulator's state line whenever its key changes, every ``period_s``, until
    ``done`` (SIGTERM), Ctrl-C or ``duration_s``."""
    t_end = None if duration_s is None else time.monotonic() + duration_s
    last = None
    try:
        while not done.is_set() and (t_end is None or time.monotonic() < t_end):
            key, text = state()
            if key != last:
                say(text)
                last = key
            done.wait(period_s)
    except KeyboardInterrupt:
        pass


def _check_emulator_options(tcp: int | None, host: str, link: str | None, unit: int, comm_loss_s: float,
                            seed: int | None) -> None:
    """``mill-emulator``'s options that both emulators share, checked before anything opens
    (one-line ControlError/TwinError): an option that does not apply is refused, not ignored."""
    from twin.config import check_host

    if tcp is not None and not 0 <= tcp <= 65535:
        raise ControlError(f"--tcp must be a port in 0..65535 (0: any free port), got {tcp}")
    check_host(host)
    if link is not None and tcp is not None:
        raise ControlError("--link names the pty's symlink: not with --tcp")
    if not 1 <= unit <= 247:
        raise ControlError(f"--unit must be in 1..247 (got {unit})")
    check_number("--comm-loss", comm_loss_s, at_least=0.0, at_most=600.0)
    if seed is not None and not 0 <= seed < 2**32:
        raise ControlError(f"--seed must be in 0..{2**32 - 1} (got {seed})")


def _drive_emulator(profile: str, unit: int, comm_loss_s: float, tcp: int | None, link: str | None,
                    faults: str, duration_s: float | None, seed: int | None) -> None:
    """``mill-emulator --modbus``: a drive emulator until Ctrl-C / SIGTERM / --duration."""
    from control.modbus.emulator import DriveEmulator, DriveFaults
    from control.modbus.profile import load_profile

    if tcp is not None and not 0 <= tcp <= 65535:
        raise ControlError(f"--tcp must be a port in 0..65535 (0: any free port), got {tcp}")
    if not 1 <= unit <= 247:
        raise ControlError(f"--unit must be in 1..247 (got {unit})")
    check_number("--comm-loss", comm_loss_s, at_least=0.0, at_most=600.0)
    f = DriveFaults()
    for item in filter(None, (x.strip() for x in faults.split(","))):
        key, _, val = item.partition("=")
        try:
            if key == "delay":
                f.delay_s = check_number("fault delay", float(val), at_least=0.0, at_most=60.0)
            elif key == "corrupt":
                f.corrupt_p = check_number("fault corrupt", float(val), at_least=0.0, at_most=1.0)
            elif key == "mute":
                f.mute = True
            else:
                raise ControlError(f"unknown drive fault {key!r} (use delay=S, corrupt=P, mute)")
        except ValueError as exc:
            raise exc if isinstance(exc, ControlError) else ControlError(f"bad fault value in {item!r}") from None
    emu = DriveEmulator(load_profile(profile), unit=unit, comm_loss_s=comm_loss_s, faults=f, seed=seed)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    try:
        if tcp is not None:
            emu.open_tcp(tcp)
        else:
            emu.open_pty(link)
        print(emu.mill_url(), flush=True)
        say(f"{emu.profile.title} emulator, unit {unit}, on {emu.url} (comm-loss trip "
            f"{emu.model.comm_loss_time_s():g} s); Ctrl-C to stop")

        def drive() -> tuple[object, str]:
            m, hz = emu.motor, emu.output_hz
            return ((round(hz, 1), m.running, m.fault),
                    f"output {hz:6.2f} Hz  {'running' if m.running else 'stopped'}  fault {m.fault or 'none'}")

        _report_until(done, duration_s, 0.25, drive)
    finally:
        emu.close()

"""The embedded demo's hidden plant: a second ``DrumSim`` with parameters the twin
does not know, filmed by sim's synthetic camera with realism (noise, blur, glare,
lighting drift), whose drum follows the motor of an in-process mill emulator on a
pty. The loop sees only what a real installation gives it: frames and a serial port.

Time: the plant's camera is paced by a ``RunClock`` (``--speed``); the emulator's
motor model is sped up by the same factor (acceleration x speed, lag / speed) so the
drive behaves in run time as it would in real time. Its watchdog stays in wall time.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import dataclass

from control.device import DeviceConfig
from control.emulator import MillEmulator
from control.limits import simulated_rpm
from control.modbus.emulator import DriveEmulator
from control.modbus.profile import load_profile
from control.motor import MotorConfig
from sim.drum import DrumSim
from sim.mixer import paper_mixer
from sim.render import Realism, Renderer
from twin.clock import RunClock
from vision.sources import Frame

# The plant differs from the twin's defaults: the twin must calibrate to it.
PLANT_FRICTION = 0.30  # the twin starts from sim.params.DEFAULT_FRICTION (0.25)
PLANT_ROLLING = 0.05  # twin default 0.0: this plant segregates within a minute at 5 rpm
PLANT_SEED_OFFSET = 1000


@dataclass(frozen=True)
class PlantConfig:
    """Hidden plant settings (run time units)."""

    case: str = "C"
    seed: int = 0
    start_rpm: float = 5.0
    fps: float = 10.0  # camera frames per second of run time
    size_px: int = 240
    friction: float = PLANT_FRICTION
    rolling: float = PLANT_ROLLING
    realism: bool = True
    watchdog_s: float = 5.0  # emulator watchdog, wall seconds (a busy machine may stall the loop for seconds)
    drive: str | None = None  # a drive profile: the mill is that inverter's emulator over Modbus RTU


class DemoPlant:
    """Hidden plant + mill emulator. ``frames()`` is the camera; ``url`` the serial port.

    Fault hooks for tests and the dashboard: ``camera_paused`` (no frames while set),
    ``emulator.disconnect()`` / ``emulator.reconnect()`` (unplug the serial cable).
    """

    def __init__(self, config: PlantConfig, clock: RunClock) -> None:
        self.config = config
        self.clock = clock
        speed = clock.speed
        motor = MotorConfig()
        motor = MotorConfig(
            max_rpm=motor.max_rpm, accel_rpm_per_s=motor.accel_rpm_per_s * speed, tau_s=motor.tau_s / speed
        )
        self.emulator: MillEmulator | DriveEmulator
        if config.drive is not None:  # a frequency inverter on Modbus RTU, its comm-loss trip the watchdog
            self.emulator = DriveEmulator(load_profile(config.drive), comm_loss_s=config.watchdog_s, speed=speed)
            self.emulator.open_pty()
            self.url = self.emulator.mill_url()
        else:
            self.emulator = MillEmulator(DeviceConfig(watchdog_s=config.watchdog_s, motor=motor), seed=config.seed)
            self.url = self.emulator.open_pty()
        self.emulator.set_motor(setpoint_rpm=float(config.start_rpm), actual_rpm=0.0, running=False)
        self.sim = DrumSim(
            mixer=paper_mixer(),  # the demo's plant: the paper's drum and bed
            case=config.case,
            seed=config.seed + PLANT_SEED_OFFSET,
            rpm=config.start_rpm,
            friction=config.friction,
            rolling=config.rolling,
        )
        self.renderer = Renderer(self.sim.drum, config.size_px, realism=_realism(config))
        self.camera_paused = threading.Event()
        self.frames_rendered = 0

    def start_drive(self) -> None:
        """The front panel: the drive spins at the start speed when the demo begins (as a
        real one would be). A run keeps only a mill it commanded alive, so the demo's
        operator then presses Start in the loop (``drumtwin run`` does both)."""
        start = float(self.config.start_rpm)
        self.emulator.set_motor(setpoint_rpm=start, actual_rpm=start, running=True)

    @property
    def roi(self):
        """The drum ROI in the plant camera's frames (vision ``DrumROI``)."""
        return self.renderer.roi

    def frames(self) -> Iterator[Frame]:
        """Camera frames paced by the run clock; the drum follows the emulator's motor.

        While ``camera_paused`` is set no frames come (a stalled camera); the plant
        keeps turning. Ends when the clock's stop event is set.
        """
        fps = self.config.fps
        k = 0
        while True:
            t = k / fps
            if not self.clock.sleep_until(t):
                return
            rpm = float(self.emulator.motor.actual_rpm)
            self.sim.set_rpm(simulated_rpm(rpm, self.sim.critical_rpm))  # the one cap (control.limits)
            dt = t - self.sim.t_s
            if dt > 0:
                self.sim.step(dt)
            k += 1
            if self.camera_paused.is_set():
                continue
            image = self.renderer.render(self.sim.particles(), t)
            if image is None:  # the synthetic camera dropped this frame
                continue
            self.frames_rendered += 1
            yield Frame(index=k - 1, t_s=t, image=image)

    def close(self) -> None:
        self.emulator.close()


def _realism(config: PlantConfig) -> Realism | None:
    """sim's realism settings for the plant camera (seeded), or None."""
    return Realism(seed=config.seed) if config.realism else None


__all__ = ["PLANT_FRICTION", "PLANT_ROLLING", "DemoPlant", "PlantConfig"]

"""Stand-ins for the loop around a dashboard in the dashboard tests: controls that record every call,
and a feeder that publishes a moving frame, a twin and plot points at 20 Hz."""

from __future__ import annotations

import threading

import numpy as np

from sim.twin_base import Particles
from twin.records import FrameReading
from twin.state import LiveState


class RecordingControls:
    """Stands in for the loop: records every call."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple]] = []
        self.lock = threading.Lock()

    def _rec(self, name: str, *args: object) -> None:
        with self.lock:
            self.calls.append((name, args))

    def names(self) -> list[str]:
        with self.lock:
            return [c[0] for c in self.calls]

    def args_of(self, name: str) -> list[tuple]:
        with self.lock:
            return [a for n, a in self.calls if n == name]

    def set_mode(self, mode: str) -> None:
        self._rec("set_mode", mode)

    def set_manual_rpm(self, rpm: float) -> None:
        self._rec("set_manual_rpm", rpm)

    def start_mill(self) -> None:
        self._rec("start_mill")

    def stop_mill(self) -> None:
        self._rec("stop_mill")

    def emergency_stop(self) -> None:
        self._rec("emergency_stop")

    def recalibrate(self) -> None:
        self._rec("recalibrate")

    def reseed_twin(self) -> None:
        self._rec("reseed_twin")

    def run_whatif(self, rpms, duration_s) -> None:
        self._rec("run_whatif", tuple(rpms), duration_s)

    def cancel_whatif(self) -> bool:
        self._rec("cancel_whatif")
        return False

    def relearn_classes(self) -> str:
        self._rec("relearn_classes")
        return "re-learning the classes from the live bed ..."


class Feeder:
    """Publishes a moving frame and plot points at 20 Hz until stopped."""

    def __init__(self, state: LiveState) -> None:
        self.state = state
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self) -> None:
        i = 0
        while not self.stop.is_set():
            img = np.zeros((120, 120, 3), np.uint8)
            img[:, (i * 3) % 120] = (0, 0, 255)
            self.state.publish_camera(img)
            a = np.linspace(0, 2 * np.pi, 12, endpoint=False) + 0.1 * i
            disks = Particles(0.1 * np.cos(a), 0.1 * np.sin(a), np.full(12, 0.01), np.arange(12) % 2,
                              class_bgr=((0, 0, 220), (220, 60, 0)))
            self.state.publish_twin(img[:, ::-1].copy(), disks, 0.15)
            t = i * 0.05
            self.state.record(FrameReading(
                t_s=t, frame=i, mi=0.8 + 0.1 * np.sin(t), mi_sigmoid=0.8, mi_linear=0.8, d_px=3.0, dsigma_px=1.0,
                concentration=0.5, slope_deg=30.0, valid=True, trend_mi=0.8, trend_lo95=0.7, trend_hi95=0.9,
                trend_rate=0.0, ma_mi=0.8, twin_mi=None, twin_slope_deg=31.0, rpm_setpoint=5.0, rpm_actual=5.0,
                mode="auto", flags=(),
            ))
            i += 1
            self.stop.wait(0.05)

    def __enter__(self) -> Feeder:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(2)

"""The twin's particles in the dashboard's 3D scene: a round point per disk inside the drum rim.

Coordinates are the twin's drum frame in metres (x right, y up, z towards the viewer);
the scene's up direction is +y and the initial camera looks at the drum face-on.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import viser

if TYPE_CHECKING:
    from sim.drum import Particles

__all__ = ["TwinScene", "ring_segments"]

_RIM_RGB = (150, 150, 150)
_FALLBACK_RGB = ((220, 0, 0), (0, 60, 220))


def ring_segments(r_m: float, n: int = 96) -> np.ndarray:
    """A circle of radius ``r_m`` in the z = 0 plane as ``n`` line segments, shape (n, 2, 3)."""
    a = np.linspace(0.0, 2 * math.pi, n + 1)
    pts = np.stack([r_m * np.cos(a), r_m * np.sin(a), np.zeros_like(a)], axis=1).astype(np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


class TwinScene:
    """Handles of the twin in a viser scene; ``update`` moves the disks to the newest state.

    Each particle class is one point cloud of round points sized to the class's diameter:
    the twin is a 2D slice, so flat disks are what it is, and a point cloud costs a
    software-GL browser a fraction of what shaded sphere meshes do (the dashboard keeps
    its 10 Hz where there is no GPU).
    """

    def __init__(self, server: viser.ViserServer) -> None:
        self._scene = server.scene
        self._scene.set_up_direction("+y")
        cam = server.initial_camera
        cam.position, cam.look_at, cam.up = (0.0, 0.0, 0.62), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)
        self._clouds: dict[int, viser.PointCloudHandle] = {}
        self._rim_r_m: float | None = None
        self._cls: np.ndarray | None = None
        self.updates = 0

    @property
    def clouds(self) -> dict[int, viser.PointCloudHandle]:
        """The point cloud of each particle class index (empty before the first update)."""
        return dict(self._clouds)

    def update(self, particles: Particles, drum_r_m: float) -> None:
        """Show ``particles`` (drum frame, m) inside a rim of radius ``drum_r_m`` (m)."""
        if drum_r_m != self._rim_r_m:
            self._scene.add_line_segments("/twin/rim", ring_segments(drum_r_m), _RIM_RGB, thickness=0.008)
            self._scene.add_label("/twin/label", "twin (particles, live)", position=(-drum_r_m, drum_r_m * 1.12, 0.0))
            self._rim_r_m = drum_r_m
        cls = np.asarray(particles.cls)
        pos = np.zeros((len(particles), 3), np.float32)
        pos[:, 0], pos[:, 1] = particles.x_m, particles.y_m
        if self._cls is None or not np.array_equal(cls, self._cls):  # new bed (re-seed): new clouds
            for h in self._clouds.values():
                h.remove()
            self._clouds = {}
            palette = particles.class_bgr or tuple(c[::-1] for c in _FALLBACK_RGB)
            r_m = np.asarray(particles.r_m)
            for k in np.unique(cls).tolist():
                sel = cls == k
                rgb = np.array(palette[k % len(palette)][::-1], np.uint8)
                # viser draws 2 x point_size across: the mean radius gives the mean diameter
                self._clouds[k] = self._scene.add_point_cloud(
                    f"/twin/particles/{k}", pos[sel], rgb, point_size=float(r_m[sel].mean()),
                    point_shape="circle", point_shading="flat", precision="float32",
                )
            self._cls = cls.copy()
        else:
            for k, h in self._clouds.items():
                h.points = pos[cls == k]
        self.updates += 1

"""The twin's particles in the dashboard's 3D scene: a round point per disk inside the drum rim,
a shaped particle's outline (``Particles.class_outline_m``, turned by its angle) as line
segments, and the drum's baffles (``Particles.baffles_m``) as closed polylines in the rim's grey.

Coordinates are the twin's drum frame in metres (x right, y up, z towards the viewer);
the scene's up direction is +y and the initial camera looks at the drum face-on.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import viser

if TYPE_CHECKING:
    from sim.twin_base import Particles

__all__ = ["TwinScene", "outline_segments", "polygon_segments", "ring_segments"]

_RIM_RGB = (150, 150, 150)
_FALLBACK_RGB = ((220, 0, 0), (0, 60, 220))


def ring_segments(r_m: float, n: int = 96) -> np.ndarray:
    """A circle of radius ``r_m`` in the z = 0 plane as ``n`` line segments, shape (n, 2, 3)."""
    a = np.linspace(0.0, 2 * math.pi, n + 1)
    pts = np.stack([r_m * np.cos(a), r_m * np.sin(a), np.zeros_like(a)], axis=1).astype(np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def polygon_segments(polygons: list[np.ndarray] | tuple[np.ndarray, ...]) -> np.ndarray:
    """Closed polygons (each (k, 2), m) in the z = 0 plane as line segments, shape (sum k, 2, 3)."""
    segs = []
    for p in polygons:
        p = np.asarray(p, dtype=np.float32).reshape(-1, 2)
        a = np.column_stack([p, np.zeros(len(p), np.float32)])
        segs.append(np.stack([a, np.roll(a, -1, axis=0)], axis=1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3), np.float32)


def outline_segments(x_m: np.ndarray, y_m: np.ndarray, angle_rad: np.ndarray | None,
                     outline_m: np.ndarray) -> np.ndarray:
    """The outline (k, 2, m, about the centroid) of each particle at (x, y) turned by its angle, as
    line segments in the z = 0 plane, shape (n * k, 2, 3)."""
    n = len(x_m)
    ang = np.zeros(n) if angle_rad is None else np.asarray(angle_rad, dtype=float)
    c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
    o = np.asarray(outline_m, dtype=float)
    px = np.asarray(x_m, dtype=float)[:, None] + c * o[None, :, 0] - s * o[None, :, 1]
    py = np.asarray(y_m, dtype=float)[:, None] + s * o[None, :, 0] + c * o[None, :, 1]
    return polygon_segments([np.column_stack([px[i], py[i]]) for i in range(n)])


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
        self._draw_shapes(particles)
        self.updates += 1

    def _draw_shapes(self, particles: Particles) -> None:
        """Shaped classes as outlines (their point cloud hidden) and the baffles, redrawn each update."""
        outlines = getattr(particles, "class_outline_m", ()) or ()
        palette = particles.class_bgr or tuple(c[::-1] for c in _FALLBACK_RGB)
        cls = np.asarray(particles.cls)
        for k, outline in enumerate(outlines):
            if outline is None:
                continue
            sel = cls == k
            if k in self._clouds:
                self._clouds[k].visible = False
            ang = None if particles.angle_rad is None else np.asarray(particles.angle_rad)[sel]
            segs = outline_segments(np.asarray(particles.x_m)[sel], np.asarray(particles.y_m)[sel], ang,
                                    np.asarray(outline))
            rgb = np.array(palette[k % len(palette)][::-1], np.uint8)
            self._scene.add_line_segments(f"/twin/shapes/{k}", segs, rgb, thickness=0.002)
        baffles = getattr(particles, "baffles_m", ()) or ()
        if baffles:
            self._scene.add_line_segments("/twin/baffles", polygon_segments(baffles), _RIM_RGB, thickness=0.006)

"""The synthetic camera: the twin's front view as a BGR frame, optionally with camera realism.

Clean frames: dark background, grey drum rim (and the baffles in the rim's grey), every disk
filled with its class colour (a shaped particle: its outline turned by its angle, filled)
(red about BGR (0, 0, 220), blue about BGR (220, 60, 0), which
``vision.colours.DEFAULT_CLASSES`` catch). ``Renderer.roi`` is the exact drum ROI
in the image, so a ``vision.meter.Meter`` needs no drum detection.

Realism (for the demo "plant"): a lighting gradient that drifts slowly, specular
glare spots on the acrylic, a slight perspective tilt, defocus blur, sensor
noise, JPEG artefacts and dropped frames -- each seeded and switchable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from sim.drum import DrumSim
from sim.errors import SimError
from sim.recipe import DrumSpec
from sim.twin_base import Particles

if TYPE_CHECKING:
    from sim.pymunk_twin import PymunkDrumSim

BACKGROUND_BGR = (22, 20, 18)
INSIDE_BGR = (34, 30, 28)
RIM_BGR = (150, 150, 150)
_SHIFT = 3  # sub-pixel bits for cv2.circle
DRAW_INSET_PX = 0.3  # OpenCV's filled circles and polygons reach 0.3-0.5 px past their outline: each particle
# is drawn this much smaller, so it covers its own area (a 36 px disc drawn as is covered 4 % more)
_MARGIN = 0.06  # fraction of the image left around the rim


@dataclass(frozen=True)
class Realism:
    """Camera imperfections of the synthetic camera (all amplitudes in 8-bit grey levels or px)."""

    noise_sd: float = 5.0  # sensor noise, grey levels
    blur_px: float = 1.2  # Gaussian defocus sigma, px
    gradient: float = 0.30  # lighting falloff across the image (0 = flat)
    drift_period_s: float = 40.0  # the lighting gradient turns and breathes with this period
    drift_amp: float = 0.12  # brightness breathing amplitude (fraction)
    glare: int = 2  # specular glare spots on the acrylic
    perspective: float = 0.03  # keystone: top edge shrinks by this fraction
    jpeg_quality: int = 75  # 0 = no JPEG round trip
    drop_prob: float = 0.02  # probability a frame is dropped (render returns None)
    seed: int = 0


def size_for_radius(r_px: float, rim_px: int) -> int:
    """The square frame size (px) whose drum is ``r_px`` in radius inside a rim of ``rim_px``: a twin
    rendered at a camera's scale (its particles as many pixels across as the camera sees them)."""
    return int(round(2.0 * (float(r_px) + rim_px) / (1.0 - 2.0 * _MARGIN)))


class Renderer:
    """Front view of a drum to ``size_px`` images (int = square, or (width, height)); ``rim_px`` the
    drum rim's width (None: 3.5 % of the image, the dashboard's bold rim; a camera sees a thin one)."""

    def __init__(
        self, drum: DrumSpec | DrumSim | PymunkDrumSim, size_px: int | tuple[int, int] = 480,
        realism: Realism | None = None, rim_px: int | None = None,
    ) -> None:
        spec = drum if isinstance(drum, DrumSpec) else getattr(drum, "drum", None)  # a DrumSpec, or any twin's
        if not isinstance(spec, DrumSpec):
            raise SimError(f"Renderer needs a DrumSpec or a twin (got {type(drum).__name__})")
        if isinstance(size_px, (int, np.integer)):
            w = h = int(size_px)
        else:
            w, h = (int(v) for v in size_px)
        if w < 32 or h < 32 or w > 8192 or h > 8192:
            raise SimError(f"image size must be 32..8192 px (got {w}x{h})")
        self.drum = spec
        self.width_px, self.height_px = w, h
        self.rim_px = max(2, int(round(0.035 * min(w, h))) if rim_px is None else int(rim_px))
        self.r_px = (min(w, h) * (1.0 - 2 * _MARGIN)) / 2.0 - self.rim_px
        self.cx_px = (w - 1) / 2.0
        self.cy_px = (h - 1) / 2.0
        self.px_per_m = self.r_px / spec.radius_m
        self.realism = realism
        self._base = np.empty((h, w, 3), np.uint8)
        self._base[:] = BACKGROUND_BGR
        c = (int(round(self.cx_px)), int(round(self.cy_px)))
        cv2.circle(self._base, c, int(round(self.r_px + self.rim_px / 2)), RIM_BGR, self.rim_px, cv2.LINE_AA)
        cv2.circle(self._base, c, int(round(self.r_px)), INSIDE_BGR, -1, cv2.LINE_AA)
        self._img = np.empty_like(self._base)
        self._rng = np.random.default_rng(realism.seed if realism else 0)
        self._frame_no = 0
        if realism is not None:
            self._prepare_realism(realism)

    @property
    def roi(self):
        """The drum's ROI in the image, as a ``vision.roi.DrumROI`` (circle, inner rim).

        With a perspective (keystone) warp it is the circle through the warped rim's
        left, right, top and bottom points (the drum is then very slightly elliptical).
        """
        from vision.roi import DrumROI

        warp = getattr(self, "_warp", None)
        if warp is None:
            return DrumROI(self.cx_px, self.cy_px, self.r_px)
        pts = np.float32([[[self.cx_px + dx * self.r_px, self.cy_px + dy * self.r_px]]
                          for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1))])
        q = cv2.perspectiveTransform(pts, warp).reshape(-1, 2)
        cx = float((q[0, 0] + q[1, 0]) / 2)
        cy = float((q[2, 1] + q[3, 1]) / 2)
        r = float(np.mean(np.hypot(q[:, 0] - cx, q[:, 1] - cy)))
        return DrumROI(cx, cy, r)

    def to_px(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image coordinates (px, y down) of drum-frame points (m, y up)."""
        return self.cx_px + x_m * self.px_per_m, self.cy_px - y_m * self.px_per_m

    def render(self, particles: Particles, t_s: float | None = None) -> np.ndarray | None:
        """BGR frame of ``particles`` (a new array). With realism, a dropped frame gives None."""
        img = self._img
        np.copyto(img, self._base)
        xs = np.rint((self.cx_px + particles.x_m * self.px_per_m) * (1 << _SHIFT)).astype(np.int64)
        ys = np.rint((self.cy_px - particles.y_m * self.px_per_m) * (1 << _SHIFT)).astype(np.int64)
        rs = np.maximum(np.rint((particles.r_m * self.px_per_m - DRAW_INSET_PX) * (1 << _SHIFT)).astype(np.int64),
                        1 << _SHIFT)
        colours = [tuple(int(v) for v in c) for c in particles.class_bgr] or [(0, 0, 220), (220, 60, 0)]
        outlines = particles.class_outline_m
        shaped = np.zeros(len(particles), dtype=bool)
        for k, outline in enumerate(outlines):
            if outline is None:
                continue
            m = particles.cls == k
            shaped |= m
            if np.any(m):
                polys = self._outlines_px(particles, m, np.asarray(outline))
                cv2.fillPoly(img, list(polys), colours[k % len(colours)], cv2.LINE_8, _SHIFT)
        if shaped.any():
            keep = ~shaped
            xs, ys, rs, cls = xs[keep], ys[keep], rs[keep], particles.cls[keep]
        else:
            cls = particles.cls
        for x, y, r, k in zip(xs.tolist(), ys.tolist(), rs.tolist(), cls.tolist(), strict=False):
            cv2.circle(img, (x, y), r, colours[k % len(colours)], -1, cv2.LINE_8, _SHIFT)
        if particles.baffles_m:
            cv2.fillPoly(img, [self._poly_px(b) for b in particles.baffles_m], RIM_BGR, cv2.LINE_8, _SHIFT)
        out = img.copy()
        if self.realism is None:
            return out
        return self._degrade(out, self._frame_no / 30.0 if t_s is None else float(t_s))

    def _poly_px(self, poly_m: np.ndarray) -> np.ndarray:
        """A drum-frame polygon (k, 2) in m as fixed-point image points (``_SHIFT`` bits), int32."""
        x, y = self.to_px(poly_m[:, 0], poly_m[:, 1])
        return np.rint(np.stack([x, y], axis=-1) * (1 << _SHIFT)).astype(np.int32)

    def _outlines_px(self, particles: Particles, mask: np.ndarray, outline_m: np.ndarray) -> np.ndarray:
        """The outline turned by each selected particle's angle about its centre: (n, k, 2) fixed-point px."""
        ang = particles.angle_rad[mask] if particles.angle_rad is not None else np.zeros(int(mask.sum()))
        c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
        reach = float(np.max(np.hypot(outline_m[:, 0], outline_m[:, 1]))) * self.px_per_m
        shrink = max(reach - DRAW_INSET_PX, 0.5) / reach if reach > 0 else 1.0  # drawn at its own area (DRAW_INSET_PX)
        ox, oy = shrink * outline_m[None, :, 0], shrink * outline_m[None, :, 1]
        x_m = particles.x_m[mask][:, None] + c * ox - s * oy
        y_m = particles.y_m[mask][:, None] + s * ox + c * oy
        x, y = self.to_px(x_m, y_m)
        return np.rint(np.stack([x, y], axis=-1) * (1 << _SHIFT)).astype(np.int32)

    # ------------------------------------------------------------- realism
    def _prepare_realism(self, rz: Realism) -> None:
        h, w = self.height_px, self.width_px
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        self._xx = (xx - w / 2) / w
        self._yy = (yy - h / 2) / h
        self._glare = np.zeros((h, w), np.float32)
        for _ in range(max(0, int(rz.glare))):
            ang = self._rng.uniform(0, 2 * math.pi)
            rad = self._rng.uniform(0.3, 0.8) * self.r_px
            gx, gy = self.cx_px + rad * math.cos(ang), self.cy_px + rad * math.sin(ang)
            sx, sy = self._rng.uniform(0.02, 0.05) * w, self._rng.uniform(0.01, 0.03) * h
            self._glare += np.exp(-(((xx - gx) / sx) ** 2 + ((yy - gy) / sy) ** 2)).astype(np.float32)
        self._glare = np.clip(self._glare, 0, 1) * 170.0
        self._glare3 = cv2.merge([self._glare] * 3)
        # a bank of sensor-noise frames, picked at random per frame (cheaper than drawing each frame)
        self._noise = [self._rng.normal(0.0, rz.noise_sd, size=(h, w, 3)).astype(np.float32)
                       for _ in range(8)] if rz.noise_sd > 0 else []
        d = rz.perspective * w / 2
        src = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float32)
        dst = np.array([[d, 0], [w - 1 - d, 0], [w - 1, h - 1], [0, h - 1]], np.float32)
        self._warp = cv2.getPerspectiveTransform(src, dst) if rz.perspective > 0 else None

    def _degrade(self, img: np.ndarray, t_s: float) -> np.ndarray | None:
        rz = self.realism
        assert rz is not None
        self._frame_no += 1
        if rz.drop_prob > 0 and self._rng.random() < rz.drop_prob:
            return None
        if self._warp is not None:
            img = cv2.warpPerspective(img, self._warp, (self.width_px, self.height_px),
                                      borderMode=cv2.BORDER_CONSTANT, borderValue=BACKGROUND_BGR)
        phase = 2 * math.pi * t_s / max(rz.drift_period_s, 1e-6)
        gain = 1.0 + rz.drift_amp * math.sin(phase)
        # lighting: a linear falloff whose direction turns slowly, breathing with ``drift_amp``
        light = cv2.addWeighted(self._xx, -rz.gradient * gain * math.cos(phase / 3),
                                self._yy, -rz.gradient * gain * math.sin(phase / 3), gain)
        f = cv2.multiply(img, cv2.merge((light, light, light)), dtype=cv2.CV_32F)
        f = cv2.add(f, self._glare3)
        if rz.blur_px > 0:
            f = cv2.GaussianBlur(f, (0, 0), rz.blur_px)
        if self._noise:
            f = cv2.add(f, self._noise[int(self._rng.integers(len(self._noise)))])
        np.clip(f, 0, 255, out=f)
        out = f.astype(np.uint8)
        if rz.jpeg_quality > 0:
            ok, enc = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(rz.jpeg_quality)])
            dec = cv2.imdecode(enc, cv2.IMREAD_COLOR) if ok else None
            if dec is not None:
                out = np.asarray(dec, np.uint8)
        return out


__all__ = ["Realism", "Renderer", "size_for_radius"]

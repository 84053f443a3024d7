"""Synthetic drum frames with known geometry (benchmarks and tests; no I/O)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.roi import DrumROI

__all__ = ["BLUE_BGR", "LIGHT_CHANGES", "PERTURBATIONS", "RED_BGR", "DrumScene", "colour_temperature_gains",
           "drum_frame", "light_change", "particle_drum", "perturb"]

RED_BGR = (0, 0, 220)
BLUE_BGR = (220, 60, 0)


def drum_frame(
    size_wh: tuple[int, int] = (640, 480),
    *,
    mix: float = 1.0,
    fill: float = 0.5,
    slope_deg: float = 30.0,
    particle_r_frac: float = 0.035,
    seed: int = 0,
    r_frac: float = 0.46,
) -> np.ndarray:
    """A front-view drum: dark background, grey rim, a tilted bed of red and blue disks.

    ``mix`` 0 puts red on one side of the bed and blue on the other, 1 mixes them at
    random. ``slope_deg`` is the free-surface angle (positive rises to the right).
    """
    w, h = size_wh
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 18, np.uint8)
    cx, cy = w / 2.0, h / 2.0
    R = r_frac * min(w, h)
    cv2.circle(img, (int(cx), int(cy)), int(R), (150, 150, 150), max(2, int(R / 60)), cv2.LINE_AA)
    pr = particle_r_frac * R * 2
    # chord at distance t from the centre, normal pointing up (rotated by the slope)
    a = math.radians(slope_deg)
    nx, ny = -math.sin(a), -math.cos(a)  # image coords, "up" rotated
    # fill fraction -> chord offset t (segment below the chord) by bisection
    lo, hi = -R, R
    for _ in range(50):
        t = 0.5 * (lo + hi)
        th = math.acos(max(-1.0, min(1.0, t / R)))
        seg = (R * R * (th - math.sin(th) * math.cos(th))) / (math.pi * R * R)
        # seg = share of the disc beyond distance t from the centre
        if 1.0 - seg < fill:
            lo = t
        else:
            hi = t
    t = -0.5 * (lo + hi)
    step = pr * 2.05
    for gy in np.arange(cy - R, cy + R, step * 0.87):
        off = (int((gy - cy) / (step * 0.87)) % 2) * step / 2
        for gx in np.arange(cx - R + off, cx + R, step):
            x, y = gx + rng.normal(0, pr * 0.08), gy + rng.normal(0, pr * 0.08)
            dx, dy = x - cx, y - cy
            if math.hypot(dx, dy) > R - pr * 1.1:
                continue
            if dx * nx + dy * ny > t:  # above the free surface
                continue
            along = dx * math.cos(a) - dy * math.sin(a)
            seg_red = along < 0
            red = seg_red if rng.random() > mix else rng.random() < 0.5
            colour = RED_BGR if red else BLUE_BGR
            cv2.circle(img, (int(round(x)), int(round(y))), int(round(pr)), colour, -1, cv2.LINE_AA)
    return img


@dataclass(frozen=True)
class DrumScene:
    """A rendered drum frame and its truth: the drum circle, each class's pixel centroid
    (px) and pixel count, the free surface's central-chord angle (deg), each class's pixel
    spread ``sqrt(var_x + var_y)`` (px) and the class map of the drawn discs (0 none, k + 1
    colour k)."""

    image: np.ndarray
    roi: DrumROI
    centroids: tuple[tuple[float, float], ...]
    counts: tuple[int, ...]
    surface_deg: float
    sigmas: tuple[float, ...] = ()
    labels: np.ndarray | None = None


def _surface_truth(a_rad: float, t: float, s_shape: float, R: float) -> float:
    """Central-chord angle (deg) of the profile v(u) = t - s R (u/R)^3 in a frame tilted by a."""
    u = np.linspace(-R, R, 4001)
    v = t - s_shape * R * (u / R) ** 3
    inside = u * u + v * v <= R * R
    u, v = u[inside], v[inside]
    mid = 0.5 * (u.min() + u.max())
    sel = np.abs(u - mid) <= 0.5 * R
    slope = np.polyfit(u[sel], v[sel], 1)[0]
    return math.degrees(a_rad + math.atan(slope))


def particle_drum(
    size_wh: tuple[int, int] = (640, 480),
    colours: tuple[tuple[int, int, int], tuple[int, int, int]] = (BLUE_BGR, (235, 235, 235)),
    *,
    mix: float = 1.0,
    fill: float = 0.45,
    slope_deg: float = 30.0,
    s_shape: float = 0.0,
    particle_r_frac: float = 0.032,
    seed: int = 0,
    r_frac: float = 0.46,
    background_bgr: tuple[int, int, int] = (18, 18, 18),
    shading: float = 0.45,
    highlight: float = 0.35,
) -> DrumScene:
    """A front-view drum of shaded particles (discs darker towards their edge, with a
    specular highlight) in two colours, so classification by colour rather than brightness
    is really tested.

    The bed lies below a free surface tilted by ``slope_deg`` (positive rises to the
    right) with an S-shape ``s_shape`` (profile ``v = t - s R (u/R)^3`` along the tilted
    axis; 0 = flat). ``mix`` 0 puts colour 0 at the low end and colour 1 at the high end,
    1 mixes them at random. Truth centroids are those of the drawn discs' pixels.
    """
    w, h = size_wh
    rng = np.random.default_rng(seed)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    R = r_frac * min(w, h)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    rr = np.hypot(xs - cx, ys - cy)
    img = np.empty((h, w, 3), np.float32)
    grad = (1.0 + 0.15 * (ys - cy) / R)[..., None]
    img[...] = np.asarray(background_bgr, np.float32) * grad
    img[rr > R + 3] = np.asarray(background_bgr, np.float32) * 0.5
    rim = (rr > R) & (rr <= R + 3)
    img[rim] = (150, 150, 150)
    a = math.radians(slope_deg)
    ux, uy = math.cos(a), -math.sin(a)  # along the surface, image coords (uphill for a > 0)
    vx, vy = -math.sin(a), -math.cos(a)  # "up" out of the bed
    lo, hi = -R, R  # offset t of the surface (flat part) for the wanted fill, by bisection on a grid
    gu = np.linspace(-R, R, 241)
    gv = np.linspace(-R, R, 241)
    GU, GV = np.meshgrid(gu, gv)
    disc = GU * GU + GV * GV <= R * R
    drop = s_shape * R * (GU / R) ** 3  # the profile's S-shape below t, the same in every step
    n_disc = disc.sum()
    for _ in range(40):
        t = 0.5 * (lo + hi)
        below = disc & (GV <= t - drop)
        if below.sum() / n_disc < fill:
            lo = t
        else:
            hi = t
    t = 0.5 * (lo + hi)
    pr = particle_r_frac * R
    step = 2.05 * pr
    lab = np.zeros((h, w), np.uint8)
    for gy in np.arange(cy - R, cy + R, step * 0.87):
        off = (int(round((gy - cy) / (step * 0.87))) % 2) * step / 2
        for gx in np.arange(cx - R + off, cx + R, step):
            x, y = gx + rng.normal(0, pr * 0.06), gy + rng.normal(0, pr * 0.06)
            dx, dy = x - cx, y - cy
            if math.hypot(dx, dy) > R - pr * 1.05:
                continue
            u, v = dx * ux + dy * uy, dx * vx + dy * vy
            if v > t - s_shape * R * (u / R) ** 3 - pr * 0.5:
                continue
            k = (1 if u > 0 else 0) if rng.random() >= mix else int(rng.random() < 0.5)
            _draw_particle(img, lab, x, y, pr, np.asarray(colours[k], np.float32), k + 1, shading, highlight)
    out = np.clip(img + rng.normal(0, 1.5, img.shape), 0, 255).astype(np.uint8)
    cents, counts, sigmas = [], [], []
    for k in (1, 2):
        yy, xx = np.nonzero(lab == k)
        cents.append((float(xx.mean()), float(yy.mean())) if xx.size else (math.nan, math.nan))
        counts.append(int(xx.size))
        sigmas.append(math.sqrt(float(xx.var() + yy.var())) if xx.size else math.nan)
    return DrumScene(out, DrumROI(cx, cy, R), tuple(cents), tuple(counts), _surface_truth(a, t, s_shape, R),
                     tuple(sigmas), lab)


def _draw_particle(img: np.ndarray, lab: np.ndarray, x: float, y: float, pr: float, colour: np.ndarray, k: int,
                   shading: float, highlight: float) -> None:
    h, w = lab.shape
    x0, x1 = max(0, int(x - pr - 1)), min(w, int(x + pr + 2))
    y0, y1 = max(0, int(y - pr - 1)), min(h, int(y + pr + 2))
    py, px = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    d = np.hypot(px - x, py - y)
    alpha = np.clip(pr + 0.5 - d, 0.0, 1.0)[..., None]
    rho2 = np.minimum(d / pr, 1.0) ** 2
    shade = (1.0 - shading * rho2)[..., None]
    r2 = (px - x + 0.35 * pr) ** 2 + (py - y + 0.35 * pr) ** 2
    spot = highlight * np.exp(-r2 / (2 * (0.2 * pr) ** 2))[..., None]
    col = colour * shade
    col = col + spot * (255.0 - col)
    patch = img[y0:y1, x0:x1]
    patch[...] = alpha * col + (1 - alpha) * patch
    lab[y0:y1, x0:x1][alpha[..., 0] >= 0.5] = k


LIGHT_CHANGES = ("exposure0.7", "exposure1.3", "ct+1000", "ct-1000")
"""The light changes after set-up of issue 22 (:func:`perturb` kinds): exposure x0.7 and x1.3,
colour temperature +-1000 K."""

_BGR_NM = (455.0, 540.0, 605.0)  # dominant wavelengths of a webcam's B, G, R filters, nm


def colour_temperature_gains(delta_k: float, base_k: float = 5500.0) -> tuple[float, float, float]:
    """Linear-light gains (B, G, R) of a black-body light going from ``base_k`` to ``base_k +
    delta_k`` kelvin, seen through narrow B, G, R filters (Planck's law), green kept at 1 (the
    exposure does not follow the white balance). +1000 K from 5500 K: blue up ~11%, red down ~9%."""
    def planck(nm: float, t: float) -> float:
        lam = nm * 1e-9
        return 1.0 / (lam**5 * math.expm1(1.4388e-2 / (lam * t)))

    t1 = base_k + delta_k
    if not (base_k > 0 and t1 > 0):
        raise ValueError(f"colour temperatures must be > 0 K, got {base_k} and {t1}")
    g = [planck(nm, t1) / planck(nm, base_k) for nm in _BGR_NM]
    return (g[0] / g[1], 1.0, g[2] / g[1])


def light_change(image_bgr: np.ndarray, gains_bgr: tuple[float, float, float] | float) -> np.ndarray:
    """A frame under other light: linear light (sRGB-like gamma 2.2 decoded) times per-channel
    gains, clipped channel by channel as a sensor clips, encoded again."""
    g = np.broadcast_to(np.asarray(gains_bgr, np.float32), (3,))
    lin = (np.asarray(image_bgr, np.float32) / 255.0) ** 2.2 * g
    return (np.clip(lin, 0, 1) ** (1 / 2.2) * 255.0 + 0.5).astype(np.uint8)


PERTURBATIONS = ("none", "exposure0.7", "exposure1.3", "noise", "jpeg30", "glare", "rotate10", "half")
"""The robustness perturbations of :func:`perturb`."""


def perturb(image_bgr: np.ndarray, kind: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A perturbed copy of a frame and the 2x3 affine that maps its original pixel
    coordinates to the new ones (identity unless rotated or resized).

    ``exposure0.7``/``exposure1.3`` scale linear light (sRGB decoded, clipped), ``noise``
    adds gaussian noise (sigma 8), ``jpeg30`` re-encodes at JPEG quality 30, ``glare``
    adds three saturated specular spots, ``rotate10`` turns the frame 10 deg about its
    centre, ``half`` halves the resolution; ``ct+1000``/``ct-1000`` (any ``ct<kelvin>``)
    shift the light's colour temperature (:func:`colour_temperature_gains`)."""
    img = np.asarray(image_bgr)
    h, w = img.shape[:2]
    ident = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    rng = np.random.default_rng(seed)
    if kind == "none":
        return img.copy(), ident
    if kind.startswith("exposure"):
        return light_change(img, float(kind[len("exposure"):])), ident
    if kind.startswith("ct") and kind[2:].lstrip("+-").isdigit():
        return light_change(img, colour_temperature_gains(float(kind[2:]))), ident
    if kind == "noise":
        return np.clip(img + rng.normal(0, 8.0, img.shape), 0, 255).astype(np.uint8), ident
    if kind == "jpeg30":
        _, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 30])
        return np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)), ident
    if kind == "glare":
        out = img.astype(np.float32)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        for _ in range(3):
            gx, gy = rng.uniform(0.3 * w, 0.7 * w), rng.uniform(0.3 * h, 0.75 * h)
            s = 0.02 * min(w, h)
            g = np.exp(-((xs - gx) ** 2 + (ys - gy) ** 2) / (2 * s * s))[..., None]
            out = out + g * 1.5 * (255.0 - out)
        return np.clip(out, 0, 255).astype(np.uint8), ident
    if kind == "rotate10":
        m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), 10.0, 1.0)
        return cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), m
    if kind == "half":
        half = np.asarray(cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA))
        return half, np.array([[0.5, 0.0, -0.25], [0.0, 0.5, -0.25]])
    raise ValueError(f"unknown perturbation {kind!r}; one of {PERTURBATIONS}")

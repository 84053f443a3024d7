"""Rigs made from real frames: the test beds of the cross-rig evaluation (pure).

Real rigs are scarce, and a method tuned on the one rig it can see fails on the next. So
other rigs are made from the real frames of one rig (the PMMA frames of ``tests/data``:
blue and white discs, each frame with YOLO boxes of one class) with the labels' truth kept:

- **colours** (:data:`PAIRS`): each class's pixels re-coloured to another colour in linear
  light, keeping their shading and texture (:func:`recolour`): a pixel is its class's colour
  times a shade (its projection on the class colour) plus what the colour does not explain
  (highlights, noise), and only the colour is swapped;
- **cameras** (:data:`CAMERAS`): quarter and arbitrary turns, a mirror, 2048 and 320 px, a
  2048 x 1948 sensor with the drum off its centre, blur, JPEG (:func:`camera_view`), the boxes moved with the image;
- **light after set-up** (:data:`LIGHTS`): exposure x0.6..x1.5 and white-balance shifts of
  15 % per channel (linear light, clipped per channel: ``vision.synthetic.light_change``).

The truth of a frame (:class:`RigFrame`): the labelled class's centroid (the mean of its box
centres: the discs are of one size) moved with the image, the drum radius, and the MI of the
labels: the labelled class from its boxes (centres, and each disc's own spread), the other
class from the source frame's own class mask (:func:`source_labels`, a fixed rule on the
untouched frame, not the method under test). Rotations, mirrors and scaling leave the MI as
it is.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from vision.mixing import mixing_indices
from vision.roi import DrumROI, detect_drum, roi_mask
from vision.synthetic import light_change

__all__ = [
    "BEYOND",
    "CAMERAS",
    "GAMMA",
    "LIGHTS",
    "PAIRS",
    "SYNTHETIC_PAIRS",
    "PreparedSource",
    "RigFrame",
    "RigSpec",
    "SourceFrame",
    "camera_view",
    "class_colours",
    "default_rigs",
    "label_truth",
    "make_rig",
    "prepare_source",
    "recolour",
    "relight",
    "setup_indices",
    "source_labels",
]

GAMMA = 2.2
"""The sensor gamma the re-colouring works under (display value = 255 linear ** (1 / GAMMA))."""

BGR = tuple[int, int, int]

PAIRS: dict[str, tuple[BGR | None, BGR | None]] = {
    "blue-white": (None, None),
    "teal-white": ((150, 140, 25), None),
    "green-white": ((45, 150, 30), None),
    "red-blue": ((25, 30, 175), (150, 60, 15)),
    "orange-black": ((20, 110, 225), (42, 40, 38)),
    "paleteal-white": ((165, 168, 118), (160, 160, 160)),
}
"""Colour pairs of the rigs: the display colour (B, G, R) that the source's blue and white
discs take at their median shade (None: kept). The pale pair is pale teal against a neutral
white of one brightness; black discs lie on the drum's black background."""

SYNTHETIC_PAIRS: dict[str, tuple[BGR, BGR]] = {
    "blue-white": ((200, 70, 10), (235, 235, 235)),
    "paleteal-white": ((205, 210, 160), (235, 235, 235)),
    "paleteal-white-clip": ((232, 240, 218), (244, 244, 244)),  # two channels clip at x1.3
    "palepink-white": ((215, 205, 245), (240, 240, 240)),
    "palecream-white": ((200, 238, 246), (244, 244, 244)),
    "darkgreen-lightgreen": ((30, 110, 20), (150, 235, 150)),
    "red-blue": ((30, 30, 210), (200, 70, 10)),
}
"""The synthetic suite's colour pairs (``vision.synthetic.particle_drum``; display colours): the
pale ones near white as real pale particles are, so that x1.3 clips them channel by channel."""

CAMERAS = ("plain", "rot90", "rot180", "rot33", "mirror", "scale2048", "scale320", "frame2048x1948", "blur",
           "jpeg40")
"""Camera set-ups of :func:`camera_view`: turned by a quarter, a half and 33 deg (counter-clockwise
on screen), mirrored, scaled to 2048 and 320 px across, a 2048 x 1948 sensor (the frame scaled to
1948 px high against the right edge of a frame of its border colour: not square, the drum off its
centre, as the issue's second rig was filmed), a Gaussian blur (sigma 1.5 px), JPEG quality 40."""

LIGHTS: dict[str, tuple[float, float, float]] = {
    "setup": (1.0, 1.0, 1.0),
    "x0.6": (0.6, 0.6, 0.6),
    "x0.7": (0.7, 0.7, 0.7),
    "x0.85": (0.85, 0.85, 0.85),
    "x1.3": (1.3, 1.3, 1.3),
    "x1.5": (1.5, 1.5, 1.5),
    "wb_warm": (0.85, 1.0, 1.15),
    "wb_cool": (1.15, 1.0, 0.85),
    "wb_green": (0.85, 1.15, 0.85),
}
"""Light after set-up: linear-light gains (B, G, R) of each frame (``vision.synthetic.light_change``)."""

BEYOND: dict[str, tuple[float, float, float] | None] = {
    "x3": (3.0, 3.0, 3.0), "x0.2": (0.2, 0.2, 0.2), "curve1.8": None}
"""Light past what a gain per channel maps back (:func:`relight`): saturating, near darkness, and
a tone curve (display value ** 1.8, no gain explains it): the frames should be flagged."""

_BED_V = 50  # a source pixel with a channel at or above this lies on a disc (the background is near black)
_EDGE_V = 22  # ... one between this and _BED_V next to a disc is its dark edge (re-coloured with it)
_BLUE_CHROMA = 0.3  # a disc pixel whose blue exceeds its other channels by this share of it is blue
_R_MAX = 1.01  # disc pixels lie within this share of the detected drum radius (its rim at ~1.025) ...
_R_RIM = 1.06  # ... blue reflections of the discs in the drum's wall out to this (re-coloured with the blue)


@dataclass(frozen=True)
class SourceFrame:
    """A real frame and its labels: YOLO boxes (N, 4: cx, cy, w, h normalised to the image) of the
    class ``labelled`` (0 = the source's blue discs, 1 = its white discs); ``name``: the frame's id."""

    name: str
    image: np.ndarray
    boxes: np.ndarray
    labelled: int


@dataclass(frozen=True)
class RigSpec:
    """A rig: a colour pair of :data:`PAIRS` seen through a camera of :data:`CAMERAS`."""

    pair: str
    camera: str = "plain"

    @property
    def name(self) -> str:
        return self.pair if self.camera == "plain" else f"{self.pair}/{self.camera}"


@dataclass(frozen=True)
class RigFrame:
    """One frame of a rig and its truth: ``labelled`` (0/1: the pair's first or second colour),
    the labels' centroid ``truth_px`` (x, y in this image), the drum radius ``r_px`` in this
    image, the labels' MI (``mi``; NaN when it cannot be formed) and the source's class map
    seen by the same camera (``classes``: 0 none, k + 1 the pair's colour k)."""

    name: str
    image: np.ndarray
    labelled: int
    truth_px: tuple[float, float]
    r_px: float
    mi: float
    classes: np.ndarray | None = None


def source_labels(image_bgr: np.ndarray, roi: DrumROI) -> np.ndarray:
    """The source rig's class map (0 none, 1 blue, 2 white) of an untouched PMMA frame: a disc
    pixel (a channel >= 50, in the bed: what an opening by a 7 px disc keeps, in pieces of at
    least 0.0015 R^2, so the drum's scratches, hub and rim glints stay out) is blue when its
    blue channel exceeds the other two by 30 % of it, else white; a darker pixel next to a
    disc (a channel >= 22) is its edge and takes the class of the disc pixels around it (the
    more of them in a 5 x 5 window); beyond 1.01 R, in the drum's wall, only the blue discs'
    reflections (blue, out to 1.06 R)."""
    img = np.asarray(image_bgr)
    f = img.astype(np.int16)
    hi = f.max(axis=2)
    inside = roi_mask(DrumROI(roi.cx_px, roi.cy_px, _R_MAX * roi.r_px), img.shape[:2])
    bright = (inside & (hi >= _BED_V)).astype(np.uint8)
    core = cv2.morphologyEx(bright, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7)))
    n, comp, stats, _ = cv2.connectedComponentsWithStats(core, connectivity=8)
    keep = np.zeros(n, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= 0.0015 * roi.r_px**2
    near = cv2.dilate(keep[comp].astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    bed = (bright > 0) & near
    blue = bed & (f[..., 0] - np.maximum(f[..., 1], f[..., 2]) >= _BLUE_CHROMA * f[..., 0])
    white = bed & ~blue
    edge = inside & near & ~bed & (hi >= _EDGE_V)
    kern = np.ones((5, 5), np.float32)
    nb = cv2.filter2D(blue.astype(np.float32), -1, kern)
    nw = cv2.filter2D(white.astype(np.float32), -1, kern)
    out = np.zeros(img.shape[:2], np.uint8)
    out[blue] = 1
    out[white] = 2
    out[edge & (nb > 0) & (nb >= nw)] = 1
    out[edge & (nw > nb)] = 2
    wall = roi_mask(DrumROI(roi.cx_px, roi.cy_px, _R_RIM * roi.r_px), img.shape[:2]) & ~inside
    out[wall & (hi >= _EDGE_V) & (f[..., 0] - np.maximum(f[..., 1], f[..., 2]) >= _BLUE_CHROMA * f[..., 0])] = 1
    return out


def _linear(img: np.ndarray) -> np.ndarray:
    return (np.asarray(img, np.float32) / 255.0) ** GAMMA


def _display(lin: np.ndarray) -> np.ndarray:
    return (np.clip(lin, 0.0, 1.0) ** (1.0 / GAMMA) * 255.0 + 0.5).astype(np.uint8)


def class_colours(frames: Sequence[np.ndarray], labels: Sequence[np.ndarray]) -> np.ndarray:
    """Each source class's colour in linear light (2, 3): the per-channel median of its disc
    pixels (a channel >= 50) over the frames."""
    out = np.empty((2, 3), np.float32)
    for k in (1, 2):
        px = np.concatenate([_linear(img[(lab == k) & (img.max(axis=2) >= _BED_V)])
                             for img, lab in zip(frames, labels, strict=True)])
        out[k - 1] = np.median(px, axis=0)
    return out


def recolour(image_bgr: np.ndarray, labels: np.ndarray, source: np.ndarray,
             targets: Sequence[BGR | None]) -> np.ndarray:
    """The frame with each class k (label k + 1) re-coloured from its colour ``source[k]``
    (linear light, :func:`class_colours`) to the display colour ``targets[k]`` (None: kept).
    In linear light a pixel p of class k is a shade s of its colour a, plus w of white (the
    glow of a translucent disc's edge, a highlight), plus a residual (noise, texture): s and
    w >= 0 by least squares (w = 0 for a near-grey class, whose colour is white's). It becomes
    s t + w white + the residual, t the target colour: shading, edges, highlights and texture
    stay where they were, and a blue disc's light-blue edge becomes a red disc's pink one."""
    lin = _linear(image_bgr)
    out = lin.copy()
    white = np.full(3, 1.0 / math.sqrt(3.0), np.float32)
    for k, target in enumerate(targets):
        if target is None:
            continue
        sel = labels == k + 1
        p = lin[sel]
        a = source[k].astype(np.float32)
        s, _ = _shade_and_white(p, a, white)
        t = _linear(np.array(target, np.uint8))
        out[sel] = p + s[:, None] * (t - a)[None, :]
    return _display(out)


def _shade_and_white(p: np.ndarray, a: np.ndarray, white: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel (rows of ``p``) the least-squares s, w >= 0 of p ~ s a + w white (w = 0 when ``a``
    lies within 15 deg of grey)."""
    s_only = np.maximum(p @ a / float(a @ a), 0.0)
    cos = float(a @ white) / float(np.linalg.norm(a))
    if cos > math.cos(math.radians(15.0)):
        return s_only, np.zeros_like(s_only)
    g = np.array([[a @ a, a @ white], [a @ white, white @ white]], np.float64)
    rhs = np.stack([p @ a, p @ white], axis=1).astype(np.float64)
    sw = rhs @ np.linalg.inv(g).T
    neg = sw[:, 1] < 0.0
    sw[neg, 0], sw[neg, 1] = s_only[neg], 0.0
    sw[:, 0] = np.maximum(sw[:, 0], 0.0)
    return sw[:, 0].astype(np.float32), sw[:, 1].astype(np.float32)


def _border(img: np.ndarray, labels: bool) -> int | tuple[int, ...]:
    """What a camera view fills in beyond the frame: its top and bottom rows' median colour (0 for a
    class map: no class)."""
    return 0 if labels else tuple(int(v) for v in np.median(np.concatenate([img[0], img[-1]]), axis=0))


def camera_view(image_bgr: np.ndarray, camera: str, labels: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The frame as a camera of :data:`CAMERAS` sees it, and the 2x3 affine from the source's pixel
    coordinates (pixel centres at integers) to the new frame's. ``labels``: a class map
    (nearest neighbours; blur and JPEG leave it as it is)."""
    img = np.asarray(image_bgr)
    h, w = img.shape[:2]
    if labels and (camera == "blur" or camera.startswith("jpeg")):
        camera = "plain"
    ident = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    if camera == "plain":
        return img, ident
    if camera == "rot90":  # counter-clockwise on screen (np.rot90): x' = y, y' = w - 1 - x
        return np.ascontiguousarray(np.rot90(img, 1)), np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, w - 1.0]])
    if camera == "rot180":
        return np.ascontiguousarray(img[::-1, ::-1]), np.array([[-1.0, 0.0, w - 1.0], [0.0, -1.0, h - 1.0]])
    if camera.startswith("rot"):
        m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), float(camera[3:]), 1.0)
        border = _border(img, labels)
        flags = cv2.INTER_NEAREST if labels else cv2.INTER_LINEAR
        return cv2.warpAffine(img, m, (w, h), flags=flags, borderValue=border), m
    if camera == "mirror":
        return np.ascontiguousarray(img[:, ::-1]), np.array([[-1.0, 0.0, w - 1.0], [0.0, 1.0, 0.0]])
    if camera.startswith("frame"):  # a sensor of W x H px ("frame2048x1948")
        sw, sh = (int(v) for v in camera[5:].split("x"))
        s = min(sh / h, sw / w)  # the whole frame fits, its top and right edges the sensor's
        big, m = camera_view(img, f"scale{int(round(w * s))}", labels)
        big = big[:sh, :sw]
        dx = sw - big.shape[1]
        out = np.empty((sh, sw, *big.shape[2:]), big.dtype)
        out[...] = _border(img, labels)
        out[:big.shape[0], dx:] = big
        return out, m + np.array([[0.0, 0.0, dx], [0.0, 0.0, 0.0]])
    if camera.startswith("scale"):
        s = float(camera[5:]) / w
        size = (int(round(w * s)), int(round(h * s)))
        interp = cv2.INTER_NEAREST if labels else cv2.INTER_AREA if s < 1.0 else cv2.INTER_CUBIC
        return cv2.resize(img, size, interpolation=interp), np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5]])
    if camera == "blur":
        return cv2.GaussianBlur(img, (0, 0), 1.5), ident
    if camera.startswith("jpeg"):
        buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(camera[4:])])[1]
        return np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)), ident
    raise ValueError(f"unknown camera {camera!r}; one of {CAMERAS}")


def relight(image_bgr: np.ndarray, light: str) -> np.ndarray:
    """The frame under the light ``light`` of :data:`LIGHTS` or :data:`BEYOND` (the set-up
    light: unchanged)."""
    if light == "curve1.8":
        return (255.0 * (np.asarray(image_bgr, np.float32) / 255.0) ** 1.8 + 0.5).astype(np.uint8)
    gains = LIGHTS[light] if light in LIGHTS else BEYOND[light]
    assert gains is not None
    return np.asarray(image_bgr) if gains == (1.0, 1.0, 1.0) else light_change(image_bgr, gains)


def label_truth(frame: SourceFrame, labels: np.ndarray, roi: DrumROI) -> tuple[tuple[float, float], float]:
    """The labelled class's centroid (px, the mean of its box centres) and the labels' MI: the
    labelled class's centroid and spread from its boxes (a disc of radius a adds a^2 / 2 to
    the spread squared), the other class's from the source class map ``labels``."""
    h, w = frame.image.shape[:2]
    b = np.asarray(frame.boxes, np.float64).reshape(-1, 4)
    xs, ys = b[:, 0] * w - 0.5, b[:, 1] * h - 0.5
    c1 = (float(xs.mean()), float(ys.mean()))
    a2 = ((b[:, 2] * w + b[:, 3] * h) / 4.0) ** 2
    s1 = math.sqrt(float(xs.var() + ys.var() + 0.5 * a2.mean()))
    yy, xx = np.nonzero(labels == (2 - frame.labelled))
    if xx.size < 50:
        return c1, math.nan
    c2 = (float(xx.mean()), float(yy.mean()))
    s2 = math.sqrt(float(xx.var() + yy.var()))
    return c1, mixing_indices(c1, c2, s1, s2, roi.r_px).mi


@dataclass(frozen=True)
class PreparedSource:
    """What every rig made from the same source frames shares: each frame's drum, its class map
    (:func:`source_labels`) and the classes' colours (:func:`class_colours`)."""

    rois: tuple[DrumROI, ...]
    labels: tuple[np.ndarray, ...]
    colours: np.ndarray


def prepare_source(frames: Sequence[SourceFrame]) -> PreparedSource:
    """The drums, class maps and class colours of the source frames (once for every rig)."""
    rois = tuple(detect_drum(f.image) for f in frames)
    labels = tuple(source_labels(f.image, r) for f, r in zip(frames, rois, strict=True))
    return PreparedSource(rois, labels, class_colours([f.image for f in frames], labels))


def make_rig(spec: RigSpec, frames: Sequence[SourceFrame],
             prepared: PreparedSource | None = None) -> Iterator[RigFrame]:
    """The frames of rig ``spec`` in the source's order (made one at a time: a 2048 px rig holds
    one frame, not 42); ``prepared``: :func:`prepare_source` of ``frames`` (made here when None)."""
    prep = prepare_source(frames) if prepared is None else prepared
    targets = PAIRS[spec.pair]
    source = prep.colours if any(t is not None for t in targets) else None
    for f, roi, lab in zip(frames, prep.rois, prep.labels, strict=True):
        img = f.image if source is None else recolour(f.image, lab, source, targets)
        view, m = camera_view(img, spec.camera)
        (cx, cy), mi = label_truth(f, lab, roi)
        tx, ty = m @ np.array([cx, cy, 1.0])
        scale = math.sqrt(abs(float(np.linalg.det(m[:, :2]))))
        yield RigFrame(f.name, view, f.labelled, (float(tx), float(ty)), roi.r_px * scale, mi,
                       camera_view(lab, spec.camera, labels=True)[0])


def setup_indices(n: int, k: int = 12) -> list[int]:
    """The frames a rig's classes are learned from: ``k`` spread evenly over ``n`` (as
    ``classes suggest --frames k`` takes them from a source)."""
    return sorted({int(round(v)) for v in np.linspace(0, n - 1, min(k, n))})


def default_rigs() -> tuple[RigSpec, ...]:
    """The bench's rigs: every colour pair through the plain camera, and two pairs (the source's
    blue/white and teal/white, the pair the issue failed on) through every other camera, plus
    the hardest pairs upside down."""
    plain = tuple(RigSpec(p) for p in PAIRS)
    cams = tuple(RigSpec(p, c) for p in ("blue-white", "teal-white") for c in CAMERAS if c != "plain")
    return plain + cams + (RigSpec("orange-black", "rot180"), RigSpec("paleteal-white", "mirror"))

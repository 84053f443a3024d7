"""``classes suggest``: learn the particle colour classes from the bed, over many frames.

1. Sample pixels inside the drum (to 0.94 R, off the rim) from every frame given, with
   their height in the drum.
2. Fit a Gaussian mixture (EM, full covariances, ``k + 3`` components, k-means start) to
   their CIELAB colours with lightness down-weighted.
3. Components over-represented in the top cap of the drum (the empty part above the
   bed) are background: the drum's back wall, rim, reflections. So is glare: a small
   component (under 0.25x the largest particle component) with 10% or more clipped
   samples (a channel >= 250) is no material of its own, as long as ``k`` particle
   components remain.
4. The other components are grouped into ``k`` classes by continuity of the fitted
   density: two components joined by a ridge (no valley in the mixture's density on the
   segment between their means) are one material seen under different shading, two
   separated by a valley are two materials; single linkage merges the shallowest valleys
   first until ``k`` groups remain. So a white particle in shadow stays white, while white
   and pale teal, or dark and light green, stay apart. A particle component darker than,
   and joined more closely to the background than to, its nearest particle component
   (gaps, shadows) joins the background, and so does a member of a class far darker (L below half) than the
   class's main component (the gaps between particles, deep shadows).
   Last, a class member (not its main component) that lies between the background's
   colour and another class's main colour is dropped to the background: mixed edge and
   gap pixels, which noise or blur make either material's (see ``_drop_bridges``).
5. Each class keeps its Gaussians; the background is one reject class. The meter's
   lookup table assigns every colour to its most likely component, and counts it only
   within ``max_distance`` sigmas of a particle class.
6. Two classes with no valley between them (the density dips by less than ``_NO_VALLEY``)
   are a note for the user: either one material was split by its shading (the other
   taken for background, e.g. black particles on a dark drum) or two materials differ
   only in lightness (grey and white), which shading mixes up pixel by pixel.
7. The class opening (``[meter] opening``) is turned on when it moves a class centroid on
   the frames given by more than ``OPENING_SHIFT`` R (``needs_opening``): chroma blur
   (JPEG 4:2:0) gives the dark gaps between light particles the colour of a darker class
   of the same hue, which the opening drops while it keeps whole particles. It works on the
   meter's stride grid, so on large frames the stride is set to about a twelfth of a
   particle's diameter (``particle_diameter_px``, ``opening_stride``; halved while the
   opening would eat the particles): the blurred gaps grow with the particles. On such a
   coarse grid the opening is always on (it costs nothing there, and the gaps it drops
   need not move a centroid on the frames given -- a mixed bed -- to move one on others).

8. The island filter (``[meter] island_px``, ``vision.islands``) is turned on, at half a
   particle's area, when it moves a class centroid on the frames given by more than
   ``OPENING_SHIFT`` R (``needs_islands``): the specular highlights of glossy dark particles
   take the colour of a lighter class of the same hue, small islands inside the dark particles.

Classes are named by colour and sorted by name, so the TOML is the same for any frames
of the same material pair.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from vision.census import run_diameter_px
from vision.colours import (
    ColourClass,
    LabComponent,
    bgr_to_lab,
    class_lut,
    class_mean_lab,
    classify,
    counted_classes,
)
from vision.config import MeterConfig
from vision.errors import VisionError
from vision.meter import gravity_matrix
from vision.photometric import class_quantiles, light_quantiles, roi_sample_index, sample_labels
from vision.roi import DrumROI, _mask_in_box, detect_drum, roi_bbox

__all__ = [
    "KEEP_FRAMES",
    "MAX_DISTANCE",
    "OPENING_GRID",
    "OPENING_KEEP",
    "OPENING_SHIFT",
    "SAMPLE_BUDGET",
    "DrumSamples",
    "class_preview",
    "colour_name",
    "fit_colour_model",
    "island_area_px",
    "needs_islands",
    "needs_opening",
    "opening_stride",
    "particle_diameter_px",
    "propose_rotation_deg",
    "relearn_classes",
    "sample_drum_pixels",
    "suggest_classes",
]

MAX_DISTANCE = 4.5
"""Reject distance of a suggested class (Mahalanobis, sigmas)."""

OPENING_SHIFT = 0.01
"""``classes suggest`` turns the class opening on when it moves a class centroid by more than
this share of R on a frame it learned from (a third of the 3% accuracy aim)."""

OPENING_KEEP = 0.5
"""... and not when it would leave a class less than this share of its pixels."""


OPENING_GRID = 12.0
"""Grid pixels across a particle for the opening's stride (``opening_stride``)."""

_L_WEIGHT_FIT = 0.5  # lightness weight in the space the mixture's k-means start sees
_SHADOW_L_RATIO = 0.5  # a class member darker than this x the class's main lightness is shadow/gap
_CLIP_LEVEL = 250  # a channel at or above this is clipped (glare, specular spots)
_GLARE_CLIPPED = 0.1  # a component with this share of clipped samples ...
_GLARE_WEIGHT = 0.25  # ... and under this x the largest particle component's weight is glare
_BRIDGE_T = (0.2, 0.8)  # a class member between the background and another class (position on the segment) ...
_BRIDGE_OFF = 0.2  # ... and this close to the segment (x its length) is mixed edge pixels of both
_NO_VALLEY = -0.6  # two classes whose density dips less than this between them (log, see _ridge): a note
_COV_FLOOR = (4.0, 1.0, 1.0)  # variance floor (L, a, b): JPEG noise, frames not seen
_HUE_NAMES = ((8, "red"), (20, "orange"), (33, "yellow"), (78, "green"), (95, "teal"), (130, "blue"),
              (155, "purple"), (170, "magenta"), (180, "red"))


def colour_name(h: float, s: float, v: float) -> str:
    """A plain colour name for a mean HSV colour (OpenCV scale)."""
    if v < 60:
        return "black"
    if s < 60:
        return "white" if v > 110 else "grey"
    for top, name in _HUE_NAMES:
        if h < top:
            return name
    return "red"


@dataclass(frozen=True)
class DrumSamples:
    """Pixels sampled inside the drum: CIELAB colour (N, 3), height ``(cy - y) / R`` (N,) and
    whether a channel is clipped (>= 250, N bool; ``None``: unknown)."""

    lab: np.ndarray
    height: np.ndarray
    clipped: np.ndarray | None = None


def sample_drum_pixels(
    frames: Sequence[np.ndarray], rois: Sequence[DrumROI], per_frame: int = 12000, seed: int = 0,
    r_max: float = 0.94, camera_rotation_deg: float = 0.0, mirror: bool = False,
) -> DrumSamples:
    """Up to ``per_frame`` random pixels inside ``r_max`` R of each frame's drum; their height
    is measured in gravity's frame (``camera_rotation_deg``, ``mirror``: see ``vision.meter.Meter``)."""
    rng = np.random.default_rng(seed)
    parts = [p for p in (_frame_samples(img, roi, per_frame, rng, r_max) for img, roi in zip(frames, rois, strict=True))
             if p is not None]
    return _samples_in_gravity(parts, camera_rotation_deg, mirror)


def _frame_samples(img: np.ndarray, roi: DrumROI, per_frame: int, rng: np.random.Generator,
                   r_max: float = 0.94) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One frame's random drum pixels: CIELAB (N, 3), offsets from the drum centre in R (N, 2),
    clipped (N,); None when the drum has no pixels in the frame."""
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    inner = DrumROI(roi.cx_px, roi.cy_px, roi.r_px * r_max, roi.kind,
                    None if roi.half_w_px is None else roi.half_w_px * r_max,
                    None if roi.half_h_px is None else roi.half_h_px * r_max)
    yy, xx = np.nonzero(_mask_in_box(inner, box))
    if yy.size == 0:
        return None
    if yy.size > per_frame:
        pick = rng.choice(yy.size, per_frame, replace=False)
        yy, xx = yy[pick], xx[pick]
    px = img[y0:y1, x0:x1][yy, xx]
    off = np.stack([(xx + x0 - roi.cx_px) / roi.r_px, (yy + y0 - roi.cy_px) / roi.r_px], axis=1)
    return bgr_to_lab(px), off, px.max(axis=1) >= _CLIP_LEVEL


def _samples_in_gravity(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], camera_rotation_deg: float,
                        mirror: bool) -> DrumSamples:
    if not parts:
        raise VisionError("no drum pixels to learn colours from")
    t = gravity_matrix(camera_rotation_deg, mirror)
    up = np.array([0.0, -1.0]) if t is None else -t[1]  # image offset . up = height
    return DrumSamples(np.concatenate([p[0] for p in parts]).astype(np.float64),
                       np.concatenate([p[1] for p in parts]) @ up, np.concatenate([p[2] for p in parts]))


def _em(x: np.ndarray, n: int, seed: int, iters: int = 60) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gaussian mixture by EM (full covariances) from a seeded k-means start.

    Returns weights (n,), means (n, 3), covariances (n, 3, 3), hard labels (N,)."""
    cv2.setRNGSeed(seed)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.1)
    _, lbl, _ = cv2.kmeans(x.astype(np.float32), n, None, crit, 3, cv2.KMEANS_PP_CENTERS)  # type: ignore[call-overload, unused-ignore]  # stubs differ by opencv version
    resp = np.zeros((x.shape[0], n))
    resp[np.arange(x.shape[0]), lbl.ravel()] = 1.0
    floor = np.diag([1e-2, 1e-2, 1e-2])
    prev = -np.inf
    for _ in range(iters):
        nk = resp.sum(axis=0) + 1e-9
        w = nk / nk.sum()
        mu = (resp.T @ x) / nk[:, None]
        cov = np.empty((n, 3, 3))
        for j in range(n):
            d = x - mu[j]
            cov[j] = (resp[:, j, None] * d).T @ d / nk[j] + floor
        logp = np.empty((x.shape[0], n))
        for j in range(n):
            d = x - mu[j]
            inv = np.linalg.inv(cov[j])
            q = np.einsum("ni,ij,nj->n", d, inv, d)
            logp[:, j] = np.log(w[j]) - 0.5 * (q + np.log(np.linalg.det(cov[j])))
        top = logp.max(axis=1, keepdims=True)
        p = np.exp(logp - top)
        s = p.sum(axis=1, keepdims=True)
        resp = p / s
        ll = float((np.log(s) + top).mean())
        if ll - prev < 1e-5:
            break
        prev = ll
    return w, mu, cov, resp.argmax(axis=1)


def _mixture_logpdf(x: np.ndarray, w: np.ndarray, mu: np.ndarray, cov: np.ndarray) -> np.ndarray:
    out = np.full(x.shape[0], -np.inf)
    for j in range(w.shape[0]):
        d = x - mu[j]
        q = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov[j]), d)
        out = np.logaddexp(out, np.log(w[j]) - 0.5 * (q + np.log(np.linalg.det(cov[j]))))
    return out


def _ridge(w: np.ndarray, mu: np.ndarray, cov: np.ndarray, steps: int = 24) -> np.ndarray:
    """Pairwise continuity of the mixture: the lowest density on the segment between two
    means over the lower of the two end densities (log). Near 0: one material (shading,
    no valley between them); very negative: a valley, two materials."""
    n = w.shape[0]
    out = np.zeros((n, n))
    ts = np.linspace(0.0, 1.0, steps)[:, None]
    for i in range(n):
        for j in range(i + 1, n):
            line = mu[i] + ts * (mu[j] - mu[i])
            lp = _mixture_logpdf(line, w, mu, cov)
            out[i, j] = out[j, i] = float(lp.min() - min(lp[0], lp[-1]))
    return out


def _lab_to_bgr(lab: np.ndarray) -> tuple[int, int, int]:
    px = np.array([[[lab[0] * 255.0 / 100.0, lab[1] + 128.0, lab[2] + 128.0]]])
    bgr = cv2.cvtColor(np.clip(px, 0, 255).astype(np.uint8), cv2.COLOR_Lab2BGR)[0, 0]
    return int(bgr[0]), int(bgr[1]), int(bgr[2])


def _name_of(lab: np.ndarray) -> str:
    bgr = _lab_to_bgr(lab)
    h, s, v = cv2.cvtColor(np.array([[bgr]], np.uint8), cv2.COLOR_BGR2HSV)[0, 0]
    return colour_name(float(h), float(s), float(v))


def fit_colour_model(samples: DrumSamples, k: int = 2, seed: int = 0) -> tuple[ColourClass, ...]:
    """``k`` particle classes (sorted by name) and one reject class ``background``."""
    return _fit_colour_model(samples, k, seed)[0]


def _fit_colour_model(samples: DrumSamples, k: int, seed: int) -> tuple[tuple[ColourClass, ...], tuple[str, ...]]:
    """:func:`fit_colour_model` and its notes for the user (classes that may be wrongly split)."""
    if not 2 <= k <= 6:
        raise VisionError(f"k must be within 2..6, got {k}")
    n = k + 3
    if samples.lab.shape[0] < 50 * n:
        raise VisionError("too few drum pixels to learn colours from")
    scale = np.array([_L_WEIGHT_FIT, 1.0, 1.0])
    w, mu_f, cov_f, lbl = _em(samples.lab * scale, n, seed)
    mu = mu_f / scale
    cov = cov_f / np.outer(scale, scale)[None] + np.diag(_COV_FLOOR)[None]
    top = samples.height > 0.5
    top_share = float(top.mean())
    counts = np.bincount(lbl, minlength=n).astype(float)
    in_top = np.bincount(lbl[top], minlength=n).astype(float)
    t = np.where(counts > 0, in_top / np.maximum(counts, 1.0), 0.0)
    order = np.argsort(t)
    background = [j for j in range(n) if top_share > 0.02 and t[j] >= 0.5 * top_share and counts[j] > 0]
    particles = [j for j in order if j not in background and counts[j] > 0]
    if len(particles) < k:  # no empty space above the bed (top view?): the least "top" components
        particles = [int(j) for j in order[:k]]
        background = [j for j in range(n) if j not in particles]
    cap = list(background)  # the background seen above the bed
    ridge = _ridge(w, mu_f, cov_f)
    if samples.clipped is not None and len(particles) > k:
        # glare: a small component made largely of clipped pixels is no material of its own
        clip_share = np.bincount(lbl[samples.clipped], minlength=n) / np.maximum(counts, 1.0)
        biggest = max(counts[i] for i in particles)
        glare = [j for j in particles if clip_share[j] >= _GLARE_CLIPPED and counts[j] < _GLARE_WEIGHT * biggest]
        glare = glare[: len(particles) - k]
        particles = [j for j in particles if j not in glare]
        background.extend(glare)
    if background and len(particles) > k:
        keep = []
        biggest = max(counts[i] for i in particles)
        top_cap = list(background)  # the background seen above the bed (not the comps moved there below)
        for j in particles:
            to_bg = max(ridge[j, b] for b in top_cap)
            near = max((i for i in particles if i != j), key=lambda i: ridge[j, i])
            # darker than its nearest particle colour and closer to the background: a gap or shadow
            if to_bg > ridge[j, near] and mu[j, 0] < mu[near, 0] and counts[j] < biggest:
                background.append(j)
            else:
                keep.append(j)
        particles = keep if len(keep) >= k else particles
    groups = [[j] for j in particles]
    while len(groups) > k:  # single linkage on continuity: merge the pair with the shallowest valley
        best = None
        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                link = max(ridge[i, j] for i in groups[a] for j in groups[b])
                if best is None or link > best[0]:
                    best = (link, a, b)
        assert best is not None
        _, a, b = best
        groups[a] = groups[a] + groups[b]
        del groups[b]
    for g in groups:  # gaps and shadows in the bed: a member far darker than the class's main colour
        main = max(g, key=lambda j: counts[j])
        for j in list(g):
            if j != main and mu[j, 0] < _SHADOW_L_RATIO * mu[main, 0]:
                g.remove(j)
                background.append(j)
    _drop_bridges(groups, background, cap, mu_f, counts)
    total = counts.sum()
    named = []
    for gi, g in enumerate(groups):
        lab_mean = np.average(mu[g], axis=0, weights=counts[g])
        comps = tuple(_component(mu[j], cov[j], counts[j] / total) for j in g)
        named.append((_name_of(lab_mean), float(lab_mean[0]), comps, _lab_to_bgr(lab_mean), gi))
    named.sort(key=lambda x: (x[0], x[1]))
    names = [x[0] for x in named]
    classes = []
    name_of_group = {}
    for i, (name, _, comps, bgr, gi) in enumerate(named):
        if names.count(name) > 1:
            same = [j for j, m in enumerate(names) if m == name]
            rank = same.index(i)
            suffix = "dark" if rank == 0 else ("light" if rank == len(same) - 1 else f"mid{rank}")
            name = f"{name}-{suffix}"
        classes.append(ColourClass(name, display_bgr=bgr, lab=comps, max_distance=MAX_DISTANCE))
        name_of_group[gi] = name
    if background:
        comps = tuple(_component(mu[j], cov[j], max(counts[j], 1.0) / total) for j in background)
        classes.append(ColourClass("background", display_bgr=(40, 40, 40), lab=comps, reject=True))
    notes = []
    for a, b in itertools.combinations(range(len(groups)), 2):
        if groups[a] and groups[b] and max(ridge[i, j] for i in groups[a] for j in groups[b]) > _NO_VALLEY:
            x, y = sorted((name_of_group[a], name_of_group[b]))
            notes.append(f"classes {x!r} and {y!r} are not separated by a valley in colour: one material in light "
                         "and shade (a second one taken for background?), or two that differ only in lightness, "
                         "which shading mixes up; check the preview, their centroids may be wrong")
    return tuple(classes), tuple(notes)


def _between(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether point ``x`` lies on the segment from ``a`` to ``b`` (away from its ends)."""
    seg = b - a
    n2 = float(seg @ seg)
    if n2 <= 0.0:
        return False
    t = float((x - a) @ seg) / n2
    off = float(np.linalg.norm(x - a - t * seg))
    return _BRIDGE_T[0] <= t <= _BRIDGE_T[1] and off <= _BRIDGE_OFF * np.sqrt(n2)


def _drop_bridges(groups: list[list[int]], background: list[int], cap: list[int], mu: np.ndarray,
                  counts: np.ndarray) -> None:
    """Move to the background the class members (not a class's main component) that lie
    between the background and *another* class's main colour (in the fit space, lightness
    down-weighted): the mixed pixels at particle edges and in the gaps, which, with noise
    or blur, belong to either material. Counting them for one class pulls its centroid
    towards the other class's particles; dropping them drops the same rim of every
    particle, which leaves centroids where they are."""
    mains = [max(g, key=lambda j: counts[j]) for g in groups]
    for gi, g in enumerate(groups):
        others = [m for hi, m in enumerate(mains) if hi != gi]
        for j in [j for j in g if j != mains[gi]]:
            if any(_between(mu[j], mu[b], mu[m]) for b in cap for m in others):
                g.remove(j)
                background.append(j)


def _component(mean: np.ndarray, cov: np.ndarray, weight: float) -> LabComponent:
    c = 0.5 * (cov + cov.T)

    def r6(v: float) -> float:  # 6 significant digits: what the TOML holds, so it reads back equal
        return float(format(float(v), ".6g"))

    return LabComponent(
        tuple(r6(v) for v in mean),  # type: ignore[arg-type]
        tuple(r6(c[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))),  # type: ignore[arg-type]
        r6(max(float(weight), 1e-6)),
    )


SAMPLE_BUDGET = 40000
"""``suggest_classes`` takes about this many colour samples from the whole source (split over
the frames expected), so the colour model's fit does not grow with ``--frames``."""
MIN_SAMPLES_PER_FRAME = 50
KEEP_FRAMES = 24
"""``suggest_classes`` keeps at most this many frames (spread evenly over the source) for the
checks that need whole frames (particle size, the class opening); of the others it keeps
only their pixel samples, so ``classes suggest --frames 500`` is bounded in memory."""


def suggest_classes(
    frames: Iterable[np.ndarray] | np.ndarray, roi: DrumROI | None = None, k: int = 2, seed: int = 0,
    per_frame: int | None = None, rois: Sequence[DrumROI] | None = None,
    camera_rotation_deg: float | None = None, mirror: bool = False, n_frames: int | None = None,
) -> MeterConfig:
    """A ``MeterConfig`` with ``k`` learned classes from one or many BGR frames, the light
    they were seen in (``light_reference``, ``vision.photometric``) and the camera's turn
    (``camera_rotation_deg``; None: proposed by :func:`propose_rotation_deg`; a mirror
    cannot be seen in the frames, so ``mirror`` is the caller's).

    ``frames`` may be a stream (any iterable, read once: each frame's pixel samples are taken
    as it comes, and at most ``KEEP_FRAMES`` frames are held; ``n_frames`` = how many to
    expect, for the samples per frame). ``roi`` fixes the drum for every frame; ``rois``
    gives each frame's (already found); with neither, it is detected in each frame. The ROI
    is not written into the config (the meter finds the drum per frame size). ``warnings``
    names classes with no valley between their colours (see the module's step 6)."""
    if isinstance(frames, np.ndarray):
        frames = [frames]
    total = len(frames) if isinstance(frames, Sequence) else n_frames
    if rois is not None and isinstance(frames, Sequence) and len(rois) != len(frames):
        raise VisionError(f"{len(rois)} drum ROIs for {len(frames)} frames")
    # a budget of colour samples for the whole source, not per frame: up to 20 frames the same
    # 2,000+ a frame as before; 500 frames held 1,000,000 samples (the EM's arrays grew with
    # them: peak RSS 723 MB at 12 frames, 811 MB at 500 of the real PMMA video)
    per = per_frame or max(MIN_SAMPLES_PER_FRAME, SAMPLE_BUDGET // max(total or 12, 1))
    rng = np.random.default_rng(seed)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    light_px: list[np.ndarray] = []
    texture = np.zeros(2)
    kept: list[tuple[np.ndarray, DrumROI]] = []
    step = 1  # keep every step-th frame; doubled (and every other kept frame dropped) when full
    n = 0
    for i, img in enumerate(frames):
        if not (isinstance(img, np.ndarray) and img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8):
            shape = getattr(img, "shape", None)
            raise VisionError(f"classes suggest needs colour (BGR, 8-bit) frames, got shape {shape}")
        if rois is not None:
            if i >= len(rois):
                raise VisionError(f"{len(rois)} drum ROIs for more frames")
            r = rois[i]
        else:
            r = roi if roi is not None else detect_drum(img)
        part = _frame_samples(img, r, per, rng)
        if part is not None:
            parts.append(part)
        light_px.append(np.ascontiguousarray(img).reshape(-1, 3)[roi_sample_index(r, img.shape[:2])])
        texture += _texture_offset(img, r)
        if i % step == 0:
            kept.append((img, r))
            if len(kept) > KEEP_FRAMES:
                kept = kept[::2]
                step *= 2
        n += 1
    if n == 0:
        raise VisionError("classes suggest needs at least one frame")
    rot = _quarter_turn(texture / n) if camera_rotation_deg is None else float(camera_rotation_deg)
    samples = _samples_in_gravity(parts, rot, mirror)
    classes, notes = _fit_colour_model(samples, k, seed)
    px = np.concatenate(light_px)
    light = tuple(tuple(round(float(v), 2) for v in row) for row in light_quantiles(px))
    n_labels = len(counted_classes(classes)) + 1
    per_class = class_quantiles(px, sample_labels(class_lut(tuple(classes)), px, n_labels), n_labels)
    light_cls = tuple(tuple(round(float(v), 2) for v in row.ravel()) for row in per_class)
    cfg = MeterConfig(classes, None, "color", source="<suggested>", warnings=notes, light_reference=light,
                      light_reference_classes=light_cls, camera_rotation_deg=rot, mirror=mirror)
    kf, kr = [f for f, _ in kept], [r for _, r in kept]
    # the smallest estimate over (up to 8 of) the frames: in a segregated bed touching
    # particles of one class merge into longer runs, a mixed frame shows them one by one
    d = min((particle_diameter_px(cfg, img, r) for img, r in kept[:8]),
            key=lambda v: v if math.isfinite(v) else math.inf)
    stride = opening_stride(d)
    while stride >= 1:  # from the particle size's grid down, while the opening eats particles
        verdict = needs_opening(cfg, kf, kr, stride)
        if verdict is not None:
            # on a coarse grid the opening is always on: it costs nothing there (the grid is
            # faster than the full one), and the blurred gaps it drops may not move a centroid
            # on the frames given (a mixed bed) yet will on others (a segregated one)
            if verdict or stride > 1:
                cfg = replace(cfg, opening=True, stride=stride)
            break
        stride //= 2
    island = island_area_px(d)
    return replace(cfg, island_px=island) if island and needs_islands(cfg, kf, kr, island) else cfg


def island_area_px(particle_diameter: float) -> int:
    """The island filter's largest island (px) for particles ``particle_diameter`` px across:
    half a particle's area (a highlight is a small part of its particle, a whole particle of
    the lighter class is never an island; ``particle_diameter_px`` reads low on glossy shaded
    discs: 8.7 px for the suite's 12.4 px green discs, whose highlights are 16-20 px islands);
    0 when the size is unknown."""
    if not (math.isfinite(particle_diameter) and particle_diameter > 0):
        return 0
    return max(1, int(round(0.5 * math.pi * (0.5 * particle_diameter) ** 2)))


def needs_islands(cfg: MeterConfig, frames: Sequence[np.ndarray], rois: Sequence[DrumROI], island_px: int) -> bool:
    """Whether the island filter (``[meter] island_px``) moves a class centroid of ``cfg`` by
    more than ``OPENING_SHIFT`` R on any of these frames."""
    plain, filtered = replace(cfg, island_px=0), replace(cfg, island_px=island_px)
    for img, roi in zip(frames, rois, strict=True):
        a, b = plain.make_meter(roi).measure(img), filtered.make_meter(roi).measure(img)
        for sa, sb in zip(a.classes, b.classes, strict=True):
            if float(np.hypot(sa.cx_px - sb.cx_px, sa.cy_px - sb.cy_px)) / roi.r_px > OPENING_SHIFT:
                return True  # (NaN, a class too small on a frame: no vote)
    return False


def relearn_classes(
    cfg: MeterConfig, frames: Iterable[np.ndarray] | np.ndarray, rois: Sequence[DrumROI] | None = None,
    seed: int = 0, per_frame: int | None = None,
) -> MeterConfig:
    """``cfg`` with its classes learned again from recent frames of the live bed (when the
    light has moved beyond what ``vision.photometric`` maps back: ``lighting_changed:``),
    keeping the names, the order and the display colours of its counted classes, so the
    MI's first and second class stay the same particles: :func:`suggest_classes` on the
    frames (as many classes, the same camera turn and mirror), each new class taking the
    name of the old one nearest in colour (CIELAB means; the assignment with the smallest
    total distance). The light reference is the frames' (the new set-up); every other
    meter setting (stride, opening, validity) stays ``cfg``'s. A pure function: the caller
    builds the meter (``make_meter``, 1-3 s) and swaps it in between frames."""
    old = cfg.counted
    new = suggest_classes(frames, k=len(old), seed=seed, per_frame=per_frame, rois=rois,
                          camera_rotation_deg=cfg.camera_rotation_deg, mirror=cfg.mirror)
    fresh = new.counted
    if len(fresh) != len(old):
        raise VisionError(f"re-learning found {len(fresh)} particle classes in the frames, not {len(old)}")
    a = [class_mean_lab(c) for c in old]
    b = [class_mean_lab(c) for c in fresh]
    perm = min(itertools.permutations(range(len(old))),
               key=lambda p: sum(float(np.linalg.norm(a[i] - b[j])) for i, j in enumerate(p)))
    classes = tuple(replace(fresh[j], name=old[i].name, display_bgr=old[i].display_bgr) for i, j in enumerate(perm))
    taken = {c.name for c in classes}
    rejects = tuple(c if c.name not in taken else replace(c, name=f"{c.name}_reject")
                    for c in new.classes if c.reject)
    rows = new.light_reference_classes
    assert rows is not None  # (suggest_classes always writes it)
    return replace(cfg, classes=classes + rejects, light_reference=new.light_reference,
                   light_reference_classes=(rows[0], *(rows[1 + j] for j in perm)), warnings=new.warnings,
                   source=f"{cfg.source} (classes re-learned)")


def propose_rotation_deg(frames: Sequence[np.ndarray], rois: Sequence[DrumROI]) -> float:
    """The camera's turn (0, 90, 180 or 270 deg) from where the bed lies in the drum.

    The bed is where the drum is textured (particle edges): the centroid of the textured
    pixels of the drum's inside (to 0.85 R) lies off its centre towards gravity's down, turned
    by at most the bed's slope, so the nearest quarter turn is the camera's (the mean offset
    over the frames). 0 when the offset is under 5% of R (a full or empty drum shows no
    direction). Any other angle is the user's to write."""
    off = sum((_texture_offset(img, roi) for img, roi in zip(frames, rois, strict=True)), np.zeros(2))
    return _quarter_turn(off / max(len(frames), 1))


def _texture_offset(img: np.ndarray, roi: DrumROI) -> np.ndarray:
    """Offset (in R) of the textured pixels' centroid from the drum centre; zero for none."""
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    inner = DrumROI(roi.cx_px, roi.cy_px, 0.85 * roi.r_px)
    gray = cv2.cvtColor(np.ascontiguousarray(img[y0:y1, x0:x1]), cv2.COLOR_BGR2GRAY).astype(np.float32)
    mag = np.hypot(cv2.Sobel(gray, cv2.CV_32F, 1, 0), cv2.Sobel(gray, cv2.CV_32F, 0, 1))
    inside = _mask_in_box(inner, box)
    # textured: well above the noise floor (the quietest fifth of the drum), whatever the
    # particles' contrast -- unweighted, so a bright class does not pull the centroid
    floor = float(np.percentile(mag[inside], 20)) if inside.any() else 0.0
    ys, xs = np.nonzero(inside & (mag > max(12.0, 4.0 * floor)))
    if ys.size < 50:
        return np.zeros(2)
    return np.array([(xs.mean() + x0 - roi.cx_px) / roi.r_px, (ys.mean() + y0 - roi.cy_px) / roi.r_px])


def _quarter_turn(off: np.ndarray) -> float:
    if math.hypot(*off) < 0.05:
        return 0.0
    # gravity's down (0, 1) turned counter-clockwise on screen by a lies along (sin a, cos a)
    a = math.degrees(math.atan2(off[0], off[1]))
    return float((round(a / 90.0) * 90) % 360)


def particle_diameter_px(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> float:
    """A particle's diameter (px) in ``frame``, from the classified drum: each counted class's
    ``vision.census.run_diameter_px`` (for the chords of a disc at uniform offsets it is d),
    the smallest over the classes (a class whose particles merge through gaps of its colour
    gives longer runs). NaN when no class has runs."""
    sizes = class_diameters_px(cfg, frame, roi)
    finite = [d for d in sizes if math.isfinite(d)]
    return float(min(finite)) if finite else float("nan")


def drum_labels(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> np.ndarray:
    """The class map (0 = none, ``j + 1`` = ``cfg.classes[j]``) of the ROI's bounding box of
    ``frame``, 0 outside the drum."""
    box = roi_bbox(roi, frame.shape[:2])
    x0, y0, x1, y1 = box
    lab = classify(np.ascontiguousarray(frame[y0:y1, x0:x1]), cfg.classes)
    lab[~_mask_in_box(roi, box)] = 0
    return lab


def class_diameters_px(cfg: MeterConfig, frame: np.ndarray, roi: DrumROI) -> list[float]:
    """``vision.census.run_diameter_px`` of every class of ``cfg`` in the drum of ``frame``
    (NaN for a reject class or one without runs), in the config's class order."""
    lab = drum_labels(cfg, frame, roi)
    return [float("nan") if cls.reject else run_diameter_px(lab == c)
            for c, cls in enumerate(cfg.classes, start=1)]


def opening_stride(diameter_px: float) -> int:
    """The meter's stride for the class opening: a power of two, at most ``diameter_px /
    OPENING_GRID`` (so a particle spans that many grid pixels and the cross fits in it, while
    the gaps between particles, their colour blurred in, shrink to a grid pixel or two), at
    most 8; 1 for an unknown or small diameter."""
    s = 1
    while math.isfinite(diameter_px) and s < 8 and 2 * s <= diameter_px / OPENING_GRID:
        s *= 2
    return s


def needs_opening(
    cfg: MeterConfig, frames: Sequence[np.ndarray], rois: Sequence[DrumROI], stride: int = 1
) -> bool | None:
    """Whether the class opening (``[meter] opening`` on the grid of ``stride``) changes what
    ``cfg`` measures on these frames: a class centroid moving by more than ``OPENING_SHIFT`` R
    on any frame (thin rims and gaps in a class's colour: JPEG chroma blur between particles of
    one hue). None when it would leave a class less than ``OPENING_KEEP`` of its pixels
    (particles too small for the grid)."""
    plain, opened = replace(cfg, opening=False), replace(cfg, opening=True, stride=stride)
    moved = False
    for img, roi in zip(frames, rois, strict=True):
        a, b = plain.make_meter(roi).measure(img), opened.make_meter(roi).measure(img)
        for sa, sb in zip(a.classes, b.classes, strict=True):
            if sa.n_px > 0 and sb.n_px < OPENING_KEEP * sa.n_px:
                return None
            shift = float(np.hypot(sa.cx_px - sb.cx_px, sa.cy_px - sb.cy_px)) / roi.r_px
            moved = moved or shift > OPENING_SHIFT  # (NaN, a class too small on a frame: no vote)
    return moved


_NO_CLASS_BGR = ((45, 45, 45), (150, 150, 150), (110, 30, 110))  # candidates, the first preferred


def _no_class_bgr(class_bgr: Sequence[tuple[int, int, int]]) -> tuple[int, int, int]:
    """The preview's colour for *no class*: dark grey, unless a class is shown in about that
    colour (black particles), then the candidate farthest from every class colour."""
    def gap(c: tuple[int, int, int]) -> float:
        return min((float(np.abs(np.subtract(c, k)).max()) for k in class_bgr), default=255.0)

    first = _NO_CLASS_BGR[0]
    return first if gap(first) >= 60 else max(_NO_CLASS_BGR, key=gap)


def class_preview(image_bgr: np.ndarray, classes: Sequence[ColourClass], roi: DrumROI) -> np.ndarray:
    """The frame beside its class map (each class in its display colour; no class dark grey,
    or, when a class is shown about that colour, another colour the legend shows), with the
    drum circle and a legend: a check at a glance."""
    img = np.asarray(image_bgr)
    h, w = img.shape[:2]
    labels = classify(img, tuple(classes))
    counted = counted_classes(classes)
    cmap = np.empty((len(counted) + 1, 3), np.uint8)
    cmap[0] = none_bgr = _no_class_bgr([c.display_bgr for c in counted])
    for i, c in enumerate(counted):
        cmap[i + 1] = c.display_bgr
    painted = cmap[labels]
    left, right = img.copy(), painted
    th = max(1, int(round(min(h, w) / 300)))
    for pane in (left, right):
        cv2.circle(pane, (int(round(roi.cx_px)), int(round(roi.cy_px))), int(round(roi.r_px)), (0, 255, 255), th,
                   cv2.LINE_AA)
    out = np.hstack([left, right])
    fs = max(0.4, min(h, w) / 900.0)
    lh = int(30 * fs) + 6
    inside = _mask_in_box(roi, (0, 0, w, h))
    n_in = max(int(inside.sum()), 1)
    lines: list[tuple[str, tuple[int, int, int] | None]] = [
        (f"{c.name}  {100 * float(((labels == i + 1) & inside).sum()) / n_in:.1f}% of drum", c.display_bgr)
        for i, c in enumerate(counted)
    ]
    lines.append(("no class (background, rim, glare, shadow)", none_bgr))
    width = max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, fs, 1)[0][0] for t, _ in lines) + lh + 20
    panel = out[0: lh * len(lines) + 10, w: min(2 * w, w + width)]
    panel[...] = (panel * 0.3).astype(np.uint8)
    y = lh
    for text, colour in lines:
        x = w + 10
        if colour is not None:
            cv2.rectangle(out, (x, y - lh + 8), (x + lh - 8, y), colour, -1)
            cv2.rectangle(out, (x, y - lh + 8), (x + lh - 8, y), (255, 255, 255), 1)
        cv2.putText(out, text, (x + lh, y - 4), cv2.FONT_HERSHEY_SIMPLEX, fs, (255, 255, 255), 1, cv2.LINE_AA)
        y += lh
    return out

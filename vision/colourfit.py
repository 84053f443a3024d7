"""The colour model of ``classes suggest``: a Gaussian mixture in CIELAB over the bed's pixels,
split into particle classes and background (pure).

1. Fit a Gaussian mixture (EM, full covariances, ``k + 3`` components, k-means start) to
   the drum's sampled CIELAB colours with lightness down-weighted.
2. Components over-represented in the frames' empty region (the drum above the bed, in each
   frame's own frame of reference: ``vision.bedframe``) are background: the drum's back
   wall, rim, reflections -- unless they are *in* the bed more densely than in the empty
   drum (a particle colour seen where a frame's bed was taken for empty): those stay
   particles. Glare: a small component (under 0.25x the largest particle component) with 10%
   or more clipped samples (a channel >= 250) is no material of its own, as long as ``k``
   particle components remain.
3. The other components are grouped into ``k`` classes by continuity of the fitted
   density: two components joined by a ridge (no valley in the mixture's density on the
   segment between their means) are one material seen under different shading, two
   separated by a valley are two materials; single linkage merges the shallowest valleys
   first until ``k`` groups remain. So a white particle in shadow stays white, while white
   and pale teal, or dark and light green, stay apart. A particle component darker than,
   and joined more closely to the background than to, its nearest particle component
   (gaps, shadows) joins the background, and so does a member of a class far darker (L below half) than the
   class's main component (the gaps between particles, deep shadows), or one seen in the bed
   region markedly less often than the class's main component (``RIM_BED_RATIO``) and at the drum
   wall at least as often (``RIM_WALL_R``): the particles' rim against the dark drum at the bed's
   surface and their reflections in the drum wall.
   Last, a class member (not its main component) that lies between the background's
   colour and another class's main colour is dropped to the background: mixed edge and
   gap pixels, which noise or blur make either material's (see ``_drop_bridges``).
4. Each class keeps its Gaussians; the background is one reject class. The meter's
   lookup table assigns every colour to its most likely component, and counts it only
   within ``max_distance`` sigmas of a particle class.
5. Two classes with no valley between them (the density dips by less than ``_NO_VALLEY``)
   are a note for the user: either one material was split by its shading (the other
   taken for background, e.g. black particles on a dark drum) or two materials differ
   only in lightness (grey and white), which shading mixes up pixel by pixel.

Classes are named by colour and sorted by name, so the TOML is the same for any frames
of the same material pair.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.colours import ColourClass, LabComponent
from vision.errors import VisionError

__all__ = ["MAX_DISTANCE", "RIM_BED_RATIO", "RIM_WALL_R", "DrumSamples", "bed_shares", "class_members",
           "colour_name", "fit_colour_model", "is_rim", "member_ratios", "wall_shares"]

MAX_DISTANCE = 4.5
"""Reject distance of a suggested class (Mahalanobis, sigmas)."""

_L_WEIGHT_FIT = 0.5  # lightness weight in the space the mixture's k-means start sees
_SHADOW_L_RATIO = 0.5  # a class member darker than this x the class's main lightness is shadow/gap
RIM_BED_RATIO = 0.8
"""A class member (not its main component) whose samples lie in their frames' bed region
(``vision.bedframe``) less than this x as often as the main component's is the particles' rim
against the drum, not a material: the mixed pixels where the bed meets the dark drum (its surface,
the discs' reflections in the drum wall), which lie at the bed's margins. A particle colour,
whatever its shade, lies in the bed as the particles do (0.93-1.15 x on the bench's rigs; the
rims 0.65-0.68 x). The rule of ``vision.loro.rim_rule`` (the middle of the ratios that best tell
the rigs' rim members from their particle members) on the real rigs of the cross-rig bench
(docs/validation.md, section 15: checked leave-one-rig-out)."""
RIM_WALL_R = 0.8
"""... and whose samples lie at the drum wall (this x R from the centre, or further) at least as
often as the main component's: a rim is where the bed meets the drum and in the wall's
reflections (the bench's real rims 1.10-1.24 x their class's share there), while a dark shade of
the material lies where its particles lie (the shaded edges of pale teal discs under JPEG 30, off
the bed region 0.78 x as often as their class, lie at the wall 0.74 x: kept). Not chosen on data:
the class's own share at the wall is the reference."""
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
    """Pixels sampled inside the drum: CIELAB colour (N, 3), height ``(cy - y) / R`` (N,, in
    gravity's frame), whether a channel is clipped (>= 250, N bool), whether the pixel lies in
    its frame's empty region and in its bed (N bool each, ``vision.bedframe``; ``None``: unknown),
    and its distance from the drum's centre (N,, in R; ``None``: unknown)."""

    lab: np.ndarray
    height: np.ndarray
    clipped: np.ndarray | None = None
    empty: np.ndarray | None = None
    bed: np.ndarray | None = None
    radius: np.ndarray | None = None


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


@dataclass
class _Grouped:
    """The mixture and its components' first split: means (CIELAB and the fit space), covariances,
    sample counts and hard labels, the ridge, the background (``cap``: the part seen in the empty
    drum) and the particle components linked into ``k`` groups."""

    mu: np.ndarray
    mu_f: np.ndarray
    cov: np.ndarray
    counts: np.ndarray
    lbl: np.ndarray
    ridge: np.ndarray
    background: list[int]
    cap: list[int]
    groups: list[list[int]]


def _fit_colour_model(samples: DrumSamples, k: int, seed: int) -> tuple[tuple[ColourClass, ...], tuple[str, ...]]:
    """:func:`fit_colour_model` and its notes for the user (classes that may be wrongly split)."""
    m = _grouped(samples, k, seed)
    counts, background = m.counts, m.background
    bed, wall = bed_shares(samples, m.lbl, counts.shape[0]), wall_shares(samples, m.lbl, counts.shape[0])
    for g in m.groups:  # gaps, shadows and rims: a member far darker than the class's main colour, or its rim
        main = max(g, key=lambda j: counts[j])
        for j in list(g):
            dark = m.mu[j, 0] < _SHADOW_L_RATIO * m.mu[main, 0]
            if j != main and (dark or is_rim(*member_ratios(bed, wall, j, main))):
                g.remove(j)
                background.append(j)
    _drop_bridges(m.groups, background, m.cap, m.mu_f, counts)
    return _named_classes(m.groups, background, m.mu, m.cov, counts, m.ridge)


def class_members(samples: DrumSamples, k: int = 2, seed: int = 0) -> tuple[np.ndarray, list[tuple[int, list[int]]],
                                                                             np.ndarray, np.ndarray]:
    """The fit's particle groups before their shadows and rims are dropped (``vision.loro.rim_records``):
    the samples' hard labels, each group's main component and its other members, and every
    component's :func:`bed_shares` and :func:`wall_shares` (what :func:`is_rim` reads)."""
    m = _grouped(samples, k, seed)
    out = []
    for g in m.groups:
        main = max(g, key=lambda j: m.counts[j])
        out.append((main, [j for j in g if j != main]))
    n = m.counts.shape[0]
    return m.lbl, out, bed_shares(samples, m.lbl, n), wall_shares(samples, m.lbl, n)


def _grouped(samples: DrumSamples, k: int, seed: int) -> _Grouped:
    """Steps 1-3 of the module's doc up to the linking into ``k`` groups."""
    if not 2 <= k <= 6:
        raise VisionError(f"k must be within 2..6, got {k}")
    n = k + 3
    if samples.lab.shape[0] < 50 * n:
        raise VisionError("too few drum pixels to learn colours from")
    scale = np.array([_L_WEIGHT_FIT, 1.0, 1.0])
    w, mu_f, cov_f, lbl = _em(samples.lab * scale, n, seed)
    mu = mu_f / scale
    cov = cov_f / np.outer(scale, scale)[None] + np.diag(_COV_FLOOR)[None]
    counts = np.bincount(lbl, minlength=n).astype(float)
    background, particles = _empty_region_split(samples, lbl, counts, k)
    cap = list(background)  # the background seen in the empty drum
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
        top_cap = list(background)  # the background seen above the bed, with glare (not the comps moved there below)
        for j in particles:
            to_bg = max(ridge[j, b] for b in top_cap)
            near = max((i for i in particles if i != j), key=lambda i: ridge[j, i])
            # darker than its nearest particle colour and closer to the background: a gap or shadow
            if to_bg > ridge[j, near] and mu[j, 0] < mu[near, 0] and counts[j] < biggest:
                background.append(j)
            else:
                keep.append(j)
        particles = keep if len(keep) >= k else particles
    return _Grouped(mu, mu_f, cov, counts, lbl, ridge, background, cap, _link(particles, ridge, k))


def is_rim(bed_ratio: float | np.ndarray, wall_ratio: float | np.ndarray,
           threshold: float = RIM_BED_RATIO) -> bool | np.ndarray:
    """A class member is the particles' rim: seen in the bed region under ``threshold`` x as often as
    its class's main component (``bed_ratio``) and at the wall at least as often (``wall_ratio``;
    both from :func:`member_ratios`). NaN (unknown) gives no verdict: kept. Element-wise on arrays."""
    out = (np.asarray(bed_ratio) < threshold) & (np.asarray(wall_ratio) >= 1.0)
    return bool(out) if out.ndim == 0 else out


def member_ratios(bed: np.ndarray, wall: np.ndarray, j: int, main: int) -> tuple[float, float]:
    """Component ``j``'s :func:`bed_shares` and :func:`wall_shares` over its class's main component's
    (``main``): what :func:`is_rim` reads. Both shares zero reads 1.0 (as often); NaN stays NaN."""
    def ratio(a: float, b: float) -> float:
        if not (math.isfinite(a) and math.isfinite(b)):
            return math.nan
        return 1.0 if a == b else (a / b if b > 0 else math.inf)
    return ratio(float(bed[j]), float(bed[main])), ratio(float(wall[j]), float(wall[main]))


def wall_shares(samples: DrumSamples, lbl: np.ndarray, n: int) -> np.ndarray:
    """Each of the ``n`` components' share of its samples (hard labels ``lbl``) at :data:`RIM_WALL_R`
    or further from the drum's centre (NaN without ``samples.radius`` or for an empty component)."""
    return _shares(lbl, None if samples.radius is None else samples.radius >= RIM_WALL_R, n)


def bed_shares(samples: DrumSamples, lbl: np.ndarray, n: int) -> np.ndarray:
    """Each of the ``n`` components' share of its samples (hard labels ``lbl``) in its frame's bed
    region (``samples.bed``; NaN without it or for an empty component: no verdict)."""
    return _shares(lbl, samples.bed, n)


def _shares(lbl: np.ndarray, where: np.ndarray | None, n: int) -> np.ndarray:
    """Each of the ``n`` components' share of its samples (hard labels ``lbl``) where ``where`` holds
    (NaN for all without ``where``, and for an empty component)."""
    if where is None:
        return np.full(n, np.nan)
    counts = np.bincount(lbl, minlength=n).astype(float)
    hits = np.bincount(lbl[where], minlength=n).astype(float)
    return np.where(counts > 0, hits / np.maximum(counts, 1.0), np.nan)


def _empty_region_split(samples: DrumSamples, lbl: np.ndarray, counts: np.ndarray,
                        k: int) -> tuple[list[int], list[int]]:
    """Background and particle components: the background is over-represented in the frames'
    empty regions (``samples.empty``; without it, the top cap above 0.5 R), and seen there at
    least as densely as in the bed (``samples.bed``): a colour denser in the bed than in the
    empty drum is a particle's, whatever a frame's empty region held (its bed on the other
    side, a full drum). Without an empty region (a top view?) the ``k`` least empty ones are
    the particles."""
    n = counts.shape[0]
    top = samples.empty if samples.empty is not None else samples.height > 0.5
    top_share = float(top.mean())
    in_top = np.bincount(lbl[top], minlength=n).astype(float)
    t = np.where(counts > 0, in_top / np.maximum(counts, 1.0), 0.0)
    order = np.argsort(t)
    background = [j for j in range(n) if top_share > 0.02 and t[j] >= 0.5 * top_share and counts[j] > 0]
    if samples.bed is not None and samples.bed.any() and top.any():
        bed_density = np.bincount(lbl[samples.bed], minlength=n) / float(samples.bed.sum())
        empty_density = in_top / float(top.sum())
        background = [j for j in background if bed_density[j] <= empty_density[j]]
    particles = [int(j) for j in order if j not in background and counts[j] > 0]
    if len(particles) < k:
        particles = [int(j) for j in order[:k]]
        background = [j for j in range(n) if j not in particles]
    return background, particles


def _link(particles: list[int], ridge: np.ndarray, k: int) -> list[list[int]]:
    """Single linkage on continuity: merge the pair of groups with the shallowest valley until ``k`` remain."""
    groups = [[j] for j in particles]
    while len(groups) > k:
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
    return groups


def _named_classes(groups: list[list[int]], background: list[int], mu: np.ndarray, cov: np.ndarray,
                   counts: np.ndarray, ridge: np.ndarray) -> tuple[tuple[ColourClass, ...], tuple[str, ...]]:
    """The classes (named by colour, sorted; a reject class ``background``) and the notes."""
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

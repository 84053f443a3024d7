"""Leave-one-rig-out checks of the thresholds chosen on data (pure).

A threshold chosen on the rigs the project can see may only fit them. Each is therefore
chosen by a stated rule, and checked the way a new rig would meet it: for every rig of the
cross-rig bench (``vision.rigbench``), the rule is applied to the *other* rigs' records, and
the threshold it gives is measured on the rig left out.

- ``vision.photometric.MAX_CLASS_SPREAD`` and ``MAX_DISAGREEMENT`` (a light no gain per
  channel explains: ``lighting_changed:unexplained_cast``): :func:`spread_rule` -- twice the
  99th percentile of what the set-up light gives, each on its own. Measured on the rig left
  out, the two together: the share of its set-up-light estimates over either threshold (the
  aim: at most 2 %), and the share of its estimates under a tone curve (display value ** 1.8,
  no gain explains it) flagged.
- ``vision.bedframe.EMPTY_DENSITY`` (the empty drum: texture under this share of the bed's):
  :func:`density_rule` -- the ratio that best tells the upper drum's empty samples from its
  bed samples (the most balanced accuracy, the source's class map as truth). Measured on the
  rig left out: the share of its bed samples in the upper drum called empty (particles that
  could be learned as background) and the share of its empty samples found.
- ``vision.colourfit.RIM_BED_RATIO`` (a class member seen in the bed less than this x as often as
  its class's main colour is the particles' rim, not a material): :func:`rim_rule` -- the middle of
  the ratios that best tell the rim members of the classes (before they are dropped) from the
  particle members (balanced accuracy; a member is a rim when a quarter or more of its samples lie
  on no particle of the real frames' class map, which counts the discs' dark edges as theirs: the
  synthetic rigs' class maps are the drawn discs without their blurred edges, so their members
  are only measured, not used to choose). Measured on the rig left out with the shipped rule
  (``vision.colourfit.is_rim``: under that bed ratio *and* at the wall at least as often as the
  class, ``RIM_WALL_R``, not chosen on data): the share of its rim members dropped and of its
  particle members kept (synthetic: of its members kept).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from vision.bedframe import EMPTY_HEIGHT, FrameSamples, density_ratio, frame_samples, in_gravity
from vision.colourfit import class_members, is_rim, member_ratios
from vision.rigs import RigFrame
from vision.roi import detect_drum
from vision.suggest import MIN_SAMPLES_PER_FRAME, SAMPLE_BUDGET

__all__ = ["DENSITY_GRID", "RIM_GRID", "RIM_OFF", "density_records", "density_rule", "leave_one_rig_out",
           "rim_records", "rim_rule", "spread_rule"]

DENSITY_GRID = np.round(np.arange(0.05, 0.81, 0.05), 2)
"""The ratios :func:`density_rule` chooses from."""

RIM_GRID = np.round(np.arange(0.5, 1.001, 0.05), 2)
"""The ratios :func:`rim_rule` chooses from."""

RIM_OFF = 0.25
"""A class member is a rim (the truth :func:`rim_rule` is chosen on) when this share of its samples
or more lies on no particle of the class map (the real rigs' members: 0-9 % or 35-42 %)."""


def spread_rule(spreads: Sequence[float]) -> float:
    """Twice the 99th percentile of the set-up light's spreads (NaN: an estimate flagged for
    another cause, left out)."""
    v = np.asarray([s for s in spreads if math.isfinite(s)])
    return 2.0 * float(np.percentile(v, 99)) if v.size else math.nan


def density_rule(ratio: np.ndarray, is_bed: np.ndarray) -> float:
    """The ratio of :data:`DENSITY_GRID` with the best balanced accuracy at telling empty (under
    it) from bed (at or over it) in the upper drum's samples."""
    best = (-1.0, math.nan)
    for t in DENSITY_GRID:
        empty = ratio < t
        acc = 0.5 * (float(empty[~is_bed].mean()) if (~is_bed).any() else 0.0) + \
            0.5 * (float((~empty[is_bed]).mean()) if is_bed.any() else 0.0)
        if acc > best[0]:
            best = (acc, float(t))
    return best[1]


def density_records(frames: Sequence[RigFrame], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The upper-drum samples of ``frames`` (above ``EMPTY_HEIGHT`` in each frame's own frame of
    reference, as ``classes suggest`` samples them): each one's texture density ratio and
    whether the source's class map puts a particle there."""
    rng = np.random.default_rng(seed)
    ratios, beds = [], []
    for f in frames:
        if f.classes is None:
            continue
        roi = detect_drum(f.image)
        part = frame_samples(f.image, roi, 4000, rng)
        if part is None:
            continue
        up = in_gravity([part], None, False)[0].height > EMPTY_HEIGHT
        xs = np.clip(np.round(part.off[:, 0] * roi.r_px + roi.cx_px).astype(int), 0, f.image.shape[1] - 1)
        ys = np.clip(np.round(part.off[:, 1] * roi.r_px + roi.cy_px).astype(int), 0, f.image.shape[0] - 1)
        ratios.append(_ratio(part)[up])
        beds.append(f.classes[ys, xs][up] > 0)
    if not ratios:
        return np.empty(0), np.empty(0, bool)
    return np.concatenate(ratios), np.concatenate(beds)


def rim_rule(ratio: np.ndarray, is_rim: np.ndarray) -> float:
    """The middle of the ratios of :data:`RIM_GRID` with the best balanced accuracy at telling rim
    members (under it) from particle members (at or over it); rows of unknown truth (NaN) left out."""
    known = np.isfinite(is_rim)
    r, rim = np.asarray(ratio)[known], np.asarray(is_rim)[known] > 0.5
    acc = np.array([0.5 * (float((r[rim] < t).mean()) if rim.any() else 0.0)
                    + 0.5 * (float((r[~rim] >= t).mean()) if (~rim).any() else 0.0) for t in RIM_GRID])
    best = RIM_GRID[np.isclose(acc, acc.max())]
    return float(np.round(0.5 * (best.min() + best.max()), 3))


def rim_records(frames: Sequence[RigFrame], edges_labelled: bool = True,
                seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The class members of the colour model ``classes suggest`` fits to ``frames`` (sampled as it
    samples them), before their shadows and rims are dropped: each member's bed share and wall
    share over its class's main component's (``vision.colourfit.member_ratios``, what the shipped
    rule ``is_rim`` reads) and whether it is a rim (1.0: a share :data:`RIM_OFF` or more of its
    samples on no particle of the frames' class maps; 0.0 not; NaN unknown: ``edges_labelled``
    False, class maps without the particles' edges)."""
    rng = np.random.default_rng(seed)
    per = max(MIN_SAMPLES_PER_FRAME, SAMPLE_BUDGET // max(len(frames), 1))
    parts, on = [], []
    for f in frames:
        roi = detect_drum(f.image)
        part = frame_samples(f.image, roi, per, rng)
        if part is None:
            continue
        parts.append(part)
        if f.classes is None:
            on.append(np.full(part.off.shape[0], np.nan))
            continue
        xs = np.clip(np.round(part.off[:, 0] * roi.r_px + roi.cx_px).astype(int), 0, f.image.shape[1] - 1)
        ys = np.clip(np.round(part.off[:, 1] * roi.r_px + roi.cy_px).astype(int), 0, f.image.shape[0] - 1)
        on.append((f.classes[ys, xs] > 0).astype(float))
    if not parts:
        return np.empty(0), np.empty(0), np.empty(0)
    lbl, groups, bed, wall = class_members(in_gravity(parts, None, False)[0])
    particle = np.concatenate(on)
    ratios, walls, truth = [], [], []
    for main, members in groups:
        for j in members:
            b, w = member_ratios(bed, wall, j, main)
            ratios.append(b)
            walls.append(w)
            off = 1.0 - float(np.mean(particle[lbl == j]))
            truth.append(float(off >= RIM_OFF) if edges_labelled and math.isfinite(off) else np.nan)
    return np.asarray(ratios, float), np.asarray(truth, float), np.asarray(walls, float)


def _rim_row(mine: Mapping, others: Sequence[Mapping]) -> dict:
    """The rim threshold chosen on ``others``' records and measured on ``mine``'s."""
    recs = [o for o in others if len(o.get("rim_ratio", ()))]
    r, truth = np.asarray(mine.get("rim_ratio", ()), float), np.asarray(mine.get("rim_truth", ()), float)
    if not recs or not r.size:
        return {}
    t = rim_rule(np.concatenate([np.asarray(o["rim_ratio"], float) for o in recs]),
                 np.concatenate([np.asarray(o["rim_truth"], float) for o in recs]))
    # the shipped rule: under the bed threshold chosen without this rig AND at the wall (no wall share
    # recorded: the bed condition alone)
    wall = np.asarray(mine.get("rim_wall", np.ones_like(r)), float)
    dropped = np.asarray(is_rim(r, wall, t), bool)
    rim, part, unknown = truth > 0.5, truth <= 0.5, ~np.isfinite(truth)
    return {"rim_threshold": t,
            "rims_dropped": float(dropped[rim].mean()) if rim.any() else math.nan,
            "particles_kept": float((~dropped[part]).mean()) if part.any() else math.nan,
            "unknown_kept": float((~dropped[unknown]).mean()) if unknown.any() else math.nan}


def _ratio(part: FrameSamples) -> np.ndarray:
    return np.nan_to_num(density_ratio(part), nan=1.0)


def leave_one_rig_out(records: Mapping[str, Mapping]) -> dict:
    """Per rig (``records[rig]``: ``setup_spreads`` and ``curve_spreads`` as (spread,
    disagreement) pairs, and ``density_ratio`` / ``density_bed`` when known), each rule chosen on
    the other rigs and measured on it; ``all``: the rules on every rig (the values in the code)."""
    out: dict = {"rigs": {}}
    names = list(records)
    for rig in names:
        others = [records[r] for r in names if r != rig]
        tau = (spread_rule([p[0] for o in others for p in o["setup_spreads"]]),
               spread_rule([p[1] for o in others for p in o["setup_spreads"]]))
        mine = records[rig]
        row = {"spread_threshold": tau[0], "disagreement_threshold": tau[1],
               "setup_flagged": _share_over(mine["setup_spreads"], tau),
               "curve_flagged": _share_over(mine["curve_spreads"], tau)}
        dens = [o for o in others if len(o.get("density_ratio", ()))]
        if len(mine.get("density_ratio", ())) and dens:
            t = density_rule(np.concatenate([np.asarray(o["density_ratio"]) for o in dens]),
                             np.concatenate([np.asarray(o["density_bed"], bool) for o in dens]))
            r, b = np.asarray(mine["density_ratio"]), np.asarray(mine["density_bed"], bool)
            row |= {"density_threshold": t, "bed_called_empty": float((r[b] < t).mean()) if b.any() else math.nan,
                    "empty_found": float((r[~b] < t).mean()) if (~b).any() else math.nan}
        out["rigs"][rig] = row | _rim_row(mine, others)
    allr = list(records.values())
    out["all"] = {"spread_threshold": spread_rule([p[0] for o in allr for p in o["setup_spreads"]]),
                  "disagreement_threshold": spread_rule([p[1] for o in allr for p in o["setup_spreads"]])}
    dens = [o for o in allr if len(o.get("density_ratio", ()))]
    if dens:
        out["all"]["density_threshold"] = density_rule(
            np.concatenate([np.asarray(o["density_ratio"]) for o in dens]),
            np.concatenate([np.asarray(o["density_bed"], bool) for o in dens]))
    rims = [o for o in allr if len(o.get("rim_ratio", ()))]
    if rims:
        out["all"]["rim_threshold"] = rim_rule(np.concatenate([np.asarray(o["rim_ratio"], float) for o in rims]),
                                               np.concatenate([np.asarray(o["rim_truth"], float) for o in rims]))
    return out


def _share_over(pairs: Sequence[tuple[float, float]], tau: tuple[float, float]) -> float:
    """The share of (spread, disagreement) ``pairs`` over either threshold of ``tau`` (NaN: an
    estimate flagged for another cause -- saturated, too dark, out of range -- counts as flagged)."""
    if not pairs:
        return math.nan
    n = sum(1 for s, d in pairs if not (math.isfinite(s) and s <= tau[0] and d <= tau[1]))
    return n / len(pairs)

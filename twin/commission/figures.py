"""The commissioning report's pictures, each a PNG ``data:`` URI: the class preview, the census overlay
(every traced particle's outline where it was found), the calibration curve, the twin's frame beside a
camera frame. Drawn from what ``twin.commission.steps`` found; no I/O."""

from __future__ import annotations

import base64
import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from twin.report.figures import axes, png

TRACE_BGR = ((0, 255, 255), (255, 0, 255), (0, 255, 0), (255, 128, 0), (0, 128, 255), (255, 255, 0))
"""Outline colours of the classes' traced particles in the census overlay (class order)."""
MAX_SIDE_PX = 900  # pictures wider or taller than this are scaled down (the report stays a few MB)


def image_uri(img: np.ndarray) -> str:
    """A BGR image as a PNG data URI (scaled to at most ``MAX_SIDE_PX``)."""
    h, w = img.shape[:2]
    s = min(1.0, MAX_SIDE_PX / max(h, w))
    if s < 1.0:
        img = cv2.resize(img, (int(w * s), int(h * s)), interpolation=cv2.INTER_AREA)
    ok, enc = cv2.imencode(".png", img)
    if not ok:
        raise ValueError("cannot encode a picture as PNG")
    return "data:image/png;base64," + base64.b64encode(enc.tobytes()).decode("ascii")


def _label(img: np.ndarray, text: str, y: int) -> None:
    cv2.putText(img, text, (10, y), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 4, cv2.LINE_AA)
    cv2.putText(img, text, (10, y), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)


def census_overlay(frame: np.ndarray, traced: Sequence[Sequence[Any]], names: Sequence[str],
                   kinds: Sequence[str], frame_index: int) -> np.ndarray:
    """``frame`` with the outline of every particle traced in it (``twin.suggest_mixer.Traced`` per
    class) in its class's ``TRACE_BGR``, and a legend: each class's name, shape and how many traced."""
    out = frame.copy()
    for k, per in enumerate(traced):
        col = TRACE_BGR[k % len(TRACE_BGR)]
        for t in per:
            if t.frame != frame_index:
                continue
            cnts, _ = cv2.findContours(t.crop.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            cv2.drawContours(out, [c + np.array([t.x_px, t.y_px]) for c in cnts], -1, col, 2, cv2.LINE_AA)
    for k, (name, kind) in enumerate(zip(names, kinds, strict=True)):
        n = sum(1 for t in traced[k] if t.frame == frame_index)
        y = 28 + 26 * k
        cv2.rectangle(out, (10, y - 14), (26, y + 2), TRACE_BGR[k % len(TRACE_BGR)], -1)
        _label(out, f"   {name}: {kind.replace('_', ' ')}, {n} traced here ({len(traced[k])} in all)", y)
    return out


def busiest_frame(traced: Sequence[Sequence[Any]]) -> int:
    """The frame in which the most particles were traced (0 when none)."""
    counts: dict[int, int] = {}
    for per in traced:
        for t in per:
            counts[t.frame] = counts.get(t.frame, 0) + 1
    return max(counts, key=lambda f: (counts[f], -f)) if counts else 0


def calibration_curve(history: Sequence[tuple[float, float, float]], target_deg: float, tol_deg: float,
                      chosen: tuple[float, float] | None, range_deg: tuple[float, float] | None) -> str:
    """Each calibration run's slope (deg, its magnitude) against its sliding friction (log), coloured by
    its rolling friction; the target with its tolerance band, the reachable range, the chosen run."""
    fig, ax = axes("free-surface slope (deg)", (6.4, 3.2))
    ax.set_xlabel("sliding friction (log scale); colour: rolling friction")
    ax.axhspan(abs(target_deg) - tol_deg, abs(target_deg) + tol_deg, color="#c8e6c9", label="target +- tolerance")
    ax.axhline(abs(target_deg), color="#2e7d32", lw=1.5, label=f"target (camera) {abs(target_deg):.1f} deg")
    if range_deg is not None and all(math.isfinite(v) for v in range_deg):
        for v in range_deg:
            ax.axhline(v, color="#9e9e9e", ls=":", lw=1.0)
    h = [x for x in history if math.isfinite(x[2])]
    if h:
        sc = ax.scatter([x[0] for x in h], [x[2] for x in h], c=[x[1] for x in h], cmap="viridis", vmin=0.0,
                        vmax=max(1.0, max(x[1] for x in h)), s=40, zorder=3, label="twin runs")
        fig.colorbar(sc, ax=ax, pad=0.01)
        ax.set_xscale("log")
    if chosen is not None:
        ax.plot([chosen[0]], [chosen[1]], "*", color="#c62828", ms=16, zorder=4, label="calibration")
    if not h:
        ax.text(0.5, 0.5, "no calibration run", transform=ax.transAxes, ha="center", color="#c62828")
    ax.legend(loc="best", fontsize=7)
    return png(fig)


def side_by_side(camera: np.ndarray, twin: np.ndarray) -> np.ndarray:
    """A camera frame and the twin's rendered frame beside each other at one height, each labelled."""
    h = min(camera.shape[0], twin.shape[0], MAX_SIDE_PX)
    a = cv2.resize(camera, (int(camera.shape[1] * h / camera.shape[0]), h), interpolation=cv2.INTER_AREA)
    b = cv2.resize(twin, (int(twin.shape[1] * h / twin.shape[0]), h), interpolation=cv2.INTER_AREA)
    _label(a, "camera", h - 14)
    _label(b, "twin (rendered, the camera's meter)", h - 14)
    return np.hstack([a, np.full((h, 8, 3), 255, np.uint8), b])


__all__ = ["MAX_SIDE_PX", "TRACE_BGR", "busiest_frame", "calibration_curve", "census_overlay", "image_uri",
           "side_by_side"]

"""Where a rig's class centroid error comes from: the labelled class's pixels split by the bed.

A diagnosis for ``drumtwin bench vision --rigs`` (docs/validation.md section 15): learns the
rig's classes as the bench does (``classes suggest`` on its 12 set-up frames), measures its
frames at the set-up light and, for the frames labelled by the pair's colour ``--colour``
(default 1: the second, e.g. orange/black's black discs), prints the labelled class's centroid
error (% of R against the labels') as the meter has it and with pixels left out:

- ``off-bed``: the class's pixels more than 3 px from any disc of the rig's truth class map
  (``RigFrame.classes``: the drum's haze, rim, scratches, hub), all / at >= 0.9 R / below 0.9 R;
- ``inset``: every class pixel beyond 0.95 R or 0.9 R (a smaller ROI);
- ``clean``: the off-bed pixels and the in-bed pixels that are not the labelled colour's discs;

and the shares of the class's pixels that are off the bed (all, >= 0.9 R) and in the bed but
not its discs. The truth map is used only here, never by the meter::

    PYTHONPATH=. .venv/bin/python -m scripts.rig_offbed orange-black [--colour 1]
"""

from __future__ import annotations

import argparse
import math

import cv2
import numpy as np

from vision.rigbench import _pair_colours, load_source, rig_setup
from vision.rigs import RigSpec, make_rig, prepare_source, setup_indices

COLUMNS = ("meter", "no off-bed", "no off-bed >=.9R", "no off-bed <.9R", "inset .95", "inset .9", "clean",
           "% off-bed", "% off-bed >=.9R", "% in-bed other")


def _err(x: np.ndarray, y: np.ndarray, truth: tuple[float, float], r_px: float) -> float:
    """The centroid of pixels ``x``, ``y`` against ``truth``, in % of R."""
    return 100.0 * math.hypot(float(x.mean()) - truth[0], float(y.mean()) - truth[1]) / r_px


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("rig", help="a rig of the bench, e.g. orange-black or orange-black/rot180")
    ap.add_argument("--colour", type=int, default=1, help="the pair's colour whose labelled frames to split (0 or 1)")
    a = ap.parse_args()
    pair, _, cam = a.rig.partition("/")
    spec = RigSpec(pair, cam or "plain")
    src = load_source()
    prep = prepare_source(src)
    frames = list(make_rig(spec, src, prep))
    pick = set(setup_indices(len(frames)))
    setup = rig_setup([f.image for i, f in enumerate(frames) if i in pick], _pair_colours(pair, prep.colours))
    meter = setup.config.make_meter()
    k = setup.index[a.colour]
    print(f"rig {a.rig}: classes {', '.join(setup.names)}; frames labelled by colour {a.colour}")
    print("frame | " + " | ".join(COLUMNS))
    rows = []
    for f in frames:
        meter.measure(f.image)  # in time order, as the bench does (the light tracker's state)
        if f.labelled != a.colour or f.classes is None:
            continue
        g = meter._geoms[f.image.shape[:2]]  # the meter's own label map (private: a diagnosis)
        lab, _, (x0, y0) = meter._grid_labels(f.image, g, 0, len(g.first), 0, int(g.last.max()))
        yy, xx = np.nonzero(lab == k + 1)
        x, y = x0 + xx * meter.stride, y0 + yy * meter.stride
        rr = np.hypot(x - g.roi.cx_px, y - g.roi.cy_px) / g.roi.r_px
        near = cv2.dilate((f.classes > 0).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
        off = ~near[y, x]
        other = near[y, x] & (f.classes[y, x] != a.colour + 1)
        keeps = (np.ones_like(off), ~off, ~(off & (rr >= 0.9)), ~(off & (rr < 0.9)), rr < 0.95, rr < 0.9, ~off & ~other)
        row = (*(_err(x[s], y[s], f.truth_px, f.r_px) for s in keeps),
               100.0 * off.mean(), 100.0 * (off & (rr >= 0.9)).mean(), 100.0 * other.mean())
        rows.append(row)
        print(f"{f.name} | " + " | ".join(f"{v:.2f}" for v in row))
    arr = np.array(rows)
    print("within 3 % of R: " + ", ".join(f"{c} {int((arr[:, i] < 3.0).sum())}/{len(arr)}"
                                         for i, c in enumerate(COLUMNS[:7])))
    print("shares of the class's pixels: " + ", ".join(f"{c} {arr[:, i].min():.1f}-{arr[:, i].max():.1f}"
                                                     for i, c in enumerate(COLUMNS[7:], start=7)))


if __name__ == "__main__":
    main()

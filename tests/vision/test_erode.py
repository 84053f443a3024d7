"""The optional one-pixel class erosion (``[meter] erode``): exact in the compiled pass,
shared with the Lacey baseline, and what it is for -- rims and gaps that JPEG chroma blur
gives the wrong class."""

import math

import numpy as np
import pytest

from vision.colours import DEFAULT_CLASSES, classify
from vision.lacey import LaceyMeter
from vision.meter import Meter
from vision.moments import class_tables, erode_labels, frame_moments, row_spans
from vision.roi import _mask_in_box, roi_bbox
from vision.suggest import suggest_classes
from vision.synthetic import drum_frame, particle_drum, perturb


def test_erode_labels_drops_thin_structures_only():
    lab = np.zeros((9, 12), np.uint8)
    lab[1:8, 1:6] = 1  # a 7 x 5 block keeps its 5 x 3 core
    lab[4, 7:11] = 2  # a one-pixel line vanishes
    out = erode_labels(lab)
    assert (out[2:7, 2:5] == 1).all() and out.sum() == 15
    assert not (out == 2).any()


@pytest.mark.parametrize("step", [1, 2, 3])
def test_compiled_erosion_matches_the_label_map(step):
    img = drum_frame((320, 240), mix=0.6, seed=2)
    roi = Meter().measure(img).roi
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    inside = _mask_in_box(roi, box)[::step, ::step]
    first, last = row_spans(inside)
    tables = class_tables(DEFAULT_CLASSES)
    shape = ((inside.shape[0] * step >> 3) + 1, (inside.shape[1] * step >> 3) + 1)
    occ_plain, occ_eroded = np.zeros(shape, np.int32), np.zeros(shape, np.int32)
    plain = frame_moments(img, tables, (x0, y0), first, last, step, occupancy=occ_plain)
    eroded = frame_moments(img, tables, (x0, y0), first, last, step, occupancy=occ_eroded, erode=True)
    sub = np.ascontiguousarray(img[y0:y1:step, x0:x1:step][: inside.shape[0], : inside.shape[1]])
    lab = erode_labels(np.where(inside, classify(sub, DEFAULT_CLASSES), 0))
    ys, xs = np.mgrid[0 : lab.shape[0], 0 : lab.shape[1]]
    X, Y = x0 + xs * step, y0 + ys * step
    for k in (1, 2):
        m = lab == k
        want = [m.sum(), X[m].sum(), Y[m].sum(), (X[m] ** 2).sum(), (Y[m] ** 2).sum(), (X[m] * Y[m]).sum()]
        assert eroded[k - 1].tolist() == [int(v) for v in want]
        assert 0.5 * plain[k - 1, 0] < eroded[k - 1, 0] < plain[k - 1, 0]
    assert (occ_plain == occ_eroded).all()  # the free surface sees the pixels before the erosion


def test_lacey_uses_the_same_eroded_labels():
    img = drum_frame((320, 240), mix=0.0, seed=1)
    roi = Meter().measure(img).roi
    a = LaceyMeter(roi=roi).measure(img)
    b = LaceyMeter(roi=roi, erode=True).measure(img)
    assert math.isfinite(a.m) and math.isfinite(b.m) and a.s0_2 != b.s0_2


def test_erosion_removes_jpeg_chroma_rims_on_a_same_hue_pair():
    """Dark vs light green at JPEG quality 30: gaps between light particles take the dark
    green's colour (chroma blur); without the erosion the dark centroid is pulled
    towards the light side, with it it stays within 3% of R."""
    cols = ((30, 110, 20), (150, 235, 150))
    scenes = [particle_drum((400, 300), cols, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
              for i, (m, sl) in enumerate([(0.0, 25.0), (0.4, 35.0)])]
    jpg = [perturb(s.image, "jpeg30", seed=i)[0] for i, s in enumerate(scenes)]
    cfg = suggest_classes(jpg, per_frame=2500)
    dark = min(range(2), key=lambda k: sum(cfg.counted[k].lab[0].mean_lab[:1]))
    errs = {}
    for erode in (False, True):
        meter = Meter(cfg.classes, erode=erode)
        errs[erode] = []
        for s, img in zip(scenes, jpg, strict=True):
            st = meter.measure(img).classes[dark]
            errs[erode].append(math.hypot(st.cx_px - s.centroids[0][0], st.cy_px - s.centroids[0][1]) / s.roi.r_px)
    assert max(errs[True]) < 0.03, errs
    assert max(errs[False]) > 2 * max(errs[True]), errs

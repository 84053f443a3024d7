"""The class opening (``[meter] opening``): exact in the compiled pass, shared with the
Lacey baseline, and what it is for -- rims and gaps that JPEG chroma blur gives the wrong
class -- without moving a particle's centroid."""

import math

import cv2
import numpy as np
import pytest

from vision.colours import DEFAULT_CLASSES, ColourClass, classify, lut_labels
from vision.config import config_to_toml
from vision.lacey import LaceyMeter
from vision.meter import Meter
from vision.moments import GLARE_MIN, class_tables, frame_moments, open_labels, row_spans
from vision.roi import _mask_in_box, roi_bbox
from vision.suggest import opening_stride, particle_diameter_px, suggest_classes
from vision.synthetic import drum_frame, particle_drum


def test_open_labels_drops_thin_structures_and_keeps_blobs_whole():
    rng = np.random.default_rng(0)
    lab = np.zeros((20, 24), np.uint8)
    lab[1:9, 1:9] = 1  # an 8 x 8 block keeps all but its four corners
    lab[4, 12:20] = 2  # a one-pixel line vanishes
    lab[12:14, 1:20] = 2  # so does a two-pixel band
    lab[16:19, 2:22] = rng.integers(0, 3, (3, 20))  # noise: checked against OpenCV below
    out = open_labels(lab)
    want = lab == 1
    want[[1, 1, 8, 8], [1, 8, 1, 8]] = False
    assert ((out == 1)[:10] == want[:10]).all()
    assert not (out[:15] == 2).any()
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    for c in (1, 2):  # the per-class morphological opening, the map's outside counted as no class
        m = np.pad((lab == c).astype(np.uint8), 1)
        ref = cv2.dilate(cv2.erode(m, cross, borderValue=0), cross, borderValue=0)[1:-1, 1:-1]
        assert ((out == c) == (ref > 0)).all(), c


def jpeg_pair(cols, quality: int, size=(400, 300), slopes=(25.0, 35.0), mixes=(0.0, 0.4)):
    """Two rendered drums of a colour pair (segregated and partly mixed) and their JPEG copies."""
    scenes = [particle_drum(size, cols, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
              for i, (m, sl) in enumerate(zip(mixes, slopes, strict=True))]
    jpg = [cv2.imdecode(cv2.imencode(".jpg", s.image, [cv2.IMWRITE_JPEG_QUALITY, quality])[1], cv2.IMREAD_COLOR)
           for s in scenes]
    return scenes, jpg


THREE = (*DEFAULT_CLASSES, ColourClass("grey", (((0, 0, 100), (179, 40, 200)),), (150, 150, 150)))


@pytest.mark.parametrize("off", [(0, 0), (5, 3)])
@pytest.mark.parametrize("opening", [False, True])
@pytest.mark.parametrize("step, classes, dark", [(1, DEFAULT_CLASSES, -1), (2, DEFAULT_CLASSES, -1),
                                                 (3, THREE, -1), (1, THREE, 80)])
def test_compiled_pass_matches_the_label_map(step, classes, dark, opening, off):
    """Every class's moments (runs summed from prefix sums), the glare's and the occupancy
    grids equal those of the label map, opened or not; the bed grid counts the classes
    before the opening, the glare grid the glare after it; cells that start ``off`` px left
    of and above the grid's first pixel (the meter anchors them on the drum centre)."""
    img = drum_frame((320, 240), mix=0.6, seed=2)
    img[100:140, 60:260] = (120, 125, 130)  # a grey band: the third class
    img[60:72, 150:171] = 255  # clipped light: glare (no class claims it)
    img[80, 100:120] = 252  # a one-pixel line of it: the opening drops it
    roi = Meter().measure(img).roi
    box = roi_bbox(roi, img.shape[:2])
    x0, y0, x1, y1 = box
    inside = _mask_in_box(roi, box)[::step, ::step]
    first, last = row_spans(inside)
    tables = class_tables(classes)
    n = len(classes)
    occ = np.full((((inside.shape[0] * step + off[1]) >> 3) + 1, ((inside.shape[1] * step + off[0]) >> 3) + 1), 7,
                  np.int32)
    gocc = np.full_like(occ, 5)
    got = frame_moments(img, tables, (x0, y0), first, last, step, dark, occupancy=occ, opening=opening,
                        glare_cells=gocc, cell_offset_xy=off)
    assert got.shape == (n + 2, 6)
    sub = np.ascontiguousarray(img[y0:y1:step, x0:x1:step][: inside.shape[0], : inside.shape[1]])
    raw = np.where(inside, lut_labels(sub, tables.fine), 0)
    assert ((raw == n + 1) == (inside & (sub.min(axis=2) >= GLARE_MIN))).all()
    assert (np.where(raw <= n, raw, 0) == np.where(inside, classify(sub, classes), 0)).all()
    lab = open_labels(raw) if opening else raw
    ys, xs = np.mgrid[0 : lab.shape[0], 0 : lab.shape[1]]
    X, Y = x0 + xs * step, y0 + ys * step
    darkpx = inside & (sub.max(axis=2) <= dark)
    for k, m in enumerate([lab == c for c in range(1, n + 2)] + [darkpx]):
        want = [m.sum(), X[m].sum(), Y[m].sum(), (X[m] ** 2).sum(), (Y[m] ** 2).sum(), (X[m] * Y[m]).sum()]
        assert got[k].tolist() == [int(v) for v in want], k
    assert (lab == 3).sum() > 100 if n == 3 else True
    assert (lab == n + 1).sum() > 20
    bed = darkpx if dark >= 0 else (raw > 0) & (raw <= n)
    for grid, m in ((occ, bed), (gocc, lab == n + 1)):
        want_occ = np.zeros_like(occ)
        np.add.at(want_occ, ((ys * step + off[1]) >> 3, (xs * step + off[0]) >> 3), m.astype(np.int32))
        assert (grid == want_occ).all()


def test_lacey_uses_the_same_opened_labels():
    img = drum_frame((320, 240), mix=0.0, seed=1)
    roi = Meter().measure(img).roi
    a = LaceyMeter(roi=roi).measure(img)
    b = LaceyMeter(roi=roi, opening=True).measure(img)
    assert math.isfinite(a.m) and math.isfinite(b.m) and a.s0_2 != b.s0_2


@pytest.mark.parametrize("quality", [30, 75])
def test_opening_removes_jpeg_chroma_rims_on_a_same_hue_pair(quality):
    """Dark vs light green at JPEG quality 30 and 75: gaps between light particles take the
    dark green's colour (chroma blur); without the opening the dark centroid is pulled
    towards the light side, with it it stays within 3% of R."""
    scenes, jpg = jpeg_pair(((30, 110, 20), (150, 235, 150)), quality)
    cfg = suggest_classes(jpg, per_frame=2500)
    dark = min(range(2), key=lambda k: sum(cfg.counted[k].lab[0].mean_lab[:1]))
    errs = {}
    for opening in (False, True):
        meter = Meter(cfg.classes, opening=opening)
        errs[opening] = []
        for s, img in zip(scenes, jpg, strict=True):
            st = meter.measure(img).classes[dark]
            errs[opening].append(math.hypot(st.cx_px - s.centroids[0][0], st.cy_px - s.centroids[0][1]) / s.roi.r_px)
    assert max(errs[True]) < 0.03, errs
    assert max(errs[False]) > 2 * max(errs[True]), errs


def test_classes_suggest_turns_the_opening_on_where_it_matters():
    """On JPEG frames of a same-hue pair the opening moves the dark class's centroid (the
    bled gaps): suggest turns it on and writes it into the TOML; on clean frames of two
    hues it changes nothing, and the fast pass stays."""
    _, jpg = jpeg_pair(((30, 110, 20), (150, 235, 150)), 50)
    cfg = suggest_classes(jpg, per_frame=2500)
    assert cfg.opening and "opening = true" in config_to_toml(cfg)
    clean = [particle_drum((400, 300), mix=m, seed=i, particle_r_frac=0.045).image for i, m in enumerate([0.0, 0.5])]
    assert not suggest_classes(clean, per_frame=2500).opening


@pytest.mark.parametrize("size, r_frac", [((400, 300), 0.045), ((1280, 960), 0.045), ((1280, 960), 0.02)])
def test_particle_diameter_is_read_from_the_classified_bed(size, r_frac):
    s = particle_drum(size, mix=0.5, particle_r_frac=r_frac, seed=1)
    cfg = suggest_classes([s.image], per_frame=2500)
    d = particle_diameter_px(cfg, s.image, s.roi)
    assert abs(d / (2 * r_frac * s.roi.r_px) - 1) < 0.25, d
    assert [opening_stride(v) for v in (float("nan"), 10.0, 23.0, 24.0, 60.0, 500.0)] == [1, 1, 1, 2, 4, 8]


def test_on_large_jpeg_frames_the_opening_works_on_a_coarser_grid():
    """Brown vs beige, 1600 x 1200, JPEG 30: the blurred gaps between beige particles (brown
    in colour) are several pixels wide, more than the cross removes on the full grid; the
    suggested config opens on a grid of about a twelfth of a particle and holds 3% of R."""
    scenes, jpg = jpeg_pair(((30, 70, 140), (170, 210, 230)), 30, size=(1600, 1200), slopes=(30.0, 35.0),
                            mixes=(0.0, 0.5))
    cfg = suggest_classes(jpg, per_frame=4000)
    assert cfg.opening and cfg.stride >= 2, (cfg.opening, cfg.stride)
    full_grid = Meter(cfg.classes, opening=True)
    for s, img in zip(scenes, jpg, strict=True):
        got, fine = cfg.make_meter().measure(img), full_grid.measure(img)
        errs = [min(math.hypot(st.cx_px - c[0], st.cy_px - c[1]) for c in s.centroids) / s.roi.r_px
                for st in got.classes]
        assert max(errs) < 0.03, errs
        fine_errs = [min(math.hypot(st.cx_px - c[0], st.cy_px - c[1]) for c in s.centroids) / s.roi.r_px
                     for st in fine.classes]
        assert max(fine_errs) >= max(errs), (fine_errs, errs)

"""The pure-Python parts of vision/moments.py at known answers (issue 27): row spans, the class
opening (against a loop written from its definition), the kernel's label map, the learned class's
chroma, the table cache, and the shell of ``frame_moments`` (its own buffers, the dark occupancy).

The numba kernels themselves (``# pragma: no cover - compiled``) are checked against the label map in
tests/vision/test_opening.py; mutmut cannot mutate them (see docs/mutation.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from vision import moments
from vision.colours import DEFAULT_CLASSES, Classifier, ColourClass, LabComponent, lut_labels
from vision.moments import MOMENT_FIELDS, class_tables, frame_moments, kernel_labels, open_labels, row_spans

RED, BLUE, BLACK = (0, 0, 255), (255, 0, 0), (0, 0, 0)


def test_moment_fields_are_the_documented_columns():
    assert MOMENT_FIELDS == ("n", "sx", "sy", "sxx", "syy", "sxy")


# --- row_spans --------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [bool, np.uint8, np.int32])
def test_row_spans_known_answers(dtype):
    m = np.zeros((5, 6), dtype)
    m[1, 2:5] = 1  # columns 2..4
    m[2, :] = 1  # the whole row
    m[3, 5] = 1  # the last column only
    m[4, 0] = 1  # the first column only
    first, last = row_spans(m)
    assert first.tolist() == [0, 2, 0, 5, 0] and last.tolist() == [0, 5, 6, 6, 1]
    assert first.dtype == np.int64 and last.dtype == np.int64


def test_row_spans_counts_any_nonzero_value_as_set():
    m = np.zeros((2, 4), np.uint8)
    m[0, 1:3] = 255
    m[1, 3] = 2
    first, last = row_spans(m)
    assert first.tolist() == [1, 3] and last.tolist() == [3, 4]


# --- open_labels --------------------------------------------------------------------------------


def _open_reference(lab: np.ndarray) -> np.ndarray:
    """The docstring's definition, pixel by pixel: erosion by the 4-neighbour cross (off-map = 0),
    then a pixel keeps its class when it or one of its four neighbours survived."""
    h, w = lab.shape

    def at(a, y, x):
        return a[y, x] if 0 <= y < h and 0 <= x < w else 0

    nbrs = ((0, -1), (0, 1), (-1, 0), (1, 0))
    core = np.zeros((h, w), bool)
    for y in range(h):
        for x in range(w):
            c = lab[y, x]
            core[y, x] = c != 0 and all(at(lab, y + dy, x + dx) == c for dy, dx in nbrs)
    out = np.zeros_like(lab)
    for y in range(h):
        for x in range(w):
            if core[y, x] or any(at(core, y + dy, x + dx) for dy, dx in nbrs):
                out[y, x] = lab[y, x]
    return out


def test_open_labels_of_a_3x3_block_is_its_cross():
    lab = np.zeros((5, 5), np.uint8)
    lab[1:4, 1:4] = 2
    want = np.zeros_like(lab)
    want[2, 1:4] = 2
    want[1:4, 2] = 2
    assert (open_labels(lab) == want).all()


def test_open_labels_counts_off_map_pixels_as_no_class():
    """A block filling the map: its border rows/columns cannot survive the erosion, so the 5x5 map
    keeps everything but its four corners (the 3x3 core dilated by the cross)."""
    lab = np.full((5, 5), 1, np.uint8)
    want = lab.copy()
    want[[0, 0, 4, 4], [0, 4, 0, 4]] = 0
    assert (open_labels(lab) == want).all()
    assert (open_labels(np.full((2, 9), 1, np.uint8)) == 0).all()  # two pixels thin: gone


def test_open_labels_keeps_classes_apart_and_returns_a_new_array_of_the_same_dtype():
    lab = np.zeros((5, 8), np.int32)
    lab[:, :4] = 1
    lab[:, 4:] = 2
    out = open_labels(lab)
    assert out.dtype == np.int32 and out is not lab and (lab[:, :4] == 1).all()
    assert (out == _open_reference(lab)).all()
    assert set(np.unique(out)) == {0, 1, 2}
    # the no-class label 0 never "survives": a hole stays a hole
    hole = np.full((7, 7), 3, np.uint8)
    hole[3, 3] = 0
    assert open_labels(hole)[3, 3] == 0


@settings(max_examples=150, deadline=None)
@given(hnp.arrays(np.uint8, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=9),
                  elements=st.integers(0, 2)))
def test_open_labels_matches_its_definition(lab):
    assert (open_labels(lab) == _open_reference(lab)).all()


# --- kernel_labels --------------------------------------------------------------------------------


def _stripe_image() -> np.ndarray:
    img = np.zeros((9, 12, 3), np.uint8)
    img[1:8, 1:6] = RED
    img[1:8, 6:11] = BLUE
    img[4, 3] = BLUE  # one wrong pixel inside the red block: the opening gives it no class
    return img


def test_kernel_labels_is_the_lut_label_inside_and_zero_outside():
    lut = np.zeros(1 << 24, np.uint8)
    lut[(0 << 16) | (0 << 8) | 255] = 1  # red
    lut[(255 << 16) | (0 << 8) | 0] = 2  # blue
    img = _stripe_image()
    inside = np.ones(img.shape[:2], bool)
    inside[:, 10:] = False
    got = kernel_labels(img, lut, inside)
    want = np.where(inside, lut_labels(img, lut), 0)
    assert got.dtype == np.uint8 and (got == want).all() and (got[1:8, 10] == 0).all() and got[4, 3] == 2
    opened = kernel_labels(img, lut, inside, opening=True)
    assert (opened == open_labels(want)).all() and opened[4, 3] == 0 and not (opened == want).all()


# --- the learned class's chroma and the tables' cache -------------------------------------------


def test_chroma_is_the_weighted_mean_colour_of_the_components():
    cov = (4.0, 0.0, 0.0, 4.0, 0.0, 4.0)
    c = ColourClass("mix", lab=(LabComponent((50.0, 10.0, 0.0), cov, 1.0), LabComponent((70.0, 0.0, 20.0), cov, 3.0)))
    assert moments._chroma(c) == pytest.approx(math.hypot(2.5, 15.0), rel=1e-12)
    grey = ColourClass("grey", lab=(LabComponent((80.0, -3.0, 4.0), cov, 2.0),))
    assert moments._chroma(grey) == pytest.approx(5.0, rel=1e-12)


def test_class_tables_accepts_a_classifier_a_list_or_a_tuple_and_builds_once():
    t = class_tables(DEFAULT_CLASSES)
    assert class_tables(list(DEFAULT_CLASSES)) is t
    assert class_tables(Classifier(DEFAULT_CLASSES)) is t
    assert t.n_classes == 2 and t.coarse.shape == (1 << 18,) and t.fine.shape == (1 << 24,)


def test_the_kernels_are_compiled_once_per_variant():
    assert moments._compiled() is moments._compiled(False) is moments._compiled(False)
    assert moments._compiled(True) is moments._compiled(True)
    assert moments._compiled(True) is not moments._compiled(False)


# --- frame_moments' shell -------------------------------------------------------------------------


def _moments_of(mask: np.ndarray, x0: int, y0: int) -> list[int]:
    ys, xs = np.nonzero(mask)
    x, y = xs + x0, ys + y0
    return [int(v) for v in (len(x), x.sum(), y.sum(), (x * x).sum(), (y * y).sum(), (x * y).sum())]


@pytest.mark.parametrize("opening", [False, True])
def test_frame_moments_allocates_its_own_buffers_and_gives_the_same_sums(opening):
    img = _stripe_image()
    img[2:4, 7:9] = BLACK  # dark pixels inside the blue block
    tables = class_tables(DEFAULT_CLASSES)
    inside = np.ones((9, 12), bool)
    first, last = row_spans(inside)
    got = frame_moments(img, tables, (0, 0), first, last, dark_v_max=0, opening=opening)
    assert got.shape == (4, 6) and got.dtype == np.int64
    lab = kernel_labels(img, tables.fine, inside, opening)
    for k in (1, 2):
        assert got[k - 1].tolist() == _moments_of(lab == k, 0, 0), k
    assert got[2].tolist() == [0] * 6  # no glare
    assert got[3].tolist() == _moments_of((img.max(axis=2) == 0), 0, 0)  # dark: V <= 0
    out = np.full((4, 6), 99, np.int64)
    assert frame_moments(img, tables, (0, 0), first, last, dark_v_max=0, out=out, opening=opening) is out
    assert (out == got).all()


def test_dark_v_max_zero_makes_the_occupancy_count_the_dark_pixels():
    """``dark_v_max >= 0`` (0 included) is the backlit bed: the occupancy cells count dark pixels, not classes."""
    img = _stripe_image()
    img[0, :] = BLACK
    tables = class_tables(DEFAULT_CLASSES)
    inside = np.ones((9, 12), bool)
    first, last = row_spans(inside)
    for dark, bed in ((0, img.max(axis=2) == 0), (-1, kernel_labels(img, tables.fine, inside) > 0)):
        occ = np.full((2, 2), 7, np.int32)
        frame_moments(img, tables, (0, 0), first, last, dark_v_max=dark, occupancy=occ)
        want = np.zeros((2, 2), np.int32)
        np.add.at(want, tuple(np.nonzero(bed)[i] >> 3 for i in (0, 1)), 1)
        assert (occ == want).all(), dark


def test_frame_moments_does_not_open_by_default():
    img = _stripe_image()
    tables = class_tables(DEFAULT_CLASSES)
    inside = np.ones((9, 12), bool)
    first, last = row_spans(inside)
    got = frame_moments(img, tables, (0, 0), first, last)
    lab = kernel_labels(img, tables.fine, inside)
    assert lab[4, 3] == 2 and got[1].tolist() == _moments_of(lab == 2, 0, 0)
    assert got[3].tolist() == [0] * 6  # dark_v_max < 0: no dark sums


def test_frame_moments_of_an_empty_roi_is_all_zero():
    tables = class_tables(DEFAULT_CLASSES)
    none = np.zeros(0, np.int64)
    for opening in (False, True):
        got = frame_moments(np.zeros((4, 4, 3), np.uint8), tables, (0, 0), none, none, opening=opening)
        assert got.shape == (4, 6) and not got.any()


@pytest.mark.slow
def test_a_fresh_compile_with_bounds_checks_gives_the_label_maps_sums(monkeypatch, tmp_path):
    """The kernels compiled from source now (an empty numba cache, bounds checking forced on): no index
    leaves frame_moments' own buffers, and the sums are the label map's. Otherwise the kernels kept in
    the process and numba's disk cache would hide a broken compile step (a mutant of ``_compiled``)."""
    import numba

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(numba.config, "BOUNDSCHECK", 1)
    monkeypatch.setattr(moments, "_kernels", {})
    monkeypatch.setattr(moments, "_add_run", moments._add_run_py)
    monkeypatch.setattr(moments, "_flush_cells", moments._flush_cells_py)
    img = _stripe_image()
    img[2:4, 7:9] = BLACK
    tables = class_tables(DEFAULT_CLASSES)
    inside = np.ones((9, 12), bool)
    first, last = row_spans(inside)
    for opening in (False, True):
        got = frame_moments(img, tables, (0, 0), first, last, dark_v_max=0, opening=opening)
        lab = kernel_labels(img, tables.fine, inside, opening)
        for k in (1, 2):
            assert got[k - 1].tolist() == _moments_of(lab == k, 0, 0), (opening, k)
        assert got[3].tolist() == _moments_of(img.max(axis=2) == 0, 0, 0)
    assert set(moments._kernels) == {False, True}

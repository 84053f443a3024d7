"""``classes suggest``: the class preview and the notes it gives on the learned classes."""

import cv2
import numpy as np

from vision.colours import classify
from vision.config import parse_config
from vision.suggest import class_preview, suggest_classes
from vision.synthetic import particle_drum


def test_preview_tells_a_black_class_from_no_class():
    """Black particles are shown about the dark grey that meant *no class*: the preview must
    paint no class in another colour, so where the black class is can be seen."""
    sc = particle_drum((400, 300), ((0, 140, 255), (35, 35, 35)), mix=0.0, seed=0, particle_r_frac=0.045)
    cfg = suggest_classes(sc.image)
    assert [c.name for c in cfg.counted] == ["black", "orange"]
    pane = class_preview(sc.image, cfg.classes, sc.roi)[:, 400:]
    labels = classify(sc.image, cfg.classes)
    legend = np.zeros(labels.shape, bool)
    legend[:120] = True  # the legend is drawn over the top of the class map
    none = pane[(labels == 0) & ~legend].astype(int)
    assert len(none) > 1000
    none_bgr = np.median(none, axis=0)
    for i, c in enumerate(cfg.counted, start=1):
        shown = np.median(pane[(labels == i) & ~legend].astype(int), axis=0)
        assert np.abs(shown - none_bgr).max() >= 60, (c.name, shown, none_bgr)


def test_classes_without_a_valley_between_them_are_a_warning(tmp_path):
    """Grey and white particles differ only in lightness, and shading spreads both over the
    same greys: no colour rule splits them right, so ``classes suggest`` says so (on stderr
    and in the TOML) instead of handing out a config that looks fine; blue/white does not."""
    from tests.cli import cli

    grey_white = particle_drum((640, 480), ((128, 128, 128), (235, 235, 235)), mix=0.0, seed=0)
    cfg = suggest_classes(grey_white.image)
    assert len(cfg.warnings) == 1 and "not separated by a valley" in cfg.warnings[0]
    assert all(f"'{c.name}'" in cfg.warnings[0] for c in cfg.counted)
    assert suggest_classes(particle_drum((640, 480), mix=0.0, seed=0).image).warnings == ()
    path = tmp_path / "grey-white.png"
    cv2.imwrite(str(path), grey_white.image)
    r = cli("classes", "suggest", path)
    assert r.code == 0 and r.err.count("warning:") == 1 and "valley" in r.err
    assert "# warning: classes" in r.out
    assert parse_config(r.out).warnings == ()  # a comment: the config itself reads back as before


def test_suggest_streams_its_frames_and_holds_few(monkeypatch):
    """``classes suggest --frames 500``: the frames are a stream, read once; only
    ``KEEP_FRAMES`` of them (spread over the source) are held, the rest leave their pixel
    samples only. 60 VGA frames, at most 4 kept: while they stream in, the memory held grows by
    a tenth of a frame per frame (its samples), not by the frame."""
    import tracemalloc

    import vision.suggest as sg
    from vision.synthetic import particle_drum

    monkeypatch.setattr(sg, "KEEP_FRAMES", 4)
    base = particle_drum((640, 480), mix=0.5, seed=1).image
    n = 60
    held = []  # memory traced as each frame is handed over

    def stream():
        for i in range(n):
            held.append(tracemalloc.get_traced_memory()[0])
            yield np.roll(base, i % 3, axis=1)  # a new array per frame, as a decoder gives

    tracemalloc.start()
    try:
        cfg = sg.suggest_classes(stream(), n_frames=n, per_frame=2000)
    finally:
        tracemalloc.stop()
    assert len(held) == n and len(cfg.counted) == 2
    growth = held[-1] - held[10]
    assert growth < 0.25 * (n - 11) * base.nbytes, (growth, (n - 11) * base.nbytes)


def test_suggest_peak_memory_and_samples_do_not_grow_with_the_frames(monkeypatch):
    """``classes suggest --frames 500`` is bounded: the colour samples are a budget for the
    whole source (``SAMPLE_BUDGET``; 2,000 a frame gave 1,000,000 samples at 500 frames and
    +88 MB peak RSS on the real PMMA video), and at most ``KEEP_FRAMES`` frames are held. 60 VGA
    frames against 12: the traced peak grows by less than 12 frames' worth (measured 4.4 MB;
    keeping every frame would add 48 frames, 44 MB) and the fit sees no more samples."""
    import tracemalloc

    import vision.suggest as sg
    from vision.synthetic import particle_drum

    base = particle_drum((640, 480), mix=0.5, seed=1).image
    seen: list[int] = []
    fit = sg._fit_colour_model
    monkeypatch.setattr(sg, "_fit_colour_model", lambda s, k, seed: (seen.append(s.lab.shape[0]), fit(s, k, seed))[1])
    sg.suggest_classes(base)  # warm-up: tables, compiled kernels

    def peak(n: int) -> int:
        frames = (np.roll(base, i % 3, axis=1) for i in range(n))  # a new array per frame, as a decoder gives
        tracemalloc.start()
        try:
            sg.suggest_classes(frames, n_frames=n)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    few, many = peak(12), peak(60)
    assert many - few < 12 * base.nbytes, (few, many)
    assert seen[-1] <= seen[-2] <= sg.SAMPLE_BUDGET, seen

"""``classes suggest``: the class preview and the notes it gives on the learned classes."""

import numpy as np

from vision.colours import classify
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

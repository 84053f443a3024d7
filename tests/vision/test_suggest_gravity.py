"""``classes suggest`` in gravity's frame (issue 38, item 2): where the bed lies is found in each
frame before learning, the background is learned from each frame's own empty region, and a
colour denser in the bed than in the empty drum is never background.

Before, one camera turn was taken from the frames' mean bed offset and the empty "top cap"
was the same for every frame: frames whose bed lies on the other side (a camera remounted,
flipped copies in a public data set) put particles into the top cap, and the particle colours
were learned as background (the real PMMA frames, every other one upside down: "black" and
"blue" learned, the white discs no class; the teal/white rig: "black" and "teal").
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.bedframe import FrameSamples, in_gravity
from vision.colourfit import DrumSamples, fit_colour_model
from vision.colours import classify
from vision.rigbench import load_source
from vision.rigs import RigSpec, make_rig, source_labels
from vision.roi import detect_drum
from vision.suggest import suggest_classes
from vision.synthetic import particle_drum

FRAMES = (1, 10, 20, 30, 40)
"""Five frames of the run (both label sets), from the segregated start to the mixed end."""


@pytest.fixture(scope="module")
def source(real_drum_dir):
    frames = load_source((real_drum_dir, real_drum_dir.parent / "real-drum-pmma-white"))
    return [frames[i] for i in FRAMES]


def mixed_views(source, pair: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The rig's frames at 320 px, every second one upside down and every third mirrored, and
    each frame's class cores (source class map eroded, 1 = the pair's first colour, 2 = its second)."""
    frames, cores = [], []
    for i, (f, src) in enumerate(zip(make_rig(RigSpec(pair, "scale320"), source), source, strict=True)):
        lab = source_labels(src.image, detect_drum(src.image))
        core = cv2.resize(cv2.erode(lab, np.ones((5, 5), np.uint8)), f.image.shape[1::-1],
                          interpolation=cv2.INTER_NEAREST)
        img = f.image
        if i % 2 == 1:
            img, core = img[::-1, ::-1], core[::-1, ::-1]
        if i % 3 == 2:
            img, core = img[:, ::-1], core[:, ::-1]
        frames.append(np.ascontiguousarray(img))
        cores.append(np.ascontiguousarray(core))
    return frames, cores


def class_shares(cfg, frames, cores, k: int) -> dict[str, float]:
    """What the learned classes call the cores of source class ``k`` (``none``: no class or background)."""
    got = np.concatenate([classify(f, cfg.classes)[c == k] for f, c in zip(frames, cores, strict=True)])
    names = ["none"] + [c.name for c in cfg.classes]
    counts = np.bincount(got, minlength=len(names)) / max(got.size, 1)
    return {n: float(v) for n, v in zip(names, counts, strict=True)}


@pytest.mark.parametrize(("pair", "names"), [
    ("blue-white", ["blue", "white"]),
    pytest.param("teal-white", ["teal", "white"], marks=pytest.mark.slow),
    pytest.param("orange-black", ["black", "orange"], marks=pytest.mark.slow),
])
def test_upright_upside_down_and_mirrored_frames_learn_both_particle_colours(source, pair, names):
    """The real PMMA frames (and two re-coloured rigs made from them), every second frame upside
    down and every third mirrored: the two particle colours are learned, each class's disc
    cores are mostly that class and hardly ever background, and a note names the frames whose
    bed lies on the other side."""
    frames, cores = mixed_views(source, pair)
    cfg = suggest_classes(frames, per_frame=2500)
    assert [c.name for c in cfg.counted] == names, cfg.warnings
    first, second = (names if pair != "orange-black" else names[::-1])  # the pair's colours, source order
    for k, name in ((1, first), (2, second)):
        shares = class_shares(cfg, frames, cores, k)
        assert shares[name] > 0.7, (k, shares)
        assert shares["none"] < 0.2, (k, shares)  # the particle colour is not background
    assert cfg.camera_rotation_deg == 0.0
    assert any("frames 2, 4 (of 5" in w for w in cfg.warnings), cfg.warnings


def samples(offset: tuple[float, float], n: int = 400) -> FrameSamples:
    rng = np.random.default_rng(0)
    off = rng.uniform(-0.9, 0.9, (n, 2))
    return FrameSamples(np.zeros((n, 3)), off, np.zeros(n, bool), np.ones(n), np.array(offset))


def test_each_frame_is_measured_in_its_own_frame_of_reference():
    """Heights follow each frame's own bed (upside down: the other way), the frames whose bed
    lies on the other side of the reference are named, and a frame without a direction takes
    the reference's; a given turn is the reference."""
    parts = [samples((0.0, 0.3)), samples((0.02, -0.3)), samples((0.0, 0.01)), samples((-0.1, 0.25))]
    got, ref, disagree = in_gravity(parts, None, False)
    assert ref == 0.0 and disagree == [1]
    h = np.split(got.height, 4)
    assert np.allclose(h[0], -parts[0].off[:, 1])  # up is -y
    assert np.corrcoef(h[1], parts[1].off[:, 1])[0, 1] > 0.99  # upside down: up is +y
    assert np.allclose(h[2], -parts[2].off[:, 1])  # no direction: the reference's
    _, ref, disagree = in_gravity(parts, 180.0, False)
    assert ref == 180.0 and disagree == [0, 3]
    _, ref, _ = in_gravity([samples((0.3, 0.0))], None, False)
    assert ref == 90.0  # the bed on the right: the camera turned a quarter counter-clockwise


@pytest.mark.parametrize("colours", [((200, 70, 10), (235, 235, 235)), ((30, 110, 20), (150, 235, 150))])
def test_a_bed_reaching_into_the_top_of_the_drum_is_not_learned_as_background(colours):
    """A bed filling 80 % of the drum reaches far above half its radius: the old top cap held
    mostly particles, and blue (or the dark green) was learned as background (blue/white: 4,400
    of the 27,500 blue pixels counted; the greens: "black" and "green"). The empty region is now
    the untextured drum facing away from the bed, and a colour denser in the bed than there is
    a particle's: each class counts its pixels within a quarter."""
    scenes = [particle_drum((360, 360), colours, mix=m, fill=0.8, slope_deg=35, seed=i, particle_r_frac=0.045)
              for i, m in enumerate((0.0, 0.5))]
    cfg = suggest_classes([s.image for s in scenes], per_frame=3000)
    lab = classify(scenes[0].image, cfg.classes)
    counted = sorted(int((lab == k).sum()) for k in (1, 2))
    assert counted == pytest.approx(sorted(scenes[0].counts), rel=0.25), (counted, scenes[0].counts, cfg.counted)


def test_a_colour_denser_in_the_bed_than_in_the_empty_drum_is_never_background():
    """The colour model's own check (``vision.colourfit``): a frame's empty region that holds
    particles (a bed on another side, a full drum) over-represents their colour there; but a
    particle colour is denser in the bed than in the empty drum, the background is not (it is
    seen in the bed only through the gaps). Blue, 700 of its 3,000 samples in an "empty"
    region, stays a class; the background, a sixth of the bed's samples (gaps), stays background."""
    rng = np.random.default_rng(1)

    def cloud(lab, n):
        return np.asarray(lab, float) + rng.normal(0.0, [2.0, 1.5, 1.5], (n, 3))

    lab = np.concatenate([cloud((8, 0, 0), 3000), cloud((30, 30, -60), 3000), cloud((80, 0, 0), 3000)])
    empty = np.zeros(9000, bool)
    empty[:2000] = True  # the background: 2,000 in the empty drum, 1,000 in the bed's gaps
    empty[3000:3700] = True  # blue: 700 where a frame's bed was taken for empty
    s = DrumSamples(lab, np.where(empty, 0.8, -0.5), np.zeros(9000, bool), empty, ~empty)
    classes = fit_colour_model(s, k=2)
    assert [c.name for c in classes if not c.reject] == ["blue", "white"]
    assert "blue" not in {c.name for c in classes if c.reject}
    (blue,) = (c for c in classes if c.name == "blue")
    assert np.linalg.norm(np.array(blue.lab[0].mean_lab) - (30, 30, -60)) < 3.0


def test_classes_suggest_on_real_frames_upright_upside_down_and_mirrored(source, tmp_path):
    """``drumtwin classes suggest`` on a folder of three real PMMA frames at their own 640 px,
    upright, upside down and mirrored (a camera remounted, flipped copies): exit 0, blue and
    white learned, each class's disc cores mostly its own class and hardly ever background
    (before: 80 % of the blue discs' cores no class), and the upside-down frame named on stderr."""
    from tests.cli import cli
    from vision.config import parse_config

    cores, picked = [], source[::2]
    for i, f in enumerate(picked):
        img, core = f.image, cv2.erode(source_labels(f.image, detect_drum(f.image)), np.ones((5, 5), np.uint8))
        if i == 1:
            img, core = img[::-1, ::-1], core[::-1, ::-1]
        if i == 2:
            img, core = img[:, ::-1], core[:, ::-1]
        cv2.imwrite(str(tmp_path / f"f{i}.png"), img)
        cores.append(np.ascontiguousarray(core))
    r = cli("classes", "suggest", tmp_path, "--frames", len(picked))
    assert r.code == 0, r.err
    cfg = parse_config(r.out)
    assert [c.name for c in cfg.counted] == ["blue", "white"], r.err
    frames = [cv2.imread(str(tmp_path / f"f{i}.png")) for i in range(len(picked))]
    for k, name in ((1, "blue"), (2, "white")):
        shares = class_shares(cfg, frames, cores, k)
        assert shares[name] > 0.7 and shares["none"] < 0.2, (name, shares)
    assert "frames 2 (of 3" in r.err, r.err

"""Photometric tracking (issue 22): classes learned on ONE unperturbed frame at set-up, then
the light changes -- exposure x0.7 and x1.3 (clipped channel by channel) and a colour
temperature shift of +-1000 K. On >= 90% of the frames the known class stays within 3% of R
of its true centroid, and every other frame carries a ``lighting_changed:`` flag: never a
wrong MI without a flag. Synthetic pairs (pale colours against white included) and the real
blue/white PMMA frames.

The synthetic frames go through a camera-like path: JPEG (quality 90, 4:2:0 chroma) after
rendering, and the light changes act in linear light and clip per channel
(``vision.synthetic.light_change``). The pale pairs sit close to white as real pale
particles do: ``test_pale_pairs_clip_channel_by_channel`` checks that at x1.3 the pale
class clips in its brightest channel(s) but not its weakest, while white clips in all three
-- the case the issue measured on a real pale-teal/white rig (34.8% of R without tracking).
"""

import dataclasses
import math

import numpy as np
import pytest

from tests.learned import learn
from tests.vision.helpers import jpeg
from tests.vision.test_real_frames import label_centroid
from vision.colours import classify
from vision.config import config_to_toml, parse_config
from vision.errors import VisionError
from vision.photometric import GAMMA, channel_maps, estimate_light, light_quantiles
from vision.rigs import SYNTHETIC_PAIRS
from vision.sources import open_source
from vision.synthetic import LIGHT_CHANGES, colour_temperature_gains, light_change, particle_drum, perturb

# one worker for the module (xdist group): its pairs' set-up (``setups``, ~12-14 s busy) once per run
pytestmark = pytest.mark.xdist_group("lighting")

LIGHT_PAIRS = SYNTHETIC_PAIRS  # the cross-rig bench's synthetic pairs (one definition: vision.rigs)
PALE = ("paleteal-white-clip", "palepink-white", "palecream-white")
SCENES = [(0.0, 25.0), (0.4, 35.0), (0.8, 30.0), (0.2, 28.0)]  # (mix, slope_deg) per frame
SETUP = 1  # the classes are learned on this frame alone (partly mixed: from the segregated frame 0
# alone, red/blue under JPEG misses the purple blend of red-blue contacts, 4% of R on mixed
# frames with no light change at all -- a limit of learning from one segregated frame)


def lighting_flagged(r) -> bool:
    return any(f.startswith("lighting_changed:") for f in r.flags)


@pytest.fixture(scope="module")
def setups():
    """Per pair: four frames (truth scenes and JPEG images) and the classes learned on one (``SETUP``)."""
    out = {}
    for name, cols in LIGHT_PAIRS.items():
        scenes = [particle_drum((400, 300), cols, mix=m, slope_deg=sl, seed=i, particle_r_frac=0.045)
                  for i, (m, sl) in enumerate(SCENES)]
        images = [jpeg(s.image) for s in scenes]
        cfg = learn([images[SETUP]], per_frame=2500)  # suggest_classes, memoised (tests/learned.py)
        r0 = cfg.make_meter().measure(images[SETUP])
        c0 = scenes[SETUP].centroids[0]
        known = min((0, 1), key=lambda k: math.hypot(r0.classes[k].cx_px - c0[0], r0.classes[k].cy_px - c0[1]))
        out[name] = (scenes, images, cfg, known)
    return out


def check_light_changes(errors_and_flags):
    """>= 90% within 3% of R and valid; every other frame flagged lighting_changed."""
    ok = sum(1 for e, valid, flagged in errors_and_flags if e < 0.03 and valid and not flagged)
    silent = [(e, valid) for e, valid, flagged in errors_and_flags if not flagged and not (e < 0.03 and valid)]
    assert not silent, f"wrong or missing MI without a lighting_changed flag: {silent}"
    assert ok >= 0.9 * len(errors_and_flags), errors_and_flags


@pytest.mark.parametrize("pair", list(LIGHT_PAIRS))
def test_light_changes_after_setup_on_synthetic_pairs(setups, pair):
    scenes, images, cfg, known = setups[pair]
    assert cfg.light_reference is not None and cfg.light_reference_classes is not None
    res = []
    for kind in LIGHT_CHANGES:
        for sc, img in zip(scenes, images, strict=True):
            r = cfg.make_meter().measure(perturb(img, kind)[0])
            st = r.classes[known]
            e = math.hypot(st.cx_px - sc.centroids[0][0], st.cy_px - sc.centroids[0][1]) / r.roi.r_px
            res.append((e, r.valid, lighting_flagged(r)))
    check_light_changes(res)


def test_pale_pairs_clip_channel_by_channel(setups):
    """The pale synthetic pairs are as hard as real pale particles: at x1.3 the pale class's
    brightest channel clips on most of its pixels (two of three for the pale teal) and its
    weakest does not, white clips in all."""
    for pair in PALE:
        scenes, images, _, _ = setups[pair]
        bright = perturb(images[0], "exposure1.3")[0]
        lab = scenes[0].image  # (labels from the truth: pixels well inside the drawn discs)
        pale_bgr, white_bgr = np.array(LIGHT_PAIRS[pair][0]), np.array(LIGHT_PAIRS[pair][1])
        d_pale = np.abs(lab.astype(int) - pale_bgr).max(axis=2) < 6
        d_white = np.abs(lab.astype(int) - white_bgr).max(axis=2) < 6
        assert d_pale.sum() > 300 and d_white.sum() > 300
        clip_pale = (bright[d_pale] >= 254).mean(axis=0)
        clip_white = (bright[d_white] >= 254).mean(axis=0)
        order = np.argsort(pale_bgr)
        assert clip_pale[order[2]] > 0.8, (pair, clip_pale)  # the brightest channel clips ...
        assert clip_pale[order[0]] < 0.2, (pair, clip_pale)  # ... the weakest does not
        assert clip_white.min() > 0.8, (pair, clip_white)


def test_without_tracking_a_colour_temperature_shift_loses_the_pale_classes(setups):
    """The reason for the tracking: the same classes with the light reference removed (the
    old meter) lose the pale pairs under a +-1000 K shift -- a class vanishes or moves."""
    bad = 0
    n = 0
    for pair in PALE:
        scenes, images, cfg, known = setups[pair]
        old = dataclasses.replace(cfg, light_reference=None, light_reference_classes=None)
        for kind in ("ct+1000", "ct-1000"):
            for sc, img in zip(scenes, images, strict=True):
                r = old.make_meter().measure(perturb(img, kind)[0])
                st = r.classes[known]
                e = math.hypot(st.cx_px - sc.centroids[0][0], st.cy_px - sc.centroids[0][1]) / r.roi.r_px
                bad += not (e < 0.03 and r.valid)
                n += 1
    assert bad > 0.5 * n


@pytest.fixture(scope="module")
def real(real_drum_dir):
    frames = {}
    for fr in open_source(real_drum_dir / "images"):
        name = fr.name.rsplit(".", 1)[0]
        lab = label_centroid(real_drum_dir / "labels" / f"{name}.txt", fr.image.shape[1], fr.image.shape[0])
        if lab is not None:
            frames[name] = (fr.image, lab)
    cfg = learn([frames["0002"][0]], per_frame=4000)  # suggest_classes, once per code version (tests/learned.py)
    return frames, cfg


def test_light_changes_after_setup_on_real_frames(real):
    frames, cfg = real
    assert cfg.counted[0].name == "blue"
    res = []
    for kind in LIGHT_CHANGES:
        for img, lab in frames.values():
            r = cfg.make_meter().measure(perturb(img, kind)[0])
            b = r.cls("blue")
            res.append((math.hypot(b.cx_px - lab[0], b.cy_px - lab[1]) / r.roi.r_px, r.valid, lighting_flagged(r)))
    check_light_changes(res)


def test_light_too_far_to_map_back_gives_no_mi_and_a_flag(real, setups):
    """Saturation (x3), near darkness (x0.2): lighting_changed and no MI, on real and synthetic frames."""
    frames, cfg = real
    cases = [(frames["0046"][0], cfg), (setups["paleteal-white-clip"][1][1], setups["paleteal-white-clip"][2])]
    for img, c in cases:
        for gain in (3.0, 0.2):
            r = c.make_meter().measure(light_change(img, gain))
            assert lighting_flagged(r), (gain, r.flags)
            assert not r.valid and math.isnan(r.mi)


def test_the_gains_are_estimated_and_the_table_rebaked_only_when_the_light_moves(setups):
    _, images, cfg, _ = setups["palepink-white"]
    meter = cfg.make_meter()
    for _ in range(6):
        meter.measure(images[0])
    assert meter.rebakes == 0 and meter.light is not None
    assert max(abs(g - 1.0) for g in meter.light.gains_bgr) < 0.02
    gains = (1.2, 0.9, 0.75)
    for _ in range(6):
        r = meter.measure(light_change(images[0], gains))
    assert meter.rebakes == 1  # the jump is seen at once; the estimate does not wander after it
    assert all(abs(a / b - 1.0) < 0.03 for a, b in zip(meter.light.gains_bgr, gains, strict=True)), meter.light
    assert r.valid


def test_channel_maps_undo_a_gain_and_clipping_maps_to_the_middle():
    assert np.array_equal(channel_maps((1.0, 1.0, 1.0))[0], np.arange(256))
    v = np.arange(256, dtype=np.uint8)
    img = np.stack([v, v, v], axis=1)[None]
    dark = light_change(img, 0.7)[0]
    m = channel_maps((0.7, 0.7, 0.7))
    assert np.abs(m[0][dark[:, 0]].astype(int) - v).max() <= 2  # 8-bit rounding of the darker frame
    bright = channel_maps((1.3, 1.3, 1.3))
    lowest = round(255 * (1 / 1.3) ** (1 / GAMMA))  # the darkest reference value that clips at x1.3
    assert bright[0][254] <= lowest < bright[0][255] < 255


def test_estimate_names_what_cannot_be_mapped():
    rng = np.random.default_rng(0)
    px = rng.integers(30, 200, (5000, 3)).astype(np.uint8)
    ref = light_quantiles(px)
    assert estimate_light(ref, light_quantiles(px)).cause is None
    sat = np.full_like(px, 255)
    assert estimate_light(ref, light_quantiles(sat)).cause.startswith("saturated:")
    black = np.zeros_like(px)
    assert estimate_light(ref, light_quantiles(black)).cause.startswith("too_dark:")
    curve = (255 * (px / 255.0) ** 3).astype(np.uint8)  # a tone curve no gain explains
    assert estimate_light(ref, light_quantiles(curve)).cause.startswith(("unexplained_cast:", "gain:"))


def test_colour_temperature_gains_follow_plancks_law():
    warm, cool = colour_temperature_gains(-1000), colour_temperature_gains(1000)
    assert warm[1] == cool[1] == 1.0
    assert warm[0] < 1.0 < warm[2] and cool[2] < 1.0 < cool[0]  # lower K: redder light
    assert 1.08 < cool[0] < 1.2 and 0.85 < cool[2] < 0.97
    with pytest.raises(ValueError):
        colour_temperature_gains(-6000)


def test_light_reference_round_trips_and_bad_values_name_the_key(setups):
    cfg = setups["blue-white"][2]
    back = parse_config(config_to_toml(cfg))
    assert back.light_reference == cfg.light_reference
    assert back.light_reference_classes == cfg.light_reference_classes
    assert back.classes == cfg.classes
    text = config_to_toml(cfg)
    start = text.index("light_reference = ")
    line = text[start: text.index("\n", start)]
    for bad, key in ((text.replace(line, "light_reference = [[1, 2]]"), "light_reference"),
                     (text.replace(line, "light_reference = [" + ", ".join(["[" + ", ".join(["5"] * 35) + "]"] * 2)
                                   + ", [" + ", ".join(str(200 - i) for i in range(35)) + "]]"), "non-decreasing"),
                     (text.replace("[meter]\n", "[meter]\nmirror = 1\n"), "mirror"),
                     (text.replace("[meter]\n", '[meter]\ncamera_rotation_deg = "left"\n'), "camera_rotation_deg"),
                     (text.replace(line, ""), "light_reference_classes needs light_reference")):
        with pytest.raises(VisionError, match=key):
            parse_config(bad)


def test_a_learned_set_classifies_what_it_learned(setups):
    """(Sanity: the pale classes are two classes on the set-up frame, not white and no class.)"""
    for pair in PALE:
        _, images, cfg, _ = setups[pair]
        lab = classify(images[0], cfg.classes)
        assert (lab == 1).sum() > 1000 and (lab == 2).sum() > 1000


def test_a_steady_noisy_bed_does_not_rebake_and_a_small_move_is_confirmed_then_baked():
    """Estimates on every frame of one bed under a webcam's noise (sigma 8) scatter by up to
    4.6 % in the dim green channel of a red/blue bed: past the 3 % re-bake threshold on some
    frames, which re-baked the 16 MB table (~12 ms) there and back again (20 re-bakes in 80
    frames). A small move is now re-baked when the next frame's estimate sees it too; a real
    6 % move is, on its second frame; a x1.3 jump on its first."""
    from vision.meter import Meter
    from vision.photometric import class_reference_from_frames, reference_from_frames
    from vision.synthetic import drum_frame

    base = drum_frame((640, 480), mix=0.3, slope_deg=25, seed=1)
    roi = Meter().measure(base).roi
    steady = [perturb(base, "noise", seed=10 + i)[0] for i in range(8)]
    plain = Meter(roi=roi)
    ref = reference_from_frames(steady[:1], [roi])
    ref_cls = class_reference_from_frames(steady[:1], [roi], plain._base_tables.fine, len(plain.classes) + 1)

    def meter() -> Meter:
        return Meter(roi=roi, light_reference=ref, light_reference_classes=ref_cls, track_every=1)

    m = meter()
    for j in range(80):
        assert m.measure(steady[j % 8]).valid
    assert m.estimates == 80 and m.rebakes == 0
    m = meter()
    m.measure(steady[0])
    m.measure(light_change(steady[1], 1.06))
    assert m.rebakes == 0  # seen once
    r = m.measure(light_change(steady[2], 1.06))
    assert m.rebakes == 1 and r.valid
    assert all(abs(g / 1.06 - 1.0) < 0.03 for g in m.light.gains_bgr), m.light
    m = meter()
    m.measure(steady[0])
    m.measure(light_change(steady[1], 1.3))
    assert m.rebakes == 1

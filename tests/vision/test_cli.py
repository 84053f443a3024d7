"""``drumtwin mi``, ``classes suggest`` and ``bench vision``, run in-process (tests/cli.py)."""

import csv
import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli import assert_one_line_error, cli
from tests.vision import helpers as H
from twin.records import FRAME_COLUMNS
from vision.config import load_config, parse_config
from vision.sources import read_image

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "pmma-blue-white.toml"


def rows_of(text: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO(text)))


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("frames")
    from vision.synthetic import drum_frame

    for i, mix in enumerate([0.0, 0.3, 0.6, 1.0, 1.0]):
        cv2.imwrite(str(d / f"f{i:02d}.png"), drum_frame(mix=mix, seed=i))
    return d


def test_mi_csv_plot_and_overlay_video(frames_dir, tmp_path):
    """The CSV is a run's frames.csv (its columns, in order; the twin's and the mill's empty), one
    row per frame with the trend and moving average beside the MI; the plot and the video too."""
    out, png, mp4 = tmp_path / "mi.csv", tmp_path / "mi.png", tmp_path / "ov.mp4"
    r = cli("mi", frames_dir, "--csv", out, "--plot", png, "--overlay-video", mp4)
    assert r.code == 0, r.err
    rows = list(csv.DictReader(out.open()))
    header = next(csv.reader(out.open()))
    assert tuple(header) == FRAME_COLUMNS
    assert len(rows) == 5 and all(r["valid"] == "1" for r in rows)
    assert [int(r["frame"]) for r in rows] == list(range(5)) and float(rows[1]["t_s"]) == pytest.approx(1 / 30)
    mis = [float(r["mi"]) for r in rows]
    assert mis[0] < 0.1 and mis[-1] > 0.8
    assert float(rows[0]["mi_linear"]) == pytest.approx(0.0)
    assert float(rows[0]["ma_mi"]) == mis[0] and float(rows[1]["ma_mi"]) == pytest.approx(sum(mis[:2]) / 2)
    assert all(0.0 <= float(r["trend_mi"]) <= 1.0 and float(r["trend_lo95"]) <= float(r["trend_hi95"])
               for r in rows)
    for row in rows:  # a coarse bed (15 discs across) drawn with a 30 deg surface
        assert 15 < float(row["slope_deg"]) < 45
        assert all(row[c] == "" for c in FRAME_COLUMNS if c.startswith(("twin_", "rpm_"))) and row["mode"] == ""
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cap = cv2.VideoCapture(str(mp4))
    n = 0
    while True:
        ok, img = cap.read()
        if not ok:
            break
        assert img.shape == (480, 640, 3)
        n += 1
    assert n == 5


def test_mi_max_frames_and_window(frames_dir):
    """``--max-frames`` stops early; ``--window`` is the moving average's (``ma_mi``) sample count."""
    rows = rows_of(cli("mi", frames_dir, "--max-frames", 3, "--window", 2).out)
    mis = [float(r["mi"]) for r in rows]
    assert len(rows) == 3 and float(rows[2]["ma_mi"]) == pytest.approx((mis[1] + mis[2]) / 2)


@pytest.mark.parametrize("method", ["lacey", "glcm"])
def test_mi_baseline_methods(frames_dir, method):
    r = cli("mi", frames_dir, "--method", method)
    assert r.code == 0, r.err
    rows = rows_of(r.out)
    assert len(rows) == 5
    vals = [float(r["mi"]) for r in rows]
    assert all(np.isfinite(vals))
    if method == "lacey":
        assert vals[0] < 0.5 < vals[-1]


def test_paths_with_brackets_are_printed_whole(frames_dir, tmp_path):
    """Rich markup took ``[run]`` in a path for a style tag: the message named another file."""
    out = tmp_path / "runs[a]" / "mi[run].csv"
    out.parent.mkdir()
    r = cli("mi", frames_dir, "--csv", out)
    assert r.code == 0, r.err
    assert out.is_file() and f"-> {out}" in r.err, r.err


def test_mi_real_frames_with_config_and_manual_roi(real_drum_dir):
    """Two real frames with the rig's config and a manual drum circle: each row is the meter's
    reading of that frame in that drum (the same numbers as ``Meter.measure``)."""
    imgs = [real_drum_dir / "images" / f"{n}.jpg" for n in ("0002", "0097")]
    r = cli("mi", *imgs, "--config", CONFIG, "--roi", "320.3,319.2,312")
    assert r.code == 0, r.err
    rows = rows_of(r.out)
    assert float(rows[0]["mi"]) < float(rows[1]["mi"]) - 0.3
    from vision.roi import DrumROI

    meter = load_config(CONFIG).make_meter(roi=DrumROI(320.3, 319.2, 312.0))
    for row, path in zip(rows, imgs, strict=True):
        want = meter.measure(read_image(path)[0])
        assert float(row["mi"]) == pytest.approx(want.mi, abs=1e-12)
        assert float(row["slope_deg"]) == pytest.approx(want.slope_deg, abs=1e-9)


def test_bad_frames_become_flagged_rows_and_new_sizes_get_their_drum(tmp_path):
    d = tmp_path / "seq"
    d.mkdir()
    cv2.imwrite(str(d / "a.png"), H.half_disks())
    (d / "b.jpg").write_bytes(b"\xff\xd8\xff corrupt")
    cv2.imwrite(str(d / "c.png"), cv2.cvtColor(H.half_disks(), cv2.COLOR_BGR2GRAY))
    cv2.imwrite(str(d / "d.png"), H.half_disks(800, 600))
    cv2.imwrite(str(d / "e.png"), H.fine_mix())
    r = cli("mi", d)
    assert r.code == 0, r.err
    rows = rows_of(r.out)
    assert [r["valid"] for r in rows] == ["1", "0", "0", "1", "1"]
    assert rows[1]["flags"].startswith("bad_frame:") and "decode" in rows[1]["flags"]
    assert rows[2]["flags"].startswith("bad_frame:") and "grayscale" in rows[2]["flags"]
    assert rows[1]["mi"] == "nan" and float(rows[4]["mi"]) > 0.9
    # the 800x600 frame has its own drum (a half-disk bed there measures as segregated too)
    assert float(rows[3]["mi"]) < 0.05


def test_classes_suggest_folder_with_preview_then_mi(real_drum_dir, tmp_path):
    prev = tmp_path / "preview.png"
    r = cli("classes", "suggest", real_drum_dir / "images", "--frames", 6, "--preview", prev)
    assert r.code == 0, r.err
    cfg = parse_config(r.out)
    assert [c.name for c in cfg.counted] == ["blue", "white"]
    img = cv2.imread(str(prev))
    assert img is not None and img.shape == (640, 1280, 3)
    path = tmp_path / "s.toml"
    path.write_text(r.out)
    out = cli("mi", real_drum_dir / "images", "--config", path)
    assert out.code == 0, out.err
    names = sorted(p.stem for p in (real_drum_dir / "images").glob("*.jpg"))
    rows = dict(zip(names, rows_of(out.out), strict=True))  # one row per image, in name order
    meter = cfg.make_meter()  # the blue class's centroid in the labelled frame: where the labels put it
    blue = meter.measure(read_image(real_drum_dir / "images" / "0097.jpg")[0]).cls("blue")
    a = np.loadtxt(real_drum_dir / "labels" / "0097.txt", ndmin=2)
    assert np.hypot(blue.cx_px - a[:, 1].mean() * 640, blue.cy_px - a[:, 2].mean() * 640) < 0.03 * 312
    assert float(rows["0002"]["mi"]) < min(float(r["mi"]) for k, r in rows.items() if k >= "0013") - 0.2


def test_no_config_and_no_default_colours_says_run_classes_suggest(tmp_path):
    img = np.full((480, 640, 3), 150, np.uint8)  # a grey backlit photo of a drum
    cv2.circle(img, (320, 240), 210, (40, 40, 40), 4)
    cv2.ellipse(img, (320, 240), (200, 200), 0, 20, 160, (90, 90, 90), -1)
    p = tmp_path / "grey.png"
    cv2.imwrite(str(p), img)
    assert_one_line_error(cli("mi", p), "classes suggest", "--config")


@pytest.fixture(scope="module")
def junk(tmp_path_factory):
    d = tmp_path_factory.mktemp("junk")
    (d / "random.png").write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    good = (REPO / "tests" / "data" / "real-drum-pmma" / "images" / "0002.jpg").read_bytes()
    (d / "truncated.jpg").write_bytes(good[: len(good) // 3])
    return d


def _cfg(tmp_path, old, new):
    text = CONFIG.read_text()
    assert old in text
    p = tmp_path / "c.toml"
    p.write_text(text.replace(old, new, 1))
    return p


def test_mi_one_line_errors(tmp_path, junk, real_drum_dir):
    img = real_drum_dir / "images" / "0002.jpg"
    assert "no such" in assert_one_line_error(cli("mi", tmp_path / "missing.png"))
    assert_one_line_error(cli("mi", img, "--window", 0), "--window")
    assert_one_line_error(cli("mi", img, "--window", -5), "--window")
    for bad in ("0", "-1", "nan", "inf"):
        assert_one_line_error(cli("mi", img, "--fps", bad), "--fps")
    assert_one_line_error(cli("mi", img, "--max-frames", -1), "--max-frames")
    assert_one_line_error(cli("mi", img, "--roi", "1,2"), "--roi")
    assert_one_line_error(cli("mi", img, "--roi", "320,320,nan"), "roi")
    msg = assert_one_line_error(cli("mi", img, "--roi", "5000,5000,100"), "outside the 640x640 image")
    assert "DrumROI(" not in msg and "5000, 5000" in msg  # what the user typed, not a repr
    assert_one_line_error(cli("mi", junk / "random.png"), "decode")
    assert_one_line_error(cli("mi", junk / "truncated.jpg"), "truncated.jpg")
    assert_one_line_error(cli("mi", junk), "none of the 2 frames")
    assert "unknown key" in assert_one_line_error(
        cli("mi", img, "--config", _cfg(tmp_path, "min_pixels = 200", "min_pixels = 200\nwobble = 1")))
    assert_one_line_error(cli("mi", img, "--config", _cfg(
        tmp_path, "[[100, 120, 70], [135, 255, 255]]", "[[135, 120, 70], [100, 255, 255]]")), "inverted")
    assert_one_line_error(cli("mi", img, "--config", _cfg(
        tmp_path, "display_bgr = [255, 60, 0]", 'display_bgr = [999, -1, "x"]')), "display_bgr")
    assert_one_line_error(cli("mi", img, "--config", _cfg(
        tmp_path, "[[100, 120, 70], [135, 255, 255]]", "[[100, 120, 70], [135, inf, 255]]")), "HSV range")
    assert_one_line_error(cli("mi", img, "--config", _cfg(
        tmp_path, "min_pixels = 200", 'min_pixels = 200\nroi = [320, 320, 300]\nroi_kind = "rect"\n'
        "half_w_px = nan\nhalf_h_px = 100")), "half_w_px")
    for key, val in (("min_share", "nan"), ("min_share", "-0.1"), ("collapse_ratio", "inf"), ("stride", "0"),
                     ("dark_v_max", "300"), ("min_pixels", "0")):
        new = f"{key} = {val}" if key == "min_pixels" else f"min_pixels = 200\n{key} = {val}"
        assert_one_line_error(cli("mi", img, "--config", _cfg(tmp_path, "min_pixels = 200", new)), key)
    vid = tmp_path / "junk.mp4"
    vid.write_bytes(b"junk" * 100)
    assert "cannot open video" in assert_one_line_error(cli("mi", vid))
    cv2.imwrite(str(tmp_path / "black.png"), np.zeros((100, 100, 3), np.uint8))
    assert "drum" in assert_one_line_error(cli("mi", tmp_path / "black.png"))
    r = cli("mi", "7")  # no camera 7 here: one line, and no CSV header before it
    assert "cannot open camera 7" in assert_one_line_error(r) and r.out == ""


def test_classes_suggest_and_bench_one_line_errors(tmp_path, junk, real_drum_dir):
    img = real_drum_dir / "images" / "0002.jpg"
    assert_one_line_error(cli("classes", "suggest", tmp_path / "none.jpg"), "no such")
    for k in (1, 7, -2):
        assert_one_line_error(cli("classes", "suggest", img, "--k", k), "--k")
    for n in (0, -1, 501):
        assert_one_line_error(cli("classes", "suggest", img, "--frames", n), "--frames")
    assert_one_line_error(cli("classes", "suggest", img, "--preview", tmp_path / "no" / "p.png"), "--preview")
    assert_one_line_error(cli("classes", "suggest", img, "--preview", tmp_path / "p.txt"), "--preview")
    assert_one_line_error(cli("classes", "suggest", img, "--roi", "1,2,inf"), "roi")
    assert_one_line_error(cli("classes", "suggest", junk / "random.png"), "decode")
    assert_one_line_error(cli("classes", "suggest", junk), "no readable frames")
    gray = tmp_path / "gray.png"
    cv2.imwrite(str(gray), np.zeros((64, 64), np.uint8))
    assert_one_line_error(cli("classes", "suggest", gray), "grayscale")
    for s in ("0", "-1", "nan", "inf"):
        assert_one_line_error(cli("bench", "vision", "--seconds", s), "--seconds")


def test_bench_vision_json():
    r = cli("bench", "vision", "--json", "--seconds", "0.02")
    assert r.code == 0, r.err
    res = json.loads(r.out)
    for k in ("centroid_fps", "glcm_fps", "lacey_fps", "centroid_fps_1080p", "centroid_cpu_fps",
              "centroid_cpu_fps_tracked", "glcm_cpu_fps", "centroid_fps_light_moved", "rebake_s",
              "centroid_cpu_fps_light_moved", "centroid_cpu_fps_islands"):
        assert res[k] > 0
    assert res["glcm_cpu_ratio"] == pytest.approx(res["centroid_cpu_fps"] / res["glcm_cpu_fps"])
    assert res["islands_cost_ratio"] == pytest.approx(res["centroid_cpu_fps_islands"] / res["centroid_cpu_fps"])
    assert 0.0 < res["tracked_estimate_share"] <= 1.0
    # the steady video runs the default schedule: every 4th frame, no jump check firing
    assert res["tracked_steady_estimate_share"] == pytest.approx(0.25)
    assert res["tracked_steady_ratio"] == pytest.approx(res["centroid_fps_tracked_steady"] / res["centroid_fps_steady"])
    assert res["centroid_cpu_fps_tracked_steady"] > 0


def test_help_lists_commands():
    r = cli("--help")
    assert r.code == 0
    for cmd in ("mi", "classes", "bench"):
        assert cmd in r.out


def test_classes_suggest_from_a_video(tmp_path):
    from vision.synthetic import particle_drum

    path = tmp_path / "clip.mp4"
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (320, 240))
    for i, mix in enumerate([0.0, 0.3, 0.6, 1.0]):
        vw.write(particle_drum((320, 240), ((30, 30, 210), (200, 70, 10)), mix=mix, seed=i,
                               particle_r_frac=0.05).image)
    vw.release()
    r = cli("classes", "suggest", path, "--frames", 3)
    assert r.code == 0, r.err
    assert [c.name for c in parse_config(r.out).counted] == ["blue", "red"]
    assert "from 3 frame(s)" in r.out


def test_mi_dark_bed_without_classes_still_gives_the_slope(tmp_path):
    img, _ = H.tilted_bed(25.0, 0.4, dark=True)
    cv2.circle(img, (320, 240), 220, (20, 20, 20), 4)  # the drum's rim for detection
    p = tmp_path / "backlit.png"
    cv2.imwrite(str(p), img)
    r = cli("mi", p, "--bed", "dark", "--roi", "320,240,216")
    assert r.code == 0, r.err
    row = rows_of(r.out)[0]
    assert row["valid"] == "0" and "few_pixels" in row["flags"]
    assert float(row["slope_deg"]) == pytest.approx(25.0, abs=1.0)


def test_mi_on_grayscale_frames_is_an_error(tmp_path):
    """A grayscale image cannot give colour classes: one image is a one-line error (it was a
    CSV with one invalid row and exit 0), and so is a folder of nothing else; in a folder
    with colour frames it stays a flagged row."""
    gray = cv2.cvtColor(H.half_disks(), cv2.COLOR_BGR2GRAY)
    cv2.imwrite(str(tmp_path / "a.png"), gray)
    cv2.imwrite(str(tmp_path / "b.jpg"), gray)
    assert_one_line_error(cli("mi", tmp_path / "a.png"), "a.png", "grayscale")
    assert_one_line_error(cli("mi", tmp_path), "none of the 2 frames", "grayscale")
    cv2.imwrite(str(tmp_path / "c.png"), H.half_disks())
    r = cli("mi", tmp_path)
    assert r.code == 0, r.err
    assert [row["valid"] for row in rows_of(r.out)] == ["0", "0", "1"]


def test_a_frame_without_a_drum_in_a_sequence_is_a_flagged_row(tmp_path):
    """A frame in which no drum is found (a test chart, a blank frame) is a ``no_drum:`` row,
    the live run's policy (vision.stream): also when it is the first frame, as long as a drum
    shows within the grace; a source that never shows one is a one-line error naming its first
    frame without a drum."""
    cv2.imwrite(str(tmp_path / "a.png"), H.half_disks())
    cv2.imwrite(str(tmp_path / "b.png"), np.full((300, 400, 3), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "c.png"), H.fine_mix())
    r = cli("mi", tmp_path)
    assert r.code == 0, r.err
    rows = rows_of(r.out)
    assert [row["valid"] for row in rows] == ["1", "0", "1"]
    assert rows[1]["flags"].startswith("no_drum:") and rows[1]["mi"] == "nan"
    r = cli("mi", tmp_path / "b.png", tmp_path / "c.png")
    assert r.code == 0, r.err
    assert [(row["valid"], row["flags"].startswith("no_drum:")) for row in rows_of(r.out)] == [("0", True),
                                                                                                ("1", False)]
    assert_one_line_error(cli("mi", tmp_path / "b.png", tmp_path / "b.png"), "b.png", "drum", "--roi")


def test_classes_suggest_uses_every_frame_of_a_short_source(tmp_path):
    """Fewer images than --frames: every one is learned from (3 of 3 was 1, 5 of 5 was 2:
    the spread divided by --frames instead of the frames taken)."""
    from vision.synthetic import particle_drum

    for i in range(5):
        cv2.imwrite(str(tmp_path / f"f{i}.png"), particle_drum((200, 150), mix=0.5, seed=i).image)
    for n, want in ((12, 5), (3, 3), (1, 1)):
        r = cli("classes", "suggest", tmp_path, "--frames", n)
        assert r.code == 0, r.err
        assert f"from {want} frame(s)" in r.out, r.out.splitlines()[0]


def test_classes_suggest_skips_frames_without_a_drum(tmp_path):
    """One frame without a drum among the frames made classes suggest fail without saying
    which; it is now left out with a warning naming it (and all of them is an error)."""
    from vision.synthetic import particle_drum

    for i in range(2):
        cv2.imwrite(str(tmp_path / f"f{i}.png"), particle_drum((400, 300), mix=0.5, seed=i).image)
    cv2.imwrite(str(tmp_path / "f2.png"), np.full((300, 400, 3), 128, np.uint8))
    r = cli("classes", "suggest", tmp_path)
    assert r.code == 0, r.err
    assert "warning" in r.err and "f2.png" in r.err and "drum" in r.err
    assert [c.name for c in parse_config(r.out).counted] == ["blue", "white"]
    assert_one_line_error(cli("classes", "suggest", tmp_path / "f2.png"), "f2.png", "drum", "--roi")

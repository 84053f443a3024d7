"""``drumtwin mi``, ``classes suggest`` and ``bench vision`` through the real console script."""

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.vision import helpers as H
from twin.cli.vision_cmds import csv_columns
from vision.config import parse_config

REPO = Path(__file__).resolve().parents[2]
EXE = str(Path(sys.executable).parent / "drumtwin")
CONFIG = REPO / "configs" / "pmma-blue-white.toml"


def run(*args, timeout=120):
    env = dict(os.environ)
    env.pop("DRUMTWIN_DEBUG", None)
    env["COLUMNS"] = "400"  # rich wraps at 80 columns when not on a terminal
    return subprocess.run([EXE, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)


def one_line_error(p):
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert "Traceback" not in p.stderr and "Traceback" not in p.stdout
    lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), p.stderr
    return lines[0]


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("frames")
    from vision.synthetic import drum_frame

    for i, mix in enumerate([0.0, 0.3, 0.6, 1.0, 1.0]):
        cv2.imwrite(str(d / f"f{i:02d}.png"), drum_frame(mix=mix, seed=i))
    return d


@pytest.mark.timeout(120)
def test_mi_csv_plot_and_overlay_video(frames_dir, tmp_path):
    out, png, mp4 = tmp_path / "mi.csv", tmp_path / "mi.png", tmp_path / "ov.mp4"
    p = run("mi", frames_dir, "--csv", out, "--plot", png, "--overlay-video", mp4)
    assert p.returncode == 0, p.stderr
    rows = list(csv.DictReader(out.open()))
    header = next(csv.reader(out.open()))
    assert header == csv_columns(["red", "blue"])
    assert header[:9] == ["frame", "t_s", "mi", "mi_sigmoid", "mi_linear", "d_px", "dsigma_px", "slope_deg", "valid"]
    assert header[9:17] == ["cx_red", "cy_red", "sigma_red", "frac_red", "cx_blue", "cy_blue", "sigma_blue", "frac_blue"]
    assert len(rows) == 5 and all(r["valid"] == "1" for r in rows)
    mis = [float(r["mi"]) for r in rows]
    assert mis[0] < 0.1 and mis[-1] > 0.8
    assert float(rows[0]["mi_linear"]) == pytest.approx(0.0)
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


@pytest.mark.timeout(120)
@pytest.mark.parametrize("method", ["lacey", "glcm"])
def test_mi_baseline_methods(frames_dir, method):
    p = run("mi", frames_dir, "--method", method)
    assert p.returncode == 0, p.stderr
    rows = list(csv.DictReader(io.StringIO(p.stdout)))
    assert len(rows) == 5
    vals = [float(r["mi"]) for r in rows]
    assert all(np.isfinite(vals))
    if method == "lacey":
        assert vals[0] < 0.5 < vals[-1]


@pytest.mark.timeout(60)
def test_mi_real_frames_with_config_and_manual_roi(real_drum_dir):
    p = run("mi", real_drum_dir / "images" / "0002.jpg", real_drum_dir / "images" / "0097.jpg",
            "--config", CONFIG, "--roi", "320.3,319.2,312")
    assert p.returncode == 0, p.stderr
    rows = list(csv.DictReader(io.StringIO(p.stdout)))
    assert [r["source"] for r in rows] == ["0002.jpg", "0097.jpg"]
    assert "cx_white" in rows[0] and float(rows[0]["mi"]) < float(rows[1]["mi"]) - 0.3


@pytest.mark.timeout(60)
def test_bad_inputs_one_line_errors(tmp_path):
    assert "no such" in one_line_error(run("mi", tmp_path / "missing.png"))
    bad_cfg = tmp_path / "bad.toml"
    bad_cfg.write_text((CONFIG.read_text()).replace("min_pixels = 200", "min_pixels = 200\nwobble = 1"))
    assert "unknown key" in one_line_error(run("mi", tmp_path, "--config", bad_cfg))
    inv = tmp_path / "inv.toml"
    inv.write_text(CONFIG.read_text().replace("[[100, 120, 70], [135, 255, 255]]", "[[135, 120, 70], [100, 255, 255]]"))
    assert "inverted" in one_line_error(run("mi", tmp_path, "--config", inv))
    assert "--roi" in one_line_error(run("mi", tmp_path, "--roi", "1,2"))
    vid = tmp_path / "junk.mp4"
    vid.write_bytes(b"junk" * 100)
    assert "cannot open video" in one_line_error(run("mi", vid))
    cv2.imwrite(str(tmp_path / "black.png"), np.zeros((100, 100, 3), np.uint8))
    assert "drum" in one_line_error(run("mi", tmp_path / "black.png"))
    p = run("mi", "7")  # no camera 7 here: one line, and no CSV header before it
    assert "cannot open camera 7" in one_line_error(p) and p.stdout == ""


@pytest.mark.timeout(60)
def test_bad_frames_become_flagged_rows(tmp_path):
    d = tmp_path / "seq"
    d.mkdir()
    cv2.imwrite(str(d / "a.png"), H.half_disks())
    (d / "b.jpg").write_bytes(b"\xff\xd8\xff corrupt")
    cv2.imwrite(str(d / "c.png"), cv2.cvtColor(H.half_disks(), cv2.COLOR_BGR2GRAY))
    cv2.imwrite(str(d / "d.png"), H.half_disks(800, 600))
    cv2.imwrite(str(d / "e.png"), H.fine_mix())
    p = run("mi", d)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    rows = list(csv.DictReader(io.StringIO(p.stdout)))
    assert [r["valid"] for r in rows] == ["1", "0", "0", "0", "1"]
    assert "decode" in rows[1]["flags"]
    assert "3-channel" in rows[2]["flags"]
    assert "size_changed" in rows[3]["flags"]
    assert rows[1]["mi"] == "" and float(rows[4]["mi"]) > 0.9


@pytest.mark.timeout(120)
def test_classes_suggest_separates_real_frames(real_drum_dir, tmp_path):
    p = run("classes", "suggest", real_drum_dir / "images" / "0002.jpg")
    assert p.returncode == 0, p.stderr
    cfg = parse_config(p.stdout)
    names = [c.name for c in cfg.classes]
    assert sorted(names) == ["blue", "white"]
    path = tmp_path / "s.toml"
    path.write_text(p.stdout)
    out = run("mi", real_drum_dir / "images", "--config", path)
    assert out.returncode == 0, out.stderr
    rows = {r["source"]: r for r in csv.DictReader(io.StringIO(out.stdout))}
    a = np.loadtxt(real_drum_dir / "labels" / "0097.txt", ndmin=2)
    r = rows["0097.jpg"]
    err = np.hypot(float(r["cx_blue"]) - a[:, 1].mean() * 640, float(r["cy_blue"]) - a[:, 2].mean() * 640)
    assert err < 0.03 * 312
    assert float(rows["0002.jpg"]["mi"]) < min(float(r["mi"]) for k, r in rows.items() if k >= "0013") - 0.2
    assert "error" in one_line_error(run("classes", "suggest", tmp_path / "none.jpg"))


@pytest.mark.timeout(120)
def test_bench_vision_json():
    p = run("bench", "vision", "--json", "--seconds", "0.1")
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    for k in ("centroid_fps", "glcm_fps", "lacey_fps", "centroid_fps_1080p"):
        assert res[k] > 0


def test_help_lists_commands():
    p = run("--help")
    assert p.returncode == 0
    for cmd in ("mi", "classes", "bench"):
        assert cmd in p.stdout

"""``drumtwin sim``, ``calibrate``, ``whatif`` and ``bench twin``: outputs and one-line errors (in-process)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from sim.drum import DEFAULT_DT_S
from tests.cli import assert_one_line_error, cli
from tests.conftest import BENCH_TWIN_ARGS, BENCHES

DRUMTWIN = Path(sys.executable).with_name("drumtwin")


@pytest.mark.timeout(240)
def test_sim_writes_csv_video_and_json_summary_with_the_contact_numbers(tmp_path):
    out_csv = tmp_path / "mi.csv"
    out_mp4 = tmp_path / "run.mp4"
    r = cli("sim", "--case", "A", "--rpm", "5", "--duration", "3", "--fps", "5", "--csv", out_csv,
            "--video", out_mp4, "--dt-ms", "0.1", "--json")
    assert r.code == 0, r.err
    s = json.loads(r.out)
    assert s["mi_start"] < 0.3
    assert s["mi_end"] > s["mi_start"]
    assert s["dt_ms"] == 0.1 and s["default_dt_ms"] == pytest.approx(DEFAULT_DT_S * 1e3)
    assert 0 < s["slope_deg"] < 60  # free surface after min(5 s, half the run)
    assert 0 < s["overlap_p99_r"] <= 0.05 and 0 < s["wall_max_mm"] <= 2.0
    assert s["regime"] in ("rolling", "cascading", "cataracting") and s["froude"] > 0
    assert s["end_friction"] == pytest.approx(0.25)  # the end plates take the wall's (the paper's) friction
    rows = list(csv.DictReader(out_csv.open()))
    assert len(rows) == 16
    assert {"t_s", "rpm", "mi", "mi_sigmoid", "mi_particles", "slope_deg", "slope_deg_particles"} <= set(rows[0])
    assert abs(float(rows[-1]["mi"]) - float(rows[-1]["mi_particles"])) < 0.05
    cap = cv2.VideoCapture(str(out_mp4))
    assert cap.isOpened() and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 16
    cap.release()


def test_sim_end_friction_sets_the_end_plates_apart_from_the_wall():
    r = cli("sim", "--rpm", "5", "--duration", "2", "--fps", "2", "--end-friction", "0", "--json")
    assert r.code == 0, r.err
    assert json.loads(r.out)["end_friction"] == 0.0
    bad = cli("sim", "--end-friction", "-1")
    assert bad.code == 2 and "--end-friction" in bad.err and "Traceback" not in bad.err


@pytest.mark.timeout(240)
def test_sim_with_realism_still_measures_at_the_default_step():
    r = cli("sim", "--case", "C", "--rpm", "10", "--duration", "1", "--fps", "10", "--realism", "--json")
    assert r.code == 0, r.err
    s = json.loads(r.out)
    assert s["mi_start"] > 0.8
    assert s["dt_ms"] == pytest.approx(DEFAULT_DT_S * 1e3)


@pytest.mark.timeout(240)
def test_whatif_json_csv_and_plot(tmp_path):
    png = tmp_path / "w.png"
    out_csv = tmp_path / "w.csv"
    r = cli("whatif", "--rpm", "5,40", "--duration", "1.5", "--workers", "1", "--csv", out_csv, "--plot", png,
            "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert [e["rpm"] for e in out["rpm"]] == [5.0, 40.0]
    for e in out["rpm"]:
        assert 0 <= e["plateau_mi"] <= 1 and e["plateau_mi_sd"] >= 0 and e["t_plateau_s"] >= 0
        assert e["regime"] in ("rolling", "cascading", "cataracting") and 0 <= e["airborne"] <= 1
    assert out["rpm"][1]["froude"] > out["rpm"][0]["froude"]
    assert cv2.imread(str(png)) is not None
    assert len(out_csv.read_text().splitlines()) == 1 + 2 * 4


@pytest.mark.timeout(240)
def test_calibrate_from_frames(tmp_path):
    quick = ("--spin-up-s", "1", "--window-s", "1.5", "--max-evals", "4")  # 16 runs: the fit of 6's 20 (0.24 deg)
    # a folder of rendered frames as the measured source (the search itself: tests/sim/test_calibrate.py)
    from sim.drum import DrumSim
    from sim.render import Renderer

    sim = DrumSim(rpm=10.0, friction=0.2, rolling=0.1)
    ren = Renderer(sim, 360)
    sim.advance(2.0)
    for i in range(6):
        sim.advance(0.25)
        cv2.imwrite(str(tmp_path / f"f{i:02d}.png"), ren.render(sim.particles()))
    r = cli("calibrate", tmp_path, "--rpm", "10", "--json", *quick)
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["frames"] == 6
    assert abs(out["twin_slope_deg"] - out["slope_deg"]) <= 1.5
    assert out["range_deg"][0] - 1.0 <= out["slope_deg"] <= out["range_deg"][1] + 1.0
    assert {"friction", "rolling", "residual_deg", "path"} <= set(out)


def _truncated_jpeg(real_drum_dir: Path, tmp_path: Path) -> Path:
    """The first third of a real frame's JPEG bytes."""
    data = sorted((real_drum_dir / "images").glob("*.jpg"))[0].read_bytes()
    path = tmp_path / "TRUNCATED.jpg"
    path.write_bytes(data[: len(data) // 3])
    return path


@pytest.mark.parametrize(
    "args, needles",
    [
        (("sim", "--rpm", "90", "--duration", "1"), ("77.2",)),
        (("sim", "--case", "Q", "--duration", "1"), ("case",)),
        (("sim", "--duration", "1e307", "--fps", "240"), ("--duration", "3600")),
        (("sim", "--duration", "nan"), ("--duration",)),
        (("sim", "--duration", "inf"), ("--duration",)),
        (("sim", "--duration", "-1"), ("--duration",)),
        (("sim", "--duration", "1", "--fps", "0"), ("--fps", "240")),
        (("sim", "--duration", "1", "--fps", "nan"), ("--fps",)),
        (("sim", "--duration", "1", "--seed", "-1"), ("--seed", "2**32")),
        (("sim", "--duration", "1", "--seed", str(2**32)), ("--seed", "2**32")),
        (("sim", "--duration", "1", "--dt-ms", "0"), ("--dt-ms", "20")),
        (("sim", "--duration", "1", "--dt-ms", "inf"), ("--dt-ms",)),
        (("sim", "--duration", "1", "--dt-ms", "5"), ("too long", "contacts")),
        (("sim", "--duration", "1", "--friction", "nan"), ("--friction",)),
        (("sim", "--duration", "1", "--rolling", "-0.1"), ("--rolling",)),
        (("sim", "--duration", "1", "--size", "0"), ("--size",)),
        (("whatif", "--rpm", "5,x"), ("--rpm",)),
        (("whatif", "--rpm", "5,90"), ("77.2",)),
        (("whatif", "--seeds", "100000000"), ("--seeds", "1000")),
        (("whatif", "--rpm", "5", "--seeds", "0"), ("--seeds",)),
        (("whatif", "--rpm", "5", "--duration", "inf"), ("what-if duration", "3600")),  # the limits' one check
        (("whatif", "--rpm", "5", "--duration", "1", "--sample-s", "0"), ("--sample-s",)),
        (("whatif", "--rpm", "5", "--duration", "1", "--workers", "0"), ("--workers",)),
        (("whatif", "--rpm", "5", "--duration", "1", "--fill", "2"), ("--fill",)),
        (("calibrate", "--rpm", "5"), ("SOURCE or --slope-deg",)),
        (("calibrate", "/nonexistent/video.mp4", "--rpm", "5"), ("no such file",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "5", "--seed", "-1"), ("--seed", "2**32")),
        (("calibrate", "--slope-deg", "nan", "--rpm", "5"), ("--slope-deg",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "0"), ("--rpm",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "nan"), ("rpm",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "5", "--max-evals", "0"), ("--max-evals", "1")),
        (("calibrate", "--slope-deg", "30", "--rpm", "5", "--window-s", "0"), ("--window-s",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "5", "--curvature", "inf"), ("--curvature",)),
        (("calibrate", "--slope-deg", "30", "--rpm", "5", "--dt-ms", "-1"), ("--dt-ms",)),
        (("bench", "twin", "--duration", "1e9"), ("--duration", "600")),
        (("bench", "twin", "--duration", "nan"), ("--duration",)),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, needles):
    r = cli(*args)
    assert_one_line_error(r, *needles)
    assert r.out == ""


def test_a_truncated_image_is_one_line_and_exit_2(real_drum_dir, tmp_path):
    r = cli("calibrate", _truncated_jpeg(real_drum_dir, tmp_path), "--rpm", "5")
    assert_one_line_error(r)


@pytest.mark.timeout(120)
def test_a_target_outside_the_reachable_range_is_exit_2_with_the_range():
    r = cli("calibrate", "--slope-deg", "75", "--rpm", "10", "--spin-up-s", "0.5", "--window-s", "0.5")
    line = assert_one_line_error(r, "reachable range", "10 rpm")
    assert "75.0 deg" in line


def test_bad_input_through_the_console_script():
    r = subprocess.run([str(DRUMTWIN), "sim", "--rpm", "90", "--duration", "1"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "77.2" in " ".join(r.stderr.split()) and "Traceback" not in r.stderr


@BENCHES
@pytest.mark.timeout(240)
def test_bench_twin_prints_the_real_time_factors_and_the_step(cli_once):
    """``bench twin --duration 0.02 --json`` (the session's run, tests/conftest.py: shared with the
    bad-input sweep's base of ``bench twin``)."""
    r = cli_once("bench", "twin", *BENCH_TWIN_ARGS)
    assert r.code == 0, r.err
    out = json.loads(r.out)
    for k in ("rtf_paper_5rpm", "rtf_paper_30rpm", "rtf_4x", "rtf_16x"):
        assert out[k] > 0
    assert out["n_4x"] == 4 * out["n_paper_5rpm"]
    assert out["dt_ms"] == pytest.approx(DEFAULT_DT_S * 1e3) and out["cost_exponent_16x"] > 0
    # the pymunk engine in the same run: the same paper bed, and the cut-disc rig's 250 particles
    assert out["rtf_paper_5rpm_pymunk"] > 0 and out["n_paper_5rpm_pymunk"] == out["n_paper_5rpm"]
    assert out["rtf_cutdisc_10rpm_pymunk"] > 0 and out["n_cutdisc_10rpm_pymunk"] == 250
    # each at its own default step: the paper bed of discs 0.5 ms, the half-cut rig 1 ms
    assert out["dt_ms_paper_5rpm_pymunk"] == pytest.approx(0.5)
    assert out["dt_ms_cutdisc_10rpm_pymunk"] == pytest.approx(1.0)
    # where its step goes: 125 discs, 125 cut discs of 2 convex pieces each, a wall of 180 segments
    prof = out["profile_cutdisc_pymunk"]
    assert prof["shapes"] == 125 + 2 * 125 + 180 and prof["bodies"] == 251 and prof["iterations"] == 10
    assert prof["contacts_per_step"] > 250  # a settled bed: every particle touches something
    assert prof["chipmunk_share"] + prof["post_share"] == pytest.approx(1.0)

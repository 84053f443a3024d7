"""``drumtwin sim``, ``calibrate``, ``whatif`` and ``bench twin`` from the command line."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

DRUMTWIN = Path(sys.executable).with_name("drumtwin")


def run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """The real console script in a subprocess (end to end)."""
    return subprocess.run([str(DRUMTWIN), *args], capture_output=True, text=True, timeout=timeout)


def run_here(capsys, *args: str) -> tuple[int, str, str]:
    """The same entry point in this process (fast): exit code, stdout, stderr."""
    from twin.cli import main

    try:
        main(list(args))
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.timeout(240)
def test_sim_writes_csv_video_and_json_summary(tmp_path):
    out_csv = tmp_path / "mi.csv"
    out_mp4 = tmp_path / "run.mp4"
    r = run("sim", "--case", "A", "--rpm", "5", "--duration", "6", "--fps", "5", "--csv", str(out_csv),
            "--video", str(out_mp4), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["mi_start"] < 0.3
    assert summary["mi_end"] > summary["mi_start"]
    assert 0 < summary["slope_deg"] < 60
    rows = list(csv.DictReader(out_csv.open()))
    assert len(rows) == 31
    assert {"t_s", "rpm", "mi", "mi_sigmoid", "mi_particles", "slope_deg"} <= set(rows[0])
    assert abs(float(rows[-1]["mi"]) - float(rows[-1]["mi_particles"])) < 0.05
    cap = cv2.VideoCapture(str(out_mp4))
    assert cap.isOpened() and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 31
    cap.release()


@pytest.mark.timeout(240)
def test_sim_with_realism_still_measures(capsys):
    code, out, err = run_here(capsys, "sim", "--case", "C", "--rpm", "10", "--duration", "2", "--fps", "10",
                              "--realism", "--json")
    assert code == 0, err
    s = json.loads(out)
    assert s["mi_start"] > 0.8


@pytest.mark.timeout(240)
def test_whatif_json_csv_and_plot(tmp_path, capsys):
    png = tmp_path / "w.png"
    out_csv = tmp_path / "w.csv"
    code, stdout, err = run_here(capsys, "whatif", "--rpm", "5,20", "--duration", "3", "--workers", "2",
                                 "--csv", str(out_csv), "--plot", str(png), "--json")
    assert code == 0, err
    out = json.loads(stdout)
    assert [e["rpm"] for e in out["rpm"]] == [5.0, 20.0]
    assert [e["regime"] for e in out["rpm"]] == ["rolling", "cascading"]
    for e in out["rpm"]:
        assert 0 <= e["plateau_mi"] <= 1 and e["plateau_mi_sd"] >= 0 and e["t_plateau_s"] >= 0
    assert cv2.imread(str(png)) is not None
    assert len(out_csv.read_text().splitlines()) == 1 + 2 * 7


@pytest.mark.timeout(240)
def test_calibrate_from_a_slope_and_from_frames(tmp_path, capsys):
    code, stdout, err = run_here(capsys, "calibrate", "--slope-deg", "18", "--rpm", "5", "--json")
    assert code == 0, err
    out = json.loads(stdout)
    assert out["slope_deg"] == 18.0
    assert abs(out["twin_slope_deg"] - 18.0) <= 1.5
    assert {"friction", "rolling", "residual_deg"} <= set(out)
    # a folder of rendered frames as the measured source
    from sim.drum import DrumSim
    from sim.render import Renderer

    sim = DrumSim(rpm=5.0, friction=0.15)
    ren = Renderer(sim, 360)
    sim.advance(4.0)
    for i in range(8):
        sim.advance(0.5)
        cv2.imwrite(str(tmp_path / f"f{i:02d}.png"), ren.render(sim.particles()))
    code, stdout, err = run_here(capsys, "calibrate", str(tmp_path), "--rpm", "5", "--json")
    assert code == 0, err
    out = json.loads(stdout)
    assert out["frames"] == 8
    assert abs(out["twin_slope_deg"] - out["slope_deg"]) <= 1.5


@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    "args, needle",
    [
        (("sim", "--rpm", "90", "--duration", "1"), "77.2"),
        (("sim", "--case", "Q", "--duration", "1"), "case"),
        (("whatif", "--rpm", "5,x"), "--rpm"),
        (("whatif", "--rpm", "5", "--duration", "1", "--scheduler", "tcp://127.0.0.1:9"), "no Dask scheduler"),
        (("calibrate", "--rpm", "5"), "SOURCE or --slope-deg"),
        (("calibrate", "/nonexistent/video.mp4", "--rpm", "5"), "no such file"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, needle, capsys):
    code, out, err = run_here(capsys, *args)
    assert code == 2
    assert needle in " ".join(err.split())
    assert "Traceback" not in err and out == ""


def test_bad_input_through_the_console_script():
    r = run("sim", "--rpm", "90", "--duration", "1")
    assert r.returncode == 2 and "77.2" in " ".join(r.stderr.split()) and "Traceback" not in r.stderr


@pytest.mark.timeout(240)
def test_bench_twin_prints_the_four_real_time_factors(capsys):
    code, stdout, err = run_here(capsys, "bench", "twin", "--duration", "0.05", "--json")
    assert code == 0, err
    out = json.loads(stdout)
    for k in ("rtf_paper_5rpm", "rtf_paper_30rpm", "rtf_4x", "rtf_16x"):
        assert out[k] > 0
    assert out["n_4x"] == 4 * out["n_paper_5rpm"]

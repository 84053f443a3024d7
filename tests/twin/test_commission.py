"""``drumtwin commission`` (issue 39) on the real PMMA frames: the must-show command (the frames carry
neither the drum's size nor its speed; the report says they were given) exits 0 with every check passing,
writes mixer.toml and a self-contained report.html that opens in the real chromium with every section and
no blank picture, and ``drumtwin run --config mixer.toml`` takes the file as it is. Bad input (no drum, one
colour of particles, a video too short for a slope, an rpm of 0 or above critical, frames of two rigs) is
one line, exit 2, and nothing written.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.cli import CliResult, assert_one_line_error, cli
from tests.conftest import COMMISSION
from twin.commission.checks import STEPS
from twin.commission.report import SECTIONS

pytestmark = [COMMISSION]


def check_lines(r: CliResult) -> list[str]:
    return [ln for ln in r.err.splitlines() if ln.startswith("check failed:")]


@pytest.mark.slow
def test_commissioning_the_real_pmma_frames_passes_every_check(commission_pmma: tuple[CliResult, Path]) -> None:
    r, out = commission_pmma
    assert "Traceback" not in r.err
    assert (out / "mixer.toml").is_file() and (out / "report.html").is_file(), r.err[-2000:]
    progress = [ln for ln in r.err.splitlines() if ln.startswith("commission: ")]
    for step in ("drum", "classes", "census", "light", "calibration", "twin"):  # each step's name and time, in order
        assert any(ln.startswith(f"commission: {step}: ") and "s CPU)" in ln for ln in progress), (step, r.err)
    page = (out / "report.html").read_text()
    assert "250 mm (given" in page and "5 rpm (given" in page  # the frames carry neither number
    assert r.code == 0, r.err[-3000:]
    assert "Every check passed" in page and 'class="fail"' not in page
    assert not check_lines(r)


@pytest.mark.slow
def test_the_commissioned_mixer_describes_the_pmma_rig(commission_pmma: tuple[CliResult, Path]) -> None:
    """mixer.toml: the learned classes with the set-up light, the census's mixer (the labels' 122 blue discs
    of 9.3 mm, the rig turning clockwise), and the friction the calibration found."""
    from twin.config import load_checked_config

    r, out = commission_pmma
    checked = load_checked_config(out / "mixer.toml")  # the one validation every command applies
    m = checked.mixer
    assert [k.name for k in checked.meter.counted] == ["blue", "white"] and checked.meter.light_reference
    assert [p.shape.kind for p in m.particles] == ["disc", "disc"] and m.monolayer and m.direction == -1
    assert m.particles[0].shape.diameter_m * 1e3 == pytest.approx(9.3, abs=0.4)
    from sim.mixer import resolve

    assert resolve(m)[0].count == pytest.approx(122, abs=6)
    table = tomllib.loads((out / "mixer.toml").read_text())
    if r.code == 0:
        assert m.friction is not None and table["drum"]["friction"]["sliding"] == pytest.approx(m.friction.sliding)


@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.timeout(180)
def test_the_report_opens_in_chromium_with_every_section_and_no_blank_picture(
        commission_pmma: tuple[CliResult, Path], page) -> None:
    _, out = commission_pmma
    asked: list[str] = []
    page.route("**/*", lambda route: (asked.append(route.request.url), route.continue_()
                                      if route.request.url.startswith("file:") else route.abort()))
    page.goto((out / "report.html").resolve().as_uri())
    assert [u for u in asked if not u.startswith("file:")] == []  # self-contained: no request leaves the file
    shown = page.eval_on_selector_all("section[data-section]", "els => els.map(e => [e.dataset.section, "
                                      "e.innerText.length])")
    assert [s for s, _ in shown] == [s for s, _ in SECTIONS] and all(n > 20 for _, n in shown), shown
    pics = page.eval_on_selector_all("img", """els => els.map(e => {
        const c = document.createElement('canvas'); c.width = e.naturalWidth; c.height = e.naturalHeight;
        const g = c.getContext('2d'); g.drawImage(e, 0, 0);
        const d = g.getImageData(0, 0, c.width, c.height).data; let lo = 255, hi = 0;
        for (let i = 0; i < d.length; i += 4 * 97) { const v = d[i] + d[i + 1] + d[i + 2];
            lo = Math.min(lo, v); hi = Math.max(hi, v); }
        return [e.dataset.pic, e.complete, e.naturalWidth, hi - lo]; })""")
    assert {p[0] for p in pics} == {"preview", "census", "calibration", "twin"}, pics
    for name, complete, width, span in pics:
        assert complete and width > 100 and span > 60, (name, width, span)  # drawn, and not one flat colour
    rows = page.eval_on_selector_all("section[data-section=checks] tr", "els => els.length")
    assert rows >= 1 + len(STEPS)  # a header and at least a check per step


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_run_takes_the_commissioned_mixer_toml_as_it_is(commission_pmma: tuple[CliResult, Path], real_drum_dir: Path,
                                                        tmp_path: Path) -> None:
    """``drumtwin run --config mixer.toml`` on a video of the rig's frames: the twin is the commissioned
    mixer (seeded with its particles), starting from the calibrated friction; nothing to edit."""
    from control.device import DeviceConfig
    from control.emulator import MillEmulator
    from sim.mixer import resolve
    from twin.config import load_checked_config
    from twin.runlog import read_events

    _, out = commission_pmma
    video = tmp_path / "rig.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 10.0, (640, 640))
    for f in sorted((real_drum_dir / "images").glob("*.jpg"))[3:]:
        vw.write(cv2.imread(str(f)))
    vw.release()
    emu = MillEmulator(DeviceConfig(watchdog_s=300.0), seed=1)
    port = emu.open_tcp(0)
    emu.set_motor(setpoint_rpm=5.0, actual_rpm=5.0, running=True)
    try:
        r = cli("run", "--video", video, "--mill", f"socket://127.0.0.1:{port}", "--config", out / "mixer.toml",
                "--mode", "off", "--no-dashboard", "--duration", "3", "--log", tmp_path / "run")
    finally:
        emu.close()
    assert r.code == 0, r.err[-2000:]
    seeded = [e for e in read_events(tmp_path / "run") if e["kind"] == "twin_seeded"]
    mixer = load_checked_config(out / "mixer.toml").mixer
    assert seeded and seeded[0]["n_particles"] == sum(k.count for k in resolve(mixer))


# -- bad input: one line, exit 2, nothing written ---------------------------------------------------------
def _nothing_written(where: Path) -> None:
    assert sorted(p.name for p in where.iterdir()) == ["in"], list(where.iterdir())  # no out, no hidden temp


def _commission(tmp_path: Path, *args: object) -> CliResult:
    return cli("commission", *args, "--out", tmp_path / "out")


def _write(folder: Path, frames: list[np.ndarray]) -> Path:
    folder.mkdir(parents=True)
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{i:03d}.png"), f)
    return folder


def test_no_drum_is_one_line(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    frames = []
    for _ in range(6):  # a bench top: a flat grey with a little sensor noise, no rim anywhere
        f = np.full((240, 320, 3), 90, np.uint8)
        frames.append(np.clip(f + rng.normal(0, 3, f.shape), 0, 255).astype(np.uint8))
    src = _write(tmp_path / "in", frames)
    assert_one_line_error(_commission(tmp_path, src, "--drum-diameter-mm", "250", "--rpm", "5"), "no drum")
    _nothing_written(tmp_path)


@pytest.mark.parametrize(("rpm", "says"), [("0", "must be turning"), ("-3", "must be turning"),
                                           ("90", "above the critical speed")])
def test_an_rpm_of_zero_or_above_critical_is_one_line(tmp_path: Path, real_drum_dir: Path, rpm: str, says: str) -> None:
    (tmp_path / "in").mkdir()
    r = _commission(tmp_path, real_drum_dir / "images", "--drum-diameter-mm", "250", "--rpm", rpm)
    assert_one_line_error(r, "--rpm", says)
    _nothing_written(tmp_path)


def _rig_frames(n: int, same_colour: bool = False, size: int = 480) -> list[np.ndarray]:
    from dataclasses import replace

    from twin.commission.rigs import WHITE_BGR, RigRun, disc_rig, film

    m = disc_rig()
    if same_colour:
        m = replace(m, particles=tuple(replace(p, colour_bgr=WHITE_BGR) for p in m.particles))
    return film(m, RigRun(size_px=size, frames=n, spin_up_s=1.0))


@pytest.mark.timeout(120)
def test_one_colour_of_particles_is_one_line(tmp_path: Path) -> None:
    src = _write(tmp_path / "in", _rig_frames(6, same_colour=True))
    r = _commission(tmp_path, src, "--drum-diameter-mm", "120", "--rpm", "5")
    assert_one_line_error(r, "one colour of particles")
    _nothing_written(tmp_path)


@pytest.mark.timeout(120)
def test_a_video_too_short_for_a_slope_is_one_line(tmp_path: Path, real_drum_dir: Path) -> None:
    (tmp_path / "in").mkdir()
    video = tmp_path / "in" / "short.avi"
    vw = cv2.VideoWriter(str(video), cv2.VideoWriter.fourcc(*"MJPG"), 30.0, (640, 640))
    for f in sorted((real_drum_dir / "images").glob("*.jpg"))[5:8]:  # three frames: a tenth of a second
        vw.write(cv2.imread(str(f)))
    vw.release()
    r = _commission(tmp_path, video, "--drum-diameter-mm", "250", "--rpm", "5")
    assert_one_line_error(r, "too few frames to measure a slope", "3 of 3")
    _nothing_written(tmp_path)


def test_frames_of_two_rigs_are_one_line(tmp_path: Path, real_drum_dir: Path) -> None:
    pmma = [cv2.imread(str(f)) for f in sorted((real_drum_dir / "images").glob("*.jpg"))[:4]]
    src = _write(tmp_path / "in", pmma + _rig_frames(3, size=640))  # the same frame size, another drum
    r = _commission(tmp_path, src, "--drum-diameter-mm", "250", "--rpm", "5")
    assert_one_line_error(r, "frames of two rigs", "004.png")
    _nothing_written(tmp_path)
    other = _write(tmp_path / "in2", [pmma[0], cv2.resize(pmma[1], (480, 480))])  # another camera's frame size
    assert_one_line_error(_commission(tmp_path, other, "--drum-diameter-mm", "250", "--rpm", "5"), "two rigs",
                          "480x480")


def test_an_out_folder_that_exists_is_refused_before_any_work(tmp_path: Path, real_drum_dir: Path) -> None:
    (tmp_path / "in").mkdir()
    (tmp_path / "out").mkdir()
    r = cli("commission", real_drum_dir / "images", "--drum-diameter-mm", "250", "--rpm", "5", "--out",
            tmp_path / "out")
    assert_one_line_error(r, "exists", "nothing is overwritten")
    assert not any((tmp_path / "out").iterdir())

"""Commissioning's steps, in order, on a rig's frames: the drum, the camera's orientation, the colour
classes, the light reference, the census, the calibration, the twin against the camera. Each step
reports its name and time as it goes (``progress``) and adds its checks (``twin.commission.checks``).

Bad input (what no check can judge: no drum, one class only, a source too short for a slope, an rpm
the drum cannot turn at, frames of two rigs) is a one-line error (``VisionError``/``SimError``/
``TwinError``) before anything is written. The calibration is called in one place
(``calibrate_twin``): a slope out of the twin's reach fails its check with the calibration's message
as the advice, and the twin is then checked uncalibrated (the report shows how far off it is).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NoReturn

import numpy as np

from sim.calibrate import CONFIRM_EVALS
from sim.errors import SimError
from sim.mixer import Friction, Mixer
from twin.commission import checks as ck
from twin.commission.measure import FrameMeasure, Summary, measure_frame, summarize
from twin.commission.source import MAX_FRAMES, RigFrames, rig_frames
from twin.commission.twin_check import TWIN_RUN, CheckRuns, TwinFrames
from vision.colours import ColourClass
from vision.config import MeterConfig
from vision.errors import VisionError
from vision.roi import DrumROI

MIN_SLOPE_FRAMES = 5  # frames with a free surface the camera's slope needs, at least
MIN_CHROMA_APART = 5.0  # two classes whose mean colours (CIELAB a, b) are closer are one material in light and
# shade (one colour of particles: 0.6 apart on a rendered white bed; the PMMA rig's blue/white 64, teal/white 25)
CENSUS_FRAMES = 24  # frames the census measures (the first of the frames kept, spread over the source)
CALIBRATE: dict[str, Any] = {"confirm_evals": CONFIRM_EVALS, "tol_deg": ck.TOLERANCES.slope_deg / 2}
"""Keyword arguments of the one calibration call (``calibrate_twin``): the search as ``sim.calibrate.
calibrate``'s defaults, then up to ``CONFIRM_EVALS`` (3) confirming runs, each the twin-vs-camera check's own run
(``twin_check.CheckRuns``), until the twin's slope is within half the check's tolerance: a search run
(one seed, 5 s) is good to 2-4 deg on a monolayer, the check's run to about 0.5 (docs/commissioning.md)."""

Progress = Callable[[str, str], None]
"""``progress(step, message)``: a step's name and what it did (with its time)."""


@dataclass(frozen=True)
class Given:
    """What the user gave: the frames (``source``), the drum's inner diameter (mm) and speed (rpm) the
    frames carry neither of, and optionally the drum's depth (mm; None: a monolayer), the camera's
    turn (deg; None: proposed from the frames), the drum's circle and the twin's engine."""

    source: tuple[str, ...]
    drum_diameter_mm: float
    rpm: float
    drum_depth_mm: float | None = None
    camera_rotation_deg: float | None = None
    roi: DrumROI | None = None
    engine: str | None = None
    max_frames: int = MAX_FRAMES


@dataclass(frozen=True)
class StepTime:
    step: str
    wall_s: float
    cpu_s: float


@dataclass
class Commission:
    """Everything commissioning found (the report draws it, ``mixer.toml`` is written from it)."""

    given: Given
    frames: RigFrames
    cfg: MeterConfig
    camera: list[FrameMeasure]
    camera_summary: Summary
    mixed: np.ndarray
    suggested: Any  # twin.suggest_mixer.SuggestedMixer
    mixer: Mixer
    calibration: Any = None  # sim.calibrate.Calibration, None when it failed
    calibration_error: str | None = None
    target_slope_deg: float = math.nan
    twin: TwinFrames | None = None
    twin_summary: Summary | None = None
    checks: list[ck.Check] = field(default_factory=list)
    times: list[StepTime] = field(default_factory=list)

    @property
    def cpu_s(self) -> float:
        return sum(t.cpu_s for t in self.times)

    @property
    def wall_s(self) -> float:
        return sum(t.wall_s for t in self.times)


def check_given(g: Given) -> None:
    """The numbers the user gave, each a one-line error when out of range (before any work)."""
    from sim.engine import check_engine
    from sim.errors import check_number
    from sim.params import check_rpm
    from sim.recipe import DrumSpec

    check_number("--drum-diameter-mm", g.drum_diameter_mm, 10.0, 1e4)
    if g.drum_depth_mm is not None:
        check_number("--drum-depth-mm", g.drum_depth_mm, 0.1, 1e4)
    if not (math.isfinite(g.rpm) and g.rpm > 0):
        raise SimError(f"--rpm {g.rpm:g}: the drum must be turning in the frames (rpm > 0)")
    try:
        check_rpm(g.rpm, DrumSpec(g.drum_diameter_mm * 1e-3, 0.01))
    except SimError as exc:
        raise SimError(f"--rpm {g.rpm:g}: {exc}") from None
    if g.camera_rotation_deg is not None:
        check_number("--camera-rotation-deg", g.camera_rotation_deg, -360.0, 360.0)
    check_number("--frames", g.max_frames, MIN_SLOPE_FRAMES, 500, integer=True)
    check_engine(g.engine)


def calibrate_twin(mixer: Mixer, target_slope_deg: float, rpm: float, engine: str | None, measure: CheckRuns,
                   progress: Callable[[int, int], None] | None = None) -> tuple[Any, Friction | None, str | None]:
    """The one calibration call: ``sim.calibrate.calibrate`` of ``mixer`` to the camera's slope at
    ``rpm`` (``CALIBRATE``), confirmed by the check's runs (``measure``), and the friction it gives the
    mixer. A slope the twin cannot reach: (None, None, the calibration's message)."""
    from sim.calibrate import calibrate

    try:
        cal = calibrate(target_slope_deg, rpm, mixer=mixer, engine=engine, progress=progress, measure=measure,
                        **CALIBRATE)
    except SimError as exc:
        return None, None, str(exc)
    plates = float(cal.end_friction) if cal.end_friction_max > 0 else None  # a monolayer's: calibrated
    return cal, Friction(sliding=float(cal.friction), rolling=float(cal.rolling), end_plates=plates), None


class _Clock:
    """Each step's wall and CPU time, reported as it ends; held back until ``accept`` (the input is
    known good): bad input is one line, never a step's progress before it."""

    def __init__(self, progress: Progress) -> None:
        self.progress, self.times = progress, []  # type: tuple[Progress, list[StepTime]]
        self._held: list[tuple[str, str]] | None = []
        self._t = (time.perf_counter(), time.process_time())

    def done(self, step: str, message: str) -> None:
        w, c = time.perf_counter(), time.process_time()
        t = StepTime(step, w - self._t[0], c - self._t[1])
        self.times.append(t)
        self._t = (w, c)
        line = (step, f"{message} ({t.wall_s:.1f} s, {t.cpu_s:.1f} s CPU)")
        if self._held is None:
            self.progress(*line)
        else:
            self._held.append(line)

    def accept(self) -> None:
        """The input is good: the steps held back are reported, and each later one as it ends."""
        for line in self._held or ():
            self.progress(*line)
        self._held = None


def _chroma(c: ColourClass) -> np.ndarray:
    """A learned class's mean colour's (a, b) in CIELAB (its components weighted)."""
    w = np.array([k.weight for k in c.lab], dtype=float)
    m = np.array([k.mean_lab for k in c.lab], dtype=float)
    return (w[:, None] * m).sum(axis=0)[1:] / w.sum()


def _classes(g: Given, fr: RigFrames) -> MeterConfig:
    """The colour classes learned from the frames; one class only (or classes of one colour, lighter and
    darker: one material in light and shade) is bad input."""
    from vision.suggest import suggest_classes

    cfg = suggest_classes(fr.images, rois=fr.rois, camera_rotation_deg=g.camera_rotation_deg)
    cs = [c for c in cfg.counted if c.lab]
    names = ", ".join(c.name for c in cfg.counted)
    if len(cfg.counted) < 2:
        raise VisionError(f"one colour class only in the frames ({names}): commissioning needs two kinds of "
                          "particles that differ in colour")
    gap = min((float(np.hypot(*(_chroma(a) - _chroma(b)))) for i, a in enumerate(cs) for b in cs[i + 1:]),
              default=math.inf)
    if gap < MIN_CHROMA_APART:
        raise VisionError(f"one colour of particles in the frames: the classes learned ({names}) differ in "
                          f"lightness only ({gap:.1f} apart in colour), one material in light and shade; "
                          "commissioning needs two kinds of particles that differ in colour")
    return cfg


def _camera(cfg: MeterConfig, fr: RigFrames, diameter_px: float) -> list[FrameMeasure]:
    """Each frame measured by the camera's meter (the drum found per frame, as the live meter does)."""
    out = []
    for img, roi in zip(fr.images, fr.rois, strict=True):
        out.append(measure_frame(cfg, cfg.make_meter(roi=roi), img, roi, diameter_px))
    return out


def _setup_checks(c: Commission) -> list[ck.Check]:
    fr, cam, cfg = c.frames, c.camera, c.cfg
    cen = c.suggested.census
    shares = {k.name: k.pixel_share for k in cen.classes}
    flagged = sum(any(f.startswith("lighting_changed") for f in m.flags) for m in cam)
    return [ck.drum_check([r.r_px for r in fr.rois], [r.cx_px for r in fr.rois], [r.cy_px for r in fr.rois]),
            ck.orientation_check(c.camera_summary.bed_angle_deg, cfg.camera_rotation_deg),
            ck.classes_check(shares, cfg.warnings), ck.light_check(flagged, len(cam)),
            ck.census_check(cen.frame_counts or [math.nan])]


def _twin_checks(cam: Summary, tw: Summary, names: Sequence[str], calibrated: bool) -> list[ck.Check]:
    out = [ck.slope_check(tw.slope_deg, cam.slope_deg), ck.fill_check(tw.cover, cam.cover), ck.mi_check(tw.mi, cam.mi)]
    out += [ck.spread_check(n, t, k) for n, t, k in zip(names, tw.ratios, cam.ratios, strict=True)]
    if not calibrated:
        out = [replace(x, detail=x.detail + "; the twin uncalibrated (the engine's friction)") for x in out]
    return out


def _too_short(slopes: int, frames: int) -> NoReturn:
    raise VisionError(f"too few frames to measure a slope: {slopes} of {frames} frames show a free surface, "
                      f"commissioning needs {MIN_SLOPE_FRAMES} (a longer video, or more frames)")


def commission(g: Given, progress: Progress, frames: RigFrames | None = None) -> Commission:
    """Run every step on the frames of ``g`` (``frames``: already read, e.g. from a live camera; see the
    module doc)."""
    from twin.suggest_mixer import suggest_mixer

    check_given(g)
    clock = _Clock(progress)
    fr = frames if frames is not None else rig_frames(list(g.source) if len(g.source) > 1 else g.source[0], g.roi,
                                                      g.max_frames)
    if len(fr.images) < MIN_SLOPE_FRAMES:  # too short whatever the frames show: said before any learning
        _too_short(len(fr.images), len(fr.images))
    clock.done("drum", f"{len(fr.images)} frames with a drum (of {fr.total} read), radius "
                       f"{np.median([r.r_px for r in fr.rois]):.0f} px")
    cfg = _classes(g, fr)
    clock.done("classes", f"classes {', '.join(c.name for c in cfg.counted)}; camera turned "
                          f"{cfg.camera_rotation_deg:g} deg")
    n = min(CENSUS_FRAMES, len(fr.images))
    try:
        sug = suggest_mixer(cfg, fr.images[:n], fr.rois[:n], g.drum_diameter_mm, g.drum_depth_mm)
    except SimError as exc:
        raise VisionError(str(exc)) from None
    d_px = float(np.median([c.diameter_px for c in sug.census.classes]))
    clock.done("census", ", ".join(f"{c.name} {c.count:.0f} x {c.diameter_px * sug.mm_per_px:.1f} mm"
                                   for c in sug.census.classes))
    cam = _camera(cfg, fr, d_px)
    mixed = ck.mixed_frames([m.mi for m in cam])
    summ = summarize(cam, mixed)
    if summ.slopes < MIN_SLOPE_FRAMES:
        _too_short(summ.slopes, len(cam))
    clock.done("light", f"camera: slope {summ.slope_deg:.1f} deg, MI {summ.mi:.3f} on {summ.mixed} mixed frames")
    clock.accept()
    c = Commission(g, fr, cfg, cam, summ, mixed, sug, sug.mixer, target_slope_deg=summ.slope_deg)
    c.checks = _setup_checks(c)
    runs = CheckRuns(sug.mixer, g.rpm, cfg, float(np.median([r.r_px for r in fr.rois])), d_px, engine=g.engine)
    cal, friction, err = calibrate_twin(sug.mixer, summ.slope_deg, g.rpm, g.engine, runs)
    c.calibration, c.calibration_error = cal, err
    c.mixer = replace(sug.mixer, friction=friction)
    c.checks.append(ck.calibration_check(math.nan if cal is None else cal.residual_deg, err))
    clock.done("calibration", err or f"sliding {cal.friction:.3f}, rolling {cal.rolling:.3f}, residual "
                                     f"{cal.residual_deg:+.2f} deg ({cal.confirmations} confirming runs)")
    c.twin = runs.frames(friction or Friction())  # the answer's confirming run (uncalibrated: the engine's friction)
    c.twin_summary = summarize(list(c.twin.measures))
    c.checks += _twin_checks(summ, c.twin_summary, [k.name for k in cfg.counted], cal is not None)
    clock.done("twin", f"twin: slope {c.twin_summary.slope_deg:.1f} deg, MI {c.twin_summary.mi:.3f} on "
                       f"{TWIN_RUN.frames} frames")
    c.times = clock.times
    return c


__all__ = ["CALIBRATE", "CENSUS_FRAMES", "MIN_SLOPE_FRAMES", "Commission", "Given", "StepTime",
           "calibrate_twin", "check_given", "commission"]

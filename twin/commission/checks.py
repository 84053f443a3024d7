"""The commissioning checks, pure: each step's number against its tolerance, and what to do when it
is off. The tolerances live here and only here (``TOLERANCES``); the report prints them.

A ``Check`` is one row of the report's table: the measured value, what it is held against (the
camera's number, or a bound), the tolerance, the verdict and one line of advice for when it fails.
The twin-vs-camera checks (issue 39 item 4) compare the calibrated twin, rendered and measured by the
camera's meter, with the camera's frames:

- **slope**: the free surface's slope (median over frames, deg) within ``slope_deg``;
- **fill**: the share of the drum the bed covers (``vision.census.bed_cover``, median) within
  ``fill_rel`` of the camera's (relative);
- **MI**: the twin's plateau MI (eq. 4, median) within ``mi`` of the camera's on its mixed frames;
- **spread**: each class's spread about the bed's centroid over the bed's own (``vision.census.
  spread_ratios``, median) within ``spread_ratio`` of the camera's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tolerances:
    """Every tolerance of the commissioning checks (units in the names)."""

    slope_deg: float = 1.0  # twin's free-surface slope against the camera's
    fill_rel: float = 0.05  # twin's bed cover against the camera's, relative
    mi: float = 0.05  # twin's plateau MI against the camera's MI on its mixed frames
    spread_ratio: float = 0.1  # each class's spread ratio, twin against camera
    drum_rel: float = 0.02  # the drum's circle from frame to frame (radius and centre, in radii)
    bed_down_deg: float = 60.0  # the bed's centroid, seen from the drum's axis, from gravity's down
    light_flagged: float = 0.10  # share of the set-up frames the meter may flag for their light
    count_spread: float = 0.15  # particles per frame: interquartile range over median
    min_class_share: float = 0.05  # each class's share of the bed's classified pixels, at least


TOLERANCES = Tolerances()

STEPS: tuple[tuple[str, str], ...] = (
    ("drum", "Drum"),
    ("orientation", "Camera orientation"),
    ("classes", "Colour classes"),
    ("light", "Light reference"),
    ("census", "Census"),
    ("calibration", "Calibration"),
    ("twin", "Twin against camera"),
)
"""(id, title) of each step, in the order they run; every ``Check`` belongs to one."""


@dataclass(frozen=True)
class Check:
    """One check: ``value`` held against ``target`` (None: against a bound) within ``tolerance``
    (``unit``); ``passed``; ``advice``: one line saying what to do when it fails; ``detail``: how
    the value was measured."""

    step: str
    name: str
    value: float
    target: float | None
    tolerance: float
    unit: str
    passed: bool
    advice: str
    detail: str = ""

    @property
    def off(self) -> float:
        """``value - target`` (NaN against a bound)."""
        return self.value - self.target if self.target is not None else math.nan


def _close(step: str, name: str, value: float, target: float, tol: float, unit: str, advice: str,
           detail: str = "", relative: bool = False) -> Check:
    """``value`` within ``tol`` of ``target`` (relative: of ``|target|``); NaN fails."""
    scale = abs(target) if relative else 1.0
    ok = bool(math.isfinite(value) and math.isfinite(target) and abs(value - target) <= tol * scale)
    return Check(step, name, float(value), float(target), tol, unit, ok, advice, detail)


def _bound(step: str, name: str, value: float, tol: float, unit: str, advice: str, detail: str = "",
           at_least: bool = False) -> Check:
    """``value`` at most (``at_least``: at least) ``tol``; NaN fails."""
    ok = bool(math.isfinite(value) and (value >= tol if at_least else value <= tol))
    return Check(step, name, float(value), None, tol, unit, ok, advice, detail)


# -- the set-up steps --------------------------------------------------------------------------------
def drum_check(r_px: Sequence[float], cx_px: Sequence[float], cy_px: Sequence[float],
               tol: Tolerances = TOLERANCES) -> Check:
    """The drum's circle steady from frame to frame: its largest move (radius or centre) over the
    median radius."""
    r = np.asarray(r_px, dtype=float)
    rm = float(np.median(r))
    move = max(float(np.max(np.abs(r - rm))), float(np.max(np.hypot(np.asarray(cx_px) - np.median(cx_px),
                                                                     np.asarray(cy_px) - np.median(cy_px)))))
    return _bound("drum", "drum circle steady", move / rm, tol.drum_rel, "of R",
                  "the drum moves between frames: fix the camera (or pass --roi cx,cy,r)",
                  f"found in {len(r)} frames, radius {rm:.1f} px")


def orientation_check(bed_angle_deg: float, rotation_deg: float, tol: Tolerances = TOLERANCES) -> Check:
    """The bed lies at the bottom in gravity's frame: its centroid's angle, seen from the drum's axis,
    from straight down (deg, median over frames)."""
    return _bound("orientation", "bed at the bottom", abs(bed_angle_deg), tol.bed_down_deg, "deg",
                  "the bed does not lie at the bottom: pass --camera-rotation-deg (how far the camera is turned)",
                  f"camera turned {rotation_deg:g} deg")


def classes_check(shares: dict[str, float], warnings: Sequence[str], tol: Tolerances = TOLERANCES) -> Check:
    """Every colour class is in the bed (its share of the classified pixels at least ``min_class_share``)
    and no two classes lack a valley between their colours (``suggest``'s warnings)."""
    name, low = min(shares.items(), key=lambda kv: kv[1])
    c = _bound("classes", "smallest class's share", low, tol.min_class_share, "", f"class {name!r} is hardly in "
               "the bed: give frames where every kind of particle shows", ", ".join(f"{k} {v:.2f}"
                                                                                  for k, v in shares.items()),
               at_least=True)
    if warnings and c.passed:
        return Check(c.step, c.name, c.value, None, c.tolerance, c.unit, False, warnings[0], c.detail)
    return c


def light_check(flagged: int, frames: int, tol: Tolerances = TOLERANCES) -> Check:
    """The set-up frames measured against the light reference learned from them: the share the meter
    flags (``lighting_changed``)."""
    return _bound("light", "frames flagged for their light", flagged / max(frames, 1), tol.light_flagged, "",
                  "the light changes through the frames: film the set-up under the light the rig runs in",
                  f"{flagged} of {frames} frames")


def census_check(counts: Sequence[float], tol: Tolerances = TOLERANCES) -> Check:
    """Particles per frame steady (the whole bed in view, one rig): interquartile range over median."""
    c = np.asarray(counts, dtype=float)
    q1, med, q3 = (float(v) for v in np.percentile(c, [25, 50, 75]))
    return _bound("census", "particles per frame steady", (q3 - q1) / med if med > 0 else math.inf,
                  tol.count_spread, "", "the particle count changes between frames: check the class map "
                  "(--preview) and that every frame shows the same rig", f"median {med:.0f} per frame")


def calibration_check(residual_deg: float, error: str | None, tol: Tolerances = TOLERANCES) -> Check:
    """The calibration reached the camera's slope: its answer's residual (deg; its confirming run, the
    twin-vs-camera check's own, so within the slope check's tolerance), or why it could not (``error``:
    the calibration's message, the advice)."""
    if error is not None:
        return Check("calibration", "calibration residual", math.nan, None, tol.slope_deg, "deg", False,
                     error, "no calibration")
    return _bound("calibration", "calibration residual", abs(residual_deg), tol.slope_deg, "deg",
                  "the calibration stopped short of the slope: more frames, or a rig the twin can reach")


# -- the twin against the camera ---------------------------------------------------------------------
def slope_check(twin_deg: float, camera_deg: float, tol: Tolerances = TOLERANCES) -> Check:
    return _close("twin", "free-surface slope", twin_deg, camera_deg, tol.slope_deg, "deg",
                  "the twin's slope is off the camera's: re-run commissioning with more frames of the turning "
                  "drum (the calibration's target is their median)", "median over frames")


def fill_check(twin: float, camera: float, tol: Tolerances = TOLERANCES) -> Check:
    return _close("twin", "fill (bed cover)", twin, camera, tol.fill_rel, "relative",
                  "the twin's bed covers another share of the drum: check the particle size and counts of the "
                  "census (mixer.toml), and --drum-diameter-mm", "share of the drum, median", relative=True)


def mi_check(twin: float, camera: float, tol: Tolerances = TOLERANCES) -> Check:
    return _close("twin", "plateau MI", twin, camera, tol.mi, "",
                  "the twin mixes to another MI than the camera sees: check the classes' shares and shapes "
                  "(mixer.toml), or give frames of the mixed bed", "eq. 4; the camera's mixed frames")


def spread_check(name: str, twin: float, camera: float, tol: Tolerances = TOLERANCES) -> Check:
    return _close("twin", f"spread ratio {name}", twin, camera, tol.spread_ratio, "",
                  f"class {name!r} sits elsewhere in the twin's bed (core or rim) than in the camera's: check its "
                  "size, shape and density (mixer.toml)", "its spread about the bed's centroid over the bed's")


# -- pure helpers --------------------------------------------------------------------------------------
def mixed_frames(mi: Sequence[float], tol: Tolerances = TOLERANCES) -> np.ndarray:
    """Which frames (in time order) show the mixed bed: from the first whose MI comes within ``mi`` of
    the plateau (the median MI of the last half of the valid frames: a batch ends mixed) to the end,
    valid frames only. All False when no frame is valid."""
    m = np.asarray(mi, dtype=float)
    ok = np.isfinite(m)
    if not ok.any():
        return np.zeros(m.shape, dtype=bool)
    valid = m[ok]
    plateau = float(np.median(valid[len(valid) // 2:]))
    near = ok & (m >= plateau - tol.mi)
    first = int(np.argmax(near))
    out = np.zeros(m.shape, dtype=bool)
    out[first:] = ok[first:]
    return out


def failed(checks: Sequence[Check]) -> list[Check]:
    return [c for c in checks if not c.passed]


EXIT_FAILED = 1
"""Exit code when the rig was measured and written but a check failed (bad input is 2, nothing written)."""


def exit_code(checks: Sequence[Check]) -> int:
    """0 when every check passed, else ``EXIT_FAILED``."""
    return EXIT_FAILED if failed(checks) else 0


__all__ = ["EXIT_FAILED", "STEPS", "TOLERANCES", "Check", "Tolerances", "calibration_check", "census_check",
           "classes_check", "drum_check", "exit_code", "failed", "fill_check", "light_check", "mi_check",
           "mixed_frames", "orientation_check", "slope_check", "spread_check"]

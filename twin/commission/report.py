"""The commissioning report: one self-contained HTML file (every picture inline, no request of any
kind) of what commissioning found. Sections (``SECTIONS``, each a ``<section data-section=...>``): what
was given, every check with its value, tolerance and verdict, the class preview, the census with its
overlay of traced shapes, the calibration curve, the twin's frame beside a camera frame, the written
``mixer.toml``, each step's time."""

from __future__ import annotations

import html
import math
from typing import Any

from twin.commission import figures
from twin.commission.checks import STEPS, TOLERANCES, Check
from twin.commission.steps import Commission
from twin.commission.twin_check import TWIN_RUN, seeds_spread
from twin.report.build import CSS, fmt, table

SECTIONS: tuple[tuple[str, str], ...] = (
    ("given", "What was given"),
    ("checks", "Checks"),
    ("preview", "Colour classes"),
    ("census", "Census: sizes, counts, shares, shapes"),
    ("calibration", "Calibration"),
    ("twin", "Twin against camera"),
    ("mixer", "mixer.toml"),
    ("times", "Steps and times"),
)
EXTRA_CSS = """
.pass{color:#1b5e20;font-weight:bold} .fail{color:#b71c1c;font-weight:bold}
img.pic{max-width:100%;height:auto;border:1px solid #eee;display:block;margin:6px 0}
.verdict{font-size:18px;margin:8px 0}
"""


def _img(section: str, uri: str, alt: str) -> str:
    return f'<img class="pic" data-pic="{section}" alt="{html.escape(alt)}" src="{uri}">'


def _num(v: float, spec: str = ".3g") -> str:
    return fmt(v, spec) if isinstance(v, float) and math.isfinite(v) else "–"


def check_rows(checks: list[Check]) -> list[tuple[str, ...]]:
    """The checks table's rows: step, check, value, held against, tolerance, verdict, what to do."""
    titles = dict(STEPS)
    rows: list[tuple[str, ...]] = []
    for c in checks:
        tol = f"{c.tolerance:g}" + (f" {c.unit}" if c.unit else "")
        against = "bound" if c.target is None else _num(c.target, ".4g")
        verdict = '<span class="pass">pass</span>' if c.passed else '<span class="fail">FAIL</span>'
        rows.append((html.escape(titles.get(c.step, c.step)), html.escape(c.name), _num(c.value, ".4g"), against,
                     html.escape(tol), verdict, "" if c.passed else html.escape(c.advice), html.escape(c.detail)))
    return rows


def _given(c: Commission) -> str:
    g, fr = c.given, c.frames
    rows = [("source", html.escape(" ".join(g.source))),
            ("drum diameter", f"{g.drum_diameter_mm:g} mm (given: the frames carry no scale)"),
            ("drum speed", f"{g.rpm:g} rpm (given: the frames carry no speed)"),
            ("drum depth", "monolayer (one particle between the plates)" if g.drum_depth_mm is None
             else f"{g.drum_depth_mm:g} mm (given)"),
            ("frames", f"{len(fr.images)} with a drum of {fr.total} read" + (
                f"; left out: {html.escape('; '.join(fr.skipped))}" if fr.skipped else "")),
            ("camera turned", f"{c.cfg.camera_rotation_deg:g} deg" + (
                " (given)" if g.camera_rotation_deg is not None else " (proposed from where the bed lies)")),
            ("twin engine", html.escape(g.engine or "the mixer's (dem for discs, pymunk for shapes)"))]
    return table(rows)


def _checks(c: Commission) -> str:
    bad = [x for x in c.checks if not x.passed]
    head = (f'<p class="verdict pass">Every check passed ({len(c.checks)}).</p>' if not bad else
            f'<p class="verdict fail">{len(bad)} of {len(c.checks)} checks failed.</p>')
    tol = ", ".join(f"{k} = {v:g}" for k, v in vars(TOLERANCES).items())
    return head + table(check_rows(c.checks), ("step", "check", "value", "against", "tolerance", "verdict",
                                               "what to do", "how")) + (
        f"<p>Tolerances (<code>twin.commission.checks.TOLERANCES</code>): {html.escape(tol)}.</p>")


def _preview(c: Commission) -> str:
    from vision.suggest import class_preview

    fr = c.frames
    return _img("preview", figures.image_uri(class_preview(fr.images[0], c.cfg.classes, fr.rois[0])),
                "a frame beside its class map") + (
        f"<p>{len(c.cfg.counted)} classes learned from {len(fr.images)} frames: "
        f"{html.escape(', '.join(k.name for k in c.cfg.counted))}.</p>")


def _census(c: Commission) -> str:
    s = c.suggested
    names = [k.name for k in c.mixer.particles]
    kinds = [k.shape.kind for k in c.mixer.particles]
    f = figures.busiest_frame(s.traced)
    pic = figures.census_overlay(c.frames.images[f], s.traced, names, kinds, f)
    rows = []
    for k, p in zip(s.census.classes, c.mixer.particles, strict=True):
        sh = p.shape
        shape = sh.kind.replace("_", " ") + (f", notch {sh.notch_deg:g} deg, {sh.notch_depth:g} of the radius deep"
                                             if sh.kind == "notched_disc" else "")
        rows.append((html.escape(k.name), f"{sh.diameter_m * 1e3:.2f}", f"{k.diameter_px:.1f}", f"{k.count:.0f}",
                     f"{k.share:.3f}", f"{k.pixel_share:.3f}", html.escape(shape),
                     html.escape(s.notes.get(f"particles.{k.name}.shape", ""))))
    return _img("census", figures.image_uri(pic), "traced particles") + table(
        rows, ("class", "size mm", "size px", "per frame", "share", "pixel share", "shape", "how")) + (
        f"<p>fill {c.mixer.fill:g} (median of {s.census.frames} frames; {s.mm_per_px:.3f} mm/px).</p>")


def _calibration(c: Commission) -> str:
    cal = c.calibration
    tol = TOLERANCES.slope_deg
    if cal is None:
        pic = figures.calibration_curve((), c.target_slope_deg, tol, None, None)
        return _img("calibration", pic, "calibration curve") + (
            f'<p class="fail">{html.escape(c.calibration_error or "no calibration")}</p>')
    pic = figures.calibration_curve(cal.history, c.target_slope_deg, tol, (cal.friction, abs(cal.twin_slope_deg)),
                                    cal.range_deg)
    rows = [("target (the camera's median slope)", f"{c.target_slope_deg:.2f} deg"),
            ("sliding friction", f"{cal.friction:.4g}"), ("rolling friction", f"{cal.rolling:.4g}"),
            ("twin's slope", f"{cal.twin_slope_deg:.2f} deg (residual {cal.residual_deg:+.2f})"),
            ("reachable at this rpm", f"{cal.range_deg[0]:.1f}-{cal.range_deg[1]:.1f} deg"),
            ("twin runs", f"{cal.evaluations} ({cal.confirmations} of them confirming: the twin check's run, its "
                          f"slope's standard error {cal.slope_se_deg:.2f} deg)")]
    return _img("calibration", pic, "calibration curve") + table(rows)


def _twin(c: Commission) -> str:
    from vision.overlay import draw_overlay

    if c.twin is None or c.twin_summary is None:
        return '<p class="none">The twin was not run.</p>'
    mixed = [i for i, m in enumerate(c.mixed) if m] or [0]
    i = mixed[len(mixed) // 2]
    cam = draw_overlay(c.frames.images[i], c.cfg.make_meter(roi=c.frames.rois[i]).measure(c.frames.images[i]))
    cs, ts = c.camera_summary, c.twin_summary
    rows: list[tuple[Any, ...]] = [
        ("slope deg (median; its standard error)", f"{cs.slope_deg:.2f} ({cs.slope_se_deg:.2f})",
         f"{ts.slope_deg:.2f} ({ts.slope_se_deg:.2f})"),
        ("bed cover (share of the drum)", f"{cs.cover:.4f}", f"{ts.cover:.4f}"),
        ("MI, eq. 4 (camera: its mixed frames)", f"{cs.mi:.4f} ({cs.mixed} frames)", f"{ts.mi:.4f}"),
        *[(f"spread ratio {html.escape(k.name)}", f"{a:.4f}", f"{b:.4f}")
          for k, a, b in zip(c.cfg.counted, cs.ratios, ts.ratios, strict=True)],
        ("frames", str(cs.frames), f"{ts.frames} ({len(TWIN_RUN.seeds)} runs of {TWIN_RUN.window_s:g} s; their "
                                   f"own median slopes spread {seeds_spread(c.twin.measures):.2f} deg)")]
    return _img("twin", figures.image_uri(figures.side_by_side(cam, c.twin.frame)), "camera and twin") + table(
        rows, ("", "camera", "twin"))


def _times(c: Commission) -> str:
    rows = [(html.escape(t.step), f"{t.wall_s:.1f}", f"{t.cpu_s:.1f}") for t in c.times]
    rows.append(("all", f"{c.wall_s:.1f}", f"{c.cpu_s:.1f}"))
    return table(rows, ("step", "wall s", "CPU s"))


def render_report(c: Commission, mixer_toml: str) -> str:
    """The whole report of commission ``c`` (``mixer_toml``: the file written beside it)."""
    body = {"given": _given(c), "checks": _checks(c), "preview": _preview(c), "census": _census(c),
            "calibration": _calibration(c), "twin": _twin(c),
            "mixer": f"<pre>{html.escape(mixer_toml)}</pre>", "times": _times(c)}
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'><title>drumtwin commissioning</title>"
             f"<style>{CSS}{EXTRA_CSS}</style></head><body><h1>drumtwin commissioning</h1>"]
    for sid, title in SECTIONS:
        parts.append(f'<section data-section="{sid}"><h2 id="{sid}">{html.escape(title)}</h2>{body[sid]}</section>')
    parts.append("</body></html>")
    return "".join(parts)


__all__ = ["SECTIONS", "check_rows", "render_report"]

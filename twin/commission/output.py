"""What commissioning writes: ``mixer.toml`` (the learned classes and the light they were learned in,
the census's mixer, the calibrated friction; ``drumtwin run --config`` reads it as it is) and
``report.html``, both into ``--out`` at once: written into a hidden folder beside it, then renamed into
place (nothing half-written is ever at ``--out``; on any error the hidden folder is removed)."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

from twin.commission.checks import failed
from twin.commission.report import render_report
from twin.commission.steps import Commission
from twin.errors import TwinError

MIXER_TOML = "mixer.toml"
REPORT_HTML = "report.html"


def mixer_toml(c: Commission) -> str:
    """The config commissioning writes: the meter's classes (``vision.config.config_to_toml``), then the
    mixer's tables (``sim.mixer.mixer_to_toml``) with every number commented, the calibrated friction's too."""
    from sim.mixer import mixer_to_toml
    from twin.suggest_mixer import SUGGEST_HEAD
    from vision.config import config_to_toml

    g, bad = c.given, failed(c.checks)
    comment = (f"written by `drumtwin commission {' '.join(g.source)} --drum-diameter-mm {g.drum_diameter_mm:g} "
               f"--rpm {g.rpm:g}`;\n" + (f"every check passed ({len(c.checks)})" if not bad else
                                         f"{len(bad)} of {len(c.checks)} checks failed: see report.html")
               + f"; classes: {', '.join(k.name for k in c.cfg.counted)}.")
    notes = dict(c.suggested.notes)
    cal = c.calibration
    if cal is not None and c.mixer.friction is not None:
        why = (f"calibrated at {g.rpm:g} rpm to the camera's median slope {c.target_slope_deg:.1f} deg (twin "
               f"{cal.twin_slope_deg:.1f} deg, {cal.evaluations} twin runs)")
        notes["drum.friction.sliding"] = why
        notes["drum.friction.rolling"] = "calibrated with the sliding friction"
    return config_to_toml(c.cfg, comment) + "\n" + SUGGEST_HEAD + mixer_to_toml(c.mixer, notes)


def default_out(now: float | None = None) -> Path:
    """``commission-YYYYmmdd-HHMMSS`` in the working folder (``-2``, ``-3`` ... when taken)."""
    base = Path(time.strftime("commission-%Y%m%d-%H%M%S", time.localtime(now)))
    out, k = base, 1
    while out.exists():
        k += 1
        out = base.with_name(f"{base.name}-{k}")
    return out


def check_out(out: Path) -> Path:
    """``--out`` as it will be written: a folder that does not exist yet, in a folder that does.
    Anything else is a one-line ``TwinError`` before any work (nothing is ever overwritten)."""
    if out.exists() or out.is_symlink():
        raise TwinError(f"--out {out} exists: give a new folder (nothing is overwritten)")
    if not out.absolute().parent.is_dir():
        raise TwinError(f"--out: folder {out.absolute().parent} does not exist")
    return out


def write_outputs(c: Commission, out: Path) -> tuple[Path, Path]:
    """``mixer.toml`` and ``report.html`` of ``c`` into ``out`` at once (see the module doc)."""
    check_out(out)
    text = mixer_toml(c)
    page = render_report(c, text)
    parent = out.absolute().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        mask = os.umask(0)
        os.umask(mask)
        tmp.chmod(0o777 & ~mask)  # a folder as any other the user makes (mkdtemp's is private)
        (tmp / MIXER_TOML).write_text(text, encoding="utf-8")
        (tmp / REPORT_HTML).write_text(page, encoding="utf-8")
        os.rename(tmp, out)  # refused if --out appeared meanwhile (a folder with files, or a file)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise TwinError(f"cannot write --out {out}: {exc.strerror or exc}") from None
    return out / MIXER_TOML, out / REPORT_HTML


__all__ = ["MIXER_TOML", "REPORT_HTML", "check_out", "default_out", "mixer_toml", "write_outputs"]

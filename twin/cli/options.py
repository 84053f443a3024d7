"""Small helpers the vision commands share: a checked number option, warnings on stderr."""

from __future__ import annotations

import math
from collections.abc import Iterable

from twin.cli.app import say
from vision.errors import VisionError


def check_number(option: str, value: float, lo: float, hi: float) -> None:
    """A one-line error naming ``option`` unless ``lo <= value <= hi`` (and finite)."""
    if not (math.isfinite(value) and lo <= value <= hi):
        raise VisionError(f"{option} must be within {lo:g}..{hi:g}, got {value:g}")


def warn(lines: Iterable[str]) -> None:
    """Each line as ``warning: ...`` on stderr."""
    for ln in lines:
        say(f"warning: {ln}")

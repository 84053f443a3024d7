"""What a run records about itself besides its settings: the versions its results depend on and
the user's mixer (``RunStart``, ``metadata.json``)."""

from __future__ import annotations

import platform
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sim.mixer import Mixer

PACKAGES = ("drumtwin", "numpy", "opencv-python-headless", "pymunk", "viser", "numba", "pyserial", "sqlalchemy",
            "pymodbus")


def versions() -> dict[str, str]:
    """The versions a run's results depend on (``RunStart.versions``, metadata.json)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def mixer_metadata(mixer: Mixer) -> dict[str, object]:
    """The user's mixer for ``metadata.json``."""
    from sim.mixer import resolve

    return {"classes": [{"name": k.name, "count": k.count, "diameter_mm": 1e3 * k.shape.diameter_m,
                         "shape": k.shape.kind} for k in resolve(mixer)],
            "drum_diameter_mm": 1e3 * mixer.drum.diameter_m, "fill": mixer.fill,
            "direction": mixer.direction, "monolayer": mixer.monolayer}


__all__ = ["PACKAGES", "mixer_metadata", "versions"]

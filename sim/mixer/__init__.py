"""The user's mixer: the model (``sim.mixer.model``: the dataclasses, counts and masses the engines
take) and its config tables (``sim.mixer.config``: ``[drum]`` and ``[[particles]]`` read and
written). Import from here; a particle's outline as the camera sees it is ``vision.shapes``'s."""

from sim.mixer.config import (
    MAX_BAFFLES,
    MAX_PARTICLE_SHARE_OF_DRUM,
    SHAPE_KINDS,
    mixer_from_config,
    mixer_to_toml,
    parse_mixer,
)
from sim.mixer.model import (
    ROUND_SHAPES,
    Baffles,
    Mixer,
    ParticleKind,
    ResolvedKind,
    Shape,
    ShapeKind,
    bed_area_m2,
    check_fits,
    disk_classes,
    paper_mixer,
    polygon_shape,
    resolve,
    resolve_counts,
    shape_area_m2,
    shape_from_crops,
    shape_outline_m,
    with_counts,
)

__all__ = [
    "MAX_BAFFLES",
    "MAX_PARTICLE_SHARE_OF_DRUM",
    "ROUND_SHAPES",
    "SHAPE_KINDS",
    "Baffles",
    "Mixer",
    "ParticleKind",
    "ResolvedKind",
    "Shape",
    "ShapeKind",
    "bed_area_m2",
    "check_fits",
    "disk_classes",
    "mixer_from_config",
    "mixer_to_toml",
    "paper_mixer",
    "parse_mixer",
    "polygon_shape",
    "resolve",
    "resolve_counts",
    "shape_area_m2",
    "shape_from_crops",
    "shape_outline_m",
    "with_counts",
]

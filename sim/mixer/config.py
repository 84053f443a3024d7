"""The mixer's config tables: ``[drum]`` and ``[[particles]]`` read into a ``sim.mixer.Mixer``
(every number checked, one-line ``SimError``s naming the key) and written back as TOML.

The config holds them next to the colour classes::

    [drum]
    diameter_mm = 300          # inner diameter
    depth_mm = 100             # distance between the end plates; or monolayer = true
    monolayer = false          # quasi-2D drum one particle thick: depth = the particles' thickness
    fill = 0.5                 # share of the cross-section the bed covers (at random packing)
    rotation = "ccw"           # as the camera sees it: "ccw" (surface rises to the right) or "cw"
    density_kg_m3 = 1180       # drum material (not used by the physics yet)

    [drum.baffles]             # optional: lifters on the wall, turning with the drum
    count = 4
    height_mm = 20             # radial length from the wall inwards
    thickness_mm = 4

    [drum.friction]            # optional, each key too: the twin's friction for this rig (`drumtwin commission`
    sliding = 0.06             # writes its calibration here); particle-particle sliding friction
    rolling = 0.08             # rolling friction
    end_plates = 0.03          # the end plates' friction (default: the wall's; a monolayer's is calibrated)

    [[particles]]              # one table per colour class, same name as the camera's class
    name = "blue"
    shape = "disc"             # disc | polygon | pellet | cut_disc | notched_disc | vertices | traced
    diameter_mm = 10           # circumscribed diameter (disc, polygon, cut_disc, vertices) or length (pellet)
    density_kg_m3 = 1190
    share = 0.5                # share of the bed's solid area; or count = 120
    # polygon:  sides = 6
    # pellet:   width_mm = 5, corner_mm = 1   (rounded rectangle diameter_mm x width_mm)
    # cut_disc: wedge_deg = 90                 (a disc with a wedge cut out: non-convex)
    # notched_disc: notch_deg = 90, notch_depth = 0.4   (a V-notch of 90 deg cut from the rim to 0.4 of the
    #           radius: its apex 0.4 r in from the rim; 1 reaches the centre, a cut disc; non-convex)
    # vertices: vertices_mm = [[x, y], ...]    (a simple polygon about its centroid)
    # traced:   image = "particle.png"         (outline of one particle, pymunk.autogeometry)
    thickness_mm = 5           # monolayer drums: the particle's thickness (default its diameter)
    colour_bgr = [255, 60, 0]  # optional: the twin's render colour (default: the camera class's display colour)

Counts: a class with ``count`` has that many particles in the slice; classes with ``share``
divide the bed's solid area ``fill * PACKING_2D * pi R^2`` (``sim.recipe.slice_2d``'s rule)
by their shares, ``n_k = round(share_k * A / area_k)``. Give every class a count, or every
class a share (summing to 1).

Frame: origin at the drum axis, x to the right, y up, as the camera sees the front face
(the DEM's frame, ``sim.drum``). ``direction`` +1 is counter-clockwise as seen.

``parse_mixer`` takes the TOML's dict; a ``traced`` shape's picture is read and traced
(``vision.shapes.trace_outline``) relative to the config's folder.
"""


from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sim.errors import SimError, check_number
from sim.mixer.model import Baffles, Friction, Mixer, ParticleKind, Shape, check_fits, polygon_shape
from sim.recipe import BLUE_BGR, MAX_FILL, RED_BGR, DrumSpec
from vision.errors import VisionError
from vision.shapes import trace_outline

SHAPE_KINDS: tuple[str, ...] = ("disc", "sphere", "polygon", "pellet", "cut_disc", "notched_disc", "vertices",
                                "traced")
_DRUM_KEYS = {"diameter_mm", "depth_mm", "monolayer", "fill", "rotation", "density_kg_m3", "baffles", "friction"}
_BAFFLE_KEYS = {"count", "height_mm", "thickness_mm"}
_FRICTION_KEYS = {"sliding", "rolling", "end_plates"}
MAX_FRICTION = 5.0  # a friction coefficient, at most (the engines' own bound)
_PARTICLE_KEYS = {"name", "shape", "diameter_mm", "density_kg_m3", "share", "count", "thickness_mm", "sides",
                  "width_mm", "corner_mm", "wedge_deg", "notch_deg", "notch_depth", "vertices_mm", "image",
                  "colour_bgr"}
_SHAPE_KEYS = {"polygon": {"sides"}, "pellet": {"width_mm", "corner_mm"}, "cut_disc": {"wedge_deg"},
               "notched_disc": {"notch_deg", "notch_depth"}, "vertices": {"vertices_mm"}, "traced": {"image"}}
MAX_PARTICLE_SHARE_OF_DRUM = 0.25  # a particle's diameter over the drum's, at most
MIN_PARTICLE_MM = 0.1  # a particle's size (diameter, width, thickness), at least: below ~0.1 mm cohesion
# outweighs a particle's weight (a powder, not the free-flowing bed the twin's contact laws describe)
MAX_BAFFLES = 36


def _num(where: str, key: str, value: object, lo: float, hi: float, *, lo_open: bool = False,
         integer: bool = False) -> float:
    if isinstance(value, bool):
        value = repr(value)
    return check_number(f"{where}: {key}", value, lo, hi, lo_open=lo_open, integer=integer)


def _unknown(where: str, table: Mapping, allowed: set[str]) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SimError(f"{where}: unknown key(s) {unknown} (allowed: {sorted(allowed)})")



def _bgr(where: str, value: object) -> tuple[int, int, int]:
    if not (isinstance(value, list) and len(value) == 3
            and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in value)):
        raise SimError(f"{where}: colour_bgr must be [b, g, r], three integers 0..255 (got {value!r})")
    return (int(value[0]), int(value[1]), int(value[2]))


def _parse_shape(where: str, t: Mapping, drum_d_m: float, base_dir: Path | None) -> Shape:
    kind = t.get("shape", "disc")
    if kind not in SHAPE_KINDS:
        raise SimError(f"{where}: unknown shape {kind!r} (one of {', '.join(SHAPE_KINDS)})")
    kind = "disc" if kind == "sphere" else kind
    for other, keys in _SHAPE_KEYS.items():
        stray = sorted(keys & set(t)) if other != kind else []
        if stray:
            raise SimError(f"{where}: {stray[0]} belongs to shape = {other!r}, not {kind!r}")
    if "diameter_mm" not in t:
        raise SimError(f"{where}: needs diameter_mm (the particle's size)")
    d_m = 1e-3 * _num(where, "diameter_mm", t["diameter_mm"], MIN_PARTICLE_MM, 1e4)
    if d_m > MAX_PARTICLE_SHARE_OF_DRUM * drum_d_m:
        raise SimError(f"{where}: diameter_mm = {d_m * 1e3:g} does not fit a {drum_d_m * 1e3:g} mm drum "
                       f"(at most {MAX_PARTICLE_SHARE_OF_DRUM:g} of its diameter)")
    if kind == "disc":
        return Shape("disc", d_m)
    if kind == "polygon":
        sides = int(_num(where, "sides", t.get("sides", 6), 3, 64, integer=True))
        return Shape("polygon", d_m, sides=sides)
    if kind == "pellet":
        w_m = 1e-3 * _num(where, "width_mm", t.get("width_mm", d_m * 1e3), MIN_PARTICLE_MM, d_m * 1e3)
        c_m = 1e-3 * _num(where, "corner_mm", t.get("corner_mm", 0.0), 0.0, 0.5 * w_m * 1e3)
        return Shape("pellet", d_m, width_m=w_m, corner_m=c_m)
    if kind == "cut_disc":
        wedge = _num(where, "wedge_deg", t.get("wedge_deg", 90.0), 0.0, 180.0, lo_open=True)
        return Shape("cut_disc", d_m, wedge_deg=wedge)
    if kind == "notched_disc":
        notch = _num(where, "notch_deg", t.get("notch_deg", 90.0), 0.0, 180.0, lo_open=True)
        depth = _num(where, "notch_depth", t.get("notch_depth", 0.4), 0.0, 1.0, lo_open=True)
        return Shape("notched_disc", d_m, notch_deg=notch, notch_depth=depth)
    if kind == "vertices":
        raw = t.get("vertices_mm")
        if not (isinstance(raw, list) and len(raw) >= 3 and all(isinstance(r, list) and len(r) == 2 for r in raw)):
            raise SimError(f"{where}: vertices_mm must be a list of at least three [x, y] pairs (got {raw!r})")
        v = np.array([[_num(where, "vertices_mm", c, -1e4, 1e4) for c in r] for r in raw]) * 1e-3
        return polygon_shape(where, v, d_m)
    # traced: the outline of one particle in a picture
    if base_dir is None:
        raise SimError(f"{where}: shape = 'traced' needs the config's folder to find its image")
    img = t.get("image")
    if not isinstance(img, str) or not img:
        raise SimError(f"{where}: shape = 'traced' needs image = \"particle.png\"")
    path = Path(img) if Path(img).is_absolute() else Path(base_dir) / img
    try:
        return polygon_shape(where, trace_outline(path, where), d_m)
    except VisionError as exc:
        raise SimError(str(exc)) from None




def parse_mixer(
    table: Mapping,
    class_names: Sequence[str] | None = None,
    *,
    base_dir: str | Path | None = None,
    colours: Mapping[str, tuple[int, int, int]] | None = None,
    source: str = "config",
) -> Mixer:
    """The mixer from a config's ``[drum]`` and ``[[particles]]`` tables (see the module doc).

    ``class_names``: the camera's counted colour classes; every particle class must be one of
    them and each of them needs a particle class (the result is in the camera's order).
    ``colours``: display colours by class name (the render colour unless ``colour_bgr`` is given).
    Every number is checked; a bad one is a one-line ``SimError`` naming the key.
    """
    drum_t = table.get("drum")
    parts = table.get("particles")
    if not isinstance(drum_t, Mapping):
        raise SimError(f"{source}: a mixer needs a [drum] table")
    if not (isinstance(parts, list) and parts and all(isinstance(p, Mapping) for p in parts)):
        raise SimError(f"{source}: a mixer needs [[particles]] tables, one per colour class")
    w = f"{source} [drum]"
    d_m, monolayer, fill, direction, rho_drum = _parse_drum(w, drum_t)
    baffles = _parse_baffles(f"{source} [drum.baffles]", drum_t["baffles"], d_m) if "baffles" in drum_t else None
    friction = _parse_friction(f"{source} [drum.friction]", drum_t["friction"]) if "friction" in drum_t else None
    names = None if class_names is None else list(class_names)
    kinds: list[ParticleKind] = []
    for i, t in enumerate(parts):
        kinds.append(_parse_particle(source, i, t, kinds, names, d_m, None if base_dir is None else Path(base_dir),
                                     colours))
    kinds = _check_classes(source, kinds, names)
    thickest = max(k.thickness_m if k.thickness_m is not None else k.shape.diameter_m for k in kinds)
    depth = thickest if monolayer else 1e-3 * _num(w, "depth_mm", drum_t["depth_mm"], 0.0, 1e4, lo_open=True)
    if depth < thickest * (1.0 - 1e-9):
        raise SimError(f"{w}: depth_mm = {depth * 1e3:g} is thinner than the particles ({thickest * 1e3:g} mm; "
                       "give their thickness_mm)")
    mixer = Mixer(DrumSpec(d_m, depth, rho_drum), tuple(kinds), fill=fill, direction=direction,
                  monolayer=monolayer, baffles=baffles, friction=friction)
    check_fits(mixer, source)
    return mixer


def _parse_drum(w: str, drum_t: Mapping) -> tuple[float, bool, float, int, float]:
    """The ``[drum]`` table (``w`` names it): diameter (m), monolayer, fill, direction (+1 ccw), density."""
    _unknown(w, drum_t, _DRUM_KEYS)
    if "diameter_mm" not in drum_t:
        raise SimError(f"{w}: needs diameter_mm (the drum's inner diameter)")
    d_m = 1e-3 * _num(w, "diameter_mm", drum_t["diameter_mm"], 10.0, 1e4)
    monolayer = drum_t.get("monolayer", False)
    if not isinstance(monolayer, bool):
        raise SimError(f"{w}: monolayer must be true or false (got {monolayer!r})")
    if monolayer and "depth_mm" in drum_t:
        raise SimError(f"{w}: give depth_mm or monolayer = true, not both (a monolayer drum is one particle deep)")
    if not monolayer and "depth_mm" not in drum_t:
        raise SimError(f"{w}: needs depth_mm (the end plates' distance) or monolayer = true")
    fill = _num(w, "fill", drum_t.get("fill", 0.5), 0.0, MAX_FILL, lo_open=True)
    rotation = drum_t.get("rotation", "ccw")
    if rotation not in ("ccw", "cw"):
        raise SimError(f"{w}: rotation must be \"ccw\" or \"cw\" as the camera sees it (got {rotation!r})")
    rho_drum = _num(w, "density_kg_m3", drum_t.get("density_kg_m3", 1180.0), 0.0, 1e5, lo_open=True)
    return d_m, monolayer, fill, 1 if rotation == "ccw" else -1, rho_drum


def _parse_baffles(wb: str, bt: object, d_m: float) -> Baffles:
    """The ``[drum.baffles]`` table of a drum of diameter ``d_m`` (m)."""
    if not isinstance(bt, Mapping):
        raise SimError(f"{wb}: must be a table")
    _unknown(wb, bt, _BAFFLE_KEYS)
    for key in ("count", "height_mm", "thickness_mm"):
        if key not in bt:
            raise SimError(f"{wb}: needs {key}")
    count = int(_num(wb, "count", bt["count"], 1, MAX_BAFFLES, integer=True))
    height = 1e-3 * _num(wb, "height_mm", bt["height_mm"], 0.0, 1e4, lo_open=True)
    thick = 1e-3 * _num(wb, "thickness_mm", bt["thickness_mm"], 0.0, 1e4, lo_open=True)
    if height >= 0.5 * d_m:
        raise SimError(f"{wb}: height_mm = {height * 1e3:g} is longer than the drum's radius "
                       f"({0.5 * d_m * 1e3:g} mm)")
    if count * thick >= math.pi * d_m:
        raise SimError(f"{wb}: {count} baffles of {thick * 1e3:g} mm do not fit on the wall")
    return Baffles(count, height, thick)


def _parse_friction(wf: str, ft: object) -> Friction:
    """The ``[drum.friction]`` table: the calibrated sliding, rolling (and end plates') friction."""
    if not isinstance(ft, Mapping):
        raise SimError(f"{wf}: must be a table")
    _unknown(wf, ft, _FRICTION_KEYS)
    if not ft:
        raise SimError(f"{wf}: give sliding, rolling or end_plates (or leave the table out)")
    sliding, rolling, end = (_num(wf, key, ft[key], 0.0, MAX_FRICTION) if key in ft else None
                             for key in ("sliding", "rolling", "end_plates"))
    return Friction(sliding, rolling, end)


def _parse_particle(source: str, i: int, t: Mapping, kinds: Sequence[ParticleKind], names: list[str] | None,
                    d_m: float, base_dir: Path | None,
                    colours: Mapping[str, tuple[int, int, int]] | None) -> ParticleKind:
    """The ``i``-th ``[[particles]]`` table ``t`` (``kinds``: the classes read before it)."""
    name = t.get("name")
    wp = f"{source} [[particles]] {name!r}" if isinstance(name, str) else f"{source} particles[{i}]"
    _unknown(wp, t, _PARTICLE_KEYS)
    if not isinstance(name, str) or not name:
        raise SimError(f"{wp}: needs name = \"...\" (the camera's colour class)")
    if any(k.name == name for k in kinds):
        raise SimError(f"{wp}: the class is described twice")
    if names is not None and name not in names:
        raise SimError(f"{wp}: the camera has no colour class {name!r} (its classes: {', '.join(names)})")
    shape = _parse_shape(wp, t, d_m, base_dir)
    rho = _num(wp, "density_kg_m3", t.get("density_kg_m3", 1190.0), 0.0, 1e5, lo_open=True)
    if ("count" in t) == ("share" in t):
        raise SimError(f"{wp}: give either count or share (got {'both' if 'count' in t else 'neither'})")
    count_v = int(_num(wp, "count", t["count"], 1, 1e6, integer=True)) if "count" in t else None
    share_v = _num(wp, "share", t["share"], 0.0, 1.0, lo_open=True) if "share" in t else None
    thick_v = (1e-3 * _num(wp, "thickness_mm", t["thickness_mm"], MIN_PARTICLE_MM, 1e4)
               if "thickness_mm" in t else None)
    if "colour_bgr" in t:
        bgr = _bgr(wp, t["colour_bgr"])
    elif colours is not None and name in colours:
        bgr = tuple(int(c) for c in colours[name])  # type: ignore[assignment]
    else:
        bgr = (RED_BGR, BLUE_BGR)[i % 2]
    return ParticleKind(name, shape, rho, count=count_v, share=share_v, thickness_m=thick_v, colour_bgr=bgr)


def _check_classes(source: str, kinds: list[ParticleKind], names: list[str] | None) -> list[ParticleKind]:
    """The classes in the camera's order (each of its ``names`` described), all by count or all by
    shares that add up to 1."""
    if names is not None:
        missing = [n for n in names if n not in {k.name for k in kinds}]
        if missing:
            raise SimError(f"{source}: no [[particles]] table for the camera's class {missing[0]!r}")
        kinds = sorted(kinds, key=lambda k: names.index(k.name))
    by_share = [k.share is not None for k in kinds]
    if any(by_share) and not all(by_share):
        raise SimError(f"{source} [[particles]]: give every class a count or every class a share, not a mix")
    if all(by_share):
        total = sum(float(k.share or 0.0) for k in kinds)
        if abs(total - 1.0) > 0.01:
            raise SimError(f"{source} [[particles]]: the shares add up to {total:g}, not 1")
    return kinds


def mixer_from_config(cfg: Any, *, default: Mixer | None = None) -> Mixer | None:
    """The mixer a vision ``MeterConfig`` carries (its ``[drum]``/``[[particles]]`` tables, named as
    its counted colour classes and drawn in their display colours), else ``default``."""
    tables = getattr(cfg, "mixer_tables", None) or {}
    if not tables:
        return default
    source = str(getattr(cfg, "source", "config"))
    base = Path(source).parent if source and not source.startswith("<") else Path.cwd()
    counted = tuple(getattr(cfg, "counted", ()))
    return parse_mixer(tables, [c.name for c in counted], base_dir=base,
                       colours={c.name: tuple(c.display_bgr) for c in counted}, source=f"config {source}")


# ------------------------------------------------------------------ writing
def _f(v: float) -> str:
    return format(float(v), ".4g")


def mixer_to_toml(mixer: Mixer, notes: Mapping[str, str] | None = None) -> str:
    """The ``[drum]`` and ``[[particles]]`` tables of ``mixer`` as TOML text (``parse_mixer``
    reads it back). ``notes``: a comment per key, ``"drum.fill"`` or ``"particles.blue.share"``
    (where the number came from)."""
    notes = notes or {}

    def line(key: str, value: str, where: str) -> str:
        note = notes.get(f"{where}.{key}")
        return f"{key} = {value}" + (f"  # {note}" if note else "")

    out = ["[drum]", line("diameter_mm", _f(mixer.drum.diameter_m * 1e3), "drum")]
    if mixer.monolayer:
        out.append(line("monolayer", "true", "drum"))
    else:
        out.append(line("depth_mm", _f(mixer.drum.depth_m * 1e3), "drum"))
    out.append(line("fill", _f(mixer.fill), "drum"))
    out.append(line("rotation", '"ccw"' if mixer.direction > 0 else '"cw"', "drum"))
    out.append(line("density_kg_m3", _f(mixer.drum.density_kg_m3), "drum"))
    if mixer.baffles is not None:
        b = mixer.baffles
        out += ["", "[drum.baffles]", line("count", str(b.count), "drum.baffles"),
                line("height_mm", _f(b.height_m * 1e3), "drum.baffles"),
                line("thickness_mm", _f(b.thickness_m * 1e3), "drum.baffles")]
    if mixer.friction is not None:
        fr = mixer.friction
        out += ["", "[drum.friction]"] + [line(key, _f(v), "drum.friction") for key, v in (
            ("sliding", fr.sliding), ("rolling", fr.rolling), ("end_plates", fr.end_plates)) if v is not None]
    for p in mixer.particles:
        w = f"particles.{p.name}"
        s = p.shape
        out += ["", "[[particles]]", line("name", f'"{p.name}"', w), line("shape", f'"{s.kind}"', w),
                line("diameter_mm", _f(s.diameter_m * 1e3), w)]
        if s.kind == "polygon":
            out.append(line("sides", str(s.sides), w))
        elif s.kind == "pellet":
            out += [line("width_mm", _f(float(s.width_m or s.diameter_m) * 1e3), w),
                    line("corner_mm", _f(float(s.corner_m or 0.0) * 1e3), w)]
        elif s.kind == "cut_disc":
            out.append(line("wedge_deg", _f(float(s.wedge_deg or 90.0)), w))
        elif s.kind == "notched_disc":
            out += [line("notch_deg", _f(float(s.notch_deg or 90.0)), w),
                    line("notch_depth", _f(float(s.notch_depth or 0.4)), w)]
        elif s.kind == "vertices":
            pts = ", ".join(f"[{_f(x * 1e3)}, {_f(y * 1e3)}]" for x, y in (s.vertices_m or ()))
            out.append(line("vertices_mm", f"[{pts}]", w))
        out.append(line("density_kg_m3", _f(p.density_kg_m3), w))
        if p.count is not None:
            out.append(line("count", str(p.count), w))
        else:
            out.append(line("share", _f(float(p.share or 0.0)), w))
        if p.thickness_m is not None:
            out.append(line("thickness_mm", _f(p.thickness_m * 1e3), w))
    return "\n".join(out) + "\n"



"""``drumtwin classes suggest``: learn the particle colours from many frames and print a TOML config
(with ``--drum-diameter-mm`` also the twin's mixer, ``twin.suggest_mixer.suggest_mixer_toml``).
Frames in which the drum cannot be found are left out by the one no-drum policy
(``vision.stream.DrumWatch``, without a time limit: the frames are picked across the source)."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from twin.cli.app import app, say
from twin.cli.options import check_number, warn
from vision.errors import VisionError

if TYPE_CHECKING:
    from collections.abc import Iterator

    import numpy as np

    from vision.config import MeterConfig
    from vision.roi import DrumROI

classes_app = typer.Typer(help="Colour classes: suggest a TOML config from a frame.")
app.add_typer(classes_app, name="classes")

_SIDE = ("bottom", "right", "top", "left")  # where gravity's down lies in the image per quarter turn


def _pick_count(source: list[str], n_frames: int) -> int:
    """How many frames :func:`_pick_frames` will try to give (images: exact; a video: at most)."""
    from vision.sources import _image_paths, source_kind

    spec = source if len(source) > 1 else source[0]
    kind = source_kind(spec)
    if kind == "image":
        return 1
    if kind in ("folder", "images"):
        return max(1, min(n_frames, len(_image_paths(spec))))
    return n_frames


def _pick_frames(source: list[str], n_frames: int) -> Iterator[tuple[str, np.ndarray]]:
    """Up to ``n_frames`` readable frames spread evenly over the source, as (name, image), read
    one at a time (``classes suggest --frames 500`` holds no more than it must)."""
    from vision.sources import _image_paths, open_source, read_image, source_kind

    spec = source if len(source) > 1 else source[0]
    kind = source_kind(spec)
    if kind in ("folder", "images", "image"):
        paths = [Path(str(spec))] if kind == "image" else _image_paths(spec)
        if kind == "image" and not paths[0].exists():
            raise FileNotFoundError(f"no such file: {paths[0]}")
        m = min(n_frames, len(paths))
        idx = sorted({round(i * (len(paths) - 1) / max(m - 1, 1)) for i in range(m)})
        for i in idx:
            img, err = read_image(paths[i])
            if err:
                if kind == "image":
                    raise VisionError(err)
                continue
            yield paths[i].name, img
        return
    total = 0
    if kind == "video":
        import cv2

        cap = cv2.VideoCapture(str(spec))
        total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        cap.release()
    step = max(1, total // n_frames) if total > 0 else 10
    got = 0
    for fr in open_source(spec, reconnect=False):
        if fr.index % step == 0 and not fr.error:
            yield fr.name or str(fr.index), fr.image
            got += 1
        if got >= n_frames:
            break


class _Picked:
    """The frames ``classes suggest`` learns from, as they are read: their names, each one's
    drum (found in it, or the ``--roi``), the first (for the preview) and up to ``keep`` kept
    for the mixer's census; frames without a drum are left out (``skipped``, the policy's
    ``DrumWatch`` says when that is an error)."""

    def __init__(self, source: list[str], n_frames: int, manual: DrumROI | None, keep: int) -> None:
        from vision.stream import DrumWatch

        self.source, self.n_frames, self.manual, self.keep = source, n_frames, manual, keep
        self.watch = DrumWatch(grace_s=math.inf)
        self.names: list[str] = []
        self.rois: list[DrumROI] = []  # grows as the stream goes: each frame's drum before it is handed over
        self.first: np.ndarray | None = None
        self.kept: list[np.ndarray] = []
        self.skipped: list[str] = []
        self.done = False  # the source read to its end

    def stream(self) -> Iterator[np.ndarray]:
        from vision.roi import detect_drum

        for name, img in _pick_frames(self.source, self.n_frames):
            if img.ndim != 3:
                raise VisionError(f"{name} is a grayscale image; colour classes need colour frames")
            if self.manual is None:
                try:
                    self.rois.append(detect_drum(img))
                except VisionError as exc:
                    self.watch.missed(math.nan, name, exc)
                    self.skipped.append(f"{name} left out: {exc}")
                    continue
            self.watch.found()
            self.names.append(name)
            self.first = img if self.first is None else self.first
            if len(self.kept) < self.keep:
                self.kept.append(img)  # the mixer's census measures these again (bounded)
            yield img
        self.done = True
        self.watch.finish()


@classes_app.command("suggest")
def suggest_cmd(
    source: list[str] = typer.Argument(..., help="Frames with both particle kinds: images, a folder, a video."),
    k: int = typer.Option(2, "--k", help="Number of particle classes (2..6)."),
    roi: str | None = typer.Option(None, "--roi", help="Drum circle cx,cy,r in px (overrides detection)."),
    n_frames: int = typer.Option(12, "--frames", help="Frames to learn from, spread over the source (1..500)."),
    preview: Path | None = typer.Option(None, "--preview", help="PNG: a frame beside its class map."),
    drum_diameter_mm: float | None = typer.Option(
        None, "--drum-diameter-mm", help="The drum's inner diameter (mm): also write the twin's mixer (\\[drum], "
        "[\\[particles]]) measured in the frames."),
    drum_depth_mm: float | None = typer.Option(
        None, "--drum-depth-mm", help="With --drum-diameter-mm: the end plates' distance (mm); default a "
        "monolayer drum (one particle thick)."),
    rotation: float | None = typer.Option(
        None, "--camera-rotation-deg",
        help="How far the camera is turned (deg, counter-clockwise as seen); default: from where the bed lies."),
    mirror: bool = typer.Option(False, "--mirror", help="The drum is filmed through a mirror."),
) -> None:
    """Learn the particle colours from the bed over many frames and print a ready TOML config."""
    from twin.cli.vision_cmds import CENSUS_MAX_FRAMES
    from twin.suggest_mixer import suggest_mixer_toml
    from vision.config import config_to_toml
    from vision.roi import parse_roi
    from vision.suggest import suggest_classes

    _check_suggest_options(k, n_frames, drum_diameter_mm, drum_depth_mm, rotation, preview)
    manual = parse_roi(roi) if roi else None
    picked = _Picked(source, n_frames, manual, CENSUS_MAX_FRAMES if drum_diameter_mm is not None else 0)
    try:
        cfg = suggest_classes(picked.stream(), manual, k=k, rois=None if manual else picked.rois,
                              camera_rotation_deg=rotation, mirror=mirror, n_frames=_pick_count(source, n_frames))
    except VisionError:
        if picked.names or not picked.done or picked.watch.misses:  # a frame's, the fit's or the policy's
            raise
        raise VisionError("no readable frames in the source") from None
    warn(picked.skipped)
    assert picked.first is not None
    r0 = manual or picked.rois[0]
    text = config_to_toml(cfg, _suggest_comment(cfg, picked, rotation))
    warn(cfg.warnings)
    if preview is not None:
        import cv2

        from vision.suggest import class_preview

        if not cv2.imwrite(str(preview), class_preview(picked.first, cfg.classes, r0)):
            raise VisionError(f"cannot write {preview}")
        say(f"preview of {picked.names[0]} -> {preview}")
    if drum_diameter_mm is not None:
        n = len(picked.kept)
        text += "\n" + suggest_mixer_toml(cfg, picked.kept, picked.rois[:n] if picked.rois else [r0] * n,
                                          float(drum_diameter_mm), drum_depth_mm)
    sys.stdout.write(text)


def _check_suggest_options(k: int, n_frames: int, drum_diameter_mm: float | None, drum_depth_mm: float | None,
                           rotation: float | None, preview: Path | None) -> None:
    check_number("--k", k, 2, 6)
    check_number("--frames", n_frames, 1, 500)
    if drum_diameter_mm is not None:
        check_number("--drum-diameter-mm", drum_diameter_mm, 10.0, 1e4)
    if drum_depth_mm is not None:
        if drum_diameter_mm is None:
            raise VisionError("--drum-depth-mm needs --drum-diameter-mm")
        check_number("--drum-depth-mm", drum_depth_mm, 0.1, 1e4)
    if rotation is not None:
        check_number("--camera-rotation-deg", rotation, -360, 360)
    if preview is not None and not preview.parent.exists():
        raise VisionError(f"--preview folder does not exist: {preview.parent}")
    if preview is not None and preview.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise VisionError(f"--preview must be a .png or .jpg file, got {preview.name}")


def _suggest_comment(cfg: MeterConfig, picked: _Picked, rotation: float | None) -> str:
    """The config's head comment: where it came from, and why opening and the camera's turn are
    what they are (both also said on stderr)."""
    from vision.suggest import OPENING_GRID

    names = ", ".join(c.name for c in cfg.counted)
    comment = (f"suggested by `drumtwin classes suggest` from {len(picked.names)} frame(s) ({picked.names[0]} ...); "
               f"classes: {names}.\nLearned colour model (CIELAB Gaussians); the first two classes give the MI.\n"
               "The drum is detected per frame size; add roi = [cx, cy, r] under [meter] to fix it.")
    if cfg.opening:
        why = (f"particles about {cfg.stride * OPENING_GRID:.0f} px or more across: opened on a grid of stride "
               f"{cfg.stride}" if cfg.stride > 1 else "it moved a class centroid by more than 1% of R on these frames")
        comment += (f"\nopening = true ({why}): it drops the thin rims and gaps that colour blur gives a class,\n"
                    "and keeps whole particles.")
        if cfg.stride > 1:  # turned on by frame size alone: it helps on blurred JPEG, costs on sharp frames
            comment += ("\nOn sharp frames (not heavily compressed JPEG) opening = false may read closer: on the\n"
                        "re-coloured real rigs at 2048 px it did, by up to 1.5 % of R (docs/validation.md, sec. 15).")
        say(f"class opening on ({why})")
    if rotation is None and cfg.camera_rotation_deg:
        why = (f"camera_rotation_deg = {cfg.camera_rotation_deg:g}: the bed lies towards the image's "
               f"{_SIDE[int(cfg.camera_rotation_deg) // 90]}, so gravity points there (nearest quarter turn)")
        comment += f"\n{why}"
        say(why)
    return comment + "".join(f"\nwarning: {w}" for w in cfg.warnings)

"""Frame sources: camera index, video file, stream URL, folder or list of images.

``open_source`` yields timestamped BGR frames. A live camera or stream that drops is
reopened with exponential back-off. A file that cannot be opened is a clear error; an
image in a sequence that cannot be decoded is yielded as a frame with ``error`` set (the
meter turns it into a flagged row) so one bad file does not stop a long run.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from vision.errors import VisionError

# Keep FFmpeg's own log lines ("moov atom not found") off stderr: a file that cannot be
# opened is reported once, as a VisionError. Set the variable yourself to see them.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")

__all__ = ["IMAGE_EXTENSIONS", "Frame", "open_source", "read_image", "source_kind"]

IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm")
_URL_PREFIXES = ("rtsp://", "rtsps://", "http://", "https://", "udp://", "tcp://", "rtmp://")
_EMPTY = np.zeros((0, 0, 3), np.uint8)


@dataclass(frozen=True, slots=True)
class Frame:
    """One frame: running index, time ``t_s`` (s since the source started, or video time),
    the BGR uint8 image, its origin and, for an unreadable image, ``error`` (image empty)."""

    index: int
    t_s: float
    image: np.ndarray
    name: str = ""
    error: str | None = None


def source_kind(spec) -> str:
    """``camera``, ``url``, ``folder``, ``images``, ``image`` or ``video`` for a source spec."""
    if isinstance(spec, (list, tuple)):
        if len(spec) == 1:
            return source_kind(spec[0])
        return "images"
    if isinstance(spec, int) or (isinstance(spec, str) and spec.strip().isdigit()):
        return "camera"
    s = str(spec)
    if s.lower().startswith(_URL_PREFIXES):
        return "url"
    p = Path(s)
    if p.is_dir():
        return "folder"
    if p.suffix.lower() in IMAGE_EXTENSIONS:
        return "image"
    return "video"


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, str | None]:
    """Decode one image file into BGR uint8: ``(image, None)`` or ``(empty, reason)``.

    Grayscale files stay 2-D (the meter flags them); alpha is dropped; 16-bit is scaled; a
    JPEG's EXIF orientation is applied (the image as a viewer shows it).
    Raises ``FileNotFoundError`` when the file does not exist.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no such image: {p}")
    data = np.fromfile(str(p), dtype=np.uint8)
    # any depth and channel count, alpha dropped, EXIF orientation applied (IMREAD_UNCHANGED ignores it)
    img = cv2.imdecode(data, cv2.IMREAD_ANYCOLOR | cv2.IMREAD_ANYDEPTH) if data.size else None
    if img is None:
        return _EMPTY, f"cannot decode image {p.name} (corrupt or not an image)"
    if _truncated(data):
        return _EMPTY, f"cannot decode image {p.name} (truncated file)"
    if img.dtype == np.uint16:
        img = (np.asarray(img, np.uint16) >> 8).astype(np.uint8)
    elif img.dtype != np.uint8:
        return _EMPTY, f"unsupported image depth {img.dtype} in {p.name}"
    if img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    return img, None


def _truncated(data: np.ndarray) -> bool:
    """A JPEG without its end marker or a PNG without its IEND chunk (OpenCV decodes what
    is there and fills the rest, so a cut-off file would look like a real frame)."""
    head = data[:8].tobytes()
    tail = data[-64:].tobytes().rstrip(b"\x00\r\n ")
    if head[:2] == b"\xff\xd8":
        return not tail.endswith(b"\xff\xd9")
    if head == b"\x89PNG\r\n\x1a\n":
        return b"IEND" not in tail
    return False


def _image_paths(spec) -> list[Path]:
    if isinstance(spec, (list, tuple)):
        paths: list[Path] = []
        for s in spec:
            p = Path(str(s))
            if p.is_dir():
                paths += _image_paths(p)
            elif not p.exists():
                raise FileNotFoundError(f"no such file: {p}")
            else:
                paths.append(p)
        return sorted(paths, key=lambda q: q.name)
    p = Path(str(spec))
    files = sorted(
        (q for q in p.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_EXTENSIONS), key=lambda q: q.name
    )
    if not files:
        raise VisionError(f"folder {p} has no images ({', '.join(IMAGE_EXTENSIONS)})")
    return files


def open_source(
    spec,
    *,
    loop: bool = False,
    reconnect: bool = True,
    fps: float = 30.0,
    reconnect_tries: int = 10,
    backoff_s: tuple[float, float] = (0.5, 8.0),
    capture_factory: Callable[[object], Any] | None = None,
    sleep: Callable[[float], None] = time.sleep,
) -> Iterator[Frame]:
    """Yield ``Frame`` objects from ``spec``.

    ``spec``: camera index (``0`` or ``"0"``), stream URL, video file, image file, folder of
    images (name order) or a list of those (name order). ``fps`` timestamps image
    sequences (``t_s = index / fps``); videos use their own clock; live sources the
    monotonic clock. ``loop`` restarts files at the end. A live source that stops
    delivering is reopened after ``backoff_s[0]`` s, doubling up to ``backoff_s[1]``;
    after ``reconnect_tries`` failed reopenings in a row it raises ``ConnectionError``.
    ``capture_factory`` replaces ``cv2.VideoCapture`` (tests, emulated cameras).
    """
    kind = source_kind(spec)
    if isinstance(spec, (list, tuple)) and len(spec) == 1:
        spec = spec[0]
    if fps <= 0:
        raise VisionError(f"fps must be > 0, got {fps}")
    factory = capture_factory or cv2.VideoCapture
    if capture_factory is None:
        _quiet_opencv()
    if kind in ("camera", "url"):
        target = int(str(spec).strip()) if kind == "camera" else str(spec)
        cap = factory(target)  # opened now, so a missing camera fails before any output
        if not cap.isOpened():
            cap.release()
            what = f"camera {target}" if isinstance(target, int) else f"stream {target}"
            raise ConnectionError(f"cannot open {what}")
        return _live(target, factory, reconnect, reconnect_tries, backoff_s, sleep, cap)
    if kind == "video":
        p = Path(str(spec))
        if not p.exists():
            raise FileNotFoundError(f"no such file: {p}")
        cap = factory(str(p))
        if not cap.isOpened():
            cap.release()
            raise VisionError(f"cannot open video {p} (not a video OpenCV can read)")
        return _video(p, factory, loop, cap)
    paths = [Path(str(spec))] if kind == "image" else _image_paths(spec)
    if kind == "image" and not paths[0].exists():
        raise FileNotFoundError(f"no such file: {paths[0]}")
    return _images(paths, loop, fps)


def _images(paths: Sequence[Path], loop: bool, fps: float) -> Iterator[Frame]:
    i = 0
    while True:
        for p in paths:
            img, err = read_image(p)
            yield Frame(i, i / fps, img, p.name, err)
            i += 1
        if not loop:
            return


def _quiet_opencv() -> None:
    """OpenCV's own warnings (V4L2, FFmpeg) would add lines to a one-line error."""
    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:  # pragma: no cover - older builds
        pass


def _video(path: Path, factory, loop: bool, cap) -> Iterator[Frame]:
    try:
        fps = cap.get(cv2.CAP_PROP_FPS) or 0.0
        if not (0 < fps < 1000):
            fps = 30.0
        i = 0
        j = 0  # index within the current pass
        offset_s = 0.0
        while True:
            ok, img = cap.read()
            if not ok:
                if j == 0:
                    raise VisionError(f"video {path} has no readable frames")
                if not loop:
                    return
                offset_s += j / fps
                j = 0
                cap.release()
                cap = factory(str(path))
                continue
            yield Frame(i, offset_s + j / fps, img, path.name)
            i += 1
            j += 1
    finally:
        cap.release()


def _live(target, factory, reconnect: bool, tries: int, backoff_s: tuple[float, float], sleep, cap) -> Iterator[Frame]:
    what = f"camera {target}" if isinstance(target, int) else f"stream {target}"
    t0 = time.monotonic()
    i = 0
    failures = 0  # reopenings since the last good frame
    delay = backoff_s[0]
    try:
        while True:
            ok, img = cap.read()
            if ok and img is not None:
                failures = 0
                delay = backoff_s[0]
                yield Frame(i, time.monotonic() - t0, img, str(target))
                i += 1
                continue
            if not reconnect:
                return
            cap.release()
            while True:
                if failures >= tries:
                    raise ConnectionError(f"{what} dropped and did not come back after {tries} tries")
                sleep(delay)
                failures += 1
                delay = min(delay * 2.0, backoff_s[1])
                cap = factory(target)
                if cap.isOpened():
                    break
                cap.release()
    finally:
        cap.release()

"""Vision benchmark: frames/s of the centroid, GLCM and Lacey pipelines on one thread.

Frames are synthetic drums (``vision.synthetic``), decoded in memory beforehand; the centroid
pipelines run the one measurement path (``vision.stream.FrameMeter.measure``: a ``Frame`` in,
its ``Reading`` out, the no-drum policy included), the baselines their full per-frame path (ROI
crop, classify, counts, index).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TypeVar

import cv2
import numpy as np

from vision.glcm import GLCMMeter
from vision.lacey import LaceyMeter
from vision.meter import Meter
from vision.moments import remapped_tables
from vision.photometric import channel_maps, class_reference_from_frames, reference_from_frames
from vision.roi import DrumROI
from vision.sources import Frame
from vision.stream import FrameMeter
from vision.synthetic import drum_frame, light_change, perturb

__all__ = ["frames_per_second", "path_fps", "run_vision_bench"]

T = TypeVar("T")
SCENES = [(0.0, 30), (0.3, 25), (0.7, 35), (1.0, 28)]  # (mix, slope_deg) of the four bench drums


def frames_per_second(
    fn: Callable[[T], object], frames: Sequence[T], seconds: float, min_calls: int = 3,
    clock: Callable[[], float] = time.perf_counter,
) -> float:
    """Calls of ``fn`` per second of ``clock`` (wall time; ``time.thread_time``: this thread's
    CPU time, which a busy machine changes far less) over ``frames`` (cycled) for about
    ``seconds`` s of it."""
    fn(frames[0])  # warm-up: geometry, buffers
    n = 0
    t0 = clock()
    while True:
        fn(frames[n % len(frames)])
        n += 1
        dt = clock() - t0
        if n >= min_calls and dt >= seconds:
            return n / dt


def _frames(images: Sequence[np.ndarray]) -> list[Frame]:
    return [Frame(i, i / 30.0, img) for i, img in enumerate(images)]


def path_fps(meter: Meter, images: Sequence[np.ndarray], seconds: float,
             clock: Callable[[], float] = time.perf_counter) -> float:
    """Frames/s of the measurement path with ``meter`` over ``images`` (see :func:`frames_per_second`)."""
    return frames_per_second(FrameMeter(meter).measure, _frames(images), seconds, clock=clock)


def _light(images: list[np.ndarray], roi: DrumROI) -> dict:
    """The meter's light reference (set-up light and per class) from the first image."""
    plain = Meter(roi=roi)
    return {"light_reference": reference_from_frames(images[:1], [roi]),
            "light_reference_classes": class_reference_from_frames(images[:1], [roi], plain._base_tables.fine,
                                                                   len(plain.classes) + 1)}


def _estimate_share(meter: Meter, images: Sequence[np.ndarray]) -> float:
    """The share of 40 frames (``images`` looped) on which ``meter`` ran a full light estimate."""
    fm, frames = FrameMeter(meter), _frames(images)
    for i in range(40):
        fm.measure(frames[i % len(frames)])
    return meter.estimates / 40


def run_vision_bench(seconds: float = 1.5, log: Callable[[str], None] | None = None) -> dict:
    """Run the benchmark and return the numbers (frames/s); ``centroid_fps_opening`` is the
    centroid path with the class opening (``[meter] opening = true``), ``centroid_fps_glare``
    on the same frames with three glare spots each (filled, ``vision.glare``).

    ``centroid_fps_tracked``: photometric tracking on (``vision.photometric``; a light
    reference from the first frame, the light estimated every 4th frame as the meter does by
    default), the same frames under unchanged light; ``centroid_fps_light_moved``: frames
    whose exposure alternates x1 and x0.8, so each tracked frame re-bakes the table;
    ``rebake_s``: one re-bake of the 2^24 table (the cost of a light change);
    ``tracked_ratio``: tracked / plain frames/s in this run. ``*_cpu_fps``: the same paths per
    second of the thread's CPU time (on a shared machine, the numbers to compare between runs),
    ``glcm_cpu_ratio`` their ratio. ``tracked_estimate_share``: the share of frames of the
    tracked CPU row that ran a full light estimate (the four bench scenes differ in their
    colour shares, so the meter's jump check starts one on nearly every frame: the worst case,
    not the every-4th-frame default of a steady video). ``centroid_fps_steady`` and
    ``centroid_fps_tracked_steady`` (``centroid_cpu_fps_tracked_steady`` in CPU time): plain and
    tracked on a steady video -- eight frames of one bed (mix 0.3) under a webcam's sensor noise
    (sigma 8, a new draw each frame), so the meter runs its default schedule;
    ``tracked_steady_ratio`` their ratio, ``tracked_steady_estimate_share`` the share of its
    frames fully estimated (0.25 when no jump check fires). ``centroid_cpu_fps_light_moved``: the
    light-moved row in CPU time (a re-bake per frame). ``centroid_cpu_fps_islands``: the island
    filter on (``[meter] island_px``, ``vision.islands``; 30 px), ``islands_cost_ratio`` its
    CPU frames/s over the plain path's."""
    prev = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        say = log or (lambda s: None)
        vga = [drum_frame((640, 480), mix=m, slope_deg=s, seed=i) for i, (m, s) in enumerate(SCENES)]
        # the same scenes drawn natively at 1080p (a resize would stretch the drum into an ellipse)
        hd = [drum_frame((1920, 1080), mix=m, slope_deg=s, seed=i) for i, (m, s) in enumerate(SCENES)]
        roi = Meter().measure(vga[0]).roi  # the drum is where detect_drum finds it; fix it for all
        roi_hd = Meter().measure(hd[0]).roi
        assert roi is not None and roi_hd is not None
        res: dict = {}
        say("centroid 640x480 ...")
        res.update(_plain_rows(vga, roi, seconds))
        say("centroid 640x480, photometric tracking ...")
        res.update(_tracked_rows(vga, roi, seconds))
        say("GLCM 640x480 ...")
        res["glcm_fps"] = frames_per_second(GLCMMeter(roi).measure, vga, seconds)
        say("CPU time per frame (centroid, tracked, GLCM) ...")
        res.update(_cpu_rows(vga, roi, seconds))
        res.update(_steady_rows(vga, roi, seconds))
        say("centroid 640x480, island filter ...")
        res["centroid_cpu_fps_islands"] = path_fps(Meter(roi=roi, island_px=30), vga, seconds, clock=time.thread_time)
        say("Lacey 640x480 ...")
        res["lacey_fps"] = frames_per_second(LaceyMeter(roi=roi).measure, vga, seconds)
        say("centroid 1920x1080 ...")
        res["centroid_fps_1080p"] = path_fps(Meter(roi=roi_hd), hd, seconds)
        res["centroid_fps_1080p_stride2"] = path_fps(Meter(roi=roi_hd, stride=2), hd, seconds)
        res.update(tracked_ratio=res["centroid_fps_tracked"] / res["centroid_fps"],
                   glcm_cpu_ratio=res["centroid_cpu_fps"] / res["glcm_cpu_fps"],
                   islands_cost_ratio=res["centroid_cpu_fps_islands"] / res["centroid_cpu_fps"],
                   glcm_ratio=res["centroid_fps"] / res["glcm_fps"], lacey_ratio=res["centroid_fps"] / res["lacey_fps"],
                   threads=1, stride=1)
        return res
    finally:
        cv2.setNumThreads(prev)


def _plain_rows(vga: list[np.ndarray], roi: DrumROI, seconds: float) -> dict:
    glare = [perturb(f, "glare", seed=i)[0] for i, f in enumerate(vga)]
    return {"centroid_fps": path_fps(Meter(roi=roi), vga, seconds),
            "centroid_fps_stride2": path_fps(Meter(roi=roi, stride=2), vga, seconds),
            "centroid_fps_opening": path_fps(Meter(roi=roi, opening=True), vga, seconds),
            "centroid_fps_glare": path_fps(Meter(roi=roi), glare, seconds)}


def _tracked_rows(vga: list[np.ndarray], roi: DrumROI, seconds: float) -> dict:
    light = _light(vga, roi)
    moved = [light_change(f, 0.8) if i % 2 else f for i, f in enumerate(vga)]
    res = {"centroid_fps_tracked": path_fps(Meter(roi=roi, **light), vga, seconds),
           "centroid_fps_light_moved": path_fps(Meter(roi=roi, **light, track_every=1), moved, seconds)}
    t0 = time.perf_counter()
    remapped_tables(Meter(roi=roi).colour_classes, channel_maps((0.8, 0.8, 0.8)))
    res["rebake_s"] = time.perf_counter() - t0
    return res


def _cpu_rows(vga: list[np.ndarray], roi: DrumROI, seconds: float) -> dict:
    cpu, light = time.thread_time, _light(vga, roi)
    moved = [light_change(f, 0.8) if i % 2 else f for i, f in enumerate(vga)]
    return {"centroid_cpu_fps": path_fps(Meter(roi=roi), vga, seconds, clock=cpu),
            "centroid_cpu_fps_tracked": path_fps(Meter(roi=roi, **light), vga, seconds, clock=cpu),
            "glcm_cpu_fps": frames_per_second(GLCMMeter(roi).measure, vga, seconds, clock=cpu),
            "tracked_estimate_share": _estimate_share(Meter(roi=roi, **light), vga),
            "centroid_cpu_fps_light_moved": path_fps(Meter(roi=roi, **light, track_every=1), moved, seconds,
                                                     clock=cpu)}


def _steady_rows(vga: list[np.ndarray], roi: DrumROI, seconds: float) -> dict:
    """A steady video: one bed under the sensor noise of a webcam (a new draw each frame), as
    consecutive frames of a turning drum -- the meter's default schedule (a full estimate every
    4th frame, the jump check on the others)."""
    steady = [perturb(vga[1], "noise", seed=10 + i)[0] for i in range(8)]
    light = _light(steady, roi)
    res = {"centroid_fps_steady": path_fps(Meter(roi=roi), steady, seconds),
           "centroid_fps_tracked_steady": path_fps(Meter(roi=roi, **light), steady, seconds),
           "centroid_cpu_fps_tracked_steady": path_fps(Meter(roi=roi, **light), steady, seconds,
                                                       clock=time.thread_time),
           "tracked_steady_estimate_share": _estimate_share(Meter(roi=roi, **light), steady)}
    res["tracked_steady_ratio"] = res["centroid_fps_tracked_steady"] / res["centroid_fps_steady"]
    return res

"""A stream of frames -> one ``Reading`` per frame: the one measurement path of the project.

``drumtwin mi``, the live run's camera worker, the benches and ``classes suggest``'s drum
search all go through here, so a frame that cannot be measured is treated the same
everywhere (the no-drum policy, :class:`DrumWatch`):

* an unreadable frame (a corrupt image, a grayscale one) is an invalid reading flagged
  ``bad_frame:<why>``;
* a frame in which the drum cannot be found (a webcam warming up: black or washed-out
  frames; a test chart of another size) is an invalid reading flagged ``no_drum:<why>``;
* the stream is bad input (a ``VisionError``) when no drum has been found within
  ``NO_DRUM_GRACE_S`` of camera time from its first frame, or when it ends without one
  (:func:`readings`, a file's frames, also when it ends without a single readable frame).

The frame -> ``Reading`` step itself is ``vision.meter.Meter.measure``; the trend, moving
average and the frame row (``twin.records.FrameReading``) follow in ``twin.frame_rows``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import replace

import numpy as np

from vision.errors import VisionError
from vision.meter import Meter, Reading
from vision.sources import Frame

__all__ = ["NO_DRUM_GRACE_S", "DrumWatch", "FrameMeter", "readings", "with_index"]

NO_DRUM_GRACE_S = 5.0
"""Camera seconds from the first frame during which frames without a findable drum are
flagged readings (``no_drum:``); a source that shows no drum for longer, or ends without one,
is bad input."""

_NAN = float("nan")


class DrumWatch:
    """The no-drum policy (see the module doc): call :meth:`found` for a frame whose drum was
    found, :meth:`missed` for one where it was not (it returns the reading's flag, or raises once
    the grace is over), :meth:`finish` when the source ends. ``grace_s``: camera seconds from the
    first frame (``math.inf``: until the source ends, for frames picked across a whole source)."""

    def __init__(self, grace_s: float = NO_DRUM_GRACE_S) -> None:
        self.grace_s = float(grace_s)
        self.found_any = False
        self._t_first: float | None = None
        self._first_miss: str | None = None  # "<frame>: <why>" of the first frame without a drum
        self.misses = 0

    def seen(self, t_s: float) -> None:
        """A frame at camera time ``t_s`` arrived (the grace runs from the first one with a time)."""
        if self._t_first is None and math.isfinite(t_s):
            self._t_first = t_s

    def found(self) -> None:
        self.found_any = True

    def missed(self, t_s: float, name: str, exc: Exception) -> str:
        """The flag of a frame without a findable drum; a ``VisionError`` when no drum has
        been found for longer than the grace."""
        self.misses += 1
        if self._first_miss is None:
            self._first_miss = f"{name}: {exc}" if name else str(exc)
        waited = t_s - self._t_first if self._t_first is not None else _NAN
        if not self.found_any and waited > self.grace_s:
            raise VisionError(f"no drum in {waited:.0f} s of camera frames: {exc}")
        return f"no_drum:{exc}"

    def finish(self) -> None:
        """The source ended: a ``VisionError`` when frames came and no drum was found in any."""
        if not self.found_any and self._first_miss is not None:
            raise VisionError(f"no drum in any frame ({self.misses} without one; the first, {self._first_miss})")


class FrameMeter:
    """``Frame`` -> ``Reading`` with the no-drum policy: ``measure(frame)`` never raises for a
    frame that cannot be measured (it flags it), only when the policy says the stream is bad
    input; ``finish()`` at the end of the source (the policy's last word). ``meter`` may be
    swapped between frames (the live run's re-learned classes)."""

    def __init__(self, meter: Meter, grace_s: float = NO_DRUM_GRACE_S) -> None:
        self.meter = meter
        self.watch = DrumWatch(grace_s)
        self.frames = 0  # frames handed in
        self.measured = 0  # frames the meter measured (readable, drum found)
        self.first_bad: str | None = None  # why the first unreadable frame could not be read

    def measure(self, frame: Frame) -> Reading:
        """One frame's reading (flagged ``bad_frame:`` / ``no_drum:`` when it cannot be measured)."""
        self.frames += 1
        self.watch.seen(frame.t_s)
        image = frame.image
        if frame.error or image.ndim == 2:
            why = frame.error or (f"{frame.name or 'the frame'} is a grayscale image; the mixing index needs "
                                  "colour frames")
            self.first_bad = self.first_bad or why
            return self.meter.invalid(f"bad_frame:{why}")
        try:
            reading = self.meter.measure(image)
        except VisionError as exc:  # no drum in a frame of a new size
            return self.meter.invalid(self.watch.missed(frame.t_s, frame.name, exc))
        self.watch.found()
        self.measured += 1
        return reading

    def finish(self) -> None:
        """The source ended: a ``VisionError`` when frames came and none showed a drum."""
        self.watch.finish()


def readings(frames: Iterable[Frame], meter: FrameMeter, max_frames: int = 0) -> Iterator[tuple[Frame, Reading]]:
    """Each frame of ``frames`` with its reading, in order (at most ``max_frames``, 0: all), then
    the policy's word on the frames measured: a ``VisionError`` when the source gave no frame, no
    readable frame (a run's camera that ends so is lost vision instead: the supervisor's safe
    state) or no drum."""
    for n, frame in enumerate(frames, 1):
        yield frame, meter.measure(frame)
        if max_frames and n >= max_frames:
            break
    if meter.frames == 0:
        raise VisionError("the source gave no frames")
    if meter.measured == 0 and meter.watch.misses == 0:
        raise VisionError(f"none of the {meter.frames} frames could be read (corrupt or not images): "
                          f"{meter.first_bad}")
    meter.finish()


def with_index(reading: Reading, mi: float) -> Reading:
    """``reading`` with another mixing index in place of the centroid MI (a baseline, Lacey or
    GLCM: ``drumtwin mi --method``): the paper's other indices and distances left out (NaN),
    the slope and the classes kept; valid when ``mi`` is a number."""
    return replace(reading, mi=float(mi), mi_sigmoid=_NAN, mi_linear=_NAN, d_px=_NAN, dsigma_px=_NAN,
                   valid=bool(np.isfinite(mi)))

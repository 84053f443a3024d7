"""Streaming decimation of a plotted series: memory bounded by the plot, not the log.

A million-row log needs a few thousand points on a 6-inch plot. :class:`MinMax` keeps, for each
bucket of consecutive rows, the row with the smallest and the row with the largest value, and
takes rows as they stream in: when the points kept pass ``4 * buckets``, the buckets double in
width and are merged (min of the mins, max of the maxes), so it never holds more than
``4 * buckets`` points plus one batch, whatever the log's length.

Min/max rather than LTTB (largest-triangle-three-buckets): min/max keeps every spike, a single
frame's MI dip or rpm glitch, which is what an operator looks for in a fault, and the drawn
envelope is exactly the data's; it needs no look-ahead (LTTB picks a bucket's point against the
next bucket's mean: a second pass or a buffer) and it vectorises per batch. LTTB draws a
smoother line of the same size but may drop an isolated spike.

A bucket whose values are all NaN (invalid frames, no twin yet) keeps one NaN point, so the line
shows the gap; ``x`` rides along with each kept row (the run time of that row).
"""

from __future__ import annotations

import numpy as np

BUCKETS = 2000
"""Buckets of a report plot: at most ~4,000 points a series (2 a bucket) on a 576-px-wide axis."""


def minmax_rows(rows: np.ndarray, y: np.ndarray, width: int) -> np.ndarray:
    """Indexes (into ``rows``/``y``, increasing) of the rows to keep: per bucket of ``width``
    consecutive row numbers, the smallest and the largest finite ``y`` (one NaN row for a bucket
    of NaN only). ``rows`` must be increasing."""
    if rows.size == 0:
        return np.zeros(0, dtype=np.int64)
    b = rows // width
    first = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])  # start of each bucket (b is sorted)
    seg = np.repeat(np.arange(first.size), np.diff(np.r_[first, b.size]))
    keep = []
    for v in (np.where(np.isnan(y), np.inf, y), np.where(np.isnan(y), np.inf, -y)):
        best = np.minimum.reduceat(v, first)  # per bucket (a NaN bucket: inf, its first row)
        at = np.flatnonzero(v == best[seg])
        keep.append(at[np.r_[True, seg[at][1:] != seg[at][:-1]]])  # the first such row per bucket
    return np.union1d(keep[0], keep[1])


class MinMax:
    """One series, decimated as it streams (module doc): ``add(x, y)`` per batch of rows, in row
    order; ``points()`` -> ``(x, y)`` of the rows kept, in row order."""

    def __init__(self, buckets: int = BUCKETS) -> None:
        self.buckets = max(1, int(buckets))
        self.width = 1  # rows per bucket
        self.n = 0  # rows seen
        self._rows = np.zeros(0, dtype=np.int64)
        self._x = np.zeros(0)
        self._y = np.zeros(0)

    def add(self, x: np.ndarray, y: np.ndarray) -> None:
        """The next rows (equal lengths; NaN y: a gap)."""
        m = len(y)
        if m == 0:
            return
        rows = np.arange(self.n, self.n + m, dtype=np.int64)
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        self.n += m
        if self.width > 1:  # the batch on its own first: a bucket it shares with the last keeps 4
            keep = minmax_rows(rows, y, self.width)
            rows, x, y = rows[keep], x[keep], y[keep]
        self._rows = np.concatenate([self._rows, rows])
        self._x = np.concatenate([self._x, x])
        self._y = np.concatenate([self._y, y])
        if self._rows.size > 4 * self.buckets:
            while self.n > self.width * self.buckets:
                self.width *= 2
            keep = minmax_rows(self._rows, self._y, self.width)
            self._rows, self._x, self._y = self._rows[keep], self._x[keep], self._y[keep]

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        return self._x.copy(), self._y.copy()

    def coarser(self, buckets: int) -> tuple[np.ndarray, np.ndarray]:
        """The points kept, decimated again to ``buckets`` (an overview of many runs)."""
        width = max(1, -(-self.n // max(1, buckets)))
        keep = minmax_rows(self._rows, self._y, width)
        return self._x[keep], self._y[keep]

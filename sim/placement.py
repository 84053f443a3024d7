"""Where a twin's particles start: random sequential addition of discs in the drum, on a cell grid.

Both engines place their particles as discs (a shaped particle as its circumscribed disc) at
``SHRINK`` of their size, largest first, at least ``GAP_R`` of the largest radius apart, then
inflate them. A candidate is checked against the placed discs near it only: ``DiscGrid`` keeps
each placed disc in the cells its bounding box touches (cells about the smallest disc's size,
never more than ``CELLS_PER_DISC`` per disc, so a drum of any size costs memory in proportion to
its particles), and a candidate looks in the cells its own reach touches. Placement is then
linear in the particle count (2 x 100,000 discs in a 10 m drum: about a second, where the check
against every placed disc took over 70 s; docs/validation.md, "Placement").

The grid answers exactly what the check against every placed disc answered (the same strict
inequality in the same floating-point order), and ``place_random`` draws the same random numbers
in the same order as the loop it replaced, so a seed places every disc where it did before.

Why not the DEM's cell code (``sim.dem_neighbours.rebuild_list``): that sorts a finished set of positions into
cells once per neighbour list (a counting sort); placement adds one disc at a time and asks
after each, which wants cells that grow (a linked list per cell).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from sim.errors import SimError
from sim.recipe import DiskClass, DrumSpec

SHRINK = 0.8  # placement size before inflation (of the full radius)
GAP_R = 0.02  # placed discs keep this share of the largest radius apart
MAX_TRIES = 20_000  # random candidates per disc before the bed is declared not to fit
CELLS_PER_DISC = 16  # the grid's cells per disc at most (its memory, whatever the drum's size)
_BATCH_TRIES = 4  # random candidates drawn per disc still to place, per batch of draws


@njit(cache=True)
def _cell_range(lo: float, hi: float, origin: float, cs: float, nc: int) -> tuple[int, int]:
    """The first and last cell (clamped to 0..nc-1) a span [lo, hi] of one axis touches."""
    a0 = int(math.floor((lo - origin) / cs))
    a1 = int(math.floor((hi - origin) / cs))
    return min(max(a0, 0), nc - 1), min(max(a1, 0), nc - 1)


@njit(cache=True)
def _is_free(x: float, y: float, r: float, gap: float, head: np.ndarray, nxt: np.ndarray, ent: np.ndarray,
             px: np.ndarray, py: np.ndarray, pr: np.ndarray, origin: float, cs: float, nc: int) -> bool:
    """No placed disc ``j`` with ``(px_j - x)^2 + (py_j - y)^2 < (pr_j + r + gap)^2``: the cells the
    candidate's reach touches (a hair wider: rounding can only add a cell) hold every such disc."""
    reach = r + gap + 1e-9 * cs
    a0, a1 = _cell_range(x - reach, x + reach, origin, cs, nc)
    b0, b1 = _cell_range(y - reach, y + reach, origin, cs, nc)
    for b in range(b0, b1 + 1):
        for a in range(a0, a1 + 1):
            e = head[b * nc + a]
            while e >= 0:
                j = ent[e]
                dx = px[j] - x
                dy = py[j] - y
                t = pr[j] + r + gap
                if dx * dx + dy * dy < t * t:
                    return False
                e = nxt[e]
    return True


@njit(cache=True)
def _add(j: int, x: float, y: float, r: float, head: np.ndarray, nxt: np.ndarray, ent: np.ndarray,
         n_ent: np.ndarray, px: np.ndarray, py: np.ndarray, pr: np.ndarray, origin: float, cs: float,
         nc: int) -> None:
    """Disc ``j`` at (x, y) of radius ``r`` into every cell its bounding box touches."""
    px[j] = x
    py[j] = y
    pr[j] = r
    a0, a1 = _cell_range(x - r, x + r, origin, cs, nc)
    b0, b1 = _cell_range(y - r, y + r, origin, cs, nc)
    for b in range(b0, b1 + 1):
        for a in range(a0, a1 + 1):
            c = b * nc + a
            e = n_ent[0]
            ent[e] = j
            nxt[e] = head[c]
            head[c] = e
            n_ent[0] = e + 1


class DiscGrid:
    """Placed discs in the cells of a square over the drum (radius ``radius_m``), for discs of
    placement radii ``radii_m`` (their number bounds the grid's memory) kept ``gap_m`` apart.

    ``first_free(points, r, inside)``: the first point (of those ``inside`` the wall) clear of
    every placed disc by ``gap_m``, or -1; ``add(j, x, y, r)``: disc ``j`` placed.
    """

    def __init__(self, radius_m: float, radii_m: np.ndarray, gap_m: float) -> None:
        radii = np.asarray(radii_m, dtype=np.float64)
        n = max(int(radii.size), 1)
        side = 2.0 * float(radius_m)
        r_min = float(radii.min()) if radii.size else 0.0
        cs = max(2.0 * r_min + gap_m, side / math.sqrt(CELLS_PER_DISC * n), 1e-12)
        self.nc = int(side / cs) + 2
        self.cs = cs
        self.origin = -float(radius_m) - 0.5 * cs
        self.gap_m = float(gap_m)
        per_disc = (np.floor(2.0 * radii / cs) + 2.0) ** 2  # cells a disc's bounding box can touch
        cap = int(per_disc.sum()) + 1
        self.head = np.full(self.nc * self.nc, -1, dtype=np.int64)
        self.nxt = np.empty(cap, dtype=np.int64)
        self.ent = np.empty(cap, dtype=np.int64)
        self.n_ent = np.zeros(1, dtype=np.int64)
        self.px = np.zeros(n)
        self.py = np.zeros(n)
        self.pr = np.zeros(n)

    def add(self, j: int, x: float, y: float, r: float) -> None:
        _add(int(j), float(x), float(y), float(r), self.head, self.nxt, self.ent, self.n_ent, self.px, self.py,
             self.pr, self.origin, self.cs, self.nc)

    def first_free(self, points: np.ndarray, r: float, inside: np.ndarray) -> int:
        return int(_first_free(np.ascontiguousarray(points, dtype=np.float64), float(r), self.gap_m,
                               np.asarray(inside, dtype=np.bool_), self.head, self.nxt, self.ent, self.px, self.py,
                               self.pr, self.origin, self.cs, self.nc))


@njit(cache=True)
def _first_free(points, r, gap, inside, head, nxt, ent, px, py, pr, origin, cs, nc) -> int:
    for k in range(points.shape[0]):
        if inside[k] and _is_free(points[k, 0], points[k, 1], r, gap, head, nxt, ent, px, py, pr, origin, cs, nc):
            return k
    return -1


@njit(cache=True)
def _sequential(u, done, tries, order, small_r, full_r, cls, case, split, radius_m, gap, pos,
                head, nxt, ent, n_ent, px, py, pr, origin, cs, nc, max_tries):
    """Random sequential addition of the discs ``order[done:]`` from the uniform numbers ``u``
    (two per candidate: x, y); ``tries`` candidates of ``order[done]`` were drawn before.
    Returns (discs done, tries of the next disc, numbers used, False if a disc found no room)."""
    k = 0
    n = order.size
    while done < n:
        i = order[done]
        r = small_r[i]
        lim = radius_m - full_r[i] - gap
        span = lim - -lim
        placed = False
        while tries < max_tries:
            if k + 2 > u.size:
                return done, tries, k, True
            x = -lim + span * u[k]
            y = -lim + span * u[k + 1]
            k += 2
            tries += 1
            if x * x + y * y > lim * lim:
                continue
            if split and case == 1 and ((x > -r) if cls[i] == 0 else (x < r)):
                continue  # case A: class 0 (large) left, the others right
            if split and case == 2 and ((y < r) if cls[i] == 0 else (y > -r)):
                continue  # case B: class 0 (large) on top, the others below
            if not _is_free(x, y, r, gap, head, nxt, ent, px, py, pr, origin, cs, nc):
                continue
            pos[i, 0] = x
            pos[i, 1] = y
            _add(i, x, y, r, head, nxt, ent, n_ent, px, py, pr, origin, cs, nc)
            placed = True
            break
        if not placed:
            return done, tries, k, False
        done += 1
        tries = 0
    return done, tries, k, True


def disc_arrays(classes: Sequence[DiskClass]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Per disc (class order): full radius (m) and class index; the placement order (largest first,
    stable) and the gap (m) the placed discs keep."""
    radii = np.concatenate([np.full(c.count, c.radius_m) for c in classes])
    cls = np.concatenate([np.full(c.count, k, dtype=np.int64) for k, c in enumerate(classes)])
    return radii, cls, np.argsort(-radii, kind="stable"), GAP_R * float(radii.max())


def place_random(classes: Sequence[DiskClass], case: str, radius_m: float,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 2; m) and class indices (n,) of ``classes``' discs by random sequential addition at
    ``SHRINK`` size over the drum of radius ``radius_m``: case "A" class 0 left and the others right,
    "B" class 0 on top and the others below, "C" anywhere. Each candidate takes two of ``rng``'s
    uniform numbers; exactly those used are taken from ``rng`` (what follows draws what it drew before)."""
    radii, cls, order, gap = disc_arrays(classes)
    small_r = radii * SHRINK
    grid = DiscGrid(radius_m, small_r, gap)
    pos = np.zeros((radii.size, 2))
    case_no = {"A": 1, "B": 2}.get(case, 0)
    done, tries = 0, 0
    while True:
        state = rng.bit_generator.state
        u = rng.random(2 * _BATCH_TRIES * max(radii.size - done, 64))
        done, tries, used, fits = _sequential(u, done, tries, order, small_r, radii, cls, case_no, len(classes) >= 2,
                                              float(radius_m), gap, pos, grid.head, grid.nxt, grid.ent, grid.n_ent,
                                              grid.px, grid.py, grid.pr, grid.origin, grid.cs, grid.nc, MAX_TRIES)
        if not fits:
            raise SimError(f"recipe does not fit: could not place {radii.size} disks in the drum "
                           f"(case {case}); lower the fill level or the counts")
        if done == radii.size:
            rng.bit_generator.state = state
            rng.random(used)  # the numbers used, no more
            return pos, cls


def check_placement(pos_m: np.ndarray, classes: np.ndarray, angle_rad: np.ndarray, n_classes: int,
                    drum: DrumSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A caller's placement (centres ``pos_m`` (n, 2; m, drum frame), class indices ``classes`` (n,)
    into ``n_classes`` classes, angles ``angle_rad`` (n,; rad)) as float64, int64 and float64 arrays;
    a one-line SimError when the shapes, the classes or the numbers are off or a centre lies outside
    the drum."""
    pos = np.asarray(pos_m, dtype=np.float64)
    k = np.asarray(classes)
    ang = np.asarray(angle_rad, dtype=np.float64)
    n = k.size
    if pos.shape != (n, 2) or ang.shape != (n,) or k.ndim != 1:
        raise SimError(f"a placement needs (n, 2) centres, n classes and n angles (got {pos.shape}, "
                       f"{k.shape}, {ang.shape})")
    if n == 0:
        raise SimError("a placement needs at least one particle")
    if not (np.issubdtype(k.dtype, np.integer) and 0 <= int(k.min()) and int(k.max()) < n_classes):
        raise SimError(f"placement classes must be indices 0..{n_classes - 1} of the mixer's classes")
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(ang))):
        raise SimError("placement centres and angles must be finite")
    if float(np.hypot(pos[:, 0], pos[:, 1]).max()) >= drum.radius_m:
        raise SimError(f"a placed particle lies outside the {drum.diameter_m * 1e3:g} mm drum")
    return pos, k.astype(np.int64), ang


__all__ = ["CELLS_PER_DISC", "GAP_R", "MAX_TRIES", "SHRINK", "DiscGrid", "check_placement", "disc_arrays",
           "place_random"]

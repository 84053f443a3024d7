"""The pymunk twin's drum: the wall is a ring of ``WALL_SEGMENTS`` static segments whose inner
surface is the circle of radius ``R`` (to ``R * (1 - cos(pi/N)) / cos``, 0.02 mm on a 250 mm drum),
its surface moving at the drum's ``w x p`` (Chipmunk's ``surface_velocity``: a round wall turning
about its centre is the same surface; a static one is not re-indexed by the broad phase every step);
baffles are boxes on one KINEMATIC body turning about the axis, from the wall inwards.
Units: m, rad, drum frame (origin at the axis, y up).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from sim.mixer import Baffles

WALL_SEGMENTS = 180


def add_wall(space: pymunk.Space, radius_m: float, r_min_m: float) -> None:
    """The round wall on the space's static body: segments of radius ``r_min_m / 2`` whose inner
    surface is the drum's circle."""
    seg_r = 0.5 * r_min_m
    rv = (radius_m + seg_r) / math.cos(math.pi / WALL_SEGMENTS)
    a = 2 * math.pi * np.arange(WALL_SEGMENTS) / WALL_SEGMENTS
    pts = [(rv * math.cos(t), rv * math.sin(t)) for t in a]
    wall = space.static_body  # the round wall turns in place: static, its surface moving (``wall_tangents``)
    for i in range(WALL_SEGMENTS):
        space.add(pymunk.Segment(wall, pts[i], pts[(i + 1) % WALL_SEGMENTS], seg_r))


def wall_tangents(wall: tuple[pymunk.Shape, ...], radius_m: float) -> tuple[tuple[float, float], ...]:
    """Each wall segment's tangential speed per rad/s of the drum (m/rad): ``w x p`` at its midpoint,
    on the contact surface (radius ``radius_m``)."""
    tang = []
    for seg in wall:
        assert isinstance(seg, pymunk.Segment)
        mx, my = 0.5 * (seg.a.x + seg.b.x), 0.5 * (seg.a.y + seg.b.y)
        k = radius_m / math.hypot(mx, my)  # the contact surface: radius R
        tang.append((-my * k, mx * k))
    return tuple(tang)


def baffle_polygons_m(baffles: Baffles | None, radius_m: float, r_min_m: float,
                      drum_angle_rad: float) -> list[np.ndarray]:
    """The baffles as (4, 2) polygons (m, drum frame) at the drum's angle (rad); they reach half the
    smallest radius into the wall."""
    bf = baffles
    if bf is None or bf.count <= 0:
        return []
    R = radius_m
    r_out = R + 0.5 * r_min_m
    box = np.array([[R - bf.height_m, -0.5 * bf.thickness_m], [r_out, -0.5 * bf.thickness_m],
                    [r_out, 0.5 * bf.thickness_m], [R - bf.height_m, 0.5 * bf.thickness_m]])
    out = []
    for j in range(bf.count):
        t = drum_angle_rad - 0.5 * math.pi + 2 * math.pi * j / bf.count
        c, s = math.cos(t), math.sin(t)
        out.append(box @ np.array([[c, s], [-s, c]]))
    return out


def contact_impulse_moment(space: pymunk.Space, drum: pymunk.Body) -> float:
    """Moment about the axis (N m s, counter-clockwise +) of the last step's contact impulses on the
    drum: its body's (baffles) and the wall's (``Body.each_arbiter``, ``Arbiter.total_impulse`` at the
    mean of its contact points)."""
    tq = [0.0]

    def one(arb: pymunk.Arbiter) -> None:
        pts = arb.contact_point_set.points
        if not pts:
            return
        x = sum(p.point_a.x + p.point_b.x for p in pts) / (2 * len(pts))
        y = sum(p.point_a.y + p.point_b.y for p in pts) / (2 * len(pts))
        j = arb.total_impulse  # each_arbiter turns the arbiter to the drum's side: the impulse on the drum
        tq[0] += x * j.y - y * j.x

    drum.each_arbiter(one)
    space.static_body.each_arbiter(one)
    return tq[0]


__all__ = ["WALL_SEGMENTS", "add_wall", "baffle_polygons_m", "contact_impulse_moment", "wall_tangents"]

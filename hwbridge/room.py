"""The stand-in robot's room: wall segments its disk body cannot cross (pure, no I/O).

A physical robot that drives into a wall stops there (and slides along it); a stand-in
robot without walls would drive on through, leave the map, and then be held by the
bridge's geofence while its twin stays at the wall. :class:`Room` gives the stand-in the
same walls as the world's map: after every motion step the body's centre is pushed back
out of any wall closer than the body radius, along the wall's normal (frictionless
contact, as in world/physics.py). World frame, metres.

Contacts are side-agnostic: a body that starts outside the map stays outside.
"""
from __future__ import annotations

import math

import numpy as np

from swarmcover.ground.geometry import rings_to_segments

PUSH_ITERATIONS = 4      # corners need more than one push


class Room:
    """Wall segments (E, 4) and the body radius (m)."""

    def __init__(self, walls, radius: float):
        self.walls = np.asarray(walls, float).reshape(-1, 4)
        if not (math.isfinite(radius) and radius > 0):
            raise ValueError(f"robot radius: must be a finite number > 0, got {radius!r}")
        if not np.isfinite(self.walls).all():
            raise ValueError("room walls: coordinates must be finite")
        self.radius = float(radius)
        a = self.walls[:, 0:2]
        d = self.walls[:, 2:4] - a
        self._a, self._d = a, d
        self._L2 = np.maximum((d * d).sum(1), 1e-18)

    @classmethod
    def from_polygons(cls, boundary, obstacles=(), radius: float = 0.06) -> "Room":
        """A room from the map's outer polygon and obstacle polygons (world frame)."""
        rings = ([boundary] if boundary is not None and len(boundary) else []) + list(obstacles)
        return cls(rings_to_segments(rings), radius)

    def __len__(self) -> int:
        return len(self.walls)

    def nearest(self, x: float, y: float) -> tuple[float, float, float, int]:
        """(distance, closest x, closest y, wall index) of the nearest wall; inf if none."""
        if not len(self.walls):
            return math.inf, x, y, -1
        p = np.array([x, y])
        t = np.clip(((p - self._a) * self._d).sum(1) / self._L2, 0.0, 1.0)
        c = self._a + t[:, None] * self._d
        dist = np.hypot(c[:, 0] - x, c[:, 1] - y)
        k = int(np.argmin(dist))
        return float(dist[k]), float(c[k, 0]), float(c[k, 1]), k

    def collide(self, x: float, y: float, prev: tuple[float, float] | None = None
                ) -> tuple[float, float, bool]:
        """Push the centre (x, y) out of every wall closer than the radius.

        ``prev``: the centre before this motion step; a centre that crossed a wall line goes
        back to prev's side. Returns (x, y, touched).
        """
        touched = False
        r = self.radius
        for _ in range(PUSH_ITERATIONS):
            dist, cx, cy, k = self.nearest(x, y)
            if dist >= r - 1e-12:
                break
            touched = True
            if dist > 1e-12:
                nx, ny = (x - cx) / dist, (y - cy) / dist
            else:                               # on the wall line: its normal
                dx, dy = self._d[k]
                L = math.hypot(dx, dy)
                nx, ny = -dy / L, dx / L
            if prev is not None and (prev[0] - cx) * nx + (prev[1] - cy) * ny < 0:
                nx, ny = -nx, -ny               # crossed it: back to the side it came from
            x, y = cx + nx * r, cy + ny * r
        return x, y, touched

"""A tiny pure-Python kinematic simulator for the agent tests (and tests of it).

Robots are points with a body radius, holonomic or unicycle; walls are line segments that
the robots cannot penetrate (they are pushed back out, so motion along a wall survives).
It produces real :class:`bus.messages.Sense` messages: bearings of robots within rv (no
occlusion), the back bearings, and touch sectors quantised like the world's.
"""
from __future__ import annotations

import math
import random

from swarmcover.bus.messages import Sense

PI = math.pi


def wrap(a):
    return (a + PI) % (2 * PI) - PI


class KinSim:
    def __init__(self, robots, rv=1.0, dt=0.05, radius=0.06, walls=(), n_touch=8, noise_deg=0.0,
                 seed=0):
        """robots: {id: (x, y, theta)}; walls: [((x0, y0), (x1, y1)), ...]."""
        self.pose = {i: list(map(float, p)) for i, p in robots.items()}
        self.rv, self.dt, self.radius = rv, dt, radius
        self.walls = list(walls)
        self.n_touch = n_touch
        self.noise = math.radians(noise_deg)
        self.rng = random.Random(seed)
        self.tick = 0
        self.t = 0.0

    # -- sensing
    def _closest(self, x, y, seg):
        (x0, y0), (x1, y1) = seg
        dx, dy = x1 - x0, y1 - y0
        L2 = dx * dx + dy * dy
        s = 0.0 if L2 == 0 else max(0.0, min(1.0, ((x - x0) * dx + (y - y0) * dy) / L2))
        return x0 + s * dx, y0 + s * dy

    def touches(self, i):
        x, y, th = self.pose[i]
        out = []
        width = 2 * PI / self.n_touch
        for seg in self.walls:
            cx, cy = self._closest(x, y, seg)
            if math.hypot(cx - x, cy - y) <= self.radius + 1e-3:
                b = wrap(math.atan2(cy - y, cx - x) - th)
                k = round(b / width)
                centre = wrap(k * width)
                if centre not in out:
                    out.append(centre)
        return out

    def sense(self, i) -> Sense:
        x, y, th = self.pose[i]
        ids, bs, backs = [], [], []
        for j, (xj, yj, thj) in self.pose.items():
            if j == i:
                continue
            dx, dy = xj - x, yj - y
            if math.hypot(dx, dy) > self.rv:
                continue
            n1 = self.rng.gauss(0, self.noise) if self.noise else 0.0
            n2 = self.rng.gauss(0, self.noise) if self.noise else 0.0
            ids.append(j)
            bs.append(wrap(math.atan2(dy, dx) - th + n1))
            backs.append(wrap(math.atan2(-dy, -dx) - thj + n2))
        touch = self.touches(i)
        return Sense(robot=i, tick=self.tick, t=self.t, ids=ids, bearings=bs,
                     back_bearings=backs, touch=touch, touch_robot=[False] * len(touch))

    # -- motion
    def apply(self, i, cmd):
        x, y, th = self.pose[i]
        c, s = math.cos(th), math.sin(th)
        vx = c * cmd.vx - s * cmd.vy
        vy = s * cmd.vx + c * cmd.vy
        x += vx * self.dt
        y += vy * self.dt
        th = wrap(th + cmd.wz * self.dt)
        for seg in self.walls:  # push back out of walls
            cx, cy = self._closest(x, y, seg)
            d = math.hypot(x - cx, y - cy)
            if d < self.radius:
                if d < 1e-12:
                    continue
                f = self.radius / d
                x, y = cx + (x - cx) * f, cy + (y - cy) * f
        self.pose[i] = [x, y, th]

    def advance(self):
        self.tick += 1
        self.t = round(self.t + self.dt, 9)

    def dist(self, i, xy):
        x, y, _ = self.pose[i]
        return math.hypot(x - xy[0], y - xy[1])


def bearings_from(sim, at, landmarks, theta=0.0):
    """Desired bearings (frame with heading theta) from point ``at`` to the landmarks."""
    return [wrap(math.atan2(sim.pose[l][1] - at[1], sim.pose[l][0] - at[0]) - theta)
            for l in landmarks]


def run(beh, sim, rid, ticks, until=None):
    """Drive robot ``rid`` with behaviour ``beh`` for up to ``ticks`` ticks."""
    for _ in range(ticks):
        cmd = beh.step(sim.sense(rid))
        sim.apply(rid, cmd)
        sim.advance()
        if until is not None and until():
            return True
    return False


# ------------------------------------------------------------------ tests of the sim itself

def test_sim_bearings_and_back_bearings():
    sim = KinSim({1: (0, 0, 0.3), 2: (1, 0, -0.2)}, rv=2)
    s = sim.sense(1)
    assert s.ids == [2]
    assert abs(s.bearings[0] - wrap(0 - 0.3)) < 1e-12
    assert abs(s.back_bearings[0] - wrap(PI + 0.2)) < 1e-12


def test_sim_wall_blocks_and_touch_points_at_it():
    sim = KinSim({1: (0, 0.3, 0)}, walls=[((-5, 0.5), (5, 0.5))])

    class C:
        vx, vy, wz = 0.0, 1.0, 0.0
    for _ in range(20):
        sim.apply(1, C)
    assert abs(sim.pose[1][1] - (0.5 - sim.radius)) < 1e-9
    assert sim.touches(1) == [wrap(PI / 2)]

"""Emulated omnidirectional bearing cameras and touch sensors, vectorised over the swarm.

Pure: positions/headings (world frame, m / rad) and the map's wall grid in, per-robot
arrays out. No per-robot loops over other robots:
  * candidates within rv come from a cKDTree (``query_pairs``);
  * line of sight is tested against the wall segments listed by a :class:`SegmentGrid`
    cell (cell rv/2, grown by rv/2: a sight line <= rv whose midpoint is in a cell can only
    cross that cell's walls), all (pair, wall) tests in one numpy expression;
  * optionally robots occlude too (a third robot's disk meets the sight line).

Bearings are body-frame, CCW positive, wrapped to [-pi, pi). Directed sighting a->b carries
a's (noisy) bearing of b and ``back``: b's noisy bearing of a (what b would tell a).
Touch sector k is centred on body bearing 2*pi*k/N_T and spans +-pi/N_T; it fires when a
wall or robot surface is within ``skin`` of the body; ``touch_robot`` says whether a robot
touches it there (the other robot feels the contact too and tells it, as neighbours tell
each other their bearings: ``back``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import chain

import numpy as np
from scipy.spatial import cKDTree

from swarmcover.ground.angles import wrap_array

from .maps import SegmentGrid, WorldMap, segments_intersect

TWO_PI = 2.0 * math.pi


def sector_of(bearing, n: int) -> np.ndarray:
    """Touch sector index of body bearings: sector k is centred on 2*pi*k/n."""
    w = TWO_PI / n
    return (np.floor((np.asarray(bearing, float) % TWO_PI + w / 2) / w).astype(np.int64)) % n


def sector_centres(n: int) -> np.ndarray:
    return wrap_array(np.arange(n) * (TWO_PI / n))


def visible_pairs(pos: np.ndarray, grid: SegmentGrid | None, rv: float, *,
                  radius: float = 0.0, robots_occlude: bool = False,
                  tree: cKDTree | None = None) -> np.ndarray:
    """Pairs (P, 2) with i < j, sorted, within rv of each other with a clear line of sight."""
    n = len(pos)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    tree = tree if tree is not None else cKDTree(pos)
    pairs = tree.query_pairs(rv, output_type="ndarray").astype(np.int64)
    if len(pairs) == 0:
        return pairs.reshape(0, 2)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    a, b = pos[pairs[:, 0]], pos[pairs[:, 1]]
    keep = np.ones(len(pairs), bool)
    if grid is not None and len(grid.walls):
        q, w = grid.candidates(0.5 * (a + b))
        if len(q):
            wl = grid.walls[w]
            hit = segments_intersect(a[q], b[q], wl[:, 0:2], wl[:, 2:4])
            keep[q[hit]] = False
    if robots_occlude and radius > 0 and keep.any():
        keep &= ~_robot_blocked(pos, tree, pairs, radius)
    return pairs[keep]


def _robot_blocked(pos, tree, pairs, radius) -> np.ndarray:
    """For each pair, does a third robot's disk (radius) meet the open sight segment?"""
    a, b = pos[pairs[:, 0]], pos[pairs[:, 1]]
    mid = 0.5 * (a + b)
    half = 0.5 * np.hypot(*(b - a).T)
    res = tree.query_ball_point(mid, half + radius)
    lens = np.fromiter((len(r) for r in res), np.int64, len(res))
    k = np.fromiter(chain.from_iterable(res), np.int64, int(lens.sum()))
    p = np.repeat(np.arange(len(pairs)), lens)
    other = (k != pairs[p, 0]) & (k != pairs[p, 1])
    p, k = p[other], k[other]
    pa, pb, c = a[p], b[p], pos[k]
    d = pb - pa
    dd = np.maximum((d * d).sum(1), 1e-300)
    t = np.clip(((c - pa) * d).sum(1) / dd, 0.0, 1.0)
    dist = np.hypot(*(pa + t[:, None] * d - c).T)
    blocked = np.zeros(len(pairs), bool)
    blocked[p[dist < radius]] = True
    return blocked


@dataclass
class SenseBatch:
    """One tick of sensing for n robots (indices into the position array).

    Camera: directed sightings sorted by (obs, tgt); ``cam_off[k]:cam_off[k+1]`` are robot
    k's. Touch: (robot, sector) sorted; ``touch_off`` likewise.
    """
    n: int
    obs: np.ndarray
    tgt: np.ndarray
    bearing: np.ndarray
    back: np.ndarray
    cam_off: np.ndarray
    touch_robot: np.ndarray   # robot index per touch
    touch_sector: np.ndarray
    touch_bearing: np.ndarray
    touch_is_robot: np.ndarray
    touch_off: np.ndarray
    pairs: np.ndarray         # true visible pairs (i < j), before dropout

    def robot(self, k: int) -> dict:
        """Robot k's lists: tgt (indices), bearings, back, touch (bearings), touch_robot."""
        a, b = self.cam_off[k], self.cam_off[k + 1]
        c, d = self.touch_off[k], self.touch_off[k + 1]
        return dict(tgt=self.tgt[a:b], bearings=self.bearing[a:b], back=self.back[a:b],
                    touch=self.touch_bearing[c:d], touch_robot=self.touch_is_robot[c:d])

    def lists(self, ids, rows=None) -> list[dict]:
        """Robots' Sense fields as plain Python lists, for robot k of ``ids`` for each k in
        ``rows`` (default: every robot, in order): ids (the seen robots' ids), bearings,
        back_bearings (rad), touch (rad), touch_robot. One ``tolist`` per array, then
        slices: what the world encodes."""
        tgt = np.asarray(ids, np.int64)[self.tgt].tolist()
        brg, back = self.bearing.tolist(), self.back.tolist()
        tb, tr = self.touch_bearing.tolist(), self.touch_is_robot.tolist()
        co, to = self.cam_off.tolist(), self.touch_off.tolist()
        rows = range(len(ids)) if rows is None else rows
        return [dict(ids=tgt[co[k]:co[k + 1]], bearings=brg[co[k]:co[k + 1]],
                     back_bearings=back[co[k]:co[k + 1]], touch=tb[to[k]:to[k + 1]],
                     touch_robot=tr[to[k]:to[k + 1]]) for k in rows]


class Sensors:
    """Camera + touch for one map and sensing config; holds the noise generator.

    ``rng`` must be the run's seeded numpy Generator: draws happen in a fixed order (pairs
    sorted by index), so equal inputs give equal outputs.
    """

    def __init__(self, wm: WorldMap, rv: float, *, radius: float, noise_sigma: float = 0.0,
                 dropout: float = 0.0, robots_occlude: bool = False, n_touch: int = 8,
                 skin: float = 0.015, rng: np.random.Generator | None = None):
        self.rv = float(rv)
        self.radius = float(radius)
        self.sigma = float(noise_sigma)
        self.dropout = float(dropout)
        self.occlude = bool(robots_occlude)
        self.n_touch = int(n_touch)
        self.skin = float(skin)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        margin = max(self.rv / 2, self.radius + self.skin) * (1 + 1e-9) + 1e-9
        self.grid = wm.segment_grid(self.rv / 2, margin)
        self._centres = sector_centres(self.n_touch)

    def sense(self, pos: np.ndarray, heading: np.ndarray) -> SenseBatch:
        pos = np.ascontiguousarray(pos, float).reshape(-1, 2)
        heading = np.asarray(heading, float).reshape(-1)
        n = len(pos)
        tree = cKDTree(pos) if n else None
        pairs = visible_pairs(pos, self.grid, self.rv, radius=self.radius,
                              robots_occlude=self.occlude, tree=tree) if n >= 2 else \
            np.zeros((0, 2), np.int64)
        i, j = pairs[:, 0], pairs[:, 1]
        d = pos[j] - pos[i]
        ang = np.arctan2(d[:, 1], d[:, 0])
        obs = np.concatenate([i, j])
        tgt = np.concatenate([j, i])
        true = wrap_array(np.concatenate([ang - heading[i], ang + math.pi - heading[j]]))
        m = len(obs)
        noisy = true
        if self.sigma > 0 and m:
            noisy = wrap_array(true + self.rng.normal(0.0, self.sigma, m))
        half = m // 2
        back = np.concatenate([noisy[half:], noisy[:half]])
        keep = None
        if self.dropout > 0 and m:
            keep = self.rng.random(m) >= self.dropout
        if keep is not None:
            obs, tgt, noisy, back = obs[keep], tgt[keep], noisy[keep], back[keep]
        order = np.lexsort((tgt, obs))
        obs, tgt, noisy, back = obs[order], tgt[order], noisy[order], back[order]
        cam_off = np.searchsorted(obs, np.arange(n + 1))
        tr, ts, is_robot = self._touch(pos, heading, tree)
        touch_off = np.searchsorted(tr, np.arange(n + 1))
        return SenseBatch(n, obs, tgt, noisy, back, cam_off, tr, ts, self._centres[ts],
                          is_robot, touch_off, pairs)

    def _touch(self, pos, heading, tree):
        """(robot index, sector, touched by a robot) of every active touch sector, unique,
        sorted by (robot, sector). A sector touched by a robot (the other robot feels the
        contact too and says so) is a robot's, whatever wall it also touches."""
        n = len(pos)
        none = np.zeros(0, np.int64)
        if n == 0:
            return none, none, np.zeros(0, bool)
        reach = self.radius + self.skin
        rob, dirs = [], []
        g = self.grid
        if len(g.walls):
            q, w = g.candidates(pos)
            if len(q):
                wl = g.walls[w]
                p = pos[q]
                a = wl[:, 0:2]
                d = wl[:, 2:4] - a
                dd = np.maximum((d * d).sum(1), 1e-300)
                t = np.clip(((p - a) * d).sum(1) / dd, 0.0, 1.0)
                c = a + t[:, None] * d
                v = c - p
                dist = np.hypot(v[:, 0], v[:, 1])
                hit = dist < reach
                rob.append(q[hit])
                dirs.append(np.arctan2(v[hit, 1], v[hit, 0]) - heading[q[hit]])
        n_wall = sum(len(x) for x in rob)
        if n >= 2:
            pr = tree.query_pairs(2 * self.radius + self.skin, output_type="ndarray")
            if len(pr):
                i, j = pr[:, 0].astype(np.int64), pr[:, 1].astype(np.int64)
                v = pos[j] - pos[i]
                ang = np.arctan2(v[:, 1], v[:, 0])
                rob += [i, j]
                dirs += [ang - heading[i], ang + math.pi - heading[j]]
        if not rob:
            return none, none, np.zeros(0, bool)
        r = np.concatenate(rob)
        s = sector_of(np.concatenate(dirs), self.n_touch)
        keys = r * self.n_touch + s
        key = np.unique(keys)
        return key // self.n_touch, key % self.n_touch, np.isin(key, keys[n_wall:])

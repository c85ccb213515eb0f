"""Does "certified" mean covered? Random maps grown to the end by the real fence rules,
judged by an independent oracle (bench/oracle.py).

Each map (seeded) is a rectangle, an L-shape, a room with boxes, a cluttered room, or two
rooms joined by a door 0.3-1.2 rv wide; a third of the sources stand 0.3 m from a wall,
facing it. rv = 1 m, robot radius 0.06 m, 0.5 deg Gaussian bearing noise on half the maps.
With ``--raster M`` every map is turned 5-40 deg and drawn on a grid of M m (walls in
steps, as a ROS map draws them: :func:`raster_map`), the same maps otherwise.

The growth loop uses the system's real topology core on emulated measurements: the
complex from the bearings of true positions (``coordinator.build_complex``; who sees whom
is the oracle's rule, distance <= rv and a clear line of sight), the fence
(``coordinator.detect_fence``), the pushes (``coordinator.plan_pushes``, up to 8 a cycle as the deployer's max_paths,
from the source), and each deployment executed geometrically: the robot drives d0 = 0.9 rv
along the deployment bearing; if its disk (radius r) touches a wall within the deployer's
``[coordinator] wall_keep_rv`` of the start it is a failed test drive (fed back to the
fence), a touch farther out
leaves it at the wall as a new robot (touch flag and contact bearing), a clear drive places
a new robot at d0. A probe (kind "probe", when the fence offers it) first moves
``via_frac`` along its edge toward the other end, then drives ``depth_rv`` rv along its
bearing, with the same outcomes (coordinator.topology.fence's Deployment docstring). A wall
sweep (a probe with ``sweep_far``, the default rule for candidate sides) drives its bearing;
a touch starts the sweep of bench/sweep.py (the agent's rule, on true positions), which
comes home with the part of the edge it joined ("swept") or leaves a new robot where it
went round a wall's end ("opening") or its wall receded ("room"). Drive outcomes
go back to the fence through ``coordinator.topology.evidence`` when the project has it (else as
``test_drive_failures``). The loop runs until the fence has no deployment left, or a robot
cap; with no frontier edge either that is a fixed point. The claim is then the deployer's
own finish rule, ``coordinator.planner.plan_cycle`` on the same reports: complete =
certified (``coordinator.certify``, and whatever the planner adds) with no frontier and no
deployment (frontier edges with no deployment left are "stuck": the deployer stops
uncertified).

The oracle judges the end state:

* false certificate: complete while uncovered free area that a robot's
  body can reach from the source lies farther than 0.5 rv from every wall (components
  above 0.01 m^2 on a 2 cm raster);
* refusal: a fixed point the oracle finds covered (no such area) not called complete;
* complex: the system's edges and triangles against the oracle's Rips complex;
* algebra: the certificate's chain has boundary z, and z is (or is not) a boundary by the
  oracle's own GF(2) elimination, as certify says.

Usage: python bench/truth.py [--maps 500] [--seed 0] [--jobs 1] [--raster 0.05] [--out FILE.json]
(with --out, each map's result also goes to FILE.json.partial.jsonl as it comes, and a
rerun resumes from it)
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.oracle import PolyMap, Raster, chain_boundary, in_boundary_span, judge, rips  # noqa: E402

RV = 1.0
RADIUS = 0.06
D0 = 0.9 * RV
N_TOUCH = 8          # touch sectors, centred on body bearings 2 pi k / N_TOUCH (the world's)
NOISE_DEG = 0.5
KINDS = ("rect", "L", "boxes", "clutter", "two_rooms")
KIND_P = (0.14, 0.14, 0.14, 0.14, 0.44)
BUCKETS = ("0.30", "0.45", "0.60", "0.75", "0.85", ">=0.95")
_BUCKET_W = (0.30, 0.45, 0.60, 0.75, 0.85)
DOOR_EDGE_RV = (0.40, 0.50)   # --doors: widths at the guarantee's edge (door_min_rv = 0.4)


def door_bucket(w: float | None) -> str | None:
    """Door-width bucket (w in rv): [.3,.4) .30, [.4,.525) .45, [.525,.675) .60,
    [.675,.8) .75, [.8,.95) .85, else >= .95."""
    if w is None:
        return None
    for edge, name in ((0.4, "0.30"), (0.525, "0.45"), (0.675, "0.60"), (0.8, "0.75"), (0.95, "0.85")):
        if w < edge:
            return name
    return ">=0.95"


# ---------------------------------------------------------------------------- maps
@dataclass
class MapCase:
    kind: str
    pm: PolyMap
    source: tuple[float, float]
    source_dir: float          # world direction the base faces (rad)
    facing_wall: bool
    door_w: float | None = None
    noise_deg: float = 0.0
    index: int = 0
    seed: int = 0


def _cross2(a, b) -> float:
    """z of the cross product of two 2-vectors."""
    return float(a[0] * b[1] - a[1] * b[0])


def _rect(x0, y0, x1, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


def _place_rects(rng, W, H, n, lo, hi, gap, keep_out, tries=400):
    """Up to n axis-aligned rectangles inside (0,0)-(W,H), sides in [lo, hi], at least
    ``gap`` from each other and from the walls, none within ``keep_out`` (point, dist)."""
    out = []
    for _ in range(tries):
        if len(out) >= n:
            break
        w, h = rng.uniform(lo, hi, 2)
        x = rng.uniform(gap, W - gap - w)
        y = rng.uniform(gap, H - gap - h)
        r = (x, y, x + w, y + h)
        if any(not (r[2] + gap <= o[0] or o[2] + gap <= r[0] or r[3] + gap <= o[1] or o[3] + gap <= r[1])
               for o in out):
            continue
        if keep_out is not None:
            px, py = keep_out[0]
            dx = max(r[0] - px, 0, px - r[2])
            dy = max(r[1] - py, 0, py - r[3])
            if math.hypot(dx, dy) < keep_out[1]:
                continue
        out.append(r)
    return [_rect(*r) for r in out]


def make_map(seed: int, index: int, raster: float = 0.0, doors: bool = False) -> MapCase:
    """The ``index``-th random map of campaign ``seed``; with ``raster`` > 0 (m) the same
    map turned by 5-40 deg about its centre (its own random stream) and drawn on a grid of
    that cell (:func:`raster_map`): oblique walls in steps, as a ROS map draws them.

    ``doors``: every map is two rooms joined by one door at the guarantee's edge, drawn
    from a stream of its own (the rest of the map, source and noise as without it): width
    ``DOOR_EDGE_RV`` (0.40-0.50 rv, door_min_rv and just above), a dividing wall
    0.05-0.30 m thick (a thick one makes the door a short passage), and one door in four
    flush with the outer wall (the jamb a corner)."""
    rng = np.random.default_rng([int(seed), int(index)])
    kind = KINDS[int(rng.choice(len(KINDS), p=KIND_P))]
    if doors:
        kind = "two_rooms"
    facing = bool(rng.random() < 1.0 / 3.0)
    noise = NOISE_DEG if (index % 2 == 1) else 0.0
    door_w = None
    room_a = None          # (x0, y0, x1, y1) where the source goes
    holes: list[np.ndarray] = []
    if kind == "rect":
        W, H = rng.uniform(2.5, 7.0), rng.uniform(2.0, 5.0)
        outer = _rect(0, 0, W, H)
    elif kind == "L":
        W, H = rng.uniform(3.5, 7.0), rng.uniform(3.0, 5.5)
        a, b = rng.uniform(0.35, 0.6) * W, rng.uniform(0.35, 0.6) * H
        outer = np.array([[0, 0], [W, 0], [W, H - b], [W - a, H - b], [W - a, H], [0, H]], float)
        # rotate the L by a multiple of 90 deg about the centre (which corner is cut)
        k = int(rng.integers(4))
        c = np.array([W / 2, H / 2])
        R = np.array([[0, -1], [1, 0]], float)
        for _ in range(k):
            outer = (outer - c) @ R.T + c
        outer -= outer.min(axis=0)
    elif kind in ("boxes", "clutter"):
        W, H = (rng.uniform(4.0, 7.0), rng.uniform(3.0, 5.0)) if kind == "boxes" else \
            (rng.uniform(3.0, 6.0), rng.uniform(3.0, 5.0))
        outer = _rect(0, 0, W, H)
    else:  # two rooms: a wall 0.1 m thick across the room, a door of width door_w in it
        W, H = rng.uniform(5.0, 8.0), rng.uniform(2.5, 4.5)
        b = int(rng.integers(len(BUCKETS)))
        door_w = (max(0.3, _BUCKET_W[b] + rng.uniform(-0.03, 0.03)) if b < 5
                  else rng.uniform(0.95, 1.2)) * RV
        xw = rng.uniform(0.4, 0.6) * W
        t = 0.1
        yc = rng.uniform(0.1 + door_w / 2, H - 0.1 - door_w / 2)
        if doors:
            rd = np.random.default_rng([int(seed), int(index), 11])
            door_w = rd.uniform(*DOOR_EDGE_RV) * RV
            t = rd.uniform(0.05, 0.30)
            flush = rd.random() < 0.25
            yc = ((door_w / 2 if rd.random() < 0.5 else H - door_w / 2) if flush
                  else rd.uniform(0.1 + door_w / 2, H - 0.1 - door_w / 2))
        y0, y1 = yc - door_w / 2, yc + door_w / 2
        ring = [[0, 0], [xw, 0], [xw, y0], [xw + t, y0], [xw + t, 0], [W, 0], [W, H],
                [xw + t, H], [xw + t, y1], [xw, y1], [xw, H], [0, H]]
        # a flush door: the divider's stub on that side is gone, no zero-length walls
        keep = [q for k, q in enumerate(ring) if not np.allclose(q, ring[k - 1])]
        keep = [q for k, q in enumerate(keep)
                if abs(_cross2(np.subtract(q, keep[k - 1]), np.subtract(keep[(k + 1) % len(keep)], q))) > 1e-12]
        outer = np.array(keep, float)
        room_a = (0.0, 0.0, xw, H)
    pm = PolyMap(outer)
    lo, hi = pm.outer.min(axis=0), pm.outer.max(axis=0)
    if room_a is None:
        room_a = (lo[0], lo[1], hi[0], hi[1])
    # the source
    src, sdir = None, 0.0
    for _ in range(500):
        if facing:
            # 0.3 m from a wall of room A's bounding box that is a real wall there, facing it
            side = int(rng.integers(4))
            x0, y0, x1, y1 = room_a
            if side == 0:
                p, d = (rng.uniform(x0 + 0.4, x1 - 0.4), y0 + 0.3), -math.pi / 2
            elif side == 1:
                p, d = (rng.uniform(x0 + 0.4, x1 - 0.4), y1 - 0.3), math.pi / 2
            elif side == 2:
                p, d = (x0 + 0.3, rng.uniform(y0 + 0.4, y1 - 0.4)), math.pi
            else:
                p, d = (x1 - 0.3, rng.uniform(y0 + 0.4, y1 - 0.4)), 0.0
            if not pm.contains(np.array([p]))[0] or abs(pm.wall_distance(np.array([p]))[0] - 0.3) > 1e-6:
                continue
        else:
            x0, y0, x1, y1 = room_a
            p = (rng.uniform(x0 + 0.3, x1 - 0.3), rng.uniform(y0 + 0.3, y1 - 0.3))
            d = rng.uniform(-math.pi, math.pi)
            if not pm.contains(np.array([p]))[0] or pm.wall_distance(np.array([p]))[0] < 0.3:
                continue
        src, sdir = p, d
        break
    if src is None:  # pragma: no cover - every kind has room for a source
        raise RuntimeError(f"map {index}: no source found")
    if kind == "boxes":
        W, H = hi - lo
        holes = _place_rects(rng, W, H, int(rng.integers(1, 5)), 0.3, 1.2, 0.05, (src, 0.4))
    elif kind == "clutter":
        W, H = hi - lo
        holes = _place_rects(rng, W, H, int(rng.integers(6, 15)), 0.1, 0.3, 0.1, (src, 0.4))
    pm = PolyMap(pm.outer, holes)
    if facing and abs(pm.wall_distance(np.array([src]))[0] - 0.3) > 1e-6:  # pragma: no cover
        raise RuntimeError(f"map {index}: source not 0.3 m from a wall")
    if raster > 0.0:
        th = math.radians(np.random.default_rng([int(seed), int(index), 7]).uniform(5.0, 40.0))
        R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
        c = pm.outer.mean(axis=0)
        turn = lambda q: (np.asarray(q, float) - c) @ R.T + c  # noqa: E731
        src = tuple(turn(src))
        sdir = _wrap(sdir + th)
        pm = raster_map(PolyMap(turn(pm.outer), [turn(h) for h in pm.holes]), raster, src)
    return MapCase(kind, pm, (float(src[0]), float(src[1])), float(sdir), facing, door_w, noise,
                   index, seed)


def raster_map(pm: PolyMap, cell: float, source) -> PolyMap:
    """``pm`` as a ROS map would draw it: a grid of ``cell`` m whose cells are free when
    their centre is (the free region holding ``source``, 4-connected), traced back into
    axis-aligned polygons along the cells' sides (walls in steps of ``cell``, like
    configs/cave.toml's). Two free cells that meet only at a corner get one of the other
    two cells freed, so every ring is simple. The largest ring is the boundary."""
    lo = pm.outer.min(axis=0) - 2 * cell
    nx, ny = (np.ceil((pm.outer.max(axis=0) + 2 * cell - lo) / cell)).astype(int)
    xs, ys = lo[0] + (np.arange(nx) + 0.5) * cell, lo[1] + (np.arange(ny) + 0.5) * cell
    gx, gy = np.meshgrid(xs, ys)
    free = _join_corners(pm.contains(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(ny, nx))
    lab, _ = ndimage.label(free)
    sj, si = int((source[1] - lo[1]) // cell), int((source[0] - lo[0]) // cell)
    free = lab == lab[sj, si]
    # directed cell sides with the free cell on the left, as (start vertex) -> end vertex
    nxt: dict[tuple[int, int], tuple[int, int]] = {}
    jj, ii = np.nonzero(free)
    for j, i in zip(jj.tolist(), ii.tolist()):
        if j == 0 or not free[j - 1, i]:
            nxt[(i, j)] = (i + 1, j)             # bottom side, going +x
        if i == nx - 1 or not free[j, i + 1]:
            nxt[(i + 1, j)] = (i + 1, j + 1)     # right side, going +y
        if j == ny - 1 or not free[j + 1, i]:
            nxt[(i + 1, j + 1)] = (i, j + 1)     # top side, going -x
        if i == 0 or not free[j, i - 1]:
            nxt[(i, j + 1)] = (i, j)             # left side, going -y
    rings = []
    while nxt:
        start = next(iter(nxt))
        loop, v = [start], nxt.pop(start)
        while v != start:
            loop.append(v)
            v = nxt.pop(v)
        pts = np.array(loop, float)
        u, w = np.roll(pts, -1, 0) - pts, pts - np.roll(pts, 1, 0)
        turn = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]) > 1e-9
        rings.append(lo + pts[turn] * cell)
    rings.sort(key=lambda r: -abs(_area(r)))
    return PolyMap(rings[0], rings[1:])


def _join_corners(free: np.ndarray) -> np.ndarray:
    """``free`` (a bool grid, rows y) with every two free cells that meet only at a corner
    joined by freeing one of the other two cells of their 2 x 2 block, so the traced rings
    are simple."""
    free = free.copy()
    for _ in range(100):
        a, b, c, d = free[:-1, :-1], free[:-1, 1:], free[1:, :-1], free[1:, 1:]
        p1, p2 = a & d & ~b & ~c, b & c & ~a & ~d
        if not (p1.any() or p2.any()):
            return free
        j, i = np.nonzero(p1)
        free[j, i + 1] = True
        j, i = np.nonzero(p2)
        free[j, i] = True
    raise RuntimeError("raster_map: corner-only contacts remain after 100 passes")  # pragma: no cover


def _area(r: np.ndarray) -> float:
    return 0.5 * float(np.dot(r[:, 0], np.roll(r[:, 1], -1)) - np.dot(r[:, 1], np.roll(r[:, 0], -1)))


# ---------------------------------------------------------------------------- swarm
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Swarm:
    """True positions, headings and contacts of the robots, and the line-of-sight
    visibility among them (the oracle's rule), with persistent bearing noise per pair."""

    def __init__(self, pm: PolyMap, rng, noise_deg: float, headings: str = "zero"):
        self.pm = pm
        self.segs = pm.walls()
        self.rng = rng
        self.noise = math.radians(noise_deg)
        self.headings_mode = headings
        self.pos: list[np.ndarray] = []
        self.heading: list[float] = []
        self.contact: list[float | None] = []   # world direction to the wall touched
        self.adj: list[dict[int, float]] = []    # j -> bearing (body frame, noisy)

    @property
    def n(self) -> int:
        return len(self.pos)

    def add(self, p, contact: float | None = None) -> int:
        from bench.oracle import segments_cross
        i = self.n
        p = np.asarray(p, float)
        h = 0.0 if self.headings_mode == "zero" else float(self.rng.uniform(-math.pi, math.pi))
        self.pos.append(p)
        self.heading.append(h)
        self.contact.append(contact)
        self.adj.append({})
        if i:
            P = np.array(self.pos[:i])
            d = np.linalg.norm(P - p, axis=1)
            near = np.nonzero(d <= RV)[0]
            if near.size:
                clear = ~segments_cross(np.broadcast_to(p, (near.size, 2)), P[near], self.segs)
                for j in near[clear].tolist():
                    self._link(i, j)
        return i

    def _link(self, i: int, j: int) -> None:
        dx, dy = self.pos[j] - self.pos[i]
        a = math.atan2(dy, dx)
        nz = self.rng.normal(0.0, self.noise, 2) if self.noise else (0.0, 0.0)
        self.adj[i][j] = _wrap(a - self.heading[i] + nz[0])
        self.adj[j][i] = _wrap(a + math.pi - self.heading[j] + nz[1])

    def body(self, i: int, world_dir: float) -> float:
        return _wrap(world_dir - self.heading[i])

    def world(self, i: int, body_dir: float) -> float:
        return _wrap(body_dir + self.heading[i])

    def reports(self) -> dict[int, dict]:
        out = {}
        for i in range(self.n):
            c = self.contact[i]
            tb = None
            if c is not None:
                nz = self.rng.normal(0.0, self.noise) if self.noise else 0.0
                tb = self.body(i, c + nz)
            out[i] = {"neighbours": dict(self.adj[i]), "touch": c is not None, "touch_bearing": tb}
        return out

    def points(self) -> np.ndarray:
        return np.array(self.pos)

    def sees(self, q: np.ndarray, k: int) -> bool:
        """Robot k is in view of a robot at ``q``: within rv, no wall across the sight line."""
        from bench.oracle import segments_cross
        return bool(np.linalg.norm(self.pos[k] - q) <= RV and not segments_cross(
            q[None, :], self.pos[k][None, :], self.segs)[0])

    def back_in_sight(self, q: np.ndarray, start: np.ndarray, keep, margin: float) -> np.ndarray:
        """Where an opening's robot stays (agents.sweep: it keeps one of its vertex's
        landmarks ``keep`` in view): at ``q`` if it sees one there, else backed from ``q``
        towards ``start`` (the way it came into the opening) until one is in view, and
        ``margin`` farther, at most to ``start`` (agents.openloop.OpenBack with stay)."""
        keep = [int(k) for k in keep]
        if not keep or any(self.sees(q, k) for k in keep):
            return q
        d = np.asarray(start, float) - q
        L = float(np.linalg.norm(d))
        for t in np.arange(0.005, L + 1e-9, 0.005):
            x = q + (t / L) * d
            if any(self.sees(x, k) for k in keep):
                return q + (min(t + margin, L) / L) * d
        return np.asarray(start, float).copy()

    # ------------------------------------------------------------------ motion
    def robot_at(self, q: np.ndarray) -> float | None:
        """World direction from ``q`` to a robot whose body a body at ``q`` would overlap
        (centres under 2 radii apart), or None. Drives ignore robots; one ending on a robot
        stopped on it in the world (a bump: the drive fails, nothing is placed)."""
        if not self.pos:
            return None
        d = np.asarray(self.pos) - q
        k = int(np.argmin(np.hypot(d[:, 0], d[:, 1])))
        if math.hypot(*d[k]) >= 2.0 * RADIUS:
            return None
        return math.atan2(d[k][1], d[k][0]) if math.hypot(*d[k]) > 1e-12 else 0.0

    def drive(self, p: np.ndarray, direction: float, dist: float):
        """Drive a disk of radius RADIUS from p along ``direction`` (world, rad) up to
        ``dist``. Returns (travelled, end point, contact world direction or None)."""
        u = np.array([math.cos(direction), math.sin(direction)])
        # samples every 5 mm, then bisection on the first touching interval
        ts = np.linspace(0.0, dist, max(2, int(dist / 0.005) + 1))
        from bench.oracle import _dist_to_segments
        dd = _dist_to_segments(p[None, :] + ts[:, None] * u[None, :], self.segs)
        hit = np.nonzero(dd < RADIUS)[0]
        if hit.size == 0:
            return dist, p + dist * u, None
        k = int(hit[0])
        if k == 0:
            return 0.0, p.copy(), self._contact_dir(p)
        lo, hi = ts[k - 1], ts[k]
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            if _dist_to_segments((p + mid * u)[None, :], self.segs)[0] < RADIUS + 5e-4:
                hi = mid
            else:
                lo = mid
        q = p + lo * u
        return float(lo), q, self._contact_dir(q)

    def _contact_dir(self, q: np.ndarray) -> float:
        a = self.segs[:, 0:2]
        d = self.segs[:, 2:4] - a
        L2 = np.maximum((d * d).sum(-1), 1e-18)
        t = np.clip(((q - a) * d).sum(-1) / L2, 0, 1)
        c = a + t[:, None] * d
        k = int(np.argmin(np.linalg.norm(c - q, axis=1)))
        v = c[k] - q
        return math.atan2(v[1], v[0])


# ------------------------------------------------------------------ deploy / feedback
@dataclass
class Outcome:
    """One executed deployment: ``result`` is 'clear' (new robot at the drive's end),
    'wall' (new robot resting at a wall past wall_keep), 'touch' (failed, nothing
    placed) or 'unreached' (a probe's approach leg touched). ``direction`` is the bearing
    driven in the deploying robot's body frame. ``contact_offset`` (touch only): the
    centre of the touch sector the contact fell in, minus the direction driven (rad), as
    the agent reports it (Status.touch_offset)."""

    vertex: int
    direction: float
    kind: str
    result: str
    travelled: float
    new_robot: int | None = None
    deployment: object = None
    contact_offset: float = 0.0
    swept: tuple[float, float] | None = None
    by: tuple = ()      # a sweep's stoppers: robot indices (bench.sweep.SweepResult.by)


def execute_sweep(sw: Swarm, dep, depth: float, d0: float | None = None,
                  keep_sight: bool = False) -> Outcome:
    """A wall sweep (``dep.sweep_far`` > 0; bench/sweep.py): the end's drive along
    ``dep.bearing`` up to ``depth`` (m); clear: a new robot there ('clear'); a touch: the
    sweep, which ends 'swept' (the robot home, ``swept`` = (hi, lo)), or with a new robot
    where it stopped: 'opening' (it drove into an opening) or 'room' (its wall receded
    beyond the depth limit)."""
    from bench.sweep import Sweeper
    from swarmcover.coordinator.topology.targets import star_shape
    from swarmcover.agents.openloop import SIGHT_MARGIN_RV
    from swarmcover.ground.geometry import lens_radii, lens_reach
    i = int(dep.vertex)
    a, b = dep.edge
    j = b if a == i else a
    p = sw.pos[i]
    d = float(dep.bearing)
    if np.linalg.norm(sw.pos[j] - p) < 1e-9:
        # the edge's ends stacked on one point (raster maps, seed 0 map 10): no edge to
        # sweep along, a touch that joins nothing (the agent's SweepGeom has no length)
        return Outcome(i, d, dep.kind, "touch", 0.0, None, dep)
    go, reach, lms = sw.world(i, d), depth, []
    # the agent's landmarks: the robots whose place in i's frame the bearings fix
    star = [int(k) for k in star_shape(dict(enumerate(sw.adj)), i, j)]
    if d0 is not None:
        # TopologyParams.sweep_lenses: the landmarks hold lenses too, and the first drive
        # goes on while in them, at most d0 (coordinator.tasks)
        lms = [sw.pos[k] for k in star if k != j]
        lenses = lens_radii(tuple(sw.pos[j] - p), depth, [tuple(q - p) for q in lms])
        reach = max(depth, lens_reach(go, lenses, cap=d0))
    trav, end, cdir = sw.drive(p, go, reach)
    if cdir is None and sw.robot_at(end) is not None:
        return Outcome(i, d, dep.kind, "touch", trav, None, dep)   # a bump: no sweep
    if cdir is None:
        return Outcome(i, d, dep.kind, "clear", trav, sw.add(end), dep)
    others = np.array([q for k, q in enumerate(sw.pos) if k != i]).reshape(-1, 2)
    side = 1 if float(dep.offset) > 0 else -1
    sp = Sweeper(sw.segs, others, p, sw.pos[j], side, r=RADIUS, heading=sw.heading[i],
                 depth=depth, n_touch=N_TOUCH, rv=RV, landmarks=lms)
    res = sp.run(end, cdir, float(dep.sweep_far), float(dep.sweep_stop))
    if res.kind == "swept":
        idx = [k for k in range(len(sw.pos)) if k != i]     # others' rows -> robot indices
        return Outcome(i, d, dep.kind, "swept", trav + res.travelled, None, dep,
                       swept=(res.hi, res.lo), by=tuple(idx[k] for k in res.by))
    pos = res.pos
    if keep_sight and res.opening and res.entered is not None:
        pos = sw.back_in_sight(pos, res.entered, [j, *(k for k in star if k != j)],
                               SIGHT_MARGIN_RV * RV)
    c = sp.sectors(pos)
    return Outcome(i, d, dep.kind, "opening" if res.opening else "room",
                   trav + res.travelled, sw.add(pos, contact=c[0] if c else None), dep)


def execute(sw: Swarm, dep, sweep_depth: float, wall_keep: float,
            d0: float | None = None, keep_sight: bool = False) -> Outcome:
    """Carry out one fence deployment geometrically (see the module docstring): a sweep
    follows its wall up to ``sweep_depth`` (m) from the edge (with ``d0``, m, given:
    TopologyParams.sweep_lenses, the default, in the lenses at its vertex, its first drive
    up to d0 while in them); a touch nearer than ``wall_keep`` (m)
    fails, a farther one leaves the robot at the wall (TopologyParams.no_room_depth).
    ``keep_sight``: an opening's robot keeps one of its vertex's landmarks in view
    (:meth:`Swarm.back_in_sight`, as agents.sweep keeps it)."""
    i = int(dep.vertex)
    kind = getattr(dep, "kind", "edge")
    if float(getattr(dep, "sweep_far", 0.0) or 0.0) > 0.0:
        return execute_sweep(sw, dep, sweep_depth, d0, keep_sight)
    p = sw.pos[i]
    wdir = sw.world(i, float(dep.bearing))
    if kind == "probe":
        a, b = dep.edge
        q = sw.pos[b if a == i else a]
        start = p + float(dep.via_frac) * (q - p)
        depth = float(dep.depth_rv) * RV
        leg = float(np.linalg.norm(start - p))
        if leg > 1e-9:
            # the approach leg along the edge: the body may clip a jamb the sight line clears
            v = start - p
            t, _, c = sw.drive(p, math.atan2(v[1], v[0]), leg)
            if c is not None:
                return Outcome(i, float(dep.bearing), kind, "unreached", t, None, dep)
    else:
        start, depth = p, D0
    trav, end, cdir = sw.drive(start, wdir, depth)
    bump = sw.robot_at(end)
    if bump is not None:
        trav, cdir = 0.0, bump           # ends on a robot: fails as a touch, placing nobody
    if cdir is None:
        return Outcome(i, float(dep.bearing), kind, "clear", trav, sw.add(end), dep)
    if trav < wall_keep:
        # the robot feels the contact in a touch sector of its body: only the sector's
        # centre is known (within pi / N_TOUCH of the contact's direction)
        w = 2.0 * math.pi / N_TOUCH
        centre = round(sw.body(i, cdir) / w) * w
        return Outcome(i, float(dep.bearing), kind, "touch", trav, None, dep,
                       _wrap(centre - float(dep.bearing)))
    return Outcome(i, float(dep.bearing), kind, "wall", trav, sw.add(end, contact=cdir), dep)


class Feedback:
    """Drive outcomes -> detect_fence's keyword arguments. Uses ``coordinator.topology.evidence``
    when the project has it (its Evidence records every outcome), else the legacy
    ``test_drive_failures`` {vertex: [direction, ...]} of failed drives."""

    def __init__(self, door_min_rv: float | None = None, hold_rooms: bool = True):
        # hold_rooms: a probe's or sweep's room counts only while its robot stands beyond
        # the side, as coordinator.jobs.evidence_kwargs counts it (run_map's hold_rooms)
        self.hold_rooms = bool(hold_rooms)
        try:
            from swarmcover.coordinator.topology import evidence as ev  # noqa: F401
            from swarmcover.coordinator.config import CoordinatorConfig
            door = CoordinatorConfig().door_min_rv if door_min_rv is None else door_min_rv
            self._ev = ev.Evidence(door_min_rv=door, robot_radius_rv=RADIUS / RV)
        except Exception:
            self._ev = None
        self.failures: dict[int, list[float]] = {}

    @property
    def api(self) -> str:
        return "evidence" if self._ev is not None else "legacy"

    def record(self, o: Outcome) -> None:
        if self._ev is not None:
            if o.result == "unreached":
                self._ev.record_unreached(o.deployment)
            elif o.result == "swept":
                self._ev.record(o.deployment, touched=True, swept=o.swept, by=o.by)
            else:
                # a robot that stays (clear, wall, room, opening) holds the room it found
                # only while it stands beyond the side: booked as the deployer books it
                self._ev.record(o.deployment, touched=(o.result == "touch"),
                                contact_offset=o.contact_offset,
                                placed=(o.new_robot if self.hold_rooms and o.result != "touch"
                                        else None))
            return
        if o.result == "touch":
            self.failures.setdefault(o.vertex, []).append(o.direction)

    def room_key(self, dep):
        """The evidence key a probe's or a sweep's room is booked under (None: none)."""
        if self._ev is None or dep.edge is None:
            return None
        from swarmcover.coordinator.topology.evidence import probe_key
        return probe_key(int(dep.vertex), tuple(int(x) for x in dep.edge), int(dep.sigma),
                         float(getattr(dep, "via_frac", 0.0) or 0.0))

    def lost(self, reps: dict) -> frozenset:
        """The rooms whose robot stands beyond no side on ``reps`` (Evidence.lost_rooms)."""
        if self._ev is None or not self.hold_rooms:
            return frozenset()
        from swarmcover.coordinator.jobs import beyond_side
        return self._ev.lost_rooms(beyond_side(_snapshot(reps)))

    def kwargs(self, reps: dict | None = None) -> dict:
        """detect_fence's keyword arguments; with ``reps`` (the cycle's reports), less the
        rooms whose robot does not stand beyond their side, as coordinator.jobs'
        evidence_kwargs has them (no cut-off robot here: truth robots never move)."""
        if self._ev is not None:
            # a sweep a robot stopped: every truth robot is of the swarm (coordinator.jobs'
            # sweep_blocked; none is cut off and sent away here)
            blocked = frozenset(k for k, by in self._ev.sweep_stoppers().items() if by)
            if reps is None or not self.hold_rooms:
                return dict(self._ev.fence_kwargs(), sweep_blocked=blocked)
            from swarmcover.coordinator.jobs import beyond_side
            snap = _snapshot(reps)
            return dict(self._ev.fence_kwargs(snap.occupant, beyond_side(snap)),
                        sweep_blocked=blocked)
        return {"test_drive_failures": {k: list(v) for k, v in self.failures.items()}}


# ---------------------------------------------------------------------------- one map
def run_map(case: MapCase, *, per_cycle: int = 8, cap: int | None = None,
            headings: str = "zero", cell: float = 0.02, door_min_rv: float | None = None,
            topology: dict | None = None, wall_keep_rv: float | None = None,
            hold_rooms: bool = True) -> dict:
    """Grow one map to its end with the real fence rules and judge it. door_min_rv,
    wall_keep_rv and topology (TopologyParams fields) override the defaults, for
    experiments. ``hold_rooms``: rooms are booked as the deployer books them (a probe's or
    a sweep's room counts only while its robot stands beyond the side, and is offered again
    when it does not, no livelock then; an opening's robot keeps one of its vertex's
    landmarks in view, as agents.sweep keeps it). The default since 2026-12-03 (False, or
    ``--legacy-rooms``: a room counts once found, the rule before). Truth robots never
    move, so a room lost here stays lost, and its sweep may stack robots into the same
    opening: seed 0, 500 maps, with the edge's lens alone (``sweep_lenses=false``) 499
    certified, map 12 at its cap, 0 false, 49.6 robots on average (48.6 booked the old
    way; the product certified map 12 with 56 robots, bench/unseen.py); with the default
    sweep lenses 500 of 500, 0 false, 45.2 robots (booked the old way 1 false, map 429)."""
    import dataclasses

    from swarmcover.coordinator import build_complex, certify, detect_fence, plan_pushes, verify_certificate
    from swarmcover.coordinator.config import CoordinatorConfig

    P = dataclasses.replace(CoordinatorConfig().topology(), **(topology or {}))
    wall_keep = P.no_room_depth(CoordinatorConfig().wall_keep_rv if wall_keep_rv is None
                                else wall_keep_rv)
    rng = np.random.default_rng([case.seed, case.index, 7])
    sw = Swarm(case.pm, rng, case.noise_deg, headings)
    sw.add(np.array(case.source))
    fb = Feedback(door_min_rv, hold_rooms)
    ras = Raster(case.pm, cell)
    free_area = float(ras.free.sum() * ras.cell_area)
    cap = cap or int(4.0 * free_area / RV ** 2) + 30
    end, cycles, placed, repeats, livelock = "cycles", 0, Counter(), Counter(), []
    rooms: dict = {}    # a placing deployment's key -> its evidence key (probes, sweeps)
    t0 = time.process_time()
    for cycles in range(1, 6 * cap + 1):
        reps = sw.reports()         # one noisy sample per cycle, as the coordinator has
        cx = build_complex(reps)
        fence = detect_fence(cx, P, default_bearing=sw.body(0, case.source_dir), **fb.kwargs(reps))
        if not fence.deployments:
            # the deployer finishes only with no frontier edge either; frontier edges without
            # a deployment end the run uncertified ("no feasible push")
            end = "fixed" if fence.frontier.size == 0 else "stuck"
            break
        if sw.n >= cap:
            end = "cap"
            break
        lost = fb.lost(reps) if rooms else frozenset()
        paths = _pushes(cx, fence, P, per_cycle, plan_pushes)
        deps = [pp.deployment for pp in paths]
        if not deps:
            v = min(fence.deployments)
            deps = [fence.deployments[v][0]]
        for dep in deps:
            o = execute(sw, dep, P.sweep_depth, wall_keep, P.d0 if P.sweep_lenses else None,
                        keep_sight=hold_rooms)
            fb.record(o)
            placed[o.result] += 1
            if o.new_robot is not None:
                key = (dep.vertex, dep.kind, dep.edge, dep.sigma, round(float(getattr(dep, "via_frac", 0.0)), 3),
                       round(float(dep.bearing), 2))
                # a room whose robot stood beyond no side when this cycle began is offered
                # again by design (the deployer does so, coordinator.jobs.evidence_kwargs):
                # no repeat
                if rooms.get(key) is None or rooms[key] not in lost:
                    repeats[key] += 1
                if dep.kind == "probe":
                    rooms[key] = fb.room_key(dep)
        if repeats and max(repeats.values()) >= 3:
            # the same deployment placed a robot three times: the fence keeps offering it
            # although its robots arrived (they stack on one point), a livelock
            end = "livelock"
            livelock = [list(map(str, k)) for k, c in repeats.items() if c >= 3][:3]
            reps = sw.reports()
            cx = build_complex(reps)
            fence = detect_fence(cx, P, default_bearing=sw.body(0, case.source_dir), **fb.kwargs(reps))
            break
    cert = certify(cx, fence)
    # the claim from the same sample the last fence saw (a fresh noise sample gave another
    # complex: 3 of 491 covered end states "refused" that way)
    claim = _planner_claim(sw, case, P, fb, reps)
    grow_s = time.process_time() - t0
    pts = sw.points()
    ver = judge(ras, pts, case.source, RV, RADIUS, deep=0.5 * RV, min_area=0.01)
    ids = cx.ids
    sys_edges = {tuple(sorted(int(x) for x in ids[e])) for e in cx.edges}
    sys_tris = {tuple(sorted(int(x) for x in ids[t])) for t in cx.triangles}
    o_edges, o_tris = rips(pts, case.pm.walls(), RV)
    z_edges = [tuple(int(x) for x in ids[cx.edges[e]]) for e in np.asarray(cert.z, int)]
    fz_edges = [tuple(int(x) for x in ids[cx.edges[e]]) for e in np.asarray(fence.z, int)]
    own_z = in_boundary_span(o_tris, z_edges)
    own_fz = in_boundary_span(o_tris, fz_edges)
    chain_ok = (not cert.certified) or chain_boundary(cert.chain_nodes.tolist()) == {tuple(sorted(e)) for e in z_edges}
    fixed = end == "fixed"
    false_cert = bool(claim and not ver.fully_covered)
    refusal = bool(fixed and not claim and ver.fully_covered)
    hid = []
    if false_cert:
        reasons = {}
        for fe in fence.edges:
            for s in fe.sides:
                if s.kind == "obstacle":
                    reasons[(fe.u, fe.v)] = s.reason
        reg = ver.hole_region
        for (u, v), why in sorted(reasons.items()):
            a, b = pts[u], pts[v]
            d = b - a
            t = np.clip((reg - a) @ d / max(float(d @ d), 1e-12), 0, 1)
            gap = np.linalg.norm(a + t[:, None] * d - reg, axis=1)
            # robots see rv around them: an edge that hid the region is within about rv of it
            if gap.size and gap.min() <= 1.1 * RV:
                hid.append({"edge": [u, v], "reason": why, "length": round(float(np.linalg.norm(d)), 3),
                            "gap": round(float(gap.min()), 3)})
        hid.sort(key=lambda h: h["gap"])
    return {
        "index": case.index, "seed": case.seed, "kind": case.kind, "door_w": case.door_w,
        "bucket": door_bucket(case.door_w), "noise_deg": case.noise_deg,
        "facing_wall": case.facing_wall, "robots": sw.n, "cycles": cycles, "end": end,
        "drives": dict(placed), "certified": bool(claim), "certify": bool(cert.certified),
        "empty_target": bool(cert.certified and len(z_edges) == 0),
        "slack_closure": int(cert.stats.get("slack_closure", 0)) if cert.certified else 0,
        "verify_with_fence": bool(verify_certificate(cx, cert, fence)) if cert.certified else None,
        "coverage": round(ver.covered_fraction, 4), "free_area": round(ver.free_area, 3),
        "uncovered_reachable": round(ver.uncovered_reachable, 3),
        "hole_area": round(ver.hole_area, 3),
        "hole_depth": round(max((h[1] for h in ver.holes), default=0.0), 3),
        "holes": [[round(a, 3), round(d, 3), [round(c[0], 2), round(c[1], 2)]] for a, d, c in ver.holes[:5]],
        "false_certificate": false_cert, "refusal": refusal, "hid_by": hid[:8],
        "complex_ok": sys_edges == o_edges and sys_tris == o_tris,
        "algebra_ok": bool(chain_ok and own_z == bool(cert.certified)),
        "fence_z_boundary": bool(own_fz), "livelock": livelock, "api": fb.api, "grow_cpu_s": round(grow_s, 3),
        "inferred": dict(Counter(s.reason for fe in fence.edges for s in fe.sides if s.inferred)),
    }


def _pushes(cx, fence, P, k: int, plan_pushes) -> list:
    """Up to k pushes from the source (vertex 0) as coordinator.planner.plan_cycle picks
    them: vertex-disjoint paths, then further paths from the source (its new robots enter
    one after another) clear of the earlier paths and of their frontier vertices'
    neighbours."""
    chosen = list(plan_pushes(cx, fence, [0], params=P, max_paths=k))
    while len(chosen) < k:
        used: set[int] = set()
        for pp in chosen:
            used.update(pp.vertices)
            used.update(int(x) for x in cx.neighbours(pp.vertices[-1]))
        cand = plan_pushes(cx, fence, [0], params=P, max_paths=1, exclude=used - {0})
        if not cand or cand[0].frontier in used:
            break
        chosen.append(cand[0])
    return chosen


def _snapshot(reps: dict, source_dir: float = 0.0):
    """The deployer's view of the truth swarm's reports: robot i at vertex i, the source
    robot 0 (its heading ``source_dir``, body frame)."""
    from swarmcover.coordinator.planner import Snapshot
    return Snapshot(occupant={i: i for i in reps}, nbrs={i: r["neighbours"] for i, r in reps.items()},
                    contact={i: r["touch_bearing"] for i, r in reps.items() if r["touch"]},
                    kinds={i: "holonomic" for i in reps}, sources=[0], source_dirs=[source_dir])


def _planner_claim(sw: Swarm, case: MapCase, P, fb: Feedback, reps: dict) -> bool:
    """What the deployer would conclude from this swarm: ``coordinator.planner.plan_cycle``
    on the same reports ``reps`` (no lattice, no redundancy pass), complete = certified with
    no frontier edge and no deployment left (the deployer's finish)."""
    import inspect
    from swarmcover.coordinator.planner import plan_cycle

    snap = _snapshot(reps, sw.body(0, case.source_dir))
    kw = fb.kwargs(reps)
    extra = {}
    if "evidence" in inspect.signature(plan_cycle).parameters:
        extra["evidence"] = {k: v for k, v in kw.items() if k != "test_drive_failures"}
    plan = plan_cycle(snap, P, cycle=0, redundancy=False,
                      test_drive_failures=kw["test_drive_failures"], previous_redundant=set(),
                      protected=set(), max_paths=3, scale_correct=False, test_drive=True,
                      next_vertex=sw.n, lattice_spacing=None, **extra)
    return bool(plan.complete)


def run_index(args) -> dict:
    seed, idx, kw = args
    kw = dict(kw)
    case = make_map(seed, idx, kw.pop("raster", 0.0), kw.pop("doors", False))
    try:
        return run_map(case, **kw)
    except Exception as e:  # a crash in the system under test is a finding, not the end
        import traceback
        return {"index": idx, "seed": seed, "kind": case.kind, "door_w": case.door_w,
                "bucket": door_bucket(case.door_w), "error": f"{type(e).__name__}: {e}",
                "trace": traceback.format_exc()[-800:]}


# ---------------------------------------------------------------------------- report
def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if "error" not in r]
    fixed = [r for r in ok if r["end"] == "fixed"]
    covered_fixed = [r for r in fixed if r["hole_area"] == 0.0]
    by_bucket = {}
    for b in BUCKETS:
        rs = [r for r in ok if r.get("bucket") == b]
        by_bucket[b] = {"maps": len(rs), "false": sum(r["false_certificate"] for r in rs),
                        "certified": sum(r["certified"] for r in rs)}
    by_kind = {}
    for k in KINDS:
        rs = [r for r in ok if r["kind"] == k]
        by_kind[k] = {"maps": len(rs), "false": sum(r["false_certificate"] for r in rs),
                      "refused": sum(r["refusal"] for r in rs),
                      "robots_mean": round(float(np.mean([r["robots"] for r in rs])), 1) if rs else 0}
    wide = [r for r in ok if r.get("door_w") is not None and r["door_w"] >= 0.4 * RV]
    return {
        "maps": len(rows), "errors": len(rows) - len(ok), "fixed_points": len(fixed),
        "capped": sum(r["end"] in ("cap", "cycles") for r in ok),
        "stuck": sum(r["end"] == "stuck" for r in ok),
        "livelock": sum(r["end"] == "livelock" for r in ok),
        "certified": sum(r["certified"] for r in ok),
        "false_certificates": sum(r["false_certificate"] for r in ok),
        "false_on_doors_ge_0.4": sum(r["false_certificate"] for r in wide),
        "false_except_doors_lt_0.4": sum(r["false_certificate"] for r in ok
                                         if r.get("door_w") is None or r["door_w"] >= 0.4 * RV),
        "false_facing_wall": sum(r["false_certificate"] for r in ok if r["facing_wall"]),
        "false_with_empty_target": sum(r["false_certificate"] and r["empty_target"] for r in ok),
        "covered_fixed_points": len(covered_fixed),
        "refusals": sum(r["refusal"] for r in ok),
        "refusal_rate": round(sum(r["refusal"] for r in ok) / max(1, len(covered_fixed)), 4),
        "complex_mismatch": sum(not r["complex_ok"] for r in ok),
        "algebra_mismatch": sum(not r["algebra_ok"] for r in ok),
        "slack_certified": sum(r["slack_closure"] > 0 for r in ok),
        "verify_rejects_own": sum(r["verify_with_fence"] is False for r in ok),
        "by_door_width_rv": by_bucket, "by_kind": by_kind,
        "robots_mean": round(float(np.mean([r["robots"] for r in ok])), 1) if ok else 0,
        "api": sorted({r["api"] for r in ok}),
    }


def print_table(s: dict, rows: list[dict], out=sys.stdout) -> None:
    p = lambda *a: print(*a, file=out)  # noqa: E731
    p(f"\nmaps {s['maps']} (errors {s['errors']}), fixed points {s['fixed_points']}, capped "
      f"{s['capped']}, stuck (frontier, no deployment) {s['stuck']}, livelock (a deployment "
      f"repeated onto its own robots) {s['livelock']}, certified {s['certified']}, mean robots {s['robots_mean']}, fence API {s['api']}")
    p(f"false certificates: {s['false_certificates']} (all maps but doors < 0.4 rv: "
      f"{s['false_except_doors_lt_0.4']}; doors >= 0.4 rv: {s['false_on_doors_ge_0.4']}; "
      f"source facing a wall: {s['false_facing_wall']}; empty target: {s['false_with_empty_target']})")
    p(f"refusals of covered end states: {s['refusals']} of {s['covered_fixed_points']} "
      f"({100 * s['refusal_rate']:.2f}%)")
    p(f"complex != oracle Rips: {s['complex_mismatch']}; certificate != own GF(2): "
      f"{s['algebra_mismatch']}; certified by slack closure: {s['slack_certified']} "
      f"(verify_certificate(cx, cert, fence) rejects {s['verify_rejects_own']})")
    p("")
    p("| door width (rv) | maps | certified | false certificates |")
    p("|---|---|---|---|")
    for b, d in s["by_door_width_rv"].items():
        p(f"| {b} | {d['maps']} | {d['certified']} | {d['false']} |")
    p("")
    p("| map kind | maps | false certificates | refusals | mean robots |")
    p("|---|---|---|---|---|")
    for k, d in s["by_kind"].items():
        p(f"| {k} | {d['maps']} | {d['false']} | {d['refused']} | {d['robots_mean']} |")
    bad = [r for r in rows if r.get("false_certificate")]
    if bad:
        p("\nfalse certificates (index kind door/rv robots coverage hole m^2 depth m, edges that hid it):")
        for r in sorted(bad, key=lambda r: -r["hole_area"])[:25]:
            dw = f"{r['door_w']:.2f}" if r["door_w"] is not None else "-"
            hid = ", ".join(f"{h['edge'][0]}-{h['edge'][1]} {h['reason']} {h['length']}" for h in r["hid_by"][:4])
            p(f"  #{r['index']} {r['kind']} {dw} n={r['robots']} {100 * r['coverage']:.1f}% "
              f"{r['hole_area']:.2f} {r['hole_depth']:.2f}{' facing-wall' if r['facing_wall'] else ''}"
              f"{' noise' if r['noise_deg'] else ''} [{hid}]")
        if len(bad) > 25:
            p(f"  ... {len(bad) - 25} more (--out FILE.json lists them all)")
    errs = [r for r in rows if "error" in r]
    for r in errs[:5]:
        p(f"  error #{r['index']} {r['kind']}: {r['error']}")


def campaign(maps: int, seed: int, jobs: int = 1, progress=True, partial: str | None = None,
             **kw) -> list[dict]:
    """Run maps 0..maps-1 of campaign ``seed``; ``partial``: append each map's result to
    this JSON-lines file as it comes (maps already in it are not run again)."""
    rows: list[dict] = []
    done: set[int] = set()
    if partial and Path(partial).exists():
        for line in Path(partial).read_text().splitlines():
            r = json.loads(line)
            if r.get("seed") == seed and r["index"] < maps and r["index"] not in done:
                rows.append(r)
                done.add(r["index"])
    work = [(seed, i, kw) for i in range(maps) if i not in done]
    t0 = time.time()
    sink = open(partial, "a") if partial else None

    def tick(r):
        if sink is not None:
            sink.write(json.dumps(r) + "\n")
            sink.flush()
        rows.append(r)
        if progress and (len(rows) % 10 == 0 or len(rows) == maps):
            ok = [x for x in rows if "error" not in x]
            print(f"[{len(rows)}/{maps}] {time.time() - t0:.0f} s  certified {sum(x['certified'] for x in ok)}"
                  f"  false {sum(x['false_certificate'] for x in ok)}  refused {sum(x['refusal'] for x in ok)}"
                  f"  errors {len(rows) - len(ok)}", flush=True)

    if jobs > 1:
        import multiprocessing as mp
        with mp.get_context("spawn").Pool(jobs) as pool:
            for r in pool.imap_unordered(run_index, work, chunksize=2):
                tick(r)
    else:
        for w in work:
            tick(run_index(w))
    if sink is not None:
        sink.close()
    rows.sort(key=lambda r: r["index"])
    return rows


def add_campaign_args(ap: argparse.ArgumentParser) -> None:
    """The flags every campaign over these maps takes (this bench, bench/refusals.py)."""
    ap.add_argument("--maps", type=int, default=500, help="maps 0 .. N-1 of the seed's sequence")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--only", type=int, nargs="*", help="run only these map indices")
    ap.add_argument("--out", help="write every map's result and the summary as JSON")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_campaign_args(ap)
    ap.add_argument("--per-cycle", type=int, default=8, help="pushes per cycle (default 8, the deployer's max_paths)")
    ap.add_argument("--headings", choices=("zero", "random"), default="zero",
                    help="robot body headings: zero (holonomic, parallel frames) or random")
    ap.add_argument("--door-min-rv", type=float, default=None,
                    help="[coordinator] door_min_rv for the probes (default: the config's)")
    ap.add_argument("--wall-keep-rv", type=float, default=None,
                    help="[coordinator] wall_keep_rv: a drive's touch nearer fails (default: the config's)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override a coordinator.topology.params.TopologyParams field, e.g. corner_probes=true")
    ap.add_argument("--legacy-rooms", dest="hold_rooms", action="store_false",
                    help="book a room once found, whoever stands beyond its side later (the "
                         "bench's rule until 2026-12-03; the default books rooms as the "
                         "deployer does: see run_map)")
    ap.add_argument("--raster", type=float, default=0.0, metavar="M",
                    help="turn every map 5-40 deg and draw it on a grid of M metres (walls in "
                         "steps, as a ROS map's; e.g. 0.05, the cave's)")
    ap.add_argument("--doors", action="store_true",
                    help="every map two rooms joined by a door 0.40-0.50 rv wide (the "
                         "guarantee's edge), in a wall 0.05-0.30 m thick, one in four flush "
                         "with the outer wall")
    a = ap.parse_args(argv)
    if a.maps < 1 or a.jobs < 1:
        print("truth.py: --maps and --jobs must be >= 1", file=sys.stderr)
        return 2
    topo = {}
    for item in a.set:
        name, _, val = item.partition("=")
        low = val.strip().lower()
        topo[name.strip()] = (low == "true") if low in ("true", "false") else float(val)
    kw = {"per_cycle": a.per_cycle, "headings": a.headings, "door_min_rv": a.door_min_rv,
          "topology": topo, "wall_keep_rv": a.wall_keep_rv, "raster": a.raster,
          "hold_rooms": a.hold_rooms, "doors": a.doors}
    t0 = time.time()
    if a.only:
        rows = [run_index((a.seed, i, kw)) for i in a.only]
    else:
        rows = campaign(a.maps, a.seed, a.jobs,
                        partial=(a.out + ".partial.jsonl") if a.out else None, **kw)
    s = summarise(rows)
    s["wall_s"] = round(time.time() - t0, 1)
    s["grow_cpu_s"] = round(sum(r.get("grow_cpu_s", 0.0) for r in rows), 1)
    print_table(s, rows)
    print(f"\nwall {s['wall_s']} s, growth loop CPU {s['grow_cpu_s']} s")
    if a.out:
        Path(a.out).write_text(json.dumps({"summary": s, "maps": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

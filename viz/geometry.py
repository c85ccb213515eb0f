"""Where to draw things: robot positions from Truth, complex simplices through occupants.

Pure functions, no drawing and no I/O. A vertex of the Complex is drawn at the ground-truth
position of the robot occupying it (``Complex.occupants``); vertices that are empty or whose
robot is not in the Truth have no position, and simplices touching them are left out.
All coordinates are world-frame metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Scene:
    """Everything a figure or the live view draws for one instant.

    ids/xy/live: robot bodies from Truth (live = twin of a live robot); in_complex: the
    robot occupies a vertex; redundant: its vertex is in Complex.redundant; edges,
    frontier, obstacle: (n, 2, 2) segments; triangles: (m, 3, 2); mocap: {robot: (x, y)}
    measured poses of live robots, drawn beside their twins. removed: the robot was taken
    out of the complex as redundant (from the caller's history). inferred: obstacle edges
    the coordinator inferred (Complex.inferred, optional on the wire).
    """
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    live: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    in_complex: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    redundant: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    frontier: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    obstacle: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 2)))
    removed: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    inferred: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    mocap: dict = field(default_factory=dict)
    cycle: int | None = None
    t: float | None = None

    @property
    def n_robots(self) -> int:
        return int(len(self.ids))


def vertex_positions(truth, cx) -> dict[int, tuple[float, float]]:
    """{vertex id: (x, y)} for vertices whose occupant robot is in ``truth``."""
    if truth is None or cx is None:
        return {}
    pos = {int(r): (float(x), float(y)) for r, x, y in zip(truth.ids, truth.x, truth.y)}
    out = {}
    for v, r in zip(cx.vertices, cx.occupants):
        if r >= 0 and r in pos:
            out[int(v)] = pos[r]
    return out


def _segments(pairs: list[tuple[int, int]], vpos: dict) -> np.ndarray:
    segs = [(vpos[a], vpos[b]) for a, b in pairs if a in vpos and b in vpos]
    return np.asarray(segs, float).reshape(-1, 2, 2)


def redundant_robots(cx) -> set[int]:
    """The robots on ``cx``'s redundant vertices (being removed); callers that keep a
    history of them mark those robots while they are outside the complex."""
    occ_of = {int(v): int(r) for v, r in zip(cx.vertices, cx.occupants)}
    return {occ_of.get(int(v), -1) for v in cx.redundant} - {-1}


def build_scene(truth, cx, mocap: dict | None = None, removed=()) -> Scene:
    """The Scene of a Truth and a Complex (either may be None). removed: robot ids removed
    as redundant so far (marked while they hold no vertex)."""
    s = Scene(mocap=dict(mocap or {}))
    if truth is not None:
        s.ids = np.asarray(truth.ids, int)
        s.xy = np.column_stack([np.asarray(truth.x, float), np.asarray(truth.y, float)]
                               ).reshape(-1, 2)
        s.live = np.asarray(truth.live, bool)
        s.t = float(truth.t)
    s.in_complex = np.zeros(len(s.ids), bool)
    s.redundant = np.zeros(len(s.ids), bool)
    gone = {int(r) for r in removed}
    s.removed = np.array([int(r) in gone for r in s.ids], bool)
    if cx is None:
        return s
    s.cycle = int(cx.cycle)
    if s.t is None:
        s.t = float(cx.t)
    occupied = {int(r) for r in cx.occupants if r >= 0}
    red_robots = redundant_robots(cx)
    s.in_complex = np.array([int(r) in occupied for r in s.ids], bool)
    s.redundant = np.array([int(r) in red_robots for r in s.ids], bool)
    vpos = vertex_positions(truth, cx)
    pairs = [(int(cx.edges[2 * k]), int(cx.edges[2 * k + 1])) for k in range(len(cx.edges) // 2)]
    s.edges = _segments(pairs, vpos)
    s.frontier = _segments([pairs[k] for k in cx.frontier], vpos)
    s.obstacle = _segments([pairs[k] for k in cx.obstacle], vpos)
    inferred = getattr(cx, "inferred", None) or ()  # optional field: older Complexes lack it
    s.inferred = _segments([pairs[k] for k in inferred if 0 <= k < len(pairs)], vpos)
    tris = [tuple(int(v) for v in cx.triangles[3 * k:3 * k + 3])
            for k in range(len(cx.triangles) // 3)]
    s.triangles = np.asarray([[vpos[v] for v in t] for t in tris if all(v in vpos for v in t)],
                             float).reshape(-1, 3, 2)
    return s

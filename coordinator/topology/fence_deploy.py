"""The fence's sides resolved and its deployments: the last stages of
:func:`coordinator.topology.fence.detect_fence` before the cycle z.

:func:`resolve_sides` gives each open side its kind (obstacle when marked, frontier
'probing' with its probes, else frontier 'open' with one 'edge' deployment from each end
that does not see a convex corner there, plus a reflex side's deep probe where the
60-deg one is blocked). :func:`robot_deployments` adds the single-file and isolated
robots' directions, drops what failed test drives block and orders each robot's list.

Units: bearings and offsets in rad (body frame of the deploying robot), clearances in
rad. Keys of ``deps`` are local vertex indices, of the result node ids.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from swarmcover.ground.angles import circular_mean, wrap
from .complex import Complex
from .fence_local import _Local
from .fence_sides import _PI3, Marks, Room, Sides
from .fence_types import Deployment, FenceEdge, FenceSide

__all__: list[str] = []

# Single-file ends offer every direction of their open wedge 60 deg apart that keeps this
# far from every neighbour (a little under 60 deg, for bearing noise).
_SINGLE_CLEAR = math.radians(50.0)

Deps = dict[int, list[Deployment]]


def resolve_sides(cx: Complex, L: _Local, open_sides: Sides, marks: Marks,
                  probing: dict[tuple[int, int], list[Deployment]], room: Room
                  ) -> tuple[list[FenceEdge], list[int], list[int], list[int], Deps]:
    """(fence edges, K, O, z, deps) in ``open_sides`` order: K / O / z the edge ids of
    frontier, obstacle and one-sided edges; deps local index -> its deployments so far
    (probes and edge deployments, in the order the sides give them)."""
    ids = cx.ids
    fence_edges: list[FenceEdge] = []
    K: list[int] = []
    O: list[int] = []
    z: list[int] = []
    deps: Deps = {}
    for e, recs in open_sides.items():
        u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
        Bu, Bv = L.bearings(u), L.bearings(v)
        sides = []
        for sg, off_u, off_v in recs:
            why = marks.get((e, sg))
            if why is not None:
                sides.append(FenceSide(sg, "obstacle", why))
                continue
            if (e, sg) in probing:
                sides.append(FenceSide(sg, "frontier", "probing"))
                for d in probing[(e, sg)]:
                    deps.setdefault(cx.index_of(d.vertex), []).append(d)
                continue
            # an end that sees a convex corner on this side (corner_wait) does not deploy
            du = None if off_u is None else wrap(Bu[v] + off_u)
            dv = None if off_v is None else wrap(Bv[u] + off_v)
            sides.append(FenceSide(sg, "frontier", "open", du, dv, off_u, off_v))
            edge_ids = (int(ids[u]), int(ids[v]))
            for p, q, d, off in ((u, v, du, off_u), (v, u, dv, off_v)):
                if off is None:
                    continue
                deps.setdefault(p, []).append(
                    Deployment(int(ids[p]), d, edge_ids, sg, off, L.clearance(p, d), "edge"))
                deep = room.deep(p, q, off) if room.blocked(p, d) else None
                if deep is not None:
                    deps[p].append(Deployment(int(ids[p]), deep, edge_ids, sg,
                                              wrap(deep - L.bearings(p)[q]),
                                              L.clearance(p, deep), "edge"))
        fe = FenceEdge(int(ids[u]), int(ids[v]), e, tuple(sides))
        fence_edges.append(fe)
        if fe.is_frontier:
            K.append(e)
        if fe.is_obstacle:
            O.append(e)
        if len(recs) == 1:
            z.append(e)
    return fence_edges, K, O, z, deps


def _single_file(L: _Local, p: int, nid: int, offset: float = 0.0) -> list[Deployment]:
    """Directions of single-file robot p (node id nid): away from the circular mean of the
    neighbours, then 60 and 120 deg either side at least _SINGLE_CLEAR from every
    neighbour; none inside a chain (resultant < 0.5). ``offset`` (rad) turns them all
    (then each needs the clearance, the first too)."""
    out: list[Deployment] = []
    mean, res = circular_mean(L.bearings(p).values())
    if res < 0.5:
        return out
    for k in (0, 1, -1, 2, -2) if not offset else (0, 1, -1, 2, -2, 3):
        d = wrap(mean + math.pi + offset + k * _PI3)
        c = L.clearance(p, d)
        if (k == 0 and not offset) or c >= _SINGLE_CLEAR:
            out.append(Deployment(nid, d, None, 0, 0.0, c, "single_file"))
    return out


def _isolated(nid: int, default_bearing: float | Mapping[int, float],
              offset: float = 0.0) -> list[Deployment]:
    """Six directions 60 deg apart from the default bearing of a robot with no neighbour
    (turned by ``offset``, rad)."""
    if isinstance(default_bearing, Mapping):
        d0_ = wrap(float(default_bearing.get(nid, 0.0)))
    else:
        d0_ = wrap(float(default_bearing))
    return [Deployment(nid, wrap(d0_ + offset + k * _PI3), None, 0, 0.0, math.pi, "isolated")
            for k in range(6)]


def robot_deployments(cx: Complex, L: _Local, room: Room, deps: Deps,
                      default_bearing: float | Mapping[int, float]
                      ) -> dict[int, tuple[Deployment, ...]]:
    """Node id -> its deployments, best clearance first (then edge, sigma), from ``deps``
    (:func:`resolve_sides`; consumed) plus single-file and isolated robots' directions,
    without those a failed test drive blocks (probes excepted) and without single-file
    directions at a robot that still has edge deployments."""
    ids = cx.ids
    single = (room.n_tri_at == 0) & (cx.degree > 0)
    # single-file robots (no triangle, spec 3.3): away from the circular mean of the
    # neighbours -- the end of a chain; a robot between two opposite neighbours (resultant
    # < 0.5) is inside the chain and has no single-file direction.
    # Every direction of the open wedge is offered (spec 3.4 amendment: a robot with one
    # or no neighbour probes every free direction before it gives up): away from the
    # neighbours, then 60, 120 deg either side, each at least _SINGLE_CLEAR from every
    # neighbour. A failed drive blocks 30 deg either side, so each touch removes one.
    for p in np.nonzero(single)[0].tolist():
        lst = _single_file(L, p, int(ids[p]))
        if lst:
            deps.setdefault(p, []).extend(lst)
    # a robot with no neighbour: six directions 60 deg apart from its default bearing
    for p in np.nonzero(cx.degree == 0)[0].tolist():
        deps.setdefault(p, []).extend(_isolated(int(ids[p]), default_bearing))
    # test-drive failures also drop deployments pointing into the failed gap
    for p in room.failed:
        if p in deps:
            keep = [dp for dp in deps[p] if dp.kind == "probe" or not room.blocked(p, dp.bearing)]
            if keep:
                deps[p] = keep
            else:
                del deps[p]
    # a robot with no neighbour, or a chain end, whose drives all touched (each blocks 30
    # deg either side: six take the whole circle, five a chain end's wedge) tries the
    # directions between them, but where a drive of its own went: the first robot, its six
    # drives all touched within d0, ended the run alone at 15% coverage (bench/truth.py
    # seed 2 map 387); a robot in a 0.30 rv doorway touched the jambs on all five, the
    # nearest 23 and 36 deg off the way through, and the room behind was certified
    # uncovered (seed 4 map 188)
    for p in np.nonzero((cx.degree == 0) | single)[0].tolist():
        if p not in deps:
            nid = int(ids[p])
            ring = (_isolated(nid, default_bearing, _PI3 / 2.0) if cx.degree[p] == 0
                    else _single_file(L, p, nid, _PI3 / 2.0))
            lst = [dp for dp in ring if not room.blocked(p, dp.bearing, cone=_PI3 / 4.0)]
            if lst:
                deps[p] = lst

    # a robot with a frontier edge deploys off the edge (60 deg, triangles); the single-file
    # direction is its fallback once those are gone (a corridor too narrow for triangles
    # makes the edge deployments fail their test drives)
    for p, lst in deps.items():
        if any(d.kind == "edge" for d in lst):
            deps[p] = [d for d in lst if d.kind != "single_file"]
    return {
        int(ids[p]): tuple(sorted(lst, key=lambda d: (-d.clearance, d.edge or (0, 0), d.sigma)))
        for p, lst in sorted(deps.items())
    }

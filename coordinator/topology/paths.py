"""Push paths (spec sections 4.1-4.2).

Multi-source shortest paths over the 1-skeleton from the sources (base-station vertices
and redundant vertices) to frontier vertices; obstacle edges cost ``w_obstacle``, other
edges 1. Several vertex-disjoint pushes can be planned for one cycle: greedily, shortest
first; after each choice its vertices are removed, its frontier edge is no longer a
target, and deployments whose estimated new position is too close to the chosen one are
dropped (assumed geometry with spacing d0, frames aligned by mutual bearings).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from swarmcover.ground.angles import wrap
from .complex import Complex
from .fence import Deployment, Fence
from .params import TopologyParams

__all__ = ["PushPath", "plan_pushes", "deployment_point"]


@dataclass(frozen=True)
class PushPath:
    """One push: ``vertices`` = (p0, ..., pm) node ids, p0 a source or redundant vertex,
    pm the frontier vertex whose robot deploys along ``deployment``. ``cost`` is the path
    cost (1 per edge, w_obstacle per obstacle edge)."""

    vertices: tuple[int, ...]
    deployment: Deployment
    cost: float

    @property
    def start(self) -> int:
        return self.vertices[0]

    @property
    def frontier(self) -> int:
        return self.vertices[-1]


def deployment_point(cx: Complex, frame_of: int, dep: Deployment, d0: float,
                     rv: float | None = None) -> np.ndarray:
    """Estimated new position (x, y) of ``dep`` in the body frame of robot ``frame_of``,
    which must be ``dep.vertex`` or one of its neighbours (assumed spacing d0; a probe's
    depth_rv is scaled by ``rv``, default d0 / 0.9)."""
    # a probe ends depth_rv out along its bearing from the point at via_frac of its edge
    # (edge length taken as d0)
    reach, off = 1.0, np.zeros(2)
    if dep.kind == "probe":
        rv_ = d0 / 0.9 if rv is None else rv
        reach = dep.depth_rv * rv_ / max(d0, 1e-9) if dep.depth_rv > 0 else 1.0
        if dep.via_frac > 0 and dep.edge is not None:
            q = dep.edge[1] if dep.edge[0] == dep.vertex else dep.edge[0]
            if q in cx:
                tq = cx.bearing(dep.vertex, q)
                off = dep.via_frac * np.array([math.cos(tq), math.sin(tq)])
    own = off + reach * np.array([math.cos(dep.bearing), math.sin(dep.bearing)])
    if frame_of == dep.vertex:
        return d0 * own
    t_fg = cx.bearing(frame_of, dep.vertex)  # g seen from f
    t_gf = cx.bearing(dep.vertex, frame_of)  # f seen from g
    rot = wrap(t_fg - t_gf + math.pi)  # heading of g minus heading of f
    c, s_ = math.cos(rot), math.sin(rot)
    ox, oy = own
    return d0 * np.array([math.cos(t_fg) + c * ox - s_ * oy, math.sin(t_fg) + s_ * ox + c * oy])


def _dep_key(d: Deployment):
    return (d.vertex, d.edge, d.sigma, d.kind, d.via_frac)


def plan_pushes(
    cx: Complex,
    fence: Fence,
    sources: Iterable[int],
    redundant: Iterable[int] = (),
    *,
    params: TopologyParams | None = None,
    max_paths: int = 1,
    exclude: Iterable[int] = (),
    min_separation: float | None = None,
) -> list[PushPath]:
    """Vertex-disjoint push paths, best first (at most ``max_paths``).

    sources, redundant: node ids where a path may start (redundant vertices are left
    empty by the push). exclude: node ids no path may use (robots already moving).
    min_separation: two new positions closer than this (estimated, units of rv) are not
    planned in the same cycle; default 0.5 * d0.
    Tie-breaks (spec 4.2): lower cost, then the deployment with the largest clearance
    to the robot's existing neighbours, then the lower frontier vertex id; at a vertex
    with several deployments the one with the largest clearance is used.
    """
    P = params or TopologyParams()
    d0 = P.d0
    sep = 0.5 * d0 if min_separation is None else float(min_separation)
    n = cx.n
    starts = sorted({int(s) for s in list(sources) + list(redundant) if int(s) in cx})
    if not starts or not fence.deployments:
        return []
    used = np.zeros(n, dtype=bool)
    ex = [int(v) for v in exclude if int(v) in cx]
    if ex:
        used[cx.index(ex)] = True
    w = np.ones(cx.n_edges)
    if fence.obstacle.size:
        w[fence.obstacle] = P.w_obstacle
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    blocked_edges: set[tuple[int, int]] = set()
    blocked: set = set()
    out: list[PushPath] = []
    dk = [k for k in fence.deployments if k in cx]
    targets = dict(zip(cx.index(dk).tolist(), (fence.deployments[k] for k in dk))) if dk else {}
    for _ in range(max(0, int(max_paths))):
        st = [p for p in cx.index(starts).tolist() if not used[p]]
        if not st:
            break
        keep = ~(used[u] | used[v])
        g = csr_matrix((np.concatenate([w[keep], w[keep]]),
                        (np.concatenate([u[keep], v[keep]]), np.concatenate([v[keep], u[keep]]))), shape=(n, n))
        dist, pred = dijkstra(g, directed=True, indices=st, min_only=True, return_predecessors=True)[:2]
        best = None
        for f, lst in targets.items():
            if used[f] or not np.isfinite(dist[f]):
                continue
            ok = [d for d in lst if _dep_key(d) not in blocked and (d.edge is None or d.edge not in blocked_edges)]
            if not ok:
                continue
            d = max(ok, key=lambda d: (d.clearance, -d.sigma))
            key = (float(dist[f]), -d.clearance, int(cx.ids[f]))
            if best is None or key < best[0]:
                best = (key, f, d)
        if best is None:
            break
        (cost, _, _), f, dep = best
        path = [f]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        path.reverse()
        used[path] = True
        if dep.edge is not None:
            blocked_edges.add(dep.edge)
        # drop deployments of neighbours that would land too close to this one
        p_new = deployment_point(cx, dep.vertex, dep, d0, P.rv)
        fid = dep.vertex
        for g_id in cx.neighbours(fid).tolist():
            gi = cx.index_of(g_id)
            for d2 in targets.get(gi, ()):
                if np.linalg.norm(deployment_point(cx, fid, d2, d0, P.rv) - p_new) < sep:
                    blocked.add(_dep_key(d2))
        out.append(PushPath(tuple(int(x) for x in cx.ids[path]), dep, cost))
    return out

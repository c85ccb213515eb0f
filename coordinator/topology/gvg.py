"""Discrete generalised Voronoi graph on the 1-skeleton (spec section 7.3).

Hop-count wavefronts start from the labelled obstacle segments O_1..O_s; a vertex where
two fronts with different labels meet (equal distance or one hop apart) is on the GVG.
Thinning removes GVG vertices whose link in the GVG subcomplex is a path (a collapse).
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Mapping

from .complex import Complex

__all__ = ["GVG", "gvg_wavefront", "gvg_thin", "compute_gvg", "obstacle_segments"]


@dataclass(frozen=True)
class GVG:
    """vertices: GVG node ids before thinning; thinned: after thinning. distance: node id
    -> hop distance to the nearest labelled obstacle vertex (math.inf if unreachable);
    label: node id -> label of that obstacle segment (-1 if unreachable)."""

    vertices: frozenset[int]
    thinned: frozenset[int]
    distance: Mapping[int, float]
    label: Mapping[int, int]


def gvg_wavefront(cx: Complex, labels: Mapping[int, int]):
    """The wavefront of spec 7.3 (RA-L GVG_Compute), ties popped by lower node id.

    labels: node id -> obstacle segment label (>= 0) for the vertices of O_1..O_s.
    Returns (GVG node ids, distance dict, label dict).
    """
    n = cx.n
    indptr, nbr = cx.adjacency[0].tolist(), cx.adjacency[1].tolist()
    g = [math.inf] * n
    lab = [-1] * n
    for nid, k in labels.items():
        if int(nid) in cx:
            p = cx.index_of(int(nid))
            g[p] = 0
            lab[p] = int(k)
    heap = [(g[p], p) for p in range(n) if g[p] == 0]
    heapq.heapify(heap)
    expanded = [False] * n
    out: set[int] = set()
    while heap:
        gq, q = heapq.heappop(heap)
        if expanded[q] or gq != g[q]:
            continue
        expanded[q] = True
        best = None
        for w in nbr[indptr[q]:indptr[q + 1]]:
            if expanded[w] and w != q and lab[w] != lab[q]:
                if best is None or (g[w], w) < (g[best], best):
                    best = w
        if best is not None and (g[best] == g[q] or g[best] + 1 == g[q]):
            out.add(q)
        for w in nbr[indptr[q]:indptr[q + 1]]:
            if not expanded[w] and g[w] > g[q] + 1:
                g[w] = g[q] + 1
                lab[w] = lab[q]
                heapq.heappush(heap, (g[w], w))
    ids = cx.ids.tolist()
    return (frozenset(ids[p] for p in out), {ids[p]: g[p] for p in range(n)}, {ids[p]: lab[p] for p in range(n)})


def gvg_thin(cx: Complex, vertices, *, keep_leaves: bool = True) -> frozenset[int]:
    """Collapse the GVG subcomplex spanned by ``vertices`` (node ids).

    A vertex with n >= 2 GVG edges (n >= 1 when keep_leaves is False) is removed when
    its link in the GVG subcomplex (GVG neighbours, joined when they span a GVG triangle
    with it) is a path. Repeats, in id order, until nothing changes.
    """
    keep = {cx.index_of(int(v)) for v in vertices if int(v) in cx}
    indptr, nbr = cx.adjacency[0].tolist(), cx.adjacency[1].tolist()
    adj = {p: set(nbr[indptr[p]:indptr[p + 1]]) for p in keep}
    min_n = 1 if not keep_leaves else 2
    changed = True
    while changed:
        changed = False
        for p in sorted(keep):
            link = adj[p] & keep
            k = len(link)
            if k < min_n:
                continue
            # the link graph: GVG neighbours joined when adjacent (a GVG triangle)
            ldeg = {a: len(adj[a] & link) for a in link}
            ne = sum(ldeg.values()) // 2
            if ne != k - 1 or any(d > 2 for d in ldeg.values()):
                continue
            # connected?
            start = next(iter(link))
            seen = {start}
            stack = [start]
            while stack:
                x = stack.pop()
                for y in adj[x] & link:
                    if y not in seen:
                        seen.add(y)
                        stack.append(y)
            if len(seen) != k:
                continue
            keep.discard(p)
            changed = True
    ids = cx.ids
    return frozenset(int(ids[p]) for p in keep)


def compute_gvg(cx: Complex, labels: Mapping[int, int], *, thin: bool = True, keep_leaves: bool = True) -> GVG:
    """Wavefront GVG plus (optional) thinning; see :func:`gvg_wavefront`, :func:`gvg_thin`."""
    verts, dist, lab = gvg_wavefront(cx, labels)
    thinned = gvg_thin(cx, verts, keep_leaves=keep_leaves) if thin else verts
    return GVG(verts, thinned, dist, lab)


def obstacle_segments(cx: Complex, obstacle_edges) -> dict[int, int]:
    """Labels for :func:`gvg_wavefront`: node id -> index of the connected component of
    the obstacle edges (edge ids, e.g. ``Fence.obstacle``) it lies on. Components are
    numbered by their smallest node id. (No concave-corner splitting, spec 7.2.)"""
    parent: dict[int, int] = {}

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for e in list(obstacle_edges):
        a, b = (int(x) for x in cx.ids[cx.edges[int(e)]])
        parent.setdefault(a, a)
        parent.setdefault(b, b)
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = sorted({find(a) for a in parent})
    index = {r: i for i, r in enumerate(roots)}
    return {a: index[find(a)] for a in sorted(parent)}

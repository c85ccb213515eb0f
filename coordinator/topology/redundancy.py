"""Redundant robots: greedy removal with a local test (spec section 5.3-5.4).

A robot c off the fence can leave without breaking the certificate when the flag
complex of its neighbourhood (its link) is connected with H1 = 0: the part of the chain
in c's star has a boundary that is a cycle in the link, and that cycle is filled by
triangles of the link, so the chain is rerouted around c. Connectivity of the link
also keeps the 1-skeleton connected. A dominated robot (N[c] inside N[d]) is the fast
path: its link is a cone on d.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .certificate import Certificate, certificate_from_chain, certify
from .complex import Complex
from .gf2 import Basis, solve

__all__ = ["Redundancy", "find_redundant", "link_is_acyclic"]

_I64 = np.int64


@dataclass(frozen=True, eq=False)
class Redundancy:
    """Result of :func:`find_redundant`.

    removed: node ids in removal order. certificate: the rerouted certificate (its chain
    avoids every removed robot; boundary = the same z). tried: number of local tests run.
    """

    removed: tuple[int, ...]
    certificate: Certificate
    tried: int

    @property
    def redundant(self) -> frozenset[int]:
        return frozenset(self.removed)


def _link_graph(nbr: list[set], c: int) -> dict[int, set]:
    link = nbr[c]
    return {a: nbr[a] & link for a in link}


def _betti01(L: dict[int, set]) -> tuple[int, int]:
    """(beta0, beta1) over GF(2) of the flag 2-complex of the small graph L."""
    verts = list(L)
    if not verts:
        return 0, 0
    # components
    seen: set[int] = set()
    b0 = 0
    for s in verts:
        if s in seen:
            continue
        b0 += 1
        stack = [s]
        seen.add(s)
        while stack:
            x = stack.pop()
            for y in L[x]:
                if y not in seen:
                    seen.add(y)
                    stack.append(y)
    edges = {}
    for a in verts:
        for b in L[a]:
            if a < b:
                edges[(a, b)] = len(edges)
    ne = len(edges)
    cyc = ne - len(verts) + b0
    if cyc == 0:
        return b0, 0
    # rank of the triangle -> edge boundary map, counted until it reaches cyc
    B = Basis()
    rank = 0
    for a in verts:
        for b in L[a]:
            if b <= a:
                continue
            for e in L[a] & L[b]:
                if e > b and B.add((1 << edges[(a, b)]) | (1 << edges[(a, e)]) | (1 << edges[(b, e)])):
                    rank += 1
                    if rank == cyc:
                        return b0, 0
    return b0, cyc - rank


def _strong_collapse(L: dict[int, set]) -> dict[int, set]:
    """Remove dominated vertices until none is left (preserves the homotopy type)."""
    L = {a: set(s) for a, s in L.items()}
    changed = True
    while changed and len(L) > 1:
        changed = False
        for u in sorted(L):
            Nu = L[u]
            for w in Nu:
                if len(L[w]) >= len(Nu) - 1 and (Nu - {w}) <= L[w]:
                    for x in Nu:
                        L[x].discard(u)
                    del L[u]
                    changed = True
                    break
    return L


def link_is_acyclic(L: dict[int, set]) -> tuple[bool, int | None]:
    """(True, dominator or None) if the flag complex of L is connected with H1 = 0."""
    n = len(L)
    if n == 0:
        return False, None
    ne2 = 0
    for d, s in L.items():
        k = len(s)
        if k == n - 1:
            return True, d  # cone on d
        ne2 += k
    ne = ne2 // 2
    if ne < n - 1:
        return False, None  # disconnected
    # beta1 >= E - V + 1 - F: count link triangles F only as far as needed
    need = ne - n + 1
    f3 = 0  # three times the triangles found so far
    if need > 0:
        for a, s in L.items():
            for b in s:
                if b > a:
                    f3 += len(s & L[b])
            if f3 >= 3 * need:
                break
        if f3 < 3 * need:
            return False, None
    elif need == 0:
        # E = V - 1: acyclic exactly when connected
        b0, b1 = _betti01(L)
        return (b0 == 1 and b1 == 0), None
    b0, b1 = _betti01(_strong_collapse(L) if n > 12 else L)
    return (b0 == 1 and b1 == 0), None


def _fill_cycle(L: dict[int, set], gamma: set[tuple[int, int]]) -> list[tuple[int, int, int]] | None:
    """Triangles (a<b<e) of L whose GF(2) boundary is the edge set gamma, or None."""
    edges: dict[tuple[int, int], int] = {}
    for a in L:
        for b in L[a]:
            if a < b:
                edges[(a, b)] = len(edges)
    tris = []
    for a in L:
        for b in L[a]:
            if b <= a:
                continue
            for e in L[a] & L[b]:
                if e > b:
                    tris.append((a, b, e))
    r = 0
    for ab in gamma:
        r ^= 1 << edges[ab]
    subset, _ = solve([(1 << edges[(a, b)]) | (1 << edges[(a, e)]) | (1 << edges[(b, e)]) for a, b, e in tris], r)
    return None if subset is None else [tris[i] for i in subset]


def _present(cx: Complex, node_ids) -> list:
    """The ids of ``node_ids`` that are nodes of ``cx``, in their order (one vectorised
    lookup instead of a ``v in cx`` per id)."""
    ids = list(node_ids)
    if not ids or cx.n == 0:
        return []
    q = np.asarray(ids, dtype=_I64)
    p = np.minimum(np.searchsorted(cx.ids, q), cx.n - 1)
    return [v for v, ok in zip(ids, (cx.ids[p] == q).tolist()) if ok]


def _in_four_clique(cx: Complex) -> np.ndarray:
    """(n,) bool: the vertices in some 4-clique of the complex's graph. Each 4-clique
    a < b < c < d is found once, from its triangle abc and d among c's higher neighbours."""
    n = cx.n
    out = np.zeros(n, dtype=bool)
    t = cx.triangles
    if t.shape[0] == 0:
        return out
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    fptr = np.zeros(n + 1, dtype=_I64)          # edge rows are sorted: c's forward list
    np.cumsum(np.bincount(u, minlength=n), out=fptr[1:])
    c = t[:, 2]
    cnt = fptr[c + 1] - fptr[c]
    total = int(cnt.sum())
    if total == 0:
        return out
    rep = np.repeat(np.arange(t.shape[0], dtype=_I64), cnt)
    offs = np.arange(total, dtype=_I64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    d = v[fptr[c][rep] + offs]
    hit = (cx.edge_index(t[rep, 0], d) >= 0) & (cx.edge_index(t[rep, 1], d) >= 0)
    out[t[rep[hit]].ravel()] = True
    out[d[hit]] = True
    return out


def find_redundant(
    cx: Complex,
    fence,
    certificate: Certificate | None = None,
    protected: Iterable[int] = (),
) -> Redundancy:
    """Greedy removal of robots whose departure keeps the certificate (local test).

    fence: a Fence (its fence vertices and frontier are protected / used for the order)
      or anything :func:`certify` accepts as z.
    certificate: a certificate for the same z (computed if None). If it is not certified
      nothing is removed.
    protected: node ids that must stay (the source, robots currently moving, ...).
    Order: hop distance to the frontier vertices (nearest first), then higher degree,
    then lower id. A robot rejected earlier is tested again once a neighbour leaves.
    """
    if certificate is None:
        certificate = certify(cx, fence)
    if not certificate.certified:
        return Redundancy((), certificate, 0)
    n = cx.n
    z = certificate.z
    prot = np.zeros(n, dtype=bool)
    pids = [int(p) for p in protected if int(p) in cx]
    if pids:
        prot[cx.index(pids)] = True
    if z.size:
        prot[cx.edges[z].ravel()] = True
    front_ids: list[int] = []
    if hasattr(fence, "fence_vertices"):
        fv = _present(cx, fence.fence_vertices)
        if fv:
            prot[cx.index(fv)] = True
        front_ids = _present(cx, fence.frontier_vertices) or fv
    if not front_ids and z.size:
        front_ids = cx.ids[np.unique(cx.edges[z].ravel())].tolist()

    # order: hops to the frontier, then degree (high first), then id
    deg = cx.degree
    if front_ids and cx.n_edges:
        u, v = cx.edges[:, 0], cx.edges[:, 1]
        g = csr_matrix((np.ones(2 * u.shape[0]), (np.concatenate([u, v]), np.concatenate([v, u]))), shape=(n, n))
        hops = dijkstra(g, directed=True, indices=cx.index(front_ids), unweighted=True, min_only=True)
        hops = np.where(np.isfinite(hops), hops, n + 1.0).astype(_I64)
    else:
        hops = np.zeros(n, dtype=_I64)
    cand = np.nonzero(~prot)[0]
    keys = {int(p): (int(hops[p]), -int(deg[p]), int(p)) for p in cand.tolist()}
    heap = [(k, p) for p, k in keys.items()]
    heapq.heapify(heap)

    x = np.zeros(cx.n_triangles, dtype=bool)
    x[certificate.chain] = True
    nbr = cx.adjacency_sets()
    alive = np.ones(n, dtype=bool)
    state = {p: 0 for p in keys}  # 0 queued, 1 rejected, 2 removed
    vptr, vtri = cx.vertex_triangles
    tri = cx.triangles
    removed: list[int] = []
    tried = 0
    # a robot whose link has more edges (its triangles) than a tree on its neighbours and
    # no triangle (it is in no 4-clique) has a cycle in its link: rejected without building
    # the link, while no neighbour has left (most robots of a sparse swarm; the link test
    # in Python was most of the pass's time at 1,000 robots)
    cyclic = (np.diff(vptr) - deg + 1 > 0) & ~_in_four_clique(cx)
    changed = np.zeros(n, dtype=bool)   # a neighbour left: its link is no longer cx's
    while heap:
        _, c = heapq.heappop(heap)
        if state[c] != 0:
            continue
        tried += 1
        if cyclic[c] and not changed[c]:
            state[c] = 1
            continue
        V = len(nbr[c])
        L = _link_graph(nbr, c)
        if V == 0:
            state[c] = 1
            continue
        ne2 = sum(len(s) for s in L.values())  # twice the link edges
        if ne2 < 2 * (V - 1):  # fewer than V-1 edges: the link is disconnected
            state[c] = 1
            continue
        ok, dom = link_is_acyclic(L)
        if not ok:
            state[c] = 1
            continue
        # reroute the chain around c
        ts = vtri[vptr[c]:vptr[c + 1]]
        ts = ts[alive[tri[ts]].all(axis=1)]
        sx = ts[x[ts]]
        gamma: set[tuple[int, int]] = set()
        for t in sx.tolist():
            a, b, e = tri[t].tolist()
            pair = (a, b) if e == c else ((a, e) if b == c else (b, e))
            gamma ^= {pair}
        if dom is not None:
            y = [tuple(sorted((dom, a, b))) for a, b in gamma if dom != a and dom != b]
        else:
            y = _fill_cycle(L, gamma)
            if y is None:  # cannot happen when H1 = 0; keep the robot
                state[c] = 1
                continue
        x[sx] = False
        if y:
            ya = np.array(y, dtype=_I64)
            yi = cx.triangle_index(ya[:, 0], ya[:, 1], ya[:, 2])
            np.logical_xor.at(x, yi, True)
        alive[c] = False
        state[c] = 2
        removed.append(c)
        for a in nbr[c]:
            nbr[a].discard(c)
            changed[a] = True
            if state.get(a) == 1:
                state[a] = 0
                heapq.heappush(heap, (keys[a], a))
        nbr[c] = set()
    chain = np.nonzero(x)[0]
    cert = certificate_from_chain(cx, z, chain, {"rerouted_from": int(certificate.chain.size)},
                                  like=certificate)
    return Redundancy(tuple(int(cx.ids[p]) for p in removed), cert, tried)

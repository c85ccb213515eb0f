"""``run``'s own check of a certificate it is sent, before it says CERTIFIED (pure, no I/O).

The Complex message carries the complex (vertices, edges, triangles), the fence (frontier K,
obstacle O) and the claim; it does not carry the 2-chain. ``recheck`` rebuilds the complex
from the message and checks the claim again:

1. the complex is well formed: edge ends are vertices, every triangle's three edges are
   edges, every vertex is held by a robot, and there is at least one triangle (an empty
   target never certifies);
2. the frontier K is empty;
3. over GF(2), the obstacle edges O are the boundary of a 2-chain of the message's
   triangles, solved again by ``coordinator.certify`` on the rebuilt complex (an O with odd
   vertices, where edges cross, is first closed by short joins, at most MAX_JOIN edges
   each and MAX_ADDED x |O| in all, then by the certificate's slack search);
4. with ground truth (``positions``, the world's): every occupant is a robot of the world,
   and every edge joins robots at most rv apart (with ``tol`` for motion since the cycle).

It cannot tell whether O's edges are really walls (that is the coordinator's fence rule,
from bearings and touch); the ground-truth coverage check in summary.json covers that.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Recheck:
    ok: bool
    why: str = ""

    def as_dict(self) -> dict:
        return {"ok": self.ok, "why": self.why,
                "checked": "complex rebuilt from the message; K empty; O a GF(2) boundary of "
                           "its triangles; occupants and edge lengths against ground truth"}


def recheck(cx, positions: dict | None = None, rv: float | None = None,
            tol: float = 0.25) -> Recheck:
    """Check a Complex message's certified claim; see the module doc."""
    if cx.state != "certified" or not cx.certified:
        return Recheck(False, f"state {cx.state!r}, certified {cx.certified}")
    if cx.frontier:
        return Recheck(False, f"{len(cx.frontier)} frontier edges")
    verts = list(cx.vertices)
    if len(set(verts)) != len(verts):
        return Recheck(False, "duplicate vertex ids")
    if any(o < 0 for o in cx.occupants):
        return Recheck(False, "a vertex without a robot")
    loc = {v: i for i, v in enumerate(verts)}
    E = np.asarray(cx.edges, np.int64).reshape(-1, 2)
    T = np.asarray(cx.triangles, np.int64).reshape(-1, 3)
    if not len(T):
        return Recheck(False, "no triangle: an empty certificate")
    try:
        el = np.array([[loc[int(a)], loc[int(b)]] for a, b in E], np.int64).reshape(-1, 2)
        tl = np.array([[loc[int(x)] for x in t] for t in T], np.int64).reshape(-1, 3)
    except KeyError as e:
        return Recheck(False, f"edge or triangle names vertex {e.args[0]} not in the complex")
    if np.any(el[:, 0] == el[:, 1]):
        return Recheck(False, "a loop edge")
    es = np.sort(el, axis=1)
    order = np.lexsort((es[:, 1], es[:, 0]))
    es_sorted = es[order]
    if len(es_sorted) > 1 and np.any(np.all(es_sorted[1:] == es_sorted[:-1], axis=1)):
        return Recheck(False, "duplicate edges")
    ts = np.sort(tl, axis=1)
    if np.any(ts[:, 0] == ts[:, 1]) or np.any(ts[:, 1] == ts[:, 2]):
        return Recheck(False, "a degenerate triangle")
    known = {(int(a), int(b)) for a, b in es}
    for a, b, c in ts.tolist():
        if (a, b) not in known or (a, c) not in known or (b, c) not in known:
            return Recheck(False, "a triangle whose edges are not all edges")
    if positions is not None and rv is not None:
        for v, o in zip(verts, cx.occupants):
            if o not in positions:
                return Recheck(False, f"vertex {v}'s robot {o} is not in the world")
        occ = list(cx.occupants)
        for a, b in el.tolist():
            d = math.dist(positions[occ[a]], positions[occ[b]])
            if d > rv * (1 + tol):
                return Recheck(False, f"edge {verts[a]}-{verts[b]} is {d:.2f} m long in the "
                                      f"world (rv {rv:g} m)")
    # GF(2): O must be a boundary of the message's triangles
    from types import SimpleNamespace

    from coordinator.certificate import certify
    from coordinator.complex import Complex as TopoComplex
    n = len(verts)
    ids = np.asarray(verts, np.int64)
    perm = np.argsort(ids)
    rank = np.empty(n, np.int64)
    rank[perm] = np.arange(n)
    e2 = np.sort(rank[el], axis=1)
    eo = np.lexsort((e2[:, 1], e2[:, 0]))
    t2 = np.sort(rank[tl], axis=1)
    to = np.lexsort((t2[:, 2], t2[:, 1], t2[:, 0]))
    topo = TopoComplex(ids[perm], e2[eo], t2[to], np.zeros((len(e2), 2)), np.zeros(n, bool),
                       np.full(n, np.nan))
    new_index = np.empty(len(eo), np.int64)
    new_index[eo] = np.arange(len(eo))
    z = np.zeros(len(eo), bool)
    for k in cx.obstacle:
        z[new_index[k]] ^= True
    if not z.any():
        return Recheck(False, "no obstacle edge: nothing fences the region")
    cert = certify(topo, z)
    if not cert.certified:
        deg = np.bincount(topo.edges[z].ravel(), minlength=n) & 1
        if deg.any():
            # O has odd vertices (crossing edges): the certificate closed it by search
            fence = SimpleNamespace(z=z, z_raw=np.nonzero(z)[0], z_repair=np.array([1]))
            cert = _closed(topo, fence, z, deg)
    if cert is None or not cert.certified:
        return Recheck(False, "the obstacle edges are not the boundary of any 2-chain of the "
                              "complex's triangles")
    return Recheck(True)


MAX_JOIN = 4        # edges joining two odd vertices of O, where fence edges cross
MAX_ADDED = 0.25    # x |O|: the most edges a closure may add (pillar_hall's end state: 15 of 87)


def _closed(topo, fence, z, deg):
    """certify on O closed into a cycle: each odd vertex joined to the nearest other one by
    a shortest path of at most MAX_JOIN edges (a T-join, as the fence closes crossings), then
    the certificate's slack search around them. None if no such closure exists."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import shortest_path

    from coordinator.certificate import certify
    n = topo.n
    u, v = topo.edges[:, 0], topo.edges[:, 1]
    g = csr_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
    odd = [int(x) for x in np.nonzero(deg)[0]]
    zz = z.copy()
    eid = {(int(a), int(b)): i for i, (a, b) in enumerate(zip(u, v))}
    while len(odd) >= 2:
        a = odd.pop(0)
        dist, pred = shortest_path(g, directed=False, unweighted=True, indices=[a],
                                   return_predecessors=True)
        b = min(odd, key=lambda x: dist[0, x])
        if not dist[0, b] <= MAX_JOIN:
            return None
        odd.remove(b)
        x = b
        while x != a:
            p = int(pred[0, x])
            zz[eid[(min(p, x), max(p, x))]] ^= True
            x = p
    added = int((zz & ~z).sum())
    if not zz.any() or added > MAX_ADDED * int(z.sum()):
        return None
    fence.z = zz
    fence.z_repair = np.nonzero(zz & ~z)[0] if (zz & ~z).any() else np.array([0])
    return certify(topo, fence)

"""Rips complex (2-skeleton) built from neighbour reports (spec section 2).

Inputs are per-robot reports: the visible neighbour ids with their bearings (rad, the
reporting robot's body frame) and an optional touch contact. No positions anywhere.

Node ids are arbitrary ints (robot ids or vertex ids, the caller decides). Internally
every array uses *local indices* 0..n-1 into the sorted ``Complex.ids``; since the ids
are sorted, comparing local indices compares ids.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, Mapping

import numpy as np

__all__ = [
    "RobotReport",
    "as_report",
    "Complex",
    "build_complex",
    "add_robot",
    "remove_robot",
]

_I64 = np.int64


@dataclass(frozen=True)
class RobotReport:
    """What one robot reports.

    neighbours: visible robot id -> bearing (rad, body frame, CCW, in [-pi, pi)).
    touch: an obstacle contact is active. touch_bearing: contact direction (rad, body
    frame); None if unknown (then the contact cannot be used by the both-touch rule).
    """

    neighbours: Mapping[int, float]
    touch: bool = False
    touch_bearing: float | None = None


def _node_ids(keys, where: str) -> list[int]:
    """Node ids from mapping keys: all ints (Python or numpy) or all decimal strings, none
    negative, no two naming the same robot; ValueError naming the problem otherwise."""
    keys = list(keys)
    if all(type(k) is int for k in keys):  # the common case: plain ints, one per robot
        if keys and min(keys) < 0:
            raise ValueError(f"{where}: negative robot ids {[k for k in keys if k < 0][:5]} (ids must be >= 0)")
        if len(set(keys)) != len(keys):
            raise ValueError(f"{where}: robot ids repeat: {keys}")
        return keys
    kinds = set()
    out = []
    for k in keys:
        if isinstance(k, (bool, np.bool_)):
            raise ValueError(f"{where}: robot id {k!r} is a bool, not an int")
        if isinstance(k, (int, np.integer)):
            kinds.add("int")
            out.append(int(k))
        elif isinstance(k, str) and k.strip().lstrip("+-").isdigit():
            kinds.add("str")
            out.append(int(k))
        else:
            raise ValueError(f"{where}: robot id {k!r} ({type(k).__name__}) is not an integer id")
    if len(kinds) > 1:
        ints = {int(k) for k in keys if not isinstance(k, str)}
        same = [k for k in keys if isinstance(k, str) and int(k) in ints]
        raise ValueError(f"{where}: robot ids mix ints and strings"
                         + (f" ({same[0]!r} and {int(same[0])} would collapse)" if same else "")
                         + "; use one key type")
    neg = [k for k, i in zip(keys, out) if i < 0]
    if neg:
        raise ValueError(f"{where}: negative robot ids {neg[:5]} (ids must be >= 0)")
    if len(set(out)) != len(out):
        seen, dup = set(), []
        for k, i in zip(keys, out):
            if i in seen:
                dup.append(k)
            seen.add(i)
        raise ValueError(f"{where}: robot ids {dup[:5]} name the same robot as another key")
    return out


def as_report(r: Any, where: str = "report") -> RobotReport:
    """Accept a :class:`RobotReport` or a plain dict.

    Dict forms: ``{"neighbours": {id: bearing}, "touch": bool, "touch_bearing": rad}``
    or ``{"neighbours": [ids], "bearings": [rad], ...}`` (``neighbors`` also accepted).
    """
    if isinstance(r, RobotReport):
        nids = _node_ids(r.neighbours.keys(), f"{where}: neighbours")
        if all(type(k) is int for k in r.neighbours):
            return r
        return RobotReport(dict(zip(nids, r.neighbours.values())), r.touch, r.touch_bearing)
    if not isinstance(r, Mapping):
        raise TypeError(f"cannot read a robot report from {type(r).__name__}")
    nb = r.get("neighbours", r.get("neighbors", {}))
    if not isinstance(nb, Mapping):
        ids = list(nb)
        br = list(r.get("bearings", ()))
        if len(br) != len(ids):
            raise ValueError("neighbour ids and bearings differ in length")
        if len(set(map(repr, ids))) != len(ids):
            raise ValueError(f"{where}: neighbour ids repeat: {ids}")
        nb = dict(zip(ids, br))
    tb = r.get("touch_bearing")
    nids = _node_ids(nb.keys(), f"{where}: neighbours")
    return RobotReport(
        neighbours=dict(zip(nids, (float(v) for v in nb.values()))),
        touch=bool(r.get("touch", False)),
        touch_bearing=None if tb is None else float(tb),
    )


def _ro(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


class Complex:
    """2-skeleton of the Rips complex plus the measurements it was built from.

    Attributes (all numpy, read-only):
      ids (n,) int64: sorted node ids; local index p <-> node ids[p].
      edges (E, 2) int64: local indices, u < v in each row, rows sorted.
      triangles (T, 3) int64: local indices, a < b < c in each row, rows sorted.
      bearings (E, 2) float64: [theta^u_v, theta^v_u] (rad, body frame of the first
        robot of each pair) for edge (u, v).
      touch (n,) bool and touch_bearing (n,) float64 (rad, body frame; nan if none).
    """

    def __init__(self, ids, edges, triangles, bearings, touch, touch_bearing):
        self.ids = _ro(np.ascontiguousarray(ids, dtype=_I64))
        self.edges = _ro(np.ascontiguousarray(edges, dtype=_I64).reshape(-1, 2))
        self.triangles = _ro(np.ascontiguousarray(triangles, dtype=_I64).reshape(-1, 3))
        self.bearings = _ro(np.ascontiguousarray(bearings, dtype=np.float64).reshape(-1, 2))
        self.touch = _ro(np.ascontiguousarray(touch, dtype=bool))
        self.touch_bearing = _ro(np.ascontiguousarray(touch_bearing, dtype=np.float64))

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        return int(self.ids.shape[0])

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    def __repr__(self) -> str:
        return f"Complex(n={self.n}, edges={self.n_edges}, triangles={self.n_triangles})"

    # ------------------------------------------------------------ id mapping
    def index(self, node_ids) -> np.ndarray:
        """Local indices of node ids (array-like). KeyError for unknown ids."""
        q = np.asarray(node_ids, dtype=_I64)
        p = np.searchsorted(self.ids, q)
        p = np.minimum(p, max(self.n - 1, 0))
        if self.n == 0 or np.any(self.ids[p] != q):
            missing = q[(self.ids[p] != q)] if self.n else q
            raise KeyError(f"unknown node ids: {np.atleast_1d(missing)[:5].tolist()}")
        return p

    def index_of(self, node_id: int) -> int:
        return int(self.index([node_id])[0])

    def __contains__(self, node_id: int) -> bool:
        p = int(np.searchsorted(self.ids, node_id))
        return p < self.n and int(self.ids[p]) == int(node_id)

    def edge_nodes(self, edge_idx=None) -> np.ndarray:
        """(k, 2) node ids of edges (all edges if edge_idx is None)."""
        e = self.edges if edge_idx is None else self.edges[np.asarray(edge_idx, dtype=_I64)]
        return self.ids[e]

    def triangle_nodes(self, tri_idx=None) -> np.ndarray:
        """(k, 3) node ids of triangles (all if tri_idx is None)."""
        t = self.triangles if tri_idx is None else self.triangles[np.asarray(tri_idx, dtype=_I64)]
        return self.ids[t]

    # ----------------------------------------------------------- lookups
    @cached_property
    def edge_keys(self) -> np.ndarray:
        """Sorted int64 keys u*n+v of the edges (row order of ``edges``)."""
        return _ro(self.edges[:, 0] * self.n + self.edges[:, 1])

    def edge_index(self, a, b) -> np.ndarray:
        """Edge ids for local-index pairs (any order); -1 where no edge."""
        a = np.asarray(a, dtype=_I64)
        b = np.asarray(b, dtype=_I64)
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        return _lookup(self.edge_keys, lo * self.n + hi)

    @cached_property
    def triangle_keys(self) -> np.ndarray:
        n = self.n
        t = self.triangles
        return _ro((t[:, 0] * n + t[:, 1]) * n + t[:, 2])

    def triangle_index(self, a, b, c) -> np.ndarray:
        """Triangle ids for local-index triples (any order); -1 where none."""
        s = np.sort(np.stack([np.asarray(a, _I64), np.asarray(b, _I64), np.asarray(c, _I64)], -1), -1)
        n = self.n
        return _lookup(self.triangle_keys, (s[..., 0] * n + s[..., 1]) * n + s[..., 2])

    @cached_property
    def adjacency(self):
        """Directed CSR adjacency: (indptr, nbr, edge, bearing).

        Row p lists the neighbours q of p in increasing order, the edge id of {p, q} and
        theta^p_q (rad, p's body frame).
        """
        n, E = self.n, self.n_edges
        u, v = self.edges[:, 0], self.edges[:, 1]
        src = np.concatenate([u, v])
        dst = np.concatenate([v, u])
        eid = np.concatenate([np.arange(E, dtype=_I64)] * 2)
        brg = np.concatenate([self.bearings[:, 0], self.bearings[:, 1]])
        order = np.lexsort((dst, src))
        indptr = np.zeros(n + 1, dtype=_I64)
        np.cumsum(np.bincount(src, minlength=n), out=indptr[1:])
        return _ro(indptr), _ro(dst[order]), _ro(eid[order]), _ro(brg[order])

    @cached_property
    def degree(self) -> np.ndarray:
        indptr = self.adjacency[0]
        return _ro(np.diff(indptr))

    @cached_property
    def tri_edges(self) -> np.ndarray:
        """(T, 3) edge ids of each triangle (a, b, c): [ab, ac, bc]."""
        t = self.triangles
        if t.shape[0] == 0:
            return _ro(np.zeros((0, 3), dtype=_I64))
        n = self.n
        keys = np.stack([t[:, 0] * n + t[:, 1], t[:, 0] * n + t[:, 2], t[:, 1] * n + t[:, 2]], 1)
        return _ro(np.searchsorted(self.edge_keys, keys).astype(_I64))

    @cached_property
    def edge_triangles(self):
        """CSR (indptr, tri): the triangles containing each edge."""
        return _csr(self.tri_edges.ravel(), np.repeat(np.arange(self.n_triangles, dtype=_I64), 3), self.n_edges)

    @cached_property
    def vertex_triangles(self):
        """CSR (indptr, tri): the triangles containing each vertex."""
        return _csr(self.triangles.ravel(), np.repeat(np.arange(self.n_triangles, dtype=_I64), 3), self.n)

    def neighbours(self, node_id: int) -> np.ndarray:
        """Node ids of the neighbours of ``node_id``."""
        p = self.index_of(node_id)
        indptr, nbr = self.adjacency[0], self.adjacency[1]
        return self.ids[nbr[indptr[p]:indptr[p + 1]]]

    def bearing(self, i: int, j: int) -> float:
        """theta^i_j (rad, i's body frame) for adjacent node ids i, j."""
        a, b = self.index([i, j])
        e = int(self.edge_index(a, b))
        if e < 0:
            raise KeyError(f"no edge {{{i}, {j}}}")
        return float(self.bearings[e, 0] if a < b else self.bearings[e, 1])

    def adjacency_sets(self) -> list[set[int]]:
        """Neighbour sets over local indices (fresh, mutable)."""
        indptr, nbr = self.adjacency[0], self.adjacency[1]
        lst = nbr.tolist()
        ip = indptr.tolist()
        return [set(lst[ip[p]:ip[p + 1]]) for p in range(self.n)]


def _lookup(sorted_keys: np.ndarray, q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=_I64)
    if sorted_keys.shape[0] == 0:
        return np.full(q.shape, -1, dtype=_I64)
    p = np.searchsorted(sorted_keys, q)
    pc = np.minimum(p, sorted_keys.shape[0] - 1)
    return np.where(sorted_keys[pc] == q, pc, -1).astype(_I64)


def _csr(rows: np.ndarray, vals: np.ndarray, nrows: int):
    order = np.argsort(rows, kind="stable")
    indptr = np.zeros(nrows + 1, dtype=_I64)
    np.cumsum(np.bincount(rows, minlength=nrows), out=indptr[1:])
    return _ro(indptr), _ro(vals[order].astype(_I64))


def _triangles_from_edges(n: int, edges: np.ndarray) -> np.ndarray:
    """All 3-cliques (a < b < c) of the graph with sorted edge rows ``edges``."""
    E = edges.shape[0]
    if E == 0:
        return np.zeros((0, 3), dtype=_I64)
    u, v = edges[:, 0], edges[:, 1]
    keys = u * n + v
    # forward CSR: for each a, its neighbours c > a in increasing order (= edge rows)
    indptr = np.zeros(n + 1, dtype=_I64)
    np.cumsum(np.bincount(u, minlength=n), out=indptr[1:])
    # edge e = (a, b) sits at row position e inside a's forward list; candidates c are
    # the later entries of that list (c > b).
    start = np.arange(E, dtype=_I64) + 1
    stop = indptr[u + 1]
    cnt = stop - start
    total = int(cnt.sum())
    if total == 0:
        return np.zeros((0, 3), dtype=_I64)
    rep = np.repeat(np.arange(E, dtype=_I64), cnt)
    offs = np.arange(total, dtype=_I64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    c = v[start[rep] + offs]
    b = v[rep]
    hit = _lookup(keys, b * n + c) >= 0
    tri = np.stack([u[rep][hit], b[hit], c[hit]], 1)
    return tri  # already lexicographically sorted (edge order, then c)


def _edges_from_directed(n: int, src: np.ndarray, dst: np.ndarray, brg: np.ndarray):
    """Keep {u, v} only when u lists v and v lists u. Returns (edges, bearings)."""
    ok = src != dst
    src, dst, brg = src[ok], dst[ok], brg[ok]
    dkey = src * n + dst
    order = np.argsort(dkey, kind="stable")
    dkey, src, dst, brg = dkey[order], src[order], dst[order], brg[order]
    # drop duplicate directed reports (keep first)
    if dkey.shape[0]:
        first = np.ones(dkey.shape[0], dtype=bool)
        first[1:] = dkey[1:] != dkey[:-1]
        dkey, src, dst, brg = dkey[first], src[first], dst[first], brg[first]
    fwd = src < dst
    back = _lookup(dkey, dst[fwd] * n + src[fwd])
    keep = back >= 0
    u = src[fwd][keep]
    v = dst[fwd][keep]
    b_uv = brg[fwd][keep]
    b_vu = brg[back[keep]]
    edges = np.stack([u, v], 1)
    bearings = np.stack([b_uv, b_vu], 1)
    return edges, bearings  # sorted by key since dkey sorted and u < v


def _plain_report(r: Any):
    """(neighbours, touch, touch_bearing) of a report that needs no conversion -- a dict
    whose "neighbours" dict maps plain non-negative ints to floats (or numpy float64s:
    they go into a float64 array as they are), a bool "touch" (or
    none) and a float or None "touch_bearing", as the planner builds them -- else None
    (:func:`as_report` then converts it, or says what is wrong). What as_report would
    return for it, without its per-report checks (most of build_complex's time at 1,000
    robots)."""
    if type(r) is not dict:
        return None
    nb = r.get("neighbours")
    t = r.get("touch", False)
    b = r.get("touch_bearing")
    if (type(nb) is not dict or type(t) is not bool
            or not (b is None or type(b) is float)
            or not all(type(k) is int and k >= 0 for k in nb)
            or not all(type(v) is float or type(v) is np.float64 for v in nb.values())):
        return None
    return nb, t, b


def build_complex(reports: Mapping[int, Any]) -> Complex:
    """Build the 2-skeleton from per-robot reports (spec 2.1 with symmetric visibility).

    Keeps {i, j} only when i lists j and j lists i; neighbour ids without a report are
    ignored. Triangles are all 3-cliques. Bearings of both directions are stored.
    """
    ids_in = _node_ids(reports.keys(), "build_complex")
    reps = {}
    for i, (k, r) in zip(ids_in, reports.items()):
        got = _plain_report(r)
        if got is None:
            rr = as_report(r, f"build_complex: report of robot {k!r}")
            got = (rr.neighbours, rr.touch, rr.touch_bearing)
        reps[i] = got
    ids = np.array(sorted(reps), dtype=_I64)
    n = ids.shape[0]
    src_l: list[int] = []
    dst_l: list[float] = []
    brg_l: list[float] = []
    touch = np.zeros(n, dtype=bool)
    tb = np.full(n, np.nan)
    for p, rid in enumerate(ids.tolist()):
        nb, t, b = reps[rid]
        src_l.extend([p] * len(nb))
        dst_l.extend(nb.keys())
        brg_l.extend(nb.values())
        if t:
            touch[p] = True
            if b is not None:
                tb[p] = b
    src = np.array(src_l, dtype=_I64)
    dst_ids = np.array(dst_l, dtype=_I64)
    brg = np.array(brg_l, dtype=np.float64)
    if n:
        pos = np.minimum(np.searchsorted(ids, dst_ids), n - 1)
        known = ids[pos] == dst_ids
    else:
        pos = dst_ids
        known = np.zeros(0, dtype=bool)
    edges, bearings = _edges_from_directed(n, src[known], pos[known], brg[known])
    tris = _triangles_from_edges(n, edges)
    return Complex(ids, edges, tris, bearings, touch, tb)


def remove_robot(cx: Complex, node_id: int) -> Complex:
    """The complex without ``node_id`` (its edges and triangles dropped, others kept)."""
    p = cx.index_of(node_id)
    ke = ~np.any(cx.edges == p, axis=1)
    kt = ~np.any(cx.triangles == p, axis=1)
    edges = cx.edges[ke]
    tris = cx.triangles[kt]
    edges = edges - (edges > p)
    tris = tris - (tris > p)
    keep_v = np.ones(cx.n, dtype=bool)
    keep_v[p] = False
    return Complex(cx.ids[keep_v], edges, tris, cx.bearings[ke], cx.touch[keep_v], cx.touch_bearing[keep_v])


def add_robot(cx: Complex, reports: Mapping[int, Any], node_id: int) -> Complex:
    """The complex with robot ``node_id`` added, using ``reports[node_id]`` and the
    neighbours' current reports (for the symmetric check and the reverse bearings).

    Only the new robot's edges and triangles are computed; existing simplices are kept.
    """
    node_id = int(node_id)
    if node_id in cx:
        raise ValueError(f"node {node_id} already in the complex")
    if node_id < 0:
        raise ValueError(f"add_robot: negative robot id {node_id} (ids must be >= 0)")
    r = as_report(reports[node_id], f"add_robot: report of robot {node_id}")
    n_old = cx.n
    p = int(np.searchsorted(cx.ids, node_id))
    ids = np.insert(cx.ids, p, node_id)
    shift = lambda a: a + (a >= p)  # noqa: E731  old local index -> new local index
    new_nb: list[int] = []
    b_new: list[float] = []
    b_back: list[float] = []
    for j, th in r.neighbours.items():
        j = int(j)
        if j == node_id or j not in cx:
            continue
        rj = reports.get(j)
        if rj is None:
            continue
        rj = as_report(rj, f"add_robot: report of robot {j}")
        back = rj.neighbours.get(node_id)
        if back is None:
            continue
        new_nb.append(cx.index_of(j))
        b_new.append(float(th))
        b_back.append(float(back))
    nb_old = np.array(sorted(set(new_nb)), dtype=_I64)
    order = {q: k for k, q in enumerate(new_nb)}
    # new edges (p, shift(q)) oriented low-high
    qn = shift(nb_old)
    bn = np.array([b_new[order[q]] for q in nb_old.tolist()], dtype=np.float64)
    bb = np.array([b_back[order[q]] for q in nb_old.tolist()], dtype=np.float64)
    lo = np.minimum(qn, p)
    hi = np.maximum(qn, p)
    fwd_is_new = lo == p  # bearing[:, 0] belongs to the lower id
    e_new = np.stack([lo, hi], 1)
    br_new = np.stack([np.where(fwd_is_new, bn, bb), np.where(fwd_is_new, bb, bn)], 1)
    # new triangles: p with each existing edge among its neighbours
    if nb_old.shape[0] >= 2:
        a, b = np.triu_indices(nb_old.shape[0], 1)
        qa, qb = nb_old[a], nb_old[b]
        has = cx.edge_index(qa, qb) >= 0
        t_new = np.sort(np.stack([np.full(int(has.sum()), p, _I64), shift(qa[has]), shift(qb[has])], 1), 1)
    else:
        t_new = np.zeros((0, 3), dtype=_I64)
    edges = np.concatenate([shift(cx.edges), e_new]) if n_old else e_new
    bearings = np.concatenate([cx.bearings, br_new])
    tris = np.concatenate([shift(cx.triangles), t_new])
    n = n_old + 1
    eo = np.argsort(edges[:, 0] * n + edges[:, 1], kind="stable")
    to = np.lexsort((tris[:, 2], tris[:, 1], tris[:, 0])) if tris.shape[0] else np.zeros(0, _I64)
    touch = np.insert(cx.touch, p, bool(r.touch))
    tb = np.insert(cx.touch_bearing, p, np.nan if (not r.touch or r.touch_bearing is None) else r.touch_bearing)
    return Complex(ids, edges[eo], tris[to], bearings[eo], touch, tb)

"""The swarm's shape from bearings alone, and lattice targets for new robots.

Bearings between robots that see each other fix a triangulated swarm's shape up to
translation, rotation and scale (bearing rigidity); the distances the coordinator itself
commanded (a new robot's clear test drive of known length from its parent vertex) fix the
scale. Nothing here uses positions from outside the swarm.

* ``align_headings(nbrs, kinds)``: each occupant's body-frame heading relative to a root
  (spec 4.7's mutual-bearing relation, least squares over every mutual edge); all zero
  when every robot is holonomic (their frames are parallel).
* ``estimate_shape(nbrs, headings, known)``: vertex positions in the root's frame (rv's
  unit) by linear least squares on the bearing constraints n(beta_uv) . (x_v - x_u) = 0
  with the mean edge pinned and a weak prior that each edge is about one mean edge long
  (``EDGE_PRIOR``: the scale of a part the bearings leave free), scaled by the median
  ratio of known to estimated lengths.
* ``lattice_target(...)``: the point of a triangular lattice of spacing d0 that a frontier
  robot should deploy to: beyond the fence edge, within reach of both its ends, not next
  to any robot already there.

Pure functions over numpy/scipy, no I/O.
"""
from __future__ import annotations

import math
from collections import deque
from itertools import chain
from typing import Iterable, Mapping

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix, identity
from scipy.sparse.csgraph import breadth_first_order
from scipy.sparse.linalg import splu, spsolve

from swarmcover.ground.angles import wrap

__all__ = ["align_headings", "estimate_shape", "Lattice", "lattice_target"]

# Weight of the length prior, one row per bearing report: EDGE_PRIOR . (u_ab . (x_b - x_a) - 1)
# = 0, u_ab the reported bearing's unit vector (the edge about one mean edge long; bearing
# rows have weight 1). Bearings fix a triangulated part's shape up to scale, but a part
# joined to the rest by one vertex (a hinge) or by a chain has a scale of its own, which the
# bearings leave free: the one mean-edge gauge let such parts stretch, and on pillar_hall
# seed 2 a cycle's estimate had an edge 3.9 times its length and the swarm's other robots
# 2.2 rv (median) from where it put them; the lattice targets of those cycles fell on
# robots already there. With the prior, the same runs' estimates put every robot within
# 0.011 rv (pillar_hall seed 2) and 0.048 rv (structured seed 0) of where it was, 99 times
# in 100, against 1.08 and 0.65 rv without (a translation fitted within 2.5 rv of each
# robot). Its cost: noisy bearings pull a part with a free scale to shrink, against a
# prior that grows as EDGE_PRIOR^2 (a fan hinged on one robot: 0.04 rv off at 0.5 deg of
# bearing noise, 0.14 rv at 1 deg), and it bends a weakly rigid swarm a little toward
# equal edges (exact bearings, 2,000 random swarms of 3-40: median 0.003 rv, worst
# 0.033). tests/test_topology_shape.py checks both.
EDGE_PRIOR = 0.05

# estimate_shape solves swarms of up to this many vertices by the dense normal equations
# (as first written, plus the length prior), larger ones by the sparse bordered system
# (the same solution to ~1e-9 rv; 1.2 s -> 15 ms at 1,000 robots)
_DENSE_MAX = 200


def align_headings(nbrs: Mapping[int, Mapping[int, float]], kinds: Mapping[int, str] | None = None,
                   root: int | None = None, iterations: int = 2) -> dict[int, float]:
    """Heading (rad) of each vertex's occupant relative to ``root``'s (root = 0).

    Two robots a, b that see each other satisfy phi_a - phi_b = wrap(th^b_a - th^a_b + pi)
    (spec 4.7). Breadth-first from the root over mutual edges, each vertex takes the
    circular mean of what its already-placed neighbours imply; then ``iterations``
    least-squares rounds over every mutual edge. Vertices reached by no
    mutual edge get 0. With every robot holonomic (no rotation), all headings are 0.
    """
    verts = sorted(int(v) for v in nbrs)
    if not verts:
        return {}
    if kinds is not None and all(k == "holonomic" for k in kinds.values()):
        return {v: 0.0 for v in verts}
    root = verts[0] if root is None or root not in nbrs else int(root)
    phi = {root: 0.0}
    queue = deque([root])
    while queue:
        a = queue.popleft()
        for b in nbrs.get(a, {}):
            b = int(b)
            if b in phi or b not in nbrs:
                continue
            s = c = 0.0
            for w, th_bw in nbrs[b].items():  # every placed mutual neighbour of b votes
                w = int(w)
                if w in phi and b in nbrs.get(w, {}):
                    est = phi[w] - wrap(nbrs[b][w] - nbrs[w][b] + math.pi)
                    s += math.sin(est)
                    c += math.cos(est)
            if s == 0.0 and c == 0.0:
                continue
            phi[b] = math.atan2(s, c)
            queue.append(b)
    # least squares over every mutual edge (Gauss-Newton on the wrapped residuals): the
    # spanning tree's chained noise is spread over all the loops (the root stays at 0)
    placed = sorted(phi)
    if len(placed) > 1:
        col = {v: k for k, v in enumerate(placed)}
        for _ in range(iterations):
            rows, cols, vals, rhs = [], [], [], []
            r = 0
            for a in placed:
                for b, th_ab in nbrs[a].items():
                    b = int(b)
                    if b in col and a < b and a in nbrs.get(b, {}):
                        meas = wrap(nbrs[b][a] - th_ab + math.pi)  # phi_a - phi_b
                        rows += [r, r]
                        cols += [col[a], col[b]]
                        vals += [1.0, -1.0]
                        rhs.append(wrap(meas - (phi[a] - phi[b])))
                        r += 1
            rows.append(r)
            cols.append(col[root])
            vals.append(10.0)
            rhs.append(0.0)
            r += 1
            A = coo_matrix((vals, (rows, cols)), shape=(r, len(placed))).tocsr()
            M = (A.T @ A + 1e-9 * identity(len(placed), format="csr")).tocsc()
            delta = spsolve(M, A.T @ np.asarray(rhs, float))
            for v in placed:
                phi[v] = wrap(phi[v] + float(delta[col[v]]))
    return {v: phi.get(v, 0.0) for v in verts}


def _estimate_shape_dense(nbrs: Mapping[int, Mapping[int, float]], headings: Mapping[int, float],
                   known: Iterable[tuple[int, int, float]] = (), *, root: int | None = None,
                   default_edge: float = 0.85) -> dict[int, np.ndarray]:
    """:func:`estimate_shape` by the normal equations A^T A x = A^T b, the scale-gauge
    row included (which makes them dense: O(N^2) memory, about N^3 time). Kept for swarms
    of up to ``_DENSE_MAX`` vertices, where it is cheap: their results stay bit-for-bit
    what this code gives (a closed-loop run amplifies even 1e-13 rad of difference in a
    commanded direction into another trajectory)."""
    verts = sorted(int(v) for v in nbrs)
    if not verts:
        return {}
    root = verts[0] if root is None or root not in nbrs else int(root)
    comp = {root}
    stack = [root]
    while stack:
        a = stack.pop()
        for b in nbrs.get(a, {}):
            b = int(b)
            if b in nbrs and b not in comp:
                comp.add(b)
                stack.append(b)
    order = sorted(comp)
    if len(order) == 1:
        return {root: np.zeros(2)}
    col = {v: i for i, v in enumerate(order)}
    rows, cols, vals, rhs = [], [], [], []
    r = 0

    def add(row: int, a: int, b: int, ux: float, uy: float) -> None:
        """Coefficients of (ux, uy) . (x_b - x_a) in ``row``."""
        ia, ib = col[a], col[b]
        rows.extend((row, row, row, row))
        cols.extend((2 * ib, 2 * ib + 1, 2 * ia, 2 * ia + 1))
        vals.extend((ux, uy, -ux, -uy))

    world = {}
    for a in order:
        pa = headings.get(a, 0.0)
        for b, th in nbrs[a].items():
            b = int(b)
            if b in col and b != a:
                beta = pa + th
                world[(a, b)] = beta
                add(r, a, b, -math.sin(beta), math.cos(beta))  # no sideways offset
                rhs.append(0.0)
                r += 1
                # the length prior (EDGE_PRIOR): the edge about one mean edge long
                add(r, a, b, EDGE_PRIOR * math.cos(beta), EDGE_PRIOR * math.sin(beta))
                rhs.append(EDGE_PRIOR)
                r += 1
    # scale gauge, one row: the mean of the edges' lengths along their bearings is 1
    w = 10.0 * math.sqrt(len(world))
    for (a, b), beta in world.items():
        add(r, a, b, math.cos(beta) * w / len(world), math.sin(beta) * w / len(world))
    rhs.append(w)
    r += 1
    # translation gauge: the root at the origin
    i0 = col[root]
    for k in range(2):
        rows.append(r)
        cols.append(2 * i0 + k)
        vals.append(10.0)
        rhs.append(0.0)
        r += 1
    A = coo_matrix((vals, (rows, cols)), shape=(r, 2 * len(order))).tocsr()
    # normal equations, with a whisker of ridge so flexible parts (a single-file chain of
    # unknown length) stay finite instead of making the system singular
    M = (A.T @ A + 1e-9 * identity(2 * len(order), format="csr")).tocsc()
    sol = spsolve(M, A.T @ np.asarray(rhs, float)).reshape(-1, 2)
    ratios = []
    for a, b, d in known:
        a, b = int(a), int(b)
        if a in col and b in col and ((a, b) in world or (b, a) in world) and d > 0:
            est = float(np.hypot(*(sol[col[b]] - sol[col[a]])))
            if est > 1e-9:
                ratios.append(d / est)
    scale = float(np.median(ratios)) if ratios else float(default_edge)
    return {v: scale * sol[col[v]] for v in order}


def estimate_shape(nbrs: Mapping[int, Mapping[int, float]], headings: Mapping[int, float],
                   known: Iterable[tuple[int, int, float]] = (), *, root: int | None = None,
                   default_edge: float = 0.85) -> dict[int, np.ndarray]:
    """Vertex positions (root's frame, rv units) from bearings and known lengths.

    nbrs: vertex -> {neighbour vertex: bearing (rad, occupant's body frame)}. headings:
    from :func:`align_headings`. known: (a, b, length) for vertex pairs whose distance the
    coordinator commanded. The shape comes from the bearings, with the mean edge pinned to
    1 (noisy bearing rows would otherwise pull the estimate to shrink) and each edge held
    weakly to that length (``EDGE_PRIOR``: a part hinged on one robot, or joined by a
    chain, has a scale the bearings leave free); the scale is then the median of known
    length / estimated length over the known pairs (robust to pairs that drifted since),
    or ``default_edge`` without any. Only the connected component of ``root`` (default:
    the lowest vertex) is returned.
    Up to ``_DENSE_MAX`` vertices by the dense normal equations (``_estimate_shape_dense``),
    above by a sparse bordered system with the same solution.
    """
    if len(nbrs) <= _DENSE_MAX:
        return _estimate_shape_dense(nbrs, headings, known, root=root, default_edge=default_edge)
    verts = sorted(int(v) for v in nbrs)
    root = verts[0] if root is None or root not in nbrs else int(root)
    # every directed report a -> b between vertices (a in vertex order, b in a's order),
    # as arrays: the Python loops over them were most of the time at 1,000 robots
    V = np.array(verts, dtype=np.int64)
    nb = [nbrs[a] for a in verts]
    lens = np.fromiter((len(d) for d in nb), dtype=np.int64, count=len(nb))
    src = np.repeat(np.arange(len(verts), dtype=np.int64), lens)
    total = int(lens.sum())
    dst_id = np.fromiter(chain.from_iterable(nb), dtype=np.int64, count=total)
    th = np.fromiter(chain.from_iterable(d.values() for d in nb), dtype=float, count=total)
    dst = np.minimum(np.searchsorted(V, dst_id), len(verts) - 1)
    ok = (V[dst] == dst_id) & (dst != src)
    src, dst, th = src[ok], dst[ok], th[ok]
    # the part reachable from the root along reports
    i_root = int(np.searchsorted(V, root))
    G = csr_matrix((np.ones(src.shape[0]), (src, dst)), shape=(len(verts), len(verts)))
    reach = np.zeros(len(verts), dtype=bool)
    reach[breadth_first_order(G, i_root, directed=True, return_predecessors=False)] = True
    order = V[reach].tolist()
    if len(order) == 1:
        return {root: np.zeros(2)}
    col_of = np.cumsum(reach) - 1                 # vertex index -> column
    keep = reach[src]                             # (then b is reachable too)
    ia, ib = col_of[src[keep]], col_of[dst[keep]]
    head = np.fromiter((headings.get(a, 0.0) for a in verts), dtype=float, count=len(verts))
    # one bearing row per directed report a -> b: n(beta_ab) . (x_b - x_a) = 0, n the
    # normal of the world bearing beta_ab = heading_a + theta^a_b (no sideways offset)
    beta = head[src[keep]] + th[keep]
    m = 2 * len(order)
    k = ia.shape[0]
    nx, ny = -np.sin(beta), np.cos(beta)
    # then one length-prior row per report (EDGE_PRIOR): the edge about one mean edge long
    px, py = EDGE_PRIOR * np.cos(beta), EDGE_PRIOR * np.sin(beta)
    rows = np.repeat(np.arange(2 * k, dtype=np.int64), 4)
    cols = np.tile(np.stack([2 * ib, 2 * ib + 1, 2 * ia, 2 * ia + 1], 1), (2, 1)).ravel()
    vals = np.concatenate([np.stack([nx, ny, -nx, -ny], 1),
                           np.stack([px, py, -px, -py], 1)]).ravel()
    prior_rhs = np.concatenate([np.zeros(k), np.full(k, EDGE_PRIOR), [0.0, 0.0]])
    # translation gauge: the root at the origin (two rows of weight 10)
    i0 = int(col_of[i_root])
    rows = np.concatenate([rows, [2 * k, 2 * k + 1]])
    cols = np.concatenate([cols, [2 * i0, 2 * i0 + 1]])
    vals = np.concatenate([vals, [10.0, 10.0]])
    A = coo_matrix((vals, (rows, cols)), shape=(2 * k + 2, m)).tocsr()
    # scale gauge, one row g: the mean of the edges' lengths along their bearings is w/w = 1
    # (the shape from the bearings alone, with the mean edge pinned: noisy bearing rows
    # would otherwise pull the estimate to shrink)
    w = 10.0 * math.sqrt(k)
    g = np.zeros(m)
    np.add.at(g, 2 * ib, np.cos(beta) * w / k)
    np.add.at(g, 2 * ib + 1, np.sin(beta) * w / k)
    np.add.at(g, 2 * ia, -np.cos(beta) * w / k)
    np.add.at(g, 2 * ia + 1, -np.sin(beta) * w / k)
    # normal equations (S + g g^T) x = w g, with S = A^T A plus a whisker of ridge so
    # flexible parts (a single-file chain of unknown length) stay finite instead of making
    # the system singular. g couples every vertex: S + g g^T is dense and its sparse LU
    # grew as N^3 (1.2 s at 1,000 robots). Solved instead as the bordered system
    # [[S, g], [g^T, -1]] [x; y] = [w g; 0] (y = g . x), sparse, with the same solution
    # (to ~1e-9 rv), factored in a symmetric ordering with threshold pivoting (it keeps to
    # the diagonal unless a pivot is below a tenth of its column: 3-4x fewer fill-ins than
    # spsolve's partial pivoting) and small relaxed supernodes (relax 2: 8.4 -> 4.7 ms at
    # 1,000 robots, 14.0 -> 11.5 ms at 2,000, best of 21).
    S = (A.T @ A + 1e-9 * identity(m, format="csr")).tocoo()
    nz = np.nonzero(g)[0]
    K = coo_matrix((np.concatenate([S.data, g[nz], g[nz], [-1.0]]),
                    (np.concatenate([S.row, nz, np.full(nz.shape, m), [m]]),
                     np.concatenate([S.col, np.full(nz.shape, m), nz, [m]]))),
                   shape=(m + 1, m + 1)).tocsc()
    lu = splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, relax=2, panel_size=10,
              options=dict(SymmetricMode=True))
    sol = lu.solve(np.append(w * g + A.T @ prior_rhs, 0.0))[:m].reshape(-1, 2)
    col = dict(zip(order, range(len(order))))
    ratios = []
    for a, b, d in known:
        a, b = int(a), int(b)
        if (a in col and b in col and a != b and (b in nbrs[a] or a in nbrs[b])
                and d > 0):
            est = float(np.hypot(*(sol[col[b]] - sol[col[a]])))
            if est > 1e-9:
                ratios.append(d / est)
    scale = float(np.median(ratios)) if ratios else float(default_edge)
    return dict(zip(order, scale * sol))


class Lattice:
    """A triangular lattice of spacing d: origin (2,), first axis angle (rad)."""

    def __init__(self, origin, angle: float, d: float):
        self.origin = np.asarray(origin, float).reshape(2)
        self.d = float(d)
        self._angle = float(angle)
        a1 = np.array([math.cos(angle), math.sin(angle)])
        a2 = np.array([math.cos(angle + math.pi / 3), math.sin(angle + math.pi / 3)])
        self.basis = self.d * np.stack([a1, a2], 1)  # columns a1, a2

    def fitted(self, points) -> "Lattice":
        """The same lattice shifted to fit ``points`` (n, 2) best: the circular mean of
        their offsets within the lattice cell. Estimated positions drift (the root's
        robot is replaced, the scale is estimated); fitting the lattice to the robots
        near a deployment keeps the new one on the lattice its neighbours are on."""
        P = np.asarray(points, float).reshape(-1, 2)
        if not len(P):
            return self
        c = np.linalg.solve(self.basis, (P - self.origin).T)  # (2, n) lattice coordinates
        z = np.exp(2j * np.pi * c).mean(axis=1)
        shift = np.angle(z) / (2 * np.pi)
        return Lattice(self.origin + self.basis @ shift, self._angle, self.d)

    def near(self, p, rings: int = 2) -> np.ndarray:
        """Lattice points around p (within ``rings`` lattice steps of its cell)."""
        c = np.linalg.solve(self.basis, np.asarray(p, float) - self.origin)
        i0, j0 = (int(math.floor(x)) for x in c)
        ii, jj = np.mgrid[i0 - rings:i0 + rings + 2, j0 - rings:j0 + rings + 2]
        ij = np.stack([ii.ravel(), jj.ravel()], 0).astype(float)
        return self.origin + (self.basis @ ij).T


def lattice_target(lattice: Lattice, pf, po, side_dir, others, *, reach: float,
                   min_sep: float, min_dist: float, blocked=(), side_from=None) -> np.ndarray | None:
    """The lattice point a frontier robot at pf deploys to, or None.

    po: the fence edge's other end, which the point must also be within ``reach`` of
    (None: no such condition). side_dir: unit vector into the open side (the spec's own
    direction); side_from: the point whose line through pf bounds the open side (default
    po; None with po None: the half-plane facing side_dir). others: (n, 2) estimated
    positions of robots and of this cycle's other targets; a candidate keeps ``min_sep``
    from each and ``min_dist`` from pf. blocked: directions (rad) of walls felt at pf; a
    candidate within 90 deg of one is out. Of the rest, the one nearest the spec's target
    pf + d * side_dir wins.
    """
    pf = np.asarray(pf, float)
    u = np.asarray(side_dir, float)
    L = lattice.near(pf)
    rel = L - pf
    df = np.hypot(rel[:, 0], rel[:, 1])
    ok = (df <= reach) & (df >= min_dist)
    ref = po if side_from is None else side_from
    if ref is not None:
        fo = np.asarray(ref, float) - pf
        side = np.sign(fo[0] * u[1] - fo[1] * u[0])
        if side == 0:
            return None
        ok &= np.sign(fo[0] * rel[:, 1] - fo[1] * rel[:, 0]) == side
    else:
        ok &= rel @ u > 0
    if po is not None:
        ok &= np.hypot(*(L - np.asarray(po, float)).T) <= reach
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    for w in blocked:
        ok &= np.cos(ang - w) <= 0.0
    L = L[ok]
    if not len(L):
        return None
    Q = np.asarray(others, float).reshape(-1, 2)
    if len(Q):
        dmin = np.min(np.linalg.norm(L[:, None, :] - Q[None, :, :], axis=2), axis=1)
        L = L[dmin >= min_sep]
        if not len(L):
            return None
    want = pf + lattice.d * u
    return L[int(np.argmin(np.linalg.norm(L - want, axis=1)))]

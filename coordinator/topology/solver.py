"""The certificate's solver: boundary(alpha) = z over GF(2) on one complex (spec 5.3).

:mod:`coordinator.topology.certificate` states the criterion and decides it with
:class:`_Solver`, one per complex, shared by every target solved on it. Ids are local
edge and triangle ids of the ``Complex`` (no positions, no bearings). Shapes: E =
``Complex.n_edges``, T = ``Complex.n_triangles``, n = ``Complex.n``; an edge mask is
bool (E,), a chain is int64 triangle ids; the forms phi are uint64 (E, W), one bit per
critical row, W = ceil(critical rows / 64) words.

How it is solved (all on the complex alone, no positions):

1. A spanning forest (BFS from a central vertex) fixes a vertex order. The rows of the
   forest edges are redundant for cycles and are dropped.
2. A lower-star discrete Morse matching pairs every other edge (u, v) (v the later
   vertex) with a triangle of v's lower link (BFS inside the lower link, done for all
   links at once by scipy on the "link graph"). Unmatched edges are *critical rows*,
   unmatched triangles *critical columns*.
3. With critical columns set to 0, the matched rows form a triangular system; it is
   solved by peeling (an edge with one undetermined triangle fixes that triangle),
   vectorised round by round. The residual on the (few) critical rows is then fixed
   with critical triangles through the Schur complement, computed by one transposed
   peeling pass with the critical rows packed as bits (inactivation): the forms phi.
4. A target with odd vertices is closed by one more elimination (coordinator.topology.gf2):
   z_raw + f is a boundary iff it is a cycle and its forms lie in the span of the
   critical triangles' forms, both linear in f. The Fence's shortest T-join
   (``Fence.z_repair``) is tried first when it lies in the zone.
5. When the residual is not in the span, the witness y of the elimination gives psi.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from . import gf2
from .complex import Complex

__all__: list[str] = []

_I64 = np.int64


def _dedupe(a: np.ndarray) -> np.ndarray:
    if a.shape[0] < 2:
        return a
    a = np.sort(a)
    keep = np.empty(a.shape[0], dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


# --------------------------------------------------------------------- Morse matching
def _vertex_forest(cx: Complex, seed: int | None):
    """BFS forest over the 1-skeleton rooted near the centre of the largest component.

    Returns (rank (n,), tree edge mask (E,)).
    """
    n, E = cx.n, cx.n_edges
    indptr, nbr = cx.adjacency[0], cx.adjacency[1]
    g = csr_matrix((np.ones(nbr.shape[0]), nbr.astype(np.int32), indptr.astype(np.int32)), shape=(n, n))
    s0 = int(seed) if seed is not None and 0 <= int(seed) < n else int(np.argmax(cx.degree)) if n else 0
    order = breadth_first_order(g, s0, directed=True, return_predecessors=False) if n else np.zeros(0, _I64)
    if n and order.shape[0] == n:
        ncomp, lab = 1, np.zeros(n, dtype=_I64)
    else:
        ncomp, lab = connected_components(g, directed=True, connection="weak")
    roots = np.full(ncomp, -1, dtype=_I64)
    roots[lab[::-1]] = np.arange(n - 1, -1, -1, dtype=_I64)  # smallest index per component
    if n and E:
        # centre the seed's component: farthest vertex, then the middle of a longest path
        big = int(lab[s0])
        far = int(order[-1])
        order2, pred = breadth_first_order(g, far, directed=True, return_predecessors=True)
        path = [int(order2[-1])]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        roots[big] = path[len(path) // 2]
    # one BFS from a super-root n whose only edges go to the component roots
    ip2 = np.concatenate([indptr, [indptr[-1] + ncomp]]).astype(np.int32)
    g2 = csr_matrix((np.ones(nbr.shape[0] + ncomp), np.concatenate([nbr, roots]).astype(np.int32), ip2),
                    shape=(n + 1, n + 1))
    order, pred = breadth_first_order(g2, n, directed=True, return_predecessors=True)
    rank = np.empty(n + 1, dtype=_I64)
    rank[order] = np.arange(order.shape[0], dtype=_I64)
    rank = rank[:n]
    pred = pred[:n]
    child = np.nonzero((pred >= 0) & (pred < n))[0]
    tree = np.zeros(E, dtype=bool)
    if child.size:
        tree[cx.edge_index(child, pred[child])] = True
    return rank, tree


def _lower_star_matching(cx: Complex, rank: np.ndarray, tree: np.ndarray):
    """Match non-forest edges with triangles by a spanning forest of every lower link.

    The lower link of v (v later than its neighbours u in ``rank``) has one node per edge
    (u, v) and one link edge per triangle (u, w, v). Level-synchronous BFS over all links
    at once, rooted at the forest edges; nodes left over seed one more root per star
    until every node is reached. A non-root node (u, v) reached from (w, v) is matched
    with the triangle (u, w, v); any rooted spanning forest gives an acyclic matching.
    Returns (match (E,) triangle id or -1, critical row ids = the extra roots).
    """
    E, T = cx.n_edges, cx.n_triangles
    match = np.full(E, -1, dtype=_I64)
    if T == 0:
        return match, np.nonzero(~tree)[0]
    tri, te = cx.triangles, cx.tri_edges
    top = np.argmax(rank[tri], axis=1)
    pick = np.array([[0, 1], [0, 2], [1, 2]], dtype=_I64)[top]
    ar = np.arange(T, dtype=_I64)
    ea = te[ar, pick[:, 0]]
    eb = te[ar, pick[:, 1]]
    owner = np.where(rank[cx.edges[:, 0]] > rank[cx.edges[:, 1]], cx.edges[:, 0], cx.edges[:, 1])
    visited = tree.copy()
    front = tree.copy()
    crit: list[np.ndarray] = []
    while True:
        while True:
            m1 = front[ea] & ~visited[eb]
            m2 = front[eb] & ~visited[ea]
            if not (m1.any() or m2.any()):
                break
            nodes = np.concatenate([eb[m1], ea[m2]])
            tris = np.concatenate([ar[m1], ar[m2]])
            nodes, first = np.unique(nodes, return_index=True)
            visited[nodes] = True
            match[nodes] = tris[first]
            front[:] = False
            front[nodes] = True
        rest = np.nonzero(~visited)[0]
        if rest.size == 0:
            break
        # one new root per star that still has unreached nodes (smallest edge id)
        own = owner[rest]
        o = np.argsort(own, kind="stable")
        own_s = own[o]
        firsts = np.ones(own_s.shape[0], dtype=bool)
        firsts[1:] = own_s[1:] != own_s[:-1]
        roots = rest[o[firsts]]
        crit.append(roots)
        visited[roots] = True
        front[:] = False
        front[roots] = True
    critical = np.sort(np.concatenate(crit)) if crit else np.zeros(0, dtype=_I64)
    return match, critical


# ---------------------------------------------------------------------------- peeling
def _forward(cx: Complex, z: np.ndarray, tree: np.ndarray, match: np.ndarray):
    """Solve the triangular (matched) part with every critical column at 0.

    Returns (x uint8 (T,), rhs after elimination (E,), rounds list of (rows, cols)).
    """
    E, T = cx.n_edges, cx.n_triangles
    te = cx.tri_edges
    x = np.zeros(T, dtype=np.uint8)
    rhs = z.astype(np.uint8)
    matched_rows = np.nonzero(match >= 0)[0]
    mcols = match[matched_rows]
    active = ~tree  # rows still taking updates (not forest, not yet solved)
    cnt = np.bincount(te[mcols].ravel(), minlength=E).astype(_I64) if mcols.size else np.zeros(E, _I64)
    is_m = match >= 0
    front = matched_rows[cnt[matched_rows] == 1]
    rounds = []
    done = 0
    while front.size:
        cols = match[front]
        xv = rhs[front]
        x[cols] = xv
        active[front] = False
        done += front.shape[0]
        rounds.append((front, cols))
        ed = te[cols]
        f = ed.ravel()
        f = f[active[f]]
        np.subtract.at(cnt, f, 1)
        f1 = ed[xv.astype(bool)].ravel()
        f1 = f1[active[f1]]
        if f1.size:
            np.bitwise_xor.at(rhs, f1, np.uint8(1))
        front = _dedupe(f[(cnt[f] == 1) & is_m[f]])
    if done != matched_rows.shape[0]:  # pragma: no cover - the matching is acyclic
        raise AssertionError("peeling stalled on an acyclic matching")
    return x, rhs, rounds


def _replay(cx: Complex, z: np.ndarray, tree: np.ndarray, rounds, fixed_one: np.ndarray) -> np.ndarray:
    """Re-run the recorded elimination with the critical columns ``fixed_one`` at 1."""
    te = cx.tri_edges
    x = np.zeros(cx.n_triangles, dtype=np.uint8)
    rhs = z.astype(np.uint8)
    x[fixed_one] = 1
    np.bitwise_xor.at(rhs, te[fixed_one].ravel(), np.uint8(1))
    active = ~tree
    for rows, cols in rounds:
        xv = rhs[rows]
        x[cols] = xv
        active[rows] = False
        f1 = te[cols[xv.astype(bool)]].ravel()
        f1 = f1[active[f1]]
        if f1.size:
            np.bitwise_xor.at(rhs, f1, np.uint8(1))
    return x


def _transpose_forms(cx: Complex, tree: np.ndarray, crit: np.ndarray, rounds, W: int) -> np.ndarray:
    """Cocycle forms phi (E, W) uint64 over the critical-row symbols.

    phi is the unit vector on critical rows, 0 on forest rows, and on matched rows the
    unique value making every matched triangle's coboundary vanish.
    """
    E = cx.n_edges
    te = cx.tri_edges
    phi = np.zeros((E, W), dtype=np.uint64)
    k = np.arange(crit.shape[0], dtype=_I64)
    phi[crit, k // 64] = np.left_shift(np.uint64(1), (k % 64).astype(np.uint64))
    for rows, cols in reversed(rounds):
        ed = te[cols]
        phi[rows] = phi[ed[:, 0]] ^ phi[ed[:, 1]] ^ phi[ed[:, 2]]
    return phi


def _to_int(row: np.ndarray) -> int:
    return int.from_bytes(row.astype("<u8").tobytes(), "little")


# ------------------------------------------------------------------------- witnesses
def _flow_witness(cx: Complex, z: np.ndarray, max_rounds: int = 100000) -> np.ndarray:
    """Push z inward: while an edge of the current cycle has exactly one unused triangle,
    add that triangle. Returns the cycle left (edge mask)."""
    E, T = cx.n_edges, cx.n_triangles
    te = cx.tri_edges
    r = z.copy()
    if T == 0:
        return r
    used = np.zeros(T, dtype=bool)
    cnt = np.diff(cx.edge_triangles[0]).astype(_I64)
    rx = np.zeros(E, dtype=_I64)
    np.bitwise_xor.at(rx, te.ravel(), np.repeat(np.arange(T, dtype=_I64), 3))
    cand = np.nonzero(r & (cnt == 1))[0]
    it = 0
    while cand.size and it < max_rounds:
        it += 1
        t = np.unique(rx[cand])
        t = t[~used[t]]
        if t.size == 0:
            break
        used[t] = True
        f = te[t].ravel()
        np.logical_xor.at(r, f, True)
        np.subtract.at(cnt, f, 1)
        np.bitwise_xor.at(rx, f, np.repeat(t, 3))
        f = np.unique(f)
        cand = f[r[f] & (cnt[f] == 1)]
    return r


# --------------------------------------------------------------------------- solver
class _Solver:
    """The forest, the Morse matching and (lazily) the forms phi of one complex: shared
    by every target solved on it."""

    def __init__(self, cx: Complex, seed: int | None, stats: dict):
        self.cx = cx
        self.stats = stats
        self.rank, self.tree = _vertex_forest(cx, seed)
        self.match, self.crit = _lower_star_matching(cx, self.rank, self.tree)
        stats["critical_rows"] = int(self.crit.size)
        stats["matched"] = int((self.match >= 0).sum())
        self.rounds = None
        self._core = None

    def _forward(self, z: np.ndarray):
        x, rhs, rounds = _forward(self.cx, z, self.tree, self.match)
        if self.rounds is None:
            self.rounds = rounds
            self.stats["rounds"] = len(rounds)
        return x, rhs

    def core(self):
        """(phi (E, W) uint64, patterns (ints), representative critical triangles)."""
        if self._core is None:
            cx, crit = self.cx, self.crit
            if self.rounds is None:
                self._forward(np.zeros(cx.n_edges, dtype=bool))
            W = max(1, (crit.size + 63) // 64)
            phi = _transpose_forms(cx, self.tree, crit, self.rounds, W)
            is_matched_col = np.zeros(cx.n_triangles, dtype=bool)
            is_matched_col[self.match[self.match >= 0]] = True
            ccols = np.nonzero(~is_matched_col)[0]
            te = cx.tri_edges
            S = phi[te[ccols, 0]] ^ phi[te[ccols, 1]] ^ phi[te[ccols, 2]]
            nz = np.any(S != 0, axis=1)
            ccols, S = ccols[nz], S[nz]
            if S.shape[0]:
                if W == 1:
                    u1, first = np.unique(S[:, 0], return_index=True)
                    uniq = u1[:, None]
                else:
                    uniq, first = np.unique(S, axis=0, return_index=True)
                reps = ccols[first]
            else:
                uniq, reps = S, ccols
            self._core = (phi, [_to_int(row) for row in uniq], reps)
            self.stats["core"] = (int(crit.size), len(self._core[1]))
        return self._core

    def solve(self, z: np.ndarray):
        """(chain, None) with boundary(chain) = z for a cycle z, or (None, y): y over the
        critical-row bits, orthogonal to every pattern, odd on z's forms."""
        x, rhs = self._forward(z)
        resid = rhs[self.crit].astype(bool)
        if not resid.any():
            return np.nonzero(x)[0], None
        phi, patterns, reps = self.core()
        target = 0
        for k in np.nonzero(resid)[0].tolist():
            target |= 1 << k
        subset, y = gf2.solve(patterns, target)
        if subset is None:
            return None, y
        fixed = np.asarray(reps[subset], dtype=_I64)
        self.stats["fixed_critical"] = int(fixed.size)
        return np.nonzero(_replay(self.cx, z, self.tree, self.rounds, fixed))[0], None

    def closure(self, z_raw: np.ndarray, odd: np.ndarray, zone: np.ndarray):
        """(f, None): zone edges f with z_raw + f a boundary; or (None, psi): a cocycle
        (edge mask) missing the zone with |psi & z_raw| odd.

        Columns: the critical triangles' patterns (vertex part 0), and per zone edge its
        forms plus one bit for each end (vertex bits above the critical rows, over the
        zone's vertices only). Target: z_raw's forms plus its odd vertices.
        """
        cx = self.cx
        phi, patterns, _ = self.core()
        nc = self.crit.size
        u, v = cx.edges[:, 0], cx.edges[:, 1]
        zv = np.unique(np.concatenate([odd, u[zone], v[zone]]))
        vbit = np.full(cx.n, -1, dtype=_I64)
        vbit[zv] = nc + np.arange(zv.size, dtype=_I64)
        cols = list(patterns)
        k0 = len(cols)
        for e, a, b in zip(zone.tolist(), vbit[u[zone]].tolist(), vbit[v[zone]].tolist()):
            cols.append(_to_int(phi[e]) | (1 << a) | (1 << b))
        target = _to_int(np.bitwise_xor.reduce(phi[z_raw], axis=0)) if z_raw.any() else 0
        for a in vbit[odd].tolist():
            target ^= 1 << a
        subset, y = gf2.solve(cols, target)
        if subset is not None:
            f = np.zeros(cx.n_edges, dtype=bool)
            f[zone[[i - k0 for i in subset if i >= k0]]] = True
            return f, None
        g = np.zeros(cx.n, dtype=bool)
        g[zv[gf2.bits(y >> nc)]] = True
        return None, self.cocycle(y & ((1 << nc) - 1)) ^ (g[u] != g[v])

    def cocycle(self, y: int) -> np.ndarray:
        """The edge mask of sum_k y_k phi_k."""
        phi = self.core()[0]
        W = phi.shape[1]
        ybits = np.array([(y >> (64 * w)) & 0xFFFFFFFFFFFFFFFF for w in range(W)], dtype=np.uint64)
        return (np.bitwise_count(phi & ybits).sum(axis=1) & 1).astype(bool)

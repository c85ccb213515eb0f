"""Local geometry of the fence from bearings alone: per-vertex neighbour bearings and
the tests :mod:`coordinator.topology.fence` applies at one edge's ends.

No positions: a robot p knows its neighbours' bearings (rad, p's body frame, ``wrap``-ped
to (-pi, pi]) and its touch flag and contact bearing (``Complex.touch`` /
``Complex.touch_bearing``). p, q, u, v, k, m, l are local vertex indices (``Complex``
rows, not node ids); sigma, a side, is +1 (counter-clockwise) or -1 as seen at the end
named (``_canon`` turns it into the canonical side of fence.py's docstring).

* ``_Local``: the neighbour bearings of each vertex (dict node -> rad, built lazily from
  the complex's CSR), nearest neighbour on a side, clearance of a bearing, angular gaps.
* ``_is_exception``: the tightened exception rule (spec 3.2), an edge one-sided by its
  triangles yet covered on its open side.
* ``_corner``: the convex-corner / occlusion case (spec 3.3 ii).
* ``_reflex``: an end's open wedge on a side is wider than ``_REFLEX``.
* ``_touch_ok``: a wall contact that counts (no neighbour within tau of it).
"""
from __future__ import annotations

import math

from swarmcover.ground.angles import wrap
from .complex import Complex

__all__: list[str] = []

# A reflex open side (its wedge at an end wider than _REFLEX: the end sits where the front
# turns, at the mouth of a passage) gets a second probe _DEEP off the edge once the 60-deg
# drive touched; the side is closed only when that one touches too. A 0.5 m passage above a
# box (structured, seed 1) was closed when the 60-deg drives from both ends of its mouth hit
# the box, with the passage itself, straight ahead of one end, never driven into.
_REFLEX = 7.0 * math.pi / 6.0
_DEEP = 2.0 * math.pi / 3.0


def _sgn(a: float) -> int:
    return 1 if a > 0.0 else (-1 if a < 0.0 else 0)


class _Local:
    """Per-vertex neighbour data, built lazily from the complex CSR."""

    def __init__(self, cx: Complex):
        self.indptr = cx.adjacency[0]
        self.nbr = cx.adjacency[1]
        self.eid = cx.adjacency[2]
        self.brg = cx.adjacency[3]
        self._d: dict[int, dict[int, float]] = {}

    def bearings(self, p: int) -> dict[int, float]:
        d = self._d.get(p)
        if d is None:
            a, b = int(self.indptr[p]), int(self.indptr[p + 1])
            d = dict(zip(self.nbr[a:b].tolist(), self.brg[a:b].tolist()))
            self._d[p] = d
        return d

    def nearest_on_side(self, p: int, ref: int, sigma: int, thin: float = 0.0):
        """Neighbour l != ref of p with sign(theta^p_{ref l}) = sigma and the smallest
        |angle|; returns (l, |angle|) or (None, None). thin: neighbours under this angle
        that ref sees too are skipped (a near-collinear triangle p-ref-l whose side test
        fell on this side by noise says nothing about the side)."""
        d = self.bearings(p)
        t0 = d[ref]
        dref = self.bearings(ref) if thin > 0.0 else {}
        best, best_a = None, None
        for l, tl in d.items():
            if l == ref:
                continue
            a = wrap(tl - t0)
            if _sgn(a) == sigma:
                aa = abs(a)
                if aa < thin and l in dref:
                    continue
                if best_a is None or aa < best_a:
                    best, best_a = l, aa
        return best, best_a

    def clearance(self, p: int, bearing: float) -> float:
        d = self.bearings(p)
        if not d:
            return math.pi
        return min(abs(wrap(bearing - t)) for t in d.values())

    def gap(self, p: int, phi: float):
        """Neighbours (a, b) bounding the angular gap of p containing bearing phi: a is
        the nearest clockwise, b the nearest counter-clockwise. (None, None) if none."""
        d = self.bearings(p)
        if not d:
            return None, None
        a = min(d, key=lambda l: (wrap(phi - d[l]) % (2 * math.pi), l))
        b = min(d, key=lambda l: (wrap(d[l] - phi) % (2 * math.pi), l))
        return a, b

    def same_gap(self, p: int, phi: float, psi: float) -> bool:
        """True if bearings phi and psi of p lie in the same gap between neighbours."""
        d = self.bearings(p)
        if not d:
            return True
        two_pi = 2 * math.pi

        def clear(a: float, b: float) -> bool:  # no neighbour strictly inside the CCW sweep a -> b
            span = wrap(b - a) % two_pi
            return not any(0.0 < wrap(t - a) % two_pi < span for t in d.values())

        return clear(phi, psi) or clear(psi, phi)


def _canon(p: int, q: int, side_at_p: int) -> int:
    """Canonical side of edge {p, q} (local indices) from the side seen at p."""
    return side_at_p if p < q else -side_at_p


def _is_exception(L: _Local, u: int, v: int, sigma: int, apexes) -> bool:
    """Tightened exception rule (spec 3.2 [P]) for edge (u, v) open on side sigma (at u)."""
    Bu, Bv = L.bearings(u), L.bearings(v)
    tu_v, tv_u = Bu[v], Bv[u]

    def beyond(m: int) -> bool:
        if m in Bu:
            return _sgn(wrap(Bu[m] - tu_v)) == sigma
        if m in Bv:
            return _sgn(wrap(Bv[m] - tv_u)) == -sigma
        return True

    for k in apexes:
        Bk = L.bearings(k)
        tu, tv = Bk[u], Bk[v]
        whole = wrap(tv - tu)
        s = _sgn(whole)
        if s == 0:
            continue
        W = abs(whole)
        wedge = []
        for m, tm in Bk.items():
            if m == u or m == v:
                continue
            a = wrap(tm - tu) * s
            if 0.0 < a < W:
                wedge.append((a, m))
        if not wedge:
            continue
        wedge.sort()
        # monotone chain u -> m1 -> ... -> v through far-side wedge vertices only
        reach: list[tuple[float, int]] = [(0.0, u)]
        for a, m in wedge:
            if not beyond(m):
                continue
            Bm = L.bearings(m)
            if any(ap < a and p in Bm for ap, p in reach):
                reach.append((a, m))
        if any(p in Bv for _, p in reach[1:]):
            return True
    return False


def _corner(L: _Local, p: int, q: int, k, gap, thr: float) -> bool:
    """The convex-corner / occlusion case (spec 3.3 ii) at p for edge p-q: p's nearest
    neighbour k on the open side is under thr from q, and q and k do not see each other.
    Only then must an obstacle block the view between them; a k that q does see (a
    near-collinear triangle whose side test fell on one side by noise) proves nothing, and
    ``nearest_on_side(thin=thr)`` skips it (bench/truth.py map 11 certified 21.8 % of a room
    through one; deploying at half its gap instead stacked robots on one point, map 129)."""
    return k is not None and gap < thr and k not in L.bearings(q)


def _reflex(L: _Local, p: int, q: int, sigma: int) -> bool:
    """p's open wedge from its neighbour q, turning the sigma way, is reflex (> _REFLEX)."""
    bp = L.bearings(p)
    t0 = bp[q]
    wedge = min(((sigma * (t - t0)) % (2.0 * math.pi) for l, t in bp.items() if l != q),
                default=2.0 * math.pi)
    return wedge > _REFLEX


def _touch_ok(cx: Complex, L: _Local, p: int, tau: float) -> float | None:
    """The contact bearing of p if it counts as an obstacle contact, else None.

    A contact counts only if no neighbour is visible within tau of its direction.
    """
    if not cx.touch[p]:
        return None
    tb = float(cx.touch_bearing[p])
    if math.isnan(tb):
        return None
    for t in L.bearings(p).values():
        if abs(wrap(t - tb)) < tau:
            return None
    return tb


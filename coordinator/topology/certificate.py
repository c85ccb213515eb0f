"""Coverage certificate by relative homology over GF(2) (spec section 5.2-5.3).

The criterion (the only one: :func:`certify` decides it, :func:`verify_certificate`
checks it). The *target* is a set of edges z_raw: a Fence's one-sided fence edges
(``Fence.z_raw``) or an explicit edge set. Its *closure zone* S is, for a Fence, every
edge with both ends within one hop of an odd-degree vertex of z_raw, in z_raw or not, and
every edge of z_raw with both ends within two hops (DROP_HOPS) of one (empty when z_raw is
a cycle, and always empty for an explicit edge set). The target is
*certified* when z_raw is not empty and a set of triangles alpha (the chain) and a set f
of zone edges (the closure) satisfy boundary(alpha) = z_raw + f over GF(2), with z =
z_raw + f not empty; z is the certificate's cycle (an f edge in z_raw leaves it).
Otherwise it is *refused*, with an obstruction: a cocycle psi (every triangle has an even
number of edges in psi) that misses S and meets z_raw an odd number of times, which proves
that no such alpha and f exist. Exactly one of the two holds (Fredholm alternative). An
empty target is refused without an obstruction.

Why it means coverage (robots at their true positions, every edge at most rv long with
line of sight): for a point x on no edge, the number of triangles of alpha containing x
and the number of edges of z crossed by a ray from x agree mod 2 (true for one triangle,
and summing over alpha counts each edge boundary(alpha)_e times). So every point that z
encloses an odd number of times lies in a triangle of alpha, within rv of each of its
three robots (README, "The topology core"). z and z_raw differ only on zone edges, near
the odd vertices, where z_raw encloses nothing well defined (it is not a cycle there).

Why target edges near odd vertices may leave z: Rips triangles overlap. Two triangles on
the same side of a shared edge e (a fold, where edges cross) make e and both their outer
edges one-sided, yet a GF(2) chain counts their overlap twice and cancels e, so no
chain's boundary holds all three (the obstruction is those three edges, a cocycle inside
z_raw, whatever else f may add). Likewise a one-sided edge that other edges cross lies
inside the triangles' union although its own triangle is on one side of it; in the
refused covered end states of bench/truth.py 77 of 78 odd vertices had such an edge
(bench/refusals.py). Dropping an edge only stops the certificate from claiming the
points beside it; every point z encloses an odd number of times is still in a triangle
of alpha. What the zone cannot hide: a run claims coverage only with no frontier edge
and no deployment left (coordinator.planner), and then a boundary point of the
triangles' union lies on an edge with no triangle on its outer side, a one-sided edge
the fence closed as an obstacle on evidence (coordinator.topology.evidence) or reported
as inferred. certify searches the narrowest zone first (only fold edges of z_raw at odd
vertices may leave it), then every edge within one hop, then the whole zone, each only
when the narrower finds no closure: over bench/truth.py seeds 0 and 1 (1,000 maps) the
fold-only zone refused 13 covered end states and the one-hop zone 1 (seed 0 map 58), with
the same false certificates; the one-hop zone also refused the cave's seed-0 end state
(tests/data/cave_refused.json: twenty odd vertices, each on a one-sided edge that other
edges cross, paired two to four hops apart), which dropping target edges within two hops
closes. Added edges stay within one hop: a closure that adds edges two hops out bridged a
2.5 m gap cut in the pillar hall's fence (tests/test_run_report.py), dropping never can
(it only moves a gap's ends apart along z_raw).

How it is solved (a lower-star Morse matching, peeling and one GF(2) elimination, on the
complex alone): :mod:`coordinator.topology.solver`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .complex import Complex
from .solver import _flow_witness, _Solver

__all__ = [
    "Certificate",
    "certify",
    "verify_certificate",
    "boundary_of",
    "is_cocycle",
    "fence_cycle",
    "closure_zone",
    "hop_ball",
    "certificate_from_chain",
]

_I64 = np.int64
_EMPTY = np.zeros(0, dtype=_I64)
# the closure zone's reach for dropping target edges: z_raw's edges with both ends within
# this many hops of an odd vertex (edges it adds stay within one hop: a gap in the fence
# whose ends are farther apart than two hops is never bridged)
DROP_HOPS = 2


def _empty() -> np.ndarray:
    return _EMPTY


@dataclass(frozen=True, eq=False)
class Certificate:
    """Result of :func:`certify`.

    certified: True when boundary(chain) = z = target + closure (module docstring).
    z: edge ids (into ``Complex.edges``) of the certified cycle (the target when refused).
    chain: triangle ids of alpha (empty when refused).
    obstruction: edge ids of a cocycle psi missing the closure zone with |psi & target|
      odd (empty when certified, and when the target is empty).
    hole_edges: when refused, edge ids of a cycle homologous to z that could not be
      filled further by pushing z inward (around the uncovered hole on planar-like
      complexes; the target's edges at its odd vertices when it is not a cycle).
    odd_vertices: node ids where the target has odd degree.
    chain_nodes (k, 3), hole_edge_nodes (k, 2), support: node-id views (support = the
      vertices of the chain).
    stats: counts from the solver (critical rows, peeling rounds, core size, closure).
    target: edge ids of z_raw. closure: edge ids of f (z = target XOR closure). closable: whether the target has
      a closure zone (a Fence's one-sided edges) or is an explicit, exact target.
    """

    certified: bool
    z: np.ndarray
    chain: np.ndarray
    obstruction: np.ndarray
    hole_edges: np.ndarray
    odd_vertices: np.ndarray
    chain_nodes: np.ndarray
    hole_edge_nodes: np.ndarray
    support: np.ndarray
    stats: Mapping[str, Any] = field(default_factory=dict)
    target: np.ndarray = field(default_factory=_empty)
    closure: np.ndarray = field(default_factory=_empty)
    closable: bool = False

    def __bool__(self) -> bool:
        return self.certified


# --------------------------------------------------------------------------- helpers
def _ids(a, n: int, what: str, where: str) -> np.ndarray:
    """Validated ids (ints in [0, n), no repeats) as int64; ValueError naming the problem."""
    arr = np.asarray(a)
    if arr.size == 0:
        return _EMPTY
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        if np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(_I64)
        else:
            raise ValueError(f"{where}: {what} must be integer ids, got dtype {arr.dtype}")
    arr = arr.astype(_I64).ravel()
    bad = arr[(arr < 0) | (arr >= n)]
    if bad.size:
        raise ValueError(f"{where}: {what} out of range [0, {n}): {bad[:5].tolist()}")
    u, c = np.unique(arr, return_counts=True)
    if np.any(c > 1):
        raise ValueError(f"{where}: {what} repeat (a repeated id would cancel over GF(2)): "
                         f"{u[c > 1][:5].tolist()}")
    return arr


def _is_fence(t) -> bool:
    return not isinstance(t, np.ndarray) and hasattr(t, "z_raw")


def _as_edge_mask(cx: Complex, z, where: str = "certify") -> np.ndarray:
    """An explicit target: a bool mask (E,), edge ids, or (k, 2) node-id pairs."""
    if not isinstance(z, np.ndarray) and hasattr(z, "z"):
        z = z.z
    a = np.asarray(z)
    m = np.zeros(cx.n_edges, dtype=bool)
    if a.size == 0:
        return m
    if a.dtype == bool:
        if a.shape != (cx.n_edges,):
            raise ValueError(f"{where}: boolean edge mask has length {a.shape}, the complex has "
                             f"{cx.n_edges} edges")
        return a.copy()
    if a.ndim == 2 and a.shape[1] == 2:
        loc = cx.index(a.ravel()).reshape(-1, 2)
        e = cx.edge_index(loc[:, 0], loc[:, 1])
        if np.any(e < 0):
            raise KeyError(f"{where}: some target edges are not edges of the complex: "
                           f"{a[e < 0][:5].tolist()}")
        e = _ids(e, cx.n_edges, "target edges (node pairs)", where)
    else:
        e = _ids(a, cx.n_edges, "target edge ids", where)
    m[e] = True
    return m


def _target(cx: Complex, target, where: str) -> tuple[np.ndarray, bool]:
    """(mask of z_raw, closable). A Fence gives its one-sided edges and a closure zone;
    an explicit edge set must not be empty."""
    if _is_fence(target):
        m = np.zeros(cx.n_edges, dtype=bool)
        m[_ids(target.z_raw, cx.n_edges, "Fence.z_raw edge ids", where)] = True
        return m, True
    m = _as_edge_mask(cx, target, where)
    if not m.any():
        raise ValueError(f"{where}: the target has no edge (an empty cycle certifies nothing)")
    return m, False


def hop_ball(cx: Complex, seeds: np.ndarray, hops: int) -> np.ndarray:
    """Bool mask over local vertices: those within ``hops`` edges of a ``seeds`` vertex
    (a bool mask over local vertices)."""
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    near = np.asarray(seeds, dtype=bool).copy()
    for _ in range(hops):
        step = near.copy()
        step[v[near[u]]] = True
        step[u[near[v]]] = True
        near = step
    return near


def closure_zone(cx: Complex, z_raw: np.ndarray, *, folds_only: bool = False,
                 drop_hops: int = DROP_HOPS) -> tuple[np.ndarray, np.ndarray]:
    """(odd vertices (local indices), zone edge ids) of a target edge mask: every edge with
    both ends within one hop of an odd-degree vertex of z_raw (a closure may add it, or drop
    it from z_raw), and z_raw's edges with both ends within ``drop_hops`` hops (the
    criterion's: DROP_HOPS; a closure may drop them); module docstring: why.

    folds_only: of z_raw's edges, only the fold edges at an odd vertex (two or more
    triangles; a one-sided edge's triangles all lie on its one side, so they overlap
    there). :func:`certify` searches this narrowest zone first, then the zone with
    drop_hops 1, then the whole zone, so a closure drops any other target edge, or one
    farther off, only when no closure in a narrower zone exists."""
    if not z_raw.any():
        return _EMPTY, _EMPTY
    odd = (np.bincount(cx.edges[z_raw].ravel(), minlength=cx.n) & 1).astype(bool)
    if not odd.any():
        return _EMPTY, _EMPTY
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    near = hop_ball(cx, odd, 1)
    zone = near[u] & near[v]
    if folds_only:
        zone &= ~z_raw | ((np.diff(cx.edge_triangles[0]) >= 2) & (odd[u] | odd[v]))
    elif drop_hops > 1:
        far = hop_ball(cx, odd, drop_hops)
        zone |= z_raw & far[u] & far[v]
    return np.nonzero(odd)[0], np.nonzero(zone)[0]


def boundary_of(cx: Complex, chain) -> np.ndarray:
    """GF(2) boundary of a set of triangle ids, as a bool mask over edges."""
    t = np.asarray(chain, dtype=_I64).ravel()
    if t.size == 0:
        return np.zeros(cx.n_edges, dtype=bool)
    cnt = np.bincount(cx.tri_edges[t].ravel(), minlength=cx.n_edges)
    return (cnt & 1).astype(bool)


def is_cocycle(cx: Complex, edges) -> bool:
    """True if every triangle has an even number of its edges in ``edges`` (edge ids)."""
    m = np.zeros(cx.n_edges, dtype=bool)
    e = np.asarray(edges, dtype=_I64).ravel()
    np.logical_xor.at(m, e, True)
    if cx.n_triangles == 0:
        return True
    return not np.any(m[cx.tri_edges].sum(1) & 1)


def verify_certificate(cx: Complex, cert: Certificate, target=None) -> bool:
    """Check the criterion of the module docstring on a certificate (either outcome).

    target: a Fence (its one-sided edges, with their closure zone), an explicit edge set
    (no closure), or None for the certificate's own target. ValueError for malformed
    certificates (negative, out-of-range or repeated ids) and empty explicit targets.
    Certified: the chain is not empty, the closure lies in the zone and boundary(chain)
    = target + closure = cert.z. Refused: the obstruction is a cocycle that misses the
    zone and meets the target an odd number of times; or the target is empty.
    """
    where = "verify_certificate"
    if target is None:
        zm = np.zeros(cx.n_edges, dtype=bool)
        zm[_ids(cert.target, cx.n_edges, "certificate target edge ids", where)] = True
        closable = bool(cert.closable)
        if not closable and not zm.any():
            raise ValueError(f"{where}: the certificate's target has no edge")
    else:
        zm, closable = _target(cx, target, where)
    chain = _ids(cert.chain, cx.n_triangles, "chain triangle ids", where)
    ob = _ids(cert.obstruction, cx.n_edges, "obstruction edge ids", where)
    f = _ids(cert.closure, cx.n_edges, "closure edge ids", where)
    zc = _ids(cert.z, cx.n_edges, "certificate cycle edge ids", where)
    if not zm.any():
        return not cert.certified
    _, zone = closure_zone(cx, zm) if closable else (_EMPTY, _EMPTY)
    in_zone = np.zeros(cx.n_edges, dtype=bool)
    in_zone[zone] = True
    if cert.certified:
        if chain.size == 0 or not np.all(in_zone[f]):
            return False
        z = zm.copy()
        z[f] ^= True  # an f edge in z_raw leaves it
        zc_m = np.zeros(cx.n_edges, dtype=bool)
        zc_m[zc] = True
        return bool(np.array_equal(zc_m, z) and np.array_equal(boundary_of(cx, chain), z))
    if ob.size == 0 or np.any(in_zone[ob]):
        return False
    return is_cocycle(cx, ob) and bool(zm[ob].sum() & 1)


def _support(cx: Complex, chain: np.ndarray) -> np.ndarray:
    m = np.zeros(cx.n, dtype=bool)
    if chain.size:
        m[cx.triangles[chain].ravel()] = True
    return cx.ids[m]


def _make(cx: Complex, ok: bool, z: np.ndarray, chain, ob, hole, odd, stats, target: np.ndarray,
          closure, closable: bool) -> Certificate:
    chain = np.sort(np.asarray(chain, dtype=_I64))
    hole = np.asarray(hole, dtype=_I64)
    return Certificate(
        certified=ok,
        z=np.nonzero(z)[0],
        chain=chain,
        obstruction=np.sort(np.asarray(ob, dtype=_I64)),
        hole_edges=hole,
        odd_vertices=np.asarray(odd, dtype=_I64),
        chain_nodes=cx.ids[cx.triangles[chain]] if chain.size else np.zeros((0, 3), _I64),
        hole_edge_nodes=cx.ids[cx.edges[hole]] if hole.size else np.zeros((0, 2), _I64),
        support=_support(cx, chain),
        stats=stats,
        target=np.nonzero(target)[0],
        closure=np.sort(np.asarray(closure, dtype=_I64)),
        closable=closable,
    )


def certificate_from_chain(cx: Complex, z, chain, stats: Mapping[str, Any] | None = None, *,
                           like: Certificate | None = None) -> Certificate:
    """Wrap a known chain as a certified Certificate for the explicit cycle z (or, with
    ``like``, for ``like``'s target and closure, z = like.z); ValueError unless the chain's
    triangle ids are valid and boundary(chain) = z."""
    where = "certificate_from_chain"
    zm = _as_edge_mask(cx, z, where)
    chain = np.sort(_ids(chain, cx.n_triangles, "chain triangle ids", where))
    if not zm.any() or chain.size == 0:
        raise ValueError(f"{where}: an empty cycle or chain certifies nothing")
    if not np.array_equal(boundary_of(cx, chain), zm):
        raise ValueError(f"{where}: boundary(chain) != z")
    if like is not None:
        tm = np.zeros(cx.n_edges, dtype=bool)
        tm[like.target] = True
        if not np.array_equal(tm ^ zm, np.isin(np.arange(cx.n_edges), like.closure)):
            raise ValueError(f"{where}: z is not the target plus the closure of ``like``")
        return _make(cx, True, zm, chain, _EMPTY, _EMPTY, like.odd_vertices, dict(stats or {}), tm,
                     like.closure, like.closable)
    return _make(cx, True, zm, chain, _EMPTY, _EMPTY, _EMPTY, dict(stats or {}), zm, _EMPTY, False)


def fence_cycle(cx: Complex, fence) -> np.ndarray:
    """Edge ids of the certificate's target: a Fence's one-sided edges ``z_raw`` (or an
    explicit edge set, validated)."""
    return np.nonzero(_target(cx, fence, "fence_cycle")[0])[0]


# ----------------------------------------------------------------------------- main
def certify(cx: Complex, fence, *, seed: int | None = None) -> Certificate:
    """Decide the criterion of the module docstring: a chain alpha and a closure f in the
    zone with boundary(alpha) = z_raw + f, or an obstruction.

    fence: a Fence (its one-sided edges ``z_raw`` are the target, with a closure zone
    when they leave odd vertices), or an explicit target without closure: a bool edge
    mask, edge ids or (k, 2) node-id pairs (ValueError when empty or repeated). A Fence
    with no one-sided edge is refused (stats["reason"] = "empty target").
    seed: optional local vertex index to start the BFS from.
    """
    E, T = cx.n_edges, cx.n_triangles
    zr, closable = _target(cx, fence, "certify")
    stats: dict[str, Any] = {"edges": E, "triangles": T, "z": int(zr.sum())}

    def result(ok, z, chain=_EMPTY, ob=_EMPTY, hole=_EMPTY, closure=_EMPTY):
        return _make(cx, ok, z, chain, ob, hole, cx.ids[odd], stats, zr, closure, closable)

    if not zr.any():
        odd = _EMPTY
        stats["reason"] = "empty target: no one-sided fence edge"
        return result(False, zr)
    odd, zone = closure_zone(cx, zr) if closable else (_EMPTY, _EMPTY)
    if not closable:  # an explicit target: its odd vertices refuse it at once
        odd = np.nonzero(np.bincount(cx.edges[zr].ravel(), minlength=cx.n) & 1)[0]
        if odd.size:
            star = np.nonzero(np.any(cx.edges == odd[0], axis=1))[0]
            stats["reason"] = "the target is not a cycle"
            return result(False, zr, ob=star, hole=np.nonzero(zr & np.isin(cx.edges, odd).any(1))[0])

    S = _Solver(cx, seed, stats)
    if odd.size == 0:
        chain, y = S.solve(zr)
        if chain is not None:
            _check(cx, chain, zr)
            return result(True, zr, chain)
        stats["reason"] = "the target is not a boundary"
        ob = np.nonzero(S.cocycle(y))[0]
        hole = np.nonzero(_flow_witness(cx, zr))[0]
        return _guard(cx, result(False, zr, ob=ob, hole=hole))

    # odd vertices (edges cross, e.g. around pillars): close z_raw inside the zone
    # first inside the narrowest zone (only fold edges may leave z_raw), then any edge
    # within one hop, then the whole zone (target edges within DROP_HOPS may leave)
    narrow = closure_zone(cx, zr, folds_only=True)[1]
    hint = getattr(fence, "z_repair", None)
    in_zone = np.zeros(E, dtype=bool)
    in_zone[narrow] = True
    if hint is not None and len(hint) and np.all(in_zone[np.asarray(hint, dtype=_I64)]):
        z1 = zr.copy()
        z1[np.asarray(hint, dtype=_I64)] ^= True
        if z1.any() and not (np.bincount(cx.edges[z1].ravel(), minlength=cx.n) & 1).any():
            chain, _ = S.solve(z1)
            if chain is not None:
                _check(cx, chain, z1)
                stats["closure"] = int(len(hint))
                stats["closure_dropped"] = int(zr[np.asarray(hint, dtype=_I64)].sum())
                return result(True, z1, chain, closure=np.asarray(hint, dtype=_I64))
    f, psi = S.closure(zr, odd, narrow)
    searched = len(narrow)
    for name in ("one hop", "whole"):
        if f is not None and (zr ^ f).any():
            break
        wider = zone if name == "whole" else closure_zone(cx, zr, drop_hops=1)[1]
        if len(wider) > searched:
            f, psi = S.closure(zr, odd, wider)
            searched = len(wider)
            stats["closure_zone"] = name
    if f is not None and not (zr ^ f).any():  # a closure never certifies nothing
        stats["reason"] = "the closure empties the target"
        return result(False, zr)
    if f is not None:
        z2 = zr ^ f
        chain, _ = S.solve(z2)
        if chain is None:  # pragma: no cover - the closure search guarantees a boundary
            raise AssertionError("closure search produced a non-boundary")
        _check(cx, chain, z2)
        stats["closure"] = int(f.sum())
        stats["closure_dropped"] = int((f & zr).sum())
        return result(True, z2, chain, closure=np.nonzero(f)[0])
    stats["reason"] = "no closure of the target in its zone is a boundary"
    hole = np.nonzero(zr & np.isin(cx.edges, odd).any(1))[0]
    return _guard(cx, result(False, zr, ob=np.nonzero(psi)[0], hole=hole))


def _check(cx: Complex, chain: np.ndarray, z: np.ndarray) -> None:
    if chain.size == 0 or not np.array_equal(boundary_of(cx, chain), z):  # pragma: no cover
        raise AssertionError("certificate solver produced a wrong chain")


def _guard(cx: Complex, cert: Certificate) -> Certificate:
    if not verify_certificate(cx, cert):  # pragma: no cover - internal bug guard
        raise AssertionError("certificate solver produced a wrong obstruction")
    return cert

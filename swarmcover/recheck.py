"""``run``'s own check of a certificate it is sent, before it says CERTIFIED (pure, no I/O).

The Complex message carries the complex (vertices, edges, triangles), the fence (frontier K,
obstacle O) and the claim; it does not carry the 2-chain. ``recheck`` rebuilds the complex
from the message and checks the claim again:

1. the complex is well formed: edge ends are vertices, every triangle's three edges are
   edges, every vertex is held by a robot, and there is at least one triangle (an empty
   target never certifies);
2. the frontier K is empty;
3. over GF(2), the obstacle edges O are the boundary of a 2-chain of the message's
   triangles up to a closure inside O's one-hop closure zone, the coordinator's own
   criterion (``coordinator.topology.certificate``), solved again on the rebuilt complex;
4. with ground truth (``positions``, the world's): every occupant is a robot of the world,
   every edge joins robots at most rv apart (with ``tol`` for motion since the cycle), and
   every edge whose triangles all lie clearly on one side of it in the world is an
   obstacle or an exception edge of the message (no open side left unclosed).

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
                           "its triangles up to its closure zone; occupants, edge lengths and "
                           "one-sided edges (all obstacle or exception) against ground truth"}


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
        missing = _open_sides_left(el, tl, [positions[o] for o in occ],
                                   set(cx.obstacle) | set(getattr(cx, "exceptions", ()) or ()),
                                   SIDE_MARGIN * rv)
        if missing:
            a, b = el[missing[0]].tolist()
            return Recheck(False, f"{len(missing)} edges with triangles on one side only in the "
                                  f"world are neither obstacle nor exception, e.g. "
                                  f"{verts[a]}-{verts[b]}")
    # GF(2): O must be a boundary of the message's triangles
    from types import SimpleNamespace

    from swarmcover.coordinator.topology.certificate import certify
    from swarmcover.coordinator.topology.complex import Complex as TopoComplex
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
    has_tri = np.diff(topo.edge_triangles[0]) > 0
    for k in cx.obstacle:
        # an obstacle edge with no triangle (a single-file chain walled on both sides) is
        # in no boundary: the certificate's target is the one-sided edges
        if has_tri[new_index[k]]:
            z[new_index[k]] ^= True
    if not z.any():
        return Recheck(False, "no obstacle edge: nothing fences the region")
    # the coordinator's own criterion: O is the target z_raw, closed (where fence edges
    # cross) only by edges of its one-hop closure zone
    cert = certify(topo, SimpleNamespace(z_raw=np.nonzero(z)[0]))
    if not cert.certified:
        return Recheck(False, "the obstacle edges are not the boundary of any 2-chain of the "
                              "complex's triangles")
    return Recheck(True)


SIDE_MARGIN = 0.05   # x rv: an apex nearer an edge's line than this is on neither side


def _apex_sides(tl, P: np.ndarray, margin: float) -> dict[tuple[int, int], set]:
    """For each edge (a, b), a < b, of the triangles ``tl`` (rows of indices into the
    positions ``P``): the sides of the line a -> b its triangles' apexes lie on (+1 left,
    -1 right, 0 within ``margin`` of the line). A NaN position counts as 0."""
    side: dict[tuple[int, int], set] = {}
    for t in np.asarray(tl, np.int64).reshape(-1, 3).tolist():
        for i in range(3):
            u, v, w = t[i], t[(i + 1) % 3], t[(i + 2) % 3]
            a, b = min(u, v), max(u, v)
            d = P[b] - P[a]
            ln = math.hypot(*d)
            c = (d[0] * (P[w] - P[a])[1] - d[1] * (P[w] - P[a])[0]) / ln if ln > 0 else 0.0
            side.setdefault((a, b), set()).add(
                0 if not abs(c) > margin else (1 if c > 0 else -1))
    return side


def _open_sides_left(el, tl, pts, fenced: set, margin: float) -> list[int]:
    """Edges (indices into ``el``) that in the world have triangles clearly on one side
    only (every apex more than ``margin`` off the edge's line, all on one side) and are
    in ``fenced`` (obstacle or exception) neither: sides nobody closed."""
    side = _apex_sides(tl, np.asarray(pts, float).reshape(-1, 2), margin)
    out = []
    for k, (a, b) in enumerate(el.tolist()):
        s = side.get((min(a, b), max(a, b)))
        if s and len(s) == 1 and 0 not in s and k not in fenced:
            out.append(k)
    return out


AUDIT_FRACTIONS = tuple(k / 10 for k in range(1, 10))   # where along an edge rays start


def side_depths(pa, pb, normal, walls, cap: float):
    """(starts (9, 2), depths (9,)): how far (m, at most ``cap``) the free space runs from
    9 points along the side pa-pb (``AUDIT_FRACTIONS``) along the unit ``normal`` before a
    segment of ``walls`` (E, 4)."""
    from swarmcover.world.maps import ray_lengths
    starts = np.asarray(pa, float) + np.outer(AUDIT_FRACTIONS, np.asarray(pb, float) - pa)
    return starts, ray_lengths(starts, np.tile(normal, (len(starts), 1)), walls, cap)


def fence_audit(cx, positions: dict, walls, rv: float, room_depth: float,
                covered=None, raster=None) -> dict:
    """Ground truth on the claim each closed fence side makes (pure, no I/O).

    For every obstacle edge of the Complex message ``cx`` with triangles on one side only
    in the world (``positions``: robot id -> (x, y)), rays leave its open side along the
    normal from 9 points along it, and the deepest free run before a segment of ``walls``
    (E, 4) is its depth (capped at 2 rv). A side deeper than ``room_depth`` (m) has room
    behind it: it was closed although free space goes on there, and only the rest of the
    swarm covers that space. Per reason ('probes' for evidence, 'gap_probes' for the
    evidence of ``gap_probed``, else ``inferred_why``):
    sides, room_behind, and of those how many have the point 0.9 rv into the room along
    the deepest ray (or short of the wall it meets) in ``covered`` (the summary's coverage
    raster, ``raster``'s cells) or not. ``examples`` lists up to 20 room-behind sides."""
    verts = list(cx.vertices)
    loc = {v: i for i, v in enumerate(verts)}
    P = np.array([positions.get(o, (math.nan, math.nan)) for o in cx.occupants],
                 float).reshape(-1, 2)
    E = np.asarray(cx.edges, np.int64).reshape(-1, 2)
    why = {int(k): "gap_probes" for k in getattr(cx, "gap_probed", None) or ()}
    why.update({int(k): str(w) for k, w in zip(getattr(cx, "inferred", None) or (),
                                               getattr(cx, "inferred_why", None) or ())})
    try:
        tl = [[loc[int(x)] for x in t]
              for t in np.asarray(cx.triangles, np.int64).reshape(-1, 3).tolist()]
    except KeyError:
        tl = []                       # a malformed message: recheck says why; no audit
    apex = _apex_sides(tl, P, SIDE_MARGIN * rv)
    rows = []
    for k in sorted(set(int(x) for x in cx.obstacle)):
        if not 0 <= k < len(E) or int(E[k][0]) not in loc or int(E[k][1]) not in loc:
            continue
        a, b = (int(x) for x in E[k])
        ia, ib = loc[a], loc[b]
        pa, pb = (P[ia], P[ib]) if ia < ib else (P[ib], P[ia])
        d = pb - pa
        ln = float(np.hypot(*d))
        if not ln > 0:
            continue                  # a robot not in the world, or two on one point
        signs = apex.get((min(ia, ib), max(ia, ib)), set())
        if len(signs) != 1 or 0 in signs:
            continue                  # no triangle, or triangles on both sides: not one-sided
        normal = -next(iter(signs)) * np.array([-d[1], d[0]]) / ln
        starts, depths = side_depths(pa, pb, normal, walls, 2.0 * rv)
        j = int(np.argmax(depths))
        row = dict(a=a, b=b, why=why.get(k, "probes"), depth_m=float(depths[j]))
        if row["depth_m"] > room_depth and covered is not None and raster is not None:
            q = starts[j] + normal * min(0.9 * rv, row["depth_m"] - raster.cell)
            ix = int(math.floor((q[0] - raster.x0) / raster.cell))
            iy = int(math.floor((q[1] - raster.y0) / raster.cell))
            ny, nx = covered.shape
            row["beyond_covered"] = bool(0 <= iy < ny and 0 <= ix < nx and covered[iy, ix])
        rows.append(row)
    by: dict[str, dict] = {}
    for r in rows:
        s = by.setdefault(r["why"], dict(sides=0, room_behind=0, room_covered=0,
                                         room_uncovered=0, max_depth_rv=0.0))
        s["sides"] += 1
        s["max_depth_rv"] = max(s["max_depth_rv"], round(r["depth_m"] / rv, 3))
        if r["depth_m"] > room_depth:
            s["room_behind"] += 1
            if "beyond_covered" in r:
                s["room_covered" if r["beyond_covered"] else "room_uncovered"] += 1
    deep = sorted((r for r in rows if r["depth_m"] > room_depth), key=lambda r: -r["depth_m"])
    return dict(room_depth_m=room_depth, by_why=by, examples=deep[:20])

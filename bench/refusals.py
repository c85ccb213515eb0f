"""Why are covered end states refused? (issue 21, "at most 1% refusals")

Grows the maps of bench/truth.py (same seeds, same growth loop: ``truth.run_map``),
keeps the end state (true positions, complex, fence) and, for maps certify refuses,
classifies every odd vertex of the target z_raw (coordinator.topology.certificate's docstring)
with the true positions:

* ``interior``: a one-sided edge at the vertex whose open side is covered by other
  triangles of the complex (sampled points beside the edge on both sides lie in
  triangles): the exception rule (fence_local._is_exception) missed it;
* ``crossing``: a one-sided edge at the vertex properly crosses another edge;
* ``flip``: an edge at the vertex whose triangles' apexes lie geometrically on both sides
  while the fence's bearing test put them on one (near-collinear apex, bearing noise);
* ``dup``: the vertex has a neighbour closer than 2 x robot radius (stacked robots);
* ``exc``: an exception edge (fence.exceptions) at the vertex.

It also pairs the odd vertices by a minimum T-join in hops (exact matching DP) and,
for every map, reruns ``certify`` with wider closure zones (edges within k hops of an odd
vertex, k = 1, 2, 3, and 'all' (any edge), adding edges only) and with closures that may
also drop target edges within k hops ('k1t', 'k2t'), so one campaign gives refusals and
false certificates per variant (claim = certified with no frontier, no deployment).
``certify`` itself searches k = 1 with only fold edges droppable, then 'k1t'.

Usage: python bench/refusals.py --maps 500 --seed 0 --jobs 2 --out R.json
       python bench/refusals.py --only 49 57 --seed 0
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench import truth  # noqa: E402
from swarmcover.coordinator.topology.certificate import hop_ball  # noqa: E402

VARIANTS = ("k1", "k2", "k3", "all", "k1t", "k2t")


def grow(seed: int, idx: int, **kw):
    """(row, swarm, cx, fence) of map idx: truth.run_map with its end state kept."""
    import swarmcover.coordinator as coordinator
    box: dict = {}
    real_certify = coordinator.certify
    RealSwarm = truth.Swarm

    class KeepSwarm(RealSwarm):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            box["sw"] = self

    def keep_certify(cx, fence, **k):
        box["cx"], box["fence"] = cx, fence
        return real_certify(cx, fence, **k)

    truth.Swarm = KeepSwarm
    coordinator.certify = keep_certify
    try:
        row = truth.run_map(truth.make_map(seed, idx), **kw)
    finally:
        truth.Swarm = RealSwarm
        coordinator.certify = real_certify
    return row, box["sw"], box["cx"], box["fence"]


def khop_zone(k):
    """A closure_zone replacement: edges outside z_raw with both ends within k hops of an
    odd vertex (k None: every edge outside z_raw). ``folds_only`` and ``drop_hops``
    (certify's narrower zones) are ignored: every variant is one zone."""
    def zone(cx, z_raw, folds_only=False, drop_hops=None):
        if not z_raw.any():
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        odd = (np.bincount(cx.edges[z_raw].ravel(), minlength=cx.n) & 1).astype(bool)
        if not odd.any():
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        u, v = cx.edges[:, 0], cx.edges[:, 1]
        near = np.ones(cx.n, bool) if k is None else hop_ball(cx, odd, k)
        return np.nonzero(odd)[0], np.nonzero(near[u] & near[v] & ~z_raw)[0]
    return zone


def certify_toggle(cx, fence, k):
    """The 'toggle' variant: the closure f may also remove target edges, f any edge with
    both ends within k hops of an odd vertex, z = z_raw XOR f. Returns (certified, ok):
    ok = boundary(chain) == z, z a cycle, f in that zone (checked here, not trusted)."""
    from swarmcover.coordinator.topology import certificate as C
    from swarmcover.coordinator.topology.solver import _Solver
    zr = np.zeros(cx.n_edges, bool)
    zr[np.asarray(fence.z_raw, int)] = True
    if not zr.any():
        return False, True
    odd, zone = khop_zone(k)(cx, zr)
    S = _Solver(cx, None, {})
    if odd.size == 0:
        chain, _ = S.solve(zr)
        return chain is not None, True
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    near_z = np.nonzero(zr & np.isin(u, _ball(cx, odd, k)) & np.isin(v, _ball(cx, odd, k)))[0]
    zone = np.unique(np.concatenate([zone, near_z]))
    f, _ = S.closure(zr, odd, zone)
    if f is None:
        return False, True
    z = zr ^ f
    chain, _ = S.solve(z)
    ok = chain is not None and np.array_equal(C.boundary_of(cx, chain), z) and chain.size > 0
    return chain is not None, bool(ok)


def _ball(cx, odd, k):
    seeds = np.zeros(cx.n, bool)
    seeds[odd] = True
    return np.nonzero(hop_ball(cx, seeds, k))[0]


def certify_with(cx, fence, variant: str):
    from swarmcover.coordinator.topology import certificate as C
    if variant.endswith("t"):
        ok, good = certify_toggle(cx, fence, int(variant[1]))
        return type("C", (), {"certified": ok})(), good
    real = C.closure_zone
    C.closure_zone = khop_zone({"k1": 1, "k2": 2, "k3": 3, "all": None}[variant])
    try:
        cert = C.certify(cx, fence)
        ok = C.verify_certificate(cx, cert, fence)
    finally:
        C.closure_zone = real
    return cert, ok


# ------------------------------------------------------------------- geometry
def _in_tris(P, tri_pts):
    """(m,) True where a point of P (m, 2) lies strictly inside one of the triangles."""
    a, b, c = tri_pts[:, 0], tri_pts[:, 1], tri_pts[:, 2]

    def cross(o, p, q):
        return (p[:, 0] - o[:, 0]) * (q[:, 1] - o[:, 1]) - (p[:, 1] - o[:, 1]) * (q[:, 0] - o[:, 0])

    out = np.zeros(len(P), bool)
    area = cross(a, b, c)
    good = np.abs(area) > 1e-9
    a, b, c, area = a[good], b[good], c[good], area[good]
    for i, x in enumerate(P):
        X = np.broadcast_to(x, a.shape)
        s1, s2, s3 = cross(a, b, X), cross(b, c, X), cross(c, a, X)
        sg = np.sign(area)
        out[i] = bool(np.any((s1 * sg > 0) & (s2 * sg > 0) & (s3 * sg > 0)))
    return out


def _proper_cross(p1, p2, q1, q2):
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    return d1 * d2 < 0 and d3 * d4 < 0


def _hops(cx):
    from scipy.sparse import csr_matrix
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    g = csr_matrix((np.ones(2 * len(u)), (np.concatenate([u, v]), np.concatenate([v, u]))), shape=(cx.n, cx.n))
    return g


def min_tjoin_pairs(D: np.ndarray):
    """Exact minimum perfect matching on a small even set (bitmask DP); [(i, j, d)]."""
    m = D.shape[0]
    from functools import lru_cache

    @lru_cache(maxsize=None)
    def best(mask):
        if mask == 0:
            return 0.0, ()
        i = (mask & -mask).bit_length() - 1
        rest = mask & ~(1 << i)
        out = (np.inf, ())
        j = rest
        while j:
            b = (j & -j).bit_length() - 1
            j &= j - 1
            c, pr = best(rest & ~(1 << b))
            c += D[i, b]
            if c < out[0]:
                out = (c, ((i, b),) + pr)
        return out

    if m > 22:
        return None
    _, pairs = best((1 << m) - 1)
    return [(i, j, float(D[i, j])) for i, j in pairs]


def classify(sw, cx, fence) -> dict:
    """Per odd vertex of z_raw: its classes; per map: the hop T-join."""
    from scipy.sparse.csgraph import shortest_path

    pts = sw.points()
    zr = np.zeros(cx.n_edges, bool)
    zr[np.asarray(fence.z_raw, int)] = True
    deg = np.bincount(cx.edges[zr].ravel(), minlength=cx.n)
    odd = np.nonzero(deg & 1)[0]
    exc = set(np.asarray(fence.exceptions, int).tolist())
    tri_pts = pts[cx.ids[cx.triangles]] if cx.n_triangles else np.zeros((0, 3, 2))
    eptr, etri = cx.edge_triangles
    vout = []
    for p in odd.tolist():
        cls = set()
        nb = cx.neighbours(int(cx.ids[p]))
        dmin = float(np.min(np.linalg.norm(pts[nb] - pts[cx.ids[p]], axis=1))) if len(nb) else np.inf
        if dmin < 2 * truth.RADIUS:
            cls.add("dup")
        inc = np.nonzero(np.any(cx.edges == p, axis=1))[0]
        if any(int(e) in exc for e in inc):
            cls.add("exc")
        ntri = 0
        for e in inc[zr[inc]].tolist():
            a, b = pts[cx.ids[cx.edges[e]]]
            d = b - a
            L = float(np.linalg.norm(d))
            nrm = np.array([-d[1], d[0]]) / max(L, 1e-12)
            ts = np.array([0.2, 0.35, 0.5, 0.65, 0.8])
            mid = a[None] + ts[:, None] * d[None]
            left = _in_tris(mid + 0.01 * nrm, tri_pts)
            right = _in_tris(mid - 0.01 * nrm, tri_pts)
            if np.all(left) and np.all(right):
                cls.add("interior")
            elif np.any(left) and np.any(right):
                cls.add("partly_interior")
            # apex sides
            sides = set()
            for t in etri[eptr[e]:eptr[e + 1]].tolist():
                c = pts[cx.ids[cx.triangles[t]]].sum(0) - a - b
                s = np.sign(d[0] * (c - a)[1] - d[1] * (c - a)[0])
                sides.add(int(s))
                ntri += 1
            if len(sides) > 1:
                cls.add("flip")
            for f in range(cx.n_edges):
                if f == e or np.any(np.isin(cx.edges[f], cx.edges[e])):
                    continue
                q1, q2 = pts[cx.ids[cx.edges[f]]]
                if _proper_cross(a, b, q1, q2):
                    cls.add("crossing")
                    break
        if not cls:
            cls.add("other")
        vout.append({"v": int(cx.ids[p]), "zdeg": int(deg[p]), "classes": sorted(cls),
                     "nearest": round(dmin, 3)})
    pairs = None
    if 0 < odd.size <= 22:
        D = shortest_path(_hops(cx), unweighted=True, indices=odd)[:, odd]
        pairs = min_tjoin_pairs(D)
    return {"odd": vout, "pairs": pairs,
            "tjoin_hops": sorted(d for _, _, d in pairs) if pairs else []}


def run_one(args) -> dict:
    seed, idx, kw, deep = args
    row, sw, cx, fence = grow(seed, idx, **kw)
    out = {k: row[k] for k in ("index", "kind", "robots", "noise_deg", "end", "certified", "certify",
                              "refusal", "false_certificate", "hole_area", "complex_ok", "algebra_ok")}
    covered = row["hole_area"] == 0.0
    done = row["end"] == "fixed"
    out["var"] = {}
    for vname in VARIANTS:
        cert, ok = certify_with(cx, fence, vname)
        claim = bool(cert.certified and done and fence.frontier.size == 0 and not fence.deployments)
        out["var"][vname] = {"certified": bool(cert.certified), "verify": bool(ok),
                             "refusal": bool(done and covered and not claim),
                             "false": bool(claim and not covered)}
    if deep or not row["certify"]:
        try:
            out["analysis"] = classify(sw, cx, fence)
        except Exception as e:  # noqa: BLE001 - an analysis failure is reported, not fatal
            out["analysis"] = {"error": repr(e)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    truth.add_campaign_args(ap)
    a = ap.parse_args(argv)
    kw = {}
    idx = a.only if a.only else list(range(a.maps))
    work = [(a.seed, i, kw, False) for i in idx]
    t0 = time.time()
    rows = []
    if a.jobs > 1:
        import multiprocessing as mp
        with mp.get_context("spawn").Pool(a.jobs) as pool:
            for r in pool.imap_unordered(run_one, work, chunksize=2):
                rows.append(r)
                if len(rows) % 20 == 0:
                    print(f"[{len(rows)}/{len(work)}] {time.time() - t0:.0f} s", flush=True)
    else:
        rows = [run_one(w) for w in work]
    rows.sort(key=lambda r: r["index"])
    summ = {"maps": len(rows), "covered_fixed": sum(r["end"] == "fixed" and r["hole_area"] == 0.0 for r in rows),
            "truth_refusals": sum(r["refusal"] for r in rows),
            "truth_false": sum(r["false_certificate"] for r in rows)}
    for v in VARIANTS:
        summ[v] = {"refusals": sum(r["var"][v]["refusal"] for r in rows),
                   "false": sum(r["var"][v]["false"] for r in rows),
                   "verify_fail": sum(not r["var"][v]["verify"] for r in rows)}
    an = [r["analysis"] for r in rows if "analysis" in r and "odd" in r["analysis"]]
    cls = Counter(c for x in an for o in x["odd"] for c in o["classes"])
    maps_cls = Counter(c for x in an for c in {c for o in x["odd"] for c in o["classes"]})
    summ["analysed_maps"] = len(an)
    summ["odd_vertices"] = sum(len(x["odd"]) for x in an)
    summ["odd_per_map"] = sorted(len(x["odd"]) for x in an)
    summ["odd_vertex_classes"] = dict(cls)
    summ["maps_with_class"] = dict(maps_cls)
    summ["tjoin_hop_hist"] = dict(Counter(int(d) if np.isfinite(d) else -1 for x in an for d in x["tjoin_hops"]))
    summ["max_pair_hops_per_map"] = dict(Counter(int(max(x["tjoin_hops"])) if x["tjoin_hops"] else 0 for x in an))
    summ["wall_s"] = round(time.time() - t0, 1)
    print(json.dumps(summ, indent=1))
    if a.out:
        Path(a.out).write_text(json.dumps({"summary": summ, "maps": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())

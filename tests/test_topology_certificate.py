"""Coverage certificate: boundary(c) = z over GF(2), or a verifiable obstruction."""
from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from scipy import ndimage
from scipy.spatial import cKDTree

from swarmcover.coordinator import (TopologyParams, boundary_of, build_complex, certify, closure_zone, detect_fence,
                         is_cocycle, verify_certificate)
from test_topology_geom import boundary_edges_near, lattice, reports

seeds = st.integers(min_value=0, max_value=2**32 - 1)


def _random_complex(seed, n_lo=4, n_hi=45):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(n_lo, n_hi))
    P = rng.uniform(0, rng.uniform(1.0, 3.5), (n, 2))
    return rng, P, build_complex(reports(P))


def _fundamental_cycles(cx, edge_ids):
    """A basis of the cycle space of the graph made of ``edge_ids`` (bool masks)."""
    parent = {}
    basis = []
    adj = {}
    for e in edge_ids:
        a, b = cx.edges[e].tolist()
        adj.setdefault(a, []).append((b, e))
        adj.setdefault(b, []).append((a, e))
    depth, pedge = {}, {}
    for r in adj:
        if r in depth:
            continue
        depth[r], parent[r], pedge[r] = 0, None, None
        stack = [r]
        while stack:
            x = stack.pop()
            for y, e in adj[x]:
                if y not in depth:
                    depth[y], parent[y], pedge[y] = depth[x] + 1, x, e
                    stack.append(y)
    tree = {pedge[x] for x in depth if pedge[x] is not None}
    for e in edge_ids:
        if e in tree:
            continue
        m = np.zeros(cx.n_edges, bool)
        m[e] = True
        a, b = cx.edges[e].tolist()
        while a != b:
            if depth[a] < depth[b]:
                a, b = b, a
            m[pedge[a]] ^= True
            a = parent[a]
        basis.append(m)
    return basis


def _gudhi_boundary_rank(cx, z_mask):
    """dim(Z1(supp z) & B1(R)) from gudhi: beta2 of R plus a cone on z, minus beta2(R)."""
    gudhi = pytest.importorskip("gudhi")

    def beta2(cone):
        stree = gudhi.SimplexTree()
        for v in range(cx.n):
            stree.insert([v])
        for s in cx.edges.tolist() + cx.triangles.tolist():
            stree.insert(s)
        if cone:
            for e in np.nonzero(z_mask)[0]:
                stree.insert(cx.edges[e].tolist() + [cx.n])
        stree.compute_persistence(homology_coeff_field=2, persistence_dim_max=True)
        b = stree.betti_numbers()
        return b[2] if len(b) > 2 else 0

    return beta2(True) - beta2(False)


def _check_against_gudhi(cx, z_mask):
    """Certify every cycle of supp(z)'s cycle space; the number certified must be
    2**k - 1 with k from gudhi. Returns (certified count, k)."""
    basis = _fundamental_cycles(cx, np.nonzero(z_mask)[0].tolist())
    if len(basis) > 4:
        basis = basis[:4]
        z_mask = np.logical_or.reduce(basis)
        basis = _fundamental_cycles(cx, np.nonzero(z_mask)[0].tolist())
        if len(basis) > 4:
            return None
    k = _gudhi_boundary_rank(cx, z_mask)
    count = 0
    for r in range(1, len(basis) + 1):
        for combo in itertools.combinations(basis, r):
            zz = np.logical_xor.reduce(combo)
            cert = certify(cx, zz)
            assert verify_certificate(cx, cert)
            count += cert.certified
    assert count == 2**k - 1
    return count, k


@settings(max_examples=60, deadline=None)
@given(seed=seeds, frac=st.floats(0.0, 1.0))
def test_boundaries_are_certified(seed, frac):
    rng, P, cx = _random_complex(seed)
    sel = np.nonzero(rng.random(cx.n_triangles) < frac)[0]
    z = boundary_of(cx, sel)
    if not z.any():  # an empty target certifies nothing: refused loudly
        with pytest.raises(ValueError, match="no edge"):
            certify(cx, z)
        return
    cert = certify(cx, z)
    assert cert.certified
    assert verify_certificate(cx, cert)
    assert np.array_equal(boundary_of(cx, cert.chain), z)
    assert set(cert.support.tolist()) <= set(cx.ids.tolist())


@settings(max_examples=60, deadline=None)
@given(seed=seeds)
def test_odd_fence_is_rejected_with_a_star_cocycle(seed):
    rng, P, cx = _random_complex(seed)
    if cx.n_edges == 0:
        return
    z = boundary_of(cx, np.nonzero(rng.random(cx.n_triangles) < 0.5)[0])
    z[int(rng.integers(cx.n_edges))] ^= True
    cert = certify(cx, z)
    assert not cert.certified and cert.odd_vertices.size >= 2
    assert verify_certificate(cx, cert)
    assert is_cocycle(cx, cert.obstruction)


@settings(max_examples=40, deadline=None)
@given(seed=seeds)
def test_random_cycles_match_gudhi(seed):
    rng, P, cx = _random_complex(seed, 6, 40)
    if cx.n_edges == 0:
        return
    # random cycles: XOR of a few fundamental cycles of the whole 1-skeleton
    basis = _fundamental_cycles(cx, list(range(cx.n_edges)))
    if not basis:
        return
    pick = rng.choice(len(basis), size=min(len(basis), int(rng.integers(1, 4))), replace=False)
    z = np.logical_xor.reduce([basis[i] for i in pick])
    if not z.any():
        return
    _check_against_gudhi(cx, z)


@settings(max_examples=25, deadline=None)
@given(seed=seeds)
def test_fence_decisions_match_gudhi(seed):
    rng, P, cx = _random_complex(seed, 10, 60)
    f = detect_fence(cx)
    z = np.zeros(cx.n_edges, bool)
    z[f.z] = True
    cert = certify(cx, f)
    assert verify_certificate(cx, cert)
    if z.any():
        _check_against_gudhi(cx, z)


def _holey(seed, holes, rows=14):
    rng = np.random.default_rng(seed)
    P = lattice(rows, rows, 0.8, 0.02, rng)
    for c, r in holes:
        P = P[np.linalg.norm(P - np.asarray(c), axis=1) > r + 0.05]
    cx = build_complex(reports(P, discs=[(c[0], c[1], r) for c, r in holes]))
    return P, cx


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_certified_iff_every_hole_is_fenced(seed):
    holes = [((3.0, 3.0), 0.9), ((7.5, 6.0), 1.1)]
    P, cx = _holey(seed, holes)
    rims, outer = [], set(range(cx.n_edges))
    for c, r in holes:
        near, far = boundary_edges_near(cx, P, c, r + 1.2)
        rims.append(set(near.tolist()))
        outer &= set(far.tolist())
    for fenced in itertools.product([False, True], repeat=len(holes)):
        z = set(outer)
        for rim, on in zip(rims, fenced):
            if on:
                z |= rim
        cert = certify(cx, sorted(z))
        assert verify_certificate(cx, cert)
        assert cert.certified == all(fenced)
        if not cert.certified:
            # the witness cycle is exactly the rims of the unfenced holes
            want = set().union(*(rim for rim, on in zip(rims, fenced) if not on))
            assert set(cert.hole_edges.tolist()) == want
            assert len(cert.obstruction) > 0 and is_cocycle(cx, cert.obstruction)
        else:
            # the chain covers every triangle of the annulus-like region exactly once
            assert cert.chain.size == cx.n_triangles


def test_no_hole_certifies_and_a_removed_robot_opens_one():
    rng = np.random.default_rng(7)
    P = lattice(12, 12, 0.8, 0.02, rng)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    cert = certify(cx, f)
    assert cert.certified and cert.chain.size == cx.n_triangles
    # drop an interior robot but keep the old outer fence: a hole no fence edge sees
    k = int(np.argmin(np.linalg.norm(P - P.mean(0), axis=1)))
    keep = [i for i in range(len(P)) if i != k]
    cx2 = build_complex(reports(P[keep], ids=keep))
    z_old = cx.edge_nodes(f.z)
    cert2 = certify(cx2, z_old)
    assert not cert2.certified and verify_certificate(cx2, cert2)
    ring = {tuple(sorted(e)) for e in cert2.hole_edge_nodes.tolist()}
    nbrs = set(cx.neighbours(k).tolist())
    assert len(ring) == len(nbrs) and all(a in nbrs and b in nbrs for a, b in ring)
    # the fence detected on the new complex sees the hole and certifies again
    f2 = detect_fence(cx2)
    assert certify(cx2, f2).certified


def test_empty_and_disconnected():
    P = np.vstack([lattice(4, 4, 0.8), lattice(4, 4, 0.8, origin=(20.0, 0.0))])
    cx = build_complex(reports(P))
    with pytest.raises(ValueError, match="no edge"):
        certify(cx, [])
    f = detect_fence(cx)
    cert = certify(cx, f)
    assert cert.certified and verify_certificate(cx, cert) and cert.chain.size == cx.n_triangles


def _pillar_hall_end():
    """The last cycle of a pillar_hall run (seed 0): reports, failed test drives, truth."""
    d = json.loads((Path(__file__).parent / "data" / "pillar_hall_end.json").read_text())
    reps = {int(v): {"neighbours": {int(k): b for k, b in r["neighbours"].items()},
                     "touch": r["touch"], "touch_bearing": r["touch_bearing"]}
            for v, r in d["reports"].items()}
    tdf = {int(k): v for k, v in d["test_drive_failures"].items()}
    pos = {int(k): np.array(v) for k, v in d["positions"].items()}
    return reps, tdf, pos


def test_a_fence_closed_the_wrong_way_round_pillars_is_closed_inside_its_zone():
    reps, tdf, pos = _pillar_hall_end()
    cx = build_complex(reps)
    f = detect_fence(cx, TopologyParams(), test_drive_failures=tdf)
    assert f.z_repair.size  # the raw fence had odd vertices
    assert not certify(cx, f.z).certified           # the shortest closure is not a boundary
    cert = certify(cx, f)
    assert cert.certified and verify_certificate(cx, cert)
    z, raw = set(cert.z.tolist()), set(f.z_raw.tolist())
    # z = raw XOR closure: the closure adds zone edges and may drop raw edges at odd
    # vertices (folds where edges cross; certificate.py's docstring)
    assert z ^ raw == set(cert.closure.tolist()) and len(z ^ raw) == cert.stats["closure"]
    assert raw - z <= set(np.nonzero(np.isin(cx.edges, cx.index(cert.odd_vertices)).any(1))[0].tolist())
    # the closure runs around the pillars (0.3 m squares on a 2 m grid, rv = 1 m), where
    # edges cross: every added or dropped edge within 1.5 m of one
    pillars = np.array([(x, y) for x in (1.5, 3.5, 5.5, 7.5) for y in (1.5, 4.5)])
    for a, b in cx.ids[cx.edges[sorted(z ^ raw)]].tolist():
        mid = (pos[a] + pos[b]) / 2.0
        assert np.min(np.linalg.norm(pillars - mid, axis=1)) < 1.5


def test_the_closure_cannot_hide_a_hole_away_from_the_odd_vertices():
    holes = [((3.0, 3.0), 0.9), ((7.5, 6.0), 1.1)]
    P, cx = _holey(0, holes)
    rims, outer = [], set(range(cx.n_edges))
    for c, r in holes:
        near, far = boundary_edges_near(cx, P, c, r + 1.2)
        rims.append(set(near.tolist()))
        outer &= set(far.tolist())
    # a raw fence with a gap on the outer boundary, far from both holes: two odd vertices
    far_e = max(outer, key=lambda e: np.linalg.norm(P[cx.edges[e]].mean(0) - (5.0, 5.0)))
    for fenced in ([True, True], [True, False]):
        raw = set(outer) - {far_e}
        for rim, on in zip(rims, fenced):
            raw |= rim if on else set()
        closure = sorted(raw | {far_e})
        fence = SimpleNamespace(z=np.array(closure), z_raw=np.array(sorted(raw)),
                                z_repair=np.array([far_e]))
        cert = certify(cx, fence)
        assert cert.certified == all(fenced) and verify_certificate(cx, cert, fence)
        assert cert.certified or (cert.obstruction.size and is_cocycle(cx, cert.obstruction))


# ----------------------------------------------------------------- the one criterion
def _crossing_fence():
    """A fence whose one-sided edges leave odd vertices: the pillar_hall end state."""
    reps, tdf, pos = _pillar_hall_end()
    cx = build_complex(reps)
    return cx, detect_fence(cx, TopologyParams(), test_drive_failures=tdf)


def test_verify_checks_the_closure_zone_and_the_cycle():
    cx, f = _crossing_fence()
    cert = certify(cx, f)
    assert cert.certified and cert.closure.size and cert.closable
    assert verify_certificate(cx, cert, f) and verify_certificate(cx, cert)
    odd, zone = closure_zone(cx, np.isin(np.arange(cx.n_edges), f.z_raw))
    assert set(cert.closure.tolist()) <= set(zone.tolist()) and odd.size
    assert set(cx.ids[odd].tolist()) == set(cert.odd_vertices.tolist())
    # the same chain is not a certificate of the raw edges as an exact target
    assert not verify_certificate(cx, cert, f.z_raw)
    # a closure edge outside the zone is refused, even with a matching chain
    out = np.setdiff1d(np.arange(cx.n_edges), np.concatenate([zone, f.z_raw]))
    out = out[np.diff(cx.edge_triangles[0])[out] > 0]
    tri = int(cx.edge_triangles[1][cx.edge_triangles[0][out[len(out) // 2]]])
    bad_chain = np.setxor1d(cert.chain, [tri])
    bz = boundary_of(cx, bad_chain)
    bad = replace(cert, chain=bad_chain, z=np.nonzero(bz)[0],
                  closure=np.nonzero(bz & ~np.isin(np.arange(cx.n_edges), f.z_raw))[0])
    assert not verify_certificate(cx, bad, f)
    # z must be the target plus the closure
    assert not verify_certificate(cx, replace(cert, z=f.z_raw), f)


def test_refusal_with_odd_vertices_carries_a_cocycle_that_misses_the_zone():
    # a lattice strip whose raw target is one side of it only: no closure near its two
    # ends can bound, and the obstruction proves it
    P = lattice(3, 8, 0.8)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    raw = np.array(f.z_raw)
    pos = P[cx.index(cx.ids)]
    mid = pos[cx.edges[raw]].mean(1)
    half = raw[mid[:, 1] < pos[:, 1].mean()]  # the bottom side of the strip only
    fake = SimpleNamespace(z_raw=half, z_repair=np.zeros(0, np.int64))
    cert = certify(cx, fake)
    assert not cert.certified and cert.obstruction.size and is_cocycle(cx, cert.obstruction)
    odd, zone = closure_zone(cx, np.isin(np.arange(cx.n_edges), half))
    assert not set(cert.obstruction.tolist()) & set(zone.tolist())
    assert verify_certificate(cx, cert, fake) and cert.stats["reason"].startswith("no closure")


def test_empty_targets_never_certify():
    # a Fence with no one-sided edge (a single file, a lone robot) is refused, not an error
    P = np.array([[0.0, 0.0], [0.8, 0.0], [1.6, 0.0]])
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    assert f.z_raw.size == 0
    cert = certify(cx, f)
    assert not cert.certified and cert.stats["reason"].startswith("empty target")
    assert verify_certificate(cx, cert, f)
    forged = replace(cert, certified=True, chain=np.zeros(0, np.int64))
    assert not verify_certificate(cx, forged, f)
    lone = build_complex({7: {"neighbours": {}}})
    assert not certify(lone, detect_fence(lone)).certified
    # an explicit empty target is a caller's error
    for empty in ([], np.zeros(cx.n_edges, bool), np.zeros((0, 2), np.int64)):
        with pytest.raises(ValueError, match="no edge"):
            certify(cx, empty)
        with pytest.raises(ValueError, match="no edge"):
            verify_certificate(cx, cert, empty)
    # one-sided edges but no triangle: refused with an obstruction
    Q = np.array([[0.0, 0.0], [0.9, 0.0], [0.45, 0.8]])
    cq = build_complex(reports(Q))
    c2 = certify(cq, [[0, 1], [1, 2]])
    assert not c2.certified and verify_certificate(cq, c2)


def test_malformed_targets_and_certificates_are_rejected():
    P = lattice(4, 4, 0.8)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    cert = certify(cx, f)
    assert cert.certified
    z = list(f.z_raw)
    with pytest.raises(ValueError, match=r"target edge ids repeat .*\[%d\]" % z[0]):
        certify(cx, z + [z[0]])
    with pytest.raises(ValueError, match="target edge ids repeat"):
        verify_certificate(cx, cert, z + [z[0]])
    pairs = cx.edge_nodes(f.z_raw)
    with pytest.raises(ValueError, match=r"node pairs\) repeat"):
        certify(cx, np.vstack([pairs, pairs[:1, ::-1]]))
    with pytest.raises(ValueError, match=r"target edge ids out of range"):
        certify(cx, [-1] + z[1:])
    with pytest.raises(ValueError, match="integer ids"):
        certify(cx, np.array(z, float) + 0.5)
    for chain, msg in (([-1], r"chain triangle ids out of range \[0, %d\): \[-1\]" % cx.n_triangles),
                       (list(cert.chain) + [int(cert.chain[0])], "chain triangle ids repeat"),
                       ([cx.n_triangles], "out of range")):
        with pytest.raises(ValueError, match=msg):
            verify_certificate(cx, replace(cert, chain=np.array(chain)), f)
    with pytest.raises(ValueError, match="obstruction edge ids repeat"):
        verify_certificate(cx, replace(cert, certified=False, obstruction=np.array([0, 0])), f)
    # a negative id that numpy would have read from the end is refused, not wrapped
    t = cx.n_triangles
    with pytest.raises(ValueError):
        verify_certificate(cx, replace(cert, chain=np.where(cert.chain == t - 1, -1, cert.chain)), f)


# ---------------------------------------------------------------- random-complex campaign
# Positions exist only here. A room (rectangle) with 0-3 obstacles (boxes, triangles);
# robots along every wall (offset by their body radius, touching, contact towards the
# wall) and uniform inside; edges within rv with line of sight through the walls; true
# bearings; detect_fence with default params; certify. Raster truth (no coordinator code):
#  (a) certified => no hidden hole: a flood from the triangles' union that crosses no
#      one-sided fence edge and no wall never reaches a free cell outside the union, and
#      every cell the certificate's cycle encloses (even-odd rule) is in a chain triangle;
#  (b) every certificate passes verify_certificate(cx, cert, fence);
#  (c) covered end states (no frontier, every free cell farther than 0.3 rv from a wall
#      inside the union) are certified.
_RB = 0.1     # robot body radius (rv units)
_CELL = 0.05  # raster cell


def _polys(rng, W, H):
    """Obstacles: convex polygons (CCW vertex arrays), pairwise apart and off the walls."""
    out = []
    for _ in range(int(rng.integers(0, 4))):
        for _try in range(20):
            w, h = rng.uniform(0.3, 1.4, 2)
            if W - 1.2 - w < 0 or H - 1.2 - h < 0:
                continue
            x, y = rng.uniform(0.6, W - 0.6 - w), rng.uniform(0.6, H - 0.6 - h)
            if rng.random() < 0.5:
                p = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]])
            else:
                p = np.array([[x, y], [x + w, y], [x + rng.uniform(0, w), y + h]])
            lo, hi = p.min(0) - 0.5, p.max(0) + 0.5
            if all(np.any(hi < q.min(0)) or np.any(lo > q.max(0)) for q in out):
                out.append(p)
                break
    return out


def _walls(W, H, polys):
    """All wall segments (k, 2, 2): the room's sides and every obstacle's sides."""
    room = np.array([[0, 0], [W, 0], [W, H], [0, H]], float)
    segs = [np.stack([q, np.roll(q, -1, 0)], 1) for q in [room] + polys]
    return np.concatenate(segs)


def _inside(pts, poly):
    """Points strictly inside a convex CCW polygon."""
    a, b = poly, np.roll(poly, -1, 0)
    cr = (b[None, :, 0] - a[None, :, 0]) * (pts[:, None, 1] - a[None, :, 1]) - \
         (b[None, :, 1] - a[None, :, 1]) * (pts[:, None, 0] - a[None, :, 0])
    return np.all(cr > 0, axis=1)


def _seg_dist(pts, segs):
    """(distance to the nearest segment, nearest point) for every point."""
    a, b = segs[None, :, 0], segs[None, :, 1]
    ab = b - a
    t = np.clip(((pts[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    q = a + t[..., None] * ab
    d = np.linalg.norm(pts[:, None] - q, axis=-1)
    k = np.argmin(d, axis=1)
    return d[np.arange(len(pts)), k], q[np.arange(len(pts)), k]


def _crosses(p, q, segs):
    """For segment pairs (p[i], q[i]): does it properly cross any wall segment?"""
    a, b = segs[None, :, 0], segs[None, :, 1]
    p, q = p[:, None], q[:, None]

    def orient(u, v, w):
        return np.sign((v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (w[..., 0] - u[..., 0]))

    return np.any((orient(p, q, a) != orient(p, q, b)) & (orient(a, b, p) != orient(a, b, q)), axis=1)


def campaign_sample(seed):
    """One random room: (P, reports, polys, W, H)."""
    rng = np.random.default_rng(seed)
    W, H = rng.uniform(1.5, 4.5, 2)
    polys = _polys(rng, W, H)
    segs = _walls(W, H, polys)
    pts = []
    inner = [np.array([[_RB, _RB], [W - _RB, _RB], [W - _RB, H - _RB], [_RB, H - _RB]])]
    for q in polys:  # offset outward along the corners' bisectors by the body radius
        a, b = np.roll(q, 1, 0) - q, np.roll(q, -1, 0) - q
        bis = -(a / np.linalg.norm(a, axis=1)[:, None] + b / np.linalg.norm(b, axis=1)[:, None])
        inner.append(q + _RB * bis / np.linalg.norm(bis, axis=1)[:, None])
    for q in inner:  # robots along every wall, touching it
        s = rng.uniform(0.3, 0.75)
        for a, b in zip(q, np.roll(q, -1, 0)):
            L = np.linalg.norm(b - a)
            k = max(1, int(math.ceil(L / s)))
            for t in np.arange(k) / k:
                pts.append(a + t * (b - a))
    # a little jitter: robots on one wall are never exactly collinear (exactly collinear
    # triples are degenerate triangles, issue 21's wrap(pi) finding, not this test's)
    pts = list(np.array(pts) + rng.normal(0.0, 0.003, (len(pts), 2)))
    dens = rng.uniform(4.0, 10.0)
    m = rng.poisson(dens * W * H)
    X = rng.uniform([0, 0], [W, H], (m, 2))
    ok = np.ones(m, bool)
    for q in polys:
        ok &= ~_inside(X, q)
    X = X[ok]
    if len(X):
        X = X[_seg_dist(X, segs)[0] > _RB]
    P = np.vstack([np.array(pts), X]) if len(X) else np.array(pts)
    P = P[(P[:, 0] > 0) & (P[:, 1] > 0) & (P[:, 0] < W) & (P[:, 1] < H)]
    for q in polys:
        P = P[~_inside(P, q)]
    # edges: within rv, line of sight through no wall
    pairs = cKDTree(P).query_pairs(1.0, output_type="ndarray")
    if len(pairs):
        pairs = pairs[~_crosses(P[pairs[:, 0]], P[pairs[:, 1]], segs)]
    nb = [dict() for _ in range(len(P))]
    for a, b in pairs.tolist():
        d = P[b] - P[a]
        nb[a][b] = math.atan2(d[1], d[0])
        nb[b][a] = math.atan2(-d[1], -d[0])
    reps = {}
    for i in range(len(P)):
        r = {"neighbours": nb[i]}
        ct = _contact(P[i], segs)
        if ct is not None:
            r["touch"], r["touch_bearing"] = True, ct
        reps[i] = r
    return P, reps, polys, W, H, segs


def _contact(p, segs):
    """Contact bearing of a robot at p touching walls (mean direction at a corner), or None."""
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    q = a + t[:, None] * ab
    d = np.linalg.norm(q - p, axis=1)
    if d.min() > _RB + 0.02:
        return None
    u = (q - p)[d <= d.min() + 0.02]
    u = (u / np.linalg.norm(u, axis=1)[:, None]).sum(0)
    return math.atan2(u[1], u[0])


def _drives(cx, pos, segs, fence, ev):
    """Simulated drives: each deployment drives d_td = 0.25 rv, a probe first to its point on
    the edge, then depth_rv along its bearing; one that comes within a body radius of a
    wall fails. Outcomes go to ``ev`` (coordinator.topology.evidence.Evidence). Returns True if a new
    outcome was recorded."""
    before = len(ev.records)
    done = {(r.vertex, round(r.direction, 9), r.via_frac, r.edge) for r in ev.records}
    for v, deps in fence.deployments.items():
        p = pos[cx.index_of(v)]
        for d in deps:
            key = (int(v), round(float(d.bearing), 9), float(getattr(d, "via_frac", 0.0) or 0.0),
                   tuple(d.edge) if d.edge is not None else None)
            if key in done:
                continue
            start, length = p, 0.25
            if d.kind == "probe":
                if d.via_frac > 0 and d.edge is not None:
                    q = pos[cx.index_of(d.edge[1] if d.edge[0] == v else d.edge[0])]
                    start = p + d.via_frac * (q - p)
                length = d.depth_rv
            end = start + length * np.array([math.cos(d.bearing), math.sin(d.bearing)])
            sd = np.linspace(0, 1, 13)[:, None] * (end - start) + start
            touched = bool(_seg_dist(sd, segs)[0].min() <= _RB)
            if touched or d.kind == "probe":   # a clear probe is done (no robot placed here)
                ev.record(d, touched)
                done.add(key)
    return len(ev.records) > before


class _Grid:
    """Cell centres of a W x H raster, row-major (y rows, x columns)."""

    def __init__(self, W, H):
        self.nx, self.ny = int(W / _CELL) + 1, int(H / _CELL) + 1
        self.x0, self.y0 = 1.3e-4, 0.7e-4   # off any rational coordinate
        gx, gy = np.meshgrid(self.x0 + (np.arange(self.nx) + 0.5) * _CELL, self.y0 + (np.arange(self.ny) + 0.5) * _CELL)
        self.G = np.stack([gx.ravel(), gy.ravel()], 1)

    def box(self, lo, hi):
        """Flat indices of the cells whose centres may lie in the box [lo, hi]."""
        i0 = max(0, int((lo[0] - self.x0) / _CELL) - 1)
        i1 = min(self.nx, int((hi[0] - self.x0) / _CELL) + 2)
        j0 = max(0, int((lo[1] - self.y0) / _CELL) - 1)
        j1 = min(self.ny, int((hi[1] - self.y0) / _CELL) + 2)
        if i0 >= i1 or j0 >= j1:
            return np.zeros(0, np.int64)
        jj, ii = np.meshgrid(np.arange(j0, j1), np.arange(i0, i1), indexing="ij")
        return (jj * self.nx + ii).ravel()


def _raster_segments(R, segs, eps):
    """Cells of grid R within eps of any segment."""
    hit = np.zeros(len(R.G), bool)
    for a, b in segs:
        sel = R.box(np.minimum(a, b) - eps, np.maximum(a, b) + eps)
        if sel.size:
            hit[sel[_seg_dist(R.G[sel], np.array([[a, b]]))[0] <= eps]] = True
    return hit


def _tri_cells(R, T):
    """(cell, triangle) pairs: the cell centres of grid R inside each triangle (k, 3, 2),
    vectorised over every (triangle, cell of its bounding box) pair, in chunks."""
    cells, tris = [], []
    for c0 in range(0, len(T), 1500):
        t = T[c0:c0 + 1500]
        lo, hi = t.min(1), t.max(1)
        i0 = np.clip(((lo[:, 0] - R.x0) / _CELL).astype(np.int64) - 1, 0, R.nx)
        i1 = np.clip(((hi[:, 0] - R.x0) / _CELL).astype(np.int64) + 2, 0, R.nx)
        j0 = np.clip(((lo[:, 1] - R.y0) / _CELL).astype(np.int64) - 1, 0, R.ny)
        j1 = np.clip(((hi[:, 1] - R.y0) / _CELL).astype(np.int64) + 2, 0, R.ny)
        w, h = np.maximum(i1 - i0, 0), np.maximum(j1 - j0, 0)
        m = w * h
        k = np.repeat(np.arange(len(t)), m)
        off = np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)
        cell = (j0[k] + off // np.maximum(w[k], 1)) * R.nx + i0[k] + off % np.maximum(w[k], 1)
        g = R.G[cell]
        tk = t[k]
        s_ = [np.sign((tk[:, (q + 1) % 3, 0] - tk[:, q, 0]) * (g[:, 1] - tk[:, q, 1])
                      - (tk[:, (q + 1) % 3, 1] - tk[:, q, 1]) * (g[:, 0] - tk[:, q, 0])) for q in range(3)]
        inside = ((s_[0] >= 0) & (s_[1] >= 0) & (s_[2] >= 0)) | ((s_[0] <= 0) & (s_[1] <= 0) & (s_[2] <= 0))
        cells.append(cell[inside])
        tris.append(c0 + k[inside])
    if not cells:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(cells), np.concatenate(tris)


def _ray_parity(G, segs):
    """Even-odd rule: crossings of a ray to +x from each grid point, mod 2."""
    par = np.zeros(len(G), bool)
    for a, b in segs:
        if a[1] == b[1]:
            continue
        y0, y1 = min(a[1], b[1]), max(a[1], b[1])
        sel = np.nonzero((G[:, 1] >= y0) & (G[:, 1] < y1))[0]
        if sel.size:
            x = a[0] + (G[sel, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            par[sel[x > G[sel, 0]]] ^= True
    return par


def campaign_case(seed, drop_fence_edge=False):
    """Run one sample; returns a dict of outcomes (see the comment above). With
    ``drop_fence_edge`` the flood ignores every other one-sided fence edge (tests the oracle)."""
    P, reps, polys, W, H, segs = campaign_sample(seed)
    cx = build_complex(reps)
    pos = P[cx.index(cx.ids)]
    from swarmcover.coordinator.topology.evidence import Evidence
    ev = Evidence(door_min_rv=0.4, robot_radius_rv=0.06)
    # the probe rule's straight-line drives (_drives emulates no wall sweep): the campaign
    # tests the certificate on the end states they reach
    probes = TopologyParams(sweep=False)
    for _ in range(12):
        fence = detect_fence(cx, probes, **ev.fence_kwargs())
        if not _drives(cx, pos, segs, fence, ev):
            break
    cert = certify(cx, fence)
    out = {"seed": seed, "n": cx.n, "triangles": cx.n_triangles, "certified": bool(cert.certified),
           "end": not fence.frontier.size and not fence.deployments, "closure": int(cert.closure.size),
           "verified": verify_certificate(cx, cert, fence), "hidden": 0, "outside_chain": 0, "covered": False}
    R = _Grid(W, H)
    G, nx, ny = R.G, R.nx, R.ny
    free = (G[:, 0] < W) & (G[:, 1] < H)
    for q in polys:
        free &= ~_inside(G, q)
    cell, tri = _tri_cells(R, pos[cx.triangles])
    U = np.bincount(cell, minlength=len(G)) > 0
    far = _seg_dist(G, segs)[0] > 0.3
    out["covered"] = bool(cx.n_triangles and np.all(U[free & far]))
    if cert.certified:
        # the theorem: cells the cycle encloses (even-odd) are in chain triangles
        par = _ray_parity(G, pos[cx.edges[cert.z]])
        inc = np.isin(tri, cert.chain)
        inchain = np.bincount(cell[inc], minlength=len(G))
        out["outside_chain"] = int(np.sum(par != (inchain & 1).astype(bool)))
        # no hidden hole: flood from the union through free cells, fences and walls block
        zb = fence.z_raw[::2] if drop_fence_edge else fence.z_raw
        block = ~free | _raster_segments(R, pos[cx.edges[zb]], 1.5 * _CELL)
        grid = (~block).reshape(ny, nx)
        lab, _ = ndimage.label(grid)
        seeds = np.unique(lab.ravel()[U & ~block])
        reach = np.isin(lab.ravel(), seeds[seeds > 0])
        out["hidden"] = int(np.sum(reach & free & ~U))
    return out


def _campaign_summary(rows):
    ends = [r for r in rows if r["end"] and r["covered"]]
    return {"complexes": len(rows), "certified": sum(r["certified"] for r in rows),
            "verified": sum(r["verified"] for r in rows),
            "certified_with_hidden_hole": sum(1 for r in rows if r["certified"] and r["hidden"]),
            "enclosed_outside_chain": sum(1 for r in rows if r["outside_chain"]),
            "closures": sum(1 for r in rows if r["closure"]), "end_states": sum(r["end"] for r in rows),
            "covered_end_states": len(ends), "covered_end_states_certified": sum(r["certified"] for r in ends)}


def test_random_rooms_certify_covered_end_states_and_hide_no_hole():
    """The fast campaign (12 rooms); ``python tests/test_topology_certificate.py 1000`` runs
    the large one and prints the same summary."""
    rows = [campaign_case(s) for s in range(12)]
    s = _campaign_summary(rows)
    assert s["verified"] == s["complexes"]                       # (b)
    assert s["certified_with_hidden_hole"] == 0                  # (a)
    assert s["enclosed_outside_chain"] == 0                      # the parity theorem
    assert s["covered_end_states"] >= 2 and s["closures"] >= 2   # the sample exercises both
    assert s["covered_end_states_certified"] == s["covered_end_states"]   # (c)
    # the oracle sees gaps: a flood that ignores half the fence edges leaks out of the union
    assert campaign_case(1, drop_fence_edge=True)["hidden"] > 0


if __name__ == "__main__":
    import sys

    out = [campaign_case(s) for s in range(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)]
    print(json.dumps(_campaign_summary(out)))
    for r in out:
        if (r["certified"] and (r["hidden"] or r["outside_chain"])) or not r["verified"] \
                or (r["end"] and r["covered"] and not r["certified"]):
            print(json.dumps(r))


def _end_state(name: str):
    """A bench/truth.py end state saved in tests/data: (its JSON, the complex built from its
    reports, a function from node-id pairs to edge ids)."""
    d = json.loads((Path(__file__).parent / "data" / name).read_text())
    reps = {int(v): {"neighbours": {int(k): b for k, b in r["neighbours"].items()},
                     "touch": r["touch"], "touch_bearing": r["touch_bearing"]}
            for v, r in d["reports"].items()}
    cx = build_complex(reps)

    def eids(pairs):
        loc = cx.index(np.array(pairs).ravel()).reshape(-1, 2)
        return cx.edge_index(loc[:, 0], loc[:, 1])

    return d, cx, eids


def test_a_fold_of_overlapping_triangles_is_closed_by_dropping_its_shared_edge():
    # bench/truth.py seed 0 map 242 (two rooms, 41 robots): a covered fixed point that
    # certify refused. Triangles 7-9-22 and 9-22-28 lie on the same side of 9-22 (a fold,
    # where edges cross): 9-22, 7-22 and 9-28 are all one-sided, and over GF(2) no chain's
    # boundary holds all three (they are a cocycle inside z_raw, met an odd number of
    # times, whatever edges a closure adds). The closure may drop target edges at odd
    # vertices (certificate.py's docstring).
    d, cx, eids = _end_state("truth_map242_fold.json")
    raw, fold = eids(d["z_raw"]), eids(d["fold"])
    fence = SimpleNamespace(z_raw=raw, z_repair=eids(d["z_repair"]))
    assert set(fold.tolist()) <= set(raw.tolist()) and is_cocycle(cx, fold) and len(fold) % 2 == 1
    pos = {int(k): np.array(v) for k, v in d["positions"].items()}
    (a, b), apex = d["fold"][0], (7, 28)   # the shared edge 9-22 and the two apexes
    u = pos[b] - pos[a]
    side = [np.sign(u[0] * (pos[k] - pos[a])[1] - u[1] * (pos[k] - pos[a])[0]) for k in apex]
    assert side[0] == side[1]               # the two triangles overlap
    cert = certify(cx, fence)
    assert cert.certified and verify_certificate(cx, cert, fence) and verify_certificate(cx, cert)
    z, rset = set(cert.z.tolist()), set(raw.tolist())
    dropped = rset - z
    assert dropped and dropped & set(fold.tolist())
    at_odd = set(np.nonzero(np.isin(cx.edges, cx.index(cert.odd_vertices)).any(1))[0].tolist())
    assert dropped <= at_odd and cert.stats["closure_dropped"] == len(dropped)
    odd, zone = closure_zone(cx, np.isin(np.arange(cx.n_edges), raw))
    assert set(cert.closure.tolist()) <= set(zone.tolist())
    # the closure must stay in the zone: without the dropped edges' freedom (a closure
    # outside z_raw only) the same chain is no certificate of the raw edges
    assert not verify_certificate(cx, replace(cert, closure=np.array(sorted(z - rset))), fence)


def test_a_closure_adds_edges_before_it_drops_an_edge_with_one_triangle():
    """Two sides of a square's triangle as the target (odd at their far ends): dropping
    both would leave nothing, a certificate from nothing (the forged-Complex re-check of
    tests/test_run_report.py hit it). certify searches the narrower zone first, where only
    fold edges (two or more triangles) may leave the target: the closure adds the diagonal."""
    from swarmcover.coordinator.topology.complex import Complex as TopoComplex
    ids = np.arange(4)
    edges = np.array([[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]])
    tris = np.array([[0, 1, 2], [1, 2, 3]])
    cx = TopoComplex(ids, edges, tris, np.zeros((5, 2)), np.zeros(4, bool), np.full(4, np.nan))
    cert = certify(cx, SimpleNamespace(z_raw=np.array([0, 1])))
    assert cert.certified and "closure_zone" not in cert.stats
    z = set(np.asarray(cert.z).tolist())
    assert {0, 1} <= z and z == {0, 1, 2}                  # 0-1, 0-2 and the diagonal
    target = np.isin(np.arange(5), [0, 1])
    assert not {0, 1} & set(closure_zone(cx, target, folds_only=True)[1].tolist())
    assert {0, 1} <= set(closure_zone(cx, target)[1].tolist())


def _assert_no_closure_in(cx, zr, odd_zone):
    """No closure of target mask ``zr`` within the zone exists: the solver's obstruction
    is a cocycle that misses the zone and meets the target an odd number of times."""
    from swarmcover.coordinator.topology.solver import _Solver
    odd, zone = odd_zone
    f, psi = _Solver(cx, None, {}).closure(zr, odd, zone)
    assert f is None and is_cocycle(cx, np.nonzero(psi)[0])
    assert not psi[zone].any() and (psi & zr).sum() % 2 == 1


def _certified_in(cx, fence, zone: str):
    """certify's certificate, found in the named zone and verified both ways."""
    cert = certify(cx, fence)
    assert cert.certified and cert.stats["closure_zone"] == zone
    assert verify_certificate(cx, cert, fence) and verify_certificate(cx, cert)
    return cert


def test_a_one_sided_edge_crossed_by_others_may_leave_the_target():
    """bench/truth.py seed 1 map 49 (boxes, 57 robots, 0.5 deg noise): a covered end state
    that the fold-only closure refused. Its odd vertices 18 and 43 are far apart; 31-43 is
    one-sided with one triangle, yet three edges cross it (it lies inside the union).
    The one-hop zone may drop it, and certify then certifies; no closure in the fold-only
    zone exists (the obstruction proves it)."""
    d, cx, eids = _end_state("truth_s1_map49_crossing.json")
    raw = eids(d["z_raw"])
    fence = SimpleNamespace(z_raw=raw, z_repair=eids(d["z_repair"]))
    zr = np.isin(np.arange(cx.n_edges), raw)
    _assert_no_closure_in(cx, zr, closure_zone(cx, zr, folds_only=True))
    cert = _certified_in(cx, fence, "one hop")
    dropped = set(raw.tolist()) - set(cert.z.tolist())
    one = [e for e in dropped if np.diff(cx.edge_triangles[0])[e] == 1]
    assert one
    # each dropped one-triangle edge is crossed by another edge (true positions)
    pos = {int(k): np.array(v) for k, v in d["positions"].items()}

    def cross(p1, p2, q1, q2):
        o = lambda a, b, c: np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
        return o(q1, q2, p1) * o(q1, q2, p2) < 0 and o(p1, p2, q1) * o(p1, p2, q2) < 0

    for e in one:
        a, b = (int(x) for x in cx.ids[cx.edges[e]])
        assert any(cross(pos[a], pos[b], pos[int(c)], pos[int(w)])
                   for c, w in cx.ids[cx.edges] if not {int(c), int(w)} & {a, b})


def test_a_closure_may_drop_target_edges_two_hops_out_but_adds_edges_within_one():
    """configs/cave.toml's seed-0 end state (154 robots, no frontier, 100% ground truth):
    twenty odd vertices, each on a one-sided edge that other edges cross, paired two to
    four hops apart. No closure within one hop exists (the obstruction proves it); dropping
    target edges within two hops closes it. What the closure adds stays within one hop of
    an odd vertex, so no fence gap wider than that is ever bridged."""
    d, cx, eids = _end_state("cave_refused.json")
    raw = eids(d["z_raw"])
    fence = SimpleNamespace(z_raw=raw)
    zr = np.isin(np.arange(cx.n_edges), raw)
    odd, one = closure_zone(cx, zr, drop_hops=1)
    assert len(odd) == 20
    _assert_no_closure_in(cx, zr, (odd, one))
    cert = _certified_in(cx, fence, "whole")
    z = np.isin(np.arange(cx.n_edges), cert.z)
    added, dropped = np.nonzero(z & ~zr)[0], np.nonzero(zr & ~z)[0]
    assert set(added.tolist()) <= set(one.tolist())
    assert len(dropped) and not set(dropped.tolist()) <= set(one.tolist())

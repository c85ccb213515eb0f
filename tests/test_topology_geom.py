"""Test-only geometry for the topology core: positions -> neighbour reports.

The library never sees positions; these helpers compute bearings, line of sight and
touch contacts from positions so that tests know the truth. The tests at the bottom
check the helpers themselves.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

RV = 1.0


def lattice(rows: int, cols: int, s: float, jitter: float = 0.0, rng=None, origin=(0.0, 0.0)) -> np.ndarray:
    """Triangular lattice with spacing s, optional Gaussian jitter (std ``jitter``)."""
    pts = [(origin[0] + c * s + (r % 2) * s / 2.0, origin[1] + r * s * math.sqrt(3) / 2.0)
           for r in range(rows) for c in range(cols)]
    P = np.array(pts, dtype=float)
    if jitter and rng is not None:
        P = P + rng.normal(0.0, jitter, P.shape)
    return P


def _seg_hits_disc(a, b, c, r) -> bool:
    ab = b - a
    t = np.clip(np.dot(c - a, ab) / max(np.dot(ab, ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(a + t * ab - c) < r


def visible_pairs(P: np.ndarray, rv: float = RV, discs=()) -> list[tuple[int, int]]:
    """Pairs within rv whose segment misses every disc (cx, cy, r)."""
    pairs = cKDTree(P).query_pairs(rv, output_type="ndarray")
    out = []
    for a, b in pairs.tolist():
        if any(_seg_hits_disc(P[a], P[b], np.array(d[:2]), d[2]) for d in discs):
            continue
        out.append((a, b))
    return out


def reports(P: np.ndarray, rv: float = RV, discs=(), touch_gap: float | None = None,
            ids=None, drop_one_way=(), noise: float = 0.0, rng=None) -> dict:
    """Per-robot reports (dict form) as robots at P would send them.

    discs: circular obstacles (cx, cy, r): they block sight and give touch contacts to
    robots within ``touch_gap`` of their rim (contact bearing towards the disc centre).
    ids: robot ids (default 0..n-1). drop_one_way: (i, j) pairs where i does not list j.
    noise: Gaussian bearing noise (rad).
    """
    n = P.shape[0]
    ids = list(range(n)) if ids is None else list(ids)
    nb = {i: {} for i in range(n)}
    for a, b in visible_pairs(P, rv, discs):
        d = P[b] - P[a]
        ta = math.atan2(d[1], d[0])
        tb = math.atan2(-d[1], -d[0])
        if noise and rng is not None:
            ta += rng.normal(0, noise)
            tb += rng.normal(0, noise)
        nb[a][b] = ta
        nb[b][a] = tb
    for i, j in drop_one_way:
        nb[i].pop(j, None)
    out = {}
    for i in range(n):
        rep = {"neighbours": {ids[j]: th for j, th in nb[i].items()}}
        if touch_gap is not None:
            for d in discs:
                c = np.array(d[:2])
                dist = np.linalg.norm(P[i] - c) - d[2]
                if dist <= touch_gap:
                    v = c - P[i]
                    rep["touch"] = True
                    rep["touch_bearing"] = math.atan2(v[1], v[0])
        out[ids[i]] = rep
    return out


def boundary_edges_near(cx, P, centre, radius):
    """Edge ids of edges with exactly one triangle whose midpoint is within radius."""
    cnt = np.diff(cx.edge_triangles[0])
    one = np.nonzero(cnt == 1)[0]
    mid = P[cx.index(cx.ids[cx.edges[one]].ravel())].reshape(-1, 2, 2).mean(1)
    near = np.linalg.norm(mid - np.asarray(centre), axis=1) < radius
    return one[near], one[~near]


# ------------------------------------------------------------------ helper tests
def test_lattice_spacing():
    P = lattice(3, 4, 0.8)
    d = np.linalg.norm(P[1] - P[0])
    assert abs(d - 0.8) < 1e-12
    assert abs(np.linalg.norm(P[4] - P[0]) - 0.8) < 1e-12


def test_reports_bearings_and_occlusion():
    P = np.array([[0.0, 0.0], [0.9, 0.0], [0.0, 0.9]])
    r = reports(P)
    assert abs(r[0]["neighbours"][1] - 0.0) < 1e-12
    assert abs(r[1]["neighbours"][0] - (-math.pi)) < 1e-12 or abs(r[1]["neighbours"][0] - math.pi) < 1e-12
    assert abs(r[0]["neighbours"][2] - math.pi / 2) < 1e-12
    r2 = reports(P, discs=[(0.45, 0.0, 0.1)], touch_gap=0.5)
    assert 1 not in r2[0]["neighbours"] and 0 not in r2[1]["neighbours"]
    assert r2[0]["touch"] and abs(r2[0]["touch_bearing"]) < 1e-12

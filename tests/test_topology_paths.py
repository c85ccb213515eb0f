"""Push paths, push targets (spec 4.2, 4.4) and the GVG wavefront (spec 7.3)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from swarmcover.coordinator import (
    TopologyParams,
    build_complex,
    compute_gvg,
    deployment_point,
    detect_fence,
    frontier_desired_bearings,
    gvg_thin,
    plan_push_targets,
    plan_pushes,
    push_desired_bearings,
    wrap,
)
from test_topology_geom import lattice, reports

DEG = math.pi / 180


def _weights(cx, f, w_o):
    w = np.ones(cx.n_edges)
    w[f.obstacle] = w_o
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    return csr_matrix((np.concatenate([w, w]), (np.concatenate([u, v]), np.concatenate([v, u]))), shape=(cx.n, cx.n))


def _path_cost(cx, f, path, w_o):
    loc = cx.index(list(path))
    obst = set(f.obstacle.tolist())
    cost = 0.0
    for a, b in zip(loc[:-1], loc[1:]):
        e = int(cx.edge_index(a, b))
        assert e >= 0, "consecutive path vertices must be adjacent"
        cost += w_o if e in obst else 1.0
    return cost


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_push_is_a_shortest_path_with_the_spec_tie_breaks(seed):
    rng = np.random.default_rng(seed)
    P = lattice(7, 9, 0.8, 0.03 * seed, rng)
    cx = build_complex(reports(P))
    # remember the bottom row as obstacle edges so they cost w_O
    bottom = [(i, i + 1) for i in range(8)]
    f = detect_fence(cx, forced_obstacle=bottom)
    assert len(f.obstacle) == 8
    src = 4  # bottom row, middle
    (push,) = plan_pushes(cx, f, [src])
    assert push.start == src and push.frontier in f.deployments
    assert push.cost == _path_cost(cx, f, push.vertices, 3.0)
    dist = dijkstra(_weights(cx, f, 3.0), indices=cx.index_of(src))
    cands = {v: dist[cx.index_of(v)] for v in f.deployments}
    best = min(cands.values())
    assert push.cost == best
    # among the nearest, the largest clearance, then the lowest id
    near = [v for v, d in cands.items() if d == best]
    clear = {v: max(d.clearance for d in f.deployments[v]) for v in near}
    top = max(clear.values())
    assert push.frontier == min(v for v in near if clear[v] == top)
    assert push.deployment.clearance == top
    # the deployment used is one of the frontier vertex's own
    assert push.deployment in f.deployments[push.frontier]


def test_obstacle_edges_are_avoided_when_cheaper():
    import dataclasses

    P = lattice(2, 9, 0.8)  # bottom row 0..8, top row 9..17
    cx = build_complex(reports(P))
    f = detect_fence(cx, forced_obstacle=[(i, i + 1) for i in range(8)])
    only8 = dataclasses.replace(f, deployments={8: f.deployments[8]})
    (p3,) = plan_pushes(cx, only8, [0], params=TopologyParams(w_obstacle=3.0))
    assert p3.frontier == 8 and p3.cost == 9.0  # up, along the top row, down
    obst = set(f.obstacle.tolist())
    loc = cx.index(list(p3.vertices))
    assert not any(int(cx.edge_index(a, b)) in obst for a, b in zip(loc[:-1], loc[1:]))
    (p1,) = plan_pushes(cx, only8, [0], params=TopologyParams(w_obstacle=1.0))
    assert p1.cost == 8.0 and p1.vertices == tuple(range(9))  # straight along the wall


def test_several_pushes_are_vertex_disjoint_and_apart():
    rng = np.random.default_rng(3)
    P = lattice(10, 10, 0.8, 0.02, rng)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    srcs = [44, 45, 54, 55]
    pushes = plan_pushes(cx, f, srcs[:1], redundant=srcs[1:], max_paths=4)
    assert len(pushes) >= 2
    seen: set[int] = set()
    edges = set()
    d0 = TopologyParams().d0
    for p in pushes:
        assert not seen & set(p.vertices)
        seen |= set(p.vertices)
        assert p.vertices[0] in srcs
        if p.deployment.edge is not None:
            assert p.deployment.edge not in edges
            edges.add(p.deployment.edge)
    # estimated new positions of pushes from neighbouring frontier robots are apart
    for a in pushes:
        for b in pushes:
            if a is b or b.frontier not in cx.neighbours(a.frontier).tolist():
                continue
            pa = deployment_point(cx, a.frontier, a.deployment, d0)
            pb = deployment_point(cx, a.frontier, b.deployment, d0)
            assert np.linalg.norm(pa - pb) >= 0.5 * d0


def test_deployment_point_matches_geometry_for_parallel_frames():
    s = 0.9
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, s * math.sqrt(3) / 2]])
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    d1 = [d for d in f.deployments[1] if d.edge == (0, 1)][0]
    # robot 1's deployment seen from robot 0's frame, spacing = the true spacing s
    q = deployment_point(cx, 0, d1, s)
    assert np.allclose(q, [s / 2, -s * math.sqrt(3) / 2])


def test_frontier_desired_bearings_make_an_equilateral_triangle():
    # f at the origin, j at bearing 0; deploy at +60 deg
    out = frontier_desired_bearings({7: 0.0, 9: math.pi}, 60 * DEG, d0=0.9, rv=1.0, old_vertex=3)
    assert set(out) == {7, 3}  # 9 is 1.56 d0 away from the target: out of range
    assert out[7] == pytest.approx(-60 * DEG)
    assert out[3] == pytest.approx(wrap(240 * DEG))
    # bearings carry no scale: at the real equilateral spot (any side length) they match
    for L in (0.5, 0.8):
        p = L * np.array([math.cos(60 * DEG), math.sin(60 * DEG)])
        tj = math.atan2(-p[1], L - p[0])
        to = math.atan2(-p[1], -p[0])
        assert wrap(tj - out[7]) == pytest.approx(0.0, abs=1e-12)
        assert wrap(to - out[3]) == pytest.approx(0.0, abs=1e-12)


def test_push_remapping_keys_by_vertex_and_maps_to_new_occupants():
    path = [10, 11, 12, 13]  # 10 = source vertex, 13 = frontier vertex
    occ = {10: 100, 11: 101, 12: 102, 13: 103, 20: 200, 21: 201}
    rec = {
        11: {10: 3.0, 12: 0.0, 20: 1.0},
        12: {11: 3.1, 13: 0.1, 20: 2.0, 21: -1.0},
        13: {12: 3.0, 21: -2.0},
    }
    movers = push_desired_bearings(path, rec, occ, new_robot=999)
    assert [(m.robot, m.from_vertex, m.to_vertex) for m in movers] == [(100, 10, 11), (101, 11, 12), (102, 12, 13)]
    m0, m1, m2 = movers
    assert m0.by_vertex == rec[11]
    assert m0.by_robot == {999: 3.0, 101: 0.0, 200: 1.0}  # 10 now held by the new robot, 12 by 101
    assert m1.by_robot == {100: 3.1, 102: 0.1, 200: 2.0, 201: -1.0}
    assert m2.by_robot == {101: 3.0, 201: -2.0}
    # a redundant start vertex is left empty: its landmark is dropped
    m0r = push_desired_bearings(path, rec, occ, new_robot=None)[0]
    assert m0r.by_robot == {101: 0.0, 200: 1.0} and 10 in m0r.by_vertex
    full = plan_push_targets(path, rec, occ, 60 * DEG, d0=0.9, rv=1.0, new_robot=999)
    last = full[-1]
    assert last.robot == 103 and last.to_vertex is None
    assert 13 in last.by_vertex and last.by_robot[102] == last.by_vertex[13]  # old vertex -> follower
    assert 103 not in last.by_robot and all(103 not in m.by_robot for m in full)


def test_frontier_only_push_from_a_source_on_the_frontier():
    full = plan_push_targets([5], {5: {6: 0.0}}, {5: 50, 6: 60}, 60 * DEG, d0=0.9, rv=1.0, new_robot=77)
    assert len(full) == 1 and full[0].robot == 50
    assert full[0].by_robot[77] == full[0].by_vertex[5] and full[0].by_robot[60] == full[0].by_vertex[6]


def test_gvg_corridor_is_its_middle_row():
    rows, cols = 5, 12
    P = lattice(rows, cols, 0.8)
    cx = build_complex(reports(P))
    labels = {i: 0 for i in range(cols)} | {(rows - 1) * cols + i: 1 for i in range(cols)}
    g = compute_gvg(cx, labels)
    assert g.vertices == frozenset(range(2 * cols, 3 * cols))
    assert g.thinned == g.vertices  # a path: nothing collapses, leaves kept
    assert all(g.distance[v] == 2 for v in g.vertices)
    # hop distances are BFS distances to the nearest wall
    A = csr_matrix((np.ones(cx.n_edges), (cx.edges[:, 0], cx.edges[:, 1])), shape=(cx.n, cx.n))
    d = dijkstra(A, directed=False, indices=list(labels), unweighted=True, min_only=True)
    assert all(g.distance[int(v)] == d[i] for i, v in enumerate(cx.ids))
    short = gvg_thin(cx, g.vertices, keep_leaves=False)
    assert len(short) == 1  # without the leaf rule a path collapses to a point


def test_gvg_thinning_collapses_a_band_but_keeps_it_connected():
    P = lattice(2, 10, 0.8)
    cx = build_complex(reports(P))
    band = frozenset(range(20))
    thin = gvg_thin(cx, band)
    assert thin and thin < band
    A = csr_matrix((np.ones(cx.n_edges), (cx.edges[:, 0], cx.edges[:, 1])), shape=(cx.n, cx.n))
    keep = sorted(thin)
    sub = A[keep][:, keep]
    from scipy.sparse.csgraph import connected_components
    assert connected_components(sub, directed=False)[0] == 1
    # nothing left is removable: every kept vertex with >= 2 GVG neighbours has a link
    # that is not a path
    assert gvg_thin(cx, thin) == thin


def test_obstacle_segments_label_components():
    from swarmcover.coordinator import obstacle_segments

    P = lattice(5, 12, 0.8)
    cx = build_complex(reports(P))
    f = detect_fence(cx, forced_obstacle=[(i, i + 1) for i in range(11)] + [(48 + i, 49 + i) for i in range(11)])
    lab = obstacle_segments(cx, f.obstacle)
    assert set(lab.values()) == {0, 1}
    assert all(lab[i] == 0 for i in range(12)) and all(lab[48 + i] == 1 for i in range(12))
    g = compute_gvg(cx, lab)
    assert g.vertices == frozenset(range(24, 36))

"""Redundant robots: greedy local removal keeps the certificate and the graph connected."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from swarmcover.coordinator import build_complex, certify, detect_fence, find_redundant, remove_robot, verify_certificate
from swarmcover.coordinator.topology.redundancy import link_is_acyclic
from test_topology_geom import lattice, reports

seeds = st.integers(min_value=0, max_value=2**32 - 1)


def _components(cx):
    g = csr_matrix((np.ones(cx.n_edges), (cx.edges[:, 0], cx.edges[:, 1])), shape=(cx.n, cx.n))
    return connected_components(g, directed=False)[0]


def _check(cx, f, red, protected=()):
    cert = red.certificate
    assert cert.certified and verify_certificate(cx, cert)
    removed = set(red.removed)
    assert not removed & set(cert.support.tolist())
    assert not removed & set(f.fence_vertices) and not removed & set(protected)
    assert len(removed) == len(red.removed)
    # replay: every removal, in order, leaves a certifiable and connected complex
    z_nodes = cx.edge_nodes(cert.z)
    cur = cx
    comps = _components(cx)
    for v in red.removed:
        cur = remove_robot(cur, v)
        c = certify(cur, z_nodes)
        assert c.certified and verify_certificate(cur, c), v
        assert _components(cur) == comps


@settings(max_examples=25, deadline=None)
@given(seed=seeds, spacing=st.floats(0.45, 0.8))
def test_jittered_lattice_removal_keeps_certificate(seed, spacing):
    rng = np.random.default_rng(seed)
    P = lattice(9, 9, spacing, 0.03, rng)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    cert = certify(cx, f)
    assert cert.certified
    src = [int(rng.integers(cx.n))]
    red = find_redundant(cx, f, cert, protected=src)
    _check(cx, f, red, src)


@settings(max_examples=20, deadline=None)
@given(seed=seeds)
def test_random_swarm_removal_keeps_certificate(seed):
    rng = np.random.default_rng(seed)
    P = rng.uniform(0, 3.0, (int(rng.integers(20, 70)), 2))
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    cert = certify(cx, f)
    red = find_redundant(cx, f, cert)
    if not cert.certified:
        assert red.removed == ()
        return
    _check(cx, f, red)


def test_tight_lattice_has_no_redundant_robot():
    P = lattice(8, 8, 0.8, 0.0)
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    red = find_redundant(cx, f)
    assert red.removed == () and red.tried == cx.n - len(f.fence_vertices)


def test_dominated_twin_is_removed_first_and_protection_holds():
    P = lattice(6, 6, 0.8, 0.0)
    c = int(np.argmin(np.linalg.norm(P - P.mean(0), axis=1)))
    twin = P[c] + np.array([0.05, 0.02])
    P2 = np.vstack([P, twin])
    cx = build_complex(reports(P2))
    f = detect_fence(cx)
    red = find_redundant(cx, f)
    assert len(red.removed) == 1 and red.removed[0] in (c, len(P))
    _check(cx, f, red)
    red2 = find_redundant(cx, f, protected=[c, len(P)])
    assert red2.removed == ()


def test_link_tests():
    cycle = {0: {1, 5}, 1: {0, 2}, 2: {1, 3}, 3: {2, 4}, 4: {3, 5}, 5: {4, 0}}
    assert link_is_acyclic(cycle) == (False, None)
    path = {0: {1}, 1: {0, 2}, 2: {1}}
    assert link_is_acyclic(path)[0]
    cone = {0: {1, 2, 3}, 1: {0}, 2: {0}, 3: {0}}
    assert link_is_acyclic(cone) == (True, 0)
    two = {0: {1}, 1: {0}, 2: set()}
    assert not link_is_acyclic(two)[0]
    # two triangles sharing an edge: a disc
    disc = {0: {1, 2}, 1: {0, 2, 3}, 2: {0, 1, 3}, 3: {1, 2}}
    assert link_is_acyclic(disc)[0]
    # the flag complex fills a 3-cycle but not a 4-cycle
    assert link_is_acyclic({0: {1, 2}, 1: {0, 2}, 2: {0, 1}})[0]
    assert not link_is_acyclic({0: {1, 3}, 1: {0, 2}, 2: {1, 3}, 3: {2, 0}})[0]


def test_not_certified_removes_nothing():
    P = lattice(6, 6, 0.8, 0.0)
    cx = build_complex(reports(P))
    bad = [0]  # a single edge is not a cycle
    red = find_redundant(cx, bad)
    assert red.removed == () and not red.certificate.certified


def test_removal_keeps_a_closed_certificate_valid_for_the_fence():
    """pillar_hall's end state needs closure edges; the rerouted certificate keeps the
    same target and closure and still passes verify against the Fence."""
    import json
    from pathlib import Path

    from swarmcover.coordinator import TopologyParams

    d = json.loads((Path(__file__).parent / "data" / "pillar_hall_end.json").read_text())
    reps = {int(v): {"neighbours": {int(k): b for k, b in r["neighbours"].items()},
                     "touch": r["touch"], "touch_bearing": r["touch_bearing"]}
            for v, r in d["reports"].items()}
    cx = build_complex(reps)
    f = detect_fence(cx, TopologyParams(), test_drive_failures={int(k): v for k, v in d["test_drive_failures"].items()})
    cert = certify(cx, f)
    assert cert.certified and cert.closure.size
    red = find_redundant(cx, f, cert)
    assert red.removed
    rc = red.certificate
    assert verify_certificate(cx, rc, f)
    assert np.array_equal(rc.z, cert.z) and np.array_equal(rc.closure, cert.closure)
    assert np.array_equal(rc.target, cert.target) and rc.closable
    assert not set(red.removed) & set(rc.support.tolist())

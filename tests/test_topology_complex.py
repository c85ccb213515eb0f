"""Rips complex from neighbour reports: symmetric visibility, cliques, incremental updates."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from swarmcover.coordinator import RobotReport, add_robot, build_complex, remove_robot
from test_topology_geom import reports, visible_pairs

points = st.integers(min_value=0, max_value=2**32 - 1).map(np.random.default_rng)


def _brute(P, rv=1.0):
    E = set(visible_pairs(P, rv))
    T = {t for t in itertools.combinations(range(len(P)), 3)
         if (t[0], t[1]) in E and (t[0], t[2]) in E and (t[1], t[2]) in E}
    return E, T


@settings(max_examples=40, deadline=None)
@given(rng=points, n=st.integers(0, 30), side=st.floats(0.5, 4.0))
def test_edges_and_triangles_are_the_cliques(rng, n, side):
    P = rng.uniform(0, side, (n, 2))
    cx = build_complex(reports(P))
    E, T = _brute(P)
    assert set(map(tuple, cx.edges.tolist())) == E
    assert set(map(tuple, cx.triangles.tolist())) == T
    # stored bearings are theta^u_v and theta^v_u
    for (u, v), (buv, bvu) in zip(cx.edges.tolist(), cx.bearings.tolist()):
        d = P[v] - P[u]
        assert abs(math.remainder(buv - math.atan2(d[1], d[0]), 2 * math.pi)) < 1e-9
        assert abs(math.remainder(bvu - math.atan2(-d[1], -d[0]), 2 * math.pi)) < 1e-9
    # every triangle's edges are edges
    if cx.n_triangles:
        assert np.all(cx.tri_edges >= 0)


def test_one_way_sighting_is_dropped():
    P = np.array([[0.0, 0.0], [0.5, 0.0], [0.25, 0.4]])
    cx = build_complex(reports(P, drop_one_way=[(0, 1)]))
    assert set(map(tuple, cx.edges.tolist())) == {(0, 2), (1, 2)}
    assert cx.n_triangles == 0


def test_report_forms_and_unknown_ids():
    reps = {
        10: RobotReport({20: 0.0, 99: 1.0}),
        20: {"neighbours": [10, 30], "bearings": [math.pi * 0.999, 0.5]},
        30: {"neighbors": {20: -2.0}, "touch": True, "touch_bearing": 0.3},
    }
    cx = build_complex(reps)
    assert cx.ids.tolist() == [10, 20, 30]
    assert cx.edge_nodes().tolist() == [[10, 20], [20, 30]]
    assert cx.bearing(20, 30) == 0.5 and cx.bearing(30, 20) == -2.0
    assert cx.touch.tolist() == [False, False, True]
    assert sorted(cx.neighbours(20).tolist()) == [10, 30]


@settings(max_examples=30, deadline=None)
@given(rng=points, n=st.integers(2, 25), k=st.integers(0, 24))
def test_incremental_update_equals_rebuild(rng, n, k):
    P = rng.uniform(0, 2.5, (n, 2))
    ids = rng.permutation(1000)[:n].tolist()
    reps = reports(P, ids=ids)
    full = build_complex(reps)
    rid = ids[k % n]
    without = build_complex({i: r for i, r in reps.items() if i != rid})
    removed = remove_robot(full, rid)
    added = add_robot(without, reps, rid)
    for a, b in ((removed, without), (added, full)):
        assert a.ids.tolist() == b.ids.tolist()
        assert a.edges.tolist() == b.edges.tolist()
        assert a.triangles.tolist() == b.triangles.tolist()
        assert np.allclose(a.bearings, b.bearings)
        assert a.touch.tolist() == b.touch.tolist()


def test_report_ids_are_validated():
    good = {"neighbours": {}}
    with pytest.raises(ValueError, match=r"mix ints and strings \('1' and 1 would collapse\)"):
        build_complex({1: good, "1": good})
    with pytest.raises(ValueError, match="mix ints and strings"):
        build_complex({1: good, "2": good})
    with pytest.raises(ValueError, match=r"negative robot ids \[-3\]"):
        build_complex({-3: good, 1: good})
    with pytest.raises(ValueError, match="name the same robot"):
        build_complex({"1": good, "01": good})
    with pytest.raises(ValueError, match="not an integer id"):
        build_complex({1.5: good})
    with pytest.raises(ValueError, match="is a bool"):
        build_complex({True: good})
    # neighbour ids follow the same rules, inside the report that lists them
    with pytest.raises(ValueError, match=r"report of robot 1: neighbours: robot ids mix"):
        build_complex({1: {"neighbours": {2: 0.0, "2": 0.1}}, 2: good})
    with pytest.raises(ValueError, match=r"report of robot 1: neighbours: negative robot ids"):
        build_complex({1: {"neighbours": {-2: 0.0}}, 2: good})
    with pytest.raises(ValueError, match="negative robot ids"):
        build_complex({1: RobotReport({-2: 0.0})})
    # one key type is fine, strings included (JSON)
    cx = build_complex({"1": {"neighbours": {"2": 0.0}}, "2": {"neighbours": {"1": math.pi}}})
    assert cx.ids.tolist() == [1, 2] and cx.n_edges == 1
    cx = build_complex({np.int64(1): {"neighbours": {np.int64(2): 0.0}}, 2: {"neighbours": {1: math.pi}}})
    assert cx.n_edges == 1
    with pytest.raises(ValueError, match="negative robot id"):
        add_robot(cx, {-1: good}, -1)

"""The ground floor stays the only one: one wrap, one circular mean (issue 17), and they
behave as documented, whatever the input (property tests)."""
from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from swarmcover.ground.angles import (PI, bearing_spread, circmean, circular_mean, side, side_array,
                                      wrap, wrap_array)

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("agents", "bus", "coordinator", "ground", "hwbridge", "swarmcover", "viz", "world", "bench")
# function names that exist once, in the module named here
ONE_HOME = {
    "wrap": "ground/angles.py", "wrap_array": "ground/angles.py", "_wrap": None,
    "circmean": "ground/angles.py", "circular_mean": "ground/angles.py", "circ_mean": None,
    "bearing_spread": "ground/angles.py",
}

angles = st.floats(-1e4, 1e4, allow_nan=False)


# the independent oracle of bench/truth.py keeps its own arithmetic on purpose: it must not
# share code with what it judges (issue 21)
INDEPENDENT = {"bench/oracle.py", "bench/truth.py"}


def _defs():
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path.relative_to(ROOT).as_posix() in INDEPENDENT:
                continue
            tree = ast.parse(path.read_text(), str(path))
            for node in tree.body:  # module level: a method or a closure named so is another concept
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    yield path.relative_to(ROOT).as_posix(), node.name, node.lineno


def test_angle_helpers_are_defined_once_in_the_ground_floor():
    stray = [f"{p}:{line} defines {name}" for p, name, line in _defs()
             if name in ONE_HOME and p != ONE_HOME[name]]
    assert not stray, "a second copy of a ground-floor helper: " + "; ".join(stray)


@given(angles)
def test_wrap_is_half_open_and_keeps_the_angle(a):
    w = wrap(a)
    assert -PI <= w < PI
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)


@given(st.lists(angles, min_size=1, max_size=20))
def test_wrap_array_agrees_with_wrap(xs):
    wa = wrap_array(np.array(xs))
    assert np.all((wa >= -PI) & (wa < PI))
    assert np.allclose(np.cos(wa), np.cos([wrap(x) for x in xs]), atol=1e-9)
    assert np.allclose(np.sin(wa), np.sin([wrap(x) for x in xs]), atol=1e-9)
    inside = [x for x in xs if -PI <= x < PI]
    assert wrap_array(np.array(inside)).tolist() == inside == [wrap(x) for x in inside]


def test_exact_pi_wraps_to_minus_pi_in_both_and_has_no_side():
    assert wrap(PI) == -PI and wrap(-PI) == -PI and wrap(3 * PI) == -PI
    assert wrap_array(np.array([PI, -PI, -1e-300]))[0] == -PI
    assert wrap_array(np.array([-1e-20]))[0] < PI          # np.mod rounding to 2pi is caught
    assert side(PI) == 0 and side(-PI) == 0 and side(0.0) == 0
    assert side(0.1) == 1 and side(-0.1) == -1 and side(PI - 1e-9) == 1
    assert side_array(np.array([PI, -PI, 0.0, 0.2, -0.2])).tolist() == [0, 0, 0, 1, -1]


@given(angles, st.floats(0.01, 1.0))
def test_circular_mean_of_a_symmetric_pair_is_its_centre(c, half):
    m, r = circular_mean([c - half, c + half])
    assert abs(wrap(m - c)) < 1e-6
    assert math.isclose(r, math.cos(half), abs_tol=1e-9)
    assert abs(wrap(circmean([c - half, c + half]) - c)) < 1e-6


def test_circular_mean_of_nothing_and_of_opposites():
    assert circular_mean([]) == (0.0, 0.0)
    assert circmean([]) is None and circmean([0.0, PI]) is None


# plane geometry: closed rings -> wall segments (world/maps.py and hwbridge/room.py each had
# their own) and a WorldInfo's flat polygon -> points (hwbridge, fake-robot, scene, ros2)
GEOMETRY_HOME = {"rings_to_segments": "ground/geometry.py", "rings_to_walls": None,
                 "flat_to_points": "ground/geometry.py", "flat_to_polygon": None,
                 "point_in_polygon": "ground/geometry.py", "edge_distance": "ground/geometry.py",
                 "signed_area": "ground/geometry.py", "polygon_signed_area": None,
                 "lens_radii": "ground/geometry.py", "in_lenses": "ground/geometry.py",
                 "lens_reach": "ground/geometry.py"}


def test_geometry_helpers_are_defined_once_in_the_ground_floor():
    stray = [f"{p}:{line} defines {name}" for p, name, line in _defs()
             if name in GEOMETRY_HOME and p != GEOMETRY_HOME[name]]
    assert not stray, "a second copy of a ground-floor helper: " + "; ".join(stray)


def test_rings_to_segments_of_a_square_a_repeated_vertex_and_nothing():
    from swarmcover.ground.geometry import rings_to_segments
    sq = [[0, 0], [1, 0], [1, 1], [0, 1]]
    w = rings_to_segments([sq])
    assert w.dtype == np.float64 and w.flags.c_contiguous
    assert w.tolist() == [[0, 0, 1, 0], [1, 0, 1, 1], [1, 1, 0, 1], [0, 1, 0, 0]]
    # a repeated vertex gives no zero-length wall; a lone point and an empty ring none at all
    w2 = rings_to_segments([[[0, 0], [1, 0], [1, 0], [1, 1], [0, 1]], [[5, 5]], []])
    assert w2.tolist() == w.tolist()
    assert rings_to_segments([]).shape == (0, 4) and rings_to_segments([[[2, 3]]]).shape == (0, 4)
    assert rings_to_segments([[[0, 0], [0, 0]]]).shape == (0, 4)


coords = st.floats(-100, 100, allow_nan=False).map(lambda v: round(v, 1))


@given(st.lists(st.lists(st.tuples(coords, coords), max_size=7), max_size=4))
def test_rings_to_segments_is_every_nonzero_edge_in_ring_order(rings):
    from swarmcover.ground.geometry import rings_to_segments
    want = [[*r[k], *r[(k + 1) % len(r)]] for r in rings if len(r) >= 2 for k in range(len(r))
            if r[k] != r[(k + 1) % len(r)]]
    w = rings_to_segments(rings)
    assert w.shape == (len(want), 4) and w.tolist() == want


def test_flat_to_points_pairs_floats_and_drops_an_odd_tail():
    from swarmcover.ground.geometry import flat_to_points
    assert flat_to_points([0, 1, 2.5, 3, 4]) == ((0.0, 1.0), (2.5, 3.0))
    assert all(type(c) is float for p in flat_to_points([1, 2]) for c in p)
    assert flat_to_points([]) == () and flat_to_points([7.0]) == ()


# one TOML writer (resolved.toml, `config defaults`, docs/config.md); two copies once
# disagreed on escaping and on keys that are not bare
TOML_HOME = {"dumps_toml": "ground/toml.py", "toml_value": "ground/toml.py",
             "toml_key": "ground/toml.py", "_toml_value": None, "_toml_key": None}


def test_the_toml_writer_is_defined_once_in_the_ground_floor():
    stray = [f"{p}:{line} defines {name}" for p, name, line in _defs()
             if name in TOML_HOME and p != TOML_HOME[name]]
    assert not stray, "a second copy of a ground-floor helper: " + "; ".join(stray)


_keys = st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=8)
_scalars = (st.booleans() | st.integers(-2**63, 2**63 - 1)
            | st.floats(allow_nan=False) | st.text(st.characters(blacklist_categories=("Cs",)),
                                                   max_size=12))
_values = st.recursive(_scalars, lambda inner: st.lists(inner, max_size=4)
                       | st.dictionaries(_keys, inner, max_size=3), max_leaves=8)


@settings(deadline=None)  # a loaded CI box; the test is about values, not time
@given(st.dictionaries(_keys, _values | st.dictionaries(_keys, _values, max_size=3),
                       max_size=5))
def test_dumps_toml_round_trips_through_tomllib(d):
    import tomllib

    from swarmcover.ground.toml import dumps_toml
    assert tomllib.loads(dumps_toml(d)) == d


@settings(deadline=None)  # the first example imports world.maps (matplotlib)
@given(st.lists(st.tuples(st.floats(0.1, 5), st.floats(-math.pi, math.pi)), min_size=3,
                max_size=12, unique_by=lambda p: round(p[1], 2)),
       st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6)), min_size=1, max_size=20))
def test_scalar_polygon_forms_agree_with_the_world_s_array_forms(rays, points):
    """ground.geometry's pure-Python point_in_polygon, signed_area and edge_distance (the
    bridge's geofence, config checks) against world/maps.py's vectorised forms, on star-shaped
    polygons (vertices sorted by angle around the origin), random points off the edges."""
    from swarmcover.ground.geometry import edge_distance, point_in_polygon, rings_to_segments, signed_area
    from swarmcover.world.maps import point_segment_distance, points_in_polygon, polygon_area
    poly = [(r * math.cos(a), r * math.sin(a)) for r, a in sorted(rays, key=lambda p: p[1])]
    assert math.isclose(abs(signed_area(poly)), polygon_area(poly), rel_tol=1e-9, abs_tol=1e-9)
    walls = rings_to_segments([poly])
    d = point_segment_distance(np.asarray(points), walls).min(axis=1)
    inside = points_in_polygon(points, poly)
    for (x, y), dk, ik in zip(points, d, inside):
        assert math.isclose(edge_distance(x, y, poly), dk, rel_tol=1e-9, abs_tol=1e-9)
        if dk > 1e-6:
            assert point_in_polygon(x, y, poly) == bool(ik), (x, y)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.floats(-PI, PI, allow_nan=False), max_size=7))
def test_bearing_spread_is_the_determinant_of_the_bearing_normals_gram_matrix(angles):
    """det(sum n n^T), n the unit normals (what bearing_spread computes, in O(n)) = the sum
    over pairs of sin^2 of the difference (the oracle here): zero with fewer than two
    bearings, and for bearings on one line (opposite too)."""
    pairs = sum(math.sin(x - y) ** 2 for i, x in enumerate(angles) for y in angles[:i])
    assert bearing_spread(angles) == pytest.approx(pairs, abs=1e-9)
    if angles:
        a = angles[0]
        assert bearing_spread([a, a + PI, a, wrap(a - PI)]) == pytest.approx(0.0, abs=1e-12)
    assert bearing_spread([0.0, PI / 6]) == pytest.approx(0.25)
    assert bearing_spread([0.0, 2 * PI / 3, -2 * PI / 3]) == pytest.approx(2.25)


# the lenses at a vertex: the wall sweep's room test (agents.sweep.SweepGeom.held)
_pt = st.tuples(st.floats(-1.6, 1.6), st.floats(-1.6, 1.6))


@settings(max_examples=300, deadline=None)
@given(st.floats(0.3, 1.0), st.floats(-math.pi, math.pi), st.floats(0.3, 0.8),
       st.lists(_pt, max_size=6), _pt, st.floats(0.0, 1.0))
def test_a_point_in_the_lenses_is_within_the_edge_s_reach_of_a_robot_and_so_is_its_way_home(
        L, a, depth, others, x, t):
    """Whatever the landmarks: a point in the lenses at the vertex lies within
    sqrt(depth^2 + |q|^2 / 4) (the edge's own guarantee) of the vertex, q or a landmark, and
    so does every point between it and the vertex (the union is star-shaped from it: a wall
    followed inside it encloses nothing outside it)."""
    from swarmcover.ground.geometry import in_lenses, lens_radii
    q = (L * math.cos(a), L * math.sin(a))
    lenses = lens_radii(q, depth, others)
    reach = math.sqrt(depth ** 2 + 0.25 * L ** 2)
    robots = [(0.0, 0.0), q, *others]
    if in_lenses(x[0], x[1], lenses):
        for px, py in ((x[0], x[1]), (t * x[0], t * x[1])):
            assert in_lenses(px, py, lenses)
            assert min(math.dist((px, py), r) for r in robots) <= reach + 1e-9


@settings(max_examples=300, deadline=None)
@given(st.floats(0.3, 1.0), st.floats(0.3, 0.8), st.lists(_pt, max_size=6),
       st.floats(-math.pi, math.pi), st.floats(0.2, 3.0))
def test_lens_reach_is_where_the_ray_leaves_the_lenses(L, depth, others, theta, cap):
    """lens_reach: the ray from the vertex is in the lenses up to it (sampled) and out of
    them just beyond it, unless the cap stopped it; never less than the depth (the edge's
    lens holds the disk of that radius round the vertex)."""
    from swarmcover.ground.geometry import in_lenses, lens_radii, lens_reach
    lenses = lens_radii((L, 0.0), depth, others)
    s = lens_reach(theta, lenses, cap=cap)
    u = (math.cos(theta), math.sin(theta))
    assert s >= min(depth, cap) - 1e-6 and s <= cap
    for k in range(21):
        r = s * k / 20 - 1e-6
        assert in_lenses(r * u[0], r * u[1], lenses)
    if s < cap - 1e-5:
        r = s + 1e-5
        assert not in_lenses(r * u[0], r * u[1], lenses)


def test_a_landmark_s_lens_holds_what_the_edge_s_does_not():
    """The vertex at the origin, its edge 0.9 m along x, a neighbour 0.87 m along y:
    (-0.5, 0.6) is out of the edge's lens (0.75 m) and in the neighbour's (sqrt(0.765 -
    0.87^2 / 4) = 0.76 m about the segment); (-0.5, -0.6) is in neither."""
    from swarmcover.ground.geometry import in_lenses, lens_radii, lens_reach
    lenses = lens_radii((0.9, 0.0), 0.75, [(0.0, 0.87)])
    assert lenses[1][2] == pytest.approx(math.sqrt(0.75 ** 2 + 0.45 ** 2 - 0.87 ** 2 / 4))
    assert in_lenses(-0.5, 0.6, lenses) and not in_lenses(-0.5, -0.6, lenses)
    assert lens_reach(-math.pi / 2, lenses) == pytest.approx(lenses[1][2], abs=1e-5)
    assert lens_reach(-math.pi / 2, lenses[:1]) == pytest.approx(0.75, abs=1e-5)
    assert lens_reach(math.pi / 2, lenses) == pytest.approx(0.87 + lenses[1][2], abs=1e-5)
    assert lens_reach(math.pi / 2, lenses, cap=0.9) == 0.9

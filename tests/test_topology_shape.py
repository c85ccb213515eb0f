"""The swarm's shape from bearings (coordinator.topology.shape): recovered up to translation, with
the scale from commanded lengths; lattice targets beyond a fence edge."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from swarmcover.coordinator.topology import shape
from swarmcover.coordinator.topology.shape import Lattice, align_headings, estimate_shape, lattice_target


def _scatter(seed: int, n: int, rv: float = 1.0):
    """n points, each new one within 0.5-0.95 rv of two earlier points that see each other
    (so the bearing graph is triangulated, hence bearing rigid)."""
    rng = np.random.default_rng(seed)
    P = [np.zeros(2), np.array([0.8 * rv, 0.0])]
    while len(P) < n:
        a, b = rng.choice(len(P), 2, replace=False)
        if np.linalg.norm(P[a] - P[b]) > 0.9 * rv:
            continue
        mid, d = (P[a] + P[b]) / 2, P[b] - P[a]
        q = mid + rng.choice([-1, 1]) * rng.uniform(0.4, 0.8) * np.array([-d[1], d[0]]) / np.linalg.norm(d) * rv
        if min(np.linalg.norm(q - p) for p in P) > 0.35 * rv and \
                max(np.linalg.norm(q - P[a]), np.linalg.norm(q - P[b])) <= 0.95 * rv:
            P.append(q)
    return np.array(P)


def _bearings(P, phi, rv=1.0, noise=0.0, rng=None):
    nbrs = {}
    for i, p in enumerate(P):
        nbrs[i] = {}
        for j, q in enumerate(P):
            if i != j and np.linalg.norm(q - p) <= rv:
                th = math.atan2(q[1] - p[1], q[0] - p[0]) - phi[i]
                if noise:
                    th += rng.normal(0.0, noise)
                nbrs[i][j] = th
    return nbrs


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 40), rotate=st.booleans())
def test_shape_is_recovered_up_to_translation(seed, n, rotate):
    P = _scatter(seed, n)
    rng = np.random.default_rng(seed + 1)
    phi = rng.uniform(-math.pi, math.pi, n) if rotate else np.zeros(n)
    nbrs = _bearings(P, phi)
    kinds = {i: ("unicycle" if rotate else "holonomic") for i in range(n)}
    head = align_headings(nbrs, kinds, root=0)
    # relative headings recovered (root = 0)
    for i in range(n):
        assert abs(math.remainder(head[i] - (phi[i] - phi[0]), 2 * math.pi)) < 1e-6
    # one known length (the first neighbour of the root) fixes the scale
    j = next(iter(nbrs[0]))
    known = [(0, j, float(np.linalg.norm(P[j] - P[0])))]
    c, s = math.cos(-phi[0]), math.sin(-phi[0])
    R = np.array([[c, -s], [s, c]])
    truth = (P - P[0]) @ R.T  # in the root's body frame
    # the bearings alone (no length prior) give the shape exactly
    with pytest.MonkeyPatch.context() as m:
        m.setattr(shape, "EDGE_PRIOR", 0.0)
        X = estimate_shape(nbrs, head, known, root=0)
    assert set(X) == set(range(n))
    assert max(np.linalg.norm(X[i] - truth[i]) for i in X) < 1e-4
    # the length prior (shape.EDGE_PRIOR) bends a weakly rigid swarm a little toward equal
    # edges: over 2,000 such random swarms, median 0.003 rv, 99% 0.014, worst 0.033
    X = estimate_shape(nbrs, head, known, root=0)
    assert max(np.linalg.norm(X[i] - truth[i]) for i in X) < 0.05


@pytest.mark.parametrize("kinds,tol", [("holonomic", 0.04), (None, 0.08)])
def test_noisy_bearings_give_centimetre_shape_on_a_lattice(kinds, tol):
    """A 10 x 6 lattice at 0.9 rv (8 x 4 m), 0.5 deg bearing noise, the bottom row's lengths
    known; frames parallel (holonomic) or aligned from the noisy mutual bearings."""
    d = 0.9
    P = np.array([[i * d + (k % 2) * d / 2, k * d * math.sqrt(3) / 2]
                  for k in range(6) for i in range(10)])
    rng = np.random.default_rng(3)
    nbrs = _bearings(P, np.zeros(len(P)), noise=math.radians(0.5), rng=rng)
    known = [(i, i + 1, d) for i in range(0, 9)]
    head = align_headings(nbrs, None if kinds is None else {i: kinds for i in nbrs}, root=0)
    X = estimate_shape(nbrs, head, known, root=0)
    err = np.array([np.linalg.norm(X[i] - (P[i] - P[0])) for i in range(len(P))])
    assert err.max() < tol, err.max()


def test_without_known_lengths_the_mean_edge_is_the_default():
    P = _scatter(7, 20)
    nbrs = _bearings(P, np.zeros(len(P)))
    X = estimate_shape(nbrs, {i: 0.0 for i in nbrs}, (), default_edge=0.8)
    lengths = [np.linalg.norm(X[a] - X[b]) for a in nbrs for b in nbrs[a] if a < b]
    assert np.mean(lengths) == pytest.approx(0.8, rel=1e-3)


@pytest.mark.parametrize("noise_deg,tol", [(0.5, 0.06), (1.0, 0.2)])
def test_a_part_hinged_on_one_robot_keeps_its_scale(noise_deg, tol):
    """Two triangulated fans that share one robot (a hinge, as around a pillar or through a
    door) and see each other nowhere else: the bearings fix each fan's shape, but not the
    second fan's scale, and noisy bearing rows pull a part with a free scale to shrink.
    Only the first fan has a known length. Without the length prior (shape.EDGE_PRIOR)
    the second fan came out 1.4 rv off at 0.5 deg of noise (pillar_hall seed 2: an edge
    3.9 times its length); with it, every robot is within 0.04 rv of where it is at 0.5
    deg (the configs' noise) and 0.14 rv at 1 deg: the prior holds the fan against a pull
    that grows as the noise squared."""
    A = np.array([[-0.85, 0.4], [-0.85, -0.4], [-1.6, 0.0], [-1.5, 0.8]])
    P = np.vstack([[0.0, 0.0], A, -A])     # fan B: fan A turned half a turn about the hinge
    rng = np.random.default_rng(1)
    nbrs = _bearings(P, np.zeros(len(P)), noise=math.radians(noise_deg), rng=rng)
    hinge_only = {j for j in nbrs[0] if P[j][0] > 0}
    assert all(j in (0, *range(5)) for i in range(1, 5) for j in nbrs[i])   # fan A
    assert all(j in (0, 5, 6, 7, 8) for i in range(5, 9) for j in nbrs[i])  # fan B
    assert hinge_only == {5, 6}
    known = [(0, 1, float(np.linalg.norm(P[1]))), (1, 2, 0.8)]
    X = estimate_shape(nbrs, {i: 0.0 for i in nbrs}, known, root=0)
    err = max(float(np.linalg.norm(X[i] - P[i])) for i in range(len(P)))
    assert err < tol, err


def test_only_the_roots_component_is_estimated():
    nbrs = {0: {1: 0.0}, 1: {0: math.pi}, 5: {6: 0.0}, 6: {5: math.pi}}
    X = estimate_shape(nbrs, {v: 0.0 for v in nbrs}, [(0, 1, 0.9)], root=0)
    assert set(X) == {0, 1}
    assert X[1] == pytest.approx([0.9, 0.0], abs=1e-6)


def test_lattice_target_is_the_apex_on_a_lattice_and_skips_taken_points():
    lat = Lattice((0.0, 0.0), 0.0, 0.9)
    pf, po = np.array([0.0, 0.0]), np.array([0.9, 0.0])
    up = np.array([math.cos(math.pi / 3), math.sin(math.pi / 3)])
    t = lattice_target(lat, pf, po, up, [pf, po], reach=0.97, min_sep=0.45, min_dist=0.45)
    assert t == pytest.approx([0.45, 0.9 * math.sqrt(3) / 2])
    # the other side when the open side points down
    t = lattice_target(lat, pf, po, -up, [pf, po], reach=0.97, min_sep=0.45, min_dist=0.45)
    assert t[1] < 0
    # taken apex: no lattice point within reach of both ends is left
    assert lattice_target(lat, pf, po, up, [pf, po, t * [1, -1]], reach=0.97, min_sep=0.45,
                          min_dist=0.45) is None


def test_fitted_lattice_follows_the_robots_it_is_fitted_to():
    lat = Lattice((0.0, 0.0), 0.3, 0.95)
    shifted = Lattice((0.21, -0.13), 0.3, 0.95)
    pts = shifted.near((1.0, 1.0), rings=1)
    fit = lat.fitted(pts)
    got = fit.near((1.0, 1.0), rings=1)
    # every fitted lattice point near the robots coincides with one of the shifted lattice
    d = np.min(np.linalg.norm(got[:, None] - shifted.near((1.0, 1.0), rings=3)[None], axis=2), axis=1)
    assert d.max() < 1e-9


def test_lattice_target_avoids_the_cone_of_a_felt_wall():
    lat = Lattice((0.0, 0.0), 0.0, 0.9)
    pf, po = np.array([0.0, 0.0]), np.array([0.9, 0.0])
    up = np.array([math.cos(math.pi / 3), math.sin(math.pi / 3)])
    # a wall felt straight up blocks the apex (60 deg); nothing else is within reach of both
    assert lattice_target(lat, pf, po, up, [pf, po], reach=0.97, min_sep=0.45, min_dist=0.45,
                          blocked=[math.pi / 2]) is None
    # f alone (po only bounds the side): still nothing on the open side outside the cone
    t = lattice_target(lat, pf, None, up, [pf, po], reach=0.97, min_sep=0.45, min_dist=0.45,
                       blocked=[math.pi / 2], side_from=po)
    assert t is None or math.cos(math.atan2(t[1], t[0]) - math.pi / 2) <= 0


def _lattice_snapshot(spacing=0.95, jitter=0.0, seed=0):
    """A 4 x 3 lattice patch at ``spacing`` through the source vertex 0, axis along the
    source heading (pi), as the robots would report it."""
    from swarmcover.coordinator.planner import Snapshot
    rng = np.random.default_rng(seed)
    a1 = spacing * np.array([-1.0, 0.0])
    a2 = spacing * np.array([math.cos(math.pi + math.pi / 3), math.sin(math.pi + math.pi / 3)])
    P = {}
    v = 0
    for j in range(3):
        for i in range(4):
            P[v] = 10.0 + i * a1 + j * a2 + np.array([0.0, 3.0]) + rng.normal(0, jitter, 2)
            v += 1
    nbrs = {a: {b: math.atan2(*(P[b] - P[a])[::-1]) for b in P
                if b != a and np.linalg.norm(P[b] - P[a]) <= 1.0} for a in P}
    known = [(a, b, float(np.linalg.norm(P[b] - P[a]))) for a in P for b in P
             if b == a + 1 and b in nbrs[a]]
    snap = Snapshot(occupant={v: 100 + v for v in P}, nbrs=nbrs, kinds={v: "holonomic" for v in P},
                    sources=[0], source_dirs=[math.pi], known=known)
    return snap, P


def test_the_planner_sends_new_robots_to_free_lattice_points():
    from swarmcover.coordinator.topology.params import TopologyParams
    from swarmcover.coordinator.planner import plan_cycle
    spacing = 0.95
    snap, P = _lattice_snapshot(spacing)
    plan = plan_cycle(snap, TopologyParams(), cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=100,
                      lattice_spacing=spacing)
    assert plan.jobs
    a1 = spacing * np.array([-1.0, 0.0])
    a2 = spacing * np.array([math.cos(4 * math.pi / 3), math.sin(4 * math.pi / 3)])
    B = np.stack([a1, a2], 1)
    Pa = np.array(list(P.values()))
    landed = []
    for job in plan.jobs:
        f = job.path[-1]
        q = P[f] + job.distance * np.array([math.cos(job.direction), math.sin(job.direction)])
        c = np.linalg.solve(B, q - P[0])
        assert np.abs(c - np.round(c)).max() < 0.02, (job, c)       # on the lattice
        assert np.min(np.linalg.norm(Pa - q, axis=1)) > 0.5 * spacing   # a free point
        assert job.distance <= 0.97 + 1e-9
        if job.frontier_edge:
            o = [x for x in job.frontier_edge if x != f][0]
            assert np.linalg.norm(P[o] - q) <= 0.97 + 1e-9           # sees both ends
        landed.append(q)
        # the plan says how it chose the point (bench/robots.py books wall robots by it)
        assert job.placed == ("lattice" if job.frontier_edge else "lattice_f"), job
    L = np.array(landed)
    if len(L) > 1:  # two pushes of one cycle never aim at the same point
        assert min(np.linalg.norm(L[i] - L[j]) for i in range(len(L))
                   for j in range(i + 1, len(L))) > 0.3 * spacing


def test_without_a_lattice_the_planner_keeps_the_spec_rule():
    from swarmcover.coordinator.topology.params import TopologyParams
    from swarmcover.coordinator.planner import plan_cycle
    snap, P = _lattice_snapshot(0.95)
    plan = plan_cycle(snap, TopologyParams(), cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=100)
    assert plan.jobs and all(j.distance is None for j in plan.jobs)
    # robots that rotate keep the spec rule too (their frames drift between cycles)
    snap.kinds = {v: "unicycle" for v in snap.kinds}
    plan = plan_cycle(snap, TopologyParams(), cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=100,
                      lattice_spacing=0.95)
    assert plan.jobs and all(j.distance is None for j in plan.jobs)
    assert all(j.placed == "" for j in plan.jobs)


def test_with_no_free_lattice_point_a_job_keeps_the_spec_direction_and_says_so():
    from swarmcover.coordinator.topology.params import TopologyParams
    from swarmcover.coordinator.planner import _place_on_lattice, plan_cycle
    snap, P = _lattice_snapshot(0.95)
    plan = plan_cycle(snap, TopologyParams(), cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=100)
    job = plan.jobs[0]
    f, spec_dir = job.path[-1], job.direction
    # drives from f failed every way round: every lattice point lies in a failed cone
    walls = {f: [0.0, math.pi / 2, math.pi, -math.pi / 2]}
    _place_on_lattice(snap, [job], 0.95, TopologyParams(), walls)
    assert job.placed == "spec"
    assert job.direction == spec_dir and job.distance == 0.95


def _target(P, job):
    f = job.path[-1]
    return P[f] + job.distance * np.array([math.cos(job.direction), math.sin(job.direction)])


def test_a_push_whose_test_drive_touched_is_replanned_to_the_next_best_frontier():
    """Spec 3.4(iv): after a touch, the next-best frontier at once (same source), never the
    direction that failed, never through this cycle's other pushes or onto their targets."""
    from swarmcover.coordinator.topology.params import TopologyParams
    from swarmcover.coordinator.planner import JobSpec, plan_cycle, replan_push
    spacing = 0.95
    snap, P = _lattice_snapshot(spacing)
    params = TopologyParams()
    kw = dict(new_vertex=200, scale_correct=False, test_drive=True, lattice_spacing=spacing)
    plan = plan_cycle(snap, params, cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=8,
                      scale_correct=False, test_drive=True, next_vertex=100,
                      lattice_spacing=spacing)
    (first,) = plan.jobs
    failed = {first.path[-1]: [first.direction]}
    again = replan_push(snap, params, start=first.path[0], busy=[], exclude=set(),
                        test_drive_failures=failed, **kw)
    assert again is not None and again.path[0] == first.path[0] and again.new_vertex == 200
    assert np.linalg.norm(_target(P, again) - _target(P, first)) > 0.5 * spacing
    # another push of this cycle aims at that point from vertex 4 (path 5 -> 4): the retry
    # keeps off its path, the neighbours of its frontier vertex, and its target
    d = _target(P, again) - P[4]
    busy = [JobSpec(path=[5, 4], direction=math.atan2(d[1], d[0]), deploy_landmarks=[],
                    deploy_bearings=[], new_vertex=150, enter_source=None,
                    distance=float(np.hypot(*d)))]
    third = replan_push(snap, params, start=first.path[0], busy=busy, exclude=set(),
                        test_drive_failures=failed, **kw)
    assert third is not None
    off_limits = {5, 4} | {v for v in snap.nbrs[4]}
    assert not (set(third.path) - {first.path[0]}) & off_limits
    assert np.linalg.norm(_target(P, third) - _target(P, busy[0])) > 0.35 * spacing
    assert np.linalg.norm(_target(P, third) - _target(P, first)) > 0.5 * spacing
    # nothing left to push to from the start: no retry
    assert replan_push(snap, params, start=first.path[0], busy=busy,
                       exclude=set(P) - {first.path[0]},
                       test_drive_failures={first.path[0]: [k * math.pi / 3 for k in range(6)]},
                       **kw) is None

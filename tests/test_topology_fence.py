"""Fence detection: hand-built cases after the thesis figures, and lattices with holes."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from swarmcover.coordinator import TopologyParams, build_complex, certify, detect_fence, verify_certificate, wrap
from swarmcover.coordinator.topology.evidence import Evidence
from test_topology_geom import boundary_edges_near, lattice, reports

DEG = math.pi / 180


def _fence(P, **kw):
    fence_kw = {k: kw.pop(k) for k in list(kw) if k in ("test_drive_failures", "default_bearing", "forced_obstacle", "params")}
    cx = build_complex(reports(P, **kw))
    return cx, detect_fence(cx, **fence_kw)


def _probed(cx, params=None, **kw):
    """detect_fence after every probe it asks for has been driven and touched (a wall
    everywhere in front of every side the ends would close; a wall sweep joins all it was
    asked to): the fence a run reaches when the ends' evidence was right. ``kw``:
    test_drive_failures and other detect_fence keywords."""
    ev = Evidence()
    ev.merge_failures(kw.pop("test_drive_failures", None) or {})
    for _ in range(20):
        f = detect_fence(cx, params, **ev.fence_kwargs(), **kw)
        probes = [d for lst in f.deployments.values() for d in lst if d.kind == "probe"]
        if not probes:
            return f
        for d in probes:
            ev.record(d, touched=True, swept=(d.sweep_far, -math.inf) if d.sweep_far else None)
    raise AssertionError("probes never ran out")


def _pairs(cx, edge_ids):
    return {tuple(p) for p in cx.edge_nodes(edge_ids).tolist()}


def _z_is_cycle(cx, f):
    deg = np.bincount(cx.edges[f.z].ravel(), minlength=cx.n)
    return not np.any(deg & 1)


def test_single_triangle_deploys_at_60_degrees_to_the_same_spot():
    s = 0.9
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, s * math.sqrt(3) / 2]])
    cx, f = _fence(P)
    assert _pairs(cx, f.frontier) == {(0, 1), (0, 2), (1, 2)}
    assert f.obstacle.size == 0 and f.exceptions.size == 0
    assert _pairs(cx, f.z) == {(0, 1), (0, 2), (1, 2)}
    e01 = f.by_index[int(cx.edge_index(0, 1))]
    (side,) = e01.sides
    assert side.sigma == -1 and side.kind == "frontier"  # open side is clockwise of 1 seen from 0
    assert side.deploy_u == pytest.approx(-60 * DEG)
    assert side.deploy_v == pytest.approx(-120 * DEG)
    # both endpoints send the new robot to the apex of the mirrored triangle
    apex = np.array([s / 2, -s * math.sqrt(3) / 2])
    for p, b in ((P[0], side.deploy_u), (P[1], side.deploy_v)):
        q = p + s * np.array([math.cos(b), math.sin(b)])
        assert np.linalg.norm(q - apex) < 1e-9
    assert all(d[0].clearance == pytest.approx(60 * DEG) for d in f.deployments.values())


def test_all_cofaces_on_one_side_is_a_fence_edge():
    P = np.array([[0.0, 0.0], [0.9, 0.0], [0.2, 0.5], [0.45, 0.7], [0.7, 0.45]])
    cx, f = _fence(P)
    e = int(cx.edge_index(0, 1))
    assert cx.edge_triangles[0][e + 1] - cx.edge_triangles[0][e] == 3
    assert e in f.z.tolist() and e in f.frontier.tolist()
    assert f.by_index[e].sides[0].sigma == -1
    cert = certify(cx, f)
    assert cert.certified and verify_certificate(cx, cert)


def test_crossing_edge_goes_to_the_exception_set():
    # thesis Fig. 3.5(a): {0,1} has its only triangle above, but the fan of 2 through
    # 3 -> 5 -> 4 covers the region below it.
    P = np.array([[0.0, 0.0], [0.95, 0.0], [0.47, 0.05], [-0.2, -0.3], [1.15, -0.3], [0.47, -0.9]])
    cx, f = _fence(P)
    e = int(cx.edge_index(0, 1))
    assert _pairs(cx, [e]) == {(0, 1)}
    assert f.exceptions.tolist() == [e]
    assert e not in f.z.tolist() and e not in f.frontier.tolist()
    assert _pairs(cx, f.z) == {(0, 2), (1, 2), (0, 3), (3, 5), (4, 5), (1, 4)}
    assert _z_is_cycle(cx, f) and f.z_repair.size == 0
    cert = certify(cx, f)
    assert cert.certified and verify_certificate(cx, cert)
    tri = {tuple(t) for t in cert.chain_nodes.tolist()}
    assert (0, 1, 2) not in tri and tri == {(0, 2, 3), (2, 3, 5), (2, 4, 5), (1, 2, 4)}


def test_fan_inside_the_triangle_is_not_an_exception():
    # the tightened rule: a chain through a vertex inside triangle {0,1,2} does not
    # cover the far side of {0,1}
    P = np.array([[0.0, 0.0], [0.9, 0.0], [0.45, 0.7], [0.45, 0.25]])
    cx, f = _fence(P)
    e = int(cx.edge_index(0, 1))
    assert f.exceptions.size == 0 and e in f.z.tolist()


def _pair_with_wall(wall_y, touch_gap):
    P = np.array([[0.0, 0.0], [0.8, 0.0], [0.4, 0.6]])
    disc = (0.4, wall_y - 10.0, 10.0)  # a huge disc: its rim is a wall at y = wall_y
    return _fence(P, discs=[disc], touch_gap=touch_gap)


def test_both_touch_makes_an_obstacle_edge():
    cx, f = _pair_with_wall(-0.05, 0.1)
    e = int(cx.edge_index(0, 1))
    # both contacts point into the open side: the side is a candidate, not closed yet
    assert e in f.frontier.tolist() and f.by_index[e].sides[0].reason == "probing"
    f = _probed(cx)
    assert e in f.obstacle.tolist() and e not in f.frontier.tolist()
    assert f.by_index[e].sides[0].reason == "probes" and not f.inferred
    assert e in f.z.tolist()  # obstacle edges are fence edges for the certificate
    assert 0 in f.obstacle_vertices and 0 not in {d.vertex for d in f.deployments.get(0, ()) if d.edge == (0, 1)}


def test_one_touch_or_touch_on_the_covered_side_stays_frontier():
    P = np.array([[0.0, 0.0], [0.8, 0.0], [0.4, 0.6]])
    rep = reports(P)
    rep[0].update(touch=True, touch_bearing=-90 * DEG)
    f = detect_fence(build_complex(rep))
    assert f.obstacle.size == 0  # only one robot touches
    rep[1].update(touch=True, touch_bearing=100 * DEG)  # points into the covered side
    cx = build_complex(rep)
    f = detect_fence(cx)
    assert f.obstacle.size == 0
    rep[1].update(touch=True, touch_bearing=-90 * DEG)
    f = _probed(build_complex(rep))
    assert _pairs(cx, f.obstacle) == {(0, 1)}


def test_both_touch_needs_contacts_clearly_on_the_open_side_not_along_the_edge():
    # robots 0 and 1 across the mouth of a passage, each touching one side of it: the
    # contacts point along the edge, away from each other, a little below it. The spec's
    # sign test closed the passage; the contacts must be >= 30 deg off the edge's line.
    P = np.array([[0.0, 0.0], [0.8, 0.0], [0.4, 0.6]])
    rep = reports(P)
    rep[0].update(touch=True, touch_bearing=-170 * DEG)
    rep[1].update(touch=True, touch_bearing=-10 * DEG)
    cx = build_complex(rep)
    f = detect_fence(cx)
    assert f.obstacle.size == 0 and int(cx.edge_index(0, 1)) in f.frontier.tolist()
    # a corner: one robot on the bottom wall, the other on a wall meeting it at 45 deg
    rep[0].update(touch_bearing=-90 * DEG)
    rep[1].update(touch_bearing=-45 * DEG)
    cx = build_complex(rep)
    assert _pairs(cx, _probed(cx).obstacle) == {(0, 1)}
    # 35 deg off the line still counts (a wall slanting away under the pair)
    rep[0].update(touch_bearing=-145 * DEG)
    rep[1].update(touch_bearing=-35 * DEG)
    cx = build_complex(rep)
    assert _pairs(cx, _probed(cx).obstacle) == {(0, 1)}


def test_touch_towards_a_visible_robot_is_not_an_obstacle_contact():
    # 3 below 0 and 4 below 1 are seen by one robot each (no triangle below {0,1});
    # contacts pointing at them are robot contacts, not wall contacts
    P = np.array([[0.0, 0.0], [0.8, 0.0], [0.4, 0.6], [-0.15, -0.9], [0.95, -0.9]])
    rep = reports(P)
    for i, j in ((0, 3), (1, 4)):
        d = P[j] - P[i]
        rep[i].update(touch=True, touch_bearing=math.atan2(d[1], d[0]))
    cx = build_complex(rep)
    assert cx.n_edges == 5
    f = detect_fence(cx)
    assert int(cx.edge_index(0, 1)) in f.frontier.tolist() and f.obstacle.size == 0
    for i, j in ((0, 3), (1, 4)):  # the same contacts with nobody in sight: a wall
        rep[i]["neighbours"].pop(j)
    f = _probed(build_complex(rep))
    assert _pairs(cx, f.obstacle) == {(0, 1)}


def _corner(angle_deg, tips=True, **params):
    """Robot 0 at an obstacle corner that hides 1 from 2 (the wedge 1-0-2 is angle_deg).
    tips: robots 5 and 6 straight beyond 1 and 2, so that neither far end has a reflex
    open wedge on the corner's side; without them 1 and 2 are tips of the swarm."""
    a = angle_deg * DEG
    i, j = np.array([0.0, 0.0]), np.array([0.8, 0.0])
    k = 0.8 * np.array([math.cos(a), math.sin(a)])
    b = a + 50 * DEG
    pts = [i, j, k, [0.4, -0.5], 0.64 * np.array([math.cos(b), math.sin(b)])]
    if tips:
        pts += [2.0 * j, 2.0 * k]
    mid = (j + k) / 2
    # an obstacle corner hides j from k
    return _fence(np.array(pts), discs=[(mid[0], mid[1], 0.05)], params=TopologyParams(**params))


def test_convex_corner_at_a_tip_waits_for_the_tips_own_drives():
    """bench/truth.py map 70: a robot in a doorway (1 here) whose neighbour 0 sees a jamb
    corner between it and 2. The occlusion argument covers the wedge 1-0-2 only; 1's own
    open wedge is reflex and leads into the next room. The side stays frontier, deployed
    from 1 (not from 0, into the thin wedge), and closes as 'convex_corner' only once 1's
    drives there (its 60 deg one and its reflex second probe) touched
    (TopologyParams.corner_wait, the default since 2026-12-04; off, the side closes at
    once)."""
    P = TopologyParams(corner_wait=True)
    cx, f = _corner(50, tips=False, corner_wait=True)
    es = {int(cx.edge_index(0, 1)): 1, int(cx.edge_index(0, 2)): 2}
    for e, far in es.items():
        assert e in f.frontier.tolist() and f.by_index[e].sides[0].reason == "open"
        pair = tuple(sorted((0, far)))
        assert not any(d.edge == pair for d in f.deployments.get(0, ()))
        assert any(d.edge == pair and d.kind == "edge" for d in f.deployments.get(far, ()))
    fails: dict[int, list[float]] = {1: [], 2: []}
    for _ in range(4):  # fail every drive the far ends offer on these edges, deep ones too
        f2 = detect_fence(cx, P, test_drive_failures=fails)
        new = [(far, d.bearing) for far in fails for d in f2.deployments.get(far, ())
               if d.edge == (0, far)]
        for far, b in new:
            fails[far].append(b)
        if not new:
            break
    assert len(fails[1]) == 2 and len(fails[2]) == 2  # the 60 deg drive and the deep probe
    f2 = _probed(cx, P, test_drive_failures=fails)
    for e in es:
        assert f2.by_index[e].sides[0].reason == "convex_corner" and e in f2.obstacle.tolist()
    assert TopologyParams().corner_wait                  # the default waits ...
    f3 = _corner(50, tips=False, corner_wait=False)[1]   # ... off, they close at once
    assert all(f3.by_index[e].sides[0].reason == "convex_corner" for e in es)


def test_convex_corner_needs_the_far_ends_not_to_see_each_other():
    """A neighbour of 0 within the threshold that the far end does see (a near-collinear
    triangle whose side test fell on one side by noise; bench/truth.py map 11 certified
    21.8 % of a room so) is no convex corner: nothing blocks the view."""
    P = np.array([[0.0, 0.0], [0.9, 0.0], [0.45, 0.003]])
    rep = reports(P)
    rep[1]["neighbours"][2] = wrap(rep[1]["neighbours"][2] + 0.9 * DEG)  # 2 seen across 0-1
    cx = build_complex(rep)
    f = detect_fence(cx)
    assert int(cx.edge_index(0, 1)) in f.frontier.tolist()
    assert not any(sd.reason == "convex_corner" for fe in f.edges for sd in fe.sides)


def test_convex_corner_below_threshold_marks_both_edges_obstacle():
    cx, f = _corner(50)
    assert int(cx.edge_index(1, 2)) < 0  # occluded
    assert {(0, 1), (0, 2)} <= _pairs(cx, f.obstacle)
    for e in (int(cx.edge_index(0, 1)), int(cx.edge_index(0, 2))):
        assert f.by_index[e].sides[0].reason == "convex_corner"
        assert e not in f.frontier.tolist()
    assert all(d.edge not in ((0, 1), (0, 2)) for d in f.deployments.get(0, ()))


def test_convex_corner_sides_can_be_probed_before_they_close():
    """The convex-corner rule (spec 3.3 ii) only makes its sides candidates (issue 21,
    bench/truth.py map 11: a free-standing box broke it): they are probed, and close on
    evidence once every probe touched."""
    cx, f = _corner(50, corner_probes=True)
    assert int(cx.edge_index(1, 2)) < 0  # occluded
    es = (int(cx.edge_index(0, 1)), int(cx.edge_index(0, 2)))
    for e in es:
        assert f.by_index[e].sides[0].reason == "probing" and e in f.frontier.tolist()
    assert not f.inferred
    # no plain edge deployment off them, only probes
    assert all(d.kind == "probe" for lst in f.deployments.values() for d in lst
               if d.edge in ((0, 1), (0, 2)))
    assert any(d.edge in ((0, 1), (0, 2)) for lst in f.deployments.values() for d in lst)
    f = _probed(cx, TopologyParams(corner_probes=True))
    assert {(0, 1), (0, 2)} <= _pairs(cx, f.obstacle)
    for e in es:
        assert f.by_index[e].sides[0].reason == "probes"
        assert e not in f.frontier.tolist()
    assert all(d.edge not in ((0, 1), (0, 2)) for d in f.deployments.get(0, ()))


def test_corner_above_threshold_deploys_on_the_bisector():
    cx, f = _corner(70)
    e = int(cx.edge_index(0, 1))
    assert e in f.frontier.tolist()
    (side,) = f.by_index[e].sides
    assert side.offset_u == pytest.approx(35 * DEG)
    assert side.deploy_u == pytest.approx(wrap(cx.bearing(0, 1) + 35 * DEG))
    # the threshold is pi/3 - 2 beta: with beta = 6 deg, 50 deg is no corner
    P = TopologyParams(beta=6 * DEG)
    cx2, _ = _corner(50)
    f2 = detect_fence(cx2, P)
    assert int(cx2.edge_index(0, 1)) in f2.frontier.tolist()


def test_test_drive_failure_reclassifies_the_touched_side_only():
    s = 0.9
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, s * math.sqrt(3) / 2]])
    cx, f = _fence(P)

    def probes(f_any, p, edge):
        return [d for d in f_any.deployments.get(p, ()) if d.edge == edge]

    dep = probes(f, 0, (0, 1))[0]
    f1 = detect_fence(cx, test_drive_failures={0: dep.bearing})
    # the drive below edge 0-1 failed: 0's deployments within 30 deg of it are dropped; edge
    # 0-2 deploys at 120 deg (180 deg from the drive) and stays. One end's touch does not
    # close the side: robot 1 still deploys into it (a door jamb is not a wall)
    assert all(abs(wrap(d.bearing - dep.bearing)) >= math.pi / 6 for d in f1.deployments[0])
    assert (0, 2) in [d.edge for d in f1.deployments[0]]
    assert _pairs(cx, f1.frontier) == {(0, 1), (0, 2), (1, 2)}
    assert (0, 1) in [d.edge for d in f1.deployments[1]]
    # a lone triangle's corners are reflex (300 deg open): after the 60-deg drive, 0 probes
    # the side again 120 deg off the edge, before the side can close
    (deep0,) = probes(f1, 0, (0, 1))
    assert abs(wrap(deep0.bearing - cx.bearing(0, 1))) == pytest.approx(2 * math.pi / 3)
    # robot 1's test drive into that side touched too: 60-deg drives alone no longer close
    # a reflex side; once both deep probes touched as well, the side is O
    dep1 = probes(f, 1, (0, 1))[0]
    f2 = detect_fence(cx, test_drive_failures={0: dep.bearing, 1: [dep1.bearing]})
    assert not _pairs(cx, f2.obstacle)
    (deep1,) = probes(f2, 1, (0, 1))
    ends = {0: [dep.bearing, deep0.bearing], 1: [dep1.bearing, deep1.bearing]}
    f2 = detect_fence(cx, test_drive_failures=ends)
    # both ends have no room: the side waits for its probes, the only deployments on it
    e01 = int(cx.edge_index(0, 1))
    assert f2.by_index[e01].sides[0].reason == "probing" and not f2.obstacle.size
    assert {d.kind for v in (0, 1) for d in probes(f2, v, (0, 1))} == {"probe"}
    f2 = _probed(cx, test_drive_failures=ends)
    assert _pairs(cx, f2.obstacle) == {(0, 1)}
    assert _pairs(cx, f2.frontier) == {(0, 2), (1, 2)}
    assert {f2.by_index[e].sides[0].reason for e in f2.obstacle} == {"probes"}
    # or robot 1 rests against a wall on that side (its contact counts as no room for both
    # of its probes)
    cx_t = build_complex({
        0: {"neighbours": {1: cx.bearing(0, 1), 2: cx.bearing(0, 2)}},
        1: {"neighbours": {0: cx.bearing(1, 0), 2: cx.bearing(1, 2)}, "touch": True,
            "touch_bearing": -math.pi / 2},
        2: {"neighbours": {0: cx.bearing(2, 0), 1: cx.bearing(2, 1)}}})
    f5 = _probed(cx_t, test_drive_failures={0: [dep.bearing, deep0.bearing]})
    assert _pairs(cx_t, f5.obstacle) == {(0, 1)}
    # failures toward all of 0's probes, and 2's toward 0-2: that side closes too
    fails = {0: [dep.bearing, deep0.bearing], 1: [dep1.bearing, deep1.bearing]}
    dep02, dep20 = probes(f, 0, (0, 2))[0], probes(f, 2, (0, 2))[0]
    fails[0].append(dep02.bearing)
    fails[2] = [dep20.bearing]
    f4 = detect_fence(cx, test_drive_failures=fails)
    fails[0] += [d.bearing for d in probes(f4, 0, (0, 2))]
    fails[2] += [d.bearing for d in probes(f4, 2, (0, 2))]
    f4 = _probed(cx, test_drive_failures=fails)
    assert _pairs(cx, f4.obstacle) == {(0, 1), (0, 2)}
    assert 0 not in f4.deployments
    # a forced obstacle edge (remembered from an earlier cycle) is an obstacle edge
    f3 = detect_fence(cx, forced_obstacle=[(1, 2)])
    assert _pairs(cx, f3.obstacle) == {(1, 2)}


def test_drives_that_touched_the_door_jambs_do_not_close_the_door():
    # two robots below a 0.9 m door, each beside one jamb (y = 0.2); each failed a drive up
    # and out towards its jamb (for its other fence edge). The door side of their edge
    # deploys 60 deg off the edge, 60 deg from those drives: it stays open (a 90 deg cone
    # around each drive closed it)
    s = 0.8
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, -s * math.sqrt(3) / 2]])
    cx, f = _fence(P)
    up = [(v, d) for v in (0, 1) for d in f.deployments[v] if d.edge == (0, 1)]
    assert len(up) == 2 and all(d.bearing > 0 for _, d in up)  # both deploy up, into the door
    jambs = {0: math.radians(120.0), 1: math.radians(60.0)}    # drives towards each jamb
    f1 = detect_fence(cx, test_drive_failures=jambs)
    assert (0, 1) in _pairs(cx, f1.frontier) and not f1.obstacle.size
    assert all((0, 1) in [d.edge for d in f1.deployments[v]] for v in (0, 1))
    # drives up the door side from both ends, and their second probes (the corners of a
    # lone triangle are reflex), close it (a wall after all)
    fails = {v: [d.bearing] for v, d in up}
    f2 = detect_fence(cx, test_drive_failures=fails)
    assert not f2.obstacle.size
    for v in (0, 1):
        fails[v] += [d.bearing for d in f2.deployments[v] if d.edge == (0, 1)]
    f2 = detect_fence(cx, test_drive_failures=fails)
    assert not f2.obstacle.size           # the ends say wall; probes through the door first
    f2 = _probed(cx, test_drive_failures=fails)
    assert _pairs(cx, f2.obstacle) == {(0, 1)}


def test_dangling_edge_deploys_at_60_degrees_and_single_file_as_fallback():
    cx = build_complex({0: {"neighbours": {1: 0.0}}, 1: {"neighbours": {0: math.pi}}})
    f = detect_fence(cx)
    kinds = sorted(d.kind for d in f.deployments[0])
    assert kinds == ["edge", "edge"]          # single file only once these are gone
    offs = sorted(round(abs(wrap(d.bearing)) / DEG) for d in f.deployments[0] if d.kind == "edge")
    assert offs == [60, 60]
    # corridor: both 60 deg test drives touched walls -> the edge is O; the chain end still
    # extends in single file, away from its neighbour
    f1 = detect_fence(cx, test_drive_failures={0: [60 * DEG, -60 * DEG]})
    assert int(cx.edge_index(0, 1)) in f1.frontier.tolist()   # 1 has not tried yet
    f2 = _probed(cx, test_drive_failures={0: [60 * DEG, -60 * DEG],
                                          1: [math.pi - 60 * DEG, -math.pi + 60 * DEG]})
    assert int(cx.edge_index(0, 1)) in f2.obstacle.tolist()
    # single file: every direction of the open wedge, straight away first; the probes'
    # perpendicular drives (+-90 deg) touched, so those within 30 deg of them are gone
    assert {d.kind for d in f2.deployments[0]} == {"single_file"}
    assert abs(wrap(f2.deployments[0][0].bearing - math.pi)) < 1e-9
    assert sorted(round(abs(d.bearing) / DEG) for d in f2.deployments[0]) == [120, 120, 180]



def test_single_file_and_isolated_robots():
    P = np.array([[0.0, 0.0], [0.8, 0.0], [1.6, 0.0], [10.0, 10.0]])
    cx, f = _fence(P, default_bearing=1.0)
    assert f.z.size == 0  # dangling edges are two-sided
    assert _pairs(cx, f.frontier) == {(0, 1), (1, 2)}
    # the chain's ends deploy at 60 deg off their dangling edge first; once both of those
    # test drives touched walls, the end continues in single file, away from its neighbour
    assert {d.kind for d in f.deployments[0]} == {d.kind for d in f.deployments[2]} == {"edge"}
    walls = {0: [math.pi / 3, -math.pi / 3], 2: [math.pi - math.pi / 3, -math.pi + math.pi / 3]}
    g = detect_fence(cx, test_drive_failures=walls, default_bearing=1.0)
    d0, d2, d3 = g.deployments[0][0], g.deployments[2][0], g.deployments[3][0]
    assert d0.kind == "single_file" and abs(wrap(d0.bearing - math.pi)) < 1e-9
    assert d2.kind == "single_file" and abs(d2.bearing) < 1e-9
    assert d0.clearance == pytest.approx(math.pi)
    # the middle robot (neighbours on opposite sides) has no single-file direction, only
    # the 60 deg deployments off its dangling edges
    assert {d.kind for d in f.deployments[1]} == {"edge"}
    assert f.deployments[1][0].clearance == pytest.approx(math.pi / 3)
    assert d3.kind == "isolated" and d3.bearing == 1.0
    assert 3 in f.frontier_vertices


def _holey_lattice(rng, holes, jitter=0.02, s=0.8):
    P = lattice(14, 14, s, jitter, rng)
    keep = np.ones(len(P), bool)
    for cxy, r in holes:
        keep &= np.linalg.norm(P - np.asarray(cxy), axis=1) > r + 0.05
    P = P[keep]
    discs = [(c[0], c[1], r) for c, r in holes]
    return P, discs


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lattice_with_holes_fences_every_hole(seed):
    rng = np.random.default_rng(seed)
    holes = [((3.0, 3.0), 0.9), ((7.5, 6.0), 1.1)]
    P, discs = _holey_lattice(rng, holes)
    cx = build_complex(reports(P, discs=discs, touch_gap=0.9))
    f = _probed(cx)
    assert f.exceptions.size == 0 and f.z_repair.size == 0 and _z_is_cycle(cx, f)
    # truth from the geometry: z = the outer boundary plus the rim of every hole
    rims = set()
    outer = set(range(cx.n_edges))
    for c, r in holes:
        near, far = boundary_edges_near(cx, P, c, r + 1.2)
        rims |= set(near.tolist())
        outer &= set(far.tolist())
    assert set(f.z.tolist()) == rims | outer
    assert set(f.frontier.tolist()) >= outer  # nothing touches the outside
    assert set(f.obstacle.tolist()) <= rims and len(f.obstacle) > 0
    cert = certify(cx, f)
    assert cert.certified and verify_certificate(cx, cert)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 80), side=st.floats(1.0, 5.0))
def test_random_swarm_fence_invariants(seed, n, side):
    rng = np.random.default_rng(seed)
    P = rng.uniform(0, side, (n, 2))
    cx = build_complex(reports(P))
    f = detect_fence(cx)
    assert _z_is_cycle(cx, f)  # after the repair z is always a cycle
    assert set(f.z_raw.tolist()) <= set(f.frontier.tolist()) | set(f.obstacle.tolist())
    assert not set(f.exceptions.tolist()) & (set(f.frontier.tolist()) | set(f.obstacle.tolist()))
    for fe in f.edges:
        for sd in fe.sides:
            if sd.kind != "frontier":
                continue
            # the new robot goes to the open side, at most 60 deg off the edge, from both ends
            a_u = wrap(sd.deploy_u - cx.bearing(fe.u, fe.v))
            a_v = wrap(sd.deploy_v - cx.bearing(fe.v, fe.u))
            assert np.sign(a_u) == sd.sigma and np.sign(a_v) == -sd.sigma
            assert 0 < abs(a_u) <= 60 * DEG + 1e-12 and 0 < abs(a_v) <= 60 * DEG + 1e-12
            # geometrically: no triangle on that edge has its apex on the open side
            loc = cx.index([fe.u, fe.v])
            u_xy, v_xy = P[loc[0]], P[loc[1]]
            for k in cx.neighbours(fe.u).tolist():
                if k in cx.neighbours(fe.v).tolist():
                    w = P[cx.index_of(k)] - u_xy
                    d = v_xy - u_xy
                    assert np.sign(d[0] * w[1] - d[1] * w[0]) == -sd.sigma
    cert = certify(cx, f)
    assert verify_certificate(cx, cert)


def test_isolated_robots_use_their_own_default_direction():
    P = np.array([[0.0, 0.0], [5.0, 0.0]])
    cx = build_complex(reports(P))
    f = detect_fence(cx, default_bearing={1: 2.0})
    assert f.deployments[0][0].bearing == 0.0 and f.deployments[1][0].bearing == 2.0


def test_a_reflex_end_probes_a_second_direction_before_its_side_closes():
    """A 0.5 m passage opened beside the robot at the corner of the front (structured, seed
    1): both 60-deg drives into the side hit the box next to the mouth and closed it, while
    straight ahead of the corner lay the passage. An end whose open wedge is reflex (> 210
    deg) probes again 120 deg off the edge; along a straight front (180 deg) it does not."""
    s = 0.9
    h = s * math.sqrt(3) / 2
    # two rows: 0 1 2 3 at y = 0, 4 5 6 at y = h (a lattice patch; 0 is an acute corner)
    P = np.array([[i * s, 0.0] for i in range(4)] + [[s / 2 + i * s, h] for i in range(3)])
    cx, f = _fence(P)

    def below(f_any, p, edge):
        return [d for d in f_any.deployments.get(p, ()) if d.edge == edge
                and math.sin(d.bearing) < 0]

    # an edge of the straight bottom row (1-2): the 60-deg drives from both ends close it
    fails = {1: [below(f, 1, (1, 2))[0].bearing], 2: [below(f, 2, (1, 2))[0].bearing]}
    g = detect_fence(cx, test_drive_failures=fails)
    assert {d.kind for v in (1, 2) for d in below(g, v, (1, 2))} == {"probe"}
    g = _probed(cx, test_drive_failures=fails)
    assert (1, 2) in _pairs(cx, g.obstacle)
    assert not below(g, 1, (1, 2)) and not below(g, 2, (1, 2))
    # the corner's edge (0-1): 0's wedge below is 300 deg; after both 60-deg drives touched
    # the side stays open and 0 probes 120 deg off the edge (down and to the left)
    fails = {0: [below(f, 0, (0, 1))[0].bearing], 1: [below(f, 1, (0, 1))[0].bearing]}
    g = detect_fence(cx, test_drive_failures=fails)
    assert (0, 1) in _pairs(cx, g.frontier)
    (deep,) = below(g, 0, (0, 1))
    assert wrap(deep.bearing) == pytest.approx(-2 * math.pi / 3)
    assert not below(g, 1, (0, 1))          # 1's wedge is straight: no second probe
    fails[0].append(deep.bearing)
    g = _probed(cx, test_drive_failures=fails)
    assert (0, 1) in _pairs(cx, g.obstacle)

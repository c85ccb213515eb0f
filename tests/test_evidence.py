"""Evidence before a fence side closes (issue 21 items 1-2, spec 3.4 amendment 2026-11).

Pure-core cases: probes along a side the ends would close, lone robots and single-file ends
that try every free direction, no certificate from an empty fence. The end-to-end cases
(lone robot facing a wall, rooms behind 0.7 / 0.8 m doors) are in
tests/test_coordinator_evidence.py.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from swarmcover.coordinator import build_complex, detect_fence, wrap
from hypothesis import assume, given, settings, strategies as st

from swarmcover.coordinator.topology.evidence import (Evidence, probe_depth_rv, probe_fractions, probe_key,
                                           tilted_door_rv)
from swarmcover.coordinator.topology.params import TopologyParams
from swarmcover.coordinator.planner import Snapshot, plan_cycle
from swarmcover.coordinator.topology.targets import probe_via_bearings

DEG = math.pi / 180
# the probe rule (perpendicular and tilted probe lines): dangling edges' sides, and every
# candidate side with [coordinator] sweep = false; tests/test_sweep.py has the wall sweeps
PROBES = TopologyParams(sweep=False)


def _reports(P, touch=None):
    """Reports from positions: everyone within 1.0 sees everyone; touch: id -> bearing."""
    rep = {}
    for i, p in enumerate(P):
        nb = {j: math.atan2(q[1] - p[1], q[0] - p[0]) for j, q in enumerate(P)
              if j != i and math.dist(p, q) <= 1.0}
        rep[i] = {"neighbours": nb}
        if touch and i in touch:
            rep[i].update(touch=True, touch_bearing=touch[i])
    return rep


def _probes(f):
    return [d for lst in f.deployments.values() for d in lst if d.kind == "probe"]


def test_probe_fractions_follow_from_the_door_width_and_the_robot_size():
    assert probe_fractions(0.4, 0.06) == (0.0, 0.25, 0.5, 0.75, 1.0)
    assert probe_fractions(0.6, 0.06) == (0.0, 0.333, 0.667, 1.0)    # s = 0.48: n = 3
    assert probe_fractions(0.3, 0.06) == tuple(round(k / 6, 3) for k in range(7))
    with pytest.raises(ValueError, match="door_min_rv"):
        probe_fractions(0.1, 0.06)
    # an interior probe's end point stays within d0 of both ends of an edge rv long
    for f in (0.25, 0.5, 0.75):
        dep = probe_depth_rv(f, 0.9, 0.9)
        assert math.hypot(max(f, 1 - f), dep) == pytest.approx(0.9)
    assert probe_depth_rv(0.0, 0.9, 0.9) == 0.9


def test_probe_fractions_pass_every_opening_at_least_door_min_wide():
    """Any opening of width >= door_min_rv whose span lies on the edge (length <= rv)
    contains a probe line with the robot's body clear of both jambs."""
    r = 0.06
    for dmin in (0.3, 0.4, 0.55):
        fr = probe_fractions(dmin, r)
        for L in (0.5, 0.8, 1.0):
            for a in np.linspace(0.0, L - dmin, 23):
                lines = [f * L for f in fr]
                assert any(a + r <= x <= a + dmin - r for x in lines), (dmin, L, a)


@settings(max_examples=300, deadline=None)
@given(f=st.floats(0.02, 0.98), tilt=st.floats(-1.2, 1.2), d0=st.floats(0.5, 1.0))
def test_a_tilted_probe_ends_within_d0_of_both_ends(f, tilt, d0):
    """Edge from (0, 0) to (1, 0) (x rv), probe from (f, 0) leaning sin(tilt) toward x = 1:
    its end point stays within d0 of both ends unless held at the floor of d0 / 4 (a start
    point already within d0 of both)."""
    assume(max(f, 1.0 - f) < d0)
    t = probe_depth_rv(f, d0, 0.45, lean=math.sin(tilt))
    end = (f + t * math.sin(tilt), t * math.cos(tilt))
    if t > 0.25 * d0 + 1e-12:
        assert math.hypot(*end) <= d0 + 1e-9 and math.hypot(end[0] - 1.0, end[1]) <= d0 + 1e-9
    assert probe_depth_rv(f, d0, 0.45, lean=0.0) == probe_depth_rv(f, d0, 0.45)


def test_the_tilted_guarantee_follows_from_the_gaps_and_tau():
    # gaps 0.25, robot 0.12 wide, lines within tau + tilt_min of the wall's normal
    tilt_min = TopologyParams().tilt_min
    assert tilted_door_rv(probe_fractions(0.4, 0.06), 0.06, math.pi / 8, tilt_min) == \
        pytest.approx(0.37 / math.cos(math.pi / 8 + tilt_min))
    # the default: not re-driven within the line's own sector (tau), 0.52 rv at any angle
    assert tilt_min == pytest.approx(math.pi / 8)
    assert 0.52 < tilted_door_rv(probe_fractions(0.4, 0.06), 0.06, math.pi / 8, tilt_min) < 0.53
    assert 0.40 < tilted_door_rv(probe_fractions(0.4, 0.06), 0.06, math.pi / 8, 3 * DEG) < 0.42


def _tilted(f):
    return [d for d in _probes(f) if d.tilt != 0.0]


def test_a_probe_that_touched_an_oblique_wall_is_driven_again_along_its_normal():
    """bench/truth.py seed 1, maps 267 and 496: perpendicular probe lines passed 0.43-0.44
    rv doors in walls at 45 deg to the edge with less than the robot's width to spare, and
    the rooms behind were certified. A probe whose touch sector lies off the direction
    driven is driven again from the same point along that sector's centre."""
    P, rep, _ = _door_pair(0.8)
    cx = build_complex(rep)
    e = int(cx.edge_index(0, 1))
    ev = Evidence()
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    first = {d.via_frac: d for d in _probes(f) if d.vertex == 0}
    assert set(first) == {0.25, 0.5, 0.75} and not _tilted(f)
    for frac, d in first.items():
        # the middle one felt a wall 45 deg off its line; the others nearly head-on
        ev.record(d, touched=True, contact_offset=(45 if frac == 0.5 else 2) * DEG)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    todo = _probes(f)
    assert todo and all(d.tilt == pytest.approx(45 * DEG) for d in todo)
    assert {d.vertex for d in todo} == {0, 1} and {probe_key(d.vertex, d.edge, d.sigma, d.via_frac)[3] for d in todo} == {0.5}
    perp = {d.vertex: wrap(cx.bearing(d.vertex, 1 - d.vertex) + (1 if d.vertex == 0 else -1) * d.sigma * math.pi / 2)
            for d in todo}
    for d in todo:
        assert wrap(d.bearing - perp[d.vertex]) == pytest.approx(45 * DEG)
    assert e in f.frontier.tolist()
    # the tilted drive found room: the side never closes on evidence
    ev2 = copy.deepcopy(ev)
    ev2.record(todo[0], touched=False)
    assert _open_or_inferred_clear(detect_fence(cx, PROBES, **ev2.fence_kwargs()), e)
    # it touched too: closed on evidence
    ev.record(todo[0], touched=True, contact_offset=0.0)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probes" and not f.inferred


def test_ends_resting_on_an_oblique_wall_tilt_every_probe_along_its_normal():
    """Ends whose wall contacts point 45 deg off the perpendicular (an edge cutting a
    corner): every interior probe that touched is driven again along that wall's normal."""
    P, _, _ = _door_pair(0.8)
    rep = _reports(P, touch={0: 135 * DEG, 1: 135 * DEG})
    cx = build_complex(rep)
    e = int(cx.edge_index(0, 1))
    ev = Evidence()
    for _ in range(3):
        f = detect_fence(cx, PROBES, **ev.fence_kwargs())
        for d in [d for d in _probes(f) if d.tilt == 0.0]:
            ev.record(d, touched=True, contact_offset=0.0)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    todo = _probes(f)
    assert {round(d.via_frac if d.vertex == 0 else 1 - d.via_frac, 3) for d in todo} == {0.25, 0.5, 0.75}
    assert all(d.tilt == pytest.approx(45 * DEG, abs=1e-6) for d in todo)
    for d in todo:
        ev.record(d, touched=True, contact_offset=0.0)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probes"


def _door_pair(door):
    """Robots 0 and 1 resting on a wall (y = 0.07) on either side of a door ``door`` wide
    centred between them; apex 2 below (the covered side). Returns (P, reports, hits):
    hits(x) says whether a robot driving up along x touches the wall."""
    P = np.array([[0.0, 0.0], [0.95, 0.0], [0.475, -0.75]])
    lo, hi = 0.475 - door / 2, 0.475 + door / 2
    rep = _reports(P, touch={0: 90 * DEG, 1: 90 * DEG})

    def hits(x, r=0.06):
        return not (lo + r <= x <= hi - r)

    return P, rep, hits


def _run_probes(cx, P, hits, ev, rounds=10):
    """Execute every probe geometrically (a drive up at the probe's x) until none is left or
    one is clear; returns (fence, clear probes)."""
    clear = []
    for _ in range(rounds):
        f = detect_fence(cx, PROBES, **ev.fence_kwargs())
        todo = _probes(f)
        if not todo or clear:
            return f, clear
        for d in todo:
            p = P[d.vertex]
            q = P[d.edge[1] if d.edge[0] == d.vertex else d.edge[0]]
            x = (p + d.via_frac * (q - p))[0]
            touched = hits(x)
            ev.record(d, touched)
            if not touched:
                clear.append(d)
    return detect_fence(cx, PROBES, **ev.fence_kwargs()), clear


def _open_or_inferred_clear(f, e) -> bool:
    """The side of edge e did not close on evidence: it is still frontier, or (a probe found
    room while the side stays one-sided) closed only as the reported inference 'probe_clear'."""
    if e in f.frontier.tolist():
        return True
    return (e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probe_clear"
            and (e, "probe_clear") in [(int(a), w) for a, w in f.inferred])


def test_both_touch_across_a_door_does_not_close_it_before_a_probe_through_the_middle():
    P, rep, hits = _door_pair(0.8)
    cx = build_complex(rep)
    f = detect_fence(cx, PROBES)
    e = int(cx.edge_index(0, 1))
    side = f.by_index[e].sides[0]
    # both contacts point straight into the open side: once this closed the door
    assert side.kind == "frontier" and side.reason == "probing" and not f.obstacle.size
    probes = _probes(f)
    assert {d.edge for d in probes} == {(0, 1)}
    assert any(d.via_frac == 0.5 for d in probes)          # through the middle
    # the contacts are the end probes (each points within 30 deg of the perpendicular)
    assert all(0 < d.via_frac < 1 for d in probes)
    # execute them: the probes in the door find room, the side never closes on evidence
    f, clear = _run_probes(cx, P, hits, Evidence())
    assert clear and _open_or_inferred_clear(f, e)
    # with a wall instead of the door every probe touches and the side closes on evidence
    f, clear = _run_probes(cx, P, lambda x: True, Evidence())
    assert not clear and e in f.obstacle.tolist()
    assert f.by_index[e].sides[0].reason == "probes" and not f.inferred


def test_a_side_closes_only_after_all_its_probes_touched():
    s = 0.9
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, s * math.sqrt(3) / 2]])
    cx = build_complex(_reports(P))
    f0 = detect_fence(cx, PROBES)
    e = int(cx.edge_index(0, 1))
    # the ends' 60-deg drives and the reflex second probes below 0-1 touched
    ev = Evidence()
    for _ in range(2):
        f = detect_fence(cx, PROBES, **ev.fence_kwargs())
        for v in (0, 1):
            for d in f.deployments[v]:
                if d.edge == (0, 1) and d.kind == "edge":
                    ev.record(d, touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert f.by_index[e].sides[0].reason == "probing"
    todo = [d for d in _probes(f) if d.edge == (0, 1)]
    keys = {probe_key(d.vertex, d.edge, d.sigma, d.via_frac) for d in todo if d.via_frac > 0}
    assert {k[3] for k in keys} == {0.25, 0.5, 0.75}
    # every probe but the middle one touched: still frontier, the middle one still offered
    for d in todo:
        if d.via_frac != 0.5:
            ev.record(d, touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert e in f.frontier.tolist() and not f.obstacle.size
    left = [d for d in _probes(f) if d.edge == (0, 1)]
    assert left and all(d.via_frac == 0.5 for d in left)
    assert {d.vertex for d in left} == {0, 1}               # either end may drive it
    # it was clear (room there): the side never closes on evidence
    ev.record(left[0], touched=False)
    assert _open_or_inferred_clear(detect_fence(cx, PROBES, **ev.fence_kwargs()), e)
    # it touched: now the side closes, on evidence
    ev.record(left[0], touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probes"
    assert f0.by_index[e].sides[0].reason == "open"


def test_interior_probes_of_one_robot_in_one_direction_do_not_block_each_other():
    s = 0.9
    P = np.array([[0.0, 0.0], [s, 0.0], [s / 2, -s * math.sqrt(3) / 2]])
    cx = build_complex(_reports(P, touch={0: 90 * DEG, 1: 90 * DEG}))
    ev = Evidence()
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    at0 = [d for d in f.deployments[0] if d.kind == "probe"]
    first = min(at0, key=lambda d: d.via_frac)
    ev.record(first, touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    fr = sorted(d.via_frac for d in f.deployments[0] if d.kind == "probe")
    assert first.via_frac not in fr and len(fr) == len(at0) - 1


def test_an_unreached_probe_is_tried_from_the_other_end_then_closes_only_as_inferred():
    """issue 21 (bench/truth.py map 26): every approach leg from one end clipped a jamb and
    the given-up probes closed a 0.77 rv door. An unreached probe is no evidence: the other
    end tries it first; unreached from both, the side closes only as an inference, reported
    with the certificate."""
    P, rep, _ = _door_pair(0.8)
    cx = build_complex(rep)
    e = int(cx.edge_index(0, 1))
    ev = Evidence()
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    mid = [d for d in _probes(f) if abs(probe_key(d.vertex, d.edge, d.sigma, d.via_frac)[3] - 0.5) < 1e-9]
    assert {d.vertex for d in mid} == {0, 1}
    for d in _probes(f):
        if d not in mid:
            ev.record(d, touched=True)
    from0 = next(d for d in mid if d.vertex == 0)
    for _ in range(Evidence.UNREACHED_LIMIT):
        ev.record_unreached(from0)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    left = _probes(f)
    assert [(d.vertex, d.via_frac) for d in left] == [(1, 0.5)]     # the other end now
    assert e in f.frontier.tolist() and not f.obstacle.size
    for _ in range(Evidence.UNREACHED_LIMIT):
        ev.record_unreached(left[0])
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    # unreached from both ends: nothing left to try; closed only as an inference, reported
    assert not _probes(f) and e in f.obstacle.tolist()
    assert f.by_index[e].sides[0].why == "probe_unreachable"
    assert (e, "probe_unreachable") in [(int(a), w) for a, w in f.inferred]
    # a probe that does reach and touch is evidence again: the side closes on probes
    ev.record(left[0], touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probes" and not f.inferred


def test_a_clear_probe_is_done_and_never_offered_again():
    """issue 21 livelock (bench/truth.py map 4): a clear probe whose robot formed no
    triangle with the edge was offered again and again, stacking robots."""
    P, rep, hits = _door_pair(0.8)
    cx = build_complex(rep)        # the clear probe's robot is not added: no triangle
    e = int(cx.edge_index(0, 1))
    ev = Evidence()
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    n0 = len({probe_key(d.vertex, d.edge, d.sigma, d.via_frac) for d in _probes(f)})
    mid = next(d for d in _probes(f) if d.via_frac == 0.5)
    ev.record(mid, touched=False)
    assert probe_key(mid.vertex, mid.edge, mid.sigma, mid.via_frac) in ev.clear_probes()
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    keys = {probe_key(d.vertex, d.edge, d.sigma, d.via_frac) for d in _probes(f)}
    assert len(keys) == n0 - 1 and all(k[3] != 0.5 for k in keys)
    for d in _probes(f):
        ev.record(d, touched=True)
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    # every probe done, one found room, the side still one-sided: not closed on evidence
    # (its robot explores beyond; the side closes only as the reported inference
    # 'probe_clear'), and nothing is offered again
    assert not _probes(f) and _open_or_inferred_clear(f, e)


def test_probe_via_bearings_follow_from_the_triangle():
    P = np.array([[0.0, 0.0], [0.9, 0.1], [0.3, -0.7], [0.8, -0.6]])
    rep = _reports(P)
    for frac in (0.25, 0.5, 0.75):
        want = probe_via_bearings(rep[0]["neighbours"], rep[1]["neighbours"], 0, 1, frac)
        x = P[0] + frac * (P[1] - P[0])
        assert set(want) >= {1} and len(want) == 2
        for k, b in want.items():
            d = P[k] - x
            assert abs(wrap(b - math.atan2(d[1], d[0]))) < 1e-9
    # a dangling edge: only the other end
    want = probe_via_bearings({1: 0.3}, {0: 0.3 + math.pi}, 0, 1, 0.5)
    assert want == {1: pytest.approx(0.3)}


def test_a_lone_robot_tries_twelve_directions_before_it_gives_up():
    """Six 60 deg apart from its default bearing; once all six touched (each blocks 30 deg
    either side: the whole circle), the six between them (bench/truth.py seed 2 map 387:
    the first robot, whose six drives all touched within d0, ended the run alone at 15%
    coverage)."""
    cx = build_complex({0: {"neighbours": {}}})
    ev = Evidence()
    driven = []
    for touches in range(13):
        f = detect_fence(cx, PROBES, default_bearing=0.3, **ev.fence_kwargs())
        deps = f.deployments.get(0, ())
        if touches < 12:
            assert deps and {d.kind for d in deps} == {"isolated"}, touches
            assert len(deps) == (6 - touches if touches < 6 else 12 - touches)
            if touches == 0:
                assert deps[0].bearing == pytest.approx(0.3)
            driven.append(deps[0].bearing)
            ev.record(deps[0], touched=True)
        else:
            assert not deps and f.done and f.z.size == 0
    want = sorted(wrap(0.3 + k * math.pi / 6) for k in range(12))
    assert sorted(driven) == pytest.approx(want)


def test_an_empty_target_never_certifies():
    snap = Snapshot(occupant={0: 0}, nbrs={0: {}}, sources=[0], source_dirs=[0.3])
    fails = {0: [wrap(0.3 + k * math.pi / 6) for k in range(12)]}   # every direction offered
    kw = dict(cycle=3, redundancy=True, previous_redundant=set(), protected=set(), max_paths=4,
              scale_correct=False, test_drive=True, next_vertex=1)
    plan = plan_cycle(snap, TopologyParams(d_td=0.9), test_drive_failures={0: fails[0][:1]}, **kw)
    assert not plan.certified and plan.jobs and plan.open_vertices   # five directions left
    plan = plan_cycle(snap, TopologyParams(d_td=0.9), test_drive_failures=fails, **kw)
    assert not plan.certified and not plan.jobs and not plan.open_vertices


def test_a_single_file_end_tries_every_direction_of_its_open_wedge():
    # a chain end: one neighbour, the edge's own sides already closed by probes
    cx = build_complex({0: {"neighbours": {1: 0.0}}, 1: {"neighbours": {0: math.pi}}})
    ev = Evidence()
    ev.merge_failures({1: [math.pi - 60 * DEG, -math.pi + 60 * DEG, 90 * DEG, -90 * DEG]})
    seen = []
    for _ in range(30):
        f = detect_fence(cx, PROBES, **ev.fence_kwargs())
        deps = [d for d in f.deployments.get(0, ())]
        if not deps:
            break
        d = deps[0]
        seen.append((d.kind, round(math.degrees(abs(wrap(d.bearing))))))
        ev.record(d, touched=True)
    kinds = {k for k, _ in seen}
    # the dangling edge's 60-deg drives and probes first, then single file: 180 (away from
    # the neighbour) and 120 deg either side; 60 deg either side went with the edge drives
    assert "single_file" in kinds
    sf = [a for k, a in seen if k == "single_file"]
    assert sorted(sf[:3]) == [120, 120, 180]
    # once those touched, the directions between them (bench/truth.py seed 4 map 188: a
    # robot in a 0.30 rv doorway): 150 and 90 deg either side; 30 deg either side is
    # within 50 deg of the neighbour, and none lies within 15 deg of a drive of its own
    assert sorted(sf[3:]) == [90, 90, 150, 150]
    assert not detect_fence(cx, PROBES, **ev.fence_kwargs()).deployments.get(0)


def test_a_clear_probe_with_the_rest_unreached_closes_only_as_inferred():
    """bench/truth.py seed 0: 95 of 500 maps ended stuck (frontier, no deployment), every
    one fully covered: a side with one probe clear (its robot stands beyond the side, yet no
    triangle forms) and the others unreached from both ends. Nothing is left to try: with
    clear_infers (default) it closes as the reported inference 'probe_unreachable'; without
    it the side stays frontier with no deployment (the run ends uncertified)."""
    P, rep, _ = _door_pair(0.8)
    cx = build_complex(rep)
    e = int(cx.edge_index(0, 1))
    ev = Evidence()
    probes = _probes(detect_fence(cx, PROBES, **ev.fence_kwargs()))
    fracs = sorted({probe_key(d.vertex, d.edge, d.sigma, d.via_frac)[3] for d in probes})
    assert len(fracs) >= 2
    for d in probes:
        f_ = probe_key(d.vertex, d.edge, d.sigma, d.via_frac)[3]
        if f_ == fracs[0]:
            ev.record(d, touched=False)                 # clear: room there
        else:
            for _ in range(Evidence.UNREACHED_LIMIT):
                ev.record_unreached(d)                  # its approach clips from this end
    f = detect_fence(cx, PROBES, **ev.fence_kwargs())
    assert not _probes(f) and e in f.obstacle.tolist()
    assert f.by_index[e].sides[0].why == "probe_unreachable"
    assert (e, "probe_unreachable") in [(int(a), w) for a, w in f.inferred]
    f = detect_fence(cx, TopologyParams(clear_infers=False, sweep=False), **ev.fence_kwargs())
    assert e in f.frontier.tolist() and not f.obstacle.size and not _probes(f)
    assert f.by_index[e].sides[0].why == "probing"
    assert not any(d.edge == (0, 1) for lst in f.deployments.values() for d in lst)

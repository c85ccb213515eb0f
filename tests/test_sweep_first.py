"""Sides swept before they are deployed (``TopologyParams.sweep_fallbacks``).

A push whose deployment found no free lattice point, from a robot that felt a wall, laid a
second row of robots along the walls (docs/measured.md, "Where the robots go"). With the flag the
planner asks its side to be swept first (``CyclePlan.sweep_first``, detect_fence's
``sweep_first``). The side then closes only on the sweeps' evidence: whatever its sweeps
would lead a candidate to by inference sends it back to its deployments, so asking can
never close a side that, left alone, a robot would have been placed on.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

from swarmcover.coordinator import build_complex, detect_fence
from swarmcover.coordinator.config import CoordinatorConfig
from swarmcover.coordinator.planner import Placed, Snapshot, plan_cycle
from swarmcover.coordinator.topology.evidence import Evidence
from swarmcover.coordinator.topology.params import TopologyParams
from test_sweep import S, TRI, _nbrs, _side, _sweeps

INF = math.inf
DATA = Path(__file__).parent / "data"
# the side below 0-1 (TRI's apex 2 is above it), canonical sigma as the fence keys it
BELOW = (0, 1, -1)


def _plain():
    """TRI's complex with no evidence at all: the side below 0-1 is a plain frontier side."""
    cx = build_complex({i: {"neighbours": _nbrs(TRI, i)} for i in range(3)})
    return cx, Evidence()


def _asked(ev):
    ev.ask_sweeps([BELOW])
    return ev.fence_kwargs()


def _edge_deps(f):
    return [d for lst in f.deployments.values() for d in lst
            if d.edge == (0, 1) and d.kind == "edge"]


def test_the_side_below_is_the_key_asked():
    cx, ev = _plain()
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert side.kind == "frontier" and side.reason == "open"
    assert {(*d.edge, d.sigma) for d in _edge_deps(f)} == {BELOW}


def test_an_asked_side_is_swept_instead_of_deployed_and_closes_on_the_sweeps_evidence():
    cx, ev = _plain()
    f = detect_fence(cx, **_asked(ev))
    e, side = _side(f, cx)
    assert side.reason == "probing" and not _edge_deps(f)
    a, b = _sweeps(f)
    assert (a.vertex, b.vertex) == (0, 1)
    ev.record(a, touched=True, swept=(0.58, -INF))
    ev.record(b, touched=True, swept=(0.57, -INF))
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert e in f.obstacle.tolist() and side.reason == "probes" and not f.inferred


def _short(ev, cx):
    """Both ends' sweeps over with (0.3, 0.4) left: a candidate would close as 'sweep_gap'."""
    a, b = _sweeps(detect_fence(cx, **ev.fence_kwargs()))
    ev.record(b, touched=True, swept=(0.55, -INF))
    ev.record(a, touched=True, swept=(0.2, -INF))
    a2, _ = _sweeps(detect_fence(cx, **ev.fence_kwargs()))
    ev.record(a2, touched=True, swept=(0.3, -INF))
    (b3,) = _sweeps(detect_fence(cx, **ev.fence_kwargs()))
    ev.record(b3, touched=True, swept=(0.6, -INF))


def test_an_asked_side_left_to_an_inference_goes_back_to_its_deployments():
    cx, ev = _plain()
    _asked(ev)
    _short(ev, cx)
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert side.kind == "frontier" and side.reason == "open" and not f.inferred
    assert e not in f.obstacle.tolist() and _edge_deps(f) and not _sweeps(f)


def test_an_asked_side_whose_sweep_found_room_is_not_closed_as_probe_clear():
    cx, ev = _plain()
    a, b = _sweeps(detect_fence(cx, **_asked(ev)))
    ev.record(a, touched=False)                       # room: its robot stays there
    ev.record(b, touched=True, swept=(0.55, -INF))
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert side.reason == "open" and not f.inferred and _edge_deps(f)


def test_a_free_sweep_that_came_home_clear_sends_an_asked_side_back_to_its_deployments():
    """A free probe's clear sweep comes home (nobody stays in the room it found): for any
    side no evidence, and never offered free again. An asked side would then wait, probing,
    for a push to take that sweep and leave its robot wherever the sweep went (pillar_hall
    seed 0: 43 of its asked sides' sweeps found room); instead the end counts as done and
    the side goes back to its deployments. A side not asked stays probing."""
    for asked in (True, False):
        cx, ev = _plain()
        if asked:
            ev.ask_sweeps([BELOW])
        else:
            for _ in range(2):   # make it a candidate as test_sweep's _candidate does
                for d in _edge_deps(detect_fence(cx, **ev.fence_kwargs())):
                    ev.record(d, touched=True)
        a, b = _sweeps(detect_fence(cx, **ev.fence_kwargs()))
        ev.record(a, touched=False, returned=True)
        ev.record(b, touched=True, swept=(0.55, -INF))
        f = detect_fence(cx, **ev.fence_kwargs())
        e, side = _side(f, cx)
        if asked:
            assert side.reason == "open" and _edge_deps(f) and not f.inferred
        else:
            assert side.reason == "probing" and [d.vertex for d in _sweeps(f)] == [0]


def test_a_side_that_became_a_candidate_of_its_own_counts_a_sweep_home_as_nothing():
    """The free sweep that came home clear ends an asked side's end only while the side is
    asked: once both ends have no room of their own (a candidate by the test-drive rule),
    no room anybody holds is counted there, and that end sweeps again."""
    cx, ev = _plain()
    a, b = _sweeps(detect_fence(cx, **_asked(ev)))
    ev.record(a, touched=False, returned=True)
    ev.record(b, touched=True, swept=(0.55, -INF))
    for _ in range(2):        # both ends' drives into the side touch, as in _candidate
        for d in _edge_deps(detect_fence(cx, test_drive_failures=ev.failed_directions())):
            ev.record(d, touched=True)
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert side.reason == "probing" and [d.vertex for d in _sweeps(f)] == [0]
    assert not f.inferred


def test_a_gap_in_front_of_an_end_is_no_gap_probes_evidence_for_an_asked_side():
    """A candidate's ends felt the wall in front of them; an asked side's did not. Sweeps
    that left (-inf, 0.3) open, gap lines at 0.25 touched: a candidate would close on
    'gap_probes', the asked side goes back to its deployments undriven."""
    cx, ev = _plain()
    a, b = _sweeps(detect_fence(cx, **_asked(ev)))
    for _ in range(TopologyParams().sweep_tries):
        ev.record(a, touched=True)                    # touched, joined nothing
        ev.record(b, touched=True, swept=(0.7, -INF))  # v: [0.3, +inf)
    f = detect_fence(cx, **ev.fence_kwargs())
    e, side = _side(f, cx)
    assert side.reason == "open" and not f.inferred and _edge_deps(f)
    assert not [d for lst in f.deployments.values() for d in lst if d.kind == "probe"
                and d.edge == (0, 1)]


def _small_snap():
    """small.toml seed 0's first cycle that placed pushes by the fallback at robots on a
    wall (tests/data/small_fallback_snapshot.json: 8 robots, captured from a real run)."""
    d = json.loads((DATA / "small_fallback_snapshot.json").read_text())
    iv = lambda m: {int(k): v for k, v in m.items()}
    snap = Snapshot(occupant=iv(d["occupant"]),
                    nbrs={int(k): iv(v) for k, v in d["nbrs"].items()},
                    contact=iv(d["contact"]), kinds=iv(d["kinds"]), sources=d["sources"],
                    source_dirs=d["source_dirs"], known=[tuple(k) for k in d["known"]])
    return snap, iv(d["failures"]), {tuple(k) for k in d["asked"]}


def _plan(snap, fails, on, evidence=None):
    c = CoordinatorConfig()
    return plan_cycle(snap, replace(c.topology(), sweep_fallbacks=on), cycle=1,
                      redundancy=False, test_drive_failures=fails, previous_redundant=set(),
                      protected=set(), max_paths=c.max_paths, scale_correct=False,
                      test_drive=True, next_vertex=14, lattice_spacing=c.d0,
                      evidence=evidence, free_probes=c.free_probes, sweeps_last=c.sweeps_last,
                      sweeps_free=c.sweeps_free, free_max=c.free_max)


def _side_of(job):
    return (*job.deployment.edge, job.deployment.sigma)


def test_the_planner_asks_for_a_sweep_instead_of_a_fallback_push_at_a_wall():
    snap, fails, captured = _small_snap()
    off = _plan(snap, fails, False)
    spec = [j for j in off.jobs if j.placed == Placed.SPEC and j.kind == "edge"
            and j.path[-1] in snap.contact]
    assert spec and not off.sweep_first
    asked = {_side_of(j) for j in spec}
    assert asked == captured
    on = _plan(snap, fails, True)
    assert on.sweep_first == frozenset(asked)
    # no push deploys an asked side of an edge with a triangle (2-9, apex 13); 6-10 is a
    # dangling edge (10 sees 6 alone), which has no third robot to sweep on: still pushed
    assert (2, 9, -1) in asked and (6, 10, -1) in asked
    pushed = {_side_of(j) for j in on.jobs if j.kind == "edge"}
    assert (2, 9, -1) not in pushed and (6, 10, -1) in pushed
    # the new vertex ids still run on from next_vertex
    assert sorted(j.new_vertex for j in on.jobs) == list(range(14, 14 + len(on.jobs)))
    # asked once: with the sides already asked, the plan asks nothing more of them
    again = _plan(snap, fails, True, evidence={"sweep_first": on.sweep_first})
    assert not (again.sweep_first & on.sweep_first)
    # and the fence offers the sweepable one's sweeps, from both ends, in place of its
    # deployments
    cx = build_complex({v: {"neighbours": nb, "touch": v in snap.contact,
                            "touch_bearing": snap.contact.get(v)} for v, nb in snap.nbrs.items()})
    f = detect_fence(cx, test_drive_failures=fails, sweep_first=on.sweep_first)
    deps = [d for lst in f.deployments.values() for d in lst if d.edge == (2, 9)]
    assert deps and all(d.kind == "probe" and d.sweep_far > 0 for d in deps)
    assert {d.vertex for d in deps} == {2, 9}

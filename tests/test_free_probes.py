"""Free probes (issue 21/19): a frontier robot away from every push probes its fence side in
the same cycle without a path, and always ends back at its own vertex.

A clear free probe is no evidence (nobody stays in the room it found): it is booked as
"returned", its side stays open, it is never offered free again, and a push along a path
may still take it. Pure cores only: the planner on a snapshot, the deployer fed statuses.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from swarmcover.bus.messages import Status
from swarmcover.coordinator import build_complex, detect_fence
from swarmcover.coordinator.actions import PublishComplex, SendTask
from swarmcover.coordinator.config import CoordinatorConfig
from swarmcover.coordinator.deployer import Deployer, Phase
from swarmcover.coordinator.jobs import StepState, make_job
from swarmcover.coordinator.roster import Robot
from swarmcover.coordinator.topology.evidence import Evidence, probe_key
from swarmcover.coordinator.topology.params import TopologyParams
from swarmcover.coordinator.planner import Snapshot, carryable, plan_cycle, replan_push

DEG = math.pi / 180
# the probe rule's free probes (interior probe lines; [coordinator] sweep = false);
# tests/test_sweep.py has free wall sweeps
PROBES = TopologyParams(d_td=0.9, sweep=False)

# robots 0 and 1 rest on a wall (y = 0.07) with a 0.8 m door between them, apex 2 below
# them, source 3 below the apex (it sees the apex only), vertex 4 beside the source
DOOR = np.array([[0.0, 0.0], [0.95, 0.0], [0.475, -0.75], [0.475, -1.5], [1.3, -1.5]])


def _nbrs(P, i):
    return {j: math.atan2(q[1] - P[i][1], q[0] - P[i][0]) for j, q in enumerate(P)
            if j != i and math.dist(P[i], q) <= 1.0}


def _snap(P=DOOR, touch=None):
    touch = {0: 90 * DEG, 1: 90 * DEG} if touch is None else touch
    return Snapshot(occupant={v: 100 + v for v in range(len(P))},
                    nbrs={v: _nbrs(P, v) for v in range(len(P))}, contact=dict(touch),
                    sources=[3], source_dirs=[90 * DEG])


def _plan(snap, **kw):
    args = dict(cycle=1, redundancy=False, test_drive_failures={}, previous_redundant=set(),
                protected=set(), max_paths=1, scale_correct=False, test_drive=True,
                next_vertex=10)
    args.update(kw)
    return plan_cycle(snap, PROBES, **args)


def _key(spec):
    d = spec.deployment
    return probe_key(d.vertex, d.edge, d.sigma, d.via_frac)


def _door_fence(ev):
    rep = {v: {"neighbours": nb, "touch": v in (0, 1), "touch_bearing": 90 * DEG}
           for v, nb in ((v, _nbrs(DOOR[:3], v)) for v in range(3))}
    cx = build_complex(rep)
    return cx, detect_fence(cx, PROBES, **ev.fence_kwargs())


def _door_middle(ev):
    """The door fence's edge (0, 1), its probes, the middle one and its key."""
    cx, f = _door_fence(ev)
    probes = [d for lst in f.deployments.values() for d in lst if d.kind == "probe"]
    mid = next(d for d in probes if d.via_frac == 0.5)
    return cx, int(cx.edge_index(0, 1)), probes, mid, probe_key(mid.vertex, mid.edge,
                                                               mid.sigma, mid.via_frac)


def test_a_returned_probe_is_no_evidence_and_keeps_its_side_open():
    ev = Evidence()
    cx, e, probes, mid, k = _door_middle(ev)
    ev.record(mid, touched=False, returned=True)
    assert ev.returned_probes() == {k} and not ev.clear_probes() and not ev.failed_probes()
    assert set(ev.fence_kwargs()) == {"test_drive_failures", "probe_failures", "probe_clear",
                                      "probe_found", "probe_unreachable", "probe_fracs",
                                      "probe_offsets", "tilt_failures", "sweeps",
                                      "sweep_tries", "sweep_first", "sweep_home"}
    # every other probe touches: the side stays frontier, the returned one still offered
    # (a recorded CLEAR probe would now close it as the inference 'probe_clear')
    for d in probes:
        if probe_key(d.vertex, d.edge, d.sigma, d.via_frac) != k:
            ev.record(d, touched=True)
    _, f = _door_fence(ev)
    left = {probe_key(d.vertex, d.edge, d.sigma, d.via_frac)
            for lst in f.deployments.values() for d in lst if d.kind == "probe"}
    assert left == {k} and e in f.frontier.tolist() and not f.obstacle.size
    assert not f.inferred
    # a push along a path that takes it and finds room stays there: a clear probe as ever
    ev.record(mid, touched=False)
    assert ev.clear_probes() == {k}


@pytest.mark.parametrize("first", ["returned", "placed_then_lost"])
def test_a_touch_where_a_probe_found_room_is_no_wall(first):
    """bench/families.py seed 0 map 1: a free probe at fraction 0.25 drove through a 0.30
    m door and came back; a probe at 0.25 from the other end then touched (a jamb, a cut
    off robot in the door), the side's other probes touched the wall, and the side closed
    on 'probes' with the room behind uncovered. A touch at a key where a drive found room
    (a free probe that came back, or a clear probe whose robot later left) is no evidence:
    the key is offered again, and after FOUND_TOUCH_LIMIT touches there no more; the side
    then stays frontier with no deployment, neither closed nor inferred. That holds on a
    side a robot cut off from the swarm stopped a sweep of (there robot 114 stood in the
    room); elsewhere a later touch counts as before."""
    from swarmcover.coordinator.topology.evidence import FOUND_TOUCH_LIMIT
    ev = Evidence()
    cx, e, probes, mid, k = _door_middle(ev)
    ev.record(mid, touched=False, returned=first == "returned",
              placed=None if first == "returned" else 7)   # its robot stood at vertex 7
    for d in probes:
        if probe_key(d.vertex, d.edge, d.sigma, d.via_frac) != k:
            ev.record(d, touched=True)
    beyond = (lambda key, vertex: False) if first == "placed_then_lost" else None  # gone

    side = (*cx.ids[list(cx.edges[e])].tolist(), probes[0].sigma)

    def fence(foreign=(side,)):
        return detect_fence(cx, PROBES, **ev.fence_kwargs(beyond=beyond), sweep_foreign=foreign)


    for n in range(FOUND_TOUCH_LIMIT):
        f = fence()
        left = {probe_key(d.vertex, d.edge, d.sigma, d.via_frac)
                for lst in f.deployments.values() for d in lst if d.kind == "probe"}
        assert left == {k} and e in f.frontier.tolist() and not f.obstacle.size
        ev.record(mid, touched=True)            # the probe at k touched again
    f = fence()
    assert not [d for lst in f.deployments.values() for d in lst if d.kind == "probe"]
    assert e in f.frontier.tolist() and not f.obstacle.size and not f.inferred
    f = fence(foreign=())                       # no robot cut off: the touches close it
    assert e in f.obstacle.tolist() and f.by_index[e].sides[0].why == "probes"
    # the same touches without the room found first: the side closes on evidence
    ev2 = Evidence()
    for d in probes:
        ev2.record(d, touched=True)
    f2 = detect_fence(cx, PROBES, **ev2.fence_kwargs())
    assert e in f2.obstacle.tolist()


def test_a_free_probe_needs_only_its_vertex_clear_of_movers_and_their_neighbours():
    snap = _snap()
    plan = _plan(snap, free_probes=True)
    push = [j for j in plan.jobs if not j.free]
    free = [j for j in plan.jobs if j.free]
    assert push and all(3 in j.path for j in push)
    movers = {v for j in push for v in j.path} | {3}
    # vertex 0's neighbour 2 is next to the source (a mover): the old rule (f's neighbours
    # off every job's neighbourhood) blocked it; its landmarks 1 and 2 hold still now
    assert 2 in snap.nbrs[0] and 3 in snap.nbrs[2]
    assert [j.path for j in free] == [[0]] and free[0].kind == "probe"
    assert not movers & ({0} | set(snap.nbrs[0]))
    # vertex 1 is a neighbour of prober 0: it would home on a mover; no second free probe
    assert all(j.path != [1] for j in free)
    # off by default
    assert not any(j.free for j in _plan(snap).jobs)


def test_a_returned_probe_is_never_offered_free_again_but_paths_still_may_take_it():
    snap = _snap()
    keys = set()
    for _ in range(10):
        free = [j for j in _plan(snap, free_probes=True, returned_probes=frozenset(keys)).jobs
                if j.free]
        if not free:
            break
        assert _key(free[0]) not in keys
        keys.add(_key(free[0]))
    assert {k[3] for k in keys} == {0.25, 0.5, 0.75}   # each probe of the door side once
    # the path pushes do not see the returned set: the same jobs with it as without it
    plain = _plan(snap, max_paths=4)
    ret = _plan(snap, max_paths=4, returned_probes=frozenset(keys))
    assert [(j.path, j.kind, j.via_frac) for j in plain.jobs] == \
        [(j.path, j.kind, j.via_frac) for j in ret.jobs]
    # a free probe's retry skips them; any other re-planned push may take them
    kw = dict(start=0, busy=[], exclude={1, 2, 3, 4}, test_drive_failures={}, new_vertex=10,
              scale_correct=False, test_drive=True)
    any_push = replan_push(snap, PROBES, **kw)
    free_retry = replan_push(snap, PROBES, skip_probes=frozenset(keys), **kw)
    assert any_push.kind == "probe" and _key(any_push) in keys
    assert free_retry is None or free_retry.kind != "probe"


def _deployer(snap, cfg=CoordinatorConfig(sweep=False)):
    """A deployer that holds ``snap``: every occupant a live robot holding its vertex."""
    dep = Deployer(cfg, sources=[90 * DEG])
    dep.snapshot = snap
    seq = iter(range(1, 10_000))
    for v, rid in snap.occupant.items():
        dep.vertex_of[rid] = v
        dep.robots[rid] = Robot(rid, alive=True, status=Status(
            robot=rid, seq=next(seq), t=0.0, state="holding", vertex=v,
            nbr_ids=[snap.occupant[u] for u in snap.nbrs[v]],
            nbr_bearings=list(snap.nbrs[v].values())))
    return dep, seq


def _tasks(dep):
    return [a.task for a in dep.out.actions if isinstance(a, SendTask)]


def _start_free_probe():
    """The first free probe of _snap's plan, started: (snap, spec, its vertex f, its robot,
    the deployer, the status seq counter, the job, the test-drive task sent)."""
    snap = _snap()
    spec = next(j for j in _plan(snap, free_probes=True).jobs if j.free)
    f, rid = spec.path[0], snap.occupant[spec.path[0]]
    dep, seq = _deployer(snap)
    job = make_job(spec, snap.occupant)
    dep.jobs = [job]
    dep.out.actions = []
    dep.pushes.advance(job, 1.0)
    (td,) = _tasks(dep)
    return snap, spec, f, rid, dep, seq, job, td


def test_a_clear_free_probe_goes_back_home_and_is_booked_as_returned():
    snap, spec, f, rid, dep, seq, job, td = _start_free_probe()
    assert td.kind == "test_drive" and td.robot == rid and td.keep_after == 0.0
    assert td.via_landmarks                        # to its point on the edge first
    # the drive found room: the agent reports it done where it ended
    dep.on_status(Status(robot=rid, seq=next(seq), t=2.0, state="holding", vertex=f,
                         task_id=td.task_id, task_state="done"))
    dep.out.actions = []
    dep.pushes.advance(job, 2.0)
    (home,) = _tasks(dep)
    # home: goto its own vertex on its neighbours' robots and its own recorded bearings
    assert home.kind == "goto" and home.vertex == f and home.robot == rid
    want = {snap.occupant[u]: b for u, b in snap.nbrs[f].items()}
    assert dict(zip(home.landmarks, home.bearings)) == want
    assert job.step("deploy").state == "cancelled" and job.step("refine").state == "cancelled"
    assert dep.evidence.returned_probes() == {_key(spec)}
    assert not dep.evidence.clear_probes() and not dep.evidence.failed_probes()
    dep.out.actions = []
    dep.pushes.advance(job, 2.5)                     # nothing more to send
    assert not _tasks(dep)
    dep.on_status(Status(robot=rid, seq=next(seq), t=3.0, state="holding", vertex=f,
                         task_id=home.task_id, task_state="done"))
    assert job.finished and dep.vertex_of[rid] == f
    # nobody was left out of place: the next snapshot has every vertex occupied
    assert set(dep.build_snapshot().occupant) == set(snap.occupant)
    # and the next plan does not offer that probe free again
    nxt = _plan(snap, free_probes=True, returned_probes=dep.evidence.returned_probes())
    assert all(_key(j) != _key(spec) for j in nxt.jobs if j.free)


def test_a_free_probe_that_touched_books_evidence_and_tries_its_next_probe():
    snap, spec, f, rid, dep, seq, job, td = _start_free_probe()
    dep.on_status(Status(robot=rid, seq=next(seq), t=2.0, state="holding", vertex=f,
                         task_id=td.task_id, task_state="failed", reason="touch"))
    dep.out.actions = []
    dep.pushes.advance(job, 2.0)
    assert _key(spec) in dep.evidence.failed_probes()
    assert not dep.evidence.returned_probes()
    # re-planned at once at the same vertex, still free, another probe
    assert job.spec.free and job.spec.path == [f] and job.spec.kind == "probe"
    assert _key(job.spec) != _key(spec)
    dep.pushes.advance(job, 2.0)
    (td2,) = _tasks(dep)
    assert td2.kind == "test_drive" and td2.robot == rid and td2.vertex == f


def test_a_free_probe_starts_within_the_cycle_once_its_neighbours_probe_is_over():
    """``free_probes_rolling``: at the cycle's start vertex 1 may not probe (its neighbour
    0 does, and would home on it); once 0's probe is over and while the push still runs, 1
    probes in the same cycle. A vertex probes free once a cycle, and nothing starts once
    the pushes are over."""
    snap = _snap()
    plan = _plan(snap, free_probes=True)
    assert [(j.path, j.free) for j in plan.jobs] == [([3], False), ([0], True)]

    def cycle(cfg):
        dep, _ = _deployer(snap, cfg)
        dep.jobs = [make_job(s, snap.occupant) for s in plan.jobs]
        dep.next_vertex = 20
        return dep, dep.jobs[0], dep.jobs[1]

    dep, push, free = cycle(CoordinatorConfig(sweep=False))
    dep.pushes.roll_free_probes(1.0)
    assert len(dep.jobs) == 2                     # nothing over yet: nothing new
    free.cancel("its probes are done")
    dep.pushes.roll_free_probes(2.0)
    (new,) = dep.jobs[2:]
    assert new.spec.free and new.spec.path == [1] and new.spec.kind == "probe"
    assert new.spec.new_vertex == 20 and dep.next_vertex == 21
    # its landmarks hold still: f and its neighbours are off the push and off every probe
    # still out
    assert not ({1} | set(snap.nbrs[1])) & (set(push.spec.path) | {3})
    dep.out.actions = []
    dep.pushes.advance(new, 2.0)
    (td,) = _tasks(dep)
    assert td.kind == "test_drive" and td.robot == snap.occupant[1]
    # vertex 0 probed this cycle already: not again, though its neighbour's probe is over
    new.cancel("its probes are done")
    dep.pushes.roll_free_probes(3.0)
    assert len(dep.jobs) == 3
    # once the push is over, nothing starts: the cycle ends and the next plans afresh
    dep, push, free = cycle(CoordinatorConfig(sweep=False))
    push.cancel("over")
    free.cancel("over")
    dep.pushes.roll_free_probes(2.0)
    assert len(dep.jobs) == 2
    # off: only the cycle's start offers free probes
    dep, push, free = cycle(CoordinatorConfig(sweep=False, free_probes_rolling=False))
    free.cancel("over")
    dep.pushes.roll_free_probes(2.0)
    assert len(dep.jobs) == 2


def _holding(dep, seq, snap, t, out=None, far=None, task_id=-1):
    """Every robot of ``snap`` reports at ``t``: holding its vertex with ``snap``'s
    bearings, but robot ``out``, test-driving (task ``task_id``) and seeing ``far`` (id ->
    bearing)."""
    for v, rid in snap.occupant.items():
        busy = rid == out
        nb = far if busy else {snap.occupant[u]: b for u, b in snap.nbrs[v].items()}
        wall = v in snap.contact and not busy
        dep.on_status(Status(robot=rid, seq=next(seq), t=t,
                             state="test_driving" if busy else "holding", vertex=v,
                             contact=wall, contact_bearing=snap.contact.get(v, 0.0),
                             task_id=task_id if busy else -1,
                             task_state="running" if busy else "",
                             nbr_ids=list(nb), nbr_bearings=list(nb.values())))


def test_a_free_probe_still_out_goes_on_into_the_next_cycle_which_plans_around_it():
    """``free_probes_carry``: the cycle ends once its pushes are over. The next plan keeps
    the prober's edges as they were when it left (not as it sees them from out there), no
    path uses its vertex or a neighbour (its landmarks home), no free probe goes next to
    it, and nothing is certified until it is back."""
    P = DOOR[[3, 0, 1, 2, 4]]        # the deployer's source 0 is vertex 0: renumbered
    snap = replace(_snap(P, touch={1: 90 * DEG, 2: 90 * DEG}), sources=[0])
    plans = []

    def planner(s, params, **kw):
        plans.append((s, kw))
        if len(plans) == 2:      # "complete": no frontier, certified
            return replace(plan_cycle(s, params, **kw), frontier=[], open_vertices=set(),
                           certified=True, jobs=[])
        return plan_cycle(s, params, **kw)

    dep = Deployer(CoordinatorConfig(sweep=False), sources=[90 * DEG], planner=planner)
    seq = iter(range(1, 10_000))
    for v, rid in snap.occupant.items():
        dep.vertex_of[rid] = v
    dep.next_vertex = 10
    _holding(dep, seq, snap, 0.0)
    dep.snapshot = snap
    dep.phase, dep.phase_t = Phase.SETTLE, 0.0
    dep.step(1.0)                                    # plans cycle 0: a push and a probe
    (s0, kw0), = plans
    push, free = dep.jobs
    assert not push.spec.free and free.spec.free and free.spec.path == [1]
    assert kw0["out"] == frozenset()
    dep.step(1.1)                                    # both start
    prober = snap.occupant[1]
    # the push is over; the prober is out, and sees the world from elsewhere
    push.cancel("over")
    for s in push.steps:
        if s.state == StepState.RUNNING:
            s.state = StepState.DONE
    far = {snap.occupant[3]: 0.3, snap.occupant[0]: -2.0}
    td = free.step("test_drive").task_id
    _holding(dep, seq, snap, 2.0, out=prober, far=far, task_id=td)
    dep.step(2.0)
    assert dep.phase == Phase.SETTLE and dep.jobs == [free]       # carried, not waited for
    _holding(dep, seq, snap, 3.0, out=prober, far=far, task_id=td)
    acts = dep.step(3.0)                             # plans cycle 1 around the prober
    (cx_msg,) = [a.complex for a in acts if isinstance(a, PublishComplex)]
    assert not cx_msg.certified                      # not even in what it publishes
    s1, kw1 = plans[1]
    assert kw1["out"] == frozenset({1}) and not kw1["redundancy"]
    assert s1.nbrs[1] == snap.nbrs[1]                # its edges as when it left
    assert all(s1.nbrs[v].get(1) == snap.nbrs[v].get(1) for v in s1.nbrs if v != 1)
    assert not dep.done and not dep.certified        # "complete", but a probe is out
    assert dep.jobs == [free] and dep.phase == Phase.EXECUTE
    # the real plan on that snapshot: nothing uses the prober or its neighbours
    real = plan_cycle(s1, PROBES, cycle=1, redundancy=False, test_drive_failures={},
                      previous_redundant=set(), protected=set(), max_paths=4,
                      scale_correct=False, test_drive=True, next_vertex=30,
                      free_probes=True, out=frozenset({1}))
    near1 = {1} | set(s1.nbrs[1])
    assert real.jobs and all(not near1 & set(j.path) for j in real.jobs)
    # it is back: the cycle of the carried probe alone ends when it does
    free.cancel("back home")
    free.step("test_drive").state = StepState.DONE
    _holding(dep, seq, snap, 4.0)
    dep.step(4.0)
    assert dep.phase == Phase.SETTLE and dep.jobs == []
    # off: the cycle waits for its free probes
    dep = Deployer(CoordinatorConfig(sweep=False, free_probes_carry=False),
                   sources=[90 * DEG])
    dep.jobs = [push, free]                       # the push is over, the probe out
    for s in free.steps:
        s.state = StepState.RUNNING if s.name == "test_drive" else StepState.PENDING
    assert push.finished and not free.finished
    assert dep.pushes.carried() is None
    dep.pushes.cfg = replace(dep.cfg, free_probes_carry=True)
    assert dep.pushes.carried() == [free]


def test_a_probe_that_would_cut_the_pushes_off_their_frontier_is_waited_for_not_carried():
    """A corridor two robots wide (rows along walls, source 0 at one end): a prober in its
    middle and its neighbours cross it, so carried it would hold every push of the next
    cycle out of the corridor beyond. It is waited for; one near the far end, beyond which
    nothing is open, may stay out, and so may a prober at the end of a room's wall."""
    P, touch = [], {}
    for i in range(7):
        P.append((0.9 * i, 0.0))
        touch[len(P) - 1] = -90 * DEG
        P.append((0.9 * i + 0.45, 0.78))
        touch[len(P) - 1] = 90 * DEG
    P = np.array(P)
    snap = Snapshot(occupant={v: 100 + v for v in range(len(P))},
                    nbrs={v: _nbrs(P, v) for v in range(len(P))}, contact=touch,
                    sources=[0], source_dirs=[0.0])
    plan = _plan(snap, free_probes=True, max_paths=8)
    free = [j.path[0] for j in plan.jobs if j.free]
    assert 6 in free                               # a probe mid-corridor, at the start
    far = max(plan.open_vertices)                  # the corridor's open end
    ok = carryable(plan.edges, [0], plan.open_vertices, free)
    mid = [f for f in free if f + 3 < far]
    assert mid and not ok & set(mid)
    # the rule itself: what it keeps out never cuts a reachable deployment off
    assert carryable(plan.edges, [0], {far}, [far - 1]) == {far - 1}
    assert carryable(plan.edges, [0], {far}, [6]) == set()
    # at the deployer: once the push is over, the cycle waits for the probe mid-corridor
    dep, _ = _deployer(snap)
    dep.jobs = [make_job(j, snap.occupant) for j in plan.jobs
                if not j.free or j.path == [6]]
    dep.plan = plan
    for j in dep.jobs:
        if not j.spec.free:
            j.cancel("over")
    assert dep.pushes.carried(plan) is None
    # a room: the DOOR scene's prober at the wall end may stay out
    room = _snap()
    rplan = _plan(room, free_probes=True)
    (rf,) = [j.path[0] for j in rplan.jobs if j.free]
    assert carryable(rplan.edges, room.sources, rplan.open_vertices, [rf]) == {rf}


def test_a_sweeps_stopper_is_booked_at_its_vertex_only_while_it_stands_still():
    """The deployer books a wall sweep's stoppers by the vertex each held standing still
    (Evidence.stopper_vertices, which 'sweep_blocked' rests on): a robot with a step of a
    push still to do, or on a vertex such a step fills, is moving and vouches for no
    place; so is a robot the deployer holds no vertex for."""
    snap = _snap()
    spec = next(j for j in _plan(snap).jobs if not j.free)
    dep, _ = _deployer(snap)
    dep.jobs = [make_job(spec, snap.occupant)]
    robots = tuple(sorted(snap.occupant.values())) + (999,)
    places = dep.pushes._stopper_places(robots)
    moving = dep.pushes._in_motion(dep.placement.holders(dep.roster))
    assert moving & set(spec.path)
    for v, rid in snap.occupant.items():
        assert places[rid] == (None if v in moving else v)
    assert places[999] is None
    assert any(p is not None for p in places.values())

"""The coordinator's deployment cycles, driven in one process (swarmcover.simloop) with the
real physics, sensors, agent behaviours and deployer: certification must mean coverage."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from swarmcover.bus.messages import Status
from swarmcover.coordinator.actions import PublishComplex, SendTask, SpawnRobot
from swarmcover.coordinator.config import CoordinatorConfig
from swarmcover.coordinator.deployer import Deployer
from swarmcover.simloop import SimLoop
from swarmcover.world.config import load_config
from swarmcover.world.groundtruth import coverage_fraction


def _coverage(sim, res) -> float:
    alive = [r for r in res.positions if r in sim.agents]
    P = np.array([res.positions[r] for r in alive]).reshape(-1, 2)
    return coverage_fraction(sim.wm, P, sim.cfg.rv)


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match=r"\[coordinator\] push_mod = 'parallel': unknown field"):
        CoordinatorConfig.from_section({"push_mod": "parallel"}, rv=1.0, where="x.toml")
    with pytest.raises(ValueError, match=r"push_mode = 'fast'"):
        CoordinatorConfig.from_section({"push_mode": "fast"}, rv=1.0)
    with pytest.raises(ValueError, match=r"max_paths = '2': expected an integer"):
        CoordinatorConfig.from_section({"max_paths": "2"}, rv=1.0)
    assert CoordinatorConfig.from_section({"task_timeout_s": 30}, rv=2.0).d0 == pytest.approx(1.8)


def test_first_cycle_spawns_then_holds_then_deploys_the_lone_robot():
    dep = Deployer(CoordinatorConfig(), sources=[0.5])
    acts = dep.step(0.0) + dep.step(1.5)
    spawns = [a.spawn for a in acts if isinstance(a, SpawnRobot)]
    assert [s.robot for s in spawns] == [0] and spawns[0].source == 0
    dep.on_alive(0, True, 1.5)
    dep.on_status(Status(robot=0, seq=1, t=1.6, state="idle"))
    acts = dep.step(1.6)
    (task,) = [a.task for a in acts if isinstance(a, SendTask)]
    assert task.kind == "hold" and task.vertex == 0 and task.robot == 0
    dep.on_status(Status(robot=0, seq=2, t=2.0, state="holding", vertex=0,
                         task_id=task.task_id, task_state="done"))
    acts = dep.step(2.0) + dep.step(3.0) + dep.step(3.1)
    cx = [a.complex for a in acts if isinstance(a, PublishComplex)]
    assert cx and cx[0].vertices == [0] and not cx[0].certified
    td = [a.task for a in acts if isinstance(a, SendTask)]
    # a lone robot is frontier: it test-drives along the base heading first
    assert td and td[0].kind == "test_drive" and td[0].direction == pytest.approx(0.5)


def test_agents_that_joined_by_hand_are_placed_first_and_not_counted_before():
    """Issue 18: an agent with no body (avail/robot/<id>) is no robot of the swarm until the
    coordinator places it, and it is placed before a new id is asked for; its alive token or
    status arriving before its avail token does not make it one either."""
    dep = Deployer(CoordinatorConfig(), sources=[0.5])
    dep.on_alive(42, True, 0.0)          # alive first (token order is not guaranteed) ...
    dep.on_status(Status(robot=42, seq=1, t=0.0, state="starting", vertex=-1))
    dep.on_available(42, True)           # ... then available: taken back out of the swarm
    dep.on_available(9, True)
    dep.on_alive(9, True, 0.0)
    dep.on_status(Status(robot=9, seq=1, t=0.0, state="starting", vertex=-1))
    assert 42 not in dep.robots and 9 not in dep.robots and dep.available == {9, 42}
    acts = dep.step(0.0) + dep.step(1.5)
    spawns = [a.spawn for a in acts if isinstance(a, SpawnRobot)]
    assert [s.robot for s in spawns] == [9] and spawns[0].source == 0   # lowest id first
    assert dep.available == {42} and 9 in dep.robots and dep.joined == 1
    dep.on_status(Status(robot=9, seq=2, t=1.6, state="idle"))
    acts = dep.step(1.6)
    (task,) = [a.task for a in acts if isinstance(a, SendTask)]
    assert task.kind == "hold" and task.robot == 9        # the first robot is the one placed
    dep.on_available(9, False)           # its first Sense: no change, it is ours
    dep.on_available(42, False)          # the other one went away while waiting
    assert dep.available == set() and 9 in dep.robots
    assert dep._spawn(0, 2.0) == 43      # new ids never reuse one seen
    assert dep.summary()["robots_joined"] == 1


@pytest.mark.timeout(480)
@pytest.mark.parametrize("config", [
    "configs/small.toml",
    # rooms behind 0.9 m doors: a test drive that touches a door jamb closes that robot's
    # deployments, not the fence side, so the robot across the edge still goes through the
    # door (one end's touch used to close whole rooms: certified at 23-87% coverage here)
    pytest.param("configs/corridor_doors.toml", marks=pytest.mark.slow),
])
def test_certified_means_covered(config):
    cfg = load_config(config)
    sim = SimLoop(cfg)
    # corridor_doors with the probe rules: 98 cycles, 1,935 s simulated, 243 s of wall time
    # on one core of this machine (seed 0); 200 s was its limit before the probes
    res = sim.run(max_sim_s=4000, max_wall_s=420)
    assert res.certified, res.stop_reason
    cx = res.final
    assert cx.certified and cx.state == "certified" and not cx.frontier
    assert _coverage(sim, res) >= 0.995
    # every vertex of the final complex is held by a live robot, and the complex is the
    # one the robots see now: each edge's robots are within rv of each other
    occ = dict(zip(cx.vertices, cx.occupants))
    assert all(o in sim.agents for o in occ.values())
    for a, b in zip(cx.edges[0::2], cx.edges[1::2]):
        pa, pb = res.positions[occ[a]], res.positions[occ[b]]
        assert math.dist(pa, pb) <= cfg.rv + 1e-6


@pytest.mark.timeout(240)
def test_failed_robots_leave_holes_that_are_refilled():
    cfg = load_config("configs/tiny.toml")
    sim = SimLoop(cfg)
    killed = []

    def on_cycle(sim, cx):
        if cx.cycle == 6 and not killed:
            occ = [o for o in cx.occupants if o not in (0,)]
            victim = occ[len(occ) // 2]
            killed.append(victim)
            sim.kill(victim)

    res = sim.run(max_sim_s=1500, max_wall_s=180, on_cycle=on_cycle)
    assert killed and res.certified, res.stop_reason
    assert killed[0] not in res.final.occupants
    assert res.deployer.failures == 1 and res.deployer.failures_healed == 1
    assert _coverage(sim, res) >= 0.99


@pytest.mark.timeout(240)
def test_a_fresh_coordinator_resumes_from_statuses():
    cfg = load_config("configs/tiny.toml")
    sim = SimLoop(cfg)
    res = {}

    def swap(sim, cx):
        if cx.cycle == 5 and "swapped" not in res:
            # the coordinator dies: a new one knows nothing but what agents report
            res["swapped"] = len(cx.vertices)
            old = sim.dep
            sim.dep = Deployer(old.cfg, sources=old.sources, epoch=2)
            for rid, core in sim.agents.items():
                sim.dep.on_alive(rid, True, sim.t)
                sim.dep.on_status(core.status())

    out = sim.run(max_sim_s=1500, max_wall_s=180, on_cycle=swap)
    assert res["swapped"] >= 4
    assert out.certified, out.stop_reason
    assert out.deployer.epoch == 2
    assert _coverage(sim, out) >= 0.99


def _started_steps(monkeypatch):
    """Record (step name, step, job) for every step the deployer starts."""
    from swarmcover.coordinator.pushes import Pushes
    started = []
    orig_start = Pushes.start

    def start(self, s, task, now):
        job = next((j for j in self.jobs if s in j.steps), None)
        started.append((s.name, s, job, task))
        return orig_start(self, s, task, now)

    monkeypatch.setattr(Pushes, "start", start)
    return started


@pytest.mark.timeout(240)
def test_a_clear_test_drive_places_the_new_robot(monkeypatch):
    # default: d_td = d0, so a test drive that found room ends where the robot belongs; it is
    # not re-homed on the assumed geometry (which inherits the parent edge's length)
    started = _started_steps(monkeypatch)
    cfg = load_config("configs/tiny.toml")
    sim = SimLoop(cfg)
    res = sim.run(max_sim_s=1500, max_wall_s=180)
    assert res.certified, res.stop_reason
    names = [n for n, *_ in started]
    assert names.count("test_drive") >= 5
    assert "refine" not in names
    # every clear drive placed its robot (a free probe's goes home: nobody refills its
    # vertex): no deploy task, the deploy step done with that reason, the refine cancelled
    clear = [job for n, s, job, _ in started if n == "test_drive" and s.state == "done"
             and s.reason != "wall" and not job.spec.free]
    assert clear
    for job in clear:
        assert job.step("deploy").reason == "placed by the test drive"
        assert job.step("refine").state == "cancelled"
    assert not [n for n, s, job, _ in started if n == "deploy" and job in clear]
    assert _coverage(sim, res) >= 0.99


@pytest.mark.timeout(240)
def test_refine_homes_on_the_robot_that_took_over_the_frontier_vertex(monkeypatch):
    # with refine_deploy on, the deployed robot re-homes using the robot now at f: the mover
    # p_{m-1} -> f, not another mover of the same path (a robot metres away)
    started = _started_steps(monkeypatch)
    cfg = load_config("configs/tiny.toml")
    sim = SimLoop(cfg, coordinator_overrides={"refine_deploy": True})
    res = sim.run(max_sim_s=1500, max_wall_s=180)
    assert res.certified, res.stop_reason
    refines = [(s, job, task) for n, s, job, task in started if n == "refine"]
    long_paths = [r for r in refines if len(r[1].spec.path) >= 3]
    assert long_paths, "no refine after a push of three or more vertices"
    checked = 0
    for s, job, task in refines:
        f = job.spec.path[-1]
        at_f = [m for m in job.steps if m.name in ("move", "enter") and m.target == f]
        assert at_f
        if at_f[0].state == "done":      # a mover that failed is near f, not known where
            assert at_f[0].robot in task.landmarks
            checked += 1
    assert checked




def _room6x4(tmp_path) -> Path:
    """configs/tiny.toml grown to a 6 m x 4 m room, entered from the middle of its right wall."""
    text = Path("configs/tiny.toml").read_text()
    text = text.replace("boundary = [[0, 0], [3, 0], [3, 2], [0, 2]]",
                        "boundary = [[0, 0], [6, 0], [6, 4], [0, 4]]")
    text = text.replace("sources = [{x = 0.3, y = 1.0, theta = 0.0}]",
                        "sources = [{x = 5.7, y = 2.0, theta = 3.14159}]")
    assert "[6, 4]" in text and "x = 5.7" in text
    path = tmp_path / "room6x4.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_the_final_redundancy_pass_sends_its_robots_away(tmp_path):
    path = _room6x4(tmp_path)  # enough robots for redundancy to find some
    # default placement: seed 4 finds 4 robots redundant at the end (seeds 0-5: 1-4 each)
    sim = SimLoop(load_config(path), seed=4)
    res = sim.run(max_sim_s=3000, max_wall_s=200)
    assert res.certified, res.stop_reason
    cx = res.final
    # passes repeat until one finds nothing: every redundant robot found has left, and none
    # of them is counted in the certified complex (the last pass's used to stay in it)
    assert not cx.redundant
    assert res.deployer.left, "no redundant robot on this map: the test shows nothing"
    assert set(res.deployer.left).isdisjoint(cx.occupants)
    assert _coverage(sim, res) >= 0.99


@pytest.mark.xfail(strict=False, reason=(
    "since the lockstep tick order (tasks apply one tick after the deciding tick) and the "
    "probe rule, seed 4 gave p90 drift 0.058 m without settling and 0.208 m with it, and the "
    "run without settling did not certify within its limits: settling is being re-measured"))
@pytest.mark.slow
@pytest.mark.timeout(240)
def test_movers_on_one_landmark_settle_so_vertices_stay_put(tmp_path):
    """A mover whose other landmarks were moving (the source refilled behind it) homes on one
    bearing, which fixes a ray, not a point. Once its push is over it settles on all of its
    vertex's landmarks: where each vertex's later robots stand stays where its first stood."""
    from swarmcover.coordinator.planner import plan_cycle

    cfg = load_config(_room6x4(tmp_path))
    p90 = {}
    for settle in (False, True):
        # without in-cycle retries: with them, later robots stand 0.175 m (p90) from a
        # vertex's first robot whether they settle or not (seed 4; not yet explained)
        sim = SimLoop(cfg, seed=4, coordinator_overrides={"settle_moves": settle,
                                                          "lattice": False, "td_retries": 0})
        first: dict[int, tuple] = {}
        drift: list[float] = []

        def planner(snap, params, sim=sim, first=first, drift=drift, **kw):
            ids, pos, _ = sim.physics.state()
            P = dict(zip(ids, map(np.asarray, pos)))
            for v, r in snap.occupant.items():
                if r not in P:
                    continue
                if v not in first:
                    first[v] = (r, P[r])
                elif first[v][0] != r:  # a later robot holds v
                    drift.append(float(np.linalg.norm(P[r] - first[v][1])))
            return plan_cycle(snap, params, **kw)

        sim.dep.planner = planner
        res = sim.run(max_sim_s=3000, max_wall_s=200)
        assert res.certified, res.stop_reason
        p90[settle] = float(np.percentile(drift, 90))
    # measured (seed 4): 0.16 m without settling, 0.05 m with it (0.137 and 0.067 since the
    # reflex second probe)
    assert p90[True] < 0.1 * cfg.rv, p90
    assert p90[True] < p90[False] / 2, p90


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_lattice_placement_covers_the_room(tmp_path, monkeypatch):
    """[coordinator] lattice = true: new robots go to free points of one lattice through the
    source (from the bearing-only shape estimate). On the 6 m x 4 m room it certifies full
    coverage. (It no longer uses fewer robots than the spec's 60-deg rule there: seeds 1-6,
    47.7 against 46.7, since failed test drives block only their own direction.)"""
    import swarmcover.coordinator.pushes as pushes

    cfg = load_config(_room6x4(tmp_path))
    sim = SimLoop(cfg, seed=1, coordinator_overrides={"lattice": True})
    jobs = []
    orig, orig_retry = sim.dep.planner, pushes.replan_push

    def planner(snap, params, **kw):
        plan = orig(snap, params, **kw)
        jobs.extend(plan.jobs)
        return plan

    def retry(*a, **kw):
        spec = orig_retry(*a, **kw)
        jobs.extend([spec] if spec else [])
        return spec

    sim.dep.planner = planner
    monkeypatch.setattr(pushes, "replan_push", retry)
    res = sim.run(max_sim_s=3000, max_wall_s=200)
    assert res.certified, res.stop_reason
    assert _coverage(sim, res) >= 0.995
    # the lattice chose the positions: about half the pushes, retries included, go to a
    # free lattice point found, whose distance is its own (the fallbacks drive exactly d0;
    # measured: 59 of 117; 64 of 116 without retries)
    d0 = sim.dep.cfg.d0
    found = [j for j in jobs if j.distance is not None and abs(j.distance - d0) > 1e-9]
    assert len(found) > 0.4 * len(jobs), (len(found), len(jobs))


def _job(path, *, feed=None, occ=None, enter=True):
    """A PushJob as the deployer builds it (robot ids = 100 + vertex unless ``occ``)."""
    from swarmcover.coordinator.jobs import PushJob, Step
    from swarmcover.coordinator.planner import JobSpec
    occ = occ or {v: 100 + v for v in path}
    job = PushJob(JobSpec(path=list(path), direction=0.0, deploy_landmarks=[], deploy_bearings=[],
                          new_vertex=99, enter_source=0 if enter else None), feed=feed)
    f = path[-1]
    job.steps.append(Step("test_drive", occ[f], f))
    job.steps.append(Step("deploy", occ[f], 99))
    for t in range(len(path) - 2, -1, -1):
        job.steps.append(Step("move", occ[path[t]], path[t + 1], t_index=t))
    job.steps.append(Step("enter", -1, path[0]))
    if feed is not None:
        job.steps_at_source().robot = -1
    return job


def test_a_push_whose_test_drive_touched_hands_its_source_robot_to_the_next_push():
    from swarmcover.coordinator.jobs import PushJob
    src = PushJob.source_robot
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a)
    c = _job([0, 5], feed=b)
    assert src(b) is None                       # a's new robot is still entering
    a.step("enter").state, a.step("enter").robot = "done", 7
    assert src(b) == 7
    # a's test drive touched: its robot at 0 never left, b takes it (not "feed failed")
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a)
    c = _job([0, 5], feed=b)
    a.cancel("test drive touched an obstacle")
    a.step("test_drive").state = "failed"
    assert src(b) == 100
    # and when b stops too, before it got a's robot, c takes it
    b.cancel("test drive touched an obstacle")
    assert src(c) == 100
    # a one-vertex push whose own robot (at the source) test-drove and came back
    a1 = _job([0])
    b1 = _job([0, 3], feed=a1)
    a1.step("test_drive").state, a1.step("test_drive").reason = "failed", "touch at 0.3 m"
    a1.aborted = True
    assert src(b1) == 100
    a1.step("test_drive").reason = "timeout"   # where it is, nobody knows
    assert src(b1) is False
    # a's robot left the source, then a's refill failed: nothing to hand on
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a)
    a.step("move", 0).state = "done"
    a.step("enter").state = "failed"
    a.aborted = True
    assert src(b) is False


class _Tasks:
    """Task builder stand-in for the push state machine alone: every task goes, with two
    static landmarks (what the real builder gives a mover on a settled lattice)."""

    def test_drive(self, spec, moving=frozenset()):
        from swarmcover.bus.messages import Task
        return Task(kind="test_drive", vertex=spec.path[-1], direction=0.0, distance=0.9)

    def deploy(self, spec, moving):
        from swarmcover.bus.messages import Task
        return Task(kind="deploy", vertex=spec.new_vertex)

    def move(self, path, t, moving, ahead, holder=None, beyond=None):
        from swarmcover.bus.messages import Task
        return Task(kind="goto", vertex=path[t + 1], landmarks=[1, 2], bearings=[0.0, 1.0])

    def refine(self, spec, moving, at_f):
        return None


@pytest.mark.parametrize("pipeline", [True, False])
def test_a_fed_push_test_drives_at_once_and_waits_for_its_source_robot_only_to_move(pipeline):
    """Issue 19 item 4: pushes fed by one source stream. The second push's test drive (at
    its own frontier vertex, nobody else's) runs while the first push's new robot is still
    entering; its movers wait for that robot. ``pipeline = false``: the whole push waits."""
    dep = Deployer(CoordinatorConfig(pipeline=pipeline), sources=[0.0])
    from swarmcover.coordinator.jobs import Step
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a)
    for job in (a, b):
        job.steps.append(Step("refine", job.step("deploy").robot, 99))
    dep.jobs = [a, b]
    dep.pushes.tasks = _Tasks()
    sent = lambda job: {(s.name, s.t_index) for s in job.steps if s.state != "pending"}
    dep.pushes.advance(a, 0.0)
    dep.pushes.advance(b, 0.0)
    assert sent(a) == {("test_drive", -1)}
    assert sent(b) == ({("test_drive", -1)} if pipeline else set())
    # both test drives drove clear: each robot is its new vertex
    for job in (a, b):
        td = job.step("test_drive")
        if td.state == "running":
            td.state = "done"
    dep.pushes.advance(a, 1.0)
    dep.pushes.advance(b, 1.0)
    assert {("move", 1), ("move", 0)} <= sent(a)
    assert a.step("enter").robot >= 0                  # a new robot asked for at the base
    if pipeline:
        # the drive placed b's new robot: deploy done, refine cancelled; nothing moved
        assert sent(b) == {("test_drive", -1), ("deploy", -1), ("refine", -1)}
    else:
        assert sent(b) == set()
    assert b.step("move", 0).robot == -1 and b.step("move", 1).state == "pending"
    # a's new robot reached the source: b's movers go (in parallel: from the front)
    ent = a.step("enter")
    ent.state = "done"
    dep.pushes.advance(b, 2.0)
    assert b.step("move", 0).robot == ent.robot
    if not pipeline:
        assert sent(b) == {("test_drive", -1)}     # the whole push started only now
        return
    assert {("move", 1), ("move", 0)} <= sent(b)


class _SettleTasks(_Tasks):
    def settle(self, rid, v, busy, holder):
        from swarmcover.bus.messages import Task
        return Task(kind="goto", vertex=v, landmarks=[1, 2], bearings=[0.0, 1.0])


@pytest.mark.parametrize("fed", [True, False])
def test_the_robot_a_fed_push_takes_is_not_settled(fed):
    """A robot that entered the source homing on one landmark settles once its push is over,
    unless the push fed by it takes that robot on: the agent runs one task at a time, and
    the settle, cut short by the fed push's move, was never reported and held the cycle for
    its whole timeout (hall300 seed 1 with pipelining: six of them, 50 s each)."""
    from swarmcover.coordinator.jobs import Step
    dep = Deployer(CoordinatorConfig(pipeline=True), sources=[0.0])
    dep.pushes.roster.live = lambda rid: True
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a if fed else None, enter=True)
    if not fed:
        b.steps_at_source().robot = 103
    for job in (a, b):
        job.steps.append(Step("refine", job.step("deploy").robot, 99, state="cancelled"))
    for st in a.steps:
        if st.state == "pending":
            st.state = "done"
    a.step("enter").robot, a.step("enter").n_landmarks = 7, 1
    dep.placement.vertex_of[7] = 0                 # robot 7 entered the source
    b.step("test_drive").state = "running"         # b is under way (pipelined)
    dep.jobs = [a, b]
    dep.pushes.tasks = _SettleTasks()
    dep.pushes.advance(a, 5.0)
    settle = a.step("settle", -1)
    if fed:
        assert settle is None                         # b moves robot 7 on: no settle
        assert b.source_robot() == 7
        # nor once b has moved it on: robot 7 is no longer at the source
        for name in ("test_drive", "deploy"):
            b.step(name).state = "done"
        dep.pushes.advance(b, 6.0)
        mv = b.step("move", 0)
        assert mv.robot == 7 and mv.state == "running"
        mv.state = "done"
        dep.pushes._step_done(b, mv)
        assert dep.placement.vertex_of[7] == 3
        dep.pushes.advance(a, 7.0)
        assert a.step("settle", -1) is None
    else:
        assert settle is not None and settle.robot == 7 and settle.state == "running"
        # a task for robot 7 (here a move of another push) ends that settle: the agent
        # drops it for the new task, and it would never report
        mv = Step("move", 7, 3, t_index=0)
        b.steps.append(mv)
        dep.pushes.start(mv, _Tasks().move([0, 3], 0, set(), None), 6.0)
        assert settle.state == "cancelled" and settle.reason == "superseded by move"
        assert a.finished


def test_the_complex_carries_the_mean_move_and_entry_as_the_agents_reported_them():
    """move_s / enter_s (summary.json's push floor) average the steps done, from each
    step's start to the simulated time of the Status that reports it; failed steps and
    other kinds do not count."""
    dep = Deployer(CoordinatorConfig(), sources=[0.0])
    job = _job([0, 1, 2])
    for s, t0 in zip(job.steps, (0.0, 0.0, 10.0, 12.0, 20.0)):
        s.state, s.started_t, s.task_id = "running", t0, 1
    dep.jobs = [job]
    mv1, mv0, ent = job.step("move", 1), job.step("move", 0), job.step("enter")
    ent.robot = 7
    done = dict(state="holding", task_id=1, task_state="done")
    dep.pushes.track(mv1.robot, Status(robot=mv1.robot, seq=1, t=13.0, **done))
    dep.pushes.track(mv0.robot, Status(robot=mv0.robot, seq=1, t=17.0, **done))
    dep.pushes.track(7, Status(robot=7, seq=1, t=21.5, **done))
    dep.pushes.track(job.step("test_drive").robot,
                     Status(robot=job.step("test_drive").robot, seq=1, t=30.0, state="holding",
                            task_id=1, task_state="failed", reason="touch"))
    assert dep.pushes.mean_done_s("move") == pytest.approx((3.0 + 5.0) / 2)
    assert dep.pushes.mean_done_s("enter") == pytest.approx(1.5)
    assert dep.pushes.mean_done_s("test_drive") == 0.0
    from swarmcover.coordinator.planner import CyclePlan
    dep.snapshot = dep.placement.snapshot(dep.roster, [0.0])
    cx = dep._complex_msg(CyclePlan(edges=[], triangles=[], frontier=[], obstacle=[],
                                    certified=False), 30.0, "running")
    assert cx.move_s == pytest.approx(4.0) and cx.enter_s == pytest.approx(1.5)


def test_a_vertex_a_push_is_done_with_is_a_landmark_held_by_the_robot_there_now():
    """A mover's landmarks: the robots holding its target's neighbour vertices now, but for
    vertices still in motion. Before, every vertex on a path of the cycle was left out, and
    with pushes streaming from the source the source's own neighbours were: robots entered
    it homing on one bearing (structured seed 0: 19 of 161 entries)."""
    from swarmcover.coordinator.planner import Snapshot
    dep = Deployer(CoordinatorConfig(pipeline=True), sources=[0.0])
    dep.pushes.roster.live = lambda rid: True
    # source 0 sees 1, 3 and 5; a (0 -> 1 -> 2) is over, b (0 -> 3 -> 4) is fed by it
    occ = {0: 100, 1: 101, 2: 102, 3: 103, 4: 104, 5: 105}
    nbrs = {0: {1: 0.0, 3: 1.0, 5: 2.0}, 1: {0: 3.0, 2: 0.0}, 3: {0: 4.0, 4: 0.0},
            5: {0: 5.0}, 2: {1: 3.0}, 4: {3: 4.0}}
    dep.pushes.snapshot = Snapshot(occupant=occ, nbrs=nbrs, sources=[0], source_dirs=[0.0])
    dep.placement.vertex_of.update({r: v for v, r in occ.items()})
    a = _job([0, 1, 2])
    b = _job([0, 3, 4], feed=a)
    for st in a.steps:
        st.state = "done"
    a.step("enter").robot = 7
    for st in a.steps:                              # as _step_done books them
        if st.name in ("deploy", "move", "enter"):
            dep.placement.vertex_of[st.robot] = st.target
    b.steps_at_source().robot = 7
    dep.jobs = [a, b]
    task = dep.pushes._task_move(b, -1, arrived=False)   # b's new robot entering 0
    # 1 is done with (held by robot 100, which moved there); 3 is b's, still to move
    assert sorted(zip(task.landmarks, task.bearings)) == [(100, 0.0), (105, 2.0)]
    # a move that failed leaves its robot somewhere near, not known where: not a landmark
    a.step("move", 0).state = "failed"
    task = dep.pushes._task_move(b, -1, arrived=False)
    assert list(zip(task.landmarks, task.bearings)) == [(105, 2.0)]


def _edges_kept_lost(complexes) -> tuple[int, int]:
    """Over consecutive published complexes: edges between two vertices of one that are
    (kept) or are not (lost) in the next while both vertices still are."""
    kept = lost = 0
    for a, b in zip(complexes, complexes[1:]):
        ea = {tuple(sorted(a.edges[i:i + 2])) for i in range(0, len(a.edges), 2)}
        eb = {tuple(sorted(b.edges[i:i + 2])) for i in range(0, len(b.edges), 2)}
        both = set(b.vertices)
        for e in ea:
            if e[0] in both and e[1] in both:
                kept, lost = kept + (e in eb), lost + (e not in eb)
    return kept, lost


@pytest.mark.timeout(240)
def test_a_pipelined_run_keeps_the_fixed_graph_and_the_certificate(monkeypatch):
    """Issue 19 item 4, a seeded in-process run (small map, seed 1) where pushes stream from
    the one source: fed pushes test-drove while the robot feeding them was still entering,
    the run certifies at ground truth, and the covered graph stays fixed: an edge between
    two vertices of one cycle's complex is in the next one's while both vertices are."""
    from swarmcover.coordinator import pushes
    early = []
    orig = pushes.Pushes.start

    def spy(self, s, task, now):
        if s.name == "test_drive":
            job = next(j for j in self.jobs if s in j.steps)
            first = job.steps_at_source()
            if job.feed is not None and first is not None and first.robot < 0:
                early.append(now)
        return orig(self, s, task, now)

    monkeypatch.setattr(pushes.Pushes, "start", spy)
    cfg = load_config("configs/small.toml")
    sim = SimLoop(cfg, seed=1, coordinator_overrides={"pipeline": True})
    res = sim.run(max_sim_s=4000, max_wall_s=200)
    assert res.certified, res.stop_reason
    assert _coverage(sim, res) >= 0.995
    assert len(early) >= 10, early          # measured: 34 test drives ran ahead of a feed (0 with
                                            # pipeline = false)
    kept, lost = _edges_kept_lost(res.complexes)
    # measured: 1 of 988 (seeds 0-2: 9 of 3,518; the barrier-per-push rule: 13 of 4,309)
    assert lost <= 0.01 * (kept + lost), (lost, kept)


def test_the_contact_a_failed_test_drive_reports_is_never_taken_for_a_wall_at_the_vertex():
    """The agent comes back from a test drive that touched with the contact still reported
    (pinned). The first status saying so used to be adopted as a resting contact before the
    job heard of the failure, and its 90-deg cone then closed a door (corridor_doors)."""
    from swarmcover.bus.messages import Task

    dep = Deployer(CoordinatorConfig(), sources=[0.0])
    rid, v = 5, 12
    dep.vertex_of[rid] = v
    job = _job([v], occ={v: rid})
    dep.jobs.append(job)
    td = job.step("test_drive")
    dep.pushes.start(td, Task(kind="test_drive", vertex=v, direction=1.8, distance=0.9), 0.0)
    seq = iter(range(1, 100))

    def status(task_id, task_state, bearing):
        dep.on_status(Status(robot=rid, seq=next(seq), t=float(next(seq)), state="holding",
                             vertex=v, task_id=task_id, task_state=task_state, reason="touch",
                             contact=True, contact_bearing=bearing))

    status(td.task_id, "failed", math.pi / 2)
    assert v not in dep.contact
    assert dep.td_contacts[v] == [pytest.approx(math.pi / 2)]
    status(td.task_id + 1, "done", math.pi / 2)   # a later hold, contact still pinned
    assert v not in dep.contact
    status(td.task_id + 2, "done", -math.pi / 2)  # a wall the robot does rest against
    assert dep.contact[v] == pytest.approx(-math.pi / 2)


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_one_touch_at_the_front_no_longer_cancels_the_other_pushes_from_the_source(monkeypatch):
    from swarmcover.coordinator.jobs import PushJob
    cancelled = []
    cfg = load_config("configs/small.toml")
    sim = SimLoop(cfg, seed=0)
    orig = PushJob.cancel

    def spy(job, why):
        cancelled.append(why)
        return orig(job, why)

    monkeypatch.setattr(PushJob, "cancel", spy)
    res = sim.run(max_sim_s=4000, max_wall_s=200)
    assert res.certified, res.stop_reason
    assert "test drive touched an obstacle" in cancelled
    # before, 23 of 61 cancelled pushes here were "source feed failed" (52 cycles, 33 robots)
    assert "source feed failed" not in cancelled
    assert res.cycles < 45


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_push_whose_test_drive_touched_is_replanned_within_its_cycle():
    """Spec 3.4(iv): on a touch, the next-best frontier at once. Before, the push was
    cancelled and its robot waited for the next cycle (small map, seed 0: 35 robots in 37
    cycles; with the retry 33 in 22, and 34 in 23 with the reflex second probe)."""
    cfg = load_config("configs/small.toml")
    out = {}
    for retries in (0, 2):
        sim = SimLoop(cfg, seed=0, coordinator_overrides={"td_retries": retries})
        res = sim.run(max_sim_s=4000, max_wall_s=200)
        assert res.certified, res.stop_reason
        assert _coverage(sim, res) >= 0.995
        out[retries] = (res.cycles, res.deployer.retried)
    assert out[0][1] == 0 and out[2][1] > 0, out
    assert out[2][0] < 0.8 * out[0][0], out


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_corridor_doors_seed_1_never_certifies_a_room_it_did_not_cover():
    """The run that certified 85.3% coverage with pipelined pushes (the room right of the
    corridor never entered; its door's side closed by 'probe_clear' after the sweep's robot
    in the doorway was gone): certified must mean covered."""
    cfg = load_config("configs/corridor_doors.toml")
    sim = SimLoop(cfg, seed=1, coordinator_overrides={"pipeline": True})
    res = sim.run(max_sim_s=20000, max_wall_s=500)
    assert res.certified, res.stop_reason
    assert _coverage(sim, res) >= 0.995


def test_robots_cut_off_stay_members_for_stray_cycles_plans_then_are_sent_away():
    """A stalled move at a door cut 14 robots off from the source (bench/unseen.py seed 0
    map 8); sent away at once, they stood in the room the complex no longer held. Cut-off
    robots stay members for ``stray_cycles`` plans in a row (the hole that cut them off is
    refilled meanwhile), nothing is certified while they wait, and only then are they sent
    away, booked as cut off (fence sides their bodies stopped sweeps at never close by
    inference: tests/test_sweep.py). A robot linked again starts its count afresh."""
    from test_free_probes import _deployer
    from swarmcover.coordinator.planner import Snapshot
    s = 0.9
    P = [(0.0, 0.0), (s, 0.0), (s / 2, s * math.sqrt(3) / 2), (5.0, 5.0)]
    nbrs = {i: {j: math.atan2(q[1] - p[1], q[0] - p[0]) for j, q in enumerate(P)
                if j != i and math.dist(p, q) <= 1.0} for i, p in enumerate(P)}
    snap = Snapshot(occupant={0: 10, 1: 11, 2: 12, 3: 42}, nbrs=nbrs, sources=[0])
    dep, _ = _deployer(snap, CoordinatorConfig(stray_cycles=3))
    dep.phase_t = 0.0

    def leaves():
        return [a.robot for a in dep.out.actions
                if getattr(a, "task", None) is not None and a.task.kind == "leave"]
    for k in range(1, 3):
        dep.out.actions = []
        dep._plan(float(k))
        assert leaves() == [] and 42 in dep.snapshot.occupant.values()
        assert dep.stray_plans == {42: k} and not dep.plan.certified
    dep.out.actions = []
    dep._plan(3.0)
    assert leaves() == [42] and dep.placement.cut_off == {42} and 42 in dep.left
    assert 42 not in dep.snapshot.occupant.values() and dep.stray_plans == {}
    # a robot of the swarm comes into its sight, and it into that robot's: it links again,
    # holding a vertex of its own where it stands
    from swarmcover.bus.messages import Status
    import dataclasses
    r12, r42 = dep.robots[12], dep.robots[42]
    r12.status = dataclasses.replace(r12.status, nbr_ids=[*r12.status.nbr_ids, 42],
                                     nbr_bearings=[*r12.status.nbr_bearings, 1.0])
    r42.status = Status(robot=42, seq=99, t=4.0, state="idle", vertex=-1, nbr_ids=[12],
                        nbr_bearings=[-2.0])
    dep.out.actions = []
    dep._plan(4.0)
    holds = [(a.robot, a.task.vertex) for a in dep.out.actions
             if getattr(a, "task", None) is not None and a.task.kind == "hold"]
    assert [r for r, _ in holds] == [42] and holds[0][1] not in (0, 1, 2, 3)
    assert not dep.placement.cut_off and 42 not in dep.left
    assert dep.snapshot.occupant[holds[0][1]] == 42 and not dep.stray_plans


def test_the_robot_refilling_a_door_vertex_homes_on_the_robot_placed_beyond_it():
    """bench/unseen.py seed 0 map 8: vertex 2 stood in a door, seen only from vertex 1. Its
    robot drove clear through the door (the new vertex); the robot moving 1 -> 2 had no
    landmark of vertex 2 left (its own vertex is the only neighbour) and was booked at 2
    without moving, and the robot beyond the door was cut off. The robot the test drive
    placed straight out from f is f's landmark at the drive's direction."""
    from test_free_probes import _deployer
    from swarmcover.coordinator.planner import Snapshot
    from swarmcover.coordinator.tasks import TaskBuilder
    nbrs = {0: {1: 0.0}, 1: {0: math.pi, 2: 0.3}, 2: {1: 0.3 - math.pi}}
    snap = Snapshot(occupant={0: 10, 1: 11, 2: 12}, nbrs=nbrs, sources=[0])
    dep, _ = _deployer(snap)
    tb = TaskBuilder(dep.cfg, dep.params, dep.roster, snap)
    assert tb.move([1, 2], 0, {1, 2}, None) is None
    task = tb.move([1, 2], 0, {1, 2}, None, beyond=(12, -0.1))
    assert task.kind == "goto" and task.vertex == 2
    assert task.landmarks == [12] and task.bearings == [pytest.approx(-0.1)]
    # with a landmark of its own the mover creeps along the edge and homes on it, then
    # settles on all of them once the push is over (the robot beyond joining cost robots)
    nbrs2 = {0: {1: 0.0, 2: 0.5, 3: 1.0}, 1: {0: math.pi, 2: 0.3},
             2: {1: 0.3 - math.pi, 0: 0.5 - math.pi, 3: 2.0}, 3: {0: 1.0 - math.pi, 2: -1.0}}
    for occ, want in (({0: 10, 1: 11, 2: 12}, [10]), ({0: 10, 1: 11, 2: 12, 3: 14}, [10, 14])):
        dep2, _ = _deployer(Snapshot(occupant=occ, nbrs={v: {u: b for u, b in nbrs2[v].items()
                                                          if u in occ} for v in occ},
                                     sources=[0]))
        tb2 = TaskBuilder(dep2.cfg, dep2.params, dep2.roster, dep2.snapshot)
        assert tb2.move([1, 2], 0, {1}, None, beyond=(13, -0.1)).landmarks == want


@pytest.mark.parametrize("sees, triangle", [({42: [43, 44], 43: [42, 44], 44: [42, 43]}, True),
                                            ({42: [43, 44], 43: [42], 44: [42]}, False),
                                            ({42: [43, 44], 43: [42, 44], 44: [42]}, False)])
def test_three_cut_off_robots_that_see_one_another_block_the_certificate(sees, triangle):
    """bench/unseen.py seed 7 map 17: all 24 robots of the room behind a 0.30 rv door were
    cut off at once and sent away, and the room was certified with the complex covering
    59% of the map. Robots cut off from every source that see one another (three of them,
    each pair both ways) stand in free space the complex does not reach: no certificate
    while they do (Deployer, via Placement.cut_off_triangle). One-way sightings, or a pair,
    are no such part."""
    from swarmcover.bus.messages import Status
    from swarmcover.coordinator.placement import Placement
    from swarmcover.coordinator.roster import Roster
    roster = Roster()
    for rid, ids in sees.items():
        roster.admit(Status(robot=rid, seq=1, t=1.0, state="idle", vertex=-1, nbr_ids=ids,
                            nbr_bearings=[0.0] * len(ids)), cycle=1)
    pl = Placement(1)
    pl.cut_off = set(sees)
    assert (pl.cut_off_triangle(roster) == (42, 43, 44)) is triangle
    if triangle:
        roster.get(44).dead = True          # a dead robot is no part of anything
        assert pl.cut_off_triangle(roster) is None

"""The coordinator's deployment cycles, driven in one process (swarmcover.simloop) with the
real physics, sensors, agent behaviours and deployer: certification must mean coverage."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bus.messages import Status
from coordinator.config import CoordinatorConfig
from coordinator.deployer import Deployer
from swarmcover.simloop import SimLoop
from world.config import load_config
from world.groundtruth import coverage_fraction


def _coverage(sim, res) -> float:
    alive = [r for r in res.positions if r in sim.agents]
    P = np.array([res.positions[r] for r in alive]).reshape(-1, 2)
    return coverage_fraction(sim.wm, P, sim.cfg.rv)


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match=r"\[coordinator\] unknown field 'push_mod'"):
        CoordinatorConfig.from_section({"push_mod": "parallel"}, rv=1.0, where="x.toml")
    with pytest.raises(ValueError, match=r"push_mode = 'fast'"):
        CoordinatorConfig.from_section({"push_mode": "fast"}, rv=1.0)
    with pytest.raises(ValueError, match=r"max_paths = '2': expected int"):
        CoordinatorConfig.from_section({"max_paths": "2"}, rv=1.0)
    assert CoordinatorConfig.from_section({"task_timeout_s": 30}, rv=2.0).d0 == pytest.approx(1.8)


def test_first_cycle_spawns_then_holds_then_deploys_the_lone_robot():
    dep = Deployer(CoordinatorConfig(), sources=[0.5])
    acts = dep.step(0.0) + dep.step(1.5)
    spawns = [a[1] for a in acts if a[0] == "spawn"]
    assert [s.robot for s in spawns] == [0] and spawns[0].source == 0
    dep.on_alive(0, True, 1.5)
    dep.on_status(Status(robot=0, seq=1, t=1.6, state="idle"))
    acts = dep.step(1.6)
    (task,) = [a[2] for a in acts if a[0] == "task"]
    assert task.kind == "hold" and task.vertex == 0 and task.robot == 0
    dep.on_status(Status(robot=0, seq=2, t=2.0, state="holding", vertex=0,
                         task_id=task.task_id, task_state="done"))
    acts = dep.step(2.0) + dep.step(3.0) + dep.step(3.1)
    cx = [a[1] for a in acts if a[0] == "complex"]
    assert cx and cx[0].vertices == [0] and not cx[0].certified
    td = [a[2] for a in acts if a[0] == "task"]
    # a lone robot is frontier: it test-drives along the base heading first
    assert td and td[0].kind == "test_drive" and td[0].direction == pytest.approx(0.5)


@pytest.mark.timeout(240)
def test_small_map_is_certified_and_certified_means_covered():
    cfg = load_config("configs/small.toml")
    sim = SimLoop(cfg)
    res = sim.run(max_sim_s=1500, max_wall_s=180)
    assert res.certified, res.stop_reason
    cx = res.final
    assert cx.certified and cx.state == "certified" and not cx.frontier
    assert _coverage(sim, res) >= 0.99
    # every vertex of the final complex is held by a live robot, and the complex is the
    # one the robots see now: each edge's robots are within rv of each other
    occ = dict(zip(cx.vertices, cx.occupants))
    assert all(o in sim.agents for o in occ.values())
    for a, b in zip(cx.edges[0::2], cx.edges[1::2]):
        pa, pb = res.positions[occ[a]], res.positions[occ[b]]
        assert math.dist(pa, pb) <= cfg.rv + 1e-6
    assert res.cycles < res.robots_spawned * 2


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
            for rid, beh in sim.agents.items():
                sim.dep.on_alive(rid, True, sim.t)
                sim.seq[rid] += 1
                sim.dep.on_status(Status(robot=rid, seq=sim.seq[rid], t=sim.t, **beh.status()))

    out = sim.run(max_sim_s=1500, max_wall_s=180, on_cycle=swap)
    assert res["swapped"] >= 4
    assert out.certified, out.stop_reason
    assert out.deployer.epoch == 2
    assert _coverage(sim, out) >= 0.99

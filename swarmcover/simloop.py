"""The whole swarm in one process, in lockstep, without Zenoh: for algorithm tests and tuning.

It is the distributed system over an in-memory transport: the same cores the processes run,
:class:`world.core.WorldCore` (pymunk physics, emulated sensors, the lockstep roster),
one :class:`agents.core.AgentCore` per robot and :class:`coordinator.core.CoordinatorCore`
(the Deployer behind the barrier), exchanging the same messages (Clock, Sense, Status,
CoordAck, Task) by reference instead of over Zenoh. What the processes add is transport
alone: serialisation, re-sends, timeouts, liveliness tokens.

Tick order: that of distributed lockstep with the coordinator in the barrier (world/node.py,
coordinator/node.py), so both give the same run for a config and seed. At the boundary of
tick k (sim time t_k): the spawns and removes of the coordinator's ack of k-1 are applied (a
spawned body's agent starts, and joins ``join_ticks`` later); the world's roster takes the
deaths and the agents that answered their first tick; the Clock of tick k (the roster, each
agent's announced status seq) goes to the coordinator core, which hands the deployer those
statuses and steps it at t_k; its ack is recorded (the tasks go to their robots' next Sense);
every agent with a body (a joiner from its join tick, when it first publishes its start-up
Status) applies its tasks, steps on Sense(k), publishes its Status every ``status_every`` of
its own ticks or on a change, and answers with the seq of its last Status; then physics
steps dt.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from swarmcover.bus.messages import Complex, Spawn
from swarmcover.coordinator.actions import (Done, PublishComplex, RemoveRobot, RequestStatus,
                                            SendTask, SpawnRobot)

log = logging.getLogger("swarmcover.simloop")


@dataclass
class SimResult:
    certified: bool
    cycles: int
    sim_time_s: float
    wall_time_s: float
    robots_spawned: int
    complexes: list = field(default_factory=list)
    positions: dict = field(default_factory=dict)   # robot id -> (x, y) at the end
    final: Complex | None = None
    stop_reason: str = ""
    deployer: object = None


class SimLoop:
    """Lockstep simulation of world + agents + coordinator for one run config."""

    def __init__(self, cfg, *, seed: int | None = None, coordinator_overrides: dict | None = None,
                 status_every: int | None = None):
        from swarmcover.agents.core import AgentCore
        from swarmcover.agents.params import from_config
        from swarmcover.coordinator.config import CoordinatorConfig
        from swarmcover.coordinator.core import CoordinatorCore, robot_kinds_from_config
        from swarmcover.coordinator.deployer import Deployer
        from swarmcover.world.config import to_dict
        from swarmcover.world.core import WorldCore
        from swarmcover.world.maps import build_map

        self.cfg = cfg
        self.wm = build_map(cfg)
        self.world = WorldCore(cfg, self.wm, seed=seed)
        self.physics = self.world.physics
        self.dt = cfg.world.dt
        # the agent processes read the resolved config's text (run --run-config), which is
        # this dict as TOML (tests/test_agent_params.py checks the two agree on every config)
        self.agent_params = from_config(to_dict(cfg), str(cfg.path))
        self._AgentCore = AgentCore
        section = dict(cfg.section("coordinator"))
        section.update(coordinator_overrides or {})
        self.ccfg = CoordinatorConfig.from_section(section, rv=cfg.rv, where=cfg.path)
        headings = [float(s[2]) for s in self.wm.sources] or [0.0]
        self._CoordinatorCore = CoordinatorCore
        self.coord = CoordinatorCore(Deployer(self.ccfg, sources=headings, epoch=1,
                                              robot_kind=robot_kinds_from_config(cfg),
                                              robot_radius=cfg.robots.radius))
        self.agents: dict = {}                 # rid -> AgentCore (its agent runs)
        self.status_every = status_every
        self.complexes: list[Complex] = []
        self.spawned = 0
        self._tasks: dict[int, list] = {}      # decided up to k-1, applied at Sense(k)
        self._ops: list = []                   # the spawns/removes of the ack of k-1
        self.done_t: float | None = None

    @property
    def dep(self):
        """The coordinator's Deployer. Setting one is a coordinator restart: a new core
        (with nothing buffered) around it, as a new process would start."""
        return self.coord.dep

    @dep.setter
    def dep(self, dep) -> None:
        self.coord = self._CoordinatorCore(dep)

    @property
    def tick(self) -> int:
        return self.world.tick

    @property
    def t(self) -> float:
        return self.world.t

    # ------------------------------------------------------------------ actions
    def _apply(self, actions) -> tuple[bool, dict]:
        """The deployer's actions of one boundary -> (done, tasks by robot); its spawns and
        removes reach the world through the ack, as over Zenoh."""
        done = False
        tasks: dict[int, list] = {}
        for a in actions:
            match a:
                case SendTask(robot=rid, task=task):
                    tasks.setdefault(rid, []).append(task)
                case SpawnRobot() | RemoveRobot() | RequestStatus():
                    pass   # through the ack, as over Zenoh
                case PublishComplex(complex=cx):
                    self.complexes.append(cx)
                case Done():
                    done = True
                case _:
                    raise TypeError(f"unknown deployer action {a!r}")
        return done, tasks

    def _apply_ops(self) -> None:
        """The ack's spawns and removes, in its order (world/node.py's acked ops)."""
        from swarmcover.world.core import SpawnRefused
        w = self.world
        ops, self._ops = self._ops, []
        for m in ops:
            if isinstance(m, Spawn):
                try:
                    w.add(m.robot, m.source, m.kind, m.live)
                except SpawnRefused:
                    continue
                w.join_later(m.robot)
                p = dataclasses.replace(self.agent_params, kind=m.kind)
                self.agents[m.robot] = self._AgentCore(p, m.robot, status_every=self.status_every,
                                                       log=log)
                w.alive(m.robot, True)           # its agent process declares its token
                self.spawned += 1
            elif w.remove(m.robot):
                self.agents.pop(m.robot, None)
                self._tasks.pop(m.robot, None)

    def kill(self, rid: int) -> None:
        """A robot fails: its agent stops and its liveliness token goes, which the world
        reports at the next boundary (the body stays until the coordinator removes it, as
        in the distributed system)."""
        self.agents.pop(rid, None)
        self.world.alive(rid, False)

    # ------------------------------------------------------------------ loop
    def _boundary(self) -> tuple[bool, dict]:
        """Tick k's boundary: the world's roster and Clock, then the coordinator's step."""
        w = self.world
        self._apply_ops()
        ids = w.physics.ids
        w.boundary([False] * len(ids), list(ids))
        actions, ack = self.coord.boundary(w.clock("lockstep", 0.0))
        done, tasks = self._apply(actions)
        self._ops = w.on_ack(ack)
        if self.dep.done and not done:
            self.dep.reopen_if_needed(w.t)
        return done, tasks

    def step(self) -> bool:
        done, tasks = self._boundary()
        w = self.world
        ids, pos, th = w.physics.state()
        cmds = np.zeros((len(ids), 3))
        if ids and w.sense_due():
            row = {rid: k for k, rid in enumerate(ids)}
            senses = w.senses(ids, pos, th, barrier=True)
            expected = w.expected()        # among the robots sensed this tick
            sync = self.coord.sync
            for sense in senses:
                rid = sense.robot
                core = self.agents.get(rid)
                if core is None:
                    continue
                if rid in w.joins:   # its first tick: the agent's start-up status
                    sync.add_status(core.status())
                for task in self._tasks.pop(rid, ()):
                    core.beh.on_task(task)
                c, st = core.step(sense)
                if c is not None:
                    cmds[row[rid]] = (c.vx, c.vy, c.wz)
                if st is not None:
                    sync.add_status(st)
                if rid in expected:
                    w.answered(rid, core.seq, core.idle)
                    if rid in w.joins:
                        w.joined.add(rid)
        for rid, ts in tasks.items():   # the coordinator's tasks of this tick: next Sense
            if rid in self.agents:
                self._tasks.setdefault(rid, []).extend(ts)
        if done:
            self.done_t = w.t
        w.step(cmds)
        return done

    def run(self, max_sim_s: float = 3600.0, max_wall_s: float = 600.0,
            on_cycle=None, kill_at: dict | None = None) -> SimResult:
        """Run until certified/stopped or a limit. ``kill_at``: {cycle: [robot ids]}."""
        t0 = time.monotonic()
        seen_cycles = 0
        kill_at = dict(kill_at or {})
        reason = ""
        while True:
            if self.step():
                break
            if len(self.complexes) > seen_cycles:
                seen_cycles = len(self.complexes)
                cx = self.complexes[-1]
                if on_cycle is not None:
                    on_cycle(self, cx)
                for c in [c for c in kill_at if c <= cx.cycle]:
                    for rid in kill_at.pop(c):
                        if rid in self.agents:
                            self.kill(rid)
            if self.t >= max_sim_s:
                reason = f"max_sim_s {max_sim_s}"
                break
            if time.monotonic() - t0 >= max_wall_s:
                reason = f"max_wall_s {max_wall_s}"
                break
        ids, pos, _ = self.physics.state()
        # sim time: when the coordinator decided (the distributed summary's sim_time_s)
        t_end = self.done_t if self.done_t is not None else self.t
        return SimResult(certified=self.dep.certified, cycles=self.dep.cycle, sim_time_s=t_end,
                         wall_time_s=time.monotonic() - t0, robots_spawned=self.spawned,
                         complexes=self.complexes,
                         positions={r: tuple(p) for r, p in zip(ids, pos)},
                         final=self.complexes[-1] if self.complexes else None,
                         stop_reason=self.dep.stop_reason or reason, deployer=self.dep)

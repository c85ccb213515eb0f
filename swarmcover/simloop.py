"""The whole swarm in one process, in lockstep, without Zenoh: for algorithm tests and tuning.

It wires the real parts together as the processes do, minus the transport: the world's
pymunk physics and emulated sensors (world.physics, world.sensing), one agent
:class:`agents.behaviours.Behaviour` per robot, and the coordinator's
:class:`coordinator.deployer.Deployer`. Messages are the same dataclasses (Sense, Task,
Status, Spawn, Remove, Complex), passed by reference.

Tick order: the same as distributed lockstep with the coordinator in the barrier (see
world/node.py and coordinator/node.py), so both give the same run for a config and seed. At
the boundary of tick k (sim time t_k): the spawns and removes the coordinator decided at
k-1 are applied (a spawned body's agent joins ``join_ticks`` later); the roster changes
(deaths, agents that answered their first tick) and the statuses the agents published while
answering tick k-1 go to the deployer (left, joined, then statuses by (robot, seq)), which
steps at t_k; every agent in the roster (or joining now: it first publishes its start-up
Status) applies the tasks decided up to k-1, steps on Sense(k), and publishes its Status
every ``status_every`` of its own ticks or on a change; then physics steps dt.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from bus.messages import Complex, Sense, Status
from coordinator.actions import Done, PublishComplex, RemoveRobot, SendTask, SpawnRobot

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
        from agents.core import AgentCore
        from agents.params import from_config
        from coordinator.config import CoordinatorConfig
        from coordinator.deployer import Deployer
        from coordinator.node import robot_kinds_from_config
        from world.config import to_dict
        from world.maps import build_map
        from world.node import join_ticks
        from world.physics import Physics
        from world.sensing import Sensors

        self.cfg = cfg
        self.wm = build_map(cfg)
        w = cfg.world
        self.dt = w.dt
        self.rng = np.random.default_rng(w.seed if seed is None else seed)
        self.physics = Physics(self.wm, radius=cfg.robots.radius, v_max=cfg.robots.v_max,
                               w_max=cfg.robots.w_max, dt=w.dt, substeps=w.substeps,
                               actuation_noise=cfg.robots.actuation_noise, rng=self.rng)
        sc = cfg.sensing
        self.sensors = Sensors(self.wm, cfg.rv, radius=cfg.robots.radius,
                               noise_sigma=math.radians(sc.noise_deg), dropout=sc.dropout,
                               robots_occlude=sc.robots_occlude, n_touch=sc.n_touch,
                               skin=sc.touch_skin, rng=self.rng)
        self.sense_every = max(1, round(1.0 / (sc.rate_hz * w.dt)))
        # the agent processes read the resolved config's text (run --run-config), which is
        # this dict as TOML (tests/test_agent_params.py checks the two agree on every config)
        self.agent_params = from_config(to_dict(cfg), str(cfg.path))
        self._AgentCore = AgentCore
        section = dict(cfg.section("coordinator"))
        section.update(coordinator_overrides or {})
        self.ccfg = CoordinatorConfig.from_section(section, rv=cfg.rv, where=cfg.path)
        headings = [float(s[2]) for s in self.wm.sources] or [0.0]
        self.dep = Deployer(self.ccfg, sources=headings, epoch=1,
                            robot_kind=robot_kinds_from_config(cfg),
                            robot_radius=cfg.robots.radius)
        self.join_ticks = join_ticks(self.dt)
        self.agents: dict = {}                 # rid -> AgentCore (its agent runs)
        self.status_every = status_every
        self.tick = 0
        self.t = 0.0
        self.complexes: list[Complex] = []
        self.spawned = 0
        self.roster: set[int] = set()          # agents taking part (the world's Clock)
        self._coord_roster: set[int] = set()   # the roster the deployer last saw
        self.joins: dict[int, int] = {}        # rid -> tick its agent joins
        self._joined: set[int] = set()
        self._gone: set[int] = set()
        self._statuses: list[Status] = []      # published at tick k-1, for boundary k
        self._tasks: dict[int, list] = {}      # decided up to k-1, applied at Sense(k)
        self._ops: list = []                   # spawns/removes decided at k-1
        self.done_t: float | None = None

    # ------------------------------------------------------------------ actions
    def _apply(self, actions) -> tuple[bool, dict, list]:
        """The deployer's actions of one boundary -> (done, tasks by robot, spawn/remove)."""
        done = False
        tasks: dict[int, list] = {}
        ops: list = []
        for a in actions:
            match a:
                case SendTask(robot=rid, task=task):
                    tasks.setdefault(rid, []).append(task)
                case SpawnRobot() | RemoveRobot():
                    ops.append(a)
                case PublishComplex(complex=cx):
                    self.complexes.append(cx)
                case Done():
                    done = True
                case _:
                    raise TypeError(f"unknown deployer action {a!r}")
        return done, tasks, ops

    def _apply_ops(self) -> None:
        ops, self._ops = self._ops, []
        for op in ops:
            if isinstance(op, SpawnRobot):
                m = op.spawn
                if self.physics.has(m.robot):
                    continue
                x, y, th = self.wm.sources[m.source]
                self.physics.add(m.robot, x, y, th, m.kind, False)
                p = dataclasses.replace(self.agent_params, kind=m.kind)
                self.agents[m.robot] = self._AgentCore(p, m.robot, status_every=self.status_every,
                                                       log=log)
                self.joins[m.robot] = self.tick + self.join_ticks
                self.spawned += 1
            else:
                m = op.remove
                if self.physics.remove(m.robot):
                    self.agents.pop(m.robot, None)
                    self.roster.discard(m.robot)
                    self.joins.pop(m.robot, None)
                    self._tasks.pop(m.robot, None)

    def kill(self, rid: int) -> None:
        """A robot fails: its agent stops and its liveliness token goes, which the world
        reports at the next boundary (the body stays until the coordinator removes it, as
        in the distributed system)."""
        self.agents.pop(rid, None)
        self._gone.add(rid)

    # ------------------------------------------------------------------ loop
    def _boundary(self) -> bool:
        """Tick k's boundary: the world's roster, then the coordinator's step."""
        self._apply_ops()
        for rid in self._gone:
            self.roster.discard(rid)
            self.joins.pop(rid, None)
        self._gone = set()
        for rid in sorted(self._joined):
            if self.joins.pop(rid, None) is not None:
                self.roster.add(rid)
        self._joined = set()
        self.roster &= set(self.physics.ids)
        dep = self.dep
        for rid in sorted(self._coord_roster - self.roster):
            dep.on_alive(rid, False, self.t)
        for rid in sorted(self.roster - self._coord_roster):
            dep.on_alive(rid, True, self.t)
        self._coord_roster = set(self.roster)
        statuses, self._statuses = self._statuses, []
        for st in sorted(statuses, key=lambda st: (st.robot, st.seq)):
            if st.robot in self.roster:
                dep.on_status(st)
        done, tasks, self._ops = self._apply(dep.step(self.t))
        if dep.done and not done:
            dep.reopen_if_needed(self.t)
        return done, tasks

    def step(self) -> bool:
        done, tasks = self._boundary()
        ids, pos, th = self.physics.state()
        cmds = np.zeros((len(ids), 3))
        if ids and self.tick % self.sense_every == 0:
            per = self.sensors.sense(pos, th).lists(ids)
            for k, rid in enumerate(ids):
                core = self.agents.get(rid)
                joining = self.joins.get(rid, 1 << 62) <= self.tick
                if core is None or (rid not in self.roster and not joining):
                    continue
                if rid in self.joins:   # its first tick: the agent's start-up status
                    self._statuses.append(core.status())
                    self._joined.add(rid)
                for task in self._tasks.pop(rid, ()):
                    core.beh.on_task(task)
                s = Sense(robot=rid, tick=self.tick, t=self.t, **per[k])
                c, st = core.step(s)
                if c is not None:
                    cmds[k] = (c.vx, c.vy, c.wz)
                if st is not None:
                    self._statuses.append(st)
        for rid, ts in tasks.items():   # the coordinator's tasks of this tick: next Sense
            if rid in self.agents:
                self._tasks.setdefault(rid, []).extend(ts)
        if done:
            self.done_t = self.t
        self.physics.step(cmds)
        self.tick += 1
        self.t = self.tick * self.dt
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

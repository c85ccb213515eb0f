"""The whole swarm in one process, in lockstep, without Zenoh: for algorithm tests and tuning.

It wires the real parts together exactly as the processes do, minus the transport: the
world's pymunk physics and emulated sensors (world.physics, world.sensing), one agent
:class:`agents.behaviours.Behaviour` per robot, and the coordinator's
:class:`coordinator.deployer.Deployer`. Messages are the same dataclasses (Sense, Task,
Status, Spawn, Remove, Complex), passed by reference. The distributed system is tested
separately end to end; this loop makes the algorithm's behaviour on many maps cheap to
check (seconds instead of minutes) and deterministic for a seed.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
import tomllib
from dataclasses import dataclass, field

import numpy as np

from bus.messages import Complex, Sense, Status

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
                 status_every: int = 4):
        from agents.behaviours import Behaviour
        from agents.params import from_config as agent_params
        from coordinator.config import CoordinatorConfig
        from coordinator.deployer import Deployer
        from coordinator.node import robot_kinds_from_config
        from world.config import to_toml
        from world.maps import build_map
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
        raw = tomllib.loads(to_toml(cfg))
        self.agent_params = agent_params(raw, source=cfg.path)
        self._Behaviour = Behaviour
        section = dict(cfg.section("coordinator"))
        section.update(coordinator_overrides or {})
        self.ccfg = CoordinatorConfig.from_section(section, rv=cfg.rv, where=cfg.path)
        headings = [float(s[2]) for s in self.wm.sources] or [0.0]
        self.dep = Deployer(self.ccfg, sources=headings, epoch=1,
                            robot_kind=robot_kinds_from_config(cfg),
                            robot_radius=cfg.robots.radius)
        self.agents: dict = {}
        self.seq: dict[int, int] = {}
        self.status_every = status_every
        self.tick = 0
        self.t = 0.0
        self.complexes: list[Complex] = []
        self.spawned = 0

    # ------------------------------------------------------------------ actions
    def _apply(self, actions) -> bool:
        done = False
        for a in actions:
            kind = a[0]
            if kind == "task":
                beh = self.agents.get(a[1])
                if beh is not None:
                    beh.on_task(a[2])
            elif kind == "spawn":
                sp = a[1]
                x, y, th = self.wm.sources[sp.source]
                self.physics.add(sp.robot, x, y, th, sp.kind, False)
                p = dataclasses.replace(self.agent_params, kind=sp.kind)
                self.agents[sp.robot] = self._Behaviour(p, sp.robot)
                self.seq[sp.robot] = 0
                self.spawned += 1
                self.dep.on_alive(sp.robot, True, self.t)
            elif kind == "remove":
                rid = a[1].robot
                self.physics.remove(rid)
                self.agents.pop(rid, None)
            elif kind == "complex":
                self.complexes.append(a[1])
            elif kind == "done":
                done = True
        return done

    def kill(self, rid: int) -> None:
        """A robot fails: its agent stops, its liveliness token goes (the body stays until
        the coordinator removes it, as in the distributed system)."""
        self.agents.pop(rid, None)
        self.dep.on_alive(rid, False, self.t)

    # ------------------------------------------------------------------ loop
    def step(self) -> bool:
        done = self._apply(self.dep.step(self.t))
        ids, pos, th = self.physics.state()
        cmds = np.zeros((len(ids), 3))
        if ids:
            b = self.sensors.sense(pos, th)
            ida = np.asarray(ids, np.int64)
            for k, rid in enumerate(ids):
                beh = self.agents.get(rid)
                if beh is None:
                    continue
                r = b.robot(k)
                s = Sense(robot=rid, tick=self.tick, t=self.t, ids=ida[r["tgt"]].tolist(),
                          bearings=r["bearings"].tolist(), back_bearings=r["back"].tolist(),
                          touch=r["touch"].tolist(), touch_robot=r["touch_robot"].tolist())
                c = beh.step(s)
                cmds[k] = (c.vx, c.vy, c.wz)
                if beh.changed or self.tick % self.status_every == 0:
                    beh.changed = False
                    self.seq[rid] += 1
                    st = Status(robot=rid, seq=self.seq[rid], t=self.t, kind=beh.p.kind,
                                **beh.status())
                    self.dep.on_status(st)
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
        return SimResult(certified=self.dep.certified, cycles=self.dep.cycle, sim_time_s=self.t,
                         wall_time_s=time.monotonic() - t0, robots_spawned=self.spawned,
                         complexes=self.complexes,
                         positions={r: tuple(p) for r, p in zip(ids, pos)},
                         final=self.complexes[-1] if self.complexes else None,
                         stop_reason=self.dep.stop_reason or reason, deployer=self.dep)

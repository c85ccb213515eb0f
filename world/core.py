"""The world without its transport: what the world process (world/node.py) and the
in-process loop (swarmcover/simloop.py) both run, so the two cannot drift apart.

:class:`WorldCore` owns the physics and the emulated sensors, the tick, and the lockstep
roster: which agents take part in a tick (and so appear in its Clock), when a body the
coordinator spawned gets its agent's first Sense, the status seq each agent's last command
announced, and the last task the coordinator announced per robot. No I/O, no wall clock:
the node feeds it what arrived (liveliness, commands' status seqs, the coordinator's acks)
and sends what it returns (Clock, Sense).

Per tick k of lockstep, the order both callers follow: ``apply`` the spawns and removes of
the coordinator's ack of k-1 (``ack_ops``), ``boundary`` (deaths, joins, agents that
appeared), ``clock`` and ``senses`` for tick k, the agents' answers (``answered``) and the
coordinator's ack (``on_ack``), then ``step`` with the commands.

With the coordinator in the barrier, ``senses`` leaves out idle robots that have nothing new
to sense (world/wake.py, ``[sensing] idle_keepalive_s``) and ``expected`` waits only for the
robots it sensed. What an ack asks (a task announced to a robot, a Status from everyone)
takes effect at the next tick's ``senses``, whichever of the two the caller runs first.
"""
from __future__ import annotations

import math

import numpy as np

from swarmcover.bus.messages import ROBOT_KINDS, Clock, CoordAck, Remove, Sense, Spawn

from .config import RunConfig
from .maps import WorldMap
from .physics import Physics
from .sensing import Sensors
from .wake import WakeRule, wake_params

JOIN_S = 0.05          # lockstep barrier: a spawned body's agent takes part this many sim
                       # seconds (at least one tick) after the body appears; that tick waits
                       # for its process to start. 1.0 s cost idle ticks, not less wall time,
                       # and more cycles (corridor_doors seed 0 in-process: > 64 cycles and
                       # 940 s sim unfinished, against 103 cycles and 859 s at one tick)


def join_ticks(dt: float) -> int:
    """Ticks between a body's spawn and its agent's first Sense (lockstep barrier)."""
    return max(1, round(JOIN_S / dt))


def ack_ops(m: CoordAck) -> list:
    """The coordinator's spawns then removes of one ack, as Spawn / Remove messages."""
    ops: list = [Spawn(robot=r, source=src, kind=ROBOT_KINDS[kd], live=lv)
                 for r, src, kd, lv in zip(m.spawn_ids, m.spawn_sources, m.spawn_kinds,
                                           m.spawn_live)]
    return ops + [Remove(robot=r, reason="coordinator") for r in m.remove_ids]


class SpawnRefused(ValueError):
    """A body that cannot be created: ``reason`` (short, fixed text, e.g. for drop counts)
    and ``detail``."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = reason, detail


class WorldCore:
    """Physics, sensors, tick and lockstep roster of one run (see the module docstring).

    seed: the rng's seed (default ``[world] seed``); one rng drives actuation and sensing
    noise, in the order physics steps and sensing calls come."""

    def __init__(self, cfg: RunConfig, wm: WorldMap, seed: int | None = None):
        self.cfg, self.wm = cfg, wm
        w = cfg.world
        self.dt = w.dt
        self.rng = np.random.default_rng(w.seed if seed is None else seed)
        self.physics = Physics(wm, radius=cfg.robots.radius, v_max=cfg.robots.v_max,
                               w_max=cfg.robots.w_max, dt=w.dt, substeps=w.substeps,
                               actuation_noise=cfg.robots.actuation_noise, rng=self.rng)
        sc = cfg.sensing
        self.sensors = Sensors(wm, cfg.rv, radius=cfg.robots.radius,
                               noise_sigma=math.radians(sc.noise_deg), dropout=sc.dropout,
                               robots_occlude=sc.robots_occlude, n_touch=sc.n_touch,
                               skin=sc.touch_skin, rng=self.rng)
        self.sense_every = max(1, round(1.0 / (sc.rate_hz * w.dt)))
        self.join_ticks = join_ticks(self.dt)
        self.tick = 0
        self.agents: set[int] = set()          # ids with a liveliness token
        self.roster: set[int] = set()          # agents taking part (waited for, in Clock)
        self.gone: set[int] = set()            # tokens that vanished since the boundary
        self.joins: dict[int, int] = {}        # body spawned by an ack -> tick it joins
        self.joined: set[int] = set()          # joiners that answered their first tick
        self.status_seq: dict[int, int] = {}   # rid -> seq announced by its last command
        self.task_last: dict[int, int] = {}    # rid -> last task id an ack announced
        # idle robots (world/wake.py): off with idle_keepalive_s = 0
        self.wake = (WakeRule(**wake_params(cfg.rv, cfg.robots.v_max, w.dt, self.sense_every,
                                            sc.idle_keepalive_s, sc.idle_wake_s))
                     if sc.idle_keepalive_s > 0 else None)
        self.idle: set[int] = set()            # robots whose last command said idle
        self.sensed: set[int] = set()          # robots sensed at the current tick
        self._asks: list[tuple[int, list[int], bool]] = []   # acks: (tick, task robots, report)

    @property
    def t(self) -> float:
        """The current tick's simulated time (s)."""
        return self.tick * self.dt

    # ------------------------------------------------------------------ inputs
    def alive(self, rid: int, present: bool) -> None:
        """Robot ``rid``'s liveliness token appeared or vanished (a death takes effect at
        the next boundary)."""
        if present:
            self.agents.add(rid)
            self.gone.discard(rid)
        else:
            self.agents.discard(rid)
            self.gone.add(rid)

    def answered(self, rid: int, status_seq: int, idle: bool = False) -> None:
        """An agent waited for answered this tick; its command announced ``status_seq``
        and whether the robot is idle (CmdVel.idle)."""
        if status_seq >= 0:
            self.status_seq[rid] = status_seq
        if idle:
            self.idle.add(rid)
        else:
            self.idle.discard(rid)

    def on_ack(self, m: CoordAck) -> list:
        """Record the tasks a coordinator's ack announces (each robot's next Senses carry
        its last one; a robot given a task is sensed at the next tick) and whether it asks
        every robot for a Status; returns the ack's spawns and removes (:func:`ack_ops`)."""
        for rid, tid in zip(m.task_robots, m.task_ids):
            self.task_last[rid] = tid
        if m.task_robots or m.report:
            self._asks.append((m.tick, list(m.task_robots), bool(m.report)))
        return ack_ops(m)

    # ------------------------------------------------------------------ bodies
    def add(self, rid: int, source: int, kind: str, live: bool,
            pose: tuple | None = None) -> tuple[float, float, float]:
        """Create robot ``rid``'s body at ``pose`` (x, y, theta) or at source ``source``;
        returns the pose it got. :class:`SpawnRefused` if it cannot."""
        if self.physics.has(rid):
            raise SpawnRefused("spawn of an existing robot", str(rid))
        if pose is None:
            if not 0 <= source < len(self.wm.sources):
                raise SpawnRefused("spawn at an unknown source",
                                   f"source {source}, {len(self.wm.sources)} source(s)")
            pose = tuple(self.wm.sources[source])
        try:
            return self.physics.add(rid, pose[0], pose[1], pose[2], kind, live)
        except ValueError as e:
            raise SpawnRefused("spawn failed", str(e)) from None

    def join_later(self, rid: int) -> None:
        """A body the coordinator's ack spawned: its agent's first Sense comes join_ticks
        from now, and that tick waits for it."""
        self.joins[rid] = self.tick + self.join_ticks

    def remove(self, rid: int) -> bool:
        """Remove robot ``rid``'s body and its roster entries (False: no such body)."""
        if not self.physics.remove(rid):
            return False
        self.roster.discard(rid)
        self.joins.pop(rid, None)
        self.status_seq.pop(rid, None)
        self.idle.discard(rid)
        return True

    # ------------------------------------------------------------------ ticks
    def boundary(self, live: list[bool], ids: list[int]) -> None:
        """The lockstep roster at a tick boundary: deaths, joins, agents that appeared
        (``ids``: the bodies, ``live``: which are live twins, in no roster)."""
        for rid in self.gone:
            self.roster.discard(rid)
            self.joins.pop(rid, None)
        self.gone = set()
        for rid in self.joined:
            if self.joins.pop(rid, None) is not None:
                self.roster.add(rid)
        self.joined = set()
        virtual = {r for k, r in enumerate(ids) if not live[k]}
        self.roster |= {r for r in self.agents & virtual if r not in self.joins}
        self.roster &= virtual

    def clock(self, mode: str, rtf: float) -> Clock:
        """This tick's Clock: the roster and, per agent, its announced status seq."""
        roster = sorted(self.roster)
        return Clock(tick=self.tick, t=self.t, mode=mode, rtf=rtf, agents=roster,
                     status_seqs=[self.status_seq.get(r, 0) for r in roster])

    def sense_due(self) -> bool:
        """Whether this tick senses (every 1 / [sensing] rate_hz)."""
        return self.tick % self.sense_every == 0

    def senses(self, ids: list[int], pos: np.ndarray, th: np.ndarray,
               barrier: bool) -> list[Sense]:
        """This tick's Sense per body whose agent takes part by now (a joiner from its join
        tick on); ``barrier``: the coordinator is in the barrier, so each Sense carries the
        last task announced to its robot (else -1), and idle robots of the roster with
        nothing new to sense get none (world/wake.py)."""
        batch = self.sensors.sense(pos, th)
        tick, t = self.tick, self.t
        asks = [a for a in self._asks if a[0] < tick]
        self._asks = [a for a in self._asks if a[0] >= tick]
        report = any(a[2] for a in asks)
        keep = None
        if barrier and self.wake is not None:
            # only roster members may be skipped: live twins and agents that have not
            # answered yet are sensed every tick
            told = {r for a in asks for r in a[1]}
            keep = self.wake.due(tick // self.sense_every, ids, pos, th,
                                 self.idle & self.roster, told)
            if report:
                keep[:] = True
        rows = [k for k, rid in enumerate(ids)
                if self.joins.get(rid, -1) <= tick and (keep is None or keep[k])]
        per = batch.lists(ids, rows)
        out = [Sense(robot=ids[k], tick=tick, t=t, **f,
                     task_id=self.task_last.get(ids[k], 0) if barrier else -1, report=report)
               for k, f in zip(rows, per)]
        self.sensed = {s.robot for s in out}
        return out

    def expected(self) -> set[int]:
        """The agents this tick waits for: the roster and the joiners due, among the
        robots sensed this tick."""
        due = self.roster | {r for r, j in self.joins.items() if j <= self.tick}
        return due & self.sensed

    def step(self, cmds: np.ndarray) -> None:
        """Step the physics dt with ``cmds`` (one row (vx, vy, wz) per body, in
        ``physics.ids`` order) and move to the next tick."""
        self.physics.step(cmds)
        self.tick += 1

"""``swarmcover world CONFIG``: the simulator process (a thin Zenoh loop over the cores).

Per tick k (sim time t = k * dt):
  * publishes Truth on world/truth and Clock on world/clock (DROP), Pose on robot/<id>/odom
    every 1/pose_rate_hz (virtual robots only, and only those that moved since their last
    one or not within [sensing] idle_keepalive_s: the hwbridge reports live ones), and Sense
    on robot/<id>/sense (BLOCK) to every body every 1/rate_hz (in lockstep with the
    coordinator in the barrier, an idle robot only when it or a robot near it moved, when
    it is given a task or asked for a Status, and every idle_keepalive_s: world/wake.py);
  * then waits (lockstep) or sleeps (realtime), applies the latest commands and steps dt.
Lockstep: tick k+1 runs once every *live* robot sent Sense(k) -- a virtual body whose
agent's liveliness token alive/robot/<id> is present -- answered it with CmdVel(tick=k)
(tick -1 also counts), or after tick_timeout_s wall seconds (the missing ones are "late" and keep their
previous command until it is stale). Unanswered Sense messages are re-sent every
min(0.25, tick_timeout_s/4) s while waiting, so a message lost at start-up does not cost a
timeout. With nobody to wait for, ticks are paced at dt/rtf wall seconds (so the clock moves
at rtf without burning a core). Realtime: one tick every dt/rtf wall seconds.
A command older than stale_cmd_s (sim seconds) counts as zero.

Lockstep with a coordinator (its liveliness token alive/coordinator/main present) adds the
coordinator to the barrier, so a run is repeatable: the Clock of tick k (BLOCK in lockstep)
carries the roster (agents taking part) and, per agent, the seq of the last Status it
published before answering tick k-1 (CmdVel.status_seq); the coordinator acts on exactly
those statuses at sim time t_k and answers with a CoordAck(k) on coord/ack; tick k+1 runs
only once every robot answered Sense(k) and the coordinator acked k (it works while the
agents do). The ack's spawns/removes are applied at that boundary, in the ack's order; a
body it spawns gets its first Sense JOIN_TICKS later, and that tick waits for its agent
(up to JOIN_TIMEOUT_S wall seconds), so process start-up time never shows in the run. Each
Sense carries the last task the coordinator sent its robot before the tick (Sense.task_id),
which the agent applies before stepping. Deaths (a vanished liveliness token) take effect at
the next boundary and show in the roster. A coordinator that does not ack within
COORD_TIMEOUT_S, or whose token goes, leaves the barrier (the run goes on); it rejoins with
its next ack of a current tick. ``--await-coordinator S`` holds tick 0 until a coordinator
is present (``run`` sets it), so the first tick it sees is tick 0.

Spawn/Remove (world/spawn, world/remove) are applied at the next tick boundary, in arrival
order (a Spawn or Remove the coordinator also listed in an ack is applied once). Twins
(Spawn.live) follow TwinCmd (world-frame velocity or teleport) and ignore
CmdVel (which the hwbridge consumes on the same key). Bad input is dropped, counted and
logged once per sender; the world never stalls on it. World/info is a queryable serving
WorldInfo with the resolved config. Liveliness token: alive/world/main.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import time
from collections import Counter

import numpy as np
import zenoh

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, CoordAck, Pose, Remove, Spawn, Truth, TwinCmd, WorldInfo
from swarmcover.bus.node import run_node
from swarmcover.bus.session import Mailbox, Receiver, add_zenoh_args, publisher

from .clock import LockstepGate, Pacer, RtfMeter
from .config import ConfigError, RunConfig, load_config, to_toml, with_sources
from .core import SpawnRefused, WorldCore, join_ticks
from .maps import WorldMap, build_map

ABSURD_FACTOR = 10.0   # commands faster than this times the limit are dropped, not clamped
ODOM_EPS_M = 1e-4      # a pose that moved less than this (m) ...
ODOM_EPS_RAD = 1e-3    # ... and turned less than this (rad) is not published again at once
JOIN_TIMEOUT_S = 30.0  # wall seconds a joining tick waits for a new agent's first command
COORD_TIMEOUT_S = 60.0  # wall seconds a tick waits for the coordinator's ack

__all__ = ["WorldNode", "join_ticks", "main"]


class WorldNode:
    """The world's state and its Zenoh edges. ``run(stop)`` is the main loop."""

    def __init__(self, cfg: RunConfig, wm: WorldMap, session: zenoh.Session, keys: Keys,
                 log: logging.Logger, max_ticks: int | None = None,
                 record_truth: bool = False, await_coordinator_s: float = 0.0):
        self.cfg, self.wm, self.s, self.keys, self.log = cfg, wm, session, keys, log
        w = cfg.world
        self.core = core = WorldCore(cfg, wm)
        self.dt = w.dt
        self.lockstep = w.mode == "lockstep"
        self.max_ticks = max_ticks
        self.physics, self.sensors = core.physics, core.sensors
        self.odom_every = max(1, round(1.0 / (w.pose_rate_hz * w.dt))) if w.pose_rate_hz > 0 \
            else 0
        self.cmds: dict[int, tuple] = {}       # rid -> (vx, vy, wz, sim t, tick)
        self.twin_cmds: dict[int, tuple] = {}  # rid -> (vx, vy, wz, sim t)
        self.pubs: dict[int, tuple] = {}       # rid -> (sense, odom) publishers
        self.pending: list = []                # Spawn / Remove messages, arrival order
        self.last_sense: dict[int, bytes] = {}
        self.last_odom: dict[int, tuple] = {}  # rid -> (x, y, theta, sim t) last published
        self.gate = LockstepGate(w.tick_timeout_s)
        self.resend_s = min(0.25, w.tick_timeout_s / 4)
        self.last_send = 0.0
        self.pacer = Pacer(w.dt, w.rtf, time.monotonic())
        self.meter = RtfMeter()
        self.rx = Receiver(log)
        self.drops: Counter = Counter()
        self._logged: set = set()
        self.late_total = 0
        self.has_agents = False
        self.truth_log: list | None = [] if record_truth else None
        self.mail = Mailbox()
        self._subs: list = []
        self._queryable = None
        self._token = None
        self._info_bytes = b""
        self._clock_pub = self._truth_pub = None
        # the coordinator barrier (the roster is the core's)
        self.coord_present = False             # coordinator liveliness token
        self.coord_in = False                  # coordinator in the barrier
        self.coord_join = False                # ... from the next boundary
        self.acked = -1                        # last tick the coordinator acked
        self.ack_ops: list = []                # spawns/removes of the ack, next boundary
        self.via_ack: set = set()              # ("spawn"|"remove", rid) applied from an ack
        self.coord_timeouts = 0
        self.coord_wait_s = 0.0               # wall time ticks waited on the ack alone
        self.join_wait_s = 0.0                # wall time of ticks waiting for a new agent
        self._t_answered = self._t_acked = None
        self.await_coordinator_s = float(await_coordinator_s)
        self._clock_bytes = b""

    # ------------------------------------------------------------------ set-up
    def declare(self) -> None:
        k, s = self.keys, self.s
        cb = self.mail.callback
        # agents already present: a synchronous snapshot, so tick 0 already waits for them.
        # Taken before the liveliness subscriber exists (with one declared, the get was seen
        # answering from the still-empty local cache); the subscriber's history covers any
        # token that appears in between.
        self.core.agents |= self.alive_snapshot() or set()
        for key in (f"{k.prefix}/robot/*/cmd_vel", f"{k.prefix}/robot/*/twin_cmd", k.spawn,
                    k.remove, k.coord_ack):
            self._subs.append(s.declare_subscriber(key, cb))
        self._subs.append(s.liveliness().declare_subscriber(k.alive_robots(), cb,
                                                            history=True))
        if self.lockstep:
            self._subs.append(s.liveliness().declare_subscriber(
                k.alive("coordinator", "**"), cb, history=True))
        # lockstep: the clock is the coordinator's half of the barrier, it must not be lost
        self._clock_pub = publisher(s, k.clock, block=self.lockstep)
        self._truth_pub = publisher(s, k.truth, block=False)
        info = WorldInfo(name=self.cfg.name, rv=self.cfg.rv,
                         robot_radius=self.cfg.robots.radius, dt=self.dt,
                         mode=self.cfg.world.mode, seed=self.cfg.world.seed,
                         config=to_toml(self.cfg), **self.wm.info_fields())
        self._info_bytes = info.validate().encode()
        self._queryable = s.declare_queryable(k.world_info)
        self._token = s.liveliness().declare_token(k.alive("world", "main"))
        self.log.debug("agents present at start: %s", sorted(self.core.agents))

    def alive_snapshot(self) -> set[int] | None:
        """Robot ids whose liveliness token is present now (None if the query failed)."""
        k = self.keys
        out: set[int] = set()
        try:
            for reply in self.s.liveliness().get(k.alive_robots(), timeout=2.0):
                if reply.ok is not None:
                    rid = k.robot_id(str(reply.ok.key_expr))
                    if rid is not None:
                        out.add(rid)
        except Exception as e:  # a missing snapshot only delays waiting for those agents
            self.log.warning("liveliness snapshot failed: %s", e)
            return None
        return out

    def close(self) -> None:
        for rid in list(self.pubs):
            self._undeclare_pubs(rid)
        for sub in self._subs:
            try:
                sub.undeclare()
            except Exception:
                pass
        self._subs = []
        for obj in (self._queryable, self._token, self._clock_pub, self._truth_pub):
            if obj is not None:
                try:
                    obj.undeclare()
                except Exception:
                    pass
        self._queryable = self._token = self._clock_pub = self._truth_pub = None

    def _declare_pubs(self, rid: int) -> None:
        self.pubs[rid] = (publisher(self.s, self.keys.sense(rid), block=True),
                          publisher(self.s, self.keys.odom(rid), block=False))

    def _undeclare_pubs(self, rid: int) -> None:
        for p in self.pubs.pop(rid, ()):
            try:
                p.undeclare()
            except Exception:
                pass

    # ------------------------------------------------------------------ bad input
    def _drop(self, key: str, reason: str, detail: str = "") -> None:
        self.drops[reason] += 1
        tag = (key, reason)
        if tag not in self._logged:
            self._logged.add(tag)
            self.log.warning("dropping message on %s: %s%s (further ones from this sender "
                             "are counted, not logged)", key, reason,
                             f" ({detail})" if detail else "")

    # ------------------------------------------------------------------ inputs
    def handle(self, item) -> None:
        key, payload, kind = item
        rel = self.keys.relative(key)
        try:
            if rel.startswith("alive/robot/"):
                rid = self.keys.robot_id(key)
                if rid is None:
                    return
                gone = kind == zenoh.SampleKind.DELETE
                self.core.alive(rid, not gone)
                if gone:
                    self.gate.forget(rid)
            elif rel.startswith("alive/coordinator/"):
                self._on_coordinator(kind != zenoh.SampleKind.DELETE)
            elif rel == "coord/ack":
                m = self.rx.decode(key, payload, CoordAck)
                if m is not None:
                    self._on_ack(m)
            elif rel.endswith("/cmd_vel"):
                self._on_cmd(key, payload)
            elif rel.endswith("/twin_cmd"):
                self._on_twin(key, payload)
            elif rel == "world/spawn":
                m = self.rx.decode(key, payload, Spawn)
                if m is not None and ("spawn", m.robot) not in self.via_ack:
                    self.pending.append(m)
            elif rel == "world/remove":
                m = self.rx.decode(key, payload, Remove)
                if m is not None and ("remove", m.robot) not in self.via_ack:
                    self.pending.append(m)
        except Exception as e:  # never crash on input
            self._drop(key, "error", f"{e.__class__.__name__}: {e}")

    def _on_coordinator(self, present: bool) -> None:
        self.coord_present = present
        if not present:
            if self.coord_in:
                self.log.info("tick %d: the coordinator left: ticks no longer wait for it",
                              self.tick)
            self.coord_in = self.coord_join = False
        elif self.lockstep and not self.coord_in:
            self.coord_join = True  # waited for from the next boundary

    def _on_ack(self, m: CoordAck) -> None:
        """The coordinator's decisions of tick m.tick: tasks are announced to their robots
        in the Senses after the next boundary, spawns/removes applied at it."""
        ops = self.core.on_ack(m)
        fresh = m.tick == self.tick and self.acked < m.tick
        for op in ops:
            tag = ("spawn" if isinstance(op, Spawn) else "remove", op.robot)
            if tag in self.via_ack:
                continue
            self.via_ack.add(tag)
            # drop the same request if it already came on world/spawn or world/remove
            self.pending = [p for p in self.pending
                            if not (type(p) is type(op) and p.robot == op.robot)]
            self.ack_ops.append((op, fresh and self.lockstep))
        if fresh:
            self.acked = m.tick
            self._t_acked = time.monotonic()
            if not self.coord_in and self.coord_present and self.lockstep:
                self.coord_in = True
                self.log.info("tick %d: the coordinator is back in the barrier", self.tick)

    def _robot_msg(self, key: str, payload: bytes, cls):
        """(robot id, message) of a per-robot key's payload, or None (counted as dropped)
        when it does not decode or its robot field is not the key's."""
        rid = self.keys.robot_id(key)
        m = self.rx.decode(key, payload, cls)
        if m is None or rid is None:
            return None
        if m.robot != rid:
            self._drop(key, "robot field differs from key", f"robot={m.robot}")
            return None
        return rid, m

    def _on_cmd(self, key: str, payload: bytes) -> None:
        got = self._robot_msg(key, payload, CmdVel)
        if got is None:
            return
        rid, m = got
        if not self.physics.has(rid):
            return self._drop(key, "unknown robot", f"no body {rid}")
        if self.physics.is_live(rid):
            self.drops["cmd_vel for live twin (ignored)"] += 1
            return
        rb = self.cfg.robots
        if (math.hypot(m.vx, m.vy) > ABSURD_FACTOR * rb.v_max
                or abs(m.wz) > ABSURD_FACTOR * rb.w_max):
            return self._drop(key, "absurd velocity", f"vx={m.vx} vy={m.vy} wz={m.wz}")
        if self.lockstep and m.tick > self.gate.tick:
            return self._drop(key, "command for a future tick", f"tick={m.tick}")
        prev = self.cmds.get(rid)
        if prev is not None and m.tick != -1 and m.tick < prev[4]:
            self.drops["late command (superseded)"] += 1
            return
        self.cmds[rid] = (m.vx, m.vy, m.wz, self.tick * self.dt, m.tick)
        if self.lockstep:
            if m.tick != -1 and m.tick < self.gate.tick:
                self.drops["late command"] += 1
            else:
                if self.gate.answer(rid, m.tick) and rid in self.gate.expected:
                    self.core.answered(rid, m.status_seq, m.idle)
                if self._t_answered is None and self.gate.all_answered():
                    self._t_answered = time.monotonic()

    def _on_twin(self, key: str, payload: bytes) -> None:
        got = self._robot_msg(key, payload, TwinCmd)
        if got is None:
            return
        rid, m = got
        if not self.physics.has(rid) or not self.physics.is_live(rid):
            return self._drop(key, "twin_cmd for a robot that is not a live twin", str(rid))
        if m.teleport:
            self.physics.teleport(rid, m.x, m.y, m.theta)
        self.twin_cmds[rid] = (m.vx, m.vy, m.wz, self.tick * self.dt)

    def _apply_pending(self) -> None:
        """Spawns and removes at a tick boundary: the coordinator's acked ones first, in
        ack order, then the others in arrival order."""
        acked, self.ack_ops = self.ack_ops, []
        ops, self.pending = self.pending, []
        for m, join in acked:
            self._apply_op(m, "coord/ack")
            if join and isinstance(m, Spawn) and not m.live and self.physics.has(m.robot):
                self.core.join_later(m.robot)
        for m in ops:
            self._apply_op(m, "world/spawn" if isinstance(m, Spawn) else "world/remove")

    def _apply_op(self, m, where: str) -> None:
        if isinstance(m, Spawn):
            self._spawn(m.robot, m.source, m.kind, m.live, None, where)
        else:
            if self.core.remove(m.robot):
                self._undeclare_pubs(m.robot)
                self.cmds.pop(m.robot, None)
                self.twin_cmds.pop(m.robot, None)
                self.last_sense.pop(m.robot, None)
                self.last_odom.pop(m.robot, None)
                self.gate.forget(m.robot)
                self.log.info("removed robot %d (%s)", m.robot, m.reason or "no reason")
            else:
                self._drop(self.keys.remove, "remove of an unknown robot", str(m.robot))

    def _spawn(self, rid, source, kind, live, pose, where) -> bool:
        try:
            x, y, th = self.core.add(rid, source, kind, live, pose)
        except SpawnRefused as e:
            self._drop(where, e.reason, e.detail)
            return False
        self._declare_pubs(rid)
        self.log.info("spawned robot %d (%s%s) at (%.3f, %.3f, %.3f)", rid, kind,
                      ", live twin" if live else "", x, y, th)
        return True

    # ------------------------------------------------------------------ ticks
    def _commands(self, ids: list[int]) -> np.ndarray:
        t = self.tick * self.dt
        stale = self.cfg.world.stale_cmd_s
        out = np.zeros((len(ids), 3))
        for k, rid in enumerate(ids):
            c = self.twin_cmds.get(rid) if self.physics.is_live(rid) else self.cmds.get(rid)
            if c is not None and t - c[3] <= stale + 1e-9:
                out[k] = c[:3]
        return out

    def advance(self) -> None:
        """Apply commands, step dt, apply spawns/removes, publish the new tick."""
        core = self.core
        if self.lockstep:
            late = self.gate.late()
            if late:
                self.late_total += len(late)
                self.drops["late robot ticks"] += len(late)
                if ("late",) not in self._logged:
                    self._logged.add(("late",))
                    self.log.warning("tick %d: robots %s did not answer within %.2f s "
                                     "(further late ticks are counted)", self.tick,
                                     sorted(late)[:10], self.gate.timeout_s)
                # an agent whose token vanished unseen must not stall every tick
                alive = self.alive_snapshot()
                if alive is not None:
                    for rid in late - alive:
                        self.core.alive(rid, False)
                for rid in late & set(core.joins):   # a new agent that never came
                    core.joins.pop(rid)
                    self.log.warning("tick %d: robot %d's agent did not start within %.0f s; "
                                     "it takes part once it answers (not repeatable)",
                                     self.tick, rid, JOIN_TIMEOUT_S)
            core.joined |= self.gate.answered & set(core.joins)
            if self.gate.expected & set(core.joins):
                self.join_wait_s += time.monotonic() - self.gate.opened
            if self._t_acked is not None:
                self.coord_wait_s += max(0.0, self._t_acked - (self._t_answered
                                                               or self.gate.opened))
            self._t_answered = self._t_acked = None
            if self.coord_in and self.acked < self.tick:
                self.coord_in = False
                self.coord_timeouts += 1
                self.log.warning("tick %d: no ack from the coordinator within %.0f s: ticks "
                                 "no longer wait for it (not repeatable from here)",
                                 self.tick, COORD_TIMEOUT_S)
        core.step(self._commands(self.physics.ids))
        self._apply_pending()
        self.publish_tick()

    def _boundary(self, live: list[bool], ids: list[int]) -> None:
        """Lockstep roster at a tick boundary (the core's), and the coordinator joining."""
        self.core.boundary(live, ids)
        if self.coord_join and self.coord_present:
            self.coord_in, self.coord_join = True, False
            self.log.info("tick %d: the coordinator joins the barrier", self.tick)

    def publish_tick(self) -> None:
        core = self.core
        t = core.t
        now = time.monotonic()
        self.meter.add(t, now)
        ids, pos, th = self.physics.state()
        live = [self.physics.is_live(r) for r in ids]
        truth = Truth(tick=self.tick, t=t, ids=list(ids), x=pos[:, 0].tolist(),
                      y=pos[:, 1].tolist(), theta=th.tolist(), live=live)
        self._truth_pub.put(truth.encode())
        if self.truth_log is not None:
            self.truth_log.append({"tick": self.tick, "ids": list(ids),
                                   "x": pos[:, 0].tolist(), "y": pos[:, 1].tolist(),
                                   "theta": th.tolist()})
        if self.lockstep:
            self._boundary(live, list(ids))
        self._clock_bytes = core.clock(self.cfg.world.mode, min(self.meter.rtf, 1e6)).encode()
        self._clock_pub.put(self._clock_bytes)
        if self.odom_every and self.tick % self.odom_every == 0:
            self._publish_odom(ids, pos, th, live, t)
        expected: set[int] = set()
        if self.lockstep:
            self.has_agents = bool(core.roster or core.joins)
        else:
            self.has_agents = any(not live[k] and r in core.agents for k, r in enumerate(ids))
        if core.sense_due() and ids:
            self._publish_sense(ids, pos, th)
            if self.lockstep:
                expected = core.expected()
            else:
                expected = {r for k, r in enumerate(ids) if not live[k] and r in core.agents}
        self.gate.open(self.tick, expected, now)
        self.last_send = now

    def _publish_odom(self, ids, pos, th, live, t: float) -> None:
        """Pose on robot/<id>/odom for virtual robots that moved since their last one (by
        more than ODOM_EPS_M or ODOM_EPS_RAD), and for the others once every
        [sensing] idle_keepalive_s: a swarm that holds still costs no 5 Hz odometry."""
        every = self.cfg.sensing.idle_keepalive_s
        last = self.last_odom
        for k, rid in enumerate(ids):
            if live[k]:
                continue
            x, y, a = float(pos[k, 0]), float(pos[k, 1]), float(th[k])
            prev = last.get(rid)
            if (prev is not None and t - prev[3] < every and abs(x - prev[0]) <= ODOM_EPS_M
                    and abs(y - prev[1]) <= ODOM_EPS_M
                    and abs(math.remainder(a - prev[2], math.tau)) <= ODOM_EPS_RAD):
                continue
            last[rid] = (x, y, a, t)
            self.pubs[rid][1].put(Pose(robot=rid, t=t, x=x, y=y, theta=a, source="sim").encode())

    def _publish_sense(self, ids, pos, th) -> None:
        self.last_sense = {}
        for sense in self.core.senses(ids, pos, th, barrier=self.coord_in):
            data = self.last_sense[sense.robot] = sense.encode()
            self.pubs[sense.robot][0].put(data)

    def _resend(self, now: float) -> None:
        for rid in sorted(self.gate.waiting):
            data = self.last_sense.get(rid)
            if data is not None and rid in self.pubs:
                self.pubs[rid][0].put(data)
        if self._ack_missing():
            self._clock_pub.put(self._clock_bytes)
        self.last_send = now

    def _ack_missing(self) -> bool:
        return self.lockstep and self.coord_in and self.acked < self.tick

    def _gate_ready(self, now: float) -> bool:
        g = self.gate
        if g.all_answered():
            return True
        if not g.timed_out(now):
            return False
        # a new agent's process may still be starting: its joining tick waits longer
        return not (g.waiting & set(self.core.joins)) or now - g.opened >= JOIN_TIMEOUT_S

    def serve_queries(self) -> None:
        q = self._queryable
        if q is None:
            return
        while True:
            query = q.try_recv()
            if query is None:
                return
            try:
                query.reply(self.keys.world_info, self._info_bytes)
            except Exception as e:
                self.log.warning("world/info reply failed: %s", e)
            finally:
                query.drop()

    def ready(self, now: float) -> bool:
        if not self.lockstep:
            return self.pacer.due(now)
        if self._ack_missing() and now - self.gate.opened < COORD_TIMEOUT_S:
            return False
        if self.gate.expected:
            return self._gate_ready(now)
        if self.has_agents or self.coord_in:  # a tick without Sense between lockstepped ones
            return True
        return self.pacer.due(now)

    def wait_time(self, now: float) -> float:
        if self.lockstep and (self.gate.expected or self._ack_missing()):
            w = self.last_send + self.resend_s - now
            if self.gate.expected and not self.gate.all_answered():
                w = min(w, self.gate.remaining(now))
        else:
            w = self.pacer.wait_time(now)
        return min(max(w, 0.0), 0.02)

    def await_coordinator(self, stop) -> None:
        """Hold tick 0 until a coordinator is present (``--await-coordinator``)."""
        end = time.monotonic() + self.await_coordinator_s
        while not stop.is_set() and not self.coord_present and time.monotonic() < end:
            for item in self.mail.drain(10_000):
                self.handle(item)
            self.serve_queries()
            item = self.mail.get(0.02)
            if item is not None:
                self.handle(item)
        if self.coord_present:
            self.coord_in, self.coord_join = True, False
            self._clock_pub.put(self._clock_bytes)
            self.last_send = time.monotonic()
        else:
            self.log.warning("no coordinator within %.0f s: ticking without it",
                             self.await_coordinator_s)

    def run(self, stop) -> None:
        for sp in self.cfg.world.spawn:
            self._spawn(sp.robot, sp.source, sp.kind or self.cfg.robots.kind, sp.live,
                        sp.pose, "[world].spawn")
        self._apply_pending()
        self.publish_tick()
        self.pacer.reset(time.monotonic())
        print(f"READY world {self.cfg.name} {self.cfg.world.mode} "
              f"robots={len(self.physics.ids)}", flush=True)
        if self.lockstep and self.await_coordinator_s > 0:
            self.await_coordinator(stop)
            self.pacer.reset(time.monotonic())
        while not stop.is_set():
            if self.max_ticks is not None and self.tick >= self.max_ticks:
                break
            for item in self.mail.drain(10_000):
                self.handle(item)
            self.serve_queries()
            now = time.monotonic()
            if self.ready(now):
                self.advance()
                self.pacer.done(time.monotonic())
                continue
            if (self.lockstep and (self.gate.expected or self._ack_missing())
                    and now - self.last_send >= self.resend_s):
                self._resend(now)
            item = self.mail.get(self.wait_time(now))
            if item is not None:
                self.handle(item)

    @property
    def tick(self) -> int:
        return self.core.tick

    def summary(self) -> dict:
        return {"ticks": self.tick, "t": self.tick * self.dt, "robots": len(self.physics.ids),
                "invalid": dict(self.rx.invalid), "dropped": dict(self.drops),
                "late": self.late_total, "coordinator_timeouts": self.coord_timeouts,
                "coordinator_wait_s": round(self.coord_wait_s, 3),
                "join_wait_s": round(self.join_wait_s, 3)}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover world", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_config", metavar="CONFIG", help="run config TOML, or a ROS map_server YAML")
    p.add_argument("--clock", dest="clock_mode", choices=("lockstep", "realtime"),
                   help="override [world].mode")
    p.add_argument("--rtf", type=float, help="override [world].rtf")
    p.add_argument("--seed", type=int, help="override [world].seed")
    p.add_argument("--max-ticks", type=int, default=None, help="stop after this many ticks")
    p.add_argument("--await-coordinator", type=float, default=0.0, metavar="S",
                   help="lockstep: hold tick 0 until a coordinator is present, up to S wall "
                        "seconds (default 0: don't wait)")
    p.add_argument("--truth-out", metavar="FILE",
                   help="write every tick's ground-truth poses to FILE (JSON) at exit")
    p.add_argument("--log-level", default="INFO")
    add_zenoh_args(p)
    return p


def _overrides(cfg: RunConfig, args) -> RunConfig:
    from dataclasses import replace
    w = cfg.world
    if args.clock_mode:
        w = replace(w, mode=args.clock_mode)
    if args.rtf is not None:
        if not (args.rtf > 0 and math.isfinite(args.rtf)):
            raise ConfigError("--rtf", "world", "rtf", args.rtf, "must be a positive number")
        w = replace(w, rtf=args.rtf)
    if args.seed is not None:
        if args.seed < 0:
            raise ConfigError("--seed", "world", "seed", args.seed, "must be >= 0")
        w = replace(w, seed=args.seed)
    return replace(cfg, world=w)


def _load(args) -> tuple[RunConfig, WorldMap]:
    """The run config (with the map's sources) and the map, checked before any connection
    (exit 2 naming the field); run_node hands them to :func:`_serve`."""
    cfg = _overrides(load_config(args.run_config), args)   # ConfigError is a ValueError
    wm = build_map(cfg)
    return with_sources(cfg, [tuple(s) for s in wm.sources]), wm


def _serve(args, session, keys, stop, loaded: tuple[RunConfig, WorldMap]) -> int:
    log = logging.getLogger("swarmcover.world")
    cfg, wm = loaded
    node = None
    rc = 0
    try:
        node = WorldNode(cfg, wm, session, keys, log, max_ticks=args.max_ticks,
                         record_truth=bool(args.truth_out),
                         await_coordinator_s=args.await_coordinator)
        node.declare()
        log.info("world %s: %s, %d walls, free area %.2f m^2, %d source(s), %s mode",
                 cfg.name, f"{len(wm.obstacles)} obstacles", len(wm.walls), wm.free_area,
                 len(wm.sources), cfg.world.mode)
        node.run(stop)
    except Exception:
        log.exception("world failed")
        rc = 1
    finally:
        if node is not None:
            node.close()
            log.info("world stopped: %s", json.dumps(node.summary()))
            if args.truth_out and node.truth_log is not None:
                with open(args.truth_out, "w") as f:
                    json.dump({"summary": node.summary(), "ticks": node.truth_log}, f)
    return rc


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover world", __doc__, build_parser(), _serve, argv=argv,
                    logger="swarmcover.world", prepare=_load)

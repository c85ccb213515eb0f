"""``swarmcover world CONFIG``: the simulator process (a thin Zenoh loop over the cores).

Per tick k (sim time t = k * dt):
  * publishes Truth on world/truth and Clock on world/clock (DROP), Pose on robot/<id>/odom
    every 1/pose_rate_hz (virtual robots only: the hwbridge reports live ones), and Sense on
    robot/<id>/sense (BLOCK) to every body every 1/rate_hz;
  * then waits (lockstep) or sleeps (realtime), applies the latest commands and steps dt.
Lockstep: tick k+1 runs once every *live* robot -- a virtual body whose agent's liveliness
token alive/robot/<id> is present -- answered Sense(k) with CmdVel(tick=k) (tick -1 also
counts), or after tick_timeout_s wall seconds (the missing ones are "late" and keep their
previous command until it is stale). Unanswered Sense messages are re-sent every
min(0.25, tick_timeout_s/4) s while waiting, so a message lost at start-up does not cost a
timeout. With nobody to wait for, ticks are paced at dt/rtf wall seconds (so the clock moves
at rtf without burning a core). Realtime: one tick every dt/rtf wall seconds.
A command older than stale_cmd_s (sim seconds) counts as zero.

Spawn/Remove (world/spawn, world/remove) are applied at the next tick boundary, in arrival
order. Twins (Spawn.live) follow TwinCmd (world-frame velocity or teleport) and ignore
CmdVel (which the hwbridge consumes on the same key). Bad input is dropped, counted and
logged once per sender; the world never stalls on it. World/info is a queryable serving
WorldInfo with the resolved config. Liveliness token: alive/world/main.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections import Counter

import numpy as np
import zenoh

from bus.keys import Keys
from bus.messages import (Clock, CmdVel, Pose, Remove, Sense, Spawn, Truth, TwinCmd,
                          WorldInfo)
from bus.session import (Mailbox, Receiver, Shutdown, add_zenoh_args, keys_from_args,
                         open_session, publisher, setup_logging)

from .clock import LockstepGate, Pacer, RtfMeter
from .config import ConfigError, RunConfig, load_config, to_toml, with_sources
from .maps import WorldMap, build_map
from .physics import Physics
from .sensing import Sensors

ABSURD_FACTOR = 10.0   # commands faster than this times the limit are dropped, not clamped


class WorldNode:
    """The world's state and its Zenoh edges. ``run(stop)`` is the main loop."""

    def __init__(self, cfg: RunConfig, wm: WorldMap, session: zenoh.Session, keys: Keys,
                 log: logging.Logger, max_ticks: int | None = None,
                 record_truth: bool = False):
        self.cfg, self.wm, self.s, self.keys, self.log = cfg, wm, session, keys, log
        w = cfg.world
        self.dt = w.dt
        self.lockstep = w.mode == "lockstep"
        self.max_ticks = max_ticks
        self.rng = np.random.default_rng(w.seed)
        self.physics = Physics(wm, radius=cfg.robots.radius, v_max=cfg.robots.v_max,
                               w_max=cfg.robots.w_max, dt=w.dt, substeps=w.substeps,
                               actuation_noise=cfg.robots.actuation_noise, rng=self.rng)
        sc = cfg.sensing
        self.sensors = Sensors(wm, cfg.rv, radius=cfg.robots.radius,
                               noise_sigma=math.radians(sc.noise_deg), dropout=sc.dropout,
                               robots_occlude=sc.robots_occlude, n_touch=sc.n_touch,
                               skin=sc.touch_skin, rng=self.rng)
        self.sense_every = max(1, round(1.0 / (sc.rate_hz * w.dt)))
        self.odom_every = max(1, round(1.0 / (w.pose_rate_hz * w.dt))) if w.pose_rate_hz > 0 \
            else 0
        self.tick = 0
        self.cmds: dict[int, tuple] = {}       # rid -> (vx, vy, wz, sim t, tick)
        self.twin_cmds: dict[int, tuple] = {}  # rid -> (vx, vy, wz, sim t)
        self.agents: set[int] = set()          # ids with a liveliness token
        self.pubs: dict[int, tuple] = {}       # rid -> (sense, odom) publishers
        self.pending: list = []                # Spawn / Remove messages, arrival order
        self.last_sense: dict[int, bytes] = {}
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

    # ------------------------------------------------------------------ set-up
    def declare(self) -> None:
        k, s = self.keys, self.s
        cb = self.mail.callback
        # agents already present: a synchronous snapshot, so tick 0 already waits for them.
        # Taken before the liveliness subscriber exists (with one declared, the get was seen
        # answering from the still-empty local cache); the subscriber's history covers any
        # token that appears in between.
        self.agents |= self.alive_snapshot() or set()
        for key in (f"{k.prefix}/robot/*/cmd_vel", f"{k.prefix}/robot/*/twin_cmd", k.spawn,
                    k.remove):
            self._subs.append(s.declare_subscriber(key, cb))
        self._subs.append(s.liveliness().declare_subscriber(k.alive_robots(), cb,
                                                            history=True))
        self._clock_pub = publisher(s, k.clock, block=False)
        self._truth_pub = publisher(s, k.truth, block=False)
        info = WorldInfo(name=self.cfg.name, rv=self.cfg.rv,
                         robot_radius=self.cfg.robots.radius, dt=self.dt,
                         mode=self.cfg.world.mode, seed=self.cfg.world.seed,
                         config=to_toml(self.cfg), **self.wm.info_fields())
        self._info_bytes = info.validate().encode()
        self._queryable = s.declare_queryable(k.world_info)
        self._token = s.liveliness().declare_token(k.alive("world", "main"))
        self.log.debug("agents present at start: %s", sorted(self.agents))

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
                if kind == zenoh.SampleKind.DELETE:
                    self.agents.discard(rid)
                    self.gate.forget(rid)
                else:
                    self.agents.add(rid)
            elif rel.endswith("/cmd_vel"):
                self._on_cmd(key, payload)
            elif rel.endswith("/twin_cmd"):
                self._on_twin(key, payload)
            elif rel == "world/spawn":
                m = self.rx.decode(key, payload, Spawn)
                if m is not None:
                    self.pending.append(m)
            elif rel == "world/remove":
                m = self.rx.decode(key, payload, Remove)
                if m is not None:
                    self.pending.append(m)
        except Exception as e:  # never crash on input
            self._drop(key, "error", f"{e.__class__.__name__}: {e}")

    def _on_cmd(self, key: str, payload: bytes) -> None:
        rid = self.keys.robot_id(key)
        m = self.rx.decode(key, payload, CmdVel)
        if m is None or rid is None:
            return
        if m.robot != rid:
            return self._drop(key, "robot field differs from key", f"robot={m.robot}")
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
                self.gate.answer(rid, m.tick)

    def _on_twin(self, key: str, payload: bytes) -> None:
        rid = self.keys.robot_id(key)
        m = self.rx.decode(key, payload, TwinCmd)
        if m is None or rid is None:
            return
        if m.robot != rid:
            return self._drop(key, "robot field differs from key", f"robot={m.robot}")
        if not self.physics.has(rid) or not self.physics.is_live(rid):
            return self._drop(key, "twin_cmd for a robot that is not a live twin", str(rid))
        if m.teleport:
            self.physics.teleport(rid, m.x, m.y, m.theta)
        self.twin_cmds[rid] = (m.vx, m.vy, m.wz, self.tick * self.dt)

    def _apply_pending(self) -> None:
        ops, self.pending = self.pending, []
        for m in ops:
            if isinstance(m, Spawn):
                self._spawn(m.robot, m.source, m.kind, m.live, None, "world/spawn")
            else:
                if self.physics.remove(m.robot):
                    self._undeclare_pubs(m.robot)
                    self.cmds.pop(m.robot, None)
                    self.twin_cmds.pop(m.robot, None)
                    self.last_sense.pop(m.robot, None)
                    self.gate.forget(m.robot)
                    self.log.info("removed robot %d (%s)", m.robot, m.reason or "no reason")
                else:
                    self._drop(self.keys.remove, "remove of an unknown robot", str(m.robot))

    def _spawn(self, rid, source, kind, live, pose, where) -> bool:
        if self.physics.has(rid):
            self._drop(where, "spawn of an existing robot", str(rid))
            return False
        if pose is None:
            if source >= len(self.wm.sources):
                self._drop(where, "spawn at an unknown source",
                           f"source {source}, {len(self.wm.sources)} source(s)")
                return False
            pose = tuple(self.wm.sources[source])
        try:
            x, y, th = self.physics.add(rid, pose[0], pose[1], pose[2], kind, live)
        except ValueError as e:
            self._drop(where, "spawn failed", str(e))
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
                    self.agents -= late - alive
        ids = self.physics.ids
        self.physics.step(self._commands(ids))
        self.tick += 1
        self._apply_pending()
        self.publish_tick()

    def publish_tick(self) -> None:
        t = self.tick * self.dt
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
        self._clock_pub.put(Clock(tick=self.tick, t=t, mode=self.cfg.world.mode,
                                  rtf=min(self.meter.rtf, 1e6)).encode())
        if self.odom_every and self.tick % self.odom_every == 0:
            for k, rid in enumerate(ids):
                if not live[k]:
                    self.pubs[rid][1].put(Pose(robot=rid, t=t, x=float(pos[k, 0]),
                                               y=float(pos[k, 1]), theta=float(th[k]),
                                               source="sim").encode())
        expected: set[int] = set()
        self.has_agents = any(not live[k] and r in self.agents for k, r in enumerate(ids))
        if self.tick % self.sense_every == 0 and ids:
            self._publish_sense(ids, pos, th, t)
            expected = {r for k, r in enumerate(ids) if not live[k] and r in self.agents}
        self.gate.open(self.tick, expected, now)
        self.last_send = now

    def _publish_sense(self, ids, pos, th, t) -> None:
        b = self.sensors.sense(pos, th)
        ida = np.asarray(ids, np.int64)
        tgt = ida[b.tgt].tolist()
        brg = b.bearing.tolist()
        back = b.back.tolist()
        tb = b.touch_bearing.tolist()
        tr = b.touch_is_robot.tolist()
        co = b.cam_off.tolist()
        to = b.touch_off.tolist()
        self.last_sense = {}
        for k, rid in enumerate(ids):
            a, e = co[k], co[k + 1]
            c, d = to[k], to[k + 1]
            data = Sense(robot=rid, tick=self.tick, t=t, ids=tgt[a:e], bearings=brg[a:e],
                         back_bearings=back[a:e], touch=tb[c:d],
                         touch_robot=tr[c:d]).encode()
            self.last_sense[rid] = data
            self.pubs[rid][0].put(data)

    def _resend(self, now: float) -> None:
        for rid in sorted(self.gate.waiting):
            data = self.last_sense.get(rid)
            if data is not None and rid in self.pubs:
                self.pubs[rid][0].put(data)
        self.last_send = now

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
        if self.gate.expected:
            return self.gate.ready(now)
        if self.has_agents:      # a tick without Sense between two lockstepped ones
            return True
        return self.pacer.due(now)

    def wait_time(self, now: float) -> float:
        if self.lockstep and self.gate.expected:
            w = min(self.gate.remaining(now), self.last_send + self.resend_s - now)
        else:
            w = self.pacer.wait_time(now)
        return min(max(w, 0.0), 0.02)

    def run(self, stop) -> None:
        for sp in self.cfg.world.spawn:
            self._spawn(sp.robot, sp.source, sp.kind or self.cfg.robots.kind, sp.live,
                        sp.pose, "[world].spawn")
        self._apply_pending()
        self.publish_tick()
        self.pacer.reset(time.monotonic())
        print(f"READY world {self.cfg.name} {self.cfg.world.mode} "
              f"robots={len(self.physics.ids)}", flush=True)
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
            if self.lockstep and self.gate.expected and now - self.last_send >= self.resend_s:
                self._resend(now)
            item = self.mail.get(self.wait_time(now))
            if item is not None:
                self.handle(item)

    def summary(self) -> dict:
        return {"ticks": self.tick, "t": self.tick * self.dt, "robots": len(self.physics.ids),
                "invalid": dict(self.rx.invalid), "dropped": dict(self.drops),
                "late": self.late_total}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover world", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_config", metavar="CONFIG", help="run config TOML, or a ROS map_server YAML")
    p.add_argument("--clock", dest="clock_mode", choices=("lockstep", "realtime"),
                   help="override [world].mode")
    p.add_argument("--rtf", type=float, help="override [world].rtf")
    p.add_argument("--seed", type=int, help="override [world].seed")
    p.add_argument("--max-ticks", type=int, default=None, help="stop after this many ticks")
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


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    log = setup_logging(args.log_level, "swarmcover.world")
    try:
        cfg = _overrides(load_config(args.run_config), args)
        wm = build_map(cfg)
        cfg = with_sources(cfg, [tuple(s) for s in wm.sources])
    except (ConfigError, ValueError) as e:
        print(f"swarmcover world: {e}", file=sys.stderr, flush=True)
        return 2
    keys = keys_from_args(args)
    try:
        session = open_session(args)
    except (ValueError, ConnectionError) as e:
        print(f"swarmcover world: {e}", file=sys.stderr, flush=True)
        return 2
    node = None
    rc = 0
    with Shutdown() as stop:
        try:
            node = WorldNode(cfg, wm, session, keys, log, max_ticks=args.max_ticks,
                             record_truth=bool(args.truth_out))
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
            session.close()
    return rc

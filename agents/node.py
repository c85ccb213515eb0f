"""``swarmcover agent --id N``: one robot's onboard computer, as one OS process.

Subscribes to its Sense (robot/N/sense), Task (robot/N/task) and body pose (robot/N/odom,
telemetry only); publishes one CmdVel per Sense (same tick, at once: a lockstep world waits
for it), its Status (every ``status_every`` Sense ticks, on every state/task change, and
once a second while no Sense arrives) and the relay of its body pose (Pose, source "agent",
on robot/N/pose). Holds the liveliness token alive/robot/N. Steering uses bearings,
identities, touch and tasks only (agents/behaviours.py); the pose is never read by it.

Parameters: defaults < the run config (``--run-config FILE``, else the world's config from
a world/info query bounded by ``--info-timeout``) < ``--kind/--v-max/--param NAME=VALUE``.
Exits cleanly on SIGINT/SIGTERM, or when ``--parent-pid`` is no longer its parent.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path

from bus.keys import Keys
from bus.messages import CmdVel, Pose, Sense, Status, Task, WireError, WorldInfo, decode
from bus.session import (Mailbox, Receiver, Shutdown, add_zenoh_args, keys_from_args,
                         open_session, publisher, setup_logging)

from .behaviours import Behaviour
from .params import ROBOT_KINDS, AgentParams, ParamError, from_toml_text, parse_override

HEARTBEAT_S = 1.0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover agent", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--id", type=int, required=True, help="robot id (>= 0)")
    p.add_argument("--kind", choices=ROBOT_KINDS, default=None,
                   help="override [robots].kind of the run config")
    p.add_argument("--live", action="store_true",
                   help="this agent drives a live robot (reported in Status)")
    p.add_argument("--v-max", type=float, default=None, help="override [robots].v_max (m/s)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override an [agent] parameter, repeatable (see agents/params.py)")
    p.add_argument("--run-config", metavar="FILE",
                   help="read the run config (TOML) from FILE instead of querying world/info")
    p.add_argument("--info-timeout", type=float, default=3.0, metavar="S",
                   help="how long to wait for the world's config (0: don't ask; default 3)")
    p.add_argument("--parent-pid", type=int, default=None, metavar="PID",
                   help="exit when this process is no longer the parent (set by spawn)")
    p.add_argument("--log-level", default="INFO")
    add_zenoh_args(p)
    return p


def query_world_info(session, keys: Keys, timeout: float, stop: Shutdown,
                     log: logging.Logger) -> WorldInfo | None:
    """The world's WorldInfo, retried until ``timeout`` seconds pass; None if no world."""
    end = time.monotonic() + timeout
    while not stop.is_set():
        left = end - time.monotonic()
        if left <= 0:
            return None
        try:
            for reply in session.get(keys.world_info, timeout=max(0.1, min(1.0, left))):
                if reply.ok is None:
                    continue
                try:
                    return decode(reply.ok.payload.to_bytes(), WorldInfo)
                except WireError as e:
                    log.warning("ignoring an invalid world/info reply: %s", e)
        except Exception as e:  # a closed/unreachable session must not crash start-up
            log.warning("world/info query failed: %s", e)
        stop.wait(0.2)
    return None


def resolve_params(args, session, keys: Keys, stop: Shutdown,
                   log: logging.Logger) -> AgentParams:
    """Parameters from the run config or the world, then the CLI. Raises ParamError."""
    params = AgentParams()
    if args.run_config:
        path = Path(args.run_config)
        try:
            text = path.read_text()
        except OSError as e:
            raise ParamError(f"--run-config {path}: {e}") from None
        params = from_toml_text(text, str(path))
        log.info("parameters from %s", path)
    elif args.info_timeout > 0:
        info = query_world_info(session, keys, args.info_timeout, stop, log)
        if info is None:
            log.info("no world/info within %.1f s: default parameters", args.info_timeout)
        elif info.config:
            params = from_toml_text(info.config, "world/info config")
            log.info("parameters from the world/info config of run %r", info.name)
        else:
            params = params.replace(rv=info.rv, radius=info.robot_radius, dt=info.dt)
    if args.kind:
        params = params.replace(kind=args.kind)
    if args.v_max is not None:
        params = params.replace(v_max=args.v_max)
    for item in args.param:
        params = parse_override(item, params)
    return params


class AgentNode:
    """The process loop around a :class:`Behaviour`: decode, step, publish."""

    def __init__(self, session, keys: Keys, rid: int, params: AgentParams, live: bool,
                 log: logging.Logger):
        self.session, self.keys, self.rid, self.p, self.live, self.log = (
            session, keys, rid, params, live, log)
        self.beh = Behaviour(params, rid)
        self.rx = Receiver(log)
        self.mailbox = Mailbox()
        self.k_sense, self.k_task, self.k_odom = keys.sense(rid), keys.task(rid), keys.odom(rid)
        self.subs = []
        self.token = None
        self.seq = 0
        self.ticks = 0
        self.skipped = 0
        self.errors = 0
        self.last_pose: list[float] = []
        self.last_t = 0.0
        self.last_status = 0.0
        self.last_tick: int | None = None
        self.last_cmd: bytes | None = None

    def open(self) -> None:
        s, k = self.session, self.keys
        self.token = s.liveliness().declare_token(k.alive("robot", self.rid))
        self.pub_cmd = publisher(s, k.cmd_vel(self.rid), block=True, express=True)
        self.pub_status = publisher(s, k.status(self.rid), block=True)
        self.pub_pose = publisher(s, k.pose(self.rid), block=False)
        for key in (self.k_sense, self.k_task, self.k_odom):
            self.subs.append(s.declare_subscriber(key, self.mailbox.callback))

    def close(self) -> None:
        for sub in self.subs:
            try:
                sub.undeclare()
            except Exception:
                pass
        self.subs = []
        if self.token is not None:
            try:
                self.token.undeclare()
            except Exception:
                pass
            self.token = None

    def _invalid(self, key: str, why: str) -> None:
        self.rx.invalid[key] += 1
        if key not in self.rx._logged:
            self.rx._logged.add(key)
            self.log.warning("dropping a message on %s: %s (further ones are counted)", key, why)

    def publish_status(self) -> None:
        self.seq += 1
        st = Status(robot=self.rid, seq=self.seq, t=self.last_t, kind=self.p.kind,
                    live=self.live, pose=self.last_pose, **self.beh.status())
        self.pub_status.put(st.encode())
        self.beh.changed = False
        self.last_status = time.monotonic()

    def handle(self, items) -> None:
        """Handle a batch from the mailbox: tasks and odometry in order, then the newest
        Sense (older ones in the same batch are already late)."""
        sense = None
        for key, payload, _kind in items:
            if key == self.k_sense:
                msg = self.rx.decode(key, payload, Sense)
                if msg is None:
                    continue
                if msg.robot != self.rid:
                    self._invalid(key, f"Sense.robot {msg.robot} is not {self.rid}")
                    continue
                if sense is not None:
                    self.skipped += 1
                sense = msg
            elif key == self.k_task:
                msg = self.rx.decode(key, payload, Task)
                if msg is None:
                    continue
                if msg.robot != self.rid:
                    self._invalid(key, f"Task.robot {msg.robot} is not {self.rid}")
                    continue
                if self.beh.on_task(msg):
                    self.log.info("task %d: %s vertex %d", msg.task_id, msg.kind, msg.vertex)
            elif key == self.k_odom:
                msg = self.rx.decode(key, payload, Pose)
                if msg is None:
                    continue
                self.last_pose = [msg.x, msg.y, msg.theta]
                relay = Pose(robot=self.rid, t=msg.t, x=msg.x, y=msg.y, theta=msg.theta,
                             source="agent")
                self.pub_pose.put(relay.encode())
        if sense is not None:
            self.tick(sense)

    def tick(self, sense: Sense) -> None:
        if sense.tick == self.last_tick and self.last_cmd is not None:
            # the world re-sent a tick we answered (lost reply?): answer again, don't re-step
            self.pub_cmd.put(self.last_cmd)
            self.skipped += 1
            return
        try:
            cmd = self.beh.step(sense)
        except Exception:  # a bug must not take the robot down: stop and say so once
            self.errors += 1
            if self.errors == 1:
                self.log.exception("behaviour error at tick %d (robot stops)", sense.tick)
            cmd = None
        out = CmdVel(robot=self.rid, tick=sense.tick)
        if cmd is not None:
            out.vx, out.vy, out.wz = cmd.vx, cmd.vy, cmd.wz
        self.last_cmd = out.encode()
        self.last_tick = sense.tick
        self.pub_cmd.put(self.last_cmd)
        self.ticks += 1
        self.last_t = sense.t
        if self.beh.changed or self.ticks % self.p.status_every == 0:
            self.publish_status()

    def stop_robot(self) -> None:
        try:
            self.pub_cmd.put(CmdVel(robot=self.rid, tick=-1).encode())
        except Exception:
            pass


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    log = setup_logging(args.log_level, f"swarmcover.agent.{args.id}")
    if args.id < 0:
        log.error("--id %d: must be >= 0", args.id)
        return 2
    keys = keys_from_args(args)
    node = None
    with Shutdown() as stop:  # installed first: a signal during start-up is a clean exit
        try:
            session = open_session(args)
        except (ValueError, ConnectionError) as e:
            log.error("%s", e)
            return 2
        try:
            try:
                params = resolve_params(args, session, keys, stop, log)
            except ParamError as e:
                log.error("%s", e)
                return 2
            if stop.is_set():
                return 0
            node = AgentNode(session, keys, args.id, params, args.live, log)
            node.open()
            node.publish_status()
            print(f"READY agent {args.id} kind={params.kind}", flush=True)
            log.info("robot %d up (%s, v_max %.2f m/s, rv %.2f m)", args.id, params.kind,
                     params.v_max, params.rv)
            parent = args.parent_pid
            mb = node.mailbox
            while not stop.is_set():
                item = mb.get(timeout=0.2)
                if item is not None:
                    node.handle([item] + mb.drain())
                if parent is not None and os.getppid() != parent:
                    log.warning("parent %d is gone: stopping", parent)
                    break
                if time.monotonic() - node.last_status > HEARTBEAT_S:
                    node.publish_status()
            node.stop_robot()
            log.info("robot %d stopped: %d ticks, %d skipped or repeated, %d invalid messages, "
                     "%d behaviour errors", args.id, node.ticks, node.skipped,
                     node.rx.invalid_total, node.errors)
        finally:
            if node is not None:
                node.close()
            session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

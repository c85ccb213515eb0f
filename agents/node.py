"""``swarmcover agent --id N``: one robot's onboard computer, as one OS process.

Subscribes to its Sense (robot/N/sense), Task (robot/N/task) and body pose (robot/N/odom,
telemetry only); publishes one CmdVel per Sense (same tick, at once: a lockstep world waits
for it; ``idle`` when the robot holds still with nothing to do, and a lockstep world then
senses it only when something near it moves, world/wake.py), its Status (every ``status_every`` Sense ticks and on every state/task change,
stamped with the tick, published before the tick's CmdVel, whose status_seq names it; once
at start; and, except in lockstep, once a second while no Sense arrives) and the relay of
its body pose (Pose, source "agent", on robot/N/pose).
Tasks: a Sense with task_id >= 0 (lockstep, coordinator in the barrier) says which task the
coordinator sent last before that tick: the agent applies its tasks up to that one, in
order, before it steps (waiting up to TASK_WAIT_S for one still in flight), and keeps later
ones for a later tick. Otherwise tasks apply as they arrive. Holds the liveliness token
alive/robot/N, and avail/robot/N until its first Sense: an agent with no body yet (started
by hand, on any host) is *available*, and the coordinator places available agents before it
asks ``run`` for new processes. An id another agent of the swarm already holds is refused at
start (exit 2), and an agent still without a body says so every BODILESS_NOTICE_S. Steering uses bearings, identities, touch and tasks only
(agents/behaviours.py); the pose is never read by it.

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

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, Pose, Sense, Task
from swarmcover.bus.node import ready, run_node
from swarmcover.bus.session import (Mailbox, Receiver, Shutdown, add_zenoh_args, publisher, query_world_info,
                         undeclare)

from .core import AgentCore
from .params import ROBOT_KINDS, AgentParams, ParamError, from_toml_text, parse_override

HEARTBEAT_S = 1.0
TASK_WAIT_S = 2.0    # wall seconds a Sense waits for the task it announces
BODILESS_NOTICE_S = 30.0   # wall seconds between "no body yet" notices of an available agent
IDLE_WAIT_S = 0.5    # wall seconds the loop sleeps with nothing to do (an idle robot in a
                     # lockstep world gets a Sense only every few seconds: world/wake.py)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover agent", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--id", type=int, required=True, help="robot id (>= 0)")
    p.add_argument("--kind", choices=ROBOT_KINDS, default=None,
                   help="override [robots].kind of the run config")
    p.add_argument("--reserve", action="store_true",
                   help="started ahead of its robot by `swarmcover run` (its reserve): waits "
                        "for a body without offering itself as available")
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


def world_mode(args, session, keys: Keys, stop: Shutdown, log: logging.Logger) -> str | None:
    """The run's clock mode ("lockstep"/"realtime") from the run config or the world, None
    if unknown. Lockstep agents send no wall-clock heartbeats (they would make the
    coordinator's input depend on timing)."""
    try:
        if args.run_config:
            import tomllib
            from swarmcover.world.config import WorldConfig
            raw = tomllib.loads(Path(args.run_config).read_text())
            return str(raw.get("world", {}).get("mode", WorldConfig().mode))
        if args.info_timeout > 0:
            info = query_world_info(session, keys, args.info_timeout, per_query=1.0, stop=stop, logger=log)
            return info.mode if info is not None else None
    except Exception as e:  # the parameters' loader reports a bad config
        log.debug("clock mode unknown: %s", e)
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
        info = query_world_info(session, keys, args.info_timeout, per_query=1.0, stop=stop, logger=log)
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
    """The process loop around an :class:`agents.core.AgentCore`: decode, step, publish."""

    def __init__(self, session, keys: Keys, rid: int, params: AgentParams, live: bool,
                 log: logging.Logger, lockstep: bool = False, reserve: bool = False):
        self.session, self.keys, self.rid, self.p, self.live, self.log = (
            session, keys, rid, params, live, log)
        self.lockstep = lockstep
        self.reserve = reserve   # run's reserve: its robot's id is run's to give, not ours
        self.core = AgentCore(params, rid, live=live, log=log)
        self.beh = self.core.beh
        self.rx = Receiver(log)
        self.mailbox = Mailbox()
        self.k_sense, self.k_task, self.k_odom = keys.sense(rid), keys.task(rid), keys.odom(rid)
        self.subs = []
        self.token = None
        self.skipped = 0
        self.last_pose: list[float] = []
        self.last_status = 0.0
        self.last_tick: int | None = None
        self.last_cmd: bytes | None = None
        self.barrier: bool | None = None     # None until the first Sense says
        self.tasks: list[list] = []          # received, not applied yet: [task, senses seen]
        self.applied: list[int] = []         # ids of the last tasks applied
        self.held: Sense | None = None       # a Sense waiting for its announced task
        self.held_since = 0.0
        self.task_waits = 0
        self.avail_token = None
        self.bodiless_since = time.monotonic()

    def got_body(self) -> None:
        """The first Sense: the world has a body for this robot; no longer available."""
        undeclare(self.avail_token)
        self.avail_token = None

    def open(self) -> None:
        s, k = self.session, self.keys
        # available (no body yet) before alive: a coordinator that sees both in order never
        # takes a waiting agent for a robot of its swarm; dropped with the first Sense
        if not self.reserve:
            self.avail_token = s.liveliness().declare_token(k.avail(self.rid))
        self.token = s.liveliness().declare_token(k.alive("robot", self.rid))
        self.pub_cmd = publisher(s, k.cmd_vel(self.rid), block=True, express=True)
        self.pub_status = publisher(s, k.status(self.rid), block=True)
        self.pub_pose = publisher(s, k.pose(self.rid), block=False)
        for key in (self.k_sense, self.k_task, self.k_odom):
            self.subs.append(s.declare_subscriber(key, self.mailbox.callback))

    def close(self) -> None:
        undeclare(*self.subs, self.avail_token, self.token)
        self.subs, self.avail_token, self.token = [], None, None

    def _invalid(self, key: str, why: str) -> None:
        self.rx.invalid[key] += 1
        if key not in self.rx._logged:
            self.rx._logged.add(key)
            self.log.warning("dropping a message on %s: %s (further ones are counted)", key, why)

    def publish_status(self, tick: int = -1) -> None:
        self._put_status(self.core.status(tick, self.last_pose))

    def _put_status(self, st) -> None:
        self.pub_status.put(st.encode())
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
                self.tasks.append([msg, 0])
                if not self.barrier:  # no barrier (or no Sense yet): apply it now
                    self._apply_tasks(len(self.tasks))
            elif key == self.k_odom:
                msg = self.rx.decode(key, payload, Pose)
                if msg is None:
                    continue
                self.last_pose = [msg.x, msg.y, msg.theta]
                relay = Pose(robot=self.rid, t=msg.t, x=msg.x, y=msg.y, theta=msg.theta,
                             source="agent")
                self.pub_pose.put(relay.encode())
        if sense is not None:
            if self.avail_token is not None:  # once: per-Sense work is the swarm's budget
                self.got_body()
            if self.held is not None and sense.tick != self.held.tick:
                self.skipped += 1
            self.held = None
            self.tick(sense)
        elif self.held is not None:
            self.tick(self.held)

    def _apply_tasks(self, n: int) -> None:
        """Apply the first ``n`` received tasks, in order."""
        todo, self.tasks = self.tasks[:n], self.tasks[n:]
        for msg, _ in todo:
            self.applied = (self.applied + [msg.task_id])[-16:]
            if self.beh.on_task(msg):
                self.log.info("task %d: %s vertex %d", msg.task_id, msg.kind, msg.vertex)

    def _tasks_for(self, sense: Sense) -> bool:
        """Apply the tasks due at this Sense; False if its announced task is still in
        flight (the Sense is held)."""
        self.barrier = sense.task_id >= 0
        if not self.barrier:
            self._apply_tasks(len(self.tasks))
            return True
        ids = [t.task_id for t, _ in self.tasks]
        n = 0
        if sense.task_id > 0 and sense.task_id not in self.applied:
            if sense.task_id in ids:
                n = ids.index(sense.task_id) + 1
            else:
                wall = time.monotonic()
                if self.held is None or self.held.tick != sense.tick:
                    self.held, self.held_since = sense, wall
                if wall - self.held_since < TASK_WAIT_S:
                    return False
                self.task_waits += 1
                self.log.warning("tick %d: task %d announced but not received within %.0f s: "
                                 "stepping without it (not repeatable)", sense.tick,
                                 sense.task_id, TASK_WAIT_S)
        # a task no Sense announced after two ticks was sent outside the barrier
        for k in range(n, len(self.tasks)):
            self.tasks[k][1] += 1
            if self.tasks[k][1] > 2:
                n = k + 1
        self._apply_tasks(n)
        self.held = None
        return True

    def tick(self, sense: Sense) -> None:
        if sense.tick == self.last_tick and self.last_cmd is not None:
            # the world re-sent a tick we answered (lost reply?): answer again, don't re-step
            self.pub_cmd.put(self.last_cmd)
            self.skipped += 1
            return
        if not self._tasks_for(sense):
            return
        cmd, st = self.core.step(sense, self.last_pose)
        if st is not None:
            self._put_status(st)
        # after the tick's status: its seq tells a lockstep world (and so the coordinator)
        # which statuses this tick produced
        out = CmdVel(robot=self.rid, tick=sense.tick, status_seq=self.core.seq,
                     idle=self.core.idle)
        if cmd is not None:
            out.vx, out.vy, out.wz = cmd.vx, cmd.vy, cmd.wz
        self.last_cmd = out.encode()
        self.last_tick = sense.tick
        self.pub_cmd.put(self.last_cmd)

    def stop_robot(self) -> None:
        try:
            self.pub_cmd.put(CmdVel(robot=self.rid, tick=-1).encode())
        except Exception:
            pass


def id_taken(session, keys: Keys, rid: int, timeout: float = 2.0) -> bool:
    """Does another agent of this swarm already hold robot ``rid``'s liveliness token?
    (Ids are unique by refusal: a second agent with the same id would steer one body.)"""
    try:
        replies = session.liveliness().get(keys.alive("robot", rid), timeout=timeout)
        return any(r.ok is not None for r in replies)
    except Exception:  # no answer is no clash: the router would have known the token
        return False


def _check(args) -> None:
    if args.id < 0:
        raise ValueError(f"--id {args.id}: must be >= 0")


def _serve(args, session, keys, stop) -> int:
    log = logging.getLogger(f"swarmcover.agent.{args.id}")
    node = None
    try:
        try:
            params = resolve_params(args, session, keys, stop, log)
        except ParamError as e:
            log.error("%s", e)
            return 2
        if stop.is_set():
            return 0
        if id_taken(session, keys, args.id):
            log.error("robot id %d is taken in swarm %s: another agent already holds %s; "
                      "start this one with another --id (or let `swarmcover run` pick ids)",
                      args.id, keys.prefix, keys.alive("robot", args.id))
            return 2
        lockstep = world_mode(args, session, keys, stop, log) == "lockstep"
        node = AgentNode(session, keys, args.id, params, args.live, log, lockstep=lockstep,
                         reserve=args.reserve)
        node.open()
        node.publish_status()
        ready(f"agent {args.id} kind={params.kind}")
        log.info("robot %d up (%s, v_max %.2f m/s, rv %.2f m)", args.id, params.kind,
                 params.v_max, params.rv)
        parent = args.parent_pid
        mb = node.mailbox
        while not stop.is_set():
            item = mb.get(timeout=IDLE_WAIT_S if node.held is None else 0.02)
            if item is not None or node.held is not None:
                node.handle(([item] if item is not None else []) + mb.drain())
            if parent is not None and os.getppid() != parent:
                log.warning("parent %d is gone: stopping", parent)
                break
            if not node.lockstep and time.monotonic() - node.last_status > HEARTBEAT_S:
                node.publish_status()
            if node.avail_token is not None and \
                    time.monotonic() - node.bodiless_since > BODILESS_NOTICE_S:
                node.bodiless_since = time.monotonic()
                log.warning("robot %d has no body yet: available, waiting for the "
                            "coordinator to place it (is a run going in swarm %s?)",
                            args.id, keys.prefix)
        if node.live or node.core.ticks:   # a virtual robot never sensed has no body to stop
            node.stop_robot()
        log.info("robot %d stopped: %d ticks, %d skipped or repeated, %d invalid messages, "
                 "%d behaviour errors, %d ticks without an announced task", args.id,
                 node.core.ticks, node.skipped, node.rx.invalid_total, node.core.errors,
                 node.task_waits)
    finally:
        if node is not None:
            node.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover agent", __doc__, build_parser(), _serve, argv=argv,
                    logger=lambda a: f"swarmcover.agent.{a.id}", before_session=_check)


if __name__ == "__main__":
    sys.exit(main())

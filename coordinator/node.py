"""``swarmcover coordinator CONFIG``: the deployment-cycle process.

A thin loop around :class:`coordinator.deployer.Deployer`: it decodes agent statuses,
liveliness changes and the world clock, advances the deployer at simulated time, and
publishes the tasks, spawn/remove requests and the per-cycle complex it asks for. All
timeouts are in simulated seconds, so a slow lockstep run never times out spuriously.
A restarted coordinator rebuilds its state from the agents' statuses and resumes.

Lockstep: the coordinator is part of the world's barrier, so a run is repeatable. At each
Clock (tick k, sim time t_k) it applies the roster's changes (agents that joined or left),
then exactly the statuses the Clock announces (per agent, those up to the seq its command of
tick k-1 reported; it waits for any still in flight), sorted by (robot, seq), steps the
deployer at t_k, publishes its tasks, spawns and removes, and acks tick k on coord/ack
(CoordAck, listing them). Nothing depends on when a message arrived.
Realtime: it acts on what has arrived, at the world's clock.
The clock is trusted only when it moves forward by plausible steps (:class:`ClockTrust`): a
forged jump is ignored and counted, so no single packet can freeze the deployer's time.
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

import zenoh

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import Clock, Status, WorldInfo
from swarmcover.bus.node import run_node
from swarmcover.bus.session import Mailbox, Receiver, Shutdown, publisher, query_world_info
from swarmcover.bus.trust import SignedPublisher, key_from_env

from .actions import Done, PublishComplex, RemoveRobot, RequestStatus, SendTask, SpawnRobot
from .config import CoordinatorConfig
from .core import CoordinatorCore, TickSync, robot_kinds_from_config
from .deployer import Deployer

__all__ = ["ClockTrust", "TickSync", "main", "robot_kinds_from_config"]

log = logging.getLogger("swarmcover.coordinator")
STATUS_WAIT_S = 5.0   # lockstep: wall seconds to wait for statuses a Clock announced


class ClockTrust:
    """Accepts a world Clock only if it is consistent (t = tick * dt) and moves forward by a
    plausible step from the last accepted one: at most ``1 + max_rate * wall seconds
    elapsed`` ticks. A clock that fails is ignored (``rejected`` counts them). Should the
    first accepted clock itself have been forged, ``rebase_after`` consecutive clocks that
    are plausible among themselves (a live world) replace it. Pure: wall times are passed in.
    """

    def __init__(self, dt: float | None, max_rate: float = 2000.0, rebase_after: int = 20):
        self.dt = dt
        self.max_rate = float(max_rate)
        self.rebase_after = int(rebase_after)
        self.tick: int | None = None
        self.wall = 0.0
        self.rejected = 0
        self._chain: list[tuple[int, float]] = []

    def _plausible(self, tick: int, wall: float, ref_tick: int, ref_wall: float) -> bool:
        return ref_tick < tick <= ref_tick + 1 + self.max_rate * max(0.0, wall - ref_wall)

    def check(self, clk: Clock, wall: float) -> str:
        """'new' (accepted, later than before), 'same' (the last tick again) or 'bad'."""
        if self.dt is not None and abs(clk.t - clk.tick * self.dt) > 1e-6 * max(1.0, clk.t):
            self.rejected += 1
            return "bad"
        if self.tick is None or self._plausible(clk.tick, wall, self.tick, self.wall):
            self.tick, self.wall = clk.tick, wall
            self._chain = []
            return "new"
        if clk.tick == self.tick:
            return "same"
        self.rejected += 1
        ch = self._chain
        if ch and not self._plausible(clk.tick, wall, *ch[-1]):
            ch.clear()
        ch.append((clk.tick, wall))
        if len(ch) >= self.rebase_after:
            log.warning("clock: %d consecutive clocks disagree with tick %d: following them",
                        len(ch), self.tick)
            self.tick, self.wall = clk.tick, wall
            ch.clear()
            return "new"
        return "bad"


def load_run_config(path: str | None, info: WorldInfo | None):
    """The run config: the world's resolved one if it answered, else the file."""
    from swarmcover.world.config import load_config, loads_config
    if info is not None and info.config:
        return loads_config(info.config, path="world/info")
    if path is None:
        raise SystemExit("swarmcover coordinator: no CONFIG given and the world did not "
                         "answer on world/info")
    return load_config(path)


def _args(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_config", metavar="CONFIG", nargs="?", help="run config (TOML or ROS map YAML); default: "
                   "the world's resolved config from world/info")
    p.add_argument("--epoch", type=int, default=None,
                   help="task-id epoch (default: from the clock; a restart gets a new one)")
    p.add_argument("--world-timeout", type=float, default=30.0,
                   help="seconds to wait for world/info (default 30)")
    p.add_argument("--exit-on-done", action="store_true",
                   help="exit once coverage is certified (default: keep watching for failures)")


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover coordinator", __doc__, _args, _serve, argv=argv,
                    logger="swarmcover.coordinator")


def _serve(args, session: zenoh.Session, keys: Keys, stop: Shutdown) -> int:
    info = query_world_info(session, keys, args.world_timeout, logger=log)
    if info is None:
        log.warning("world/info did not answer within %.0f s; using %s", args.world_timeout,
                    args.run_config)
    cfg = load_run_config(args.run_config, info)
    ccfg = CoordinatorConfig.from_section(cfg.section("coordinator"), rv=cfg.rv, where=cfg.path)
    if info is not None and info.sources:
        headings = [info.sources[k + 2] for k in range(0, len(info.sources), 3)]
    else:
        headings = [s[2] for s in cfg.map.sources] or [0.0]
    epoch = args.epoch if args.epoch is not None else int(time.time()) % 100_000
    dep = Deployer(ccfg, sources=headings, epoch=epoch, robot_kind=robot_kinds_from_config(cfg),
                   robot_radius=cfg.robots.radius)

    lockstep = ((info.mode if info is not None else cfg.world.mode) == "lockstep")
    dt = info.dt if info is not None else cfg.world.dt
    trust = ClockTrust(dt, max_rate=max(2000.0, 4.0 * cfg.world.rtf / dt))
    core = CoordinatorCore(dep)
    sync = core.sync
    rx = Receiver(log)
    mb = Mailbox()
    subs = [
        session.declare_subscriber(keys.status("*"), mb.callback),
        session.declare_subscriber(keys.clock, mb.callback),
        session.liveliness().declare_subscriber(keys.avail_robots(), mb.callback, history=True),
        session.liveliness().declare_subscriber(keys.alive_robots(), mb.callback, history=True),
    ]
    token = session.liveliness().declare_token(keys.alive("coordinator", "main"))
    # signed (bus.trust): run accepts a Complex or a Spawn only from this session
    run_key = key_from_env()
    pub_complex = SignedPublisher(publisher(session, keys.complex), run_key)
    pub_spawn = SignedPublisher(publisher(session, keys.spawn), run_key)
    pub_remove = publisher(session, keys.remove)
    pub_ack = publisher(session, keys.coord_ack)
    task_pubs: dict[int, zenoh.Publisher] = {}
    now = 0.0
    clocked = False
    clocks: list[Clock] = []      # lockstep: accepted clocks not yet handled, in order
    wait_since: float | None = None
    last_ack: tuple[int, bytes] | None = None
    status_waits = 0
    busy_s, ticks = 0.0, 0
    print(f"READY coordinator epoch {epoch} zid {session.zid()}", flush=True)
    log.info("coordinator up: swarm %s, rv %.2f, %d source(s), push_mode %s, %s", keys.swarm,
             ccfg.rv, len(headings), ccfg.push_mode,
             "lockstep (in the world's barrier)" if lockstep else "realtime")
    rc = 0

    def decode(key: str, rel: str, payload: bytes):
        """A clock or status sample (``rel``: its key relative to the swarm) -> its message,
        or None (invalid: counted by rx)."""
        if rel == "world/clock":
            return rx.decode(key, payload, Clock)
        msg = rx.decode(key, payload, Status)
        if msg is not None and keys.robot_id(key) != msg.robot:
            rx.invalid[key] += 1
            return None
        return msg

    def on_clock(clk: Clock) -> str:
        verdict = trust.check(clk, time.monotonic())
        if verdict == "bad" and trust.rejected == 1:
            log.warning("ignoring a clock that does not follow the world's (tick %d, t %.3f; "
                        "last tick %s): further ones are counted", clk.tick, clk.t, trust.tick)
        return verdict

    def execute(actions, ack=None) -> None:
        """Publish the deployer's actions; in lockstep then their ack."""
        nonlocal rc, last_ack
        for action in actions:
            match action:
                case SendTask(robot=rid, task=task):
                    pub = task_pubs.get(rid)
                    if pub is None:
                        pub = task_pubs[rid] = publisher(session, keys.task(rid))
                    pub.put(task.encode())
                case SpawnRobot(spawn=sp):
                    log.info("spawning robot %d at source %d", sp.robot, sp.source)
                    pub_spawn.put(sp.encode())
                case RemoveRobot(remove=rm):
                    pub_remove.put(rm.encode())
                case RequestStatus():
                    pass   # in the ack (lockstep); without a barrier every robot is sensed
                case PublishComplex(complex=cx):
                    pub_complex.put(cx.encode())
                    log.info("cycle %d: robots %d, complex %d vertices / %d edges / %d "
                             "triangles, frontier %d, obstacle %d, redundant %d, certified %s",
                             cx.cycle, cx.robots, len(cx.vertices), len(cx.edges) // 2,
                             len(cx.triangles) // 3, len(cx.frontier), len(cx.obstacle),
                             len(cx.redundant), cx.certified)
                case Done(certified=ok):
                    log.info("done: %s", dep.summary())
                    print(f"DONE certified={ok}", flush=True)
                    if args.exit_on_done:
                        stop.set()
                    rc = 0 if ok else 1
                case _:
                    raise TypeError(f"unknown deployer action {action!r}")
        if ack is not None:
            last_ack = (ack.tick, ack.encode())
            pub_ack.put(last_ack[1])

    def boundary(clk: Clock) -> None:
        """Lockstep: the deployer's step of tick clk.tick (CoordinatorCore.boundary)."""
        nonlocal busy_s, ticks
        t0 = time.monotonic()
        execute(*core.boundary(clk))
        if dep.done and not args.exit_on_done:
            dep.reopen_if_needed(clk.t)
        busy_s += time.monotonic() - t0
        ticks += 1

    try:
        while not stop.is_set():
            item = mb.get(0.05 if not clocks else 0.005)
            items = ([item] if item else []) + mb.drain()
            for key, payload, kind in items:
                rel = keys.relative(key)
                if rel.startswith("avail/robot/"):
                    # an agent without a body (joined by hand): outside the barrier, as it
                    # comes (hand-joined agents make a lockstep run unrepeatable anyway)
                    rid = keys.robot_id(key)
                    if rid is not None:
                        dep.on_available(rid, kind == zenoh.SampleKind.PUT)
                    continue
                if rel.startswith("alive/robot/"):
                    rid = keys.robot_id(key)
                    if rid is None:
                        continue
                    if lockstep:   # the Clock's roster, except for live robots
                        sync.add_alive(rid, kind == zenoh.SampleKind.PUT)
                    else:
                        dep.on_alive(rid, kind == zenoh.SampleKind.PUT, now)
                    continue
                msg = decode(key, rel, payload)
                if msg is None:
                    continue
                if isinstance(msg, Status):
                    if lockstep:
                        sync.add_status(msg)
                    else:
                        dep.on_status(msg)
                    continue
                verdict = on_clock(msg)
                if verdict == "bad":
                    continue
                clocked = True
                if not lockstep or msg.mode != "lockstep":
                    if verdict == "new":
                        now = msg.t
                elif verdict == "new":
                    clocks.append(msg)
                elif last_ack is not None and last_ack[0] == msg.tick:
                    pub_ack.put(last_ack[1])   # the world re-sent it: our ack was lost
            if lockstep:
                while clocks and not stop.is_set():
                    clk = clocks[0]
                    miss = sync.missing(clk) if len(clocks) == 1 else []
                    if miss:
                        wall = time.monotonic()
                        if wait_since is None:
                            wait_since = wall
                        if wall - wait_since < STATUS_WAIT_S:
                            break   # the statuses are on their way
                        status_waits += 1
                        log.warning("tick %d: statuses of robots %s announced but not "
                                    "received within %.0f s: going on without them (not "
                                    "repeatable)", clk.tick, miss[:10], STATUS_WAIT_S)
                    wait_since = None
                    clocks.pop(0)
                    now = clk.t
                    boundary(clk)
                continue
            if not clocked:
                continue  # the deployer's time is the world's: wait for its clock
            execute(dep.step(now))
            if dep.done and not args.exit_on_done:
                dep.reopen_if_needed(now)
    finally:
        for s in subs:
            s.undeclare()
        for pub in list(task_pubs.values()) + [pub_complex, pub_spawn, pub_remove, pub_ack]:
            pub.undeclare()
        token.undeclare()
        # what arrived but was not handled before the stop is still accounted for: invalid
        # messages are counted, valid ones are too late to act on
        for key, payload, _kind in mb.drain():
            rel = keys.relative(key)
            if not rel.startswith("alive/robot/"):
                decode(key, rel, payload)
        if rx.invalid_total:
            log.warning("dropped %d invalid messages", rx.invalid_total)
        if trust.rejected:
            log.warning("ignored %d implausible clocks", trust.rejected)
        if ticks:
            log.info("lockstep: %d ticks, %.1f s deciding (%.2f ms a tick)", ticks, busy_s,
                     1e3 * busy_s / ticks)
        if status_waits:
            log.warning("%d ticks went on without announced statuses", status_waits)
    return rc


if __name__ == "__main__":
    sys.exit(main())

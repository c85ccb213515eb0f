"""``swarmcover coordinator CONFIG``: the deployment-cycle process.

A thin loop around :class:`coordinator.deployer.Deployer`: it decodes agent statuses,
liveliness changes and the world clock, advances the deployer at simulated time, and
publishes the tasks, spawn/remove requests and the per-cycle complex it asks for. All
timeouts are in simulated seconds, so a slow lockstep run never times out spuriously.
A restarted coordinator rebuilds its state from the agents' statuses and resumes.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time

import zenoh

from bus.keys import Keys
from bus.messages import Clock, Complex, Status, WorldInfo
from bus.session import (Mailbox, Receiver, Shutdown, add_zenoh_args, keys_from_args,
                         open_session, publisher, setup_logging)

from .config import CoordinatorConfig
from .deployer import Deployer

log = logging.getLogger("swarmcover.coordinator")


def robot_kinds_from_config(cfg) -> callable:
    """Robot id -> (kind, live) from [robots].kind and the live robots of [hwbridge]."""
    default = cfg.robots.kind
    live = {}
    for r in cfg.section("hwbridge").get("robots", []) or []:
        if isinstance(r, dict) and isinstance(r.get("id"), int):
            live[r["id"]] = str(r.get("kind", "diffdrive"))
    return lambda rid: (live[rid], True) if rid in live else (default, False)


def query_world_info(session: zenoh.Session, keys: Keys, timeout: float) -> WorldInfo | None:
    from bus.messages import WireError, decode
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            for reply in session.get(keys.world_info, timeout=min(2.0, timeout)):
                if reply.ok is not None:
                    try:
                        return decode(reply.ok.payload.to_bytes(), WorldInfo)
                    except WireError as e:
                        log.warning("world/info reply invalid: %s", e)
        except Exception as e:  # router not reachable yet etc.
            log.debug("world/info query failed: %s", e)
        time.sleep(0.2)
    return None


def load_run_config(path: str | None, info: WorldInfo | None):
    """The run config: the world's resolved one if it answered, else the file."""
    from world.config import load_config, loads_config
    if info is not None and info.config:
        return loads_config(info.config, path="world/info")
    if path is None:
        raise SystemExit("swarmcover coordinator: no CONFIG given and the world did not "
                         "answer on world/info")
    return load_config(path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover coordinator", description=__doc__)
    p.add_argument("run_config", metavar="CONFIG", nargs="?", help="run config (TOML or ROS map YAML); default: "
                   "the world's resolved config from world/info")
    add_zenoh_args(p)
    p.add_argument("--epoch", type=int, default=None,
                   help="task-id epoch (default: from the clock; a restart gets a new one)")
    p.add_argument("--world-timeout", type=float, default=30.0,
                   help="seconds to wait for world/info (default 30)")
    p.add_argument("--exit-on-done", action="store_true",
                   help="exit once coverage is certified (default: keep watching for failures)")
    p.add_argument("--log-level", default="INFO")
    args = p.parse_args(argv)
    setup_logging(args.log_level, "swarmcover.coordinator")
    keys = keys_from_args(args)
    try:
        session = open_session(args)
    except (ValueError, ConnectionError) as e:
        log.error("%s", e)
        return 2
    with Shutdown() as stop:
        try:
            return _serve(args, session, keys, stop)
        except (ValueError, SystemExit) as e:
            log.error("%s", e)
            return 2
        finally:
            session.close()


def _serve(args, session: zenoh.Session, keys: Keys, stop: Shutdown) -> int:
    info = query_world_info(session, keys, args.world_timeout)
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

    rx = Receiver(log)
    mb = Mailbox()
    subs = [
        session.declare_subscriber(keys.status("*"), mb.callback),
        session.declare_subscriber(keys.clock, mb.callback),
        session.liveliness().declare_subscriber(keys.alive_robots(), mb.callback, history=True),
    ]
    token = session.liveliness().declare_token(keys.alive("coordinator", "main"))
    pub_complex = publisher(session, keys.complex)
    pub_spawn = publisher(session, keys.spawn)
    pub_remove = publisher(session, keys.remove)
    task_pubs: dict[int, zenoh.Publisher] = {}
    now = 0.0
    clocked = False
    print(f"READY coordinator epoch {epoch}", flush=True)
    log.info("coordinator up: swarm %s, rv %.2f, %d source(s), push_mode %s", keys.swarm,
             ccfg.rv, len(headings), ccfg.push_mode)
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

    try:
        while not stop.is_set():
            item = mb.get(0.05)
            items = ([item] if item else []) + mb.drain()
            for key, payload, kind in items:
                rel = keys.relative(key)
                if rel.startswith("alive/robot/"):
                    rid = keys.robot_id(key)
                    if rid is not None:
                        dep.on_alive(rid, kind == zenoh.SampleKind.PUT, now)
                    continue
                msg = decode(key, rel, payload)
                if msg is None:
                    continue
                now = max(now, msg.t)
                if isinstance(msg, Status):
                    dep.on_status(msg)
            if not clocked:
                clocked = any(keys.relative(k) == "world/clock" for k, _, _ in items)
                if not clocked:
                    continue  # the deployer's time is the world's: wait for its clock
            for action in dep.step(now):
                what = action[0]
                if what == "task":
                    _, rid, task = action
                    pub = task_pubs.get(rid)
                    if pub is None:
                        pub = task_pubs[rid] = publisher(session, keys.task(rid))
                    pub.put(task.encode())
                elif what == "spawn":
                    log.info("spawning robot %d at source %d", action[1].robot, action[1].source)
                    pub_spawn.put(action[1].encode())
                elif what == "remove":
                    pub_remove.put(action[1].encode())
                elif what == "complex":
                    cx: Complex = action[1]
                    pub_complex.put(cx.encode())
                    log.info("cycle %d: robots %d, complex %d vertices / %d edges / %d "
                             "triangles, frontier %d, obstacle %d, redundant %d, certified %s",
                             cx.cycle, cx.robots, len(cx.vertices), len(cx.edges) // 2,
                             len(cx.triangles) // 3, len(cx.frontier), len(cx.obstacle),
                             len(cx.redundant), cx.certified)
                elif what == "done":
                    log.info("done: %s", dep.summary())
                    print(f"DONE certified={action[1]}", flush=True)
                    if args.exit_on_done:
                        stop.set()
                    rc = 0 if action[1] else 1
            if dep.done and not args.exit_on_done:
                dep.reopen_if_needed(now)
    finally:
        for s in subs:
            s.undeclare()
        for pub in list(task_pubs.values()) + [pub_complex, pub_spawn, pub_remove]:
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
    return rc


if __name__ == "__main__":
    sys.exit(main())

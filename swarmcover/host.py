"""``swarmcover host --connect ROUTER --capacity N``: this machine offers to start up to N
agents for the runs of a swarm.

It is a Zenoh router of its own (a Python session in router mode, as ``swarmcover router``)
linked to the run's router ROUTER (``swarmcover run --listen ...``, or a ``swarmcover
router`` the run uses with ``--router``) by Zenoh's router-to-router link: the host's router
connects to ROUTER. The agents it starts are clients of the host's router (``--listen``,
default tcp/127.0.0.1:7448, or a free port if that one is taken).

It announces itself with the liveliness token alive/host/NAME and serves host/NAME: an
empty query gets its slots (capacity, the robots it runs); a start request from ``run``
names the robot, its kind and a live robot's limits and carries the run config's text
(the agent reads it with --run-config: the same parameters as the agents run starts on its
own machine); a stop request names a robot, or every robot of a run. A start is refused,
saying why, when every slot is taken or the robot already has an agent here. It reports on
host/NAME/event when one of its agents is ready, fails at start or exits. Give it the
run's --swarm (``run``'s default is the config's name).

Ends: SIGINT/SIGTERM stop its agents, then it exits 0. At start it waits --connect-timeout
seconds for the link to ROUTER (exit 2 if none). If the link is down for longer than
--reconnect-timeout (Zenoh retries it by itself meanwhile), it stops its agents and exits
1 saying so. The agents of a run whose token (alive/run/<id>) has been gone for 10 s are
stopped. Agents stop their robots on the way out, and exit by themselves if the host dies
(they watch their parent). Not with --secure yet.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import logging
import os
import queue
import re
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import IO

import zenoh

from swarmcover.agents.supervisor import Supervisor
from swarmcover.bus.keys import Keys, check_name
from swarmcover.bus.node import UsageError, ready, run_node
from swarmcover.bus.session import DEFAULT_ROUTER, Mailbox, add_zenoh_args, publisher, undeclare
from swarmcover.hosts import (HostBook, HostEvent, HostReply, HostStart, HostStop,
                              HostWireError, agent_flags, decode_request, encode)
from swarmcover.run import _first_error, _free_port, _local

DEFAULT_PORT = 7448
RUN_GONE_S = 10.0          # a run's token gone this long: its agents are stopped
STOP_GRACE_S = 5.0         # SIGTERM -> SIGKILL for the agents
log = logging.getLogger("swarmcover.host")

HOST_ZENOH_HELP = {
    "--config": "Zenoh JSON5 config file (applied first) of the host's router",
    "--mode": "Zenoh mode: a host is always a router (router-to-router link to the run's)",
    "--connect": "the run's router, repeatable (default tcp/127.0.0.1:7447): `swarmcover run "
                 "--listen` or a `swarmcover router`",
    "--listen": "where the host's router listens for the agents it starts, repeatable "
                "(default tcp/127.0.0.1:7448, or a free port if taken)",
    "--cfg": "raw config override of the host's router, repeatable",
    "--swarm": "the run's swarm (env SWARMCOVER_SWARM; default 'default'; `run`'s default "
               "is its config's name)",
    "--connect-timeout": "seconds to wait at start for the link to the run's router "
                         "(default 60)",
    "--secure": "not supported by swarmcover host yet (exit 2)",
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover host", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--capacity", type=int, required=True, metavar="N",
                   help="start at most N agents on this machine (>= 1)")
    p.add_argument("--name", default=None,
                   help="this host's name in the swarm, one key chunk (default: the machine's "
                        "host name)")
    p.add_argument("--log-dir", default=None, metavar="DIR",
                   help="where the agents' logs and the run configs they read go (default "
                        "runs/host-NAME-<time>)")
    p.add_argument("--reconnect-timeout", type=float, default=20.0, metavar="S",
                   help="stop the agents and exit 1 when the link to the run's router has "
                        "been down this long (default 20)")
    p.add_argument("--log-level", default="INFO")
    add_zenoh_args(p, mode="router", helps=HOST_ZENOH_HELP,
                   defaults={"--connect-timeout": 60.0})
    return p


def default_name() -> str:
    """The machine's host name as one key chunk."""
    name = re.sub(r"[^A-Za-z0-9_\-]", "-", socket.gethostname().split(".")[0])[:64]
    return name or "host"


def _check(args) -> None:
    """Flags checked before any connection (exit 2 naming the flag)."""
    from swarmcover.validate import port_free
    if args.capacity < 1:
        raise UsageError(f"--capacity {args.capacity}: must be >= 1")
    if not args.reconnect_timeout > 0:
        raise UsageError(f"--reconnect-timeout {args.reconnect_timeout}: must be > 0")
    if args.secure:
        raise UsageError(f"--secure {args.secure}: swarmcover host does not support the "
                         f"security profile yet (start agents by hand with `swarmcover agent "
                         f"--secure`, see docs/lab-network.md)")
    if args.mode not in (None, "router"):
        raise UsageError(f"--mode {args.mode}: a host is a router (its agents are its clients)")
    args.name = check_name(args.name or default_name())
    if args.connect is None:
        args.connect = [DEFAULT_ROUTER]
    if args.listen is None:
        port = DEFAULT_PORT if port_free(DEFAULT_PORT) else _free_port()
        args.listen = [f"tcp/127.0.0.1:{port}"]


@dataclasses.dataclass
class _Agent:
    robot: int
    run: str
    log_path: Path
    file: IO
    t0: float
    ready: bool = False


class HostNode:
    """The host's loop: answer queries, start and stop agents, watch them, the link and the
    runs. Zenoh callbacks only enqueue; everything else runs on the main thread."""

    def __init__(self, args, session, keys: Keys, log_dir: Path):
        self.args, self.session, self.keys, self.log_dir = args, session, keys, log_dir
        self.name = args.name
        self.book = HostBook(self.name, args.capacity)
        zargs = ["--connect", _local(args.listen[0]), "--swarm", keys.swarm,
                 "--connect-timeout", "10"]
        self.sup = Supervisor(zargs, env=dict(os.environ, SWARMCOVER_WATCH_PARENT="1",
                                              PYTHONUNBUFFERED="1"))
        self.agents: dict[int, _Agent] = {}
        self.queries: queue.Queue = queue.Queue()
        self.runs = Mailbox()
        self.gone: dict[str, float] = {}     # run id -> when its token went away
        self.configs: dict[str, str] = {}    # sha256 of a config text -> its file
        self.ents: list = []
        self.pub_event = None

    # -- set-up and tear-down
    def open(self) -> None:
        s, k = self.session, self.keys
        self.pub_event = publisher(s, k.host_event(self.name), block=True)
        self.ents = [s.declare_queryable(k.host(self.name), self.queries.put_nowait),
                     s.liveliness().declare_subscriber(k.alive_runs(), self.runs.callback,
                                                       history=True),
                     s.liveliness().declare_token(k.alive("host", self.name)),
                     self.pub_event]

    def close(self) -> None:
        self.book.stopping = True
        self.stop(list(self.agents), "the host is stopping")
        undeclare(*self.ents)
        self.ents = []

    # -- requests
    def serve(self, timeout: float) -> None:
        """Answer the queries that came in (waiting up to ``timeout`` s for the first)."""
        try:
            q = self.queries.get(timeout=timeout)
        except queue.Empty:
            return
        while q is not None:
            try:
                self.answer(q)
            finally:
                q.drop()
            try:
                q = self.queries.get_nowait()
            except queue.Empty:
                q = None

    def answer(self, q: "zenoh.Query") -> None:
        payload = q.payload.to_bytes() if q.payload is not None else b""
        if not payload:
            q.reply(q.key_expr, encode(self.book.info()))
            return
        try:
            req = decode_request(payload)
        except HostWireError as e:
            log.warning("refused an invalid request: %s", e)
            q.reply_err(str(e).encode())
            return
        reply = self.start(req) if isinstance(req, HostStart) else self.stop_request(req)
        q.reply(q.key_expr, encode(reply))

    def start(self, req: HostStart) -> HostReply:
        why = self.book.why_not(req)
        if why is None:
            try:
                self._spawn(req)
            except OSError as e:
                why = f"host {self.name} could not start the agent of robot {req.robot}: {e}"
        if why is not None:
            log.warning("refused to start robot %d: %s", req.robot, why)
            return HostReply(ok=False, info=self.book.info(), why=why)
        self.gone.pop(req.run, None)  # a request is proof of life
        return HostReply(ok=True, info=self.book.info(), robots=(req.robot,))

    def _spawn(self, req: HostStart) -> None:
        conf = self._config_file(req.config) if req.config else None
        limits = (req.v_max, req.w_max) if req.v_max and req.w_max else None
        path = self.log_dir / f"agent-{req.robot}.log"
        f = open(path, "ab", buffering=0)
        try:
            self.sup.start(req.robot, agent_flags(req.kind, conf, req.live, limits),
                           stdout=f, stderr=subprocess.STDOUT, watch_ready=True)
        except OSError:
            f.close()
            raise
        self.agents[req.robot] = _Agent(req.robot, req.run, path, f, time.monotonic())
        self.book.add(req.robot, req.run)
        log.info("robot %d: agent started for run %s (%d of %d slots in use)", req.robot,
                 req.run, len(self.book.agents), self.book.capacity)

    def _config_file(self, text: str) -> str:
        """The run config's text as a file the agent reads (one per distinct text)."""
        digest = hashlib.sha256(text.encode()).hexdigest()
        path = self.configs.get(digest)
        if path is None:
            p = self.log_dir / f"config-{digest[:12]}.toml"
            p.write_text(text)
            path = self.configs[digest] = str(p.resolve())
        return path

    def stop_request(self, req: HostStop) -> HostReply:
        robots, why = self.book.to_stop(req)
        if why is not None:
            return HostReply(ok=False, info=self.book.info(), why=why)
        self.stop(robots, f"run {req.run} asked")
        return HostReply(ok=True, info=self.book.info(), robots=tuple(robots))

    # -- agents
    def stop(self, robots: list[int], why: str) -> None:
        if not robots:
            return
        log.info("stopping robots %s (%s)", robots, why)
        for rid, rc in self.sup.stop_many(robots, STOP_GRACE_S, signal.SIGTERM).items():
            self._finish(rid, rc)
        for rid in robots:       # not a child any more (cannot happen: poll finishes them)
            if rid in self.agents:
                self._finish(rid, None)

    def poll(self) -> None:
        """Report agents that became ready (their readiness pipe, bus.node.ready) or exited."""
        starting, running = set(self.sup.starting()), self.sup.running()
        for a in list(self.agents.values()):
            if not a.ready and a.robot not in starting and a.robot in running:
                a.ready = True
                dt = time.monotonic() - a.t0
                log.info("robot %d: agent ready %.2f s after the request", a.robot, dt)
                self._event(a, "ready", start_s=dt)
        for rid, rc in self.sup.poll():
            self._finish(rid, rc)

    def _finish(self, rid: int, rc: int | None) -> None:
        a = self.agents.pop(rid, None)
        if a is None:
            return
        a.file.close()
        self.book.remove(rid)
        if rc is not None and rc > 0 and not _has_ready(a.log_path):  # the log decides
            detail = _first_error(a.log_path)
            log.warning("robot %d: agent exited at start (exit %d): %s", rid, rc, detail)
            self._event(a, "failed", rc=rc, detail=detail)
        else:
            log.info("robot %d: agent exited (%s)", rid, rc)
            self._event(a, "exited", rc=rc)

    def _event(self, a: _Agent, what: str, **kw) -> None:
        ev = HostEvent(robot=a.robot, what=what, info=self.book.info(), run=a.run,
                       detail=str(kw.pop("detail", ""))[:2000], **kw)
        try:
            self.pub_event.put(encode(ev))
        except Exception as e:  # a closing session: the run sees the tokens go anyway
            log.debug("event not sent: %s", e)

    # -- runs and the link
    def watch_runs(self, now: float) -> None:
        for key, _payload, kind in self.runs.drain():
            run = str(key).rsplit("/", 1)[-1]
            if kind == zenoh.SampleKind.PUT:
                self.gone.pop(run, None)
            else:
                self.gone.setdefault(run, now)
        for run, since in list(self.gone.items()):
            if now - since >= RUN_GONE_S:
                del self.gone[run]
                robots = self.book.of_run(run)
                if robots:
                    log.warning("run %s is gone (its token vanished %.0f s ago): stopping its "
                                "%d agents", run, now - since, len(robots))
                    self.stop(robots, "its run is gone")



def linked(session) -> bool:
    """Whether this router has a link to another router (the run's)."""
    try:
        return any(True for _ in session.info.routers_zid())
    except Exception:
        return False


def _has_ready(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            return b"READY agent" in f.read(65536)
    except OSError:
        return False


def _serve(args, session, keys: Keys, stop) -> int:
    ups = ", ".join(args.connect)
    end = time.monotonic() + args.connect_timeout
    while not linked(session):
        if stop.is_set():
            return 0
        if time.monotonic() > end:
            log.error("no link to the run's router at %s within %g s: is `swarmcover run "
                      "--listen ...` or `swarmcover router` running there, and reachable "
                      "from this machine?", ups, args.connect_timeout)
            return 2
        stop.wait(0.1)
    try:
        taken = any(r.ok is not None for r in session.liveliness().get(
            keys.alive("host", args.name), timeout=2.0))
    except Exception:
        taken = False
    if taken:
        log.error("host name %s is taken in swarm %s: another host holds %s; start this one "
                  "with another --name", args.name, keys.swarm, keys.alive("host", args.name))
        return 2
    log_dir = Path(args.log_dir or f"runs/host-{args.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    log_dir.mkdir(parents=True, exist_ok=True)
    node = HostNode(args, session, keys, log_dir)
    node.open()
    ready(f"host {args.name} capacity {args.capacity} router {args.listen[0]} swarm "
          f"{keys.swarm}")
    log.info("host %s: up to %d agents, linked to %s; agents connect to %s; logs in %s",
             args.name, args.capacity, ups, ", ".join(args.listen), log_dir)
    lost_since: float | None = None
    next_link = 0.0
    try:
        while not stop.is_set():
            node.serve(0.01 if any(not a.ready for a in node.agents.values()) else 0.05)
            node.poll()
            now = time.monotonic()
            if now >= next_link:
                next_link = now + 0.5
                if linked(session):
                    if lost_since is not None:
                        log.info("the link to the run's router is back after %.1f s",
                                 now - lost_since)
                        node.gone = {r: now for r in node.gone}  # tokens come back too
                    lost_since = None
                elif lost_since is None:
                    lost_since = now
                    log.warning("lost the link to the run's router at %s: Zenoh retries it; "
                                "giving up after %g s", ups, args.reconnect_timeout)
                elif now - lost_since > args.reconnect_timeout:
                    log.error("no link to the run's router at %s for %.0f s: stopping %d "
                              "agents and exiting (start `swarmcover host` again once a run's "
                              "router is up)", ups, now - lost_since, len(node.agents))
                    return 1
            if lost_since is None:
                node.watch_runs(now)
    finally:
        node.close()
    log.info("host %s stopped", args.name)
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover host", __doc__, build_parser(), _serve, argv=argv,
                    logger="swarmcover.host", mode="router", session_mode="router",
                    before_session=_check)

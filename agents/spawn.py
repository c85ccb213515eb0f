"""``swarmcover spawn N [--first-id K] [--all-or-nothing] [agent flags...]``: start N agent
processes (robot ids K..K+N-1) and supervise them.

Every flag spawn does not know is passed to each agent (e.g. ``--connect``, ``--swarm``,
``--kind``, ``--param``). Prints ``agent <id> pid <pid>`` per child, then
``READY spawn <N>``. SIGINT/SIGTERM/SIGHUP are forwarded to every agent; spawn waits up to
``--grace`` seconds, kills stragglers and exits. A child that dies is reported
(``EXITED agent <id> rc <rc>``); the others keep running, unless ``--all-or-nothing``,
which then stops them all (exit code 1). When every child has exited, spawn exits too.
Agents also exit by themselves if spawn is killed outright (``--parent-pid``).
"""
from __future__ import annotations

import argparse
import signal
import sys

from swarmcover.bus.session import Shutdown, setup_logging

from .supervisor import Supervisor


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover spawn", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                allow_abbrev=False)
    p.add_argument("n", type=int, help="number of agents")
    p.add_argument("--first-id", type=int, default=0, help="first robot id (default 0)")
    p.add_argument("--all-or-nothing", action="store_true",
                   help="if one agent dies, stop them all and exit 1")
    p.add_argument("--grace", type=float, default=5.0,
                   help="seconds to wait for agents to stop before SIGKILL (default 5)")
    p.add_argument("--max-starting", type=int, default=8, metavar="K",
                   help="agents starting at once: the next one starts when one of K is up "
                        "(READY); 500 agents started together on 2 cores timed out "
                        "connecting to the router (default 8; 0: no limit)")
    p.add_argument("--new-session", action="store_true",
                   help="start agents in their own process groups (only spawn gets ^C)")
    p.add_argument("--log-level", default="INFO")
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args, rest = p.parse_known_args(argv)
    log = setup_logging(args.log_level, "swarmcover.spawn")
    if args.n < 1:
        p.error(f"n = {args.n}: must be >= 1")
    if args.first_id < 0:
        p.error(f"--first-id {args.first_id}: must be >= 0")
    if args.max_starting < 0:
        p.error(f"--max-starting {args.max_starting}: must be >= 0")
    if "--id" in rest or any(a.startswith("--id=") for a in rest):
        p.error("--id: spawn assigns robot ids itself (use --first-id)")
    if "--parent-pid" in rest:
        p.error("--parent-pid: spawn sets it itself")
    sup = Supervisor(rest, new_session=args.new_session)
    failed = False
    codes: dict[int, int] = {}
    with Shutdown((signal.SIGINT, signal.SIGTERM, signal.SIGHUP), grace_s=0) as stop:  # supervisor
        try:
            for rid in range(args.first_id, args.first_id + args.n):
                while (args.max_starting and not stop.is_set()
                       and len(sup.starting()) >= args.max_starting):
                    stop.wait(0.02)
                if stop.is_set():
                    break
                pid = sup.start(rid, watch_ready=bool(args.max_starting))
                print(f"agent {rid} pid {pid}", flush=True)
            print(f"READY spawn {args.n}", flush=True)
            while not stop.is_set():
                for rid, rc in sup.poll():
                    codes[rid] = rc
                    print(f"EXITED agent {rid} rc {rc}", flush=True)
                    log.warning("agent %d exited with code %d", rid, rc)
                    if args.all_or_nothing:
                        failed = True
                        stop.set()
                if not sup.running() and not failed:
                    log.info("every agent has exited")
                    break
                stop.wait(0.2)
        finally:
            sig = stop.signum if stop.signum in (signal.SIGINT, signal.SIGTERM) else signal.SIGTERM
            if sup.children:
                log.info("stopping %d agents (signal %d)", len(sup.running()), sig)
            codes.update(sup.stop_all(args.grace, sig))
    if failed:
        return 1
    if stop.signum is not None:
        return 0
    return 0 if all(rc == 0 for rc in codes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())

"""``swarmcover demo``: publish a heartbeat on ``sc/<swarm>/demo`` (smoke test of a router).

Holds a liveliness token ``alive/demo/<pid>`` while it runs.
"""
from __future__ import annotations

import os
import sys
import time

from swarmcover.bus.messages import Demo
from swarmcover.bus.node import UsageError, ready, run_node
from swarmcover.bus.session import publisher


def _args(p) -> None:
    p.add_argument("--rate", type=float, default=10.0, help="messages per second (default 10)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after S seconds (0: never)")


def _check(args) -> None:
    if not args.rate > 0:
        raise UsageError(f"--rate {args.rate}: must be > 0")


def _serve(args, session, keys, stop) -> int:
    token = session.liveliness().declare_token(keys.alive("demo", os.getpid()))
    pub = publisher(session, keys.demo, block=False)
    ready(f"demo {keys.demo}")
    t0 = time.monotonic()
    seq = 0
    while not stop.is_set():
        now = time.monotonic() - t0
        if args.duration and now >= args.duration:
            break
        pub.put(Demo(seq=seq, t=now, text="hello from swarmcover").encode())
        seq += 1
        stop.wait(1.0 / args.rate)
    pub.undeclare()
    token.undeclare()
    print(f"demo sent {seq} messages", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover demo", __doc__, _args, _serve, argv=argv,
                    logger="swarmcover.demo", before_session=_check)

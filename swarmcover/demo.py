"""``swarmcover demo``: publish a heartbeat on ``sc/<swarm>/demo`` (smoke test of a router).

Holds a liveliness token ``alive/demo/<pid>`` while it runs.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from bus.messages import Demo
from bus.session import (Shutdown, add_zenoh_args, keys_from_args, open_session, publisher,
                         setup_logging)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover demo", description=__doc__)
    add_zenoh_args(p)
    p.add_argument("--rate", type=float, default=10.0, help="messages per second (default 10)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after S seconds (0: never)")
    args = p.parse_args(argv)
    log = setup_logging("INFO", "swarmcover.demo")
    if args.rate <= 0:
        p.error("--rate must be > 0")
    keys = keys_from_args(args)
    try:
        session = open_session(args)
    except (ValueError, ConnectionError) as e:
        log.error("%s", e)
        return 2
    with Shutdown() as stop:
        try:
            token = session.liveliness().declare_token(keys.alive("demo", os.getpid()))
            pub = publisher(session, keys.demo, block=False)
            print(f"READY demo {keys.demo}", flush=True)
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
        finally:
            session.close()
    print(f"demo sent {seq} messages", file=sys.stderr)
    return 0

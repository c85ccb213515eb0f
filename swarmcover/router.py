"""``swarmcover router``: a Zenoh router in a Python process.

It relays between the clients of a run (world, coordinator, agents, bridge, tools). Clients
work unchanged against a real ``zenohd`` listening on the same endpoint.
"""
from __future__ import annotations

import argparse
import logging

from bus.session import Shutdown, add_zenoh_args, open_session, setup_logging

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover router", description=__doc__)
    add_zenoh_args(p, mode="router")
    p.add_argument("--log-level", default="INFO")
    args = p.parse_args(argv)
    log = setup_logging(args.log_level, "swarmcover.router")
    if args.listen is None and not args.config:
        args.listen = [DEFAULT_LISTEN]
    if args.connect is None:
        args.connect = []
    try:
        session = open_session(args, mode="router")
    except (ValueError, ConnectionError) as e:
        log.error("%s", e)
        return 2
    with Shutdown() as stop:
        try:
            log.info("router %s listening on %s", session.zid(), ", ".join(args.listen or []))
            print(f"READY router {','.join(args.listen or [])}", flush=True)
            stop.wait()
        finally:
            session.close()
    log.info("router stopped")
    return 0

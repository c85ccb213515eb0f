"""``swarmcover router``: a Zenoh router in a Python process.

It relays between the clients of a run (world, coordinator, agents, bridge, tools). Clients
work unchanged against a real ``zenohd`` listening on the same endpoint.
"""
from __future__ import annotations

import logging

from swarmcover.bus.node import ready, run_node

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
log = logging.getLogger("swarmcover.router")


def _defaults(args) -> None:
    if args.listen is None and not args.config:
        args.listen = [DEFAULT_LISTEN]
    if args.connect is None:
        args.connect = []


def _serve(args, session, keys, stop) -> int:
    log.info("router %s listening on %s", session.zid(), ", ".join(args.listen or []))
    ready(f"router {','.join(args.listen or [])}")
    stop.wait()
    log.info("router stopped")
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover router", __doc__, lambda p: None, _serve, argv=argv,
                    logger="swarmcover.router", mode="router", session_mode="router",
                    before_session=_defaults)

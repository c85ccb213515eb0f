"""The ``swarmcover`` command: dispatches ``swarmcover <command> ...`` to its module.

Each command module exposes ``main(argv: list[str] | None = None) -> int`` and builds its own
argparse parser; modules are imported only when their command runs, so a broken optional
part never breaks the others.
"""
from __future__ import annotations

import importlib
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("swarmcover.run", "one-command coverage run: router, world, coordinator, agents, report"),
    "router": ("swarmcover.router", "embedded Zenoh router (the default hub of a run)"),
    "world": ("swarmcover.world.node", "simulator: pymunk dynamics, emulated cameras and touch, clock"),
    "coordinator": ("swarmcover.coordinator.node", "builds the complex, certifies coverage, plans pushes"),
    "agent": ("swarmcover.agents.node", "one robot: bearing-only controller and behaviours"),
    "spawn": ("swarmcover.agents.spawn", "start N agent processes and supervise them"),
    "host": ("swarmcover.host", "offer this machine to runs: its own router, agents started on request"),
    "hwbridge": ("swarmcover.hwbridge.node", "mix live robots in: mocap -> twin sync, safe command output"),
    "fake-robot": ("swarmcover.hwbridge.fake_robot", "stand-in live robot (differential drive + mocap)"),
    "topics": ("swarmcover.topics", "inspect the swarm's Zenoh topics: list, echo, hz, alive"),
    "record": ("swarmcover.recording.record", "record the swarm's key space to MCAP"),
    "replay": ("swarmcover.recording.replay", "republish an MCAP recording with its original timing"),
    "plot": ("swarmcover.plot", "thesis-style figures and animation from a run folder or MCAP"),
    "view": ("swarmcover.view", "live view of the swarm in the browser"),
    "config": ("swarmcover.configref", "run config reference: defaults (commented TOML), docs, check"),
    "secure": ("swarmcover.secure", "generate certificates, passwords and ACLs for a lab network"),
    "demo": ("swarmcover.demo", "publish a heartbeat (smoke test of a router)"),
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: swarmcover <command> [options]   (swarmcover <command> --help)", "",
             "commands:"]
    lines += [f"  {name:<{width}}  {desc}" for name, (_, desc) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    if argv[0] in ("--version", "-V"):
        from . import __version__
        print(f"swarmcover {__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"swarmcover: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    rc = module.main(rest)
    return int(rc or 0)


if __name__ == "__main__":
    sys.exit(main())

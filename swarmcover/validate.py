"""Validate a whole run up front: every flag of ``swarmcover run`` and every section of its
config, before any process starts.

``check_flags(args)`` checks the command line; ``check_run(args)`` loads the config, applies
the overrides and runs every owner's own validation on the resolved text the processes will
read ([map]/[robots]/[sensing]/[world] and the map itself with its size limits, [agent],
[coordinator], [hwbridge]); ``prepare_out(path)`` makes the run folder. Each raises a
:class:`bus.configcheck.ConfigError` naming file (or "command line"), section, field and
value; ``swarmcover run`` prints its one line and exits 2. Exit 1 then means only "ran, not
certified".
"""
from __future__ import annotations

import logging
import re
import socket
from dataclasses import dataclass
from pathlib import Path

from swarmcover.bus.configcheck import Checker, ConfigError

CLI = "command line"
MAX_WALL_TIMEOUT_S = 30 * 24 * 3600.0     # a month
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws|unixsock-stream|unixpipe)/\S+$")


@dataclass
class Checked:
    """What a valid run needs: the config, its resolved TOML, the map and live limits."""
    cfg: object
    resolved: str
    wmap: object
    live_limits: dict
    swarm: str


def port_free(port: int, host: str = "127.0.0.1") -> bool:
    with socket.socket() as s:
        try:
            s.bind((host, port))
            return True
        except OSError:
            return False


def _port(ck: Checker, flag: str, v, busy_check: bool) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 65535:
        raise ck.err(flag, v, "expected a TCP port in [1, 65535]")
    if busy_check and not port_free(v):
        raise ck.err(flag, v, f"port {v} on 127.0.0.1 is in use (tcp/127.0.0.1:{v})")
    return v


def check_flags(args) -> None:
    """The flags of ``swarmcover run`` alone (no file is read)."""
    ck = Checker(CLI, "")
    if args.wall_timeout is not None:
        ck.num("--wall-timeout", args.wall_timeout, 0.0, MAX_WALL_TIMEOUT_S, lo_open=True)
    if args.robots_max is not None:
        ck.int_("--robots-max", args.robots_max, 1, 10**6)
    if args.seed is not None:
        ck.int_("--seed", args.seed, 0, 2**63 - 1)
    if getattr(args, "hosts", 0):
        ck.int_("--hosts", args.hosts, 0, 10_000)
    if args.router is not None:
        _check_endpoint(ck, "--router", args.router)
        if args.port is not None:
            raise ck.err("--port", args.port, "give either --router or --port, not both")
    if args.port is not None:
        _port(ck, "--port", args.port, busy_check=True)
    if getattr(args, "foxglove", False):
        _port(ck, "--foxglove-port", args.foxglove_port, busy_check=True)
    if args.view or getattr(args, "foxglove", False):
        _port(ck, "--view-port", args.view_port, busy_check=True)
    elif args.view_port is not None:
        _port(ck, "--view-port", args.view_port, busy_check=False)
    if args.swarm is not None:
        from swarmcover.bus.keys import check_swarm
        try:
            check_swarm(args.swarm)
        except ValueError:
            raise ck.err("--swarm", args.swarm,
                         "expected 1-64 letters, digits, '_' or '-'") from None
    if args.secure is not None:
        if not Path(args.secure).expanduser().is_dir():
            raise ck.err("--secure", args.secure, "no such directory (create one with "
                                                  "`swarmcover secure init DIR`)")
        _check_profile(ck, args)
    level = str(args.log_level).upper()
    if not isinstance(logging.getLevelName(level), int):
        raise ck.err("--log-level", args.log_level,
                     "expected one of DEBUG, INFO, WARNING, ERROR, CRITICAL")


def _check_profile(ck: Checker, args) -> None:
    """The --secure profile holds what the router we start, the world, the coordinator and
    run itself need (each agent's identity is checked by the agent)."""
    from swarmcover.bus.security import SecurityError, config_inserts
    wanted = [("client", r) for r in ("world", "coordinator", "viewer")]
    if args.router is None:
        wanted.insert(0, ("router", "router"))
    for mode, role in wanted:
        try:
            config_inserts(args.secure, mode=mode, role=role)
        except SecurityError as e:
            raise ck.err("--secure", args.secure, f"incomplete profile: {e}") from None


def _check_endpoint(ck: Checker, flag: str, v: str) -> None:
    if not isinstance(v, str) or not _ENDPOINT.match(v):
        raise ck.err(flag, v, "expected a Zenoh endpoint such as tcp/127.0.0.1:7447")
    if v.startswith(("tcp/", "udp/", "tls/", "quic/", "ws/")):
        addr = v.split("/", 1)[1].split("#", 1)[0]
        host, sep, port = addr.rpartition(":")
        if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ck.err(flag, v, "expected HOST:PORT with a port in [1, 65535] after the "
                                  "protocol, e.g. tcp/127.0.0.1:7447")


def check_run(args) -> Checked:
    """Load and validate the whole run config with the flags applied. Raises ConfigError
    (or another ValueError / OSError naming the file) before anything starts."""
    check_flags(args)
    from swarmcover.run import _live_limits, resolve_config
    cfg, resolved = resolve_config(args.run_config, args)
    path = cfg.path
    # cheapest first, so a bad value is reported before the heavy imports
    # [agent] (and the [robots]/[sensing]/[world] values agents read), as every agent will
    # read it from the resolved file: a bad value here would kill every agent at start
    from swarmcover.agents.params import from_toml_text
    from_toml_text(resolved, path)
    # [hwbridge], by the bridge's own parser
    live_limits = _live_limits(cfg, resolved, path)
    # [coordinator], as the coordinator will read it (with --robots-max applied); importing
    # it loads the topology core (scipy)
    from swarmcover.coordinator.config import CoordinatorConfig
    CoordinatorConfig.from_section(cfg.section("coordinator"), rv=cfg.rv, where=path)
    # the map itself: ROS images, size limits, sources in free space
    from swarmcover.world.maps import build_map
    wmap = build_map(cfg)
    _check_spawns(cfg, wmap)
    if live_limits:
        _check_live(cfg, resolved, wmap)
    if args.router is not None:
        _check_reachable(Checker(CLI, ""), "--router", args.router)
    swarm = args.swarm or "".join(ch if ch.isalnum() or ch in "-_" else "_"
                                  for ch in cfg.name)[:64] or "run"
    return Checked(cfg, resolved, wmap, live_limits, swarm)


def _check_spawns(cfg, wmap) -> None:
    """Robots must fit at every source, and [world].spawn bodies must start in free space,
    at a source that exists."""
    clear = wmap.clearance(wmap.sources[:, :2])
    r = cfg.robots.radius
    for k in range(len(wmap.sources)):
        if clear[k] < r:
            where = f"sources[{k}]" if cfg.map.sources else f"sources (picked {k})"
            raise ConfigError(cfg.path, "map", where, [round(float(v), 6) for v in wmap.sources[k]],
                              f"{clear[k]:.3g} m from a wall: a robot of [robots] radius "
                              f"{r:g} m does not fit there")
    ck = Checker(cfg.path, "world")
    for k, sp in enumerate(cfg.world.spawn):
        if sp.pose is not None:
            if not wmap.contains([sp.pose[:2]])[0]:
                raise ck.err(f"spawn[{k}].pose", list(sp.pose), "not in free space")
        elif sp.source >= len(wmap.sources):
            raise ck.err(f"spawn[{k}].source", sp.source,
                         f"only {len(wmap.sources)} source(s) on this map")


def _check_live(cfg, resolved: str, wmap) -> None:
    """Each live robot's twin spawns at a source that exists; a stand-in starts in free space."""
    from swarmcover.hwbridge.config import loads
    for k, r in enumerate(loads(resolved, cfg.path).robots):
        ck = Checker(cfg.path, f"hwbridge.robots[{k}]")
        if r.source >= len(wmap.sources):
            raise ck.err("source", r.source, f"only {len(wmap.sources)} source(s) on this map")
        if r.start is not None and not wmap.contains([r.start[:2]])[0]:
            raise ck.err("start", list(r.start), "not in free space")


def _check_reachable(ck: Checker, flag: str, endpoint: str) -> None:
    """A TCP router endpoint must accept a connection now (else every process would wait
    for it and give up one by one)."""
    if not endpoint.startswith(("tcp/", "tls/")):
        return
    host, _, port = endpoint.split("/", 1)[1].split("#", 1)[0].rpartition(":")
    host = host.strip("[]")
    try:
        with socket.create_connection((host, int(port)), timeout=3.0):
            pass
    except OSError as e:
        raise ck.err(flag, endpoint, f"no router answers there: {e.strerror or e}") from None


def prepare_out(out: Path) -> Path:
    """Make the run folder and its logs/; refuse a place we cannot write."""
    try:
        (out / "logs").mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise ConfigError(CLI, "", "--out", str(out),
                          f"cannot write the run folder there: {e.strerror or e}") from None
    return out

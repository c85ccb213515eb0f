"""Zenoh session set-up shared by every swarmcover process.

Defaults: client mode connecting to tcp/127.0.0.1:7447, multicast scouting off. Overrides
are layered as in zenoh-python's examples: ``--config FILE`` first, then ``--mode``,
``--connect``, ``--listen``, ``--multicast-scouting``, then repeatable ``--cfg PATH:JSON5``.

Rules this module enforces for every process (see shared/spec/zenoh-notes.md):
  * sessions are closed on every exit path, SIGINT and SIGTERM included (:class:`Shutdown`
    turns both signals into an event the main loop checks);
  * Zenoh callbacks never block or call Zenoh: :class:`Mailbox` only enqueues.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import queue
import re
import signal
import sys
import threading
import time
import traceback
from collections import Counter
from typing import Any, Iterable

import zenoh

from .keys import Keys
from .security import config_inserts, infer_role, secure_endpoints
from .messages import Message, WireError, WorldInfo, decode

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
log = logging.getLogger("swarmcover.bus")


def add_zenoh_args(parser: argparse.ArgumentParser, mode: str = "client", *,
                   helps: dict[str, str] | None = None, defaults: dict[str, Any] | None = None,
                   title: str = "zenoh") -> None:
    """Add the standard connection flags to a command's parser (the one place they are
    defined: every command takes the same ones).

    ``helps`` and ``defaults`` (keyed by the long flag, e.g. ``"--swarm"``) let a command say
    what a flag means for it (``swarmcover run``: ``--listen`` is its embedded router's);
    the flags and their destinations stay the same everywhere."""
    helps, defaults = dict(helps or {}), dict(defaults or {})
    unknown = (set(helps) | set(defaults)) - set(ZENOH_FLAGS)
    if unknown:
        raise ValueError(f"add_zenoh_args: no such shared flag {sorted(unknown)}")
    g = parser.add_argument_group(title)

    def add(flag: str, *more: str, **kw) -> None:
        kw["help"] = helps.get(flag, kw.get("help"))
        if flag in defaults:
            kw["default"] = defaults[flag]
        g.add_argument(flag, *more, **kw)

    add("--config", metavar="FILE", help="Zenoh JSON5 config file (applied first)")
    add("--mode", choices=("client", "peer", "router"), default=None,
        help=f"Zenoh mode (default: {mode})")
    add("--connect", "-e", action="append", default=None, metavar="ENDPOINT",
        help=f"endpoint to connect to, repeatable (default for clients: {DEFAULT_ROUTER})")
    add("--listen", "-l", action="append", default=None, metavar="ENDPOINT",
        help="endpoint to listen on, repeatable")
    add("--multicast-scouting", action="store_true",
        help="enable multicast scouting (off by default: explicit endpoints only)")
    add("--cfg", action="append", default=[], metavar="PATH:JSON5",
        help='raw config override, repeatable, e.g. --cfg "transport/link/tx/lease:2000"')
    add("--swarm", default=os.environ.get("SWARMCOVER_SWARM", "default"),
        help="experiment name scoping every key (env SWARMCOVER_SWARM; default 'default')")
    add("--connect-timeout", type=float, default=10.0, metavar="S",
        help="seconds to wait for the router at start (default 10)")
    add("--secure", metavar="DIR", default=os.environ.get("SWARMCOVER_SECURE") or None,
        help="security profile from `swarmcover secure init` (mutual TLS, password, "
             "ACL; env SWARMCOVER_SECURE); see docs/lab-network.md")
    add("--role", default=None, help="identity role under --secure (default: the "
        "command's own, e.g. world; agent N is agent-N)")
    parser.set_defaults(_zenoh_mode=mode, _zenoh_role=infer_role(parser.prog))


# the shared flags, in the order add_zenoh_args adds them
ZENOH_FLAGS = ("--config", "--mode", "--connect", "--listen", "--multicast-scouting", "--cfg",
               "--swarm", "--connect-timeout", "--secure", "--role")


def zenoh_argv(args: argparse.Namespace) -> list[str]:
    """The connection flags of ``args`` as argv, to pass on to child processes: all but
    ``--listen`` (a child cannot listen where its parent does) and ``--role`` (each child
    has its own identity)."""
    out: list[str] = []
    if args.config:
        out += ["--config", args.config]
    if getattr(args, "mode", None):
        out += ["--mode", args.mode]
    for e in args.connect or []:
        out += ["--connect", e]
    if args.multicast_scouting:
        out.append("--multicast-scouting")
    for c in args.cfg or []:
        out += ["--cfg", c]
    out += ["--swarm", args.swarm, "--connect-timeout", str(args.connect_timeout)]
    if getattr(args, "secure", None):
        out += ["--secure", args.secure]
    return out


ROUTER_LIMITS = {"transport/unicast/accept_pending": "2000",
                 "transport/unicast/accept_timeout": "30000",
                 "transport/unicast/max_sessions": "10000"}


def make_config(args: argparse.Namespace, mode: str | None = None) -> zenoh.Config:
    """Build a zenoh.Config from the layered flags. Raises ValueError naming a bad flag."""
    mode = mode or args.mode or getattr(args, "_zenoh_mode", "client")
    if args.config:
        if not os.path.isfile(args.config):
            raise ValueError(f"--config {args.config}: no such file")
        try:
            conf = zenoh.Config.from_file(args.config)
        except Exception as e:
            raise ValueError(f"--config {args.config}: {zenoh_error(e)}") from None
    else:
        conf = zenoh.Config()
    _insert(conf, "mode", json.dumps(mode), "--mode")
    connect = args.connect
    if connect is None and mode == "client" and not args.config:
        connect = [DEFAULT_ROUTER]
    if connect:
        _insert(conf, "connect/endpoints", json.dumps(connect), "--connect")
    if mode == "client":
        _insert(conf, "connect/timeout_ms", str(int(args.connect_timeout * 1000)), "--connect-timeout")
    if args.listen:
        _insert(conf, "listen/endpoints", json.dumps(args.listen), "--listen")
    if not args.config:
        # shared memory off: a router with it on refused every client after the 351st (Zenoh
        # 1.10 here: each one's handshake maps a segment), and our messages are a few
        # hundred bytes (--cfg transport/shared_memory/enabled:true turns it back on)
        _insert(conf, "transport/shared_memory/enabled", "false", "shared memory")
    if mode == "router" and not args.config:
        # a swarm is hundreds of clients, many connecting at once while their processes
        # start on a loaded box: Zenoh's defaults are 100 handshakes pending, 10 s each,
        # and 1,000 sessions
        for path, value in ROUTER_LIMITS.items():
            _insert(conf, path, value, "router limits")
    _insert(conf, "scouting/multicast/enabled", "true" if args.multicast_scouting else "false",
            "--multicast-scouting")
    if getattr(args, "secure", None):
        _apply_secure(conf, args, mode, connect)
    for c in args.cfg or []:
        if ":" not in c:
            raise ValueError(f"--cfg {c!r}: expected PATH:JSON5")
        path, value = c.split(":", 1)
        _insert(conf, path, value, f"--cfg {c!r}")
    return conf


def _apply_secure(conf: zenoh.Config, args: argparse.Namespace, mode: str, connect) -> None:
    """--secure DIR: tcp/ endpoints become tls/, then the profile's TLS/auth/ACL inserts."""
    role = "router" if mode == "router" else (args.role or getattr(args, "_zenoh_role", "viewer"))
    robot = getattr(args, "id", None) if role == "agent" else None
    if connect:  # args keep the upgraded endpoints, so logs and READY lines say tls/
        args.connect = connect = secure_endpoints(connect, "--connect")
        _insert(conf, "connect/endpoints", json.dumps(connect), "--connect")
    if args.listen:
        args.listen = secure_endpoints(args.listen, "--listen")
        _insert(conf, "listen/endpoints", json.dumps(args.listen), "--listen")
    for path, value in config_inserts(args.secure, mode=mode, role=role, robot=robot):
        _insert(conf, path, value, f"--secure {args.secure}")


def _insert(conf: zenoh.Config, path: str, value: str, flag: str) -> None:
    try:
        conf.insert_json5(path, value)
    except Exception as e:
        raise ValueError(f"{flag}: cannot set {path} = {value}: {zenoh_error(e)}") from None


def zenoh_error(e: BaseException) -> str:
    """Zenoh's error text without the Rust source location it appends (`` at
    <build folder>/src/lib.rs:1507.``): a path of the machine zenoh was built on."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(e)).strip()


def open_session(args: argparse.Namespace, mode: str | None = None) -> zenoh.Session:
    """Open a session from the flags; a client waits up to --connect-timeout for the router."""
    conf = make_config(args, mode)
    try:
        return zenoh.open(conf)
    except Exception as e:
        # name the endpoints this session was given (a bad --listen port is not the router's)
        ends = [f"listen {', '.join(args.listen)}"] if args.listen else []
        if args.connect or not args.listen:
            ends.append(f"router {', '.join(args.connect or [DEFAULT_ROUTER])}")
        hint = "Is the port valid and free?" if args.listen else "Is `swarmcover router` running?"
        raise ConnectionError(
            f"cannot open a Zenoh session ({mode or args.mode or args._zenoh_mode} mode, "
            f"{'; '.join(ends)}): {zenoh_error(e)}. {hint}") from None


class Shutdown:
    """SIGINT/SIGTERM -> an event. Use as a context manager in every process's main.

    Inside ``with Shutdown() as stop:`` the loop checks ``stop.is_set()`` or calls
    ``stop.wait(dt)``; the signal handlers are restored on exit.

    Bounded exit: once stopping was requested (signal or parent gone), the process gets
    ``grace_s`` seconds (env SWARMCOVER_EXIT_GRACE_S, default 15) to close its session and
    return. If it is still alive then (a blocked put, a close that never returns), a
    watchdog prints where the main thread is stuck to stderr and ends the process with
    ``os._exit(0)``, so a stop request never leaves a process behind.
    """

    def __init__(self, signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM),
                 grace_s: float | None = None):
        self.event = threading.Event()
        self.signum: int | None = None
        self._signals = tuple(signals)
        self._old: dict[int, Any] = {}
        if grace_s is None:
            grace_s = float(os.environ.get("SWARMCOVER_EXIT_GRACE_S", "15"))
        self.grace_s = grace_s
        self._watchdog: threading.Thread | None = None

    def _handle(self, signum, frame):
        self.signum = signum
        self.event.set()
        self._arm()

    def _arm(self) -> None:
        """Start the exit watchdog (once)."""
        if self._watchdog is not None or self.grace_s <= 0:
            return
        self._watchdog = threading.Thread(target=self._expire, daemon=True, name="exit-watchdog")
        self._watchdog.start()

    def _expire(self) -> None:
        time.sleep(self.grace_s)
        main = sys._current_frames().get(threading.main_thread().ident)
        where = "".join(traceback.format_stack(main)) if main is not None else "(unknown)\n"
        try:
            sys.stderr.write(f"swarmcover: still running {self.grace_s:g} s after the stop request "
                             f"(signal {self.signum}); exiting now. Main thread was at:\n{where}")
            sys.stderr.flush()
            sys.stdout.flush()
        finally:
            os._exit(0)

    def __enter__(self) -> "Shutdown":
        if threading.current_thread() is threading.main_thread():
            for s in self._signals:
                self._old[s] = signal.signal(s, self._handle)
        if os.environ.get("SWARMCOVER_WATCH_PARENT") == "1":
            threading.Thread(target=self._watch_parent, args=(os.getppid(),), daemon=True,
                             name="watch-parent").start()
        return self

    def _watch_parent(self, ppid: int) -> None:
        """Launched by a supervisor (env SWARMCOVER_WATCH_PARENT=1): when it dies, stop too,
        so a killed ``swarmcover run`` never leaves orphans behind."""
        while not self.event.wait(0.5):
            if os.getppid() != ppid:
                self.signum = signal.SIGHUP
                self.event.set()
                self._arm()

    def __exit__(self, *exc) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)

    def is_set(self) -> bool:
        return self.event.is_set()

    def set(self) -> None:
        self.event.set()

    def wait(self, timeout: float | None = None) -> bool:
        return self.event.wait(timeout)


class Mailbox:
    """A thread-safe queue fed by Zenoh callbacks; the process loop drains it.

    ``mailbox.callback`` is what you pass to ``declare_subscriber``: it only enqueues
    ``(key, payload_bytes)``. Use ``get``/``drain`` in the main thread and decode there
    with a :class:`Receiver`.
    """

    def __init__(self, maxsize: int = 0):
        self.q: queue.Queue = queue.Queue(maxsize)
        self.dropped = 0

    def callback(self, sample: "zenoh.Sample") -> None:
        try:
            self.q.put_nowait((str(sample.key_expr), sample.payload.to_bytes(), sample.kind))
        except queue.Full:
            self.dropped += 1

    def get(self, timeout: float | None = None):
        """One (key, payload, kind) or None after ``timeout`` seconds."""
        try:
            return self.q.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self, limit: int = 100_000) -> list:
        out = []
        try:
            while len(out) < limit:
                out.append(self.q.get_nowait())
        except queue.Empty:
            pass
        return out


class Receiver:
    """Decodes payloads for a process: invalid ones are dropped, counted and logged once per
    key (sender), never raised."""

    def __init__(self, logger: logging.Logger | None = None):
        self.log = logger or log
        self.invalid: Counter = Counter()
        self._logged: set[str] = set()

    def decode(self, key: str, payload: bytes, expected=None) -> Message | None:
        try:
            return decode(payload, expected)
        except WireError as e:
            self.invalid[key] += 1
            if key not in self._logged:
                self._logged.add(key)
                self.log.warning("dropping invalid message on %s: %s (further ones from this "
                                 "sender are counted, not logged)", key, e)
            return None

    @property
    def invalid_total(self) -> int:
        return sum(self.invalid.values())


def publisher(session: zenoh.Session, key: str, *, block: bool = True, express: bool = False,
              priority: "zenoh.Priority | None" = None):
    """Declare a publisher: commands and lifecycle messages BLOCK; telemetry DROP."""
    kw: dict[str, Any] = dict(
        congestion_control=zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP,
        express=express)
    if priority is not None:
        kw["priority"] = priority
    return session.declare_publisher(key, **kw)


def undeclare(*entities) -> None:
    """Undeclare Zenoh subscribers, publishers and liveliness tokens (None skipped), each on
    its own: one that fails (its session already closed) does not keep the others."""
    for e in entities:
        if e is None:
            continue
        try:
            e.undeclare()
        except Exception:
            pass


def put(session: zenoh.Session, key: str, msg: Message, *, block: bool = True) -> None:
    """One-off put of a message (commands use BLOCK)."""
    session.put(key, msg.encode(), congestion_control=(
        zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP))


def setup_logging(level: str = "INFO", name: str = "swarmcover") -> logging.Logger:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    return logging.getLogger(name)


def wait_for(pred, timeout: float, interval: float = 0.02) -> bool:
    """Poll ``pred`` until true or ``timeout`` seconds pass (for start-up handshakes)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(interval)
    return bool(pred())


def query_world_info(session: zenoh.Session, keys: Keys, timeout: float, *,
                     per_query: float = 2.0, stop: "Shutdown | None" = None,
                     logger: logging.Logger | None = None) -> WorldInfo | None:
    """The world's WorldInfo (its ``world/info`` queryable), asked again every 0.2 s until
    one valid reply arrives or ``timeout`` seconds pass; None if no world answered.

    Each query waits at most ``per_query`` seconds (never past the deadline, at least
    0.1 s). An invalid reply is logged (warning) and skipped; a failed query (router not
    reachable yet) is logged at debug level and retried. With ``stop``, a stop request
    ends the wait early (None). ``logger``: the caller's logger (default swarmcover.bus).
    """
    lg = logger or log
    end = time.monotonic() + timeout
    while not (stop is not None and stop.is_set()):
        left = end - time.monotonic()
        if left <= 0:
            break
        try:
            for reply in session.get(keys.world_info, timeout=max(0.1, min(per_query, left))):
                if reply.ok is None:
                    continue
                try:
                    return decode(reply.ok.payload.to_bytes(), WorldInfo)
                except WireError as e:
                    lg.warning("world/info reply invalid: %s", e)
        except Exception as e:  # router not reachable yet, a closing session etc.
            lg.debug("world/info query failed: %s", e)
        if stop is not None:
            stop.wait(0.2)
        else:
            time.sleep(0.2)
    return None


def keys_from_args(args: argparse.Namespace) -> Keys:
    try:
        return Keys(args.swarm)
    except ValueError as e:
        raise SystemExit(f"--swarm: {e}")

"""``swarmcover topics``: inspect a swarm's Zenoh traffic.

  list   keys seen within a window, grouped by pattern, with rate and number of senders
  echo   decoded messages as JSON lines (``--raw`` for hex bytes)
  hz     message rate of a key expression, printed every second
  alive  liveliness tokens present (``--watch`` to follow arrivals and departures)

Key expressions are relative to ``sc/<swarm>/`` unless they start with ``sc/``.
"Senders" counts distinct robot ids (from the key, or a message's ``robot`` field); keys
without a robot are counted as one sender.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import time
from collections import defaultdict

import zenoh

from swarmcover.bus.keys import Keys, message_for_key
from swarmcover.bus.messages import WireError, decode
from swarmcover.bus.session import Mailbox, Shutdown, add_zenoh_args, keys_from_args, open_session


def _full(keys: Keys, expr: str) -> str:
    expr = expr.strip()
    full = expr if expr.startswith("sc/") else f"{keys.prefix}/{expr.lstrip('/')}"
    try:
        zenoh.KeyExpr(full)
    except Exception as e:
        raise SystemExit(f"swarmcover topics: invalid key expression {expr!r}: {e}")
    return full


def _pattern(rel: str) -> str:
    return re.sub(r"(?<=/)\d+(?=/|$)", "*", re.sub(r"^robot/\d+", "robot/*", rel))


def _sender(keys: Keys, key: str, payload: bytes) -> str:
    rid = keys.robot_id(key)
    if rid is not None:
        return f"robot {rid}"
    try:
        msg = decode(payload)
        r = getattr(msg, "robot", None)
        if r is not None:
            return f"robot {r}"
        body = getattr(msg, "body", None)
        if body is not None:
            return f"body {body}"
    except WireError:
        pass
    return "-"


def _loop(args, session, mailbox: Mailbox, on_item, stop: Shutdown) -> None:
    """Drain the mailbox until --duration, --count or a signal."""
    end = time.monotonic() + args.duration if args.duration else None
    n = 0
    while not stop.is_set():
        timeout = 0.1 if end is None else max(0.0, min(0.1, end - time.monotonic()))
        item = mailbox.get(timeout)
        if item is not None:
            on_item(*item)
            n += 1
            if args.count and n >= args.count:
                return
        if end is not None and time.monotonic() >= end:
            return


def _subscribe(session, keys: Keys, keyexpr: str, what: str):
    """A mailbox subscribed to ``keyexpr`` (relative to the swarm); says so on stderr."""
    expr = _full(keys, keyexpr)
    mb = Mailbox()
    sub = session.declare_subscriber(expr, mb.callback)
    print(f"# {what} {expr}", file=sys.stderr, flush=True)
    return mb, sub


def cmd_list(args, session, keys: Keys, stop) -> int:
    expr = _full(keys, args.keyexpr or "**")
    mb = Mailbox()
    sub = session.declare_subscriber(expr, mb.callback)
    counts: dict[str, int] = defaultdict(int)
    senders: dict[str, set] = defaultdict(set)
    types: dict[str, str] = {}
    first: dict[str, float] = {}
    last: dict[str, float] = {}
    t0 = time.monotonic()

    def on(key, payload, kind):
        rel = keys.relative(key)
        pat = rel if args.keys else _pattern(rel)
        now = time.monotonic()
        counts[pat] += 1
        first.setdefault(pat, now)
        last[pat] = now
        senders[pat].add(_sender(keys, key, payload))
        if pat not in types:
            cls = message_for_key(key)
            try:
                types[pat] = decode(payload).TAG
            except WireError:
                types[pat] = f"invalid ({cls.TAG if cls else '?'})"

    args.duration = args.window
    args.count = 0
    try:
        _loop(args, session, mb, on, stop)
    finally:
        sub.undeclare()
    window = max(1e-6, time.monotonic() - t0)
    print(f"# {len(counts)} key patterns seen under {keys.prefix}/ in {window:.1f} s")
    print(f"{'key':<32} {'type':<10} {'msgs':>7} {'rate_hz':>9} {'senders':>8}")
    for pat in sorted(counts):
        print(f"{pat:<32} {types.get(pat, '?'):<10} {counts[pat]:>7} "
              f"{counts[pat] / window:>9.2f} {len(senders[pat] - {'-'}) or 1:>8}")
    return 0


def cmd_echo(args, session, keys: Keys, stop) -> int:
    mb, sub = _subscribe(session, keys, args.keyexpr, "echo")

    def on(key, payload, kind):
        if args.raw:
            line = json.dumps({"key": key, "bytes": payload.hex()})
        else:
            try:
                d = decode(payload).to_dict()
            except WireError as e:
                d = {"_error": str(e), "_bytes": len(payload)}
            line = json.dumps({"key": key, **d}, separators=(",", ":"))
        print(line, flush=True)

    try:
        _loop(args, session, mb, on, stop)
    finally:
        sub.undeclare()
    return 0


def cmd_hz(args, session, keys: Keys, stop) -> int:
    mb, sub = _subscribe(session, keys, args.keyexpr, "hz")
    stamps: list[float] = []
    next_print = time.monotonic() + 1.0

    def on(key, payload, kind):
        stamps.append(time.monotonic())

    end = time.monotonic() + args.duration if args.duration else None
    try:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            item = mb.get(0.05)
            if item is not None:
                on(*item)
                for it in mb.drain():
                    on(*it)
            now = time.monotonic()
            if now >= next_print:
                next_print = now + 1.0
                recent = [t for t in stamps if t > now - args.window]
                stamps[:] = recent
                if len(recent) >= 2:
                    gaps = [b - a for a, b in zip(recent, recent[1:])]
                    rate = (len(recent) - 1) / (recent[-1] - recent[0]) if recent[-1] > recent[0] else 0.0
                    mean = sum(gaps) / len(gaps)
                    std = (sum((g - mean) ** 2 for g in gaps) / len(gaps)) ** 0.5
                    print(f"rate {rate:.2f} Hz  min {min(gaps)*1e3:.1f} ms  max {max(gaps)*1e3:.1f} ms"
                          f"  std {std*1e3:.1f} ms  window {len(recent)}", flush=True)
                else:
                    print("no new messages", flush=True)
    finally:
        sub.undeclare()
    return 0


def cmd_alive(args, session, keys: Keys, stop) -> int:
    expr = f"{keys.prefix}/alive/**"
    present = []
    for reply in session.liveliness().get(expr, timeout=args.timeout):
        try:
            present.append(keys.relative(str(reply.ok.key_expr))[len("alive/"):])
        except Exception:
            pass
    for name in sorted(set(present)):
        print(name, flush=True)
    print(f"# {len(set(present))} alive", file=sys.stderr, flush=True)
    if not args.watch:
        return 0
    mb = Mailbox()
    sub = session.liveliness().declare_subscriber(expr, mb.callback)

    def on(key, payload, kind):
        sign = "+" if kind == zenoh.SampleKind.PUT else "-"
        print(f"{sign} {keys.relative(key)[len('alive/'):]}", flush=True)

    try:
        _loop(args, session, mb, on, stop)
    finally:
        sub.undeclare()
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover topics", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    for name, helptext in (("list", "keys seen in a window"), ("echo", "decoded messages"),
                           ("hz", "message rate"), ("alive", "liveliness tokens")):
        sp = sub.add_parser(name, help=helptext)
        add_zenoh_args(sp)
        if name in ("echo", "hz"):
            sp.add_argument("keyexpr", help="key expression, e.g. 'robot/*/sense'")
        if name == "list":
            sp.add_argument("keyexpr", nargs="?", default="**")
            sp.add_argument("--window", type=float, default=3.0, help="seconds to listen (default 3)")
            sp.add_argument("--keys", action="store_true", help="one row per concrete key")
        if name == "echo":
            sp.add_argument("--raw", action="store_true", help="hex payload instead of decoding")
        if name == "hz":
            sp.add_argument("--window", type=float, default=5.0, help="averaging window (s)")
        if name == "alive":
            sp.add_argument("--watch", action="store_true", help="follow tokens appearing and going")
            sp.add_argument("--timeout", type=float, default=2.0, help="query timeout (s)")
        if name in ("echo", "hz", "alive"):
            sp.add_argument("--duration", type=float, default=0.0, help="stop after S seconds")
            sp.add_argument("--count", type=int, default=0, help="stop after N messages (echo)")
    args = p.parse_args(argv)
    keys = keys_from_args(args)
    try:
        session = open_session(args)
    except (ValueError, ConnectionError) as e:
        print(f"swarmcover topics: {e}", file=sys.stderr)
        return 2
    handler = {"list": cmd_list, "echo": cmd_echo, "hz": cmd_hz, "alive": cmd_alive}[args.cmd]
    with Shutdown() as stop:
        try:
            return handler(args, session, keys, stop)
        except BrokenPipeError:
            return 0
        finally:
            session.close()

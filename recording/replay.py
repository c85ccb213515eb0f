"""Republish an MCAP recording with its original timing: ``swarmcover replay FILE.mcap``.

Every recorded message is put again on its key, in log-time order, at its original offset
from the first message divided by ``--rate`` (2 = twice as fast; 0 = as fast as possible).
Recorded liveliness tokens are declared and undeclared at their times; recorded query
replies (``world/info``) are served by a queryable from the start, so late joiners get the
map as in a live run. Every tool (topics, view, plot) therefore works on a replay as on a
live run.

Swarm: the replay prints the recorded swarm name (the one ``topics``/``view`` need, with
``--swarm``). It republishes under the recorded name unless ``--swarm NAME`` (or
``--to-swarm NAME``, the same) is given: then ``sc/<recorded>/`` keys become ``sc/NAME/``.

What is republished is the msgpack payload each message had on the wire: JSON channels
(this format) are packed back to the very same bytes, old msgpack recordings are sent as
stored. The ``/swarmcover/scene`` channel is for viewers of the file; it is not published.

Module API: :func:`read_messages` iterates a recording without Zenoh (plots, analyses);
:class:`JsonDecoderFactory` lets ``mcap``'s own reader decode the JSON channels.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from mcap.reader import make_reader

from swarmcover.bus.keys import ROOT, check_swarm
from mcap.decoder import DecoderFactory

from swarmcover.recording.record import (KIND_LIVELINESS, KIND_PUT, KIND_QUERY_REPLY, KIND_SCENE,
                               LEGACY_MSG_ENCODING, LIVELINESS_ENCODING, MSG_ENCODING,
                               json_to_payload)

log = logging.getLogger("swarmcover.recording.replay")


@dataclass(frozen=True, slots=True)
class Recorded:
    """One recorded message. log_time_ns: receipt wall clock (ns since epoch); kind: "put",
    "query_reply" or "liveliness" (then data is b"put" or b"delete")."""
    key: str
    data: bytes
    log_time_ns: int
    kind: str
    schema: str   # message tag of the channel's schema, "" if none


class JsonDecoderFactory(DecoderFactory):
    """``mcap.reader.make_reader(f, decoder_factories=[JsonDecoderFactory()])``: decodes
    ``json`` channels to dicts (what Foxglove's JSON decoding does)."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding == MSG_ENCODING:
            return json.loads
        return None


def _kind(channel) -> str:
    if channel.message_encoding == LIVELINESS_ENCODING:
        return KIND_LIVELINESS
    if channel.metadata.get("swarmcover") == KIND_SCENE:
        return KIND_SCENE
    return channel.metadata.get("zenoh", KIND_PUT)


def _payload(channel, kind: str, data: bytes) -> bytes:
    """The bytes as they travelled on Zenoh (liveliness: b"put" / b"delete")."""
    enc = channel.message_encoding
    if enc == MSG_ENCODING and kind != KIND_SCENE:
        if kind == KIND_LIVELINESS:
            return json.loads(data)["token"].encode()
        return json_to_payload(data)
    if enc in (LEGACY_MSG_ENCODING, LIVELINESS_ENCODING) or kind == KIND_SCENE:
        return bytes(data)
    raise ValueError(f"channel {channel.topic}: message encoding {enc!r} is not one this "
                     f"version reads (json, or msgpack of older recordings)")


def open_recording(path: str | Path):
    """Open ``path`` for reading; raises ValueError naming the file if it is not MCAP."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording {p}: no such file")
    f = open(p, "rb")
    try:
        return f, make_reader(f)
    except Exception as e:
        f.close()
        raise ValueError(f"recording {p}: not a readable MCAP file ({e})") from None


def summary_counts(path: str | Path) -> tuple[int, dict[str, str]]:
    """(message count, {key: kind}) from the file's summary (0, {} if it has none)."""
    f, reader = open_recording(path)
    with f:
        s = reader.get_summary()
        if s is None:
            return 0, {}
        n = s.statistics.message_count if s.statistics else 0
        return n, {c.topic: _kind(c) for c in s.channels.values()}


def read_messages(path: str | Path, *, kinds: tuple[str, ...] | None = None,
                  topics: list[str] | None = None) -> Iterator[Recorded]:
    """Yield the recording's messages in log-time order (optionally only some kinds/keys).

    ``data`` is the payload as it travelled (msgpack), whatever the file's format; scene
    messages (kind "scene") carry their protobuf bytes.
    """
    f, reader = open_recording(path)
    with f:
        for schema, channel, msg in reader.iter_messages(topics=topics, log_time_order=True):
            kind = _kind(channel)
            if kinds is not None and kind not in kinds:
                continue
            try:
                data = _payload(channel, kind, msg.data)
            except (ValueError, KeyError, TypeError) as e:
                raise ValueError(f"recording {path}: channel {channel.topic}: cannot read "
                                 f"message at log time {msg.log_time}: {e}") from None
            yield Recorded(channel.topic, data, int(msg.log_time), kind,
                           schema.name if schema is not None else "")


def recording_metadata(path: str | Path) -> dict[str, str]:
    """The ``swarmcover`` metadata record of a recording (swarm, keyexpr, ...), {} if none."""
    f, reader = open_recording(path)
    with f:
        out: dict[str, str] = {}
        try:
            for rec in reader.iter_metadata():
                if rec.name == "swarmcover":
                    out.update(rec.metadata)
        except Exception:
            pass
        return out


def recorded_swarm(path: str | Path) -> str | None:
    """The swarm a recording was made on: its metadata, else the keys' ``sc/<swarm>/``."""
    sw = recording_metadata(path).get("swarm")
    if sw:
        return sw
    f, reader = open_recording(path)
    with f:
        s = reader.get_summary()
        names = set()
        for c in (s.channels.values() if s is not None else ()):
            parts = c.topic.split("/")
            if len(parts) > 2 and parts[0] == ROOT:
                names.add(parts[1])
        return names.pop() if len(names) == 1 else None


def remap_key(key: str, to_swarm: str | None) -> str:
    """``sc/<any>/rest`` -> ``sc/<to_swarm>/rest`` (unchanged if to_swarm is None)."""
    if not to_swarm:
        return key
    parts = key.split("/", 2)
    if len(parts) >= 2 and parts[0] == ROOT:
        return "/".join([ROOT, to_swarm] + parts[2:])
    return key


class Replayer:
    """Publishes a recording on an open session. ``run(stop)`` returns the number published.

    rate: speed factor (0 = no waiting); to_swarm: key remap; progress: a Progress or None.
    Query replies are served from the first moment; queries are answered from the main
    loop (a channel handler), never inside a Zenoh callback. Scene messages are skipped.
    """

    def __init__(self, session, path: str | Path, *, rate: float = 1.0,
                 to_swarm: str | None = None, progress=None):
        if rate < 0:
            raise ValueError(f"--rate {rate}: must be >= 0")
        self.session = session
        self.path = Path(path)
        self.rate = rate
        self.to_swarm = to_swarm
        self.progress = progress
        self.total, channels = summary_counts(self.path)
        self.published = 0
        self._pubs: dict[str, object] = {}
        self._tokens: dict[str, object] = {}
        self._queryables: list[tuple[object, str, bytes]] = []
        replies = [k for k, kind in channels.items() if kind == KIND_QUERY_REPLY]
        self._answers: dict[str, bytes] = {}
        if replies:
            for r in read_messages(self.path, kinds=(KIND_QUERY_REPLY,), topics=replies):
                self._answers.setdefault(remap_key(r.key, to_swarm), r.data)

    def declare(self) -> None:
        """Declare the queryables for recorded query replies."""
        for key, data in self._answers.items():
            self._queryables.append((self.session.declare_queryable(key), key, data))

    def serve_queries(self) -> int:
        """Answer pending queries (non-blocking); returns how many were answered."""
        n = 0
        for q, key, data in self._queryables:
            while True:
                query = q.try_recv()
                if query is None:
                    break
                try:
                    query.reply(key, data)
                    n += 1
                finally:
                    query.drop()
        return n

    def _publisher(self, key: str):
        pub = self._pubs.get(key)
        if pub is None:
            from swarmcover.bus.session import publisher
            from swarmcover.bus.trust import SignedPublisher  # source_info, so viewers take its Complex
            pub = SignedPublisher(publisher(self.session, key, block=True), None)
            self._pubs[key] = pub
        return pub

    def _emit(self, r: Recorded) -> None:
        key = remap_key(r.key, self.to_swarm)
        if r.kind == KIND_PUT:
            self._publisher(key).put(r.data)
        elif r.kind == KIND_LIVELINESS:
            if r.data == b"put" and key not in self._tokens:
                self._tokens[key] = self.session.liveliness().declare_token(key)
            elif r.data == b"delete" and key in self._tokens:
                self._tokens.pop(key).undeclare()
        # query replies are served by the queryables, not published

    def _sleep_until(self, target: float, stop) -> bool:
        """Serve queries until monotonic time ``target``; False if stopped."""
        while True:
            self.serve_queries()
            left = target - time.monotonic()
            if left <= 0:
                return not stop.is_set()
            if stop.wait(min(left, 0.02)):
                return False

    def run(self, stop, *, start_delay_s: float = 0.0) -> int:
        """Publish everything with the recorded timing until done or ``stop`` is set."""
        if not self._sleep_until(time.monotonic() + start_delay_s, stop):
            return self.published
        t0_wall = None
        t0_log = 0
        for r in read_messages(self.path):
            if r.kind in (KIND_QUERY_REPLY, KIND_SCENE):
                if self.progress is not None:
                    self.progress.update(1)
                continue
            if t0_wall is None:
                t0_wall, t0_log = time.monotonic(), r.log_time_ns
            if self.rate > 0:
                target = t0_wall + (r.log_time_ns - t0_log) / 1e9 / self.rate
                if not self._sleep_until(target, stop):
                    break
            elif stop.is_set():
                break
            self._emit(r)
            self.published += 1
            if self.progress is not None:
                self.progress.update(1, note=f"t={(r.log_time_ns - t0_log) / 1e9:.1f}s")
        return self.published

    def hold(self, seconds: float, stop) -> None:
        """Keep tokens and queryables alive a while after the end (viewers, late tools)."""
        self._sleep_until(time.monotonic() + seconds, stop)

    def close(self) -> None:
        """Undeclare everything declared (the session stays open)."""
        for tok in self._tokens.values():
            try:
                tok.undeclare()
            except Exception:
                pass
        self._tokens.clear()
        for q, _, _ in self._queryables:
            try:
                q.undeclare()
            except Exception:
                pass
        self._queryables.clear()
        for pub in self._pubs.values():
            try:
                pub.undeclare()
            except Exception:
                pass
        self._pubs.clear()


def main(argv: list[str] | None = None) -> int:
    from swarmcover.bus.session import Shutdown, add_zenoh_args, open_session, setup_logging
    from swarmcover.ground.progress import Progress

    p = argparse.ArgumentParser(prog="swarmcover replay", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", metavar="FILE.mcap", help="recording (from swarmcover record / run --record)")
    p.add_argument("--rate", type=float, default=1.0,
                   help="speed factor: 2 = twice as fast, 0 = as fast as possible (default 1)")
    p.add_argument("--to-swarm", default=None, metavar="NAME",
                   help="republish sc/<recorded swarm>/... keys under sc/NAME/... (the same "
                        "as --swarm NAME; default: the recorded swarm, printed at start)")
    p.add_argument("--start-delay", type=float, default=0.0, metavar="S",
                   help="serve world/info but wait S seconds before the first message")
    p.add_argument("--hold", type=float, default=0.0, metavar="S",
                   help="after the last message, keep tokens and world/info up for S seconds")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    p.add_argument("--log-level", default="INFO")
    add_zenoh_args(p)
    argv = list(sys.argv[1:] if argv is None else argv)
    args = p.parse_args(argv)
    setup_logging(args.log_level, "swarmcover.recording.replay")
    swarm_given = (any(a == "--swarm" or a.startswith("--swarm=") for a in argv)
                   or bool(os.environ.get("SWARMCOVER_SWARM")))
    target = args.to_swarm
    if swarm_given:
        if target is not None and target != args.swarm:
            log.error("--swarm %s and --to-swarm %s disagree: give one (they mean the same: "
                      "republish under that swarm)", args.swarm, target)
            return 2
        target = args.swarm
    if target is not None:
        try:
            check_swarm(target)
        except ValueError as e:
            log.error("--swarm: %s", e)
            return 2
    try:
        total, _ = summary_counts(args.file)
        recorded = recorded_swarm(args.file)
    except (OSError, ValueError) as e:
        log.error("%s", e)
        return 2
    to_swarm = target if target is not None and target != recorded else None
    shown = target or recorded
    if recorded is None:
        print("recorded swarm: unknown (keys outside sc/<swarm>/)", file=sys.stderr)
    elif to_swarm:
        print(f"recorded swarm: {recorded}; republished as swarm {to_swarm} "
              f"(swarmcover topics list --swarm {to_swarm})", file=sys.stderr, flush=True)
    else:
        print(f"recorded swarm: {recorded} (swarmcover topics list --swarm {recorded})",
              file=sys.stderr, flush=True)
    try:
        session = open_session(args)
    except (ValueError, ConnectionError) as e:
        log.error("%s", e)
        return 2
    rep = None
    try:
        with Shutdown() as stop:
            prog = Progress(total=total or None, label="replay", unit="msg",
                            enabled=not args.quiet)
            try:
                rep = Replayer(session, args.file, rate=args.rate, to_swarm=to_swarm,
                               progress=prog)
            except ValueError as e:
                log.error("%s", e)
                return 2
            rep.declare()
            print(f"READY replay {args.file} ({total} messages, rate {args.rate:g}, "
                  f"swarm {shown or '?'})", flush=True)
            n = rep.run(stop, start_delay_s=args.start_delay)
            prog.close(note="interrupted" if stop.is_set() else "done")
            if args.hold > 0 and not stop.is_set():
                rep.hold(args.hold, stop)
            print(f"replayed {n} messages from {args.file}", file=sys.stderr)
    finally:
        if rep is not None:
            rep.close()
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

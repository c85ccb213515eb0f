"""Record the swarm's key space to MCAP: ``swarmcover record [KEYEXPR] -o FILE.mcap``.

What is written (one MCAP file, zstd chunks, with summary and indexes). Every channel is in
an encoding Foxglove, Lichtblick and the ``mcap`` package's JSON/protobuf decoders read:
  * every sample PUT on ``KEYEXPR`` (default ``sc/<swarm>/**``): channel = the full key,
    message encoding ``json``: the msgpack payload as the JSON object it encodes
    (``{"_t": tag, "_v": version, field: value, ...}``); one schema per message tag
    (``jsonschema`` encoding, generated from bus/messages.py), chosen from the key's topic
    (bus.keys.message_for_key) or else from the payload's ``_t``. A payload that JSON
    cannot carry exactly (not msgpack, NaN, bytes, ...) is written as
    ``{"_msgpack_b64": "<base64 of the payload>"}``, so replay stays byte-exact;
  * liveliness tokens under the key space: channel = the token's key, message encoding
    ``json``, data ``{"token": "put"}`` / ``{"token": "delete"}`` (token appeared / went),
    channel metadata ``{"zenoh": "liveliness"}``;
  * ``world/info``: queried once at start (and again when a world's liveliness token
    appears while it is still missing); the reply is written on its key like a put, with
    channel metadata ``{"zenoh": "query_reply"}``;
  * ``/swarmcover/scene`` (unless ``--no-scene``): ``foxglove.SceneUpdate`` (protobuf,
    built with foxglove-sdk, see recording/scene.py) at most ``--scene-hz`` (5) times a second
    of recorded time and once at the end: walls, sources, robots, ids, mocap, Rips edges,
    frontier K, obstacle O, redundant robots, coverage. A Foxglove 3D panel draws it.

Recordings made before this format (message encoding ``msgpack`` / ``liveliness``) still
read and replay; ``swarmcover record --from OLD.mcap -o NEW.mcap`` converts one.

Times: ``log_time`` is the wall clock (ns since the Unix epoch) at receipt in this process;
``publish_time`` is the sample's Zenoh timestamp when the publisher set one, else log_time.

:class:`Recorder` is the importable part (``run --record`` uses it on its own session);
:class:`McapSink` writes messages to a file without Zenoh (tests, converters).
"""
from __future__ import annotations

import argparse
import atexit
import base64
import dataclasses
import json
import logging
import os
import queue
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Iterable

import msgspec
from mcap.writer import CompressionType, Writer

from swarmcover.bus import messages as m
from swarmcover.bus.keys import ROOT, message_for_key

log = logging.getLogger("swarmcover.recording.record")

MSG_ENCODING = "json"
LEGACY_MSG_ENCODING = "msgpack"          # recordings before the JSON format
LIVELINESS_ENCODING = "liveliness"       # legacy liveliness channels (data b"put"/b"delete")
SCHEMA_ENCODING = "jsonschema"
KIND_PUT, KIND_LIVELINESS, KIND_QUERY_REPLY = "put", "liveliness", "query_reply"
KIND_SCENE = "scene"
PROFILE = "swarmcover"
SCENE_HZ = 5.0           # default scene updates per second of recorded time (an update of
                         # 100 robots takes ~9 ms on the 2-core test box)
RAW_FIELD = "_msgpack_b64"
LIVELINESS_SCHEMA = "swarmcover.Liveliness"
RAW_SCHEMA = "swarmcover.Raw"


# --------------------------------------------------------------------------- schemas

def _field_schema(f: dataclasses.Field) -> dict:
    """JSON schema of one message field: msgspec's schema of the field's wire type
    (bus.messages.wire_type: the same types, bounds, choices and length caps decoding
    enforces), with its default."""
    out = msgspec.json.schema(m.wire_type(f.metadata))
    if f.metadata["kind"] == "polys":
        out["description"] = "polygons, each a flat [x0, y0, x1, y1, ...]"
    if f.default is not dataclasses.MISSING and f.default is not None:
        out["default"] = f.default
    return out


def schema_for(cls: type[m.Message]) -> dict:
    """A JSON-schema description of message class ``cls`` as it is on the wire (msgpack map)."""
    fields = dataclasses.fields(cls)
    props = {"_t": {"const": cls.TAG}, "_v": {"const": cls.VERSION}}
    props.update({f.name: _field_schema(f) for f in fields})
    doc = " ".join((cls.__doc__ or "").split())
    out = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": cls.TAG,
           "description": doc, "type": "object", "properties": props,
           "required": [k for k in props if not (k in cls._META and cls._META[k].get("optional"))],
           "additionalProperties": False}
    if cls._SAME_LEN:
        out["x-same-length"] = [list(g) for g in cls._SAME_LEN]
    return out


def schema_bytes(cls: type[m.Message]) -> bytes:
    return json.dumps(schema_for(cls), separators=(",", ":"), sort_keys=False).encode()


_LIVELINESS_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema", "title": LIVELINESS_SCHEMA,
    "description": "a Zenoh liveliness token on this key appeared (put) or went (delete)",
    "type": "object", "properties": {"token": {"enum": ["put", "delete"]}},
    "required": ["token"], "additionalProperties": False}
_RAW_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema", "title": RAW_SCHEMA,
    "description": "a payload on a key of no known message type: the msgpack object as JSON, "
                   f"or {{'{RAW_FIELD}': base64 of the bytes}} when JSON cannot carry it exactly",
    "type": "object"}


_MP_DEC = msgspec.msgpack.Decoder()
_MP_ENC = msgspec.msgpack.Encoder()
_JS_DEC = msgspec.json.Decoder()
_JS_ENC = msgspec.json.Encoder()


def payload_to_json(payload: bytes) -> tuple[bytes, str | None]:
    """(JSON bytes, message tag or None) for a msgpack payload.

    The JSON is the msgpack map itself when packing it back gives the very same bytes
    (every payload bus.messages encodes); anything else (not msgpack, NaN, bytes, integer
    keys, float32, ...) becomes ``{"_msgpack_b64": ...}``, so the conversion is lossless.
    msgspec does the conversion: 10-20x faster than the json and msgpack modules here.
    """
    payload = bytes(payload)
    try:
        d = _MP_DEC.decode(payload)
        if isinstance(d, dict) and list(d) != [RAW_FIELD]:  # that one would read as raw
            js = _JS_ENC.encode(d)
            if _MP_ENC.encode(_JS_DEC.decode(js)) == payload:
                t = d.get("_t")
                return js, t if isinstance(t, str) else None
    except Exception:  # msgspec raises several types for garbage
        pass
    return json.dumps({RAW_FIELD: base64.b64encode(payload).decode()}).encode(), None


def json_to_payload(data: bytes) -> bytes:
    """The msgpack payload a JSON message of :func:`payload_to_json` was made from."""
    d = _JS_DEC.decode(data)
    if isinstance(d, dict) and len(d) == 1 and RAW_FIELD in d:
        return base64.b64decode(d[RAW_FIELD])
    return _MP_ENC.encode(d)


# --------------------------------------------------------------------------- sink

class McapSink:
    """Writes swarmcover messages to an MCAP file; registers schemas and channels lazily.

    scene_hz: rate (per second of log time) of ``/swarmcover/scene`` SceneUpdates built
    from what is written (0 = no scene channel); one more is written at ``close()``.
    Not thread-safe: one writer thread at a time.
    """

    def __init__(self, path: str | os.PathLike, *, metadata: dict[str, str] | None = None,
                 scene_hz: float = 0.0):
        self.path = Path(path)
        if self.path.parent and not self.path.parent.exists():
            raise FileNotFoundError(f"output {self.path}: directory {self.path.parent} does not exist")
        self._f = open(self.path, "wb")
        self._w = Writer(self._f, compression=CompressionType.ZSTD)
        self._w.start(profile=PROFILE, library="swarmcover-record/mcap")
        if metadata:
            self._w.add_metadata("swarmcover", {str(k): str(v) for k, v in metadata.items()})
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._seq: Counter = Counter()
        self.counts: Counter = Counter()   # messages per key
        self.bytes = 0
        self.closed = False
        self.scene_hz = scene_hz
        self.scenes = 0
        self._scene = None
        self._scene_cid = None
        self._scene_at = -1
        self._scene_seq = 0
        self._scene_last_t = 0
        self._live: set[int] = set()
        self._pending: dict[str, bytes] = {}
        self._pending_odom: dict[str, bytes] = {}
        if scene_hz > 0:
            from swarmcover.recording.scene import SceneState
            self._scene = SceneState()

    def _schema_id(self, tag: str | None) -> int:
        if tag is None:
            tag = RAW_SCHEMA
        sid = self._schemas.get(tag)
        if sid is None:
            if tag == LIVELINESS_SCHEMA:
                data = json.dumps(_LIVELINESS_SCHEMA).encode()
            elif tag in m.REGISTRY:
                data = schema_bytes(m.REGISTRY[tag])
            else:
                tag, data = RAW_SCHEMA, json.dumps(_RAW_SCHEMA).encode()
                if tag in self._schemas:
                    return self._schemas[tag]
            sid = self._w.register_schema(tag, SCHEMA_ENCODING, data)
            self._schemas[tag] = sid
        return sid

    def _channel(self, key: str, kind: str, tag: str | None) -> int:
        cid = self._channels.get((key, kind))
        if cid is None:
            if kind == KIND_LIVELINESS:
                sid = self._schema_id(LIVELINESS_SCHEMA)
            else:
                cls = message_for_key(key)
                sid = self._schema_id(cls.TAG if cls is not None else tag)
            cid = self._w.register_channel(key, MSG_ENCODING, sid, {"zenoh": kind})
            self._channels[(key, kind)] = cid
        return cid

    def write(self, key: str, payload: bytes, log_time_ns: int, *, kind: str = KIND_PUT,
              publish_time_ns: int | None = None) -> None:
        """Write one message. kind: "put", "query_reply" or "liveliness" (payload b"put"/b"delete").

        ``payload`` is the msgpack bytes as they travelled; they are stored as JSON.
        """
        if kind not in (KIND_PUT, KIND_LIVELINESS, KIND_QUERY_REPLY):
            raise ValueError(f"McapSink.write kind={kind!r}: expected put, liveliness or query_reply")
        if kind == KIND_LIVELINESS:
            token = bytes(payload).decode("ascii", "replace")
            if token not in ("put", "delete"):
                raise ValueError(f"McapSink.write liveliness on {key}: payload {token!r}, "
                                 "expected b'put' or b'delete'")
            data, tag = json.dumps({"token": token}).encode(), None
        else:
            data, tag = payload_to_json(payload)
        cid = self._channel(key, kind, tag)
        self._seq[cid] += 1
        self._w.add_message(cid, log_time=int(log_time_ns), data=data,
                            publish_time=int(publish_time_ns or log_time_ns),
                            sequence=self._seq[cid])
        self.counts[key] += 1
        self.bytes += len(payload)
        if self._scene is not None and kind != KIND_LIVELINESS:
            self._feed_scene(key, payload, tag, int(log_time_ns))

    def _feed_scene(self, key: str, payload: bytes, tag: str | None, t_ns: int) -> None:
        """Keep the latest payload of each kind the scene draws; decode them (validated)
        only when an update is due, so the cost follows scene_hz, not the Truth rate."""
        if tag in ("Truth", "Complex", "WorldInfo"):
            self._pending[tag] = payload
        elif tag == "Pose" and key.endswith("/odom"):  # mocap of live robots, per robot
            self._pending_odom[key] = payload
        else:
            return
        self._scene_last_t = max(self._scene_last_t, t_ns)
        if t_ns - self._scene_at >= 1e9 / self.scene_hz:
            self.write_scene(t_ns)

    def _apply_pending(self) -> None:
        st = self._scene
        for tag in ("WorldInfo", "Complex", "Truth"):
            payload = self._pending.pop(tag, None)
            if payload is None:
                continue
            try:
                msg = m.decode(payload)
            except m.WireError:
                continue
            st.on_message(msg)
            if isinstance(msg, m.Truth):
                self._live = {int(i) for i, lv in zip(msg.ids, msg.live) if lv}
        odom, self._pending_odom = self._pending_odom, {}
        for key, payload in odom.items():
            parts = key.split("/")
            if len(parts) >= 2 and parts[-2].isdigit() and int(parts[-2]) in self._live:
                try:
                    st.on_message(m.decode(payload))
                except m.WireError:
                    pass

    def write_scene(self, log_time_ns: int) -> bool:
        """Write the current scene as one SceneUpdate (if the scene has anything to show)."""
        st = self._scene
        if st is None:
            return False
        self._apply_pending()
        if not st.ready:
            return False
        from swarmcover.recording.scene import SCENE_TOPIC, scene_schema
        if self._scene_cid is None:
            sch = scene_schema()
            sid = self._w.register_schema(sch.name, sch.encoding, sch.data)
            self._scene_cid = self._w.register_channel(SCENE_TOPIC, "protobuf", sid,
                                                       {"swarmcover": KIND_SCENE})
        data = st.update(log_time_ns).encode()
        self.scenes += 1
        self._w.add_message(self._scene_cid, log_time=int(log_time_ns), data=data,
                            publish_time=int(log_time_ns), sequence=self.scenes)
        self._scene_at = log_time_ns
        self._scene_seq = st.seq
        return True

    def write_message(self, key: str, msg: m.Message, log_time_ns: int, **kw) -> None:
        """Encode and write a message object (for tests and converters)."""
        self.write(key, msg.encode(), log_time_ns, **kw)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            if self._scene is not None and (self._pending or self._pending_odom
                                            or self._scene.seq != self._scene_seq):
                self.write_scene(max(self._scene_last_t, self._scene_at + 1))
            self._w.finish()
        finally:
            self._f.close()

    def __enter__(self) -> "McapSink":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --------------------------------------------------------------------------- recorder

def _zenoh():
    import zenoh  # imported lazily: McapSink users need no Zenoh
    return zenoh


class Recorder:
    """Records ``keyexpr`` from an open Zenoh session into an MCAP file.

    session: an open session (not closed by the recorder); keyexpr: e.g. ``sc/run1/**``;
    path: output file; exclude: key expressions not to record (e.g. ``sc/run1/robot/*/sense``);
    world_info_key: key of the world/info queryable (default: derived from a ``.../**``
    keyexpr, None to skip); metadata: extra MCAP metadata strings; scene_hz: rate of the
    ``/swarmcover/scene`` channel (default SCENE_HZ, 0 = none).

    ``start()`` declares the subscribers and starts a writer thread; Zenoh callbacks only
    stamp and enqueue. ``stop()`` undeclares, writes what is queued and finishes the file;
    it returns the counts. Usable as a context manager.
    """

    def __init__(self, session, keyexpr: str, path: str | os.PathLike, *,
                 exclude: Iterable[str] = (), world_info_key: str | None = "auto",
                 metadata: dict[str, str] | None = None, query_timeout_s: float = 2.0,
                 scene_hz: float = None):
        zenoh = _zenoh()
        self.session = session
        self._PUT = zenoh.SampleKind.PUT
        try:
            self.keyexpr = str(zenoh.KeyExpr(keyexpr))
        except Exception as e:
            raise ValueError(f"key expression {keyexpr!r}: {e}") from None
        self.exclude = []
        for pat in exclude:
            try:
                self.exclude.append(zenoh.KeyExpr(pat))
            except Exception as e:
                raise ValueError(f"exclude pattern {pat!r}: {e}") from None
        if world_info_key == "auto":
            world_info_key = (self.keyexpr[:-3] + "/world/info"
                              if self.keyexpr.endswith("/**") and "*" not in self.keyexpr[:-3]
                              else None)
        self.world_info_key = world_info_key
        self.path = Path(path)
        self.query_timeout_s = query_timeout_s
        self.scene_hz = SCENE_HZ if scene_hz is None else float(scene_hz)
        self._meta = {"keyexpr": self.keyexpr, "started_unix_ns": str(time.time_ns()),
                      "exclude": ",".join(str(e) for e in self.exclude), **(metadata or {})}
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._sink: McapSink | None = None
        self._subs: list = []
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._excluded_cache: dict[str, bool] = {}
        self._want_info = threading.Event()
        self.have_world_info = False
        self.deletes_skipped = 0
        self.errors = 0
        self._n = 0       # messages written (read from other threads: plain ints only)
        self._nkeys = 0
        self._stopped = False

    # -- callbacks: stamp and enqueue only
    def _on_sample(self, sample) -> None:
        kind = KIND_PUT if sample.kind == self._PUT else "delete"
        ts = sample.timestamp
        pub = None
        if ts is not None:
            try:
                pub = int(ts.get_time().timestamp() * 1e9)
            except Exception:
                pub = None
        self._q.put((time.time_ns(), str(sample.key_expr), kind,
                     sample.payload.to_bytes() if kind == KIND_PUT else b"", pub))

    def _on_token(self, sample) -> None:
        put = sample.kind == self._PUT
        self._q.put((time.time_ns(), str(sample.key_expr), KIND_LIVELINESS,
                     b"put" if put else b"delete", None))

    # -- life cycle
    def start(self) -> "Recorder":
        if self._thread is not None:
            raise RuntimeError("Recorder.start: already started")
        self._sink = McapSink(self.path, metadata=self._meta, scene_hz=self.scene_hz)
        self._subs.append(self.session.declare_subscriber(self.keyexpr, self._on_sample))
        self._subs.append(self.session.liveliness().declare_subscriber(
            self.keyexpr, self._on_token, history=True))
        if self.world_info_key:
            self._want_info.set()
        self._thread = threading.Thread(target=self._run, name="recorder-writer", daemon=True)
        self._thread.start()
        atexit.register(self.stop)  # a forgotten stop() still leaves a readable file
        return self

    def _excluded(self, key: str) -> bool:
        hit = self._excluded_cache.get(key)
        if hit is None:
            hit = any(p.intersects(key) for p in self.exclude)
            self._excluded_cache[key] = hit
        return hit

    def _query_world_info(self) -> None:
        self._want_info.clear()
        try:
            replies = self.session.get(self.world_info_key, timeout=self.query_timeout_s)
            for reply in replies:
                s = reply.ok
                if s is None:
                    continue
                key = str(s.key_expr)
                self._write(time.time_ns(), key, KIND_QUERY_REPLY, s.payload.to_bytes(), None)
                self.have_world_info = True
        except Exception as e:  # a failed query is logged, never fatal to recording
            self.errors += 1
            log.warning("world/info query on %s failed: %s", self.world_info_key, e)

    def _write(self, t, key, kind, payload, pub) -> None:
        if kind == "delete":
            self.deletes_skipped += 1
            return
        if self._excluded(key):
            return
        try:
            self._sink.write(key, payload, t, kind=kind, publish_time_ns=pub)
            self._n += 1
            self._nkeys = len(self._sink.counts)
        except Exception as e:
            self.errors += 1
            if self.errors <= 3:
                log.warning("cannot write message on %s: %s", key, e)

    def _run(self) -> None:
        world_alive = (self.world_info_key.rsplit("/world/info", 1)[0] + "/alive/world/"
                       if self.world_info_key else None)
        while True:
            if self._want_info.is_set():
                self._query_world_info()
            try:
                item = self._q.get(timeout=0.05)
            except queue.Empty:
                if self._stop.is_set():
                    break
                continue
            self._write(*item)
            if (world_alive and not self.have_world_info and item[2] == KIND_LIVELINESS
                    and item[1].startswith(world_alive) and item[3] == b"put"):
                self._want_info.set()

    def stop(self) -> dict:
        """Stop recording, finish the file; returns :meth:`stats`. Idempotent."""
        if self._stopped:
            return self.stats()
        self._stopped = True
        atexit.unregister(self.stop)
        for s in self._subs:
            try:
                s.undeclare()
            except Exception:
                pass
        self._subs.clear()
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
        if self._sink is not None:
            self._sink.close()
        return self.stats()

    def stats(self) -> dict:
        sink = self._sink
        counts = dict(sink.counts) if sink else {}
        return {"path": str(self.path), "messages": sum(counts.values()), "keys": len(counts),
                "bytes": sink.bytes if sink else 0, "world_info": self.have_world_info,
                "deletes_skipped": self.deletes_skipped, "errors": self.errors,
                "scenes": sink.scenes if sink else 0, "counts": counts}

    @property
    def messages(self) -> int:
        """Messages written so far (safe to read from any thread)."""
        return self._n

    @property
    def keys(self) -> int:
        """Distinct keys written so far (safe to read from any thread)."""
        return self._nkeys

    def __enter__(self) -> "Recorder":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


# --------------------------------------------------------------------------- CLI

def resolve_keyexpr(expr: str | None, swarm: str) -> str:
    """``None`` -> ``sc/<swarm>/**``; a key not starting with ``sc/`` is taken relative to it."""
    prefix = f"{ROOT}/{swarm}"
    if not expr:
        return prefix + "/**"
    if expr == ROOT or expr.startswith(ROOT + "/"):
        return expr
    return f"{prefix}/{expr.lstrip('/')}"


def convert(src: str | os.PathLike, dst: str | os.PathLike, *, scene_hz: float = SCENE_HZ,
            progress=None) -> dict:
    """Rewrite recording ``src`` (any format this package wrote) as ``dst`` in this format,
    with the scene channel; returns {"messages", "scenes"}. Payloads are kept exactly."""
    from swarmcover.recording.replay import read_messages, recording_metadata
    if Path(src).resolve() == Path(dst).resolve():
        raise ValueError(f"--from {src} and -o {dst}: the same file; write to a new one")
    meta = recording_metadata(src)
    meta["converted_from"] = Path(src).name
    n = 0
    with McapSink(dst, metadata=meta, scene_hz=scene_hz) as sink:
        for r in read_messages(src):
            if r.kind == KIND_SCENE:
                continue
            sink.write(r.key, r.data, r.log_time_ns, kind=r.kind)
            n += 1
            if progress is not None and n % 2000 == 0:
                progress.set(n)
    return {"messages": n, "scenes": sink.scenes}


def _args(p: argparse.ArgumentParser) -> None:
    p.add_argument("keyexpr", nargs="?", default=None,
                   help="key expression to record (default sc/<swarm>/**; a key not starting "
                        "with 'sc/' is relative to sc/<swarm>/)")
    p.add_argument("-o", "--output", required=True, metavar="FILE.mcap", help="output MCAP file")
    p.add_argument("--exclude", "-x", action="append", default=[], metavar="KEYEXPR",
                   help="do not record keys matching this (relative like KEYEXPR); repeatable")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--scene-hz", type=float, default=SCENE_HZ, metavar="HZ",
                   help=f"foxglove.SceneUpdate rate on /swarmcover/scene, per second of "
                        f"recorded time (default {SCENE_HZ:g})")
    p.add_argument("--no-scene", action="store_true", help="no /swarmcover/scene channel")
    p.add_argument("--from", dest="from_file", default=None, metavar="OLD.mcap",
                   help="no Zenoh: convert a recording (e.g. an older msgpack one) to this "
                        "format, adding the scene channel, and exit")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress line")


def _prepare(args) -> int | None:
    """Flags checked before any connection; ``--from`` converts offline and ends here."""
    from swarmcover.bus.keys import check_swarm
    from swarmcover.ground.progress import Progress
    args.scene_hz = 0.0 if args.no_scene else args.scene_hz
    if args.scene_hz < 0:
        raise ValueError(f"--scene-hz {args.scene_hz:g}: must be >= 0")
    if args.from_file is not None:
        with Progress(label="convert", unit="msg", enabled=not args.quiet) as prog:
            try:
                st = convert(args.from_file, args.output, scene_hz=args.scene_hz, progress=prog)
            except OSError as e:
                raise ValueError(str(e)) from None
        print(f"converted {st['messages']} messages (+{st['scenes']} scene updates) "
              f"{args.from_file} -> {args.output}", file=sys.stderr)
        return 0
    try:
        check_swarm(args.swarm)
    except ValueError as e:
        raise ValueError(f"--swarm: {e}") from None
    return None


def _serve(args, session, keys, stop) -> int:
    from swarmcover.bus.node import ready
    from swarmcover.ground.progress import Progress
    keyexpr = resolve_keyexpr(args.keyexpr, args.swarm)
    excludes = [resolve_keyexpr(x, args.swarm) for x in args.exclude]
    rec = None
    try:
        try:
            rec = Recorder(session, keyexpr, args.output, exclude=excludes,
                           metadata={"swarm": args.swarm}, scene_hz=args.scene_hz)
            rec.start()
        except OSError as e:
            raise ValueError(str(e)) from None
        ready(f"record {keyexpr} -> {args.output}")
        end = None if args.duration is None else time.monotonic() + args.duration
        with Progress(label="record", unit="msg", enabled=not args.quiet) as prog:
            while not stop.wait(0.2):
                prog.set(rec.messages, note=f"{rec.keys} keys")
                if end is not None and time.monotonic() >= end:
                    break
            stats = rec.stop()
            prog.set(stats["messages"], note=f"{stats['keys']} keys")
        info = "" if stats["world_info"] else " (no world/info: world not up?)"
        print(f"recorded {stats['messages']} messages on {stats['keys']} keys, "
              f"{stats['bytes']} payload bytes -> {args.output}{info}", file=sys.stderr)
    finally:
        if rec is not None:
            rec.stop()
    return 0


def main(argv: list[str] | None = None) -> int:
    from swarmcover.bus.node import run_node
    # grace 0: the recorder bounds its own exit and must never be cut short mid-flush
    return run_node("swarmcover record", __doc__, _args, _serve, argv=argv,
                    logger="swarmcover.recording.record", before_session=_prepare, grace_s=0,
                    formatter_class=argparse.RawDescriptionHelpFormatter)

if __name__ == "__main__":
    sys.exit(main())

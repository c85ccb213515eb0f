"""The swarmcover wire contract: typed messages, encoded as msgpack maps.

Every message is a dataclass registered under a type tag. On the wire it is a msgpack
map ``{"_t": tag, "_v": version, field: value, ...}``. Decoding checks the tag, the
schema version, every field's type, range and finiteness, and cross-field lengths, and
raises :class:`WireError` naming the message type and the field.

Each field is declared once, with an ``f_*`` helper below. From those declarations the
codec derives, per message, a msgspec Struct that checks the tag, version, types, bounds
and lengths in C (issue 20: decoding is 4-8x faster than checking each field in Python,
bench/msgspec_decode.py). What msgspec cannot express (same-length lists, a message's
``_post_check``, polygons of coordinate pairs) is checked in Python after it. A payload
msgspec rejects goes through the field checkers in Python (``_decode_checked``), the
reference semantics: they name the field and the reason, and they decide. So the fast
path accepts only what they accept (tests/test_wire_corpus.py holds the two to each other
and to payloads saved from the codec before msgspec).

Units and frames, unless a field says otherwise:
  * lengths in metres, times in seconds, angles in radians;
  * bearings are body-frame, CCW positive, in [-pi, pi];
  * poses (x, y, theta) are in the world frame of the map.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Annotated, Any, Callable, ClassVar, Literal, Union

import msgpack
import msgspec

PI = math.pi
_ABSURD_SPEED = 100.0  # m/s or rad/s: anything larger is a bug or an attack
_MAX_LIST = 100_000
_MAX_STR = 1_000


class WireError(ValueError):
    """A payload that does not decode to a valid message. ``field`` names the culprit."""

    def __init__(self, msg_type: str, field: str, reason: str):
        self.msg_type = msg_type
        self.field = field
        self.reason = reason
        super().__init__(f"{msg_type}.{field}: {reason}")


# --------------------------------------------------------------------------- fields
# A field checker takes (value) and returns the normalised value or raises ValueError.

def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_float(v: Any, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number, got {type(v).__name__}")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"not finite: {v}")
    if v < lo or v > hi:
        raise ValueError(f"{v} outside [{lo}, {hi}]")
    return v


def _check_int(v: Any, lo: int, hi: int) -> int:
    if not _is_int(v):
        raise ValueError(f"expected an integer, got {type(v).__name__}")
    if v < lo or v > hi:
        raise ValueError(f"{v} outside [{lo}, {hi}]")
    return v


def f_float(lo: float = -1e9, hi: float = 1e9, default: float = 0.0, optional: bool = False):
    """optional: a payload may omit the field (decoded as ``default``), so a field added
    later stays wire compatible with senders that predate it."""
    return field(default=default, metadata={"check": lambda v: _check_float(v, lo, hi),
                                             "kind": "float", "lo": lo, "hi": hi,
                                             "optional": optional})


def f_int(lo: int = -(2**62), hi: int = 2**62, default: int = 0, optional: bool = False):
    return field(default=default, metadata={"check": lambda v: _check_int(v, lo, hi),
                                             "kind": "int", "lo": lo, "hi": hi,
                                             "optional": optional})


def f_bool(default: bool = False, optional: bool = False):
    def check(v):
        if not isinstance(v, bool):
            raise ValueError(f"expected a bool, got {type(v).__name__}")
        return v
    return field(default=default, metadata={"check": check, "kind": "bool", "optional": optional})


def f_str(choices: tuple[str, ...] | None = None, maxlen: int = _MAX_STR, default: str = "",
          optional: bool = False):
    def check(v):
        if not isinstance(v, str):
            raise ValueError(f"expected a string, got {type(v).__name__}")
        if len(v) > maxlen:
            raise ValueError(f"longer than {maxlen} characters")
        if choices is not None and v not in choices:
            raise ValueError(f"{v!r} not one of {', '.join(choices)}")
        return v
    return field(default=default, metadata={"check": check, "kind": "str", "choices": choices,
                                            "maxlen": maxlen, "optional": optional})


def _list(v: Any) -> list:
    if not isinstance(v, (list, tuple)):
        raise ValueError(f"expected a list, got {type(v).__name__}")
    if len(v) > _MAX_LIST:
        raise ValueError(f"list longer than {_MAX_LIST}")
    return list(v)


def f_floats(lo: float = -1e9, hi: float = 1e9, optional: bool = False):
    def check(v):
        out = _list(v)
        for k, x in enumerate(out):
            try:
                out[k] = _check_float(x, lo, hi)
            except ValueError as e:
                raise ValueError(f"[{k}]: {e}") from None
        return out
    return field(default_factory=list, metadata={"check": check, "kind": "floats", "lo": lo,
                                                 "hi": hi, "optional": optional})


def f_ints(lo: int = -(2**62), hi: int = 2**62, optional: bool = False):
    def check(v):
        out = _list(v)
        for k, x in enumerate(out):
            try:
                _check_int(x, lo, hi)
            except ValueError as e:
                raise ValueError(f"[{k}]: {e}") from None
        return out
    return field(default_factory=list, metadata={"check": check, "kind": "ints", "lo": lo,
                                                 "hi": hi, "optional": optional})


def f_bools(optional: bool = False):
    def check(v):
        out = _list(v)
        for k, x in enumerate(out):
            if not isinstance(x, bool):
                raise ValueError(f"[{k}]: expected a bool, got {type(x).__name__}")
        return out
    return field(default_factory=list, metadata={"check": check, "kind": "bools",
                                                 "optional": optional})


def f_strs(maxlen: int = _MAX_STR, optional: bool = False):
    def check(v):
        out = _list(v)
        for k, x in enumerate(out):
            if not isinstance(x, str):
                raise ValueError(f"[{k}]: expected a string, got {type(x).__name__}")
            if len(x) > maxlen:
                raise ValueError(f"[{k}]: longer than {maxlen} characters")
        return out
    return field(default_factory=list, metadata={"check": check, "kind": "strs",
                                                 "maxlen": maxlen, "optional": optional})


def _check_pairs(polys: list) -> None:
    """Each polygon is a flat list of (x, y) pairs: the part of f_polys msgspec cannot
    check (the fast path runs it after msgspec; the checker below says the same)."""
    for k, poly in enumerate(polys):
        if len(poly) % 2:
            raise ValueError(f"[{k}]: odd number of coordinates")


def f_polys(lo: float = -1e6, hi: float = 1e6):
    """A list of polygons, each a flat list [x0, y0, x1, y1, ...] (world frame, m)."""
    def check(v):
        out = _list(v)
        for k, poly in enumerate(out):
            p = _list(poly)
            if len(p) % 2:
                raise ValueError(f"[{k}]: odd number of coordinates")
            for m, x in enumerate(p):
                try:
                    p[m] = _check_float(x, lo, hi)
                except ValueError as e:
                    raise ValueError(f"[{k}][{m}]: {e}") from None
            out[k] = p
        return out
    return field(default_factory=list, metadata={"check": check, "kind": "polys", "lo": lo,
                                                 "hi": hi, "after": _check_pairs})


# --------------------------------------------------------------------------- registry

REGISTRY: dict[str, type["Message"]] = {}


class Message:
    """Base of every wire message. Subclasses are dataclasses registered with @message."""

    TAG: ClassVar[str] = ""
    VERSION: ClassVar[int] = 1
    _FIELDS: ClassVar[tuple] = ()
    _SAME_LEN: ClassVar[tuple] = ()  # groups of list fields that must have equal lengths
    _META: ClassVar[dict] = {}       # field name -> {"kind", bounds, choices} (schemas, tests)
    _OPTIONAL: ClassVar[dict] = {}   # field name -> default factory, for fields a sender may omit
    _NAMES: ClassVar[tuple] = ()     # field names in wire order (after "_t", "_v")
    _AFTER: ClassVar[tuple] = ()     # (field name, check) msgspec cannot do, run after it
    _WIRE: ClassVar[type] = object   # the msgspec Struct derived from the fields (decoding)
    _POST: ClassVar[Any] = None      # the class's _post_check, if it has one

    def encode(self) -> bytes:
        return encode(self)

    def to_dict(self) -> dict:
        d = {"_t": self.TAG, "_v": self.VERSION}
        for name, _ in self._FIELDS:
            d[name] = getattr(self, name)
        return d

    def validate(self) -> "Message":
        """Check this instance as decoding would; returns self or raises WireError."""
        _validate_into(type(self), {k: _plain(v) for k, v in self.to_dict().items()})
        return self


def _bounded(typ: type, meta: dict) -> Any:
    """int or float with the field's [lo, hi] as a msgspec constraint. msgspec's bounds
    reject NaN; finite bounds also reject +-inf, as the Python checker does."""
    lo, hi = meta["lo"], meta["hi"]
    if typ is float and not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"float field bounds must be finite, got [{lo}, {hi}]")
    return Annotated[typ, msgspec.Meta(ge=lo, le=hi)]


def _listof(typ: Any) -> Any:
    return Annotated[list[typ], msgspec.Meta(max_length=_MAX_LIST)]


def wire_type(meta: dict) -> Any:
    """The msgspec type of a field, from its f_* declaration: the same types, bounds,
    choices and length caps its checker enforces. msgspec accepts ints for floats (made
    floats) and rejects bools for ints, as the checkers do."""
    kind = meta["kind"]
    if kind == "float":
        return _bounded(float, meta)
    if kind == "int":
        return _bounded(int, meta)
    if kind == "bool":
        return bool
    if kind == "str":
        if meta["choices"] is not None:
            return Literal[meta["choices"]]
        return Annotated[str, msgspec.Meta(max_length=meta["maxlen"])]
    if kind == "floats":
        return _listof(_bounded(float, meta))
    if kind == "ints":
        return _listof(_bounded(int, meta))
    if kind == "bools":
        return _listof(bool)
    if kind == "strs":
        return _listof(Annotated[str, msgspec.Meta(max_length=meta["maxlen"])])
    if kind == "polys":
        return _listof(_listof(_bounded(float, meta)))
    raise ValueError(f"no wire type for field kind {kind!r}")


def _wire_struct(cls) -> type:
    """A msgspec Struct for ``cls`` on the wire: tag "_t", a "_v" that must be the
    version, every field required unless declared optional (then the class default), no
    unknown fields."""
    spec: list = [("_v", Literal[cls.VERSION])]
    for f in dataclasses.fields(cls):
        typ = wire_type(f.metadata)
        if not f.metadata.get("optional"):
            spec.append((f.name, typ))
        elif f.default_factory is not dataclasses.MISSING:
            spec.append((f.name, typ, msgspec.field(default_factory=f.default_factory)))
        else:
            spec.append((f.name, typ, f.default))
    wire = msgspec.defstruct(f"{cls.__name__}Wire", spec, tag_field="_t", tag=cls.TAG,
                             forbid_unknown_fields=True, kw_only=True,
                             module=cls.__module__, namespace={"_message": cls})
    if wire.__struct_fields__ != ("_v",) + cls._NAMES:   # decode() builds cls from this order
        raise RuntimeError(f"{cls.TAG}: wire fields {wire.__struct_fields__} out of order")
    return wire


def message(tag: str, version: int = 1, same_len: tuple = ()):
    """Class decorator: make a slotted dataclass and register it under ``tag``."""

    def register(cls):
        cls = dataclass(slots=True)(cls)
        cls.TAG = tag
        cls.VERSION = version
        cls._SAME_LEN = same_len
        cls._FIELDS = tuple((f.name, f.metadata["check"]) for f in dataclasses.fields(cls))
        cls._META = {f.name: dict(f.metadata) for f in dataclasses.fields(cls)}
        cls._OPTIONAL = {f.name: (f.default_factory if f.default_factory is not dataclasses.MISSING
                                  else (lambda v=f.default: v))
                         for f in dataclasses.fields(cls) if f.metadata.get("optional")}
        cls._NAMES = tuple(f.name for f in dataclasses.fields(cls))
        cls._AFTER = tuple((f.name, f.metadata["after"]) for f in dataclasses.fields(cls)
                           if f.metadata.get("after"))
        cls._WIRE = _wire_struct(cls)
        cls._POST = getattr(cls, "_post_check", None)
        if tag in REGISTRY:
            raise RuntimeError(f"duplicate message tag {tag}")
        REGISTRY[tag] = cls
        _DECODERS.clear()
        return cls

    return register


def _plain(v: Any) -> Any:
    """numpy scalars/arrays to plain Python for msgpack."""
    tolist = getattr(v, "tolist", None)
    return tolist() if tolist is not None else v


def _enc_hook(v: Any) -> Any:
    """msgspec calls this for values it cannot encode itself: numpy arrays and scalars
    (numpy float64 is a float and needs none) become the plain values they hold."""
    tolist = getattr(v, "tolist", None)
    if tolist is None:
        raise TypeError(f"cannot encode {type(v).__name__} on the wire")
    return tolist()


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_enc_hook)


def encode(msg: Message) -> bytes:
    """Serialise a message to msgpack bytes. Does not validate (call .validate() for that).

    The bytes are those msgpack.packb made of the same map before msgspec (smallest int
    and str headers, floats as float64), tests/test_wire_corpus.py checks it."""
    d = {"_t": msg.TAG, "_v": msg.VERSION}
    for name in msg._NAMES:
        d[name] = getattr(msg, name)
    return _ENCODER.encode(d)


def _validate_into(cls, d: dict) -> Message:
    """The reference checks: each field's checker in declaration order, then the
    cross-field rules. Raises WireError naming the first bad field."""
    vals = {}
    for name, check in cls._FIELDS:
        if name not in d:
            if name in cls._OPTIONAL:
                vals[name] = cls._OPTIONAL[name]()
                continue
            raise WireError(cls.TAG, name, "missing")
        try:
            vals[name] = check(d[name])
        except ValueError as e:
            raise WireError(cls.TAG, name, str(e)) from None
    return _cross_check(cls(**vals))


def _cross_check(obj: Message) -> Message:
    """What holds between fields: equal lengths (``same_len``), then ``_post_check``."""
    cls = type(obj)
    for group in cls._SAME_LEN:
        n = len(getattr(obj, group[0]))
        for name in group:
            if len(getattr(obj, name)) != n:
                lens = {k: len(getattr(obj, k)) for k in group}
                raise WireError(cls.TAG, group[-1], f"length mismatch: {lens}")
    if cls._POST is not None:
        cls._POST(obj)
    return obj


_DECODERS: dict = {}   # expected (None, a class or a tuple of classes) -> msgspec Decoder


def _decoder(expected) -> msgspec.msgpack.Decoder:
    """The msgspec decoder for ``expected``: one Struct, or the union of the allowed (all
    registered, for None) tagged by "_t"."""
    dec = _DECODERS.get(expected)
    if dec is None:
        classes = (tuple(REGISTRY.values()) if expected is None
                   else expected if isinstance(expected, tuple) else (expected,))
        dec = _DECODERS[expected] = msgspec.msgpack.Decoder(Union[tuple(c._WIRE for c in classes)])
    return dec


def decode(data: bytes, expected: type | tuple | None = None) -> Message:
    """Decode and validate a payload. Raises WireError on anything wrong.

    ``expected``: a message class (or tuple of classes) the payload must be.

    msgspec decodes and checks the fields; the rules it cannot express follow in Python.
    Whatever msgspec rejects (invalid payloads, but also the odd valid one it is stricter
    about, such as ``_v`` sent as 1.0) is decided by the Python checkers, which name the
    field in the WireError.
    """
    try:
        wire = _decoder(expected).decode(data)
    except Exception:  # msgspec's DecodeError/ValidationError, or data that is no buffer
        return _decode_checked(data, expected)
    cls = wire._message
    obj = cls(*msgspec.structs.astuple(wire)[1:])
    for name, after in cls._AFTER:
        try:
            after(getattr(obj, name))
        except ValueError as e:
            raise WireError(cls.TAG, name, str(e)) from None
    return _cross_check(obj)


def _decode_checked(data: bytes, expected: type | tuple | None = None) -> Message:
    """decode() by the field checkers alone (msgpack, then Python): slower, exact errors."""
    name = expected.TAG if isinstance(expected, type) else "Message"
    try:
        d = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True, max_bin_len=0,
                            max_ext_len=0)
    except Exception as e:  # msgpack raises several types for garbage
        raise WireError(name, "_payload", f"not msgpack: {e.__class__.__name__}: {e}") from None
    if not isinstance(d, dict):
        raise WireError(name, "_payload", f"expected a map, got {type(d).__name__}")
    tag = d.get("_t")
    cls = REGISTRY.get(tag) if isinstance(tag, str) else None
    if cls is None:
        raise WireError(name, "_t", f"unknown message type {tag!r}")
    if expected is not None:
        exp = expected if isinstance(expected, tuple) else (expected,)
        if cls not in exp:
            raise WireError(name, "_t", f"got {tag}, expected {' or '.join(c.TAG for c in exp)}")
    ver = d.get("_v")
    if ver != cls.VERSION:
        raise WireError(cls.TAG, "_v", f"schema version {ver!r}, this build speaks {cls.VERSION}")
    extra = set(d) - {"_t", "_v"} - {n for n, _ in cls._FIELDS}
    if extra:
        raise WireError(cls.TAG, sorted(extra)[0], "unknown field")
    return _validate_into(cls, d)


def decode_to_dict(data: bytes) -> dict:
    """Decode and validate, returning a JSON-friendly dict with _t and _v (for inspection)."""
    return decode(data).to_dict()


# --------------------------------------------------------------------------- messages

ANGLE = dict(lo=-PI - 1e-9, hi=PI + 1e-9)
ROBOT_KINDS = ("holonomic", "diffdrive")


@message("Sense", same_len=(("ids", "bearings", "back_bearings"), ("touch", "touch_robot")))
class Sense(Message):
    """World -> agent, one per robot per tick: what the robot's camera and bumpers feel.

    ids/bearings: visible robots and their body-frame bearings (rad).
    back_bearings: for each visible robot l, the bearing at which l sees this robot, in l's
      body frame (rad) -- emulates neighbours telling each other (spec 1.5); used for frame
      alignment (spec 4.7).
    touch: body-frame centre bearings (rad) of active contact sectors; touch_robot: whether
      another robot touches there (it feels the contact too and tells this one, as with
      back_bearings; then the contact is not an obstacle, whatever wall it also touches).
    """
    robot: int = f_int(0)
    tick: int = f_int(0)
    t: float = f_float(0.0)
    ids: list = f_ints(0)
    bearings: list = f_floats(**ANGLE)
    back_bearings: list = f_floats(**ANGLE)
    touch: list = f_floats(**ANGLE)
    touch_robot: list = f_bools()
    # lockstep with the coordinator in the barrier: the id of the last task the coordinator
    # sent this robot before this tick (0: none yet); the agent applies its tasks up to that
    # one before it steps. -1: no barrier, tasks apply as they arrive.
    task_id: int = f_int(-1, default=-1, optional=True)
    # the coordinator asked every robot for its Status (CoordAck.report): publish one on
    # this tick, whatever the status cadence
    report: bool = f_bool(optional=True)


@message("CmdVel")
class CmdVel(Message):
    """Agent -> world (virtual robot) or hwbridge (live robot): velocity command.

    Body frame: vx forward, vy left (m/s), wz CCW (rad/s). Differential drive uses vx and
    wz only (vy must be 0). tick: the Sense tick this answers (lockstep), -1 if none.
    """
    robot: int = f_int(0)
    tick: int = f_int(-1)
    vx: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    vy: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    wz: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    # seq of the last Status the agent published before this command (-1: unknown); the
    # lockstep world announces it in the next Clock, so the coordinator knows which
    # statuses belong to the tick
    status_seq: int = f_int(-1, default=-1, optional=True)
    # the robot holds still with no task running and stays so until what it senses changes
    # (agents.core.AgentCore.idle): a lockstep world may stop sending it a Sense every tick
    # (world.wake.WakeRule) and then no longer waits for it
    idle: bool = f_bool(optional=True)


@message("Pose")
class Pose(Message):
    """A robot pose (world frame). source: who measured it (sim odometry, mocap, agent relay)."""
    robot: int = f_int(0)
    t: float = f_float(0.0)
    x: float = f_float(-1e6, 1e6)
    y: float = f_float(-1e6, 1e6)
    theta: float = f_float(**ANGLE)
    source: str = f_str(("sim", "mocap", "odom", "agent"), default="sim")


AGENT_STATES = ("starting", "idle", "holding", "moving", "deploying", "test_driving", "leaving")
TASK_STATES = ("none", "running", "done", "failed")


@message("Status", same_len=(("nbr_ids", "nbr_bearings"),))
class Status(Message):
    """Agent -> coordinator, a few Hz and on every task change.

    nbr_ids/nbr_bearings: neighbours whose link is not lost (seen within the agent's
      link_lost_ticks; last seen bearing, averaged while still), body frame (rad).
    contact/contact_bearing: sticky obstacle contact (spec 3.5), body frame (rad).
    pose: [x, y, theta] as reported by the robot's body (telemetry only, may be []).
    touch_offset: a test drive that failed with "touch": the angle (rad, CCW) from the
      direction driven to the centre of the touch sector that stopped it; the wall's normal
      lies within tau of that centre (coordinator.topology.evidence). 0 otherwise.
    reason of a wall sweep (a test_drive with ``sweep_side``) that found no opening:
      "swept HI LO" (:func:`sweep_reason`), the robot back at its vertex.
    """
    robot: int = f_int(0)
    seq: int = f_int(0)
    t: float = f_float(0.0)
    kind: str = f_str(ROBOT_KINDS, default="holonomic")
    live: bool = f_bool()
    state: str = f_str(AGENT_STATES, default="starting")
    vertex: int = f_int(-1)
    task_id: int = f_int(-1)
    task_state: str = f_str(TASK_STATES, default="none")
    reason: str = f_str(maxlen=200)
    progress: float = f_float(0.0, 1.0)
    nbr_ids: list = f_ints(0)
    nbr_bearings: list = f_floats(**ANGLE)
    contact: bool = f_bool()
    contact_bearing: float = f_float(**ANGLE)
    pose: list = f_floats(-1e6, 1e6)
    tick: int = f_int(-1, default=-1, optional=True)   # the Sense tick it answers; -1: none
    touch_offset: float = f_float(**ANGLE, optional=True)

    def _post_check(self):
        if len(self.pose) not in (0, 3):
            raise WireError(self.TAG, "pose", f"expected 0 or 3 values, got {len(self.pose)}")


TASK_KINDS = ("hold", "goto", "deploy", "test_drive", "leave")


def sweep_reason(hi: float, lo: float, by=()) -> str:
    """Status.reason of a wall sweep that found no opening: "swept HI LO", the fractions of
    the edge (from the robot's vertex towards the other end) between which its body slid
    along the wall, going round no wall's end; LO "end" when it crossed the ray at its vertex
    (Task.sweep_stop); then "by ID,ID" when a touch with robots seen in its sector stopped
    it (``by``: those robots' ids; a wall there may be one of them). The task fails with it
    once the robot is back at its vertex (with " (return: why)" after it when it could not
    get back)."""
    low = "end" if lo == -math.inf else f"{lo:.3f}"
    ids = sorted({int(i) for i in by})[:SWEEP_BY_MAX]
    return f"swept {hi:.3f} {low}" + (" by " + ",".join(map(str, ids)) if ids else "")


# at most this many robot ids after "by" (the reason stays well within Status.reason's 200
# characters); a touch sector holds one or two robots
SWEEP_BY_MAX = 8


def sweep_stoppers(reason: str) -> tuple[int, ...]:
    """The robot ids after "by" in a :func:`sweep_reason` (() when none, or not one)."""
    parts = reason.split()
    if len(parts) < 5 or parts[0] != "swept" or parts[3] != "by":
        return ()
    try:
        return tuple(int(x) for x in parts[4].split(",") if x)
    except ValueError:
        return ()


def parse_sweep_reason(reason: str) -> tuple[float, float] | None:
    """(hi, lo) of a :func:`sweep_reason` (lo -inf for "end"), or None if ``reason`` is not
    one (extra words after it, like a failed return, are ignored)."""
    parts = reason.split()
    if len(parts) < 3 or parts[0] != "swept":
        return None
    try:
        hi = float(parts[1])
        lo = -math.inf if parts[2] == "end" else float(parts[2])
    except ValueError:
        return None
    if not math.isfinite(hi) or math.isnan(lo) or lo == math.inf:
        return None
    return hi, lo


@message("Task", same_len=(("landmarks", "bearings"), ("via_landmarks", "via_bearings")))
class Task(Message):
    """Coordinator -> agent: what to do next. A new task replaces the current one.

    hold: stay, record the bearing snapshot, keep station on it.
    goto: visual homing to ``bearings`` (desired bearing to each landmark robot id, rad, in
      the reference frame), e.g. a push step to the next vertex.
    deploy: like goto, with bearings from the assumed geometry (spec 4.4); with fewer than 2
      landmarks, open-loop along ``direction`` for ``distance``; then scale correction if
      ``scale_correct``.
    test_drive: open-loop along ``direction`` for ``distance``; on a touch before
      ``keep_after`` metres, home back to ``bearings`` and fail with reason "touch"; on a
      touch after it, stop there: done with reason "wall" (the robot is the new vertex).
    leave: stop and idle (redundant robot).
    ref_offsets: per landmark, heading of the reference frame minus the landmark's heading
      (rad), for frame alignment (spec 4.7); [] means frames are parallel (psi = 0).
    via_landmarks / via_bearings (test_drive only; default empty = no approach leg): a
      probe (coordinator.topology.evidence) first homes to the point where it sees each via landmark
      (robot ids, a subset of ``landmarks`` so ``ref_offsets`` align them) at its via
      bearing (rad, reference frame); with one via landmark it drives open loop along that
      bearing for ``via_distance`` (m) instead. Then it drives along ``direction``. A touch
      on the way out sends it back to ``bearings`` as usual; an approach that fails sends it
      back and fails with reason "via (<why>)".
    sweep_* (test_drive only; ``sweep_side`` 0, the default, = none): a WALL SWEEP of the
      fence edge from this robot's vertex to the other end (coordinator.topology.evidence).
      On a touch the robot slides along the wall, pressing into it, towards the other end
      until it crosses the edge's perpendicular at fraction ``sweep_far``, then back past
      its vertex until it crosses the ray from its vertex ``sweep_stop`` (rad) beyond the
      edge's perpendicular there; then it homes back to ``bearings`` and fails with reason
      "swept HI LO" (:func:`sweep_reason`). It stays where it is, done with reason
      "opening", when it went round the end of a wall (agents.sweep), and with "room" when
      its wall recedes more than ``sweep_depth`` (m) from the edge; no touch at all is
      done as any test drive. ``sweep_edge``: direction (rad, reference frame) from the
      vertex to the other end; ``sweep_side``: +1 when the side swept is counter-clockwise
      of it, -1 clockwise. The robot finds where it is from the bearings of
      ``sweep_landmarks`` (robot ids, a subset of ``landmarks``, the other end first),
      standing at ``sweep_points`` (x, y per landmark, m, reference frame, the vertex at
      the origin). ``sweep_lenses``: room is where the wall leaves the lens of every segment
      from the vertex to a sweep landmark too, not only the edge's (agents.sweep).
    sight (test_drive only; default empty = none): robot ids, a subset of ``landmarks``
      that no other push moves, sent when nobody refills the vertex the robot leaves. The
      test leg keeps in sight one of those in view at its start: with none of them in
      view it backs up until one is, then 0.1 rv farther, and stays there, done with
      reason "link lost, backed up" (a new robot nobody sees is cut off from every
      source).
    """
    task_id: int = f_int(0)
    robot: int = f_int(0)
    epoch: int = f_int(0)
    kind: str = f_str(TASK_KINDS, default="hold")
    vertex: int = f_int(-1)
    landmarks: list = f_ints(0)
    bearings: list = f_floats(**ANGLE)
    ref_offsets: list = f_floats(**ANGLE)
    direction: float = f_float(**ANGLE)
    distance: float = f_float(0.0, 1e4)
    scale_correct: bool = f_bool()
    timeout_s: float = f_float(0.0, 1e6, default=60.0)
    keep_after: float = f_float(0.0, 1e4)  # test_drive: a touch beyond this (m) ends it "done
                                           # (wall)" with the robot kept there; 0 = never
    via_landmarks: list = f_ints(0, optional=True)
    via_bearings: list = f_floats(**ANGLE, optional=True)
    via_distance: float = f_float(0.0, 1e4, optional=True)
    sweep_side: int = f_int(-1, 1, optional=True)
    sweep_edge: float = f_float(**ANGLE, optional=True)
    sweep_far: float = f_float(0.0, 2.0, optional=True)
    sweep_stop: float = f_float(0.0, PI, optional=True)
    sweep_depth: float = f_float(0.0, 1e4, optional=True)
    sweep_landmarks: list = f_ints(0, optional=True)
    sweep_points: list = f_floats(-1e4, 1e4, optional=True)
    sweep_lenses: bool = f_bool(optional=True)
    sight: list = f_ints(0, optional=True)

    def _post_check(self):
        if self.ref_offsets and len(self.ref_offsets) != len(self.landmarks):
            raise WireError(self.TAG, "ref_offsets", "must be [] or one per landmark")
        if len(self.sweep_points) != 2 * len(self.sweep_landmarks):
            raise WireError(self.TAG, "sweep_points", "must be two (x, y) per sweep landmark")


@message("Complex", same_len=(("inferred", "inferred_why"),))
class Complex(Message):
    """Coordinator -> viewers/recorders, once per deployment cycle.

    vertices/occupants: vertex ids and the robot holding each (-1 empty).
    edges: flat vertex-id pairs [a0, b0, a1, b1, ...]; triangles: flat triples.
    frontier/obstacle: indices into the edge list. redundant: vertex ids.
    state: "running", "certified" (K empty and certificate holds) or "stopped".
    failures_healed: robot failures whose holes this coordinator has refilled so far;
    reason: why it stopped (state "stopped"), e.g. "robots_max = 40 reached".
    inferred / inferred_why: obstacle edges (indices into the edge list) closed by
      inference rather than by probes, and how ("convex_corner", "forced"); empty by
      default.
    gap_probed: obstacle edges closed on evidence by the probe lines driven in the gaps
      their wall sweeps left ('gap_probes'; the others closed on evidence are 'probes'),
      indices into the edge list; empty by default.
    exceptions: one-sided edges the fence excuses (spec 3.2: the open side lies inside
      the covered lens), indices into the edge list; with frontier and obstacle they are
      every one-sided edge, which run's re-check tests against the world's geometry.
    move_s / enter_s: mean simulated seconds (s) of the moves (a robot one vertex on along
      a push's path) and of the entries (a new robot to the source) done so far this
      epoch; 0 before the first. Their sum is about the pace at which robots leave one
      source (summary.json's ``push_floor_s``; an entry may overlap the move before it).
    """
    cycle: int = f_int(0)
    t: float = f_float(0.0)
    epoch: int = f_int(0)
    vertices: list = f_ints(0)
    occupants: list = f_ints(-1)
    edges: list = f_ints(0)
    triangles: list = f_ints(0)
    frontier: list = f_ints(0)
    obstacle: list = f_ints(0)
    redundant: list = f_ints(0)
    sources: list = f_ints(0)
    certified: bool = f_bool()
    robots: int = f_int(0)
    state: str = f_str(("running", "certified", "stopped"), default="running")
    failures_healed: int = f_int(0, optional=True)
    reason: str = f_str(maxlen=200, optional=True)
    inferred: list = f_ints(0, optional=True)
    inferred_why: list = f_strs(maxlen=40, optional=True)
    exceptions: list = f_ints(0, optional=True)
    gap_probed: list = f_ints(0, optional=True)
    move_s: float = f_float(0.0, 1e6, optional=True)
    enter_s: float = f_float(0.0, 1e6, optional=True)

    def _post_check(self):
        if len(self.vertices) != len(self.occupants):
            raise WireError(self.TAG, "occupants", "length differs from vertices")
        if len(self.edges) % 2:
            raise WireError(self.TAG, "edges", "odd length: not a list of pairs")
        if len(self.triangles) % 3:
            raise WireError(self.TAG, "triangles", "length not a multiple of 3")
        m = len(self.edges) // 2
        for name in ("frontier", "obstacle", "inferred", "exceptions", "gap_probed"):
            bad = [e for e in getattr(self, name) if e >= m]
            if bad:
                raise WireError(self.TAG, name, f"edge index {bad[0]} >= {m} edges")


@message("Clock", same_len=(("agents", "status_seqs"),))
class Clock(Message):
    """World -> all: simulation time. rtf: measured real-time factor (sim s per wall s).

    Lockstep: agents/status_seqs are the world's roster at this tick boundary (robot ids
    whose agents take part, sorted) and, per agent, the seq of the last Status it published
    before answering the previous tick: the statuses the coordinator must act on now.
    """
    tick: int = f_int(0)
    t: float = f_float(0.0)
    mode: str = f_str(("realtime", "lockstep"), default="realtime")
    rtf: float = f_float(0.0, 1e6)
    agents: list = f_ints(0, optional=True)
    status_seqs: list = f_ints(-1, optional=True)


@message("CoordAck", same_len=(("task_robots", "task_ids"),
                               ("spawn_ids", "spawn_sources", "spawn_live", "spawn_kinds")))
class CoordAck(Message):
    """Coordinator -> world (lockstep): tick ``tick``'s decisions are out.

    The world applies the listed spawns and removes at the next tick boundary, in this
    order, and tells each robot in its next Sense the last task sent to it
    (task_robots[i] got task task_ids[i]).
    """
    tick: int = f_int(0)
    task_robots: list = f_ints(0)
    task_ids: list = f_ints(0)
    spawn_ids: list = f_ints(0)
    spawn_sources: list = f_ints(0, 1000)
    spawn_live: list = f_bools()
    spawn_kinds: list = f_ints(0, len(ROBOT_KINDS) - 1)   # index into ROBOT_KINDS
    remove_ids: list = f_ints(0)
    # every robot publishes a Status with its next Sense (Sense.report): the deployer wants
    # fresh statuses (a cycle's snapshot) from robots the world may not be sensing every tick
    report: bool = f_bool(optional=True)


@message("Spawn")
class Spawn(Message):
    """Coordinator (or user) -> world: create robot ``robot`` at source index ``source``.

    live: the body is the twin of a live robot, driven by the hwbridge (TwinCmd), not by
    the agent's CmdVel.
    """
    robot: int = f_int(0)
    source: int = f_int(0, 1000)
    kind: str = f_str(ROBOT_KINDS, default="holonomic")
    live: bool = f_bool()


@message("Remove")
class Remove(Message):
    """Coordinator (or user, or a test injecting a failure) -> world: delete a robot's body."""
    robot: int = f_int(0)
    reason: str = f_str(maxlen=200)


@message("Truth", same_len=(("ids", "x", "y", "theta", "live"),))
class Truth(Message):
    """World -> recorders/viewers/reports, every tick: ground-truth poses (world frame).

    Never used by agents or the coordinator's decisions.
    """
    tick: int = f_int(0)
    t: float = f_float(0.0)
    ids: list = f_ints(0)
    x: list = f_floats(-1e6, 1e6)
    y: list = f_floats(-1e6, 1e6)
    theta: list = f_floats(**ANGLE)
    live: list = f_bools()


@message("WorldInfo")
class WorldInfo(Message):
    """World queryable reply: the map and the parameters of this run.

    boundary: flat [x0, y0, ...] outer polygon (world frame, m); obstacles: polygons.
    sources: flat [x, y, theta] per source (base station) pose.
    """
    name: str = f_str(maxlen=200)
    rv: float = f_float(1e-6, 1e6)
    robot_radius: float = f_float(0.0, 1e6)
    dt: float = f_float(1e-6, 10.0)
    mode: str = f_str(("realtime", "lockstep"), default="realtime")
    seed: int = f_int()
    boundary: list = f_floats(-1e6, 1e6)
    obstacles: list = f_polys()
    sources: list = f_floats(-1e6, 1e6)
    free_area: float = f_float(0.0, 1e12)
    config: str = f_str(maxlen=1_000_000)  # the resolved run config, TOML text


@message("MocapPose")
class MocapPose(Message):
    """Mocap source -> hwbridge: a rigid body's pose in the mocap frame (m, unit quaternion)."""
    body: str = f_str(maxlen=200)
    t: float = f_float(0.0, 1e11)  # source clock (s): may be Unix time
    x: float = f_float(-1e6, 1e6)
    y: float = f_float(-1e6, 1e6)
    z: float = f_float(-1e6, 1e6)
    qx: float = f_float(-1.0, 1.0)
    qy: float = f_float(-1.0, 1.0)
    qz: float = f_float(-1.0, 1.0)
    qw: float = f_float(-1.0, 1.0, default=1.0)


@message("LiveCmd")
class LiveCmd(Message):
    """hwbridge -> live robot driver: unicycle command, already clamped (m/s, rad/s).

    ttl: how long (s) the driver may execute this command, counted from its receipt on the
    robot's own clock (no clock sync needed); then it stops unless a newer command came.
    0 (or absent, from senders that predate the field) means "not given": the driver
    applies its own default timeout. A driver may cap it (hwbridge/README.md).
    """
    robot: int = f_int(0)
    t: float = f_float(0.0)
    v: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    omega: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    ttl: float = f_float(0.0, 10.0, optional=True)


@message("TwinCmd")
class TwinCmd(Message):
    """hwbridge -> world: drive a live robot's twin toward its mocap pose.

    vx, vy (m/s) and wz (rad/s) in the world frame; teleport: place the twin at (x, y, theta).
    """
    robot: int = f_int(0)
    t: float = f_float(0.0)
    vx: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    vy: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    wz: float = f_float(-_ABSURD_SPEED, _ABSURD_SPEED)
    teleport: bool = f_bool()
    x: float = f_float(-1e6, 1e6)
    y: float = f_float(-1e6, 1e6)
    theta: float = f_float(**ANGLE)


@message("Demo")
class Demo(Message):
    """A heartbeat published by ``swarmcover demo`` for smoke tests."""
    seq: int = f_int(0)
    t: float = f_float(0.0)
    text: str = f_str(maxlen=200)


ALL_MESSAGES: tuple[type[Message], ...] = tuple(REGISTRY.values())
Handler = Callable[[Message], None]

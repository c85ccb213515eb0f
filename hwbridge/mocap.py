"""Motion-capture sources behind one small interface, and a rate/silence monitor.

Every source yields :class:`MocapSample` (body name, source time, 3-D position in the
mocap frame (m), unit quaternion (x, y, z, w), receipt time) through
``poll(timeout) -> list[MocapSample]`` and is closed with ``close()``:

  * :class:`ZenohMocapSource`: MocapPose (msgpack) on ``sc/<swarm>/mocap/<body>``, as sent
    by ``swarmcover fake-robot`` or any publisher; or, with ``format="pose_stamped"``, CDR
    geometry_msgs/PoseStamped on a key template such as ``vrpn_mocap/{body}/pose`` (a ROS 2
    mocap node seen through zenoh-bridge-ros2dds);
  * :class:`ScriptedMocapSource`: trajectories with noise, dropouts, latency, silences and
    renamed bodies, for tests and demos (no hardware, no network);
  * :class:`LibMotionCaptureSource`: PyPI ``motioncapture`` (IMRCLab/libmotioncapture:
    vicon, optitrack, qualisys, vrpn, nokov, ...), imported lazily. Its Python objects are
    ``mc.rigidBodies -> {name: RigidBody}`` with ``.position`` (3 floats) and
    ``.rotation`` (a quaternion with ``.x .y .z .w``); :func:`samples_from_rigid_bodies`
    maps them and is tested with stand-in objects of the same shape (no hardware here).

Receipt times are ``time.monotonic()`` seconds of this process; source times are the
source's own clock (the publisher's monotonic clock for fake robots, this process's for
the scripted and libmotioncapture sources).
"""
from __future__ import annotations

import logging
import math
import queue
import random
import re
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from .frames import Transform2D, world_to_mocap, wrap

log = logging.getLogger("swarmcover.hwbridge.mocap")

MOCAP_TYPES = ("zenoh", "scripted", "motioncapture")
INSTALL_HINT = ("the 'motioncapture' package (libmotioncapture) is needed for mocap type "
                "'motioncapture': install it into swarmcover's environment with "
                "`pip install motioncapture` (binary wheels for Linux/macOS/Windows on PyPI; "
                "sources at https://github.com/IMRCLab/libmotioncapture)")


@dataclass(frozen=True, slots=True)
class MocapSample:
    """One rigid-body pose in the mocap frame. ``t``: source time (s); ``recv``: receipt
    time (s, monotonic clock of this process)."""
    body: str
    t: float
    position: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    recv: float = 0.0


class MocapSource(Protocol):
    def poll(self, timeout: float = 0.0) -> list[MocapSample]: ...

    def close(self) -> None: ...


def _finite(*vals: float) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals)


# --------------------------------------------------------------------------- Zenoh

class ZenohMocapSource:
    """Subscribes to mocap poses on Zenoh. Decoding happens in :meth:`poll` (main thread).

    ``key``: a template containing ``{body}`` (default ``sc/<swarm>/mocap/{body}``);
    ``format``: "msgpack" (MocapPose) or "pose_stamped" (CDR geometry_msgs/PoseStamped).
    """

    FORMATS = ("msgpack", "pose_stamped")

    def __init__(self, session, keys, key: str | None = None, format: str = "msgpack",
                 logger: logging.Logger | None = None):
        from swarmcover.bus.session import Mailbox, Receiver
        if format not in self.FORMATS:
            raise ValueError(f"mocap.format: {format!r} not one of {', '.join(self.FORMATS)}")
        template = key or keys.mocap("{body}")
        if template.count("{body}") != 1:
            raise ValueError(f"mocap.key: {template!r} must contain '{{body}}' exactly once")
        self.format = format
        self.template = template
        head, tail = template.split("{body}")
        self._re = re.compile("^" + re.escape(head) + r"([^/]+)" + re.escape(tail) + "$")
        self.mailbox = Mailbox()
        self.receiver = Receiver(logger or log)
        self.invalid = 0
        self._logged_bad: set[str] = set()
        self.sub = session.declare_subscriber(template.replace("{body}", "*"),
                                              self.mailbox.callback)

    def _decode(self, key: str, payload: bytes, recv: float) -> MocapSample | None:
        m = self._re.match(key)
        if m is None:
            return None
        body = m.group(1)
        if self.format == "msgpack":
            from swarmcover.bus.messages import MocapPose
            msg = self.receiver.decode(key, payload, MocapPose)
            if msg is None:
                return None
            return MocapSample(msg.body or body, msg.t, (msg.x, msg.y, msg.z),
                               (msg.qx, msg.qy, msg.qz, msg.qw), recv)
        from .ros2 import CdrError, decode_pose_stamped
        try:
            p = decode_pose_stamped(payload)
        except CdrError as e:
            self.invalid += 1
            if key not in self._logged_bad:
                self._logged_bad.add(key)
                log.warning("dropping invalid PoseStamped on %s: %s (further ones counted)", key, e)
            return None
        return MocapSample(body, p.stamp, tuple(p.position), tuple(p.orientation), recv)

    def poll(self, timeout: float = 0.0) -> list[MocapSample]:
        items = self.mailbox.drain()
        if not items and timeout > 0:
            first = self.mailbox.get(timeout)
            items = ([first] if first is not None else []) + self.mailbox.drain()
        now = time.monotonic()
        out = []
        for key, payload, _kind in items:
            s = self._decode(key, payload, now)
            if s is not None:
                out.append(s)
        return out

    def close(self) -> None:
        try:
            self.sub.undeclare()
        except Exception:  # already closed with the session
            pass


# --------------------------------------------------------------------------- scripted

PATHS = ("static", "circle", "line", "waypoints")


def _pt(v: Any, what: str, n: int = 2) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or len(v) != n or not _finite(*v):
        raise ValueError(f"{what}: expected {n} finite numbers, got {v!r}")
    return tuple(float(c) for c in v)


def _num(d: dict, name: str, what: str, default: float | None = None, lo: float = -math.inf,
         hi: float = math.inf) -> float:
    v = d.get(name, default)
    if v is None:
        raise ValueError(f"{what}.{name}: missing")
    if isinstance(v, bool) or not _finite(v) or not lo <= v <= hi:
        raise ValueError(f"{what}.{name}: expected a number in [{lo}, {hi}], got {v!r}")
    return float(v)


@dataclass(frozen=True)
class Trajectory:
    """A world-frame trajectory: ``pose(t)`` (t in s since start) -> (x, y, theta)."""
    kind: str
    params: dict

    @classmethod
    def from_spec(cls, spec: dict, what: str) -> "Trajectory":
        allowed = {"static": {"pose"}, "circle": {"center", "radius", "speed", "phase"},
                   "line": {"start", "end", "speed"},
                   "waypoints": {"points", "speed", "loop"}}
        kind = spec.get("path", "static")
        if kind not in PATHS:
            raise ValueError(f"{what}.path: {kind!r} not one of {', '.join(PATHS)}")
        extra = set(spec) - allowed[kind] - {"path", "body", "gaps"}
        if extra:
            raise ValueError(f"{what}.{sorted(extra)[0]}: unknown field for path {kind!r}")
        p: dict[str, Any] = {}
        if kind == "static":
            p["pose"] = _pt(spec.get("pose", [0.0, 0.0, 0.0]), f"{what}.pose", 3)
        elif kind == "circle":
            p["center"] = _pt(spec.get("center", [0.0, 0.0]), f"{what}.center")
            p["radius"] = _num(spec, "radius", what, 1.0, 1e-6)
            p["speed"] = _num(spec, "speed", what, 0.2)
            p["phase"] = _num(spec, "phase", what, 0.0)
        elif kind == "line":
            p["start"] = _pt(spec.get("start"), f"{what}.start")
            p["end"] = _pt(spec.get("end"), f"{what}.end")
            p["speed"] = _num(spec, "speed", what, 0.2, 1e-6)
            if math.dist(p["start"], p["end"]) < 1e-9:
                raise ValueError(f"{what}.end: equal to start")
        else:
            pts = spec.get("points")
            if not isinstance(pts, list) or len(pts) < 2:
                raise ValueError(f"{what}.points: expected at least 2 [x, y] points, got {pts!r}")
            p["points"] = [_pt(q, f"{what}.points[{k}]") for k, q in enumerate(pts)]
            p["speed"] = _num(spec, "speed", what, 0.2, 1e-6)
            p["loop"] = bool(spec.get("loop", True))
        return cls(kind, p)

    def pose(self, t: float) -> tuple[float, float, float]:
        p = self.params
        if self.kind == "static":
            return p["pose"]
        if self.kind == "circle":
            r, v = p["radius"], p["speed"]
            a = p["phase"] + v * t / r
            cx, cy = p["center"]
            heading = a + (math.pi / 2 if v >= 0 else -math.pi / 2)
            return (cx + r * math.cos(a), cy + r * math.sin(a), wrap(heading))
        if self.kind == "line":
            (x0, y0), (x1, y1), v = p["start"], p["end"], p["speed"]
            L = math.hypot(x1 - x0, y1 - y0)
            s = (v * t) % (2 * L)
            fwd = s <= L
            f = s / L if fwd else 2 - s / L
            h = math.atan2(y1 - y0, x1 - x0) + (0.0 if fwd else math.pi)
            return (x0 + f * (x1 - x0), y0 + f * (y1 - y0), wrap(h))
        pts, v = p["points"], p["speed"]
        segs = list(zip(pts, pts[1:] + ([pts[0]] if p["loop"] else [])))
        lens = [math.dist(a, b) for a, b in segs]
        total = sum(lens)
        s = v * t
        s = s % total if p["loop"] else min(s, total)
        for (a, b), L in zip(segs, lens):
            if s <= L:
                f = 0.0 if L == 0 else s / L
                return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
                        wrap(math.atan2(b[1] - a[1], b[0] - a[0])))
            s -= L
        a, b = segs[-1]
        return (b[0], b[1], wrap(math.atan2(b[1] - a[1], b[0] - a[0])))


class ScriptedMocapSource:
    """Scripted rigid bodies seen by a simulated mocap system (for tests and demos).

    ``spec`` (the [hwbridge] ``mocap`` table): ``bodies = [{body, path, ...}]`` (world-frame
    trajectories, see :class:`Trajectory`; ``gaps = [[t0, t1], ...]`` silences the body
    between t0 and t1 s), ``rate_hz`` (100), ``noise_m`` and ``noise_rad`` (Gaussian sigma,
    0), ``dropout`` (probability, 0), ``latency_s`` (0), ``rename`` ({body: emitted name}),
    ``seed`` (0), ``height`` (m along the up axis, 0). Samples are expressed in the mocap
    frame given by ``up_axis`` and ``transform`` (world -> mocap by the inverse transform).
    ``clock``: monotonic seconds (injectable for pure tests).
    """

    KEYS = {"type", "bodies", "rate_hz", "noise_m", "noise_rad", "dropout", "latency_s",
            "rename", "seed", "height"}

    def __init__(self, spec: dict, up_axis: str = "z", transform: Transform2D | None = None,
                 clock: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.monotonic):
        what = "hwbridge.mocap"
        extra = set(spec) - self.KEYS
        if extra:
            raise ValueError(f"{what}.{sorted(extra)[0]}: unknown field for type 'scripted'")
        bodies = spec.get("bodies", [])
        if not isinstance(bodies, list) or not bodies:
            raise ValueError(f"{what}.bodies: expected a non-empty list of tables, got {bodies!r}")
        self.trajs: dict[str, Trajectory] = {}
        self.gaps: dict[str, list[tuple[float, float]]] = {}
        for k, b in enumerate(bodies):
            w = f"{what}.bodies[{k}]"
            if not isinstance(b, dict) or not isinstance(b.get("body"), str) or not b["body"]:
                raise ValueError(f"{w}.body: expected a non-empty string")
            self.trajs[b["body"]] = Trajectory.from_spec(b, w)
            gaps = b.get("gaps", [])
            self.gaps[b["body"]] = [_pt(g, f"{w}.gaps[{j}]") for j, g in enumerate(gaps)]
        self.rate = _num(spec, "rate_hz", what, 100.0, 1e-3, 1e4)
        self.noise_m = _num(spec, "noise_m", what, 0.0, 0.0)
        self.noise_rad = _num(spec, "noise_rad", what, 0.0, 0.0)
        self.dropout = _num(spec, "dropout", what, 0.0, 0.0, 1.0)
        self.latency = _num(spec, "latency_s", what, 0.0, 0.0)
        self.height = _num(spec, "height", what, 0.0)
        rename = spec.get("rename", {})
        if not isinstance(rename, dict) or not all(isinstance(v, str) for v in rename.values()):
            raise ValueError(f"{what}.rename: expected a table of body = \"new name\"")
        self.rename = dict(rename)
        self.rng = random.Random(int(spec.get("seed", 0)))
        self.up_axis = up_axis
        self.transform = transform or Transform2D()
        self.clock, self.wall = clock, wall
        self.t0 = clock()
        self.wall0 = wall()
        self.k = 0            # index of the next sample to generate
        self.pending: deque = deque()

    def truth(self, body: str, t: float) -> tuple[float, float, float]:
        """World pose of ``body`` at ``t`` s after start (before noise)."""
        return self.trajs[body].pose(t)

    def _silent(self, body: str, t: float) -> bool:
        return any(a <= t < b for a, b in self.gaps[body])

    def poll(self, timeout: float = 0.0) -> list[MocapSample]:
        now = self.clock()
        if timeout > 0 and not self.pending:
            nxt = self.t0 + self.k / self.rate + self.latency
            if nxt > now:
                time.sleep(min(timeout, nxt - now))
                now = self.clock()
        el = now - self.t0
        last = int(math.floor(el * self.rate))
        self.k = max(self.k, last - int(self.rate))     # never build more than 1 s of backlog
        while self.k <= last:
            ts = self.k / self.rate
            self.k += 1
            for body, traj in self.trajs.items():
                if self._silent(body, ts) or (self.dropout and self.rng.random() < self.dropout):
                    continue
                x, y, th = traj.pose(ts)
                if self.noise_m:
                    x += self.rng.gauss(0.0, self.noise_m)
                    y += self.rng.gauss(0.0, self.noise_m)
                if self.noise_rad:
                    th += self.rng.gauss(0.0, self.noise_rad)
                pos, q = world_to_mocap(x, y, th, self.up_axis, self.transform, self.height)
                self.pending.append((ts + self.latency,
                                     MocapSample(self.rename.get(body, body), self.wall0 + ts, pos, q)))
        out = []
        while self.pending and self.pending[0][0] <= el:
            due, s = self.pending.popleft()
            out.append(MocapSample(s.body, s.t, s.position, s.quat, now))
        return out

    def close(self) -> None:
        self.pending.clear()


# --------------------------------------------------------------------------- libmotioncapture

def samples_from_rigid_bodies(rigid_bodies: Any, t: float, recv: float) -> list[MocapSample]:
    """Map libmotioncapture's ``rigidBodies`` ({name: obj with .position, .rotation.x/y/z/w})
    to samples. Bodies with non-finite values (occluded markers report NaN) are skipped."""
    items = rigid_bodies.items() if hasattr(rigid_bodies, "items") else (
        (getattr(b, "name"), b) for b in rigid_bodies)
    out = []
    for name, obj in items:
        try:
            p = tuple(float(c) for c in obj.position)
            r = obj.rotation
            q = (float(r.x), float(r.y), float(r.z), float(r.w))
        except (AttributeError, TypeError, ValueError):
            continue
        if len(p) != 3 or not _finite(*p, *q) or sum(c * c for c in q) < 1e-12:
            continue
        out.append(MocapSample(str(name), t, p, q, recv))
    return out


def import_motioncapture():
    """Import PyPI ``motioncapture`` or raise ImportError saying how to install it."""
    try:
        import motioncapture  # type: ignore
    except Exception as e:  # ImportError, or a broken binary wheel (OSError)
        raise ImportError(f"{INSTALL_HINT} ({e.__class__.__name__}: {e})") from None
    return motioncapture


class LibMotionCaptureSource:
    """A libmotioncapture client. ``system``: "vicon", "optitrack", "qualisys", "vrpn",
    "nokov", ...; ``params``: its config (values are passed as strings, e.g. hostname).
    A daemon thread blocks in ``waitForNextFrame`` and queues samples (no Zenoh in it)."""

    def __init__(self, system: str, params: dict[str, Any], module=None):
        mc_mod = module or import_motioncapture()
        cfg = {str(k): str(v) for k, v in params.items()}
        try:
            self.mc = mc_mod.connect(system, cfg)
        except Exception as e:
            raise ConnectionError(f"motioncapture.connect({system!r}, {cfg}): {e}") from None
        self.q: queue.Queue = queue.Queue(maxsize=10_000)
        self._stop = threading.Event()
        self.error: str | None = None
        self.thread = threading.Thread(target=self._run, daemon=True, name="mocap")
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.mc.waitForNextFrame()
                now = time.monotonic()
                samples = samples_from_rigid_bodies(self.mc.rigidBodies, now, now)
            except Exception as e:  # the SDK lost the connection
                self.error = f"{e.__class__.__name__}: {e}"
                time.sleep(0.5)
                continue
            for s in samples:
                try:
                    self.q.put_nowait(s)
                except queue.Full:
                    break

    def poll(self, timeout: float = 0.0) -> list[MocapSample]:
        out = []
        try:
            if timeout > 0:
                out.append(self.q.get(timeout=timeout))
            while True:
                out.append(self.q.get_nowait())
        except queue.Empty:
            pass
        return out

    def close(self) -> None:
        self._stop.set()


def make_source(spec: dict, session=None, keys=None, up_axis: str = "z",
                transform: Transform2D | None = None) -> MocapSource:
    """Build the source the [hwbridge] ``mocap`` table asks for."""
    kind = spec.get("type", "zenoh")
    if kind == "zenoh":
        extra = set(spec) - {"type", "key", "format"}
        if extra:
            raise ValueError(f"hwbridge.mocap.{sorted(extra)[0]}: unknown field for type 'zenoh'")
        if session is None or keys is None:
            raise ValueError("hwbridge.mocap: type 'zenoh' needs a Zenoh session")
        return ZenohMocapSource(session, keys, spec.get("key"), spec.get("format", "msgpack"))
    if kind == "scripted":
        return ScriptedMocapSource(spec, up_axis, transform)
    if kind == "motioncapture":
        system = spec.get("system")
        if not isinstance(system, str) or not system:
            raise ValueError("hwbridge.mocap.system: type 'motioncapture' needs e.g. "
                             "system = \"optitrack\"")
        params = {k: v for k, v in spec.items() if k not in ("type", "system")}
        return LibMotionCaptureSource(system, params)
    raise ValueError(f"hwbridge.mocap.type: {kind!r} not one of {', '.join(MOCAP_TYPES)}")


# --------------------------------------------------------------------------- monitor

class RateMonitor:
    """Per-body sample rate and silence, plus missing/unknown body names (pure; time in).

    ``expected``: {body: robot id}. :meth:`check` returns warning strings, each kind
    repeated at most every ``repeat_s`` seconds per body.
    """

    def __init__(self, expected: dict[str, int], band: tuple[float, float] = (50.0, 200.0),
                 silence_s: float = 0.5, window_s: float = 1.0, repeat_s: float = 5.0):
        self.expected = dict(expected)
        self.band = band
        self.silence_s = silence_s
        self.window_s = window_s
        self.repeat_s = repeat_s
        self.times: dict[str, deque] = {}
        self.first: dict[str, float] = {}
        self.unknown: dict[str, int] = {}
        self._last_warn: dict[tuple[str, str], float] = {}

    def on_sample(self, body: str, now: float) -> None:
        if body not in self.expected:
            self.unknown[body] = self.unknown.get(body, 0) + 1
            return
        d = self.times.setdefault(body, deque())
        self.first.setdefault(body, now)
        d.append(now)
        while d and d[0] < now - self.window_s:
            d.popleft()

    def rate(self, body: str, now: float) -> float:
        """Samples per second over the last window (Hz); 0 if never seen or silent."""
        d = self.times.get(body)
        if not d:
            return 0.0
        n = sum(1 for t in d if t >= now - self.window_s)
        span = min(self.window_s, now - self.first[body])
        return n / span if span > 0 else 0.0

    def last_seen(self, body: str) -> float | None:
        d = self.times.get(body)
        return d[-1] if d else None

    def _warn(self, key: tuple[str, str], now: float) -> bool:
        last = self._last_warn.get(key)
        if last is not None and now - last < self.repeat_s:
            return False
        self._last_warn[key] = now
        return True

    def check(self, now: float, started: float) -> list[str]:
        """Warnings due at ``now``; ``started``: when the bridge began listening."""
        out = []
        seen = sorted(set(self.times) | set(self.unknown))
        for body, rid in self.expected.items():
            last = self.last_seen(body)
            if last is None:
                if now - started >= self.silence_s and self._warn((body, "missing"), now):
                    out.append(f"mocap body {body!r} (robot {rid}) not seen; bodies seen: "
                               f"{seen or 'none'}")
                continue
            if now - last > self.silence_s:
                if self._warn((body, "silent"), now):
                    out.append(f"mocap body {body!r} (robot {rid}) silent for {now - last:.2f} s")
                continue
            if now - self.first[body] >= self.window_s:
                r = self.rate(body, now)
                lo, hi = self.band
                if not lo <= r <= hi and self._warn((body, "rate"), now):
                    out.append(f"mocap body {body!r} (robot {rid}) rate {r:.1f} Hz outside "
                               f"[{lo:g}, {hi:g}] Hz")
        for body in sorted(self.unknown):
            if self._warn((body, "unknown"), now):
                out.append(f"mocap body {body!r} is not configured (ignored); configured: "
                           f"{sorted(self.expected)}")
        return out

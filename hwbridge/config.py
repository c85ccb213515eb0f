"""The [hwbridge] section of a run config (TOML): schema, defaults and validation.

Errors name the file, the section, the field and the value. Unknown keys in [hwbridge],
[[hwbridge.robots]], [hwbridge.transform] and [hwbridge.fake] are rejected; other
sections are only read (rv, [map].boundary, [robots].v_max/w_max), never checked here.

    [hwbridge]
    mocap = {type = "zenoh"}      # or {type = "scripted", bodies = [...]} or
                                  # {type = "motioncapture", system = "optitrack", hostname = "..."}
    up_axis = "z"                 # mocap vertical axis: "z" or "y"
    transform = {yaw = 0.0, tx = 0.0, ty = 0.0, scale = 1.0}   # mocap floor -> world
    kp = 3.0                      # twin position gain (1/s)
    k_theta = 3.0                 # twin heading gain (1/s)
    feedforward = false           # add the measured robot's velocity to the twin command
    teleport_dist = 0.2           # x rv: teleport the twin beyond this position error
    deadman_s = 0.3               # stop a live robot after this much command/mocap silence
    geofence = "map"              # "map" (the map boundary), [[x, y], ...] (world), or "none"
    geofence_margin = 0.0         # m kept from the fence edge
    rate_band_hz = [50, 200]      # warn when a body's mocap rate leaves this band
    silence_s = 0.5               # warn when a body is silent this long
    rate_hz = 50                  # twin sync loop (Hz)
    cmd_rate_hz = 20              # command output to robots, zeros included (Hz)
    cmd_ttl_s = 0.3               # LiveCmd.ttl: the robot's driver stops this long after
                                  # the last command it received (>= 2 / cmd_rate_hz)
    pose_rate_hz = 10             # robot/<id>/odom (Hz)
    k_omega = 1.5                 # unicycle mapping of a body-frame vy (spec 4.8)
    k_v = 1.0
    ros_domain = 0                # rmw_zenoh key prefix
    ros_bridge_namespace = "/"    # zenoh-bridge-ros2dds `namespace` setting

    [[hwbridge.robots]]           # one per live robot
    id = 100                      # robot id (the agent's --id; the coordinator spawns it live)
    body = "scarab1"              # mocap rigid-body name
    kind = "diffdrive"
    output = "zenoh"              # "zenoh" (LiveCmd on live/<id>/cmd) or "ros2" (CDR Twist)
    ros_mapping = "ros2dds"       # "ros2dds" or "rmw_zenoh" (output = "ros2")
    ros_namespace = "/scarab1"    # the robot's ROS namespace (default "/<body>")
    v_max = 0.3                   # m/s (default [robots].v_max)
    w_max = 2.0                   # rad/s (default [robots].w_max)
    source = 0                    # source index its twin spawns at
    fake = false                  # true: `swarmcover run` starts a stand-in fake-robot
    start = [x, y, theta]         # fake robot start pose (world); default: the source pose

    [hwbridge.fake]               # stand-in robots (swarmcover fake-robot)
    latency_s = 0.03              # command latency
    v_noise = 0.05                # relative actuation noise (sigma) on v and omega
    w_noise = 0.05
    slip = 0.05                   # mean fraction of commanded motion lost to wheel slip
    mocap_rate_hz = 100
    mocap_noise_m = 0.001
    mocap_noise_rad = 0.002
    seed = 0
    cmd_timeout_s = 0.5           # the stand-in driver's own timeout: for commands without a
                                  # ttl (ROS 2 Twist, old senders) and the cap on any ttl
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarmcover.bus.configcheck import Checker, ConfigError  # one style for every section

from .frames import UP_AXES, Transform2D
from .mocap import MOCAP_TYPES
from .ros2 import ROS_MAPPINGS, check_ros_name

OUTPUTS = ("zenoh", "ros2")
KINDS = ("diffdrive",)   # live robots are differential drive (Scarab-like)

TOP_KEYS = {"mocap", "up_axis", "transform", "kp", "k_theta", "feedforward", "teleport_dist",
            "deadman_s", "geofence", "geofence_margin", "rate_band_hz", "silence_s", "rate_hz",
            "cmd_rate_hz", "cmd_ttl_s", "pose_rate_hz", "k_omega", "k_v", "ros_domain",
            "ros_bridge_namespace", "robots", "fake"}
ROBOT_KEYS = {"id", "body", "kind", "output", "ros_mapping", "ros_namespace", "v_max",
              "w_max", "source", "fake", "start"}
FAKE_KEYS = {"latency_s", "v_noise", "w_noise", "slip", "mocap_rate_hz", "mocap_noise_m",
             "mocap_noise_rad", "seed", "cmd_timeout_s"}
TRANSFORM_KEYS = {"yaw", "tx", "ty", "scale"}


@dataclass(frozen=True)
class LiveRobot:
    id: int
    body: str
    kind: str = "diffdrive"
    output: str = "zenoh"
    ros_mapping: str = "ros2dds"
    ros_namespace: str = "/"
    v_max: float = 0.3
    w_max: float = 2.0
    source: int = 0
    fake: bool = False
    start: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class FakeParams:
    latency_s: float = 0.03
    v_noise: float = 0.05
    w_noise: float = 0.05
    slip: float = 0.05
    mocap_rate_hz: float = 100.0
    mocap_noise_m: float = 0.001
    mocap_noise_rad: float = 0.002
    seed: int = 0
    cmd_timeout_s: float = 0.5


@dataclass(frozen=True)
class BridgeConfig:
    path: str
    name: str
    rv: float
    robots: tuple[LiveRobot, ...]
    mocap: dict = field(default_factory=lambda: {"type": "zenoh"})
    up_axis: str = "z"
    transform: Transform2D = Transform2D()
    kp: float = 3.0
    k_theta: float = 3.0
    feedforward: bool = False
    teleport_dist: float = 0.2
    deadman_s: float = 0.3
    geofence: Any = "map"          # "map", None, or a tuple of (x, y)
    geofence_margin: float = 0.0
    rate_band_hz: tuple[float, float] = (50.0, 200.0)
    silence_s: float = 0.5
    rate_hz: float = 50.0
    cmd_rate_hz: float = 20.0
    cmd_ttl_s: float = 0.3
    pose_rate_hz: float = 10.0
    k_omega: float = 1.5
    k_v: float = 1.0
    ros_domain: int = 0
    ros_bridge_namespace: str = "/"
    fake: FakeParams = FakeParams()
    map_boundary: tuple[tuple[float, float], ...] | None = None
    map_sources: tuple[tuple[float, float, float], ...] = ()
    raw: dict = field(default_factory=dict, repr=False)

    @property
    def teleport_m(self) -> float:
        """Teleport threshold in metres (teleport_dist x rv)."""
        return self.teleport_dist * self.rv

    @property
    def live_ids(self) -> tuple[int, ...]:
        return tuple(r.id for r in self.robots)

    def robot(self, rid: int) -> LiveRobot:
        for r in self.robots:
            if r.id == rid:
                return r
        raise KeyError(f"robot {rid} is not a live robot in {self.path} [hwbridge.robots]")

    def fence_polygon(self) -> tuple[tuple[float, float], ...] | None:
        """The geofence in the world frame, or None; "map" needs map_boundary resolved."""
        if self.geofence is None:
            return None
        if self.geofence == "map":
            return self.map_boundary
        return self.geofence


class _Ctx(Checker):
    """The common checks (bus/configcheck.py), read from a dict with a default."""

    def __init__(self, path: str, section: str):
        super().__init__(path, section)
        self.path = path

    def get_num(self, d: dict, key: str, default: float, lo: float = -math.inf,
                hi: float = math.inf, strict_lo: bool = False) -> float:
        return self.num(key, d.get(key, default), lo, hi, lo_open=strict_lo)

    def get_int(self, d: dict, key: str, default: int | None, lo: int = 0,
                hi: int = 2**31) -> int:
        v = d.get(key, default)
        if v is None:
            raise self.err(key, v, "missing (required)")
        return self.int_(key, v, lo, hi)

    def get_choice(self, d: dict, key: str, default: str, choices) -> str:
        return self.choice(key, d.get(key, default), choices)

    def get_bool(self, d: dict, key: str, default: bool) -> bool:
        return self.bool_(key, d.get(key, default))


def _points(v: Any, ctx: _Ctx, key: str, n: int = 2) -> tuple:
    if not isinstance(v, list) or not all(
            isinstance(p, list) and len(p) == n and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in p)
            for p in v):
        label = "[x, y]" if n == 2 else "[x, y, theta]"
        raise ctx.err(key, v, f"expected a list of {label} points")
    return tuple(tuple(float(c) for c in p) for p in v)


def load(path: str | Path) -> BridgeConfig:
    """Read and validate a run config file's [hwbridge] section."""
    path = str(path)
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as e:
        raise ConfigError(path, "", "", None, f"cannot read: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "", "", None, f"not valid TOML: {e}") from None
    return from_dict(doc, path)


def loads(text: str, path: str = "<config>") -> BridgeConfig:
    """Parse TOML text (e.g. WorldInfo.config) and validate its [hwbridge] section."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "", "", None, f"not valid TOML: {e}") from None
    return from_dict(doc, path)


def from_dict(doc: dict, path: str = "<config>") -> BridgeConfig:
    top = _Ctx(path, "")
    rv = top.get_num(doc, "rv", 1.0, 0.0, 1e6, strict_lo=True)
    name = doc.get("name", Path(path).stem)
    hb = doc.get("hwbridge")
    if not isinstance(hb, dict):
        raise ConfigError(path, "", "", None,
                          "no [hwbridge] section (needed by the hardware bridge)")
    c = _Ctx(path, "hwbridge")
    c.unknown(hb, TOP_KEYS)

    robots_sec = doc.get("robots", {}) if isinstance(doc.get("robots"), dict) else {}
    rc = _Ctx(path, "robots")
    default_v = rc.get_num(robots_sec, "v_max", 0.3, 0.0, 100.0, strict_lo=True)
    default_w = rc.get_num(robots_sec, "w_max", 2.0, 0.0, 100.0, strict_lo=True)

    # map boundary and sources (read only; owned by world/)
    map_sec = doc.get("map", {}) if isinstance(doc.get("map"), dict) else {}
    boundary = None
    if isinstance(map_sec.get("boundary"), list):
        boundary = _points(map_sec["boundary"], _Ctx(path, "map"), "boundary")
    sources = ()
    if isinstance(map_sec.get("sources"), list):
        srcs = []
        for s in map_sec["sources"]:
            if isinstance(s, dict) and all(isinstance(s.get(k), (int, float)) for k in ("x", "y")):
                srcs.append((float(s["x"]), float(s["y"]), float(s.get("theta", 0.0))))
        sources = tuple(srcs)

    mocap = hb.get("mocap", {"type": "zenoh"})
    if not isinstance(mocap, dict):
        raise c.err("mocap", mocap, "expected a table, e.g. {type = \"zenoh\"}")
    mocap = dict(mocap)
    mocap.setdefault("type", "zenoh")
    if mocap["type"] not in MOCAP_TYPES:
        raise c.err("mocap.type", mocap["type"], f"not one of {', '.join(MOCAP_TYPES)}")

    tr = hb.get("transform", {})
    if not isinstance(tr, dict):
        raise c.err("transform", tr, "expected a table {yaw, tx, ty, scale}")
    tc = _Ctx(path, "hwbridge.transform")
    tc.unknown(tr, TRANSFORM_KEYS)
    transform = Transform2D(tc.get_num(tr, "yaw", 0.0), tc.get_num(tr, "tx", 0.0), tc.get_num(tr, "ty", 0.0),
                            tc.get_num(tr, "scale", 1.0, 0.0, 1e6, strict_lo=True))

    geof = hb.get("geofence", "map")
    if geof == "none" or geof is False:
        geofence = None
    elif geof == "map":
        geofence = "map"
    else:
        geofence = _points(geof, c, "geofence")
        if len(geofence) < 3:
            raise c.err("geofence", geof, "a polygon needs at least 3 points")

    band = hb.get("rate_band_hz", [50, 200])
    if (not isinstance(band, list) or len(band) != 2 or not all(
            isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) and b >= 0
            for b in band) or band[0] > band[1]):
        raise c.err("rate_band_hz", band, "expected [low, high] Hz with 0 <= low <= high")

    ns = hb.get("ros_bridge_namespace", "/")
    try:
        check_ros_name(ns, "ros_bridge_namespace")
    except ValueError as e:
        raise c.err("ros_bridge_namespace", ns, str(e)) from None

    fk = hb.get("fake", {})
    if not isinstance(fk, dict):
        raise c.err("fake", fk, "expected a table")
    fc = _Ctx(path, "hwbridge.fake")
    fc.unknown(fk, FAKE_KEYS)
    fake = FakeParams(
        latency_s=fc.get_num(fk, "latency_s", 0.03, 0.0, 10.0),
        v_noise=fc.get_num(fk, "v_noise", 0.05, 0.0, 1.0),
        w_noise=fc.get_num(fk, "w_noise", 0.05, 0.0, 1.0),
        slip=fc.get_num(fk, "slip", 0.05, 0.0, 0.9),
        mocap_rate_hz=fc.get_num(fk, "mocap_rate_hz", 100.0, 0.0, 1e4, strict_lo=True),
        mocap_noise_m=fc.get_num(fk, "mocap_noise_m", 0.001, 0.0, 1.0),
        mocap_noise_rad=fc.get_num(fk, "mocap_noise_rad", 0.002, 0.0, 1.0),
        seed=fc.get_int(fk, "seed", 0, 0, 2**31),
        cmd_timeout_s=fc.get_num(fk, "cmd_timeout_s", 0.5, 0.0, 10.0, strict_lo=True),
    )

    rl = hb.get("robots")
    if not isinstance(rl, list) or not rl:
        raise c.err("robots", rl, "expected at least one [[hwbridge.robots]] table")
    robots = []
    seen_ids, seen_bodies = set(), set()
    for k, r in enumerate(rl):
        ctx = _Ctx(path, f"hwbridge.robots[{k}]")
        if not isinstance(r, dict):
            raise ctx.err("", r, "expected a table")
        ctx.unknown(r, ROBOT_KEYS)
        rid = ctx.get_int(r, "id", None, 0, 2**31)
        body = r.get("body")
        if not isinstance(body, str) or not body or "/" in body or any(ch in body for ch in "*$?#"):
            raise ctx.err("body", body, "expected a non-empty mocap body name without / * $ ? #")
        if rid in seen_ids:
            raise ctx.err("id", rid, "duplicate live robot id")
        if body in seen_bodies:
            raise ctx.err("body", body, "duplicate mocap body name")
        seen_ids.add(rid)
        seen_bodies.add(body)
        kind = ctx.get_choice(r, "kind", "diffdrive", KINDS)
        output = ctx.get_choice(r, "output", "zenoh", OUTPUTS)
        mapping = ctx.get_choice(r, "ros_mapping", "ros2dds", ROS_MAPPINGS)
        rns = r.get("ros_namespace", "/" + body)
        try:
            check_ros_name(rns, "ros_namespace")
        except ValueError as e:
            raise ctx.err("ros_namespace", rns, str(e)) from None
        start = r.get("start")
        if start is not None:
            if not isinstance(start, list) or len(start) != 3:
                raise ctx.err("start", start, "expected [x, y, theta] (world frame; m, m, rad)")
            start = _points([start], ctx, "start", 3)[0]
        robots.append(LiveRobot(
            id=rid, body=body, kind=kind, output=output, ros_mapping=mapping, ros_namespace=rns,
            v_max=ctx.get_num(r, "v_max", default_v, 0.0, 100.0, strict_lo=True),
            w_max=ctx.get_num(r, "w_max", default_w, 0.0, 100.0, strict_lo=True),
            source=ctx.get_int(r, "source", 0, 0, 1000),
            fake=ctx.get_bool(r, "fake", False), start=start))

    cmd_rate = c.get_num(hb, "cmd_rate_hz", 20.0, 0.0, 1000.0, strict_lo=True)
    ttl = c.get_num(hb, "cmd_ttl_s", 0.3, 0.0, 10.0, strict_lo=True)
    if ttl < 2.0 / cmd_rate:
        raise c.err("cmd_ttl_s", hb.get("cmd_ttl_s", 0.3),
                    f"shorter than two command periods (2 / cmd_rate_hz = {2.0 / cmd_rate:g} s): "
                    f"a robot would stop between commands")
    return BridgeConfig(
        path=path, name=str(name), rv=rv, robots=tuple(robots), mocap=mocap,
        up_axis=c.get_choice(hb, "up_axis", "z", UP_AXES), transform=transform,
        kp=c.get_num(hb, "kp", 3.0, 0.0, 1e3, strict_lo=True),
        k_theta=c.get_num(hb, "k_theta", 3.0, 0.0, 1e3, strict_lo=True),
        feedforward=c.get_bool(hb, "feedforward", False),
        teleport_dist=c.get_num(hb, "teleport_dist", 0.2, 0.0, 1e3, strict_lo=True),
        deadman_s=c.get_num(hb, "deadman_s", 0.3, 0.0, 60.0, strict_lo=True),
        geofence=geofence,
        geofence_margin=c.get_num(hb, "geofence_margin", 0.0, 0.0, 1e3),
        rate_band_hz=(float(band[0]), float(band[1])),
        silence_s=c.get_num(hb, "silence_s", 0.5, 0.0, 60.0, strict_lo=True),
        rate_hz=c.get_num(hb, "rate_hz", 50.0, 0.0, 1000.0, strict_lo=True),
        cmd_rate_hz=cmd_rate, cmd_ttl_s=ttl,
        pose_rate_hz=c.get_num(hb, "pose_rate_hz", 10.0, 0.0, 1000.0, strict_lo=True),
        k_omega=c.get_num(hb, "k_omega", 1.5, 0.0, 100.0, strict_lo=True),
        k_v=c.get_num(hb, "k_v", 1.0, 0.0, 100.0, strict_lo=True),
        ros_domain=c.get_int(hb, "ros_domain", 0, 0, 232),
        ros_bridge_namespace=ns, fake=fake, map_boundary=boundary, map_sources=sources, raw=doc)

"""``swarmcover fake-robot --id N --body NAME``: a stand-in live robot (no hardware).

A separate process simulating a differential-drive body with command latency, actuation
noise and wheel slip. It executes the commands it receives -- LiveCmd on
``sc/<swarm>/live/<id>/cmd`` (output "zenoh") or a CDR geometry_msgs/Twist on the ROS 2
key of ``<ros_namespace>/cmd_vel`` (output "ros2", ros2dds or rmw_zenoh mapping) -- and
reports its true pose as a motion-capture system would: MocapPose on
``sc/<swarm>/mocap/<body>`` in the mocap frame (``up_axis`` + the inverse of the
[hwbridge] transform), with measurement noise, stamped with this host's monotonic clock
(s; MocapPose.t cannot hold Unix time, and the bridge on the same host can then measure
the transport latency).

It fails safe as a real driver must (hwbridge/driver.py): each command is executed only
until its expiry -- LiveCmd.ttl seconds after its receipt, capped at --cmd-timeout; a Twist
(no expiry field) or a LiveCmd without ttl gets --cmd-timeout -- and then the robot stops,
whoever failed (bridge, router, network, agent). Its own loop checks the expiry every
5 ms whether or not messages arrive; the Zenoh callback only queues. Each stop is logged
("command expired") and counted (expiry_stops in the FINAL line).

With a CONFIG (positional, or --run-config / -c) it takes its output, ROS namespace, start
pose, mocap frame, noise and timeout from the run config's [hwbridge] section (flags
override).
"""
from __future__ import annotations

import argparse
import logging
import math
import random
import sys
import time
from collections import deque
from dataclasses import dataclass

from swarmcover.bus.messages import LiveCmd, MocapPose
from swarmcover.bus.node import ready, run_node
from swarmcover.bus.session import Mailbox, Receiver, add_zenoh_args, publisher, query_world_info
from swarmcover.ground.geometry import flat_to_points

from .driver import CommandExpiry
from .frames import Transform2D, world_to_mocap, wrap
from .room import Room
from .ros2 import CdrError, cmd_vel_key, decode_twist

log = logging.getLogger("swarmcover.fake_robot")


@dataclass(frozen=True)
class DriveParams:
    """latency_s (s); v_noise, w_noise: relative sigma of actuation noise; slip: mean
    fraction of motion lost (and sigma of a lateral skid, relative to |v|)."""
    latency_s: float = 0.03
    v_noise: float = 0.05
    w_noise: float = 0.05
    slip: float = 0.05


class DiffDriveSim:
    """Unicycle body with latency, multiplicative actuation noise and slip (pure, time in).

    Noise and slip are drawn once per applied command (so they do not average out within
    a command), as uneven wheels and floors do. With a :class:`~hwbridge.room.Room` the
    disk body stops at (and slides along) the room's walls, as a physical robot does;
    motion is then integrated in steps of at most a quarter of the body radius.
    """

    def __init__(self, pose: tuple[float, float, float], params: DriveParams, seed: int = 0,
                 room: Room | None = None):
        self.x, self.y, self.theta = pose
        self.p = params
        self.rng = random.Random(seed)
        self.room = room if room is not None and len(room) else None
        self.pending: deque = deque()
        self.v = self.w = self.vlat = 0.0        # actual velocities being executed
        self.cmd = (0.0, 0.0)                    # last applied command
        self.wall_time = 0.0                     # s spent pressed against a wall

    def command(self, now: float, v: float, w: float) -> None:
        self.pending.append((now + self.p.latency_s, float(v), float(w)))

    def _apply(self, v: float, w: float) -> None:
        self.cmd = (v, w)
        slip = min(0.9, max(0.0, self.rng.gauss(self.p.slip, self.p.slip / 2))) if self.p.slip else 0.0
        self.v = v * (1.0 - slip) * (1.0 + self.rng.gauss(0.0, self.p.v_noise))
        self.w = w * (1.0 - slip) * (1.0 + self.rng.gauss(0.0, self.p.w_noise))
        self.vlat = abs(v) * self.rng.gauss(0.0, self.p.slip / 2) if self.p.slip else 0.0

    def step(self, now: float, dt: float) -> tuple[float, float, float]:
        while self.pending and self.pending[0][0] <= now:
            _, v, w = self.pending.popleft()
            self._apply(v, w)
        if dt <= 0:
            return self.x, self.y, self.theta
        n = 1
        if self.room is not None:
            n = max(1, math.ceil((abs(self.v) + abs(self.vlat)) * dt / (0.25 * self.room.radius)))
        for _ in range(n):
            self._move(dt / n)
        return self.x, self.y, self.theta

    def _move(self, dt: float) -> None:
        prev = (self.x, self.y)
        if abs(self.w) > 1e-9:   # exact arc
            r = self.v / self.w
            th1 = self.theta + self.w * dt
            self.x += r * (math.sin(th1) - math.sin(self.theta))
            self.y -= r * (math.cos(th1) - math.cos(self.theta))
            self.theta = th1
        else:
            self.x += self.v * math.cos(self.theta) * dt
            self.y += self.v * math.sin(self.theta) * dt
        self.x -= self.vlat * math.sin(self.theta) * dt
        self.y += self.vlat * math.cos(self.theta) * dt
        self.theta = wrap(self.theta)
        if self.room is not None:
            self.x, self.y, hit = self.room.collide(self.x, self.y, prev)
            if hit:
                self.wall_time += dt


def _triple(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected x,y,theta numbers, got {text!r}") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected x,y,theta (3 finite numbers), got {text!r}")
    return vals


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover fake-robot", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--id", type=int, required=True, help="robot id (as in [hwbridge.robots])")
    p.add_argument("--body", default=None, help="mocap rigid-body name (default: from CONFIG)")
    p.add_argument("run_config", nargs="?", metavar="CONFIG",
                   help="run config (TOML) to take the [hwbridge] settings of this robot from")
    p.add_argument("--run-config", "-c", dest="run_config_opt", metavar="CONFIG",
                   help="same as the positional CONFIG")
    add_zenoh_args(p)
    p.add_argument("--output", choices=("zenoh", "ros2"), help="command input (default zenoh)")
    p.add_argument("--ros-mapping", choices=("ros2dds", "rmw_zenoh"))
    p.add_argument("--ros-namespace", help="ROS namespace (default /<body>)")
    p.add_argument("--start", type=_triple, help="start pose x,y,theta (world frame; m, m, rad)")
    p.add_argument("--latency", type=float, help="command latency (s)")
    p.add_argument("--v-noise", type=float, help="relative actuation noise on v (sigma)")
    p.add_argument("--w-noise", type=float, help="relative actuation noise on omega (sigma)")
    p.add_argument("--slip", type=float, help="mean fraction of motion lost to slip")
    p.add_argument("--mocap-rate", type=float, help="mocap output rate (Hz, default 100)")
    p.add_argument("--mocap-noise-m", type=float, help="mocap position noise sigma (m)")
    p.add_argument("--mocap-noise-rad", type=float, help="mocap heading noise sigma (rad)")
    p.add_argument("--up-axis", choices=("z", "y"), help="mocap frame up axis (default z)")
    p.add_argument("--transform", type=lambda s: Transform2D(*(float(v) for v in s.split(","))),
                   metavar="YAW,TX,TY,SCALE", help="mocap floor -> world transform")
    p.add_argument("--cmd-timeout", type=float, metavar="S",
                   help="the driver's own command timeout (s; default [hwbridge.fake] "
                        "cmd_timeout_s, 0.5): for a Twist or a LiveCmd without ttl, and the "
                        "cap on any LiveCmd.ttl")
    p.add_argument("--seed", type=int)
    p.add_argument("--walls", choices=("map", "none"), default="map",
                   help="map (default): the body stops at the walls of the run's map (from "
                        "CONFIG, else the world's world/info), as a physical robot in that room "
                        "does; none: an open floor")
    p.add_argument("--duration", type=float, default=0.0, metavar="S", help="exit after S seconds")
    p.add_argument("--log-level", default="INFO")
    return p


def resolve(args) -> dict:
    """Merge flags over the run config's [hwbridge] settings for this robot."""
    from .config import FakeParams
    out = {"output": "zenoh", "ros_mapping": "ros2dds", "ros_namespace": None, "start": None,
           "up_axis": "z", "transform": Transform2D(), "fake": FakeParams(), "ros_domain": 0,
           "ros_bridge_namespace": "/", "body": args.body, "sources": ()}
    if args.run_config:
        from .config import load
        cfg = load(args.run_config)
        r = cfg.robot(args.id)
        out.update(output=r.output, ros_mapping=r.ros_mapping, ros_namespace=r.ros_namespace,
                   start=r.start, up_axis=cfg.up_axis, transform=cfg.transform, fake=cfg.fake,
                   ros_domain=cfg.ros_domain, ros_bridge_namespace=cfg.ros_bridge_namespace,
                   body=args.body or r.body, sources=cfg.map_sources, source=r.source)
    if out["body"] is None:
        raise SystemExit("swarmcover fake-robot: --body is required without a CONFIG")
    for flag, key in (("output", "output"), ("ros_mapping", "ros_mapping"),
                      ("ros_namespace", "ros_namespace"), ("start", "start"),
                      ("up_axis", "up_axis"), ("transform", "transform")):
        if getattr(args, flag) is not None:
            out[key] = getattr(args, flag)
    if out["ros_namespace"] is None:
        out["ros_namespace"] = "/" + out["body"]
    f = out["fake"]
    out["drive"] = DriveParams(
        latency_s=args.latency if args.latency is not None else f.latency_s,
        v_noise=args.v_noise if args.v_noise is not None else f.v_noise,
        w_noise=args.w_noise if args.w_noise is not None else f.w_noise,
        slip=args.slip if args.slip is not None else f.slip)
    out["mocap_rate"] = args.mocap_rate if args.mocap_rate is not None else f.mocap_rate_hz
    out["noise_m"] = args.mocap_noise_m if args.mocap_noise_m is not None else f.mocap_noise_m
    out["noise_rad"] = args.mocap_noise_rad if args.mocap_noise_rad is not None else f.mocap_noise_rad
    out["seed"] = args.seed if args.seed is not None else f.seed + args.id
    out["cmd_timeout"] = args.cmd_timeout if args.cmd_timeout is not None else f.cmd_timeout_s
    if not (math.isfinite(out["cmd_timeout"]) and 0 < out["cmd_timeout"] <= 10):
        raise ValueError(f"--cmd-timeout {out['cmd_timeout']!r}: expected seconds in (0, 10]")
    return out


def make_room(walls: str, run_config: str | None, session, keys) -> Room | None:
    """The walls the stand-in body stops at: the run config's map (boundary, obstacles and
    [robots].radius, built as the world builds it), else the world's WorldInfo; None for
    ``walls == "none"`` or when neither is available (logged)."""
    if walls == "none":
        return None
    if run_config:
        try:
            from swarmcover.world.maps import map_from_path
            cfg, wm = map_from_path(run_config)
            room = Room.from_polygons(wm.boundary, wm.obstacles, cfg.robots.radius)
            log.info("walls: %d segments of the map in %s, body radius %.3f m",
                     len(room), run_config, room.radius)
            return room
        except Exception as e:           # world's ConfigError/ValueError/OSError
            log.warning("walls: cannot build the map of %s (%s); asking the world", run_config, e)
    info = query_world_info(session, keys, 5.0, logger=log)
    if info is None or len(info.boundary) < 6:
        log.warning("walls: no map (no config map and no world/info answer): open floor, "
                    "the body can leave the map")
        return None
    room = Room.from_polygons(flat_to_points(info.boundary),
                              [flat_to_points(o) for o in info.obstacles], info.robot_radius or 0.06)
    log.info("walls: %d segments from world/info, body radius %.3f m", len(room), room.radius)
    return room


def _resolve(args) -> None:
    """The stand-in's parameters, checked before any connection (exit 2 naming the field)."""
    args.run_config = args.run_config or args.run_config_opt
    try:
        args.opts = resolve(args)
    except KeyError as e:
        raise ValueError(f"fake-robot: {e}") from None


def _serve(args, session, keys, stop) -> int:
    o = args.opts
    subs, pubs = [], []
    try:
        start = o["start"]
        if start is None and o["sources"]:
            start = o["sources"][min(o.get("source", 0), len(o["sources"]) - 1)]
        if start is None:
            info = query_world_info(session, keys, 5.0, logger=log)
            src = o.get("source", 0)
            if info is not None and len(info.sources) >= 3 * (src + 1):
                start = tuple(info.sources[3 * src:3 * src + 3])
        start = tuple(start) if start is not None else (0.0, 0.0, 0.0)
        room = make_room(args.walls, args.run_config, session, keys)
        sim = DiffDriveSim(start, o["drive"], o["seed"], room)
        expiry = CommandExpiry(o["cmd_timeout"])
        rng = random.Random(o["seed"] + 7919)
        mb = Mailbox()
        rec = Receiver(log)
        if o["output"] == "zenoh":
            cmd_key = keys.live_cmd(args.id)
        else:
            cmd_key = cmd_vel_key(o["ros_mapping"], o["ros_namespace"], o["ros_domain"],
                                  o["ros_bridge_namespace"])
        subs.append(session.declare_subscriber(cmd_key, mb.callback))
        mocap_pub = publisher(session, keys.mocap(o["body"]), block=False, express=True)
        pubs.append(mocap_pub)
        ready(f"fake-robot {args.id} body={o['body']} commands on {cmd_key}")
        log.info("robot %d (%s) at (%.2f, %.2f, %.2f), mocap up=%s, %s",
                 args.id, o["body"], *start, o["up_axis"], o["transform"])
        dt = 0.005
        t0 = last = time.monotonic()
        next_mocap = t0
        n_cmd = bad = 0
        while not stop.is_set():
            now = time.monotonic()
            if args.duration and now - t0 >= args.duration:
                break
            for key, payload, _ in mb.drain():
                if o["output"] == "zenoh":
                    msg = rec.decode(key, payload, LiveCmd)
                    if msg is None or msg.robot != args.id:
                        continue
                    v, w, ttl = msg.v, msg.omega, msg.ttl
                else:
                    try:
                        tw = decode_twist(payload)
                    except CdrError as e:
                        bad += 1
                        if bad == 1:
                            log.warning("dropping invalid Twist on %s: %s", key, e)
                        continue
                    v, w, ttl = tw.lx, tw.az, 0.0
                sim.command(now, v, w)
                expiry.on_command(now, v, w, ttl)
                n_cmd += 1
            if expiry.expired(now):           # whoever failed: stop at the robot
                sim.command(now, 0.0, 0.0)
                log.warning("robot %d: command expired (%.2f s after the last command "
                            "received): stopping", args.id, expiry.last_ttl)
            x, y, th = sim.step(now, now - last)
            last = now
            if now >= next_mocap:
                next_mocap += 1.0 / o["mocap_rate"]
                if next_mocap < now:
                    next_mocap = now + 1.0 / o["mocap_rate"]
                mx, my = x + rng.gauss(0, o["noise_m"]), y + rng.gauss(0, o["noise_m"])
                mth = th + rng.gauss(0, o["noise_rad"])
                pos, q = world_to_mocap(mx, my, mth, o["up_axis"], o["transform"])
                mocap_pub.put(MocapPose(body=o["body"], t=time.monotonic(), x=pos[0], y=pos[1],
                                        z=pos[2], qx=q[0], qy=q[1], qz=q[2], qw=q[3]).encode())
            stop.wait(max(0.0, dt - (time.monotonic() - now)))
        log.info("robot %d: %d commands, %d expiry stops, final pose (%.3f, %.3f, %.3f), "
                 "%.1f s against a wall", args.id, n_cmd, expiry.stops, sim.x, sim.y,
                 sim.theta, sim.wall_time)
        print(f"FINAL fake-robot {args.id} x={sim.x:.4f} y={sim.y:.4f} theta={sim.theta:.4f} "
              f"commands={n_cmd} expiry_stops={expiry.stops} wall_s={sim.wall_time:.1f}",
              flush=True)
    finally:
        for s in subs:
            s.undeclare()
        for pb in pubs:
            pb.undeclare()
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover fake-robot", __doc__, build_parser(), _serve, argv=argv,
                    logger="swarmcover", before_session=_resolve)

if __name__ == "__main__":
    sys.exit(main())

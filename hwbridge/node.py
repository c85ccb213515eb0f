"""``swarmcover hwbridge CONFIG``: mix live robots into a simulated swarm.

For each live robot of the run config's [hwbridge] section (see hwbridge/config.py):

  * reads its mocap pose (zenoh, scripted or libmotioncapture source), converts it to the
    world frame (up axis + 2-D transform), publishes it as the robot's body pose
    (Pose source "mocap" on robot/<id>/odom), and warns on missing, unknown, silent or
    off-rate bodies;
  * drives its twin in the world toward that pose (TwinCmd on robot/<id>/twin_cmd,
    proportional control, teleport beyond teleport_dist x rv), learning the twin's pose
    from world/truth. The world spawns the twin when it receives Spawn(live=true): the
    coordinator sends it for the ids listed in [hwbridge.robots]; ``--spawn`` makes the
    bridge send it itself (standalone use, no coordinator);
  * forwards the robot's agent commands (CmdVel on robot/<id>/cmd_vel) to the robot as
    LiveCmd or a ROS 2 Twist, through the safety gate (clamp, deadman, geofence; zeros are
    sent actively at cmd_rate_hz); commands for robots that are not live are never sent.
    Each LiveCmd carries ttl = cmd_ttl_s: the robot's driver stops by itself when it
    passes, should this bridge or the network fail (hwbridge/driver.py).

At exit it sends zeros to every robot and prints ``SUMMARY {json}`` (tracking error,
lag, formation discrepancy); ``--report FILE`` writes the same JSON.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections import deque

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, Pose, Spawn, Truth, TwinCmd
from swarmcover.bus.node import ready, run_node
from swarmcover.bus.session import Mailbox, Receiver, add_zenoh_args, publisher, query_world_info
from swarmcover.ground.geometry import flat_to_points

from . import config as hwconfig
from .frames import mocap_to_world
from .metrics import TrackLog, formation_discrepancy, summary
from .mocap import RateMonitor, make_source
from .output import make_output, to_unicycle
from .safety import Gates, Limits, edge_distance, point_in_polygon
from .twin import TwinGains, VelocityEstimator, twin_command

log = logging.getLogger("swarmcover.hwbridge")

TELEPORT_COOLDOWN_S = 0.5     # no second teleport of one twin within this time
TWIN_STALE_S = 1.0            # a twin pose older than this is not used
FORMATION_EVERY_S = 0.5


class Bridge:
    """The bridge's state and its loop steps. All times are ``time.monotonic()`` seconds."""

    def __init__(self, cfg: hwconfig.BridgeConfig, session, keys: Keys, fence, spawn: bool = False):
        self.cfg, self.session, self.keys = cfg, session, keys
        self.by_body = {r.body: r for r in cfg.robots}
        self.robots = {r.id: r for r in cfg.robots}
        self.gains = TwinGains(kp=cfg.kp, k_theta=cfg.k_theta, teleport_dist=cfg.teleport_m,
                               feedforward=cfg.feedforward)
        self.gates = Gates({r.id: Limits(r.v_max, r.w_max, cfg.deadman_s, fence, cfg.geofence_margin)
                            for r in cfg.robots})
        self.monitor = RateMonitor({r.body: r.id for r in cfg.robots}, cfg.rate_band_hz,
                                   cfg.silence_s)
        self.track = TrackLog()
        self.formation: list[float] = []
        self.transport: deque = deque(maxlen=20_000)
        self.receiver = Receiver(log)
        self.spawn = spawn

        self.meas: dict[int, tuple[tuple, float]] = {}       # rid -> (world pose, recv)
        self.vel = {r.id: VelocityEstimator() for r in cfg.robots}
        self.twin: dict[int, tuple[tuple, float]] = {}       # rid -> (pose, recv)
        self.sim: dict[int, tuple] = {}                      # every body in world/truth
        self.sim_t, self.sim_recv = 0.0, None
        self.last_teleport: dict[int, float] = {}
        self.last_reason: dict[int, str] = {}
        self.bad_pose = 0
        self.not_twin_warned: set[int] = set()
        self.spawn_sent: dict[int, float] = {}
        self.n_mocap = 0
        self.n_cmd = 0
        self.n_twin_cmd = 0

        self.source = make_source(cfg.mocap, session, keys, cfg.up_axis, cfg.transform)
        self.outputs = {r.id: make_output(session, keys, r, cfg) for r in cfg.robots}
        self.twin_pubs = {r.id: publisher(session, keys.twin_cmd(r.id), block=True)
                          for r in cfg.robots}
        self.odom_pubs = {r.id: publisher(session, keys.odom(r.id), block=False)
                          for r in cfg.robots}
        self.spawn_pub = publisher(session, keys.spawn, block=True) if spawn else None
        self.mb_truth = Mailbox()
        self.mb_cmd = Mailbox()
        self.subs = [session.declare_subscriber(keys.truth, self.mb_truth.callback)]
        self.subs += [session.declare_subscriber(keys.cmd_vel(r.id), self.mb_cmd.callback)
                      for r in cfg.robots]
        self.token = session.liveliness().declare_token(keys.alive("hwbridge", "main"))

    # ------------------------------------------------------------------ inputs
    def on_mocap(self, samples, now: float) -> None:
        for s in samples:
            self.monitor.on_sample(s.body, s.recv or now)
            r = self.by_body.get(s.body)
            if r is None:
                continue
            try:
                pose = mocap_to_world(s.position, s.quat, self.cfg.up_axis, self.cfg.transform)
            except ValueError as e:
                self.bad_pose += 1
                if self.bad_pose == 1:
                    log.warning("mocap body %r: unusable pose (%s); further ones counted", s.body, e)
                continue
            t = s.recv or now
            if 0.0 <= t - s.t < 10.0:        # same-host monotonic stamps: transport latency
                self.transport.append(t - s.t)
            self.n_mocap += 1
            self.meas[r.id] = (pose, t)
            self.vel[r.id].update(t, pose)
            self.gates.on_pose(t, r.id, pose[0], pose[1])
            self.track.on_mocap(r.id, t, pose)

    def on_truth(self, now: float) -> bool:
        latest = None
        for key, payload, _ in self.mb_truth.drain():
            msg = self.receiver.decode(key, payload, Truth)
            if msg is not None and (latest is None or msg.tick >= latest.tick):
                latest = msg
        if latest is None:
            return False
        self.sim_t, self.sim_recv = latest.t, now
        self.sim = {rid: (x, y, th) for rid, x, y, th in
                    zip(latest.ids, latest.x, latest.y, latest.theta)}
        for rid, live in zip(latest.ids, latest.live):
            if rid not in self.robots:
                continue
            if not live and rid not in self.not_twin_warned:
                self.not_twin_warned.add(rid)
                log.warning("robot %d is live in %s but its world body is not a twin "
                            "(Truth.live=false): it must be spawned with Spawn(live=true)",
                            rid, self.cfg.path)
            self.twin[rid] = (self.sim[rid], now)
            self.track.on_twin(rid, now, self.sim[rid])
        return True

    def on_commands(self, now: float) -> None:
        for key, payload, _ in self.mb_cmd.drain():
            msg = self.receiver.decode(key, payload, CmdVel)
            if msg is None:
                continue
            rid = self.keys.robot_id(key)
            if rid != msg.robot:
                self.receiver.invalid[key] += 1
                if self.receiver.invalid[key] == 1:
                    log.warning("dropping CmdVel on %s: robot field %d differs from the key",
                                key, msg.robot)
                continue
            v, w = to_unicycle(msg.vx, msg.vy, msg.wz, self.cfg.k_omega, self.cfg.k_v)
            if self.gates.on_command(now, rid, v, w):
                self.n_cmd += 1
                self.send_command(rid, now)        # forward at once, then at cmd_rate_hz

    # ------------------------------------------------------------------ outputs
    def sim_time(self, now: float) -> float:
        return self.sim_t + (now - self.sim_recv if self.sim_recv is not None else 0.0)

    def send_command(self, rid: int, now: float) -> None:
        d = self.gates.decide(now, rid)
        if d is None:
            return
        if d.reason != self.last_reason.get(rid):
            g = self.gates.gates[rid]
            if d.reason == "geofence" and g.pose is not None:
                fence = g.limits.geofence or ()
                log.warning("robot %d: stopping (geofence): its mocap centre (%.3f, %.3f) "
                            "(world frame) is %s the fence, %.3f m from its edge (margin "
                            "%.3f m); it stays stopped until it is back inside", rid, *g.pose,
                            "inside" if point_in_polygon(*g.pose, fence) else "OUTSIDE",
                            edge_distance(*g.pose, fence), g.limits.margin)
            elif d.stopped:
                log.info("robot %d: stopping (%s)", rid, d.reason.replace("_", " "))
            elif self.last_reason.get(rid) not in (None, "ok", "clamped"):
                log.info("robot %d: commands flowing again", rid)
            self.last_reason[rid] = d.reason
        self.outputs[rid].send(d.v, d.omega, self.sim_time(now))

    def next_deadman(self) -> float:
        """The earliest time a moving robot's deadman expires (inf if none is moving), so
        the stop goes out at that moment rather than at the next output tick."""
        t = math.inf
        for rid, g in self.gates.gates.items():
            if self.last_reason.get(rid) in ("ok", "clamped") and g.cmd_time is not None \
                    and g.pose_time is not None:
                t = min(t, min(g.cmd_time, g.pose_time) + g.limits.deadman_s + 1e-3)
        return t

    def sync_twins(self, now: float) -> None:
        for rid in self.robots:
            m, tw = self.meas.get(rid), self.twin.get(rid)
            if m is None or tw is None or now - tw[1] > TWIN_STALE_S:
                continue
            if now - m[1] > self.cfg.deadman_s:
                cmd = twin_command(tw[0], tw[0], self.gains)          # hold still
            else:
                cmd = twin_command(m[0], tw[0], self.gains, self.vel[rid].vel)
            if cmd.teleport:
                last = self.last_teleport.get(rid)
                if last is not None and now - last < TELEPORT_COOLDOWN_S:
                    cmd = twin_command(tw[0], tw[0], self.gains)
                else:
                    self.last_teleport[rid] = now
                    self.track.on_teleport(rid, now)
                    log.info("robot %d: teleporting its twin to the mocap pose (%.2f, %.2f)",
                             rid, cmd.x, cmd.y)
            msg = TwinCmd(robot=rid, t=max(0.0, self.sim_time(now)), vx=cmd.vx, vy=cmd.vy,
                          wz=cmd.wz, teleport=cmd.teleport, x=cmd.x, y=cmd.y, theta=cmd.theta)
            self.twin_pubs[rid].put(msg.encode())
            self.n_twin_cmd += 1

    def publish_odom(self, now: float) -> None:
        for rid, (pose, t) in self.meas.items():
            if now - t > self.cfg.deadman_s:
                continue
            self.odom_pubs[rid].put(Pose(robot=rid, t=max(0.0, self.sim_time(now)), x=pose[0],
                                         y=pose[1], theta=pose[2], source="mocap").encode())

    def sample_formation(self) -> None:
        real = dict(self.sim)
        for rid, (pose, _) in self.meas.items():
            if rid in real:
                real[rid] = pose
        self.formation += formation_discrepancy(real, self.sim, self.robots, self.cfg.rv)

    def maybe_spawn(self, now: float, started: float) -> None:
        if self.spawn_pub is None or now - started < 1.0:
            return
        for rid, r in self.robots.items():
            if rid in self.sim:
                continue
            last = self.spawn_sent.get(rid)
            if last is None or now - last > 3.0:
                self.spawn_sent[rid] = now
                log.info("spawning the twin of live robot %d at source %d", rid, r.source)
                self.spawn_pub.put(Spawn(robot=rid, source=r.source, kind=r.kind, live=True).encode())

    def stop_all(self) -> None:
        """Zeros to every live robot (a few times: the last word must be a stop)."""
        for _ in range(3):
            for rid, out in self.outputs.items():
                try:
                    out.send(0.0, 0.0, self.sim_time(time.monotonic()))
                except Exception as e:
                    log.warning("robot %d: could not send the final stop: %s", rid, e)
            time.sleep(0.02)

    def report(self) -> dict:
        gates = {str(rid): dict(g.counts) for rid, g in self.gates.gates.items()}
        return {"robots": self.track.report(), "formation_discrepancy_rad": summary(self.formation),
                "gate_decisions": gates, "mocap_samples": self.n_mocap, "commands": self.n_cmd,
                "twin_cmds": self.n_twin_cmd, "refused_commands": self.gates.refused,
                "mocap_transport_latency_s": summary(list(self.transport)),
                "invalid_messages": self.receiver.invalid_total + _source_invalid(self.source),
                "unknown_bodies": self.monitor.unknown}

    def close(self) -> None:
        self.source.close()
        for s in self.subs:
            s.undeclare()
        for p in list(self.twin_pubs.values()) + list(self.odom_pubs.values()):
            p.undeclare()
        for out in self.outputs.values():
            out.close()
        if self.spawn_pub is not None:
            self.spawn_pub.undeclare()
        self.token.undeclare()

    # ------------------------------------------------------------------ loop
    def run(self, stop, duration: float = 0.0) -> None:
        cfg = self.cfg
        started = time.monotonic()
        log.info("live robots: %s", ", ".join(f"{r.id}<-{r.body!r} ({r.output})" for r in cfg.robots))
        nxt = {"twin": started, "cmd": started, "odom": started, "check": started + cfg.silence_s,
               "formation": started}
        period = {"twin": 1.0 / cfg.rate_hz, "cmd": 1.0 / cfg.cmd_rate_hz,
                  "odom": 1.0 / cfg.pose_rate_hz, "check": 0.5, "formation": FORMATION_EVERY_S}
        while not stop.is_set():
            now = time.monotonic()
            if duration and now - started >= duration:
                break
            deadman = self.next_deadman()
            wait = max(0.0, min(min(nxt.values()) - now, deadman - now, 0.02))
            self.on_mocap(self.source.poll(timeout=wait), time.monotonic())
            now = time.monotonic()
            self.on_commands(now)
            if now >= deadman:
                for rid in self.robots:
                    g = self.gates.gates[rid]
                    if self.last_reason.get(rid) in ("ok", "clamped") and g.decide(now, count=False).stopped:
                        self.send_command(rid, now)
            new_truth = self.on_truth(now)
            if new_truth or now >= nxt["twin"]:
                self.sync_twins(now)
                nxt["twin"] = now + period["twin"]
            if now >= nxt["cmd"]:
                for rid in self.robots:
                    self.send_command(rid, now)
                nxt["cmd"] += period["cmd"]
                if nxt["cmd"] < now:
                    nxt["cmd"] = now + period["cmd"]
            if now >= nxt["odom"]:
                self.publish_odom(now)
                nxt["odom"] = now + period["odom"]
            if now >= nxt["formation"]:
                self.sample_formation()
                nxt["formation"] = now + period["formation"]
            if now >= nxt["check"]:
                for w in self.monitor.check(now, started):
                    log.warning("%s", w)
                self.maybe_spawn(now, started)
                nxt["check"] = now + period["check"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swarmcover hwbridge", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_config", metavar="CONFIG", help="run config (TOML) with a [hwbridge] section")
    add_zenoh_args(p)
    p.add_argument("--spawn", action="store_true",
                   help="send Spawn(live=true) for live robots missing from world/truth "
                        "(standalone use; in `swarmcover run` the coordinator spawns them)")
    p.add_argument("--world-timeout", type=float, default=10.0, metavar="S",
                   help="seconds to wait for world/info when geofence = \"map\" needs it")
    p.add_argument("--duration", type=float, default=0.0, metavar="S",
                   help="exit after S seconds (default: run until SIGINT/SIGTERM)")
    p.add_argument("--report", metavar="FILE", help="write the tracking report (JSON) at exit")
    p.add_argument("--log-level", default="INFO")
    return p


def _load(args) -> None:
    """The [hwbridge] section, checked before any connection (exit 2 naming the field)."""
    args.bridge_cfg = hwconfig.load(args.run_config)  # its ConfigError is a ValueError


def _serve(args, session, keys, stop) -> int:
    cfg = args.bridge_cfg
    bridge = None
    try:
        fence = None
        if cfg.geofence == "map" and cfg.map_boundary is None:
            info = query_world_info(session, keys, args.world_timeout, logger=log)
            if info is None or len(info.boundary) < 6:
                log.error("%s: [hwbridge] geofence = \"map\" but the config has no "
                          "[map].boundary and world/info did not answer within %.0f s; "
                          "give a polygon or geofence = \"none\"", cfg.path, args.world_timeout)
                return 2
            fence = flat_to_points(info.boundary)
        else:
            fence = cfg.fence_polygon()
        _check_fence_margin(cfg)
        try:
            bridge = Bridge(cfg, session, keys, fence, spawn=args.spawn)
        except (ValueError, ImportError, ConnectionError) as e:
            log.error("%s", e)
            return 2
        ready(f"hwbridge {len(cfg.robots)} live robot(s): "
              f"{','.join(str(r.id) for r in cfg.robots)}")
        bridge.run(stop, args.duration)
    finally:
        if bridge is not None:
            bridge.stop_all()
            rep = bridge.report()
            try:
                bridge.close()
            except Exception as e:
                log.debug("close: %s", e)
            text = json.dumps(_clean(rep), allow_nan=False)
            print(f"SUMMARY {text}", flush=True)
            if args.report:
                with open(args.report, "w") as f:
                    f.write(text + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_node("swarmcover hwbridge", __doc__, build_parser(), _serve, argv=argv,
                    logger="swarmcover", before_session=_load)


def _check_fence_margin(cfg: hwconfig.BridgeConfig) -> None:
    """Warn when the geofence would stop robots that only touch a wall: the fence tests the
    body's centre, which stays one body radius inside a wall the robot touches."""
    if cfg.geofence != "map" or cfg.geofence_margin <= 0:
        return
    robots = cfg.raw.get("robots") if isinstance(cfg.raw.get("robots"), dict) else {}
    radius = robots.get("radius", 0.06)
    if isinstance(radius, (int, float)) and cfg.geofence_margin >= radius:
        log.warning("%s: [hwbridge] geofence_margin = %g m >= the body radius %g m: a robot "
                    "touching a wall (its centre %g m from it) is stopped there, and agents "
                    "touch walls to find them", cfg.path, cfg.geofence_margin, radius, radius)


def _source_invalid(source) -> int:
    rec = getattr(source, "receiver", None)
    return getattr(source, "invalid", 0) + (rec.invalid_total if rec is not None else 0)


def _clean(o):
    """JSON-safe copy: non-finite floats become null."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark: how well live robots' twins track them (thesis section 3.4.3, spec section 8).

Two parts, each with the twin's velocity feed-forward off (the thesis's pure P sync) and on:

  * ``loop``: in-process closed loop of the pure cores -- a differential-drive body with
    30 ms command latency, 5 % actuation noise and slip (hwbridge.fake_robot.DiffDriveSim),
    a 100 Hz mocap with 1 mm noise, the twin P-controller (hwbridge.twin) and a world that
    integrates the twin command every 50 ms one tick late. Deterministic; fast.
  * ``procs``: real processes over a real router -- ``swarmcover world`` (realtime),
    ``swarmcover hwbridge --spawn`` and two ``swarmcover fake-robot`` (one on LiveCmd, one on
    a ROS 2 CDR Twist), mocap in a Y-up rotated frame; this process plays the two agents,
    driving each robot to random waypoints from its mocap odometry. The numbers are the
    bridge's own SUMMARY: twin tracking error (mean, p95), mocap-to-twin lag, formation
    discrepancy (bearing difference, real vs simulated formation), mocap transport
    latency, and the bridge's CPU share.

    python bench/hwbridge.py [--seconds 20] [--skip-procs]      (the venv's python, from the repo root)

Progress goes to stderr; the last line on stdout is one JSON object.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import cpu_seconds, eprint, free_port, wait_line  # noqa: E402
from swarmcover.hwbridge.fake_robot import DiffDriveSim, DriveParams  # noqa: E402
from swarmcover.ground.angles import wrap  # noqa: E402
from swarmcover.hwbridge.metrics import TrackLog  # noqa: E402
from swarmcover.hwbridge.twin import TwinGains, VelocityEstimator, integrate, twin_command  # noqa: E402


def waypoint_command(pose, goal, v_max=0.25):
    """A metric stand-in for an agent: unicycle steering to a waypoint (m/s, rad/s)."""
    dx, dy = goal[0] - pose[0], goal[1] - pose[1]
    err = wrap(math.atan2(dy, dx) - pose[2])
    w = max(-1.5, min(1.5, 2.5 * err))
    v = v_max * max(0.0, math.cos(err)) ** 2
    return v, w


def random_goal(rng):
    return (rng.uniform(0.5, 2.5), rng.uniform(0.5, 1.5))


# --------------------------------------------------------------------------- in-process loop

def loop_run(feedforward: bool, seconds: float, seed: int = 0) -> dict:
    rng = random.Random(seed)
    body = DiffDriveSim((0.5, 1.0, 0.0), DriveParams(0.03, 0.05, 0.05, 0.05), seed)
    gains = TwinGains(kp=3.0, k_theta=3.0, teleport_dist=0.2, feedforward=feedforward)
    twin = (0.4, 1.0, 0.0)
    est = VelocityEstimator()
    log = TrackLog(horizon_s=seconds + 1, settle_s=1.0)
    goal = random_goal(rng)
    h, tick, mocap_dt = 0.001, 0.05, 0.01
    meas = None
    pending = None
    t = 0.0
    next_mocap = next_tick = next_cmd = 0.0
    while t < seconds:
        if t >= next_cmd:                       # the agent, 20 Hz
            if meas is not None:
                if math.dist(meas[:2], goal) < 0.15:
                    goal = random_goal(rng)
                body.command(t, *waypoint_command(meas, goal))
            next_cmd += 0.05
        pose = body.step(t, h)
        if t >= next_mocap:                     # the mocap, 100 Hz
            meas = (pose[0] + rng.gauss(0, 0.001), pose[1] + rng.gauss(0, 0.001),
                    wrap(pose[2] + rng.gauss(0, 0.002)))
            est.update(t, meas)
            log.on_mocap(1, t, meas)
            next_mocap += mocap_dt
        if t >= next_tick:                      # the world tick: applies last tick's command
            if pending is not None:
                twin = integrate(twin, pending, tick)
            log.on_twin(1, t, twin)
            pending = twin_command(meas, twin, gains, est.vel)
            if pending.teleport:
                log.on_teleport(1, t)
            next_tick += tick
        t += h
    rep = log.report()["1"]
    return {"feedforward": feedforward, "position_error_m": rep["position_error_m"],
            "heading_error_rad": rep["heading_error_rad"], "lag_s": rep["lag_s"],
            "teleports": rep["teleports"]}


# --------------------------------------------------------------------------- processes

CONFIG = """
name = "bench_hwbridge"
rv = 1.0
[map]
boundary = [[0, 0], [3, 0], [3, 2], [0, 2]]
sources = [{{x = 0.4, y = 1.0, theta = 0.0}}]
[robots]
kind = "holonomic"
[world]
dt = 0.05
mode = "realtime"
rtf = 1.0
[[world.spawn]]
robot = 9
pose = [1.5, 1.0, 0.0]
[hwbridge]
mocap = {{type = "zenoh"}}
up_axis = "y"
transform = {{yaw = 0.5, tx = -1.0, ty = 0.5}}
kp = 3.0
k_theta = 3.0
feedforward = {ff}
geofence = "map"
[[hwbridge.robots]]
id = 1
body = "scarab1"
output = "zenoh"
start = [0.6, 0.7, 0.0]
[[hwbridge.robots]]
id = 2
body = "scarab2"
output = "ros2"
ros_mapping = "ros2dds"
start = [0.6, 1.3, 0.0]
[hwbridge.fake]
latency_s = 0.03
v_noise = 0.05
w_noise = 0.05
slip = 0.05
mocap_rate_hz = 100
mocap_noise_m = 0.001
mocap_noise_rad = 0.002
"""


class Procs:
    def __init__(self):
        self.all = []

    def start(self, *args) -> subprocess.Popen:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        p = subprocess.Popen([sys.executable, "-m", "swarmcover", *map(str, args)], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                             env=env, start_new_session=True)
        self.all.append(p)
        return p

    def kill_all(self):
        for p in reversed(self.all):
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(p.pid, sig)
                    p.wait(5)
                    break
                except ProcessLookupError:
                    break
                except subprocess.TimeoutExpired:
                    continue


def procs_run(feedforward: bool, seconds: float, seed: int = 0) -> dict:
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import CmdVel, Pose, decode
    sys.path.insert(0, str(ROOT / "tests"))
    from procs import client_session

    tmp = tempfile.mkdtemp(prefix="bench_hwbridge_")
    cfg = Path(tmp) / "bench.toml"
    cfg.write_text(CONFIG.format(ff="true" if feedforward else "false"))
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    swarm = f"bench{os.getpid()}{int(feedforward)}"
    z = ["--connect", endpoint, "--swarm", swarm]
    ps = Procs()
    try:
        router = ps.start("router", "--listen", endpoint)
        wait_line(router, "READY router", 40.0)
        fakes = [ps.start("fake-robot", cfg, "--id", rid, *z) for rid in (1, 2)]
        for f in fakes:
            wait_line(f, "READY fake-robot", 40.0)
        world = ps.start("world", cfg, *z)
        wait_line(world, "READY world", 40.0)
        report = Path(tmp) / "report.json"
        bridge = ps.start("hwbridge", cfg, "--spawn", "--report", report, *z)
        wait_line(bridge, "READY hwbridge", 40.0)
        eprint(f"  procs up (feedforward={feedforward}); driving for {seconds:.0f} s")
        s = client_session(endpoint, swarm)
        keys = Keys(swarm)
        poses = {}
        subs = [s.declare_subscriber(keys.odom(rid), lambda smp: poses.__setitem__(
            int(str(smp.key_expr).split("/")[-2]), decode(smp.payload.to_bytes(), Pose)))
            for rid in (1, 2)]
        rng = random.Random(seed)
        goals = {1: random_goal(rng), 2: random_goal(rng)}
        cpu0, t0 = cpu_seconds(bridge.pid), time.monotonic()
        while time.monotonic() - t0 < seconds:
            for rid in (1, 2):
                p = poses.get(rid)
                if p is None:
                    continue
                if math.dist((p.x, p.y), goals[rid]) < 0.15:
                    goals[rid] = random_goal(rng)
                v, w = waypoint_command((p.x, p.y, p.theta), goals[rid])
                s.put(keys.cmd_vel(rid), CmdVel(robot=rid, vx=v, wz=w).encode())
            time.sleep(0.05)
        cpu_share = (cpu_seconds(bridge.pid) - cpu0) / (time.monotonic() - t0)
        for sub in subs:
            sub.undeclare()
        s.close()
        os.killpg(bridge.pid, signal.SIGINT)
        bridge.wait(30)
        rep = json.loads(report.read_text())
    finally:
        ps.kill_all()
    robots = rep["robots"]
    return {"feedforward": feedforward, "seconds": seconds,
            "robots": {rid: {"position_error_m": r["position_error_m"],
                             "heading_error_rad": r["heading_error_rad"],
                             "lag_s": r["lag_s"], "teleports": r["teleports"]}
                       for rid, r in robots.items()},
            "formation_discrepancy_rad": rep["formation_discrepancy_rad"],
            "mocap_transport_latency_s": rep["mocap_transport_latency_s"],
            "gate_decisions": rep["gate_decisions"],
            "bridge_cpu_share": cpu_share}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="driving time per process run")
    ap.add_argument("--loop-seconds", type=float, default=60.0, help="simulated time per loop run")
    ap.add_argument("--skip-procs", action="store_true")
    args = ap.parse_args(argv)
    out = {"bench": "hwbridge", "loop": [], "procs": []}
    for ff in (False, True):
        t = time.perf_counter()
        r = loop_run(ff, args.loop_seconds)
        eprint(f"loop feedforward={ff}: error mean {r['position_error_m']['mean'] * 100:.1f} cm, "
               f"p95 {r['position_error_m']['p95'] * 100:.1f} cm, lag {r['lag_s']:.3f} s "
               f"({time.perf_counter() - t:.1f} s)")
        out["loop"].append(r)
    if not args.skip_procs:
        for ff in (False, True):
            r = procs_run(ff, args.seconds)
            for rid, rr in r["robots"].items():
                e = rr["position_error_m"]
                eprint(f"procs feedforward={ff} robot {rid}: error mean {e['mean'] * 100:.1f} cm, "
                       f"p95 {e['p95'] * 100:.1f} cm, lag {rr['lag_s']} s")
            eprint(f"  formation discrepancy {r['formation_discrepancy_rad']}, "
                   f"bridge CPU {r['bridge_cpu_share'] * 100:.1f} % of a core")
            out["procs"].append(r)
    print(json.dumps(out, allow_nan=False, default=lambda o: None))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Twin sync against the real world process: the bridge spawns live twins (--spawn) and
drives them to (1) scripted mocap trajectories and (2) a stand-in fake robot commanded like
an agent would, through a Y-up, rotated mocap frame."""
from __future__ import annotations

import json
import math
import signal
import threading
import time

import pytest

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, Pose, Truth, decode
from procs import client_session

pytest.importorskip("swarmcover.world.node")
pytestmark = pytest.mark.timeout(120)

WORLD = """
rv = 1.0
[map]
boundary = [[0, 0], [3, 0], [3, 2], [0, 2]]
sources = [{x = 0.4, y = 1.0, theta = 0.0}]
[robots]
kind = "holonomic"
[world]
dt = 0.05
mode = "realtime"
rtf = 1.0
"""

SCRIPTED = 'name = "hwb_scripted"\n' + WORLD + """
[hwbridge]
up_axis = "y"
transform = {yaw = -0.7, tx = 0.5, ty = -0.25}
feedforward = true
[hwbridge.mocap]
type = "scripted"
rate_hz = 100
noise_m = 0.001
latency_s = 0.02
bodies = [
  {body = "s1", path = "circle", center = [1.5, 1.0], radius = 0.5, speed = 0.25},
  {body = "s2", path = "static", pose = [2.5, 1.5, 1.0]},
]
[[hwbridge.robots]]
id = 11
body = "s1"
[[hwbridge.robots]]
id = 12
body = "s2"
"""


class TruthLog:
    def __init__(self, session, keys):
        self.lock = threading.Lock()
        self.rows = []
        self.sub = session.declare_subscriber(keys.truth, self._cb)

    def _cb(self, sample):
        with self.lock:
            self.rows.append((time.monotonic(), sample.payload.to_bytes()))

    def poses(self, rid):
        with self.lock:
            rows = list(self.rows)
        out = []
        for t, b in rows:
            m = decode(b, Truth)
            if rid in m.ids:
                k = m.ids.index(rid)
                out.append((t, (m.x[k], m.y[k], m.theta[k]), m.live[k]))
        return out

    def close(self):
        self.sub.undeclare()


def start(procs, cfg, zargs, *bridge_args):
    world = procs.swarmcover("world", cfg, *zargs)
    world.wait_line("READY world", timeout=40)
    bridge = procs.swarmcover("hwbridge", cfg, "--spawn", *bridge_args, *zargs)
    bridge.wait_line("READY hwbridge", timeout=30)
    return world, bridge


def stop_bridge(bridge):
    bridge.signal(signal.SIGINT)
    line = bridge.wait_line("SUMMARY ", timeout=30)
    assert bridge.wait(15) == 0
    return json.loads(line.split("SUMMARY ", 1)[1])


def test_twins_converge_to_scripted_mocap(procs, router, zargs, tmp_path):
    cfg = tmp_path / "scripted.toml"
    cfg.write_text(SCRIPTED)
    swarm = zargs[zargs.index("--swarm") + 1]
    world, bridge = start(procs, cfg, zargs)
    s = client_session(router, swarm)
    log = TruthLog(s, Keys(swarm))
    try:
        time.sleep(9.0)
        p11, p12 = log.poses(11), log.poses(12)
    finally:
        log.close()
        s.close()
    rep = stop_bridge(bridge)
    print(json.dumps(rep["robots"]), rep["formation_discrepancy_rad"])
    assert p11 and p12 and all(live for _, _, live in p11 + p12)   # spawned as twins
    # the twins left the source (0.4, 1.0): the static one sits on its mocap pose
    t_end = p12[-1][0]
    late12 = [p for t, p, _ in p12 if t > t_end - 3.0]
    for x, y, th in late12:
        assert math.hypot(x - 2.5, y - 1.5) < 0.02 and abs(th - 1.0) < 0.05
    # the moving one runs on the scripted circle (radius 0.5 around (1.5, 1.0))
    late11 = [p for t, p, _ in p11 if t > t_end - 4.0]
    radii = [math.hypot(x - 1.5, y - 1.0) for x, y, _ in late11]
    assert min(radii) > 0.42 and max(radii) < 0.58
    arc = sum(math.dist(a[:2], b[:2]) for a, b in zip(late11, late11[1:]))
    assert 0.6 < arc < 1.4                       # 0.25 m/s for ~4 s
    r11 = rep["robots"]["11"]
    assert r11["teleports"] >= 1                 # first sync from the source
    assert r11["position_error_m"]["n"] > 50
    assert r11["position_error_m"]["mean"] < 0.06, r11
    assert rep["robots"]["12"]["position_error_m"]["p95"] < 0.02
    world.signal(signal.SIGINT)
    assert world.wait(20) == 0


FAKE = 'name = "hwb_fake"\n' + WORLD + """
[hwbridge]
mocap = {type = "zenoh"}
up_axis = "y"
transform = {yaw = 0.5, tx = -1.0, ty = 0.5}
feedforward = true
[[hwbridge.robots]]
id = 21
body = "scarab21"
output = "ros2"
ros_mapping = "ros2dds"
start = [0.6, 1.0, 0.0]
[hwbridge.fake]
latency_s = 0.03
slip = 0.05
"""


def test_twin_follows_a_fake_robot_driven_like_an_agent(procs, router, zargs, tmp_path):
    cfg = tmp_path / "fake.toml"
    cfg.write_text(FAKE)
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    fake = procs.swarmcover("fake-robot", cfg, "--id", 21, *zargs)
    fake.wait_line("READY fake-robot", timeout=30)
    world, bridge = start(procs, cfg, zargs)
    s = client_session(router, swarm)
    log = TruthLog(s, keys)
    odom = []
    sub = s.declare_subscriber(keys.odom(21), lambda smp: odom.append(
        (time.monotonic(), decode(smp.payload.to_bytes(), Pose))))
    try:
        assert wait_for(lambda: log.poses(21), 15)
        t_end = time.monotonic() + 6.0            # an agent's commands: an arc at 0.2 m/s
        while time.monotonic() < t_end:
            s.put(keys.cmd_vel(21), CmdVel(robot=21, vx=0.2, wz=0.25).encode())
            time.sleep(0.05)
        time.sleep(1.0)
        twin = log.poses(21)
        meas = list(odom)
    finally:
        sub.undeclare()
        log.close()
        s.close()
    rep = stop_bridge(bridge)
    print(json.dumps(rep["robots"]), rep["formation_discrepancy_rad"])
    # the robot drove about 1.2 m; its twin ends where the mocap says the robot is
    assert math.dist((meas[-1][1].x, meas[-1][1].y), (0.6, 1.0)) > 0.8
    last = twin[-1][1]
    assert math.dist(last[:2], (meas[-1][1].x, meas[-1][1].y)) < 0.03
    assert abs(math.remainder(last[2] - meas[-1][1].theta, 2 * math.pi)) < 0.05
    r = rep["robots"]["21"]
    assert r["position_error_m"]["mean"] < 0.06 and r["position_error_m"]["p95"] < 0.1, r
    assert r["lag_s"] is not None and r["lag_s"] < 0.3
    world.signal(signal.SIGINT)
    fake.signal(signal.SIGINT)
    assert world.wait(20) == 0 and fake.wait(15) == 0


def wait_for(pred, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.1)
    return bool(pred())

"""The hardware bridge and stand-in live robots as real processes over a real router:
command path (LiveCmd and ROS 2 CDR Twist, rmw_zenoh attachment), deadman on command and
mocap silence, geofence, non-live robots, body-name reports, mocap-frame odometry."""
from __future__ import annotations

import json
import math
import signal
import threading
import time

import pytest

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, LiveCmd, Pose, decode
from swarmcover.hwbridge.ros2 import cmd_vel_key, decode_twist
from procs import client_session, wait_until

pytestmark = pytest.mark.timeout(120)

MAP = """
rv = 1.0
[map]
boundary = [[0, 0], [3, 0], [3, 2], [0, 2]]
sources = [{x = 0.5, y = 1.0, theta = 0.0}]
"""

CMD_CONFIG = 'name = "hwb_cmd"\n' + MAP + """
[hwbridge]
mocap = {type = "zenoh"}
up_axis = "y"
transform = {yaw = 0.5, tx = -1.0, ty = 0.5}
deadman_s = 0.3
cmd_rate_hz = 20
[[hwbridge.robots]]
id = 1
body = "scarab1"
start = [1.0, 1.0, 0.0]
[[hwbridge.robots]]
id = 2
body = "scarab2"
output = "ros2"
ros_mapping = "rmw_zenoh"
start = [2.0, 1.0, 1.5]
[[hwbridge.robots]]
id = 3
body = "scarab3"
start = [5.0, 1.0, 0.0]          # outside the map: the geofence must hold it
[hwbridge.fake]
latency_s = 0.02
mocap_noise_m = 0.0005
mocap_noise_rad = 0.001
"""


class Recorder:
    """Subscribes to keys in the test process; stores (receipt time, key, payload, attachment)."""

    def __init__(self, session, keys):
        self.lock = threading.Lock()
        self.items = []
        self.subs = [session.declare_subscriber(k, self._cb) for k in keys]

    def _cb(self, sample):
        att = sample.attachment.to_bytes() if sample.attachment is not None else None
        with self.lock:
            self.items.append((time.monotonic(), str(sample.key_expr), sample.payload.to_bytes(), att))

    def get(self, key_part=None):
        with self.lock:
            return [it for it in self.items if key_part is None or key_part in it[1]]

    def close(self):
        for s in self.subs:
            s.undeclare()


def summary_of(proc):
    line = proc.wait_line("SUMMARY ", timeout=20)
    return json.loads(line.split("SUMMARY ", 1)[1])


def _bridge(procs, router, zargs, path, text: str, record: list[str]):
    """Write ``text`` to ``path``, start a bridge on it and wait for it; returns (bridge,
    a client session, a Recorder of the keys ``record``): close the last two."""
    path.write_text(text)
    bridge = procs.swarmcover("hwbridge", path, *zargs)
    bridge.wait_line("READY hwbridge", timeout=30)
    s = client_session(router, zargs[zargs.index("--swarm") + 1])
    return bridge, s, Recorder(s, record)


def test_commands_deadman_geofence_ros2_and_odometry(procs, router, zargs, tmp_path):
    cfg = tmp_path / "cmd.toml"
    cfg.write_text(CMD_CONFIG)
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    fakes = [procs.swarmcover("fake-robot", cfg, "--id", rid, *zargs) for rid in (1, 2, 3)]
    bridge = procs.swarmcover("hwbridge", cfg, *zargs)
    for p in fakes:
        p.wait_line("READY fake-robot", timeout=30)
    bridge.wait_line("READY hwbridge", timeout=30)

    s = client_session(router, swarm)
    rmw_key = cmd_vel_key("rmw_zenoh", "/scarab2")
    rec = Recorder(s, [keys.live_cmd("*"), rmw_key, keys.odom("*")])
    try:
        # odometry: the Y-up, rotated mocap pose comes back as the world start pose
        assert wait_until(lambda: rec.get("/robot/1/odom") and rec.get("/robot/3/odom"), 20)
        p1 = decode(rec.get("/robot/1/odom")[-1][2], Pose)
        assert p1.source == "mocap"
        assert (p1.x, p1.y) == pytest.approx((1.0, 1.0), abs=0.01) and abs(p1.theta) < 0.02
        p2 = decode(rec.get("/robot/2/odom")[-1][2], Pose)
        assert (p2.x, p2.y, p2.theta) == pytest.approx((2.0, 1.0, 1.5), abs=0.02)

        # agents command robots 1..4 for 1.5 s (4 is not live), then fall silent
        t_end = time.monotonic() + 1.5
        while time.monotonic() < t_end:
            for rid in (1, 2, 3, 4):
                s.put(keys.cmd_vel(rid), CmdVel(robot=rid, vx=0.2, wz=0.3).encode())
            t_last = time.monotonic()
            time.sleep(0.05)
        time.sleep(1.5)

        live1 = [(t, decode(b, LiveCmd)) for t, _, b, _ in rec.get("/live/1/cmd")]
        moving = [c for t, c in live1 if t < t_last and c.v > 0]
        assert moving and moving[-1].v == pytest.approx(0.2) and moving[-1].omega == pytest.approx(0.3)
        first_zero = min(t for t, c in live1 if t > t_last and c.v == 0 and c.omega == 0)
        delay = first_zero - t_last
        # deadman 0.3 s, output every 50 ms; slack for a loaded 2-core machine
        print(f"deadman stop {delay:.3f} s after the last command")
        assert delay < 0.3 + 0.05 + 0.35, f"deadman stop took {delay:.3f} s"
        assert all(c.v == 0 and c.omega == 0 for t, c in live1 if t > first_zero)

        live3 = [decode(b, LiveCmd) for _, _, b, _ in rec.get("/live/3/cmd")]
        assert live3 and all(c.v == 0 and c.omega == 0 for c in live3)      # geofence
        assert rec.get("/live/4/cmd") == []                                 # not live: never

        ros = rec.get(rmw_key)
        twists = [decode_twist(b) for _, _, b, _ in ros]
        assert any(tw.lx == pytest.approx(0.2) and tw.az == pytest.approx(0.3) for tw in twists)
        assert twists[-1].lx == 0 and twists[-1].az == 0
        atts = [a for _, _, _, a in ros]
        assert all(a is not None and len(a) == 33 for a in atts)            # rmw_zenoh needs it
        seqs = [int.from_bytes(a[:8], "little") for a in atts]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)

        # the stand-in robots moved, then stopped
        def odom(rid):
            return [(t, decode(b, Pose)) for t, _, b, _ in rec.get(f"/robot/{rid}/odom")]
        for rid, start in ((1, (1.0, 1.0)), (2, (2.0, 1.0))):
            o = odom(rid)
            last = o[-1][1]
            assert math.dist((last.x, last.y), start) > 0.15
            before = [p for t, p in o if first_zero + 0.5 < t < first_zero + 0.8]
            assert before and math.dist((before[0].x, before[0].y), (last.x, last.y)) < 0.01
        o3 = odom(3)
        assert math.dist((o3[-1][1].x, o3[-1][1].y), (5.0, 1.0)) < 0.01     # never moved
    finally:
        rec.close()
        s.close()
    bridge.signal(signal.SIGINT)
    rep = summary_of(bridge)
    assert bridge.wait(15) == 0
    gates = rep["gate_decisions"]
    assert gates["3"]["geofence"] > 0 and gates["3"]["ok"] == 0
    assert gates["1"]["command_stale"] > 0 and gates["1"]["ok"] > 0
    assert rep["mocap_transport_latency_s"]["n"] > 100
    for p in fakes:
        p.signal(signal.SIGINT)
        assert p.wait(15) == 0
        assert "FINAL fake-robot" in p.output()


SILENCE_CONFIG = 'name = "hwb_silence"\n' + MAP + """
[hwbridge]
deadman_s = 0.3
silence_s = 0.5
cmd_rate_hz = 20
geofence = "none"
rate_band_hz = [50, 200]
[hwbridge.mocap]
type = "scripted"
rate_hz = 100
rename = {other = "ghost"}
bodies = [
  {body = "scarab1", path = "static", pose = [1.0, 1.0, 0.0], gaps = [[2.0, 3.5]]},
  {body = "other", path = "static", pose = [2.0, 1.0, 0.0]},
]
[[hwbridge.robots]]
id = 1
body = "scarab1"
[[hwbridge.robots]]
id = 7
body = "nobody"
"""


def test_mocap_silence_stops_the_robot_and_bodies_are_reported(procs, router, zargs, tmp_path):
    keys = Keys(zargs[zargs.index("--swarm") + 1])
    bridge, s, rec = _bridge(procs, router, zargs, tmp_path / "silence.toml", SILENCE_CONFIG,
                             [keys.live_cmd(1)])
    try:
        t_end = time.monotonic() + 5.5          # commands never stop; mocap has a 1.5 s gap
        while time.monotonic() < t_end:
            s.put(keys.cmd_vel(1), CmdVel(robot=1, vx=0.1, wz=0.0).encode())
            time.sleep(0.05)
        cmds = [(t, decode(b, LiveCmd).v) for t, _, b, _ in rec.get()]
    finally:
        rec.close()
        s.close()
    # runs of moving / stopped outputs: moving, then stopped (gap), then moving again
    runs = []
    for t, v in cmds:
        moving = v > 0
        if not runs or runs[-1][0] != moving:
            runs.append([moving, t, t])
        runs[-1][2] = t
    pattern = [r[0] for r in runs if r[2] - r[1] > 0.2]
    assert pattern[-3:] == [True, False, True], runs
    gap = [r for r in runs if not r[0] and r[2] - r[1] > 0.2][-1]
    assert 0.6 < gap[2] - gap[1] < 1.6, runs       # 1.5 s gap minus the 0.3 s deadman
    out = bridge.output()
    assert "mocap body 'nobody' (robot 7) not seen" in out
    assert "mocap body 'ghost' is not configured" in out
    assert "mocap body 'scarab1' (robot 1) silent for" in out
    bridge.signal(signal.SIGTERM)
    rep = summary_of(bridge)
    assert rep["gate_decisions"]["1"]["mocap_stale"] > 0
    assert rep["unknown_bodies"]["ghost"] > 0
    assert bridge.wait(15) == 0


def test_bad_config_exits_naming_the_field(procs, tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(MAP + '[hwbridge]\nkp = "fast"\n[[hwbridge.robots]]\nid = 1\nbody = "b"\n')
    p = procs.swarmcover("hwbridge", cfg, "--connect", "tcp/127.0.0.1:9", "--connect-timeout", "1")
    assert p.wait(30) == 2
    assert f"{cfg}: [hwbridge] kp = 'fast': expected a number" in p.output()
    p = procs.swarmcover("fake-robot", cfg, "--id", "9", "--connect", "tcp/127.0.0.1:9")
    assert p.wait(30) == 2


POSE_STAMPED_CONFIG = 'name = "hwb_ros_mocap"\n' + MAP + """
[hwbridge]
mocap = {type = "zenoh", key = "vrpn_mocap/{body}/pose", format = "pose_stamped"}
up_axis = "z"
transform = {yaw = 1.0, tx = 0.5, ty = 0.25}
[[hwbridge.robots]]
id = 5
body = "scarab5"
"""


def test_ros2_pose_stamped_mocap_source(procs, router, zargs, tmp_path):
    """A ROS 2 mocap node seen through zenoh-bridge-ros2dds: CDR PoseStamped on a raw key."""
    from swarmcover.hwbridge.frames import Transform2D, world_to_mocap
    from swarmcover.hwbridge.ros2 import PoseStamped, encode_pose_stamped
    keys = Keys(zargs[zargs.index("--swarm") + 1])
    bridge, s, rec = _bridge(procs, router, zargs, tmp_path / "ros_mocap.toml",
                             POSE_STAMPED_CONFIG, [keys.odom(5)])
    try:
        pos, q = world_to_mocap(1.25, 0.75, -2.0, "z", Transform2D(1.0, 0.5, 0.25), 0.12)
        payload = encode_pose_stamped(PoseStamped(12.0, "mocap", pos, q))
        s.put("vrpn_mocap/scarab5/pose", b"\x00\x01\x00\x00garbage")   # dropped, counted
        end = time.monotonic() + 10
        while time.monotonic() < end and not rec.get():
            s.put("vrpn_mocap/scarab5/pose", payload)
            time.sleep(0.02)
        odom = [decode(b, Pose) for _, _, b, _ in rec.get()]
    finally:
        rec.close()
        s.close()
    assert odom, bridge.output()
    assert (odom[-1].x, odom[-1].y, odom[-1].theta) == pytest.approx((1.25, 0.75, -2.0), abs=1e-6)
    assert "dropping invalid PoseStamped on vrpn_mocap/scarab5/pose" in bridge.output()
    bridge.signal(signal.SIGTERM)
    rep = summary_of(bridge)
    assert rep["invalid_messages"] >= 1
    assert bridge.wait(15) == 0

"""Live robots fail safe at the robot (issue 22): every LiveCmd carries its own expiry
(``ttl``, seconds from receipt) and the stand-in robot's driver stops when it passes, so a
killed or frozen bridge, or a frozen router, stops the robot within its expiry; a ROS 2
Twist has no expiry field, so the driver's own cmd_vel timeout stops it.

Real processes over a real router; odometry is the stand-in's own mocap output (it is the
robot's true pose plus noise, here zero noise)."""
from __future__ import annotations

import math
import os
import signal
import threading
import time
from pathlib import Path

import msgpack
import pytest

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, LiveCmd, MocapPose, WireError, decode
from swarmcover.hwbridge.config import ConfigError, loads
from swarmcover.hwbridge.driver import CommandExpiry
from procs import client_session, free_port, toml_tables, wait_until

pytestmark = pytest.mark.timeout(120)

V = 0.2           # m/s commanded
TTL = 0.3         # s, [hwbridge] cmd_ttl_s below
PERIOD = 0.05     # s, 1 / cmd_rate_hz
LATENCY = 0.02    # s, [hwbridge.fake] latency_s
TWIST_TIMEOUT = 0.5   # s, the stand-in driver's own cmd_vel timeout (--cmd-timeout default)
FAULT_S = 2.0     # how long the fault lasts (freeze) or is watched (kill)
SLACK_M = 0.03    # mocap sample age, loop periods, scheduling on a loaded machine

CONFIG = """
name = "hwb_failsafe"
rv = 1.0
[map]
boundary = [[-10, -10], [10, -10], [10, 10], [-10, 10]]
sources = [{x = 0.0, y = 0.0, theta = 0.0}]
[hwbridge]
mocap = {type = "zenoh"}
geofence = "none"
deadman_s = 0.3
cmd_rate_hz = 20
cmd_ttl_s = 0.3
fake = {latency_s = 0.02, v_noise = 0.0, w_noise = 0.0, slip = 0.0, mocap_noise_m = 0.0, \
mocap_noise_rad = 0.0}
""" + toml_tables("hwbridge.robots", dict(id=1, body="fs1", start=[0.0, 0.0, 0.0]),
                  dict(id=2, body="fs2", output="ros2", start=[0.0, 2.0, 0.0]))


# --------------------------------------------------------------------------- pure parts

def test_expiry_stops_a_moving_command_once_its_ttl_has_passed():
    e = CommandExpiry(timeout_s=0.5)
    assert not e.expired(100.0)                       # nothing commanded: nothing to stop
    assert e.on_command(10.0, 0.2, 0.1, ttl=0.3) == pytest.approx(10.3)
    assert not e.expired(10.0) and not e.expired(10.29)
    assert e.expired(10.3) and e.stops == 1           # the driver commands zero now
    assert not e.expired(10.4) and not e.expired(50.0) and e.stops == 1   # once
    e.on_command(11.0, 0.2, 0.0, ttl=0.3)
    e.on_command(11.2, 0.2, 0.0, ttl=0.3)             # a newer command extends it
    assert not e.expired(11.45) and e.expired(11.5) and e.stops == 2
    e.on_command(12.0, 0.0, 0.0, ttl=0.3)             # a zero command needs no stop
    assert not e.expired(13.0) and e.stops == 2


def test_expiry_without_ttl_uses_the_drivers_timeout_and_caps_any_ttl():
    e = CommandExpiry(timeout_s=0.5)
    for ttl in (0.0, -1.0, math.nan, math.inf):       # absent (old sender, Twist) or bogus
        assert e.on_command(0.0, 0.1, 0.0, ttl) == pytest.approx(0.5)
    assert e.on_command(0.0, 0.1, 0.0, ttl=10.0) == pytest.approx(0.5)   # capped
    assert e.on_command(0.0, 0.1, 0.0, ttl=0.2) == pytest.approx(0.2)
    for bad in (0.0, -0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match="command timeout"):
            CommandExpiry(timeout_s=bad)


def test_livecmd_ttl_is_on_the_wire_and_old_senders_still_decode():
    m = decode(LiveCmd(robot=3, t=1.0, v=0.2, omega=0.1, ttl=0.3).encode(), LiveCmd)
    assert m.ttl == pytest.approx(0.3)
    old = msgpack.packb({"_t": "LiveCmd", "_v": 1, "robot": 3, "t": 1.0, "v": 0.2, "omega": 0.1})
    m = decode(old, LiveCmd)                          # a sender that predates ttl
    assert (m.v, m.ttl) == (0.2, 0.0)                 # 0: the driver's own timeout applies
    for bad in (-0.1, 11.0, math.nan):
        payload = msgpack.packb({**LiveCmd(robot=3, v=0.2).to_dict(), "ttl": bad})
        with pytest.raises(WireError, match="LiveCmd.ttl"):
            decode(payload, LiveCmd)
    with pytest.raises(WireError, match="LiveCmd.v: missing"):   # other fields stay required
        decode(msgpack.packb({"_t": "LiveCmd", "_v": 1, "robot": 3, "t": 1.0, "omega": 0.1}))


def test_bridge_ttl_config():
    base = 'rv = 1.0\n[hwbridge]\n%s\n[[hwbridge.robots]]\nid = 1\nbody = "b"\n'
    assert loads(base % "").cmd_ttl_s == 0.3
    assert loads(base % "cmd_ttl_s = 0.5").cmd_ttl_s == 0.5
    with pytest.raises(ConfigError, match=r"\[hwbridge\] cmd_ttl_s = 0.05: shorter than two "
                                          r"command periods \(2 / cmd_rate_hz = 0.1 s\)"):
        loads(base % "cmd_ttl_s = 0.05")
    with pytest.raises(ConfigError, match=r"\[hwbridge.fake\] cmd_timeout_s = 0"):
        loads(base % "[hwbridge.fake]\ncmd_timeout_s = 0")


# --------------------------------------------------------------------------- processes

class Poses:
    """The stand-ins' mocap poses (x, y: up axis z, identity transform = world frame)."""

    def __init__(self, session, keys):
        self.lock = threading.Lock()
        self.items: list[tuple[float, str, float, float]] = []
        self.sub = session.declare_subscriber(keys.mocap("*"), self._cb)

    def _cb(self, sample):
        m = decode(sample.payload.to_bytes(), MocapPose)
        with self.lock:
            self.items.append((time.monotonic(), m.body, m.x, m.y))

    def last(self, body, before=math.inf):
        with self.lock:
            got = [(t, x, y) for t, b, x, y in self.items if b == body and t < before]
        return got[-1] if got else None

    def close(self):
        self.sub.undeclare()


@pytest.mark.parametrize("fault", ["bridge_kill", "bridge_stop", "router_stop"])
def test_live_robot_stops_within_its_expiry_whoever_fails(procs, tmp_path, fault):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = procs.swarmcover("router", "--listen", endpoint)
    router.wait_line("READY router", timeout=20)
    swarm = "fs" + os.urandom(4).hex()
    zargs = ["--connect", endpoint, "--swarm", swarm]
    keys = Keys(swarm)
    cfg = tmp_path / "failsafe.toml"
    cfg.write_text(CONFIG)
    fakes = {rid: procs.swarmcover("fake-robot", cfg, "--id", rid, "--walls", "none", *zargs)
             for rid in (1, 2)}
    bridge = procs.swarmcover("hwbridge", cfg, *zargs)
    for p in fakes.values():
        p.wait_line("READY fake-robot", timeout=30)
    bridge.wait_line("READY hwbridge", timeout=30)

    s = client_session(endpoint, swarm)
    poses = Poses(s, keys)
    frozen = None
    try:
        assert wait_until(lambda: poses.last("fs1") and poses.last("fs2"), 20)
        # an agent drives both robots straight ahead for 1.5 s, then falls silent at the fault
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            for rid in (1, 2):
                s.put(keys.cmd_vel(rid), CmdVel(robot=rid, vx=V).encode())
            time.sleep(PERIOD)
        start = {b: poses.last(b) for b in ("fs1", "fs2")}
        t_fault = time.monotonic()
        if fault == "bridge_kill":
            os.kill(bridge.pid, signal.SIGKILL)
        elif fault == "bridge_stop":
            frozen = bridge
        else:
            frozen = router
        if frozen is not None:
            os.kill(frozen.pid, signal.SIGSTOP)
        time.sleep(FAULT_S)
        if frozen is not None:
            os.kill(frozen.pid, signal.SIGCONT)
            frozen = None
        t_back = time.monotonic()
        time.sleep(1.0)                 # fresh poses through a thawed router
        moved = {}
        for b in ("fs1", "fs2"):
            t0, x0, y0 = start[b]
            t1, x1, y1 = poses.last(b)
            assert t1 > t_back, f"no fresh pose of {b} after the fault"
            before_fault = start[b][1:]
            moved[b] = math.dist((x1, y1), before_fault) - V * (t_fault - t0)
    finally:
        if frozen is not None:
            os.kill(frozen.pid, signal.SIGCONT)
        poses.close()
        s.close()
    print(f"{fault}: moved after the fault: LiveCmd robot {moved['fs1']:.3f} m, "
          f"ROS 2 Twist robot {moved['fs2']:.3f} m (fault {FAULT_S:.0f} s)")
    assert moved["fs1"] > 0.0                       # it was moving when the fault came
    assert moved["fs1"] < V * (TTL + PERIOD + LATENCY) + SLACK_M, moved
    assert moved["fs2"] < V * (TWIST_TIMEOUT + PERIOD + LATENCY) + SLACK_M, moved
    for rid, p in fakes.items():
        p.signal(signal.SIGINT)
        assert p.wait(15) == 0
        out = p.output()
        assert "command expired" in out, out[-2000:]
        assert "expiry_stops=" in out and "expiry_stops=0 " not in out, out[-1000:]


# --------------------------------------------------------------------------- a whole run

@pytest.mark.timeout(400)
def test_ctrl_c_on_a_mixed_run_stops_live_robots_first(procs, tmp_path):
    """SIGINT to `swarmcover run configs/mixed.toml` while a live robot drives: zeros reach
    the live robots at once and are their last word; agents and coordinator stop before
    final.png is drawn (issue 22: non-zero commands went on 1.2-1.6 s, past final.png)."""
    from swarmcover.hwbridge.ros2 import cmd_vel_key, decode_twist
    root = Path(__file__).resolve().parent.parent
    port, swarm, out = free_port(), "ci" + os.urandom(4).hex(), tmp_path / "run"
    run = procs.swarmcover("run", root / "configs" / "mixed.toml", "--out", out, "--port", port,
                           "--swarm", swarm, "--quiet", "--wall-timeout", "300")
    run.wait_line("swarmcover run: mixed -> ", timeout=60)
    s = client_session(f"tcp/127.0.0.1:{port}", swarm)
    lock, cmds = threading.Lock(), []           # (wall time, robot, moving)

    def on_live(sample):
        m = decode(sample.payload.to_bytes(), LiveCmd)
        with lock:
            cmds.append((time.time(), 1, m.v != 0 or m.omega != 0))

    def on_twist(sample):
        tw = decode_twist(sample.payload.to_bytes())
        with lock:
            cmds.append((time.time(), 2, tw.lx != 0 or tw.az != 0))

    subs = [s.declare_subscriber(Keys(swarm).live_cmd(1), on_live),
            s.declare_subscriber(cmd_vel_key("ros2dds", "/scarab2"), on_twist)]

    def driving():
        with lock:
            return any(mv and time.time() - t < 0.1 for t, _, mv in cmds[-10:])
    try:
        assert wait_until(driving, 300, interval=0.01), run.output()[-3000:]
        t_int = time.time()
        run.signal(signal.SIGINT)
        assert run.wait(120) == 130, run.output()[-3000:]
        time.sleep(0.5)
    finally:
        for sub in subs:
            sub.undeclare()
        s.close()
    with lock:
        after = [(t, rid, mv) for t, rid, mv in cmds if t >= t_int]
    last_moving = max([t for t, _, mv in after if mv], default=t_int)
    png = (out / "final.png").stat().st_mtime
    logs = [out / "logs" / "coordinator.log"] + sorted((out / "logs").glob("agent-*.log"))
    last_log = max(p.stat().st_mtime for p in logs)
    n_moving = sum(mv for _, _, mv in after)
    print(f"after SIGINT: {n_moving} non-zero live commands, the last at "
          f"+{last_moving - t_int:.3f} s, "
          f"agents/coordinator last wrote +{last_log - t_int:.3f} s, "
          f"final.png +{png - t_int:.3f} s")
    for f in sorted((out / "logs").glob("fake-robot-*.log")):
        print(next((ln for ln in f.read_text().splitlines() if ln.startswith("FINAL")), f))
    for rid in (1, 2):                 # each live robot's last word is a stop
        mine = [mv for _, r, mv in after if r == rid]
        assert mine and not mine[-1], (rid, after[-20:])
    assert last_moving - t_int < 0.5, after[:40]     # was 1.2-1.6 s (issue 22)
    assert last_moving < last_log < png             # zeros first, then stop, then draw

"""The ``swarmcover agent`` process over a real Zenoh router: it reaches a recorded vertex in
a lockstep world, it steers identically with garbage or absent pose telemetry, it rejects
malformed tasks without crashing (and counts them), and it reads its parameters."""
from __future__ import annotations

import math
import signal
import sys
import threading
import time
from pathlib import Path

import pytest

from bus.keys import Keys
from bus.messages import CmdVel, Pose, Sense, Status, Task, decode
from procs import client_session

pytestmark = pytest.mark.timeout(120)
FAKE_WORLD = str(Path(__file__).resolve().parent / "test_agent_fakeworld.py")


class Collector:
    """Records decoded messages per key from a client session (callbacks only append)."""

    def __init__(self, session, keys_and_types):
        self.msgs: dict[str, list] = {k: [] for k, _ in keys_and_types}
        self.lock = threading.Lock()
        self.subs = [session.declare_subscriber(k, self._cb(k, t)) for k, t in keys_and_types]

    def _cb(self, key, typ):
        def cb(sample):
            try:
                m = decode(sample.payload.to_bytes(), typ)
            except Exception:
                return
            with self.lock:
                self.msgs[key].append(m)
        return cb

    def get(self, key):
        with self.lock:
            return list(self.msgs[key])

    def close(self):
        for s in self.subs:
            s.undeclare()


def start_agent(procs, zargs, rid, *extra):
    p = procs.swarmcover("agent", "--id", rid, "--info-timeout", "0", *zargs, *extra)
    return p


def test_agent_reaches_recorded_vertex_in_lockstep_world(procs, zargs, router):
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    agent = start_agent(procs, zargs, 0)
    agent.wait_line("READY agent 0", timeout=30)
    s = client_session(router, swarm)
    try:
        col = Collector(s, [(keys.status(0), Status), (keys.pose(0), Pose)])
        world = procs.start([sys.executable, FAKE_WORLD, *zargs, "--goto", "0,0", "--ticks",
                             "400", "--noise-deg", "0.5"])
        world.wait_line("DONE", timeout=90)
        line = world.wait_line("POSE 0")
        _, _, x, y, _ = line.split()
        assert math.hypot(float(x), float(y)) < 0.03, line
        time.sleep(0.3)
        sts = col.get(keys.status(0))
        assert any(st.task_id == 1 and st.task_state == "done" and st.state == "holding"
                   and st.vertex == 5 for st in sts), sts[-3:]
        assert [st.seq for st in sts] == sorted(st.seq for st in sts)
        assert any(st.state == "moving" for st in sts)
        last = sts[-1]
        assert sorted(last.nbr_ids) == [1, 2, 3] and len(last.pose) == 3
        relays = col.get(keys.pose(0))
        assert relays and all(p.source == "agent" and p.robot == 0 for p in relays)
        assert math.hypot(relays[-1].x, relays[-1].y) < 0.05
        col.close()
    finally:
        s.close()
    agent.signal(signal.SIGINT)
    assert agent.wait(15) == 0
    assert "400 ticks" in agent.output() or "ticks" in agent.output()


def test_pose_telemetry_is_never_used(procs, zargs, router):
    """Two agents get identical Sense streams (two copies of one world); robot 0 gets no
    odometry, robot 10 gets garbage. Their command streams must be identical."""
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    a0 = start_agent(procs, zargs, 0)
    a10 = start_agent(procs, zargs, 10)
    a0.wait_line("READY agent 0", timeout=30)
    a10.wait_line("READY agent 10", timeout=30)
    s = client_session(router, swarm)
    try:
        col = Collector(s, [(keys.cmd_vel(0), CmdVel), (keys.cmd_vel(10), CmdVel),
                            (keys.status(0), Status), (keys.status(10), Status)])
        world = procs.start([sys.executable, FAKE_WORLD, *zargs, "--goto", "0.05,0.1",
                             "--ticks", "200", "--copies", "2", "--stride", "10",
                             "--odom", "none,garbage", "--start", "0.3,-0.3,0"])
        world.wait_line("DONE", timeout=90)
        time.sleep(0.3)
        c0 = {c.tick: (c.vx, c.vy, c.wz) for c in col.get(keys.cmd_vel(0)) if c.tick >= 0}
        c10 = {c.tick: (c.vx, c.vy, c.wz) for c in col.get(keys.cmd_vel(10)) if c.tick >= 0}
        assert len(c0) == 200 and c0 == c10
        assert any(v != (0.0, 0.0, 0.0) for v in c0.values())       # it did move
        st0 = [(st.state, st.task_state, st.progress) for st in col.get(keys.status(0))]
        st10 = [(st.state, st.task_state, st.progress) for st in col.get(keys.status(10))]
        assert st0[-1] == st10[-1] and st0[-1][1] == "done"
        assert col.get(keys.status(0))[-1].pose == []            # no telemetry at all
        col.close()
    finally:
        s.close()
    for a in (a0, a10):
        a.signal(signal.SIGTERM)
        assert a.wait(15) == 0
    assert "invalid messages" in a10.output()


def test_malformed_tasks_are_rejected_and_counted(procs, zargs, router):
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    agent = start_agent(procs, zargs, 3)
    agent.wait_line("READY agent 3", timeout=30)
    s = client_session(router, swarm)
    try:
        col = Collector(s, [(keys.cmd_vel(3), CmdVel), (keys.status(3), Status)])
        time.sleep(0.5)
        bad = [b"\x00\x01 not msgpack",
               Status(robot=3).encode(),                                    # wrong type
               Task(task_id=1, robot=4, kind="hold").encode(),              # other robot
               Task(task_id=1, robot=3, kind="hold").encode().replace(b"hold", b"fly!"),
               Task(task_id=1, robot=3, landmarks=[1, 2], bearings=[0.1]).encode()]
        for payload in bad:
            s.put(keys.task(3), payload)
        s.put(keys.sense(3), b"\xc1")                                       # bad Sense
        s.put(keys.task(3), Task(task_id=9, robot=3, kind="hold", vertex=2).encode())
        for tick in range(12):
            s.put(keys.sense(3), Sense(robot=3, tick=tick, t=0.05 * tick, ids=[1],
                                       bearings=[0.5], back_bearings=[-2.6]).encode())
            end = time.monotonic() + 10
            while time.monotonic() < end and not any(c.tick == tick for c in
                                                     col.get(keys.cmd_vel(3))):
                time.sleep(0.01)
        assert {c.tick for c in col.get(keys.cmd_vel(3))} >= set(range(12))
        time.sleep(0.3)
        st = col.get(keys.status(3))[-1]
        assert st.task_id == 9 and st.task_state == "done" and st.state == "holding"
        col.close()
    finally:
        s.close()
    agent.signal(signal.SIGINT)
    assert agent.wait(15) == 0
    out = agent.output()
    assert "6 invalid messages" in out, out
    assert "not msgpack" in out        # logged once per key, then only counted


def test_agent_reads_run_config_and_rejects_unknown_agent_keys(procs, zargs, tmp_path):
    good = tmp_path / "run.toml"
    good.write_text('name = "t"\nrv = 1.5\n[robots]\nkind = "diffdrive"\nv_max = 0.3\n'
                    '[agent]\ng0 = 0.2\n')
    a = start_agent(procs, zargs, 1, "--run-config", good)
    a.wait_line("READY agent 1 kind=diffdrive", timeout=30)
    a.signal(signal.SIGTERM)
    assert a.wait(15) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text('[agent]\ngains = 3\n')
    b = start_agent(procs, zargs, 2, "--run-config", bad)
    assert b.wait(30) == 2
    assert "bad.toml [agent].gains = 3: unknown field" in b.output()

"""An agent process against the real world process (pymunk, emulated camera) over Zenoh:
hold records a vertex, a test drive takes the robot away, goto brings it back to the
recorded vertex within tolerance; the agent reads its parameters from world/info."""
from __future__ import annotations

import contextlib
import functools
import math
import signal
import threading
import time

import pytest

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import Status, Task, Truth
from procs import LOCKSTEP_ROBOTS_TOML, client_session, decoded_into

pytestmark = pytest.mark.timeout(150)

CONFIG = """
name = "agent_test"
rv = 1.0

[map]
boundary = [[0, 0], [4, 0], [4, 3], [0, 3]]
sources = [{x = 0.5, y = 1.5, theta = 0.0}]

""" + LOCKSTEP_ROBOTS_TOML + """seed = 3
spawn = [
  {robot = 0, pose = [2.0, 1.5, 0.0]},
  {robot = 1, pose = [2.8, 1.5, 0.0]},
  {robot = 2, pose = [1.6, 2.19, 0.0]},
  {robot = 3, pose = [1.6, 0.81, 0.0]},
]

[agent]
arrive_ticks = 8
"""


class Latest:
    def __init__(self, session, key, typ):
        self.msgs = []
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(key, decoded_into(typ, self.msgs, self.lock))

    def all(self):
        with self.lock:
            return list(self.msgs)

    def wait(self, pred, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in reversed(self.all()):
                if pred(m):
                    return m
            time.sleep(0.05)
        raise AssertionError(f"timed out; last: {self.all()[-1:]}")


def send_until(s, keys, status, task, pred, timeout):
    """Put the task (again, idempotently) until a Status satisfies pred."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        s.put(keys.task(0), task.encode())
        try:
            return status.wait(pred, 2.0)
        except AssertionError:
            continue
    raise AssertionError(f"task {task.task_id} never finished: {status.all()[-1:]}")


def _pose0(truth):
    """Robot 0's (x, y, theta) in the latest ground truth."""
    last = truth.all()[-1]
    k = last.ids.index(0)
    return last.x[k], last.y[k], last.theta[k]


@contextlib.contextmanager
def _world_and_agent(procs, zargs, router, cfg, *agent_args, ready="READY agent 0"):
    """The world process on ``cfg``, agent 0 and a client session recording its Status and
    the ground truth: yields (send, status, truth, agent), send = send_until on this
    session. On a clean exit the agent must stop with 0 on SIGINT."""
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    world = procs.swarmcover("world", cfg, *zargs)
    world.wait_line("READY world", timeout=60)
    agent = procs.swarmcover("agent", "--id", 0, *agent_args, *zargs)
    agent.wait_line(ready, timeout=40)
    s = client_session(router, swarm)
    try:
        status = Latest(s, keys.status(0), Status)
        truth = Latest(s, keys.truth, Truth)
        yield functools.partial(send_until, s, keys, status), status, truth, agent
        status.sub.undeclare()
        truth.sub.undeclare()
    finally:
        s.close()
    agent.signal(signal.SIGINT)
    assert agent.wait(15) == 0


def test_agent_returns_to_a_recorded_vertex_in_the_real_world(procs, zargs, router, tmp_path):
    cfg = tmp_path / "run.toml"
    cfg.write_text(CONFIG)
    with _world_and_agent(procs, zargs, router, cfg) as (send, status, truth, agent):
        st = send(Task(task_id=1, robot=0, kind="hold", vertex=0),
                  lambda m: m.task_id == 1 and m.task_state == "done", 30)
        assert sorted(st.nbr_ids) == [1, 2, 3]
        recorded = dict(zip(st.nbr_ids, st.nbr_bearings))
        assert abs(recorded[1]) < math.radians(2)          # the world frame is the body frame
        home = next(p for p in reversed(truth.all()) if 0 in p.ids)
        k = home.ids.index(0)
        home_xy = (home.x[k], home.y[k])

        send(Task(task_id=2, robot=0, kind="test_drive", vertex=0, direction=-2.0,
                  distance=0.3), lambda m: m.task_id == 2 and m.task_state == "done", 40)
        ids = list(recorded)
        st = send(Task(task_id=3, robot=0, kind="goto", vertex=0, landmarks=ids,
                       bearings=[recorded[i] for i in ids], timeout_s=60),
                  lambda m: m.task_id == 3 and m.task_state != "running"
                  and m.state == "holding", 60)
        assert st.task_state == "done", st
        time.sleep(0.5)
        x, y, _ = _pose0(truth)
        err = math.hypot(x - home_xy[0], y - home_xy[1])
        assert err < 0.04, (err, home_xy, (x, y))
    assert "parameters from the world/info config of run 'agent_test'" in agent.output()
    assert "invalid messages" in agent.output()


def _run_once(procs, router, zargs, swarm, cfg_text, tmp_path, garbage: bool):
    """One lockstep run of 150 ticks: returns {tick: (vx, vy, wz)} of robot 0."""
    import random

    from swarmcover.bus.messages import CmdVel, Pose
    keys = Keys(swarm)
    z = ["--connect", router, "--swarm", swarm]
    cfg = tmp_path / f"{swarm}.toml"
    cfg.write_text(cfg_text)
    agent = procs.swarmcover("agent", "--id", 0, "--run-config", cfg, *z)
    agent.wait_line("READY agent 0", timeout=40)
    s = client_session(router, swarm)
    cmds = Latest(s, keys.cmd_vel(0), CmdVel)
    stop = threading.Event()
    try:
        task = Task(task_id=1, robot=0, kind="goto", vertex=0, landmarks=[1, 2, 3],
                    bearings=[0.3, 2.2, -2.0])
        end = time.monotonic() + 20
        while "task 1: goto" not in agent.output() and time.monotonic() < end:
            s.put(keys.task(0), task.encode())
            time.sleep(0.2)
        assert "task 1: goto" in agent.output()

        def junk():
            rng = random.Random(5)
            while not stop.is_set():
                s.put(keys.odom(0), Pose(robot=0, x=rng.uniform(-9, 9), y=rng.uniform(-9, 9),
                                         theta=rng.uniform(-3, 3), source="odom").encode())
                s.put(keys.odom(0), b"\xa5junk")
                time.sleep(0.02)
        th = threading.Thread(target=junk, daemon=True)
        if garbage:
            th.start()
        world = procs.swarmcover("world", cfg, "--max-ticks", 150, *z)
        assert world.wait(90) == 0, world.output()
        stop.set()
        if garbage:
            th.join(5)
        time.sleep(0.3)
        out = {c.tick: (c.vx, c.vy, c.wz) for c in cmds.all() if c.tick >= 0}
        cmds.sub.undeclare()
    finally:
        stop.set()
        s.close()
    agent.signal(signal.SIGTERM)
    assert agent.wait(15) == 0
    return out, agent.output()


def test_pose_telemetry_garbage_or_absent_changes_nothing(procs, zargs, router, tmp_path):
    """Same seed, same lockstep world: one run without any odometry (pose_rate_hz = 0), one
    with the world's odometry plus a stream of garbage poses and undecodable bytes. The
    agent's command streams must be identical, tick for tick."""
    swarm = zargs[zargs.index("--swarm") + 1]
    absent = CONFIG.replace('seed = 3', 'seed = 3\npose_rate_hz = 0')
    present = CONFIG.replace('seed = 3', 'seed = 3\npose_rate_hz = 20')
    a, _ = _run_once(procs, router, zargs, swarm + "a", absent, tmp_path, garbage=False)
    b, out_b = _run_once(procs, router, zargs, swarm + "b", present, tmp_path, garbage=True)
    assert set(range(150)) <= set(a), sorted(a)[:5]
    assert any(v != (0.0, 0.0, 0.0) for v in a.values())
    assert a == b
    assert "dropping invalid message on" in out_b and "/odom" in out_b


def test_diffdrive_agent_returns_with_frame_alignment(procs, zargs, router, tmp_path):
    """A differential-drive body (it rotates): the goto carries ref_offsets (heading of the
    recording frame minus each landmark's heading; the test plays the coordinator and takes
    the headings from ground truth) and the agent aligns frames from mutual bearings."""
    cfg = tmp_path / "dd.toml"
    cfg.write_text(CONFIG.replace("{robot = 0, pose = [2.0, 1.5, 0.0]}",
                                  '{robot = 0, pose = [2.0, 1.5, 0.7], kind = "diffdrive"}'))
    with _world_and_agent(procs, zargs, router, cfg, "--kind", "diffdrive",
                          ready="READY agent 0 kind=diffdrive") as (send, status, truth, _):
        st = send(Task(task_id=1, robot=0, kind="hold", vertex=0),
                  lambda m: m.task_id == 1 and m.task_state == "done", 30)
        recorded = dict(zip(st.nbr_ids, st.nbr_bearings))
        assert sorted(recorded) == [1, 2, 3]
        *home_xy, home_th = _pose0(truth)
        assert abs(home_th - 0.7) < 0.05
        # body-frame direction -0.7 at heading 0.7: world +x, staying within rv of all three
        send(Task(task_id=2, robot=0, kind="test_drive", vertex=0, direction=-0.7,
                  distance=0.2), lambda m: m.task_id == 2 and m.task_state == "done", 40)
        assert abs(_pose0(truth)[2] - home_th) > 0.5          # it turned to drive
        ids = list(recorded)
        st = send(Task(task_id=3, robot=0, kind="goto", vertex=0, landmarks=ids,
                       bearings=[recorded[i] for i in ids],
                       ref_offsets=[home_th - 0.0 for _ in ids], timeout_s=60),
                  lambda m: m.task_id == 3 and m.task_state != "running"
                  and m.state == "holding", 60)
        assert st.task_state == "done", (st.reason, st)
        time.sleep(0.3)
        x, y, _ = _pose0(truth)
        err = math.hypot(x - home_xy[0], y - home_xy[1])
        assert err < 0.05, (err, home_xy, (x, y))


def test_deploy_with_scale_correction_in_the_real_world(procs, zargs, router, tmp_path):
    """Deploy to the assumed-geometry apex of a 0.6 m edge, then scale correction pushes the
    robot out until a link breaks and backs it up until both are back: it ends just inside
    rv of both references."""
    cfg = tmp_path / "deploy.toml"
    spawn = ('spawn = [\n  {robot = 0, pose = [1.2, 1.5, 0.0]},\n'
             '  {robot = 1, pose = [1.0, 1.2, 0.0]},\n  {robot = 2, pose = [1.0, 1.8, 0.0]},\n]')
    text = CONFIG[:CONFIG.index("spawn = [")] + spawn + "\n"
    cfg.write_text(text)
    with _world_and_agent(procs, zargs, router, cfg) as (send, status, truth, _):
        apex = (1.0 + 0.6 * math.sqrt(3) / 2, 1.5)
        bearings = [math.atan2(1.2 - apex[1], 1.0 - apex[0]),
                    math.atan2(1.8 - apex[1], 1.0 - apex[0])]
        task = Task(task_id=1, robot=0, kind="deploy", vertex=9, landmarks=[1, 2],
                    bearings=bearings, scale_correct=True, timeout_s=60)
        st = send(task, lambda m: m.task_id == 1 and m.task_state != "running", 90)
        assert st.task_state == "done", st
        assert any(m.state == "deploying" for m in status.all())
        time.sleep(0.3)
        x, y, _ = _pose0(truth)
        d1 = math.hypot(x - 1.0, y - 1.2)
        d2 = math.hypot(x - 1.0, y - 1.8)
        # out until a link broke (rv), then back 0.12 rv along the bisector: ~ rv - eps
        assert 0.83 < max(d1, d2) < 0.93, (d1, d2)
        assert abs(y - 1.5) < 0.05

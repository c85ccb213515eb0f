"""The world process against a real router: info, spawn/remove, sensing, stale commands,
bad input, twins, and lockstep determinism with a scripted command publisher."""
from __future__ import annotations

import contextlib
import json
import math
import time
import uuid

import pytest
import zenoh

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import (Clock, CmdVel, Pose, Remove, Sense, Spawn, Truth, TwinCmd, WorldInfo,
                          decode)
from swarmcover.bus.session import Mailbox, put
from procs import client_session, decoded
from swarmcover.world.config import loads_config

pytestmark = pytest.mark.timeout(120)

SMALL = """
name = "node_test"
rv = 1.0
[map]
boundary = [[0, 0], [4, 0], [4, 3], [0, 3]]
obstacles = [{{type = "rect", min = [2.0, 1.25], max = [2.5, 1.75]}}]
sources = [{{x = 0.5, y = 1.5, theta = 0.0}}]
[robots]
radius = 0.06
actuation_noise = {act}
[sensing]
noise_deg = {noise}
dropout = {dropout}
[world]
mode = "{mode}"
rtf = {rtf}
seed = {seed}
tick_timeout_s = {timeout}
stale_cmd_s = 0.5
pose_rate_hz = 5
{extra}
"""


def config(tmp_path, name="w.toml", mode="lockstep", rtf=4.0, seed=0, noise=0.0, dropout=0.0,
           act=0.0, timeout=2.0, extra=""):
    p = tmp_path / name
    p.write_text(SMALL.format(mode=mode, rtf=rtf, seed=seed, noise=noise, dropout=dropout,
                              act=act, timeout=timeout, extra=extra))
    return p


def swarm_of(zargs):
    return zargs[zargs.index("--swarm") + 1]


def collect(mail, until, timeout):
    """Decode mailbox items into a list until until(msgs) or timeout; returns msgs."""
    msgs = []
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        item = mail.get(0.05)
        if item is None:
            continue
        key, payload, kind = item
        try:
            msgs.append((key, decode(payload)))
        except Exception:
            continue
        if until(msgs):
            return msgs
    raise AssertionError(f"timed out; last messages: {[m for _, m in msgs[-3:]]}")


def last_truth(msgs):
    t = [m for _, m in msgs if isinstance(m, Truth)]
    return t[-1] if t else None


def test_info_spawn_sense_remove_twins_and_bad_input(procs, router, zargs, tmp_path):
    keys = Keys(swarm_of(zargs))
    s = client_session(router, keys.swarm)
    mail = Mailbox()
    subs = [s.declare_subscriber(k, mail.callback) for k in
            (f"{keys.prefix}/robot/*/sense", f"{keys.prefix}/robot/*/odom", keys.truth,
             keys.clock)]
    try:
        w = procs.swarmcover("world", config(tmp_path), *zargs)
        w.wait_line("READY world", timeout=30)
        replies = [r.ok for r in s.get(keys.world_info, timeout=5.0) if r.ok is not None]
        assert len(replies) == 1
        info = decode(replies[0].payload.to_bytes(), WorldInfo)
        assert info.rv == 1.0 and info.mode == "lockstep" and len(info.boundary) == 8
        assert info.free_area == pytest.approx(11.75) and info.sources[:2] == [0.5, 1.5]
        assert loads_config(info.config).map.sources == ((0.5, 1.5, 0.0),)

        put(s, keys.spawn, Spawn(robot=1, source=0))
        put(s, keys.spawn, Spawn(robot=2, source=0, kind="diffdrive"))
        msgs = collect(mail, lambda ms: any(isinstance(m, Sense) and m.robot == 1 and m.ids
                                            for _, m in ms)
                       and any(isinstance(m, Pose) and m.robot == 2 for _, m in ms)
                       # truth rides its own key: a sense can arrive before the tick's truth
                       and (last_truth(ms) or Truth()).ids == [1, 2], 20)
        sense1 = [m for _, m in msgs if isinstance(m, Sense) and m.robot == 1 and m.ids][-1]
        assert sense1.ids == [2] and len(sense1.back_bearings) == 1
        tr = last_truth(msgs)
        assert tr.ids == [1, 2] and tr.live == [False, False]
        # the second robot was placed beside the occupied source, not on top of it
        d = math.hypot(tr.x[1] - tr.x[0], tr.y[1] - tr.y[0])
        assert 0.12 <= d < 0.5
        assert any(isinstance(m, Clock) and m.mode == "lockstep" for _, m in msgs)

        # bad input: garbage, unknown robot, absurd speed, wrong robot field, bad spawn
        s.put(keys.cmd_vel(1), b"\xc1garbage")
        put(s, keys.cmd_vel(99), CmdVel(robot=99, vx=0.1))
        put(s, keys.cmd_vel(1), CmdVel(robot=1, vx=50.0))
        put(s, keys.cmd_vel(1), CmdVel(robot=2, vx=0.1))
        put(s, keys.spawn, Spawn(robot=3, source=7))
        put(s, keys.spawn, Spawn(robot=1, source=0))
        s.put(keys.spawn, b"")
        # a live twin: driven by TwinCmd (teleport), CmdVel ignored
        put(s, keys.spawn, Spawn(robot=5, source=0, kind="diffdrive", live=True))
        collect(mail, lambda ms: (last_truth(ms) or Truth()).ids == [1, 2, 5], 20)
        put(s, keys.twin_cmd(5), TwinCmd(robot=5, teleport=True, x=3.0, y=2.5, theta=1.0))
        put(s, keys.cmd_vel(5), CmdVel(robot=5, vx=0.3))
        put(s, keys.remove, Remove(robot=2, reason="test"))

        def moved(ms):
            t = last_truth(ms)
            return t is not None and t.ids == [1, 5] and abs(t.x[1] - 3.0) < 1e-9
        msgs = collect(mail, moved, 20)
        t = last_truth(msgs)
        assert t.live == [False, True] and t.theta[1] == pytest.approx(1.0)
        assert w.p.poll() is None                       # still running
        out = w.output()
        for needle in ("unknown robot", "absurd velocity", "robot field differs",
                       "unknown source", "existing robot", "dropping invalid message"):
            assert needle in out, needle
    finally:
        for sub in subs:
            sub.undeclare()
        s.close()


def test_stale_command_stops_the_robot(procs, router, zargs, tmp_path):
    keys = Keys(swarm_of(zargs))
    s = client_session(router, keys.swarm)
    mail = Mailbox()
    sub = s.declare_subscriber(keys.truth, mail.callback)
    try:
        cfg = config(tmp_path, mode="realtime", rtf=2.0,
                     extra="spawn = [{robot = 1, pose = [1.0, 2.5]}]")
        w = procs.swarmcover("world", cfg, *zargs)
        w.wait_line("READY world", timeout=30)
        collect(mail, lambda ms: last_truth(ms) is not None, 10)
        put(s, keys.cmd_vel(1), CmdVel(robot=1, tick=-1, vx=0.4))   # once, never repeated
        t0 = None

        def enough(ms):
            nonlocal t0
            t = last_truth(ms)
            if t is None or not t.ids:
                return False
            if t0 is None and abs(t.x[0] - 1.0) > 1e-6:
                t0 = t.t
            return t0 is not None and t.t > t0 + 2.0
        msgs = collect(mail, enough, 30)
        xs = [(m.t, m.x[0]) for _, m in msgs if isinstance(m, Truth) and m.ids]
        final = xs[-1][1]
        # moved for stale_cmd_s = 0.5 sim s at 0.4 m/s (+- a tick), then stood still
        assert 0.15 <= final - 1.0 <= 0.25
        late = [x for t, x in xs if t > t0 + 1.0]
        assert late and max(late) - min(late) < 1e-9
    finally:
        sub.undeclare()
        s.close()


@contextlib.contextmanager
def _world_waiting_for_robot_1(procs, router, zargs, tmp_path, timeout: float, ticks: int):
    """A lockstep world of ``ticks`` ticks that spawns robot 1, whose agent is present but
    silent (only its liveliness token, from this test's session). Yields (world, truth
    output path, leave): leave() withdraws the token (once)."""
    keys = Keys(swarm_of(zargs))
    s = client_session(router, keys.swarm)
    token = s.liveliness().declare_token(keys.alive("robot", 1))
    left = []

    def leave():
        if not left:
            left.append(True)
            token.undeclare()
    try:
        out = tmp_path / "truth.json"
        cfg = config(tmp_path, timeout=timeout, extra="spawn = [{robot = 1}]")
        w = procs.swarmcover("world", cfg, *zargs, "--max-ticks", ticks, "--truth-out", out)
        yield w, out, leave
    finally:
        leave()
        s.close()


def test_a_silent_agent_delays_ticks_but_never_stalls(procs, router, zargs, tmp_path):
    with _world_waiting_for_robot_1(procs, router, zargs, tmp_path, 0.3, 4) as (w, out, _):
        t0 = time.monotonic()
        assert w.wait(timeout=40) == 0
        assert time.monotonic() - t0 >= 4 * 0.3
        summary = json.loads(out.read_text())["summary"]
        # every tick waited the timeout for the silent agent and then went on (the first
        # one only if the token was already in the world's start-up snapshot: under load
        # it can arrive a tick late)
        assert summary["ticks"] == 4 and summary["late"] >= 3


def scripted_run(procs, router, tmp_path, tag: str) -> dict:
    """One lockstep run: 3 robots whose agents answer every Sense with a command computed
    from it; returns the truth log."""
    swarm = "det" + uuid.uuid4().hex[:8]
    keys = Keys(swarm)
    s = client_session(router, swarm)
    mail = Mailbox()
    sub = s.declare_subscriber(f"{keys.prefix}/robot/*/sense", mail.callback)
    tokens = [s.liveliness().declare_token(keys.alive("robot", r)) for r in (1, 2, 3)]
    pubs = {r: s.declare_publisher(keys.cmd_vel(r),
                                   congestion_control=zenoh.CongestionControl.BLOCK)
            for r in (1, 2, 3)}
    out = tmp_path / f"truth_{tag}.json"
    try:
        cfg = config(tmp_path, name=f"det_{tag}.toml", seed=7, noise=2.0, dropout=0.1,
                     act=0.05, extra='spawn = [{robot = 1}, {robot = 2, kind = "diffdrive"}, '
                                        '{robot = 3}]')
        w = procs.swarmcover("world", cfg, "--connect", router, "--swarm", swarm,
                             "--max-ticks", 60, "--truth-out", out)
        end = time.monotonic() + 60
        answered = 0
        while w.p.poll() is None and time.monotonic() < end:
            item = mail.get(0.05)
            if item is None:
                continue
            m = decode(item[1], Sense)
            f = sum(m.bearings) + 0.1 * m.tick + m.robot + 0.5 * len(m.touch)
            vx, vy, wz = 0.3 * math.cos(f), 0.3 * math.sin(f), 0.0
            if m.robot == 2:
                vx, vy, wz = 0.25, 0.0, 1.5 * math.sin(f)
            pubs[m.robot].put(CmdVel(robot=m.robot, tick=m.tick, vx=vx, vy=vy, wz=wz).encode())
            answered += 1
        assert w.wait(timeout=10) == 0, w.output()
        assert answered >= 3 * 60
        return json.loads(out.read_text())
    finally:
        sub.undeclare()
        for t in tokens:
            t.undeclare()
        for p in pubs.values():
            p.undeclare()
        s.close()


def test_lockstep_same_seed_same_trajectories(procs, router, tmp_path):
    a = scripted_run(procs, router, tmp_path, "a")
    b = scripted_run(procs, router, tmp_path, "b")
    assert a["summary"]["late"] == 0 and b["summary"]["late"] == 0
    assert len(a["ticks"]) == 61 and a["ticks"] == b["ticks"]     # bit for bit
    first, last = a["ticks"][0], a["ticks"][-1]
    assert last["ids"] == [1, 2, 3]
    moved = [math.hypot(last["x"][k] - first["x"][k], last["y"][k] - first["y"][k])
             for k in range(3)]
    assert min(moved) > 0.1
    assert last["theta"][1] != 0.0 and last["theta"][0] == 0.0    # only the diffdrive turns


def test_bad_config_exits_2_naming_the_field(procs, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[map]\nboundary = [[0, 0], [4, 0], [4, 3], [0, 3]]\n[world]\nmode = "warp"\n')
    w = procs.swarmcover("world", bad, "--connect", "tcp/127.0.0.1:9")
    assert w.wait(timeout=30) == 2
    assert f"{bad}: [world] mode = 'warp'" in w.output()


def test_an_agent_that_leaves_is_no_longer_waited_for(procs, router, zargs, tmp_path):
    with _world_waiting_for_robot_1(procs, router, zargs, tmp_path, 20.0, 8) as (w, out, leave):
        w.wait_line("READY world", timeout=30)
        time.sleep(0.3)
        assert w.p.poll() is None                 # tick 0 waits for agent 1
        leave()
        t0 = time.monotonic()
        assert w.wait(timeout=15) == 0
        assert time.monotonic() - t0 < 10         # far less than one 20 s timeout
        summary = json.loads(out.read_text())["summary"]
        assert summary["ticks"] == 8 and summary["late"] == 0


def test_lockstep_barrier_with_a_coordinator(procs, router, zargs, tmp_path):
    """This test plays the coordinator and robot 0's agent. The world holds tick 0 until a
    coordinator is present, never runs tick k+1 before the coordinator acked tick k, applies
    an acked spawn at the next boundary, gives the new body its first Sense (with the acked
    task's id) JOIN_TICKS later and waits for its agent there, then announces the agent and
    its status seq in the next Clock."""
    from swarmcover.bus.messages import CoordAck
    from swarmcover.world.node import join_ticks
    keys = Keys(swarm_of(zargs))
    s = client_session(router, keys.swarm)
    mail = Mailbox()
    subs = [s.declare_subscriber(k, mail.callback) for k in
            (keys.clock, keys.sense(0), keys.truth)]
    token = agent_token = None
    try:
        w = procs.swarmcover("world", config(tmp_path, rtf=50.0), "--await-coordinator", 30,
                             *zargs)
        w.wait_line("READY world", timeout=30)
        time.sleep(1.0)   # held at tick 0: nothing beyond it
        seen = collect(mail, lambda ms: any(isinstance(m, Clock) for _, m in ms), 10)
        assert {m.tick for _, m in seen if isinstance(m, (Clock, Truth))} == {0}
        token = s.liveliness().declare_token(keys.alive("coordinator", "main"))
        join = join_ticks(0.05)
        spawn_tick, acked, clocks, senses, truths = 2, set(), {}, [], {}
        held = False
        for m in decoded(mail, 60):
            if isinstance(m, Truth):
                truths[m.tick] = m.ids
            elif isinstance(m, Sense):
                senses.append(m)
                put(s, keys.cmd_vel(0), CmdVel(robot=0, tick=m.tick, status_seq=1))
            elif isinstance(m, Clock) and m.tick not in acked:
                clocks[m.tick] = m
                assert max(clocks) <= max(acked, default=-1) + 1, "ran ahead of the ack"
                if m.tick == 5 and not held:
                    held = True     # a slow coordinator: the world must wait for it
                    time.sleep(1.0)
                    waiting = [decode(x[1]) for x in list(mail.q.queue)]
                    # only re-sends of tick 5's clock (our ack might have been lost)
                    assert {c.tick for c in waiting if isinstance(c, Clock)} <= {5}
                ack = CoordAck(tick=m.tick)
                if m.tick == spawn_tick:
                    ack = CoordAck(tick=m.tick, task_robots=[0], task_ids=[77], spawn_ids=[0],
                                   spawn_sources=[0], spawn_live=[False], spawn_kinds=[0])
                    agent_token = s.liveliness().declare_token(keys.alive("robot", 0))
                acked.add(m.tick)
                put(s, keys.coord_ack, ack)
                if m.tick >= spawn_tick + 1 + join + 3:
                    break
        assert 0 not in truths.get(spawn_tick, [0]) and 0 in truths[spawn_tick + 1]
        first = spawn_tick + 1 + join
        assert senses and senses[0].tick == first and senses[0].task_id == 77
        assert clocks[first].agents == [] and clocks[first + 1].agents == [0]
        assert clocks[first + 1].status_seqs == [1]
        assert clocks[0].mode == "lockstep"
    finally:
        for x in subs + [t for t in (token, agent_token) if t is not None]:
            x.undeclare()
        s.close()

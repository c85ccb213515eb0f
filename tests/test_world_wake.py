"""Idle robots (world/wake.py): a robot that holds still is sensed only when what it would
sense changed (or when asked, or at the keep-alive), so it costs (almost) nothing.

The property test is the rule's claim checked against the emulated camera itself: over
random swarms in a room with an obstacle, where a few robots wander (at most v_max) and the
rest hold still, a robot the rule skips always has the same noiseless view (the same
neighbours, the same bearings, the same touch sectors) as on the last tick it was sensed.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcover.world.maps import map_from_path
from swarmcover.world.sensing import Sensors
from swarmcover.world.wake import WakeRule, wake_params

RV, R, V, DT = 1.0, 0.06, 0.5, 0.05


@pytest.fixture(scope="module")
def small():
    return map_from_path("configs/small.toml")[1]   # 4 x 3 m, obstacle [2,2.5]x[1.25,1.75]


def rule(**kw):
    p = wake_params(RV, V, DT, 1, keepalive_s=kw.pop("keepalive_s", 1e6),
                    wake_s=kw.pop("wake_s", 0.25))
    return WakeRule(**p)


def test_params_follow_the_run():
    p = wake_params(1.0, 0.5, 0.05, 1, keepalive_s=2.0, wake_s=0.5)
    assert p["reach"] == pytest.approx(1.05)          # rv + 2 v_max dt
    assert p["wake_ticks"] == 10 and p["keepalive_ticks"] == 40
    p = wake_params(1.0, 0.5, 0.05, 2, keepalive_s=2.0, wake_s=0.5)   # 10 Hz sensing
    assert p["wake_ticks"] == 5 and p["keepalive_ticks"] == 20


def test_idle_robots_far_from_motion_are_skipped_and_near_ones_woken():
    w = rule()
    ids = [1, 2, 3, 4]
    pos = np.array([[0.0, 0.0], [0.8, 0.0], [5.0, 0.0], [9.0, 0.0]])
    th = np.zeros(4)
    idle = {1, 2, 3, 4}
    first = w.due(0, ids, pos, th, idle, set())
    assert first.all()                      # new bodies count as moved: everyone, once
    for k in range(1, 8):
        due = w.due(k, ids, pos, th, idle, set())
    assert not due.any()                    # still for longer than wake_s: nobody
    pos = pos.copy()
    pos[0, 0] += 0.01                       # robot 1 moves
    due = w.due(8, ids, pos, th, idle, set())
    assert due.tolist() == [True, True, False, False]    # itself and robot 2 (0.8 m away)
    for k in range(9, 9 + w.wake_ticks):    # still awake for wake_ticks after it stopped
        assert w.due(k, ids, pos, th, idle, set()).tolist() == [True, True, False, False]
    assert not w.due(9 + w.wake_ticks, ids, pos, th, idle, set()).any()


def test_not_idle_told_and_keepalive_are_always_sensed():
    w = rule(keepalive_s=0.2)                  # every 4 sensing ticks
    ids = [0, 1, 2, 3]
    pos = np.array([[0.0, 0.0], [3.0, 0.0], [6.0, 0.0], [9.0, 0.0]])
    th = np.zeros(4)
    w.due(0, ids, pos, th, set(ids), set())
    seen = {i: [] for i in ids}
    for k in range(1, 41):
        due = w.due(k, ids, pos, th, {1, 2, 3}, {2} if k == 20 else set())
        for i, d in zip(ids, due):
            if d:
                seen[i].append(k)
    tail = list(range(1, w.wake_ticks + 1))   # every body is new at tick 0: it "moved"
    assert seen[0] == list(range(1, 41))                                # not idle
    alive1 = [k for k in range(1, 41) if (k + 1) % 4 == 0]              # keep-alive, staggered
    assert seen[1] == sorted(set(tail) | set(alive1))
    assert seen[2] == sorted(set(tail) | {20} | {k for k in range(1, 41) if (k + 2) % 4 == 0})
    assert seen[3] == sorted(set(tail) | {k for k in range(1, 41) if (k + 3) % 4 == 0})


def test_a_removed_body_wakes_the_robots_that_saw_it():
    w = rule()
    pos = np.array([[0.0, 0.0], [0.7, 0.0], [4.0, 0.0]])
    for k in range(10):
        w.due(k, [1, 2, 3], pos, np.zeros(3), {1, 2, 3}, set())
    due = w.due(10, [1, 3], pos[[0, 2]], np.zeros(2), {1, 3}, set())   # robot 2 removed
    assert due.tolist() == [True, False]


def test_a_pushed_robot_is_sensed_on_the_tick_it_moved():
    w = rule()
    pos = np.array([[0.0, 0.0], [3.0, 0.0]])
    th = np.zeros(2)
    for k in range(10):
        w.due(k, [1, 2], pos, th, {1, 2}, set())
    pushed = pos.copy()
    pushed[1] += (0.0, 0.002)
    assert w.due(10, [1, 2], pushed, th, {1, 2}, set()).tolist() == [False, True]
    turned = pushed.copy()
    assert w.due(11, [1, 2], turned, np.array([0.0, 0.01]), {1, 2}, set()).tolist() == \
        [False, True]


def _view(batch, k, ids):
    r = batch.robot(k)
    order = np.argsort(np.asarray(ids)[r["tgt"]])
    return (tuple(np.asarray(ids)[r["tgt"]][order].tolist()),
            np.asarray(r["bearings"])[order], tuple(sorted(r["touch"].tolist())))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 40), movers=st.integers(1, 4))
def test_a_skipped_robot_never_missed_a_change_of_its_view(small, seed, n, movers):
    _skips(small, seed, n, movers)


def test_the_wake_rule_does_skip_idle_robots(small):
    """The property above holds trivially if nobody is ever skipped: in a swarm of 40 with
    one mover, most robots are far from it and are skipped. (Whether a random swarm has
    robots out of every mover's reach is chance: seed 4186, 9 robots, 2 movers has none.)"""
    assert _skips(small, 0, 40, 1) > 100


def _skips(small, seed, n, movers) -> int:
    """Robots that move at random among still ones, sensed 60 ticks: every robot the wake
    rule skips has the same view as when it was last sensed. Returns the skips."""
    rng = np.random.default_rng(seed)
    free = []
    while len(free) < n:   # free spots, clear of walls and the obstacle, not overlapping
        p = rng.uniform([0.15, 0.15], [3.85, 2.85])
        if small.is_free(p[None], R + 0.02)[0] and all(
                math.dist(p, q) > 2 * R + 0.01 for q in free):
            free.append(p)
    pos = np.array(free)
    th = rng.uniform(-math.pi, math.pi, n)
    ids = list(range(100, 100 + n))
    moving = set(rng.choice(n, size=min(movers, n), replace=False).tolist())
    cam = Sensors(small, RV, radius=R, noise_sigma=0.0)
    w = WakeRule(**wake_params(RV, V, DT, 1, keepalive_s=1e6, wake_s=0.1))
    last: dict[int, tuple] = {}
    idle = {ids[k] for k in range(n) if k not in moving}
    skipped = 0
    for tick in range(60):
        if tick:
            for k in moving:      # a random walk at up to v_max, kept in the free space
                if rng.random() < 0.3:
                    continue      # movers pause sometimes: their neighbours' tails end
                step = rng.normal(0.0, 1.0, 2)
                step *= V * DT / max(np.linalg.norm(step), 1e-9) * rng.uniform(0.2, 1.0)
                q = pos[k] + step
                if small.is_free(q[None], R + 0.02)[0]:
                    pos[k] = q
                th[k] = th[k] + rng.normal(0.0, 0.05)
        batch = cam.sense(pos, th)
        due = w.due(tick, ids, pos, th, idle, set())
        for k, rid in enumerate(ids):
            view = _view(batch, k, ids)
            if due[k]:
                last[rid] = view
                continue
            skipped += 1
            old = last[rid]
            assert view[0] == old[0], f"robot {rid} skipped at tick {tick}: neighbours changed"
            assert np.allclose(view[1], old[1], atol=1e-12), \
                f"robot {rid} skipped at tick {tick}: bearings changed"
            assert view[2] == old[2], f"robot {rid} skipped at tick {tick}: touch changed"
    return skipped


# ---------------------------------------------------------------- the world process

ROOM = {
    "name": "idle_test", "rv": 1.0,
    "map": {"boundary": [[0, 0], [4, 0], [4, 3], [0, 3]],
            "sources": [{"x": 0.5, "y": 1.5, "theta": 0.0}]},
    "robots": {"radius": 0.06},
    "sensing": {"noise_deg": 0.5, "idle_keepalive_s": 1.0, "idle_wake_s": 0.5},
    "world": {"mode": "lockstep", "seed": 0,
              "spawn": [{"robot": 1, "pose": [1.0, 0.5, 0.0]},                # idle, agent
                        {"robot": 2, "live": True, "pose": [3.0, 0.5, 3.14159]}]},   # pusher
}


@pytest.mark.timeout(120)
def test_an_idle_agent_gets_no_20hz_sense_yet_is_sensed_the_tick_it_is_pushed(
        procs, router, zargs, tmp_path):
    """A real world and a real agent (robot 1, no task: idle); the test plays the
    coordinator (acking every tick, so lockstep has it in the barrier) and drives robot 2, a
    live twin, into robot 1. While nothing moves, robot 1 gets a Sense only at the keep-alive
    (1 s); from the tick robot 2 comes within rv on, and on every tick robot 1 itself is
    pushed, it gets one."""
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import Clock, CoordAck, Sense, Truth, TwinCmd
    from swarmcover.bus.session import Mailbox, put
    from swarmcover.ground.toml import dumps_toml
    from procs import client_session, decoded
    conf = tmp_path / "room.toml"
    conf.write_text(dumps_toml(ROOM))
    keys = Keys(zargs[zargs.index("--swarm") + 1])
    s = client_session(router, keys.swarm)
    mail = Mailbox()
    subs = [s.declare_subscriber(k, mail.callback) for k in (keys.clock, keys.sense(1),
                                                              keys.truth)]
    token = None
    try:
        a = procs.swarmcover("agent", "--id", "1", "--run-config", str(conf), *zargs)
        a.wait_line("READY agent", timeout=30)
        w = procs.swarmcover("world", str(conf), "--await-coordinator", 30, *zargs)
        w.wait_line("READY world", timeout=30)
        token = s.liveliness().declare_token(keys.alive("coordinator", "main"))
        sensed: set[int] = set()
        truth: dict[int, dict] = {}
        drive_from, end_tick = 100, None
        for m in decoded(mail, 90):
            if isinstance(m, Sense):
                sensed.add(m.tick)
            elif isinstance(m, Truth):
                truth[m.tick] = {i: (x, y) for i, x, y in zip(m.ids, m.x, m.y)}
            elif isinstance(m, Clock):
                if m.tick >= drive_from and (end_tick is None or m.tick < end_tick):
                    put(s, keys.twin_cmd(2), TwinCmd(robot=2, vx=-0.4, vy=0.0, wz=0.0))
                put(s, keys.coord_ack, CoordAck(tick=m.tick))
                moved1 = [k for k in truth if k - 1 in truth and 1 in truth[k]
                          and math.dist(truth[k][1], truth[k - 1][1]) > 1e-6]
                if end_tick is None and moved1:
                    end_tick = min(moved1) + 20          # pushed: go on a little
                if end_tick is not None and m.tick >= end_tick + 15:
                    break
        assert end_tick is not None, "robot 2 never pushed robot 1"
        quiet = [k for k in range(30, drive_from) if k in sensed]
        assert len(quiet) <= 5, f"an idle robot sensed at {quiet} (keep-alive is 1 s)"
        assert len(quiet) >= 2, "the keep-alive never came"
        near = [k for k in truth if k - 1 in truth and k >= drive_from
                and math.dist(truth[k][2], truth[k][1]) < 1.0
                and math.dist(truth[k][2], truth[k - 1][2]) > 1e-6]
        pushed = [k for k in truth if k - 1 in truth
                  and math.dist(truth[k][1], truth[k - 1][1]) > 1e-6]
        assert near and pushed
        assert not [k for k in near if k not in sensed], "robot 2 moved in view, unsensed"
        assert not [k for k in pushed if k not in sensed], "robot 1 pushed, unsensed"
    finally:
        for x in subs + ([token] if token is not None else []):
            x.undeclare()
        s.close()

"""Distributed lockstep is repeatable: the same config and seed give the same run, twice over
real processes and Zenoh, and the same as the in-process loop (swarmcover.simloop), because
the coordinator decides at tick boundaries on the statuses of the tick (coordinator/node.py,
world/node.py), never on wall-clock arrival order. A forged clock jump changes nothing."""
from __future__ import annotations

import json
import time
from pathlib import Path

import msgpack
import pytest

from swarmcover.bus.messages import Clock, CmdVel, Sense, Status, decode
from swarmcover.coordinator.node import ClockTrust, TickSync
from procs import client_session, free_port, wait_cycle

KEYS = ("robots_used", "robots_spawned", "cycles", "sim_time_s", "coverage", "mean_spacing")


def _run(procs, out: Path, config: str, seed: int, port: int):
    return procs.swarmcover("run", config, "--seed", seed, "--out", str(out), "--quiet",
                            "--port", port, "--swarm", "det")


def _summary(out: Path) -> dict:
    s = json.loads((out / "summary.json").read_text())
    return {k: s[k] for k in KEYS} | {"certified": s["certified"]}


def _inproc(config: str, seed: int) -> dict:
    from swarmcover.run import compute_summary
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    cfg = load_config(config)
    sim = SimLoop(cfg, seed=seed)
    res = sim.run(max_sim_s=4000, max_wall_s=400)
    ids = sorted(res.positions)
    truth = type("T", (), dict(ids=ids, x=[res.positions[i][0] for i in ids],
                               y=[res.positions[i][1] for i in ids]))
    s = compute_summary(cfg, sim.wm, truth, res.final,
                        dict(certified=res.certified, cycles=res.cycles,
                             sim_time_s=res.sim_time_s, robots_spawned=res.robots_spawned))
    return {k: s[k] for k in KEYS} | {"certified": s["certified"]}


def _same(a: dict, b: dict) -> bool:
    return all(a[k] == pytest.approx(b[k], abs=1e-9) for k in a)


# ------------------------------------------------------------------ pure parts

def test_clock_trust_ignores_forged_jumps_and_follows_the_world():
    trust = ClockTrust(0.05)
    assert trust.check(Clock(tick=0, t=0.0), 0.0) == "new"
    assert trust.check(Clock(tick=1, t=0.05), 0.01) == "new"
    assert trust.check(Clock(tick=1, t=0.05), 0.02) == "same"          # a re-sent clock
    assert trust.check(Clock(tick=0, t=1e8), 0.03) == "bad"            # t is not tick * dt
    assert trust.check(Clock(tick=2_000_000_000, t=1e8), 0.04) == "bad"  # implausible step
    assert trust.check(Clock(tick=0, t=0.0), 0.05) == "bad"            # backwards
    assert trust.check(Clock(tick=2, t=0.1), 0.06) == "new" and trust.tick == 2
    assert trust.rejected == 3
    # a forged first clock is outvoted by a live world's consistent ticks
    trust = ClockTrust(0.05, rebase_after=5)
    assert trust.check(Clock(tick=2_000_000_000, t=1e8), 0.0) == "new"
    verdicts = [trust.check(Clock(tick=k, t=k * 0.05), 0.01 * k) for k in range(1, 6)]
    assert verdicts == ["bad"] * 4 + ["new"] and trust.tick == 5


def test_tick_sync_hands_over_exactly_the_announced_statuses_in_order():
    sync = TickSync()
    first = Clock(tick=0, agents=[], status_seqs=[])
    assert sync.missing(first) == [] and sync.take(first) == ([], [], [])
    # statuses arrive in any order across robots; one of robot 2 already answers tick 1
    for rid, seq in ((2, 1), (1, 1), (2, 2), (1, 2), (2, 3)):
        sync.add_status(Status(robot=rid, seq=seq))
    clk = Clock(tick=1, agents=[1, 2, 5], status_seqs=[2, 2, 1])
    assert sync.missing(clk) == [5]               # robot 5's status is still in flight
    sync.add_status(Status(robot=5, seq=1))
    assert sync.missing(clk) == []
    left, joined, sts = sync.take(clk)
    assert left == [] and joined == [1, 2, 5]
    assert [(s.robot, s.seq) for s in sts] == [(1, 1), (1, 2), (2, 1), (2, 2), (5, 1)]
    left, joined, sts = sync.take(Clock(tick=2, agents=[2], status_seqs=[3]))
    assert left == [1, 5] and joined == [] and [(s.robot, s.seq) for s in sts] == [(2, 3)]
    # a live robot is in no roster (it moves in real time): its statuses and liveliness
    # changes are handed over at the next boundary as they came
    sync.add_status(Status(robot=9, seq=4, live=True))
    sync.add_alive(9, True)
    sync.add_alive(7, True)                       # a virtual robot's token: the roster rules
    left, joined, sts = sync.take(Clock(tick=3, agents=[2], status_seqs=[3]))
    assert left == [] and joined == [9] and [(s.robot, s.seq) for s in sts] == [(9, 4)]


def test_new_fields_are_optional_on_the_wire():
    """Senders that predate the lockstep fields still decode (their defaults)."""
    for msg, field, default in ((Status(robot=1), "tick", -1), (CmdVel(robot=1), "status_seq", -1),
                                (Sense(robot=1), "task_id", -1), (Clock(tick=3), "agents", [])):
        d = msgpack.unpackb(msg.encode())
        del d[field]
        assert getattr(decode(msgpack.packb(d)), field) == default


# ------------------------------------------------------------------ real processes

@pytest.mark.timeout(600)
def test_tiny_twice_distributed_with_a_forged_clock_and_in_process_agree(procs, tmp_path):
    """Two lockstep runs of tiny at once (they load each other's CPU: timing differs), one
    of them sent forged clocks; then the in-process loop. All four numbers agree."""
    a, b = tmp_path / "a", tmp_path / "b"
    port_b = free_port()
    pa = _run(procs, a, "configs/tiny.toml", 0, free_port())
    pb = _run(procs, b, "configs/tiny.toml", 0, port_b)
    wait_cycle(b, 2, 240)
    s = client_session(f"tcp/127.0.0.1:{port_b}", "det")
    try:
        pub = s.declare_publisher("sc/det/world/clock")
        for forged in (Clock(t=1e8), Clock(tick=2_000_000_000, t=1e8, mode="lockstep"),
                       Clock(tick=10, t=1e8, mode="lockstep")):
            pub.put(forged.encode())
        time.sleep(0.5)
        pub.undeclare()
    finally:
        s.close()
    assert pa.wait(500) == 0, pa.output()[-3000:]
    assert pb.wait(500) == 0, pb.output()[-3000:]
    sa, sb = _summary(a), _summary(b)
    assert sa["certified"] and sa["coverage"] >= 0.99
    assert _same(sa, sb), (sa, sb)
    log = (b / "logs" / "coordinator.log").read_text()
    assert "ignoring a clock" in log and "ignored 3 implausible clocks" in log
    assert "not repeatable" not in log + (b / "logs" / "world.log").read_text()
    si = _inproc("configs/tiny.toml", 0)
    assert _same(sa, si), (sa, si)


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_small_twice_distributed_agree(procs, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    pa = _run(procs, a, "configs/small.toml", 0, free_port())
    pb = _run(procs, b, "configs/small.toml", 0, free_port())
    assert pa.wait(850) == 0, pa.output()[-3000:]
    assert pb.wait(850) == 0, pb.output()[-3000:]
    sa, sb = _summary(a), _summary(b)
    assert sa["certified"] and _same(sa, sb), (sa, sb)

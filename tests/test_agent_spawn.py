"""``swarmcover spawn`` and agents.supervisor: processes are started, reported, forwarded
signals, and never left behind (interrupt, a dying child, --all-or-nothing, SIGKILL)."""
from __future__ import annotations

import os
import re
import signal
import time

import pytest

from swarmcover.bus.keys import Keys
from procs import client_session

pytestmark = pytest.mark.timeout(120)


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return ") Z " not in f.read()
    except OSError:
        return False


def wait_gone(pids, timeout=15.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if not any(alive(p) for p in pids):
            return True
        time.sleep(0.1)
    return False


def child_pids(proc, n):
    pids = {}
    end = time.monotonic() + 30
    while len(pids) < n and time.monotonic() < end:
        for line in proc.output().splitlines():
            m = re.match(r"agent (\d+) pid (\d+)$", line)
            if m:
                pids[int(m.group(1))] = int(m.group(2))
        time.sleep(0.05)
    assert len(pids) == n, proc.output()
    return pids


def wait_ready_agents(proc, ids, timeout=45):
    for i in ids:
        proc.wait_line(f"READY agent {i} ", timeout=timeout)


def test_spawn_reports_a_dead_child_keeps_others_and_stops_all_on_sigint(procs, zargs, router):
    sp = procs.swarmcover("spawn", "3", "--first-id", "5", "--info-timeout", "0", *zargs)
    sp.wait_line("READY spawn 3", timeout=30)
    pids = child_pids(sp, 3)
    assert sorted(pids) == [5, 6, 7]
    wait_ready_agents(sp, [5, 6, 7])
    swarm = zargs[zargs.index("--swarm") + 1]
    s = client_session(router, swarm)
    try:
        tokens = set()
        end = time.monotonic() + 10
        while tokens != {5, 6, 7} and time.monotonic() < end:
            tokens = {Keys(swarm).robot_id(str(r.ok.key_expr))
                      for r in s.liveliness().get(Keys(swarm).alive_robots(), timeout=2.0)
                      if r.ok is not None}
        assert tokens == {5, 6, 7}
    finally:
        s.close()
    os.kill(pids[6], signal.SIGKILL)
    sp.wait_line("EXITED agent 6 rc -9", timeout=10)
    time.sleep(0.5)
    assert alive(pids[5]) and alive(pids[7]) and sp.p.poll() is None
    sp.signal(signal.SIGINT)
    assert sp.wait(20) == 0
    assert wait_gone(pids.values())


def test_spawn_all_or_nothing_stops_everyone(procs, zargs):
    sp = procs.swarmcover("spawn", "2", "--all-or-nothing", "--info-timeout", "0", *zargs)
    sp.wait_line("READY spawn 2", timeout=30)
    pids = child_pids(sp, 2)
    wait_ready_agents(sp, [0, 1])
    os.kill(pids[0], signal.SIGTERM)
    assert sp.wait(20) == 1
    assert "EXITED agent 0 rc 0" in sp.output()
    assert wait_gone(pids.values())


def test_agents_exit_when_spawn_is_killed_outright(procs, zargs):
    sp = procs.swarmcover("spawn", "2", "--info-timeout", "0", *zargs)
    sp.wait_line("READY spawn 2", timeout=30)
    pids = child_pids(sp, 2)
    wait_ready_agents(sp, [0, 1])
    os.kill(sp.pid, signal.SIGKILL)       # the supervisor only, not its process group
    sp.wait(10)
    assert wait_gone(pids.values(), timeout=15), "agents outlived their supervisor"


def test_spawn_rejects_an_explicit_id(procs):
    sp = procs.swarmcover("spawn", "2", "--id", "3")
    assert sp.wait(30) == 2
    assert "--id" in sp.output()


def test_supervisor_start_poll_stop(zargs):
    from swarmcover.agents.supervisor import Supervisor
    import subprocess
    with Supervisor(["--info-timeout", "0", *zargs]) as sup:
        pid = sup.start(4, stdout=subprocess.PIPE)
        with pytest.raises(ValueError, match="robot 4"):
            sup.start(4)
        assert sup.running() == {4: pid}
        assert sup.children[4].proc.stdout.readline().startswith(b"READY agent 4")
        assert sup.poll() == []
        assert sup.stop(4, timeout=15) == 0
        sup.start(8, stdout=open(os.devnull, "w"))
    assert sup.running() == {} and not sup.children


def test_a_second_agent_with_a_taken_id_is_refused_naming_the_id(procs, zargs):
    """Issue 18: ids are unique by refusal. A second agent with a held id exits 2 at once,
    naming the id and the swarm; the first keeps running."""
    first = procs.swarmcover("agent", "--id", "4", "--info-timeout", "0", *zargs)
    first.wait_line("READY agent 4 ", timeout=45)
    t0 = time.monotonic()
    second = procs.swarmcover("agent", "--id", "4", "--info-timeout", "0", *zargs)
    rc = second.wait(30)
    assert rc == 2, second.output()
    assert time.monotonic() - t0 < 20
    out = second.output()
    assert "robot id 4 is taken" in out and zargs[zargs.index("--swarm") + 1] in out, out
    assert "Traceback" not in out
    assert first.p.poll() is None


def test_an_agent_without_a_body_is_available_until_its_first_sense(procs, zargs, router):
    """An agent started by hand holds avail/robot/<id> (and alive/robot/<id>) while it has
    no body, so a coordinator can place it; a world's Sense for it ends availability."""
    from swarmcover.bus.messages import Sense
    swarm = zargs[zargs.index("--swarm") + 1]
    keys = Keys(swarm)
    a = procs.swarmcover("agent", "--id", "11", "--info-timeout", "0", *zargs)
    a.wait_line("READY agent 11 ", timeout=45)
    s = client_session(router, swarm)
    try:
        def held(key):
            return any(r.ok is not None for r in s.liveliness().get(key, timeout=2.0))
        assert held(keys.avail(11)) and held(keys.alive("robot", 11))
        s.put(keys.sense(11), Sense(robot=11, tick=1, t=0.05).encode())
        end = time.monotonic() + 10
        while time.monotonic() < end and held(keys.avail(11)):
            time.sleep(0.1)
        assert not held(keys.avail(11)), "still available after its first Sense"
        assert held(keys.alive("robot", 11))
    finally:
        s.close()

"""The ``swarmcover agent`` process over a real Zenoh router, with this test as its world: it
rejects malformed messages without crashing (and counts them), answers every Sense tick once
(a re-sent tick is answered again without stepping), reads its parameters, and maps no
heavy library (numpy, scipy, pymunk, matplotlib, PIL) while it runs. The runs
against the real world process are in test_agent_world.py."""
from __future__ import annotations

import signal
import threading
import time

import pytest

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import CmdVel, Sense, Status, Task, decode
from procs import client_session, decoded_into

pytestmark = pytest.mark.timeout(120)


class Collector:
    """Records decoded messages per key from a client session (callbacks only append)."""

    def __init__(self, session, keys_and_types):
        self.msgs: dict[str, list] = {k: [] for k, _ in keys_and_types}
        self.lock = threading.Lock()
        self.subs = [session.declare_subscriber(k, self._cb(k, t)) for k, t in keys_and_types]

    def _cb(self, key, typ):
        return decoded_into(typ, self.msgs[key], self.lock)

    def get(self, key):
        with self.lock:
            return list(self.msgs[key])

    def close(self):
        for s in self.subs:
            s.undeclare()


HEAVY_LIBS = ("numpy", "scipy", "pymunk", "matplotlib", "PIL")


def heavy_libraries_mapped(pid: int) -> set[str]:
    """The heavy packages (numpy, scipy, pymunk, matplotlib, PIL) with a file of their
    package directory mapped into process ``pid``: each has extension modules there, so
    one imported anywhere in the process shows up."""
    found = set()
    with open(f"/proc/{pid}/maps") as f:
        for line in f:
            found.update(lib for lib in HEAVY_LIBS if f"/{lib}/" in line)
    return found


def start_agent(procs, zargs, rid, *extra):
    p = procs.swarmcover("agent", "--id", rid, "--info-timeout", "0", *zargs, *extra)
    return p


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
        # the world re-sends tick 11 (its reply was "lost"): answered again, not re-stepped
        s.put(keys.sense(3), Sense(robot=3, tick=11, t=0.55, ids=[1], bearings=[0.5],
                                   back_bearings=[-2.6]).encode())
        end = time.monotonic() + 10
        while time.monotonic() < end and sum(c.tick == 11 for c in
                                             col.get(keys.cmd_vel(3))) < 2:
            time.sleep(0.01)
        assert sum(c.tick == 11 for c in col.get(keys.cmd_vel(3))) == 2
        time.sleep(0.3)
        st = col.get(keys.status(3))[-1]
        assert st.task_id == 9 and st.task_state == "done" and st.state == "holding"
        # an agent that decoded, stepped and answered holds no heavy library (issue 18)
        assert heavy_libraries_mapped(agent.pid) == set()
        col.close()
    finally:
        s.close()
    agent.signal(signal.SIGINT)
    assert agent.wait(15) == 0
    out = agent.output()
    assert "12 ticks, 1 skipped or repeated, 6 invalid messages" in out, out
    assert "not msgpack" in out        # logged once per key, then only counted


def test_agent_reads_run_config_and_rejects_unknown_agent_keys(procs, zargs, tmp_path):
    good = tmp_path / "run.toml"
    good.write_text('name = "t"\nrv = 1.5\n[robots]\nkind = "diffdrive"\nv_max = 0.3\n'
                    '[agent]\ng0 = 0.2\n')
    a = start_agent(procs, zargs, 1, "--run-config", good)
    a.wait_line("READY agent 1 kind=diffdrive", timeout=30)
    assert heavy_libraries_mapped(a.pid) == set()      # the run-config path: no numpy
    a.signal(signal.SIGTERM)
    assert a.wait(15) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text('[agent]\ngains = 3\n')
    b = start_agent(procs, zargs, 2, "--run-config", bad)
    assert b.wait(30) == 2
    assert "bad.toml: [agent] gains = 3: unknown field" in b.output()

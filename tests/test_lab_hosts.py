"""`swarmcover run` over three hosts (issue 18.4), each a network namespace running its own
`swarmcover host` and therefore its own Zenoh router, linked to the run's router:

  ns R        `swarmcover run --hosts 3`: its router (listening on 10.200.b+k.1 only), the
              world, the coordinator, no agent
  ns A, B, C  `swarmcover host --connect tcp/10.200.b+k.1:7447`: a router of its own and
              the agents it starts, clients of it on the namespace's own loopback
  host        this test (10.200.b+3.2), watching the run's complex

Skips with the reason where namespaces cannot be made (netns.py)."""
from __future__ import annotations

import json
import os
import signal
import time
import uuid
from pathlib import Path

import pytest

from netns import in_ns, lab_or_skip
from procs import no_leftovers, pids_with

CONFIG = "configs/tiny.toml"
SIDES = "abc"


@pytest.fixture
def lab():
    with lab_or_skip(SIDES) as lab:
        yield lab


def _start(procs, lab, tmp_path: Path, swarm: str, capacity: int = 8):
    """The run in ns R and one host per namespace; returns (run, {name: host})."""
    listen = [a for k in range(len(SIDES) + 1) for a in ("--listen", f"tcp/{lab.addr(k, 1)}:7447")]
    run = procs.start(in_ns(lab.r, "run", CONFIG, "--out", str(tmp_path / "run"), "--quiet",
                            "--swarm", swarm, "--hosts", str(len(SIDES)), *listen))
    hosts = {}
    for k, side in enumerate(SIDES):
        name = f"h{side.upper()}"
        hosts[name] = procs.start(in_ns(
            lab.ns(side), "host", "--connect", f"tcp/{lab.addr(k, 1)}:7447", "--swarm", swarm,
            "--capacity", str(capacity), "--name", name, "--log-dir", str(tmp_path / name),
            "--reconnect-timeout", "5", "--connect-timeout", "60"))
    for h in hosts.values():
        h.wait_line("READY host", timeout=90)
    return run, hosts


def _summary(tmp_path: Path) -> dict:
    return json.loads((tmp_path / "run" / "summary.json").read_text())


def _ended(run, hosts: dict, tmp_path: Path) -> None:
    """Hosts stop by themselves once the run's router is gone; nothing is left behind."""
    for name, h in hosts.items():
        if h.p.poll() is None:
            assert h.wait(40) == 1, h.output()[-2000:]
            assert "no link to the run's router" in h.output()
    for name in hosts:
        assert not pids_with(str(tmp_path / name)), f"agents of {name} still alive"
    no_leftovers(tmp_path / "run")


@pytest.mark.timeout(300)
def test_run_over_three_namespace_hosts_certifies_as_in_process(procs, lab, tmp_path):
    from test_determinism import KEYS, _inproc, _same
    swarm = "t" + uuid.uuid4().hex[:8]
    run, hosts = _start(procs, lab, tmp_path, swarm)
    assert run.wait(240) == 0, run.output()[-3000:]
    s = _summary(tmp_path)
    assert s["certified"] and s["coverage"] >= 0.99
    # every agent ran on a host, spread by free slots (8 each: round robin), none here
    by = s["agents_by_host"]
    assert sum(by.values()) == s["robots_spawned"] and "local" not in by, by
    assert set(by) == set(hosts) and max(by.values()) - min(by.values()) <= 1, by
    assert not list((tmp_path / "run" / "logs").glob("agent-*.log"))
    for name, n in by.items():
        assert len(list((tmp_path / name).glob("agent-*.log"))) == n
        assert s["hosts"][name]["capacity"] == 8 and s["hosts"][name]["lost_with"] is None
    # lockstep: one seed, one answer, whichever machine each robot's agent runs on
    ref = _inproc(CONFIG, 0)
    got = {k: s[k] for k in KEYS} | {"certified": s["certified"]}
    assert _same(got, ref), (got, ref)
    _ended(run, hosts, tmp_path)


def _host_robots(host) -> list[int]:
    """The robot ids of the agents a host process runs now (from /proc)."""
    out = []
    for pid in pids_with(f"--parent-pid {host.pid} "):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
        except OSError:
            continue
        out.append(int(argv[argv.index("--id") + 1]))
    return sorted(out)


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_host_that_dies_takes_its_agents_and_the_run_heals_and_certifies(procs, lab,
                                                                          tmp_path):
    """SIGKILL host B and its agents (a machine dying) at a cycle where every one of its
    robots is in the complex: the coordinator refills their holes on A and C and
    failures_healed counts exactly B's robots."""
    from procs import client_session
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import Complex, decode
    from swarmcover.bus.session import Mailbox
    swarm = "t" + uuid.uuid4().hex[:8]
    run, hosts = _start(procs, lab, tmp_path, swarm, capacity=12)   # A and C hold the refills
    victim = hosts["hB"]
    s = client_session(f"tcp/{lab.addr(len(SIDES), 1)}:7447", swarm)
    mb = Mailbox()
    sub = s.declare_subscriber(Keys(swarm).complex, mb.callback)
    lost: list[int] = []
    try:
        end = time.monotonic() + 150
        while not lost and time.monotonic() < end and run.p.poll() is None:
            item = mb.get(0.2)
            items = ([item] if item else []) + mb.drain()
            if not items:
                continue
            cx = decode(items[-1][1], Complex)
            if cx.cycle < 3 or cx.state != "running":
                continue
            os.kill(victim.pid, signal.SIGSTOP)        # it starts nothing more from here
            robots = _host_robots(victim)
            if len(robots) >= 2 and set(robots) <= set(cx.occupants):
                os.killpg(victim.pid, signal.SIGKILL)  # the host and its agents, at once
                lost = robots
            else:
                os.kill(victim.pid, signal.SIGCONT)
    finally:
        sub.undeclare()
        s.close()
    assert lost, f"no cycle with all of host B's robots in the complex: {run.output()[-2000:]}"
    assert run.wait(240) == 0, run.output()[-3000:]
    sm = _summary(tmp_path)
    assert sm["certified"] and sm["coverage"] >= 0.99
    assert sm["failures_healed"] == len(lost), (sm["failures_healed"], lost)
    assert sm["hosts"]["hB"]["lost_with"] == lost
    assert sm["agents_by_host"].get("local", 0) == 0      # none needed this machine
    del hosts["hB"]
    _ended(run, hosts, tmp_path)

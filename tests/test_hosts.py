"""Hosts (issue 18.4): the slot book, the spreading rule and the wire as plain code, then a
real `swarmcover host` (its own router, linked to a real router) starting, refusing and
stopping real agents, and ending cleanly on every path. The runs over namespace hosts are
in test_lab_hosts.py."""
from __future__ import annotations

import signal
import time
import uuid

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from procs import ROOT, client_session, free_port, pids_with, wait_until
from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import Spawn
from swarmcover.hosts import (HostBook, HostEvent, HostInfo, HostReply, HostStart, HostStop,
                              HostWireError, agent_flags, decode, decode_request, encode,
                              pick_host, refuse_full, refuse_running, refuse_stopping,
                              refuse_unknown, spread, tally_line)

TINY = (ROOT / "configs" / "tiny.toml").read_text()


# --------------------------------------------------------------------------- pure parts

def _hosts(**caps) -> list[HostInfo]:
    return [HostInfo(name=n, capacity=c) for n, c in caps.items()]


def test_spread_takes_the_most_free_slots_then_falls_back_to_this_machine():
    assert spread(8, _hosts(A=3, B=1, C=3)) == ["A", "C", "A", "C", "A", "C", "B", None]
    assert spread(3, []) == [None, None, None]          # no host: today's run, all local
    busy = [HostInfo(name="A", capacity=4, running=(1, 2, 3)), HostInfo(name="B", capacity=2)]
    assert spread(4, busy) == ["B", "A", "B", None]
    assert pick_host(busy, exclude={"B"}) == "A"
    assert pick_host(busy, exclude={"A", "B"}) is None
    assert pick_host([HostInfo(name="A", capacity=1, running=(7,))]) is None


@settings(max_examples=200, deadline=None)
@given(caps=st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6)), max_size=5),
       n=st.integers(0, 40))
def test_spread_never_overfills_and_always_picks_a_host_with_the_most_free(caps, n):
    hosts = [HostInfo(name=f"h{k}", capacity=c, running=tuple(range(min(r, c))))
             for k, (c, r) in enumerate(caps)]
    free = {h.name: h.free for h in hosts}
    placed = spread(n, hosts)
    assert len(placed) == n
    assert sum(p is not None for p in placed) == min(n, sum(free.values()))
    for p in placed:
        if p is None:
            assert not any(free.values())
            continue
        assert free[p] == max(free.values()) > 0
        free[p] -= 1


def test_the_slot_book_counts_slots_and_says_why_it_refuses():
    book = HostBook("pc1", 2)
    start = lambda rid, run="r1": HostStart(run=run, robot=rid)  # noqa: E731
    assert book.why_not(start(4)) is None and book.free == 2
    book.add(4, "r1")
    assert book.why_not(start(4)) == refuse_running("pc1", 4) == \
        "robot 4 already has an agent on host pc1"
    book.add(9, "r2")
    assert book.free == 0 and book.info() == HostInfo(name="pc1", capacity=2, running=(4, 9),
                                                      seq=2)
    assert book.why_not(start(5)) == refuse_full("pc1", 2, [9, 4]) == (
        "host pc1 is full: 2 of 2 slots in use (robots 4, 9); start it with a larger "
        "--capacity, or add a host")
    assert book.to_stop(HostStop(run="r1")) == ([4], None)           # only run r1's agents
    assert book.to_stop(HostStop(run="r1", robot=9)) == ([9], None)  # a named robot: any run
    assert book.to_stop(HostStop(run="r1", robot=5)) == ([], refuse_unknown("pc1", 5))
    assert book.of_run("r2") == [9]
    assert book.remove(4) and not book.remove(4) and book.seq == 3 and book.free == 1
    book.stopping = True
    assert book.why_not(start(5)) == refuse_stopping("pc1")


def test_the_wire_round_trips_and_names_the_field_it_refuses():
    msgs = [HostStart(run="r", robot=3, kind="diffdrive", live=True, v_max=0.3, w_max=1.5,
                      config=TINY), HostStop(run="r", robot=-1)]
    for m in msgs:
        assert decode_request(encode(m)) == m
    info = HostInfo(name="pc1", capacity=4, running=(1, 2), seq=7)
    for m in (info, HostReply(ok=False, info=info, why="full"),
              HostEvent(robot=2, what="failed", info=info, run="r", rc=2, detail="x")):
        assert decode(encode(m), type(m)) == m
    bad = {"kind": "tank", "robot": -1, "v_max": float("nan"), "config": "x" * 1_000_001}
    for field, value in bad.items():
        d = msgspec.to_builtins(HostStart(run="r", robot=1)) | {field: value}
        with pytest.raises(HostWireError, match=rf"\$\.{field}"):
            decode_request(msgspec.msgpack.encode(d))
    with pytest.raises(HostWireError):
        decode_request(b"\x01")
    with pytest.raises(HostWireError, match="name"):
        decode(encode(HostInfo(name="a/b", capacity=1)), HostInfo)


def test_local_and_host_agents_get_the_same_flags(monkeypatch):
    from swarmcover.run import _agent_args
    monkeypatch.setenv("SWARMCOVER_AGENT_EXTRA_ARGS", "--log-level DEBUG")
    sp = Spawn(robot=7, kind="diffdrive", live=True)
    assert _agent_args(sp, "r.toml", {7: (0.3, 1.5)}) == [
        "agent", "--id", "7", *agent_flags("diffdrive", "r.toml", True, (0.3, 1.5))]
    assert agent_flags("diffdrive", "r.toml", True, (0.3, 1.5)) == [
        "--kind", "diffdrive", "--run-config", "r.toml", "--live", "--v-max", "0.3",
        "--param", "w_max=1.5", "--log-level", "DEBUG"]
    assert agent_flags("holonomic", None) == ["--kind", "holonomic", "--log-level", "DEBUG"]
    assert tally_line({"B": 2, "local": 1, "A": 0}) == "local 1, A 0, B 2"


def test_host_keys():
    k = Keys("host")
    assert k.host_name(k.alive("host", "pc-1")) == "pc-1"
    assert k.host_name(k.host_event("pc_2")) == "pc_2" and k.host_name(k.host("x")) == "x"
    assert k.host_name(k.alive("robot", 3)) is None
    with pytest.raises(ValueError, match="host name 'a/b' is invalid"):
        k.host("a/b")


# --------------------------------------------------------------------------- the command

def test_host_flags_are_checked_before_any_connection(procs):
    for flags, needle in ((["--capacity", "0"], "--capacity 0: must be >= 1"),
                          (["--capacity", "2", "--secure", "lab/"], "does not support"),
                          (["--capacity", "2", "--mode", "client"], "a host is a router"),
                          (["--capacity", "2", "--name", "a.b"], "host name 'a.b' is invalid")):
        p = procs.swarmcover("host", *flags, "--connect", f"tcp/127.0.0.1:{free_port()}")
        assert p.wait(30) == 2, p.output()
        assert needle in p.output()


def test_host_without_a_router_exits_2_saying_so(procs):
    ep = f"tcp/127.0.0.1:{free_port()}"
    p = procs.swarmcover("host", "--capacity", "1", "--connect", ep, "--connect-timeout", "1",
                         "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert p.wait(30) == 2, p.output()
    assert f"no link to the run's router at {ep} within 1 s" in p.output()


# --------------------------------------------------------------------------- real processes

class _Client:
    """The test's session on the run's router: asks a host, hears its events."""

    def __init__(self, endpoint: str, swarm: str, name: str):
        from swarmcover.bus.session import Mailbox
        self.s = client_session(endpoint, swarm)
        self.k, self.name = Keys(swarm), name
        self.events = Mailbox()
        self.sub = self.s.declare_subscriber(self.k.host_event(name), self.events.callback)
        self.seen: list[HostEvent] = []

    def ask(self, msg=None):
        for r in self.s.get(self.k.host(self.name), payload=encode(msg) if msg else None,
                            timeout=20):
            assert r.ok is not None, r.err.payload.to_bytes()
            return decode(r.ok.payload.to_bytes(), HostReply if msg else HostInfo)
        raise AssertionError("the host did not answer")

    def event(self, robot: int, what: str, timeout: float = 20.0) -> HostEvent:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for ev in self.seen:
                if ev.robot == robot and ev.what == what:
                    return ev
            item = self.events.get(0.1)
            if item is not None:
                self.seen.append(decode(item[1], HostEvent))
        raise AssertionError(f"no {what} event of robot {robot}: {self.seen}")

    def alive(self, robot: int) -> bool:
        return any(r.ok is not None for r in self.s.liveliness().get(
            self.k.alive("robot", robot), timeout=2.0))

    def close(self):
        self.sub.undeclare()
        self.s.close()


def _host(procs, endpoint, swarm, tmp_path, name="pc1", capacity=2, *extra):
    p = procs.swarmcover("host", "--connect", endpoint, "--swarm", swarm, "--name", name,
                         "--capacity", capacity, "--listen", f"tcp/127.0.0.1:{free_port()}",
                         "--log-dir", tmp_path / name, *extra)
    p.wait_line("READY host", timeout=40)
    return p


def _agents_of(host) -> list[int]:
    return pids_with(f"--parent-pid {host.pid} ")


@pytest.mark.timeout(120)
def test_host_starts_refuses_and_stops_agents_on_request(procs, router, tmp_path):
    swarm = "t" + uuid.uuid4().hex[:8]
    host = _host(procs, router, swarm, tmp_path)
    c = _Client(router, swarm, "pc1")
    try:
        assert c.ask() == HostInfo(name="pc1", capacity=2)
        r = c.ask(HostStart(run="r1", robot=5, config=TINY))
        assert r.ok and r.robots == (5,) and r.info.running == (5,)
        r = c.ask(HostStart(run="r1", robot=5, config=TINY))
        assert not r.ok and r.why == "robot 5 already has an agent on host pc1"
        assert c.ask(HostStart(run="r1", robot=6, config=TINY)).ok
        r = c.ask(HostStart(run="r1", robot=7, config=TINY))
        assert not r.ok and r.why == refuse_full("pc1", 2, [5, 6]) and r.info.free == 0
        # both agents came up as clients of the host's router; the run's router sees their
        # tokens through the router-to-router link
        for rid in (5, 6):
            assert 0 < c.event(rid, "ready").start_s < 15
            assert wait_until(lambda: c.alive(rid), 10)  # noqa: B023
        assert len(_agents_of(host)) == 2
        assert (tmp_path / "pc1" / "agent-5.log").read_text().count("parameters from") == 1
        r = c.ask(HostStop(run="r1"))
        assert r.ok and r.robots == (5, 6) and r.info.running == ()
        assert c.event(5, "exited").rc == 0 and not _agents_of(host)
        assert wait_until(lambda: not c.alive(5) and not c.alive(6), 10)
        assert "stopped: " in (tmp_path / "pc1" / "agent-6.log").read_text()
        # an agent that cannot start (its config is refused) is reported with its error
        assert c.ask(HostStart(run="r1", robot=8, config=TINY + "\n[agent]\nbogus = 1\n")).ok
        ev = c.event(8, "failed")
        assert ev.rc == 2 and "bogus" in ev.detail and ev.info.running == ()
        # a second host under the same name is refused
        dup = procs.swarmcover("host", "--connect", router, "--swarm", swarm, "--name", "pc1",
                               "--capacity", 1, "--listen", f"tcp/127.0.0.1:{free_port()}",
                               "--log-dir", tmp_path / "dup")
        assert dup.wait(40) == 2 and "host name pc1 is taken" in dup.output()
    finally:
        c.close()
    host.signal(signal.SIGTERM)
    assert host.wait(30) == 0


@pytest.mark.timeout(120)
def test_host_stops_the_agents_of_a_run_that_is_gone_and_its_own_on_sigterm(procs, router,
                                                                           tmp_path):
    swarm = "t" + uuid.uuid4().hex[:8]
    host = _host(procs, router, swarm, tmp_path, "pc2", 3)
    c = _Client(router, swarm, "pc2")
    try:
        token = c.s.liveliness().declare_token(c.k.alive("run", "r9"))
        assert c.ask(HostStart(run="r9", robot=1, config=TINY)).ok
        assert c.ask(HostStart(run="r8", robot=2, config=TINY)).ok   # a run with no token
        c.event(1, "ready")
        c.event(2, "ready")
        token.undeclare()
        t0 = time.monotonic()
        assert c.event(1, "exited", timeout=30).rc == 0
        assert 8 < time.monotonic() - t0 < 25            # RUN_GONE_S = 10 s
        assert c.ask().running == (2,)
    finally:
        c.close()
    host.signal(signal.SIGTERM)
    assert host.wait(30) == 0
    assert "stopping robots [2] (the host is stopping)" in host.output()
    assert not _agents_of(host)


@pytest.mark.timeout(120)
def test_host_whose_router_goes_away_stops_its_agents_and_exits(procs, tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = procs.swarmcover("router", "--listen", ep)
    router.wait_line("READY router", timeout=20)
    swarm = "t" + uuid.uuid4().hex[:8]
    host = _host(procs, ep, swarm, tmp_path, "pc3", 2, "--reconnect-timeout", "3")
    c = _Client(ep, swarm, "pc3")
    try:
        assert c.ask(HostStart(run="r1", robot=4, config=TINY)).ok
        c.event(4, "ready")
    finally:
        c.close()
    agents = _agents_of(host)
    assert len(agents) == 1
    router.signal(signal.SIGKILL)
    t0 = time.monotonic()
    assert host.wait(40) == 1
    assert 3 < time.monotonic() - t0 < 20
    assert f"no link to the run's router at {ep} for" in host.output()
    assert "stopping robots [4] (the host is stopping)" in host.output()
    assert not pids_with(f"--parent-pid {host.pid} ")
    assert "robot 4 stopped" in (tmp_path / "pc3" / "agent-4.log").read_text()


@pytest.mark.timeout(180)
def test_runs_pool_spreads_skips_a_silent_host_and_keeps_the_robots_of_one_that_comes_back(
        procs, tmp_path):
    """run's side (swarmcover.hostpool) against two real hosts: the spreading order; a host
    that does not answer (SIGSTOP) skipped and not asked again, and the start it answers
    late stopped there; local when no host has room; a router restart (every token
    vanishes and comes back) losing no robot."""
    import os
    import threading

    from swarmcover.bus.session import Mailbox
    from swarmcover.hostpool import HostPool
    ep = f"tcp/127.0.0.1:{free_port()}"
    router = procs.swarmcover("router", "--listen", ep)
    router.wait_line("READY router", timeout=20)
    swarm = "t" + uuid.uuid4().hex[:8]
    h1 = _host(procs, ep, swarm, tmp_path, "h1", 2)
    h2 = _host(procs, ep, swarm, tmp_path, "h2", 3)
    s = client_session(ep, swarm)
    k = Keys(swarm)
    inbox = Mailbox()     # what run's loop hands the pool: host tokens and host events
    subs = [s.liveliness().declare_subscriber(k.alive_hosts(), inbox.callback, history=True),
            s.declare_subscriber(k.host_events(), inbox.callback)]
    pool = HostPool(s, k, "r1", TINY, timeout=2.0)
    seen: list = []

    def loop_until(pred, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not pred():
            item = inbox.get(0.2)
            if item is not None and k.relative(item[0]).startswith("alive/"):
                name, present = k.host_name(item[0]), str(item[2]).endswith("PUT")
                seen.append((name, present))
                pool.on_token(name, present)
            elif item is not None:
                pool.on_event(item[1])
            pool.refresh()
        return pred()

    try:
        assert pool.wait(2, 30, threading.Event())
        place = lambda rid: pool.place(Spawn(robot=rid), None)  # noqa: E731
        assert [place(r) for r in range(3)] == ["h2", "h2", "h1"]   # then h2, by capacity
        os.kill(h2.pid, signal.SIGSTOP)
        try:
            t0 = time.monotonic()
            assert place(3) == "h1" and 2.0 <= time.monotonic() - t0 < 5.0  # h2 timed out
            t0 = time.monotonic()
            assert place(4) is None and time.monotonic() - t0 < 1.0  # h1 full, h2 not asked
        finally:
            os.kill(h2.pid, signal.SIGCONT)
        assert pool.silent.keys() == {"h2"} and pool.cancel == {"h2": {3}}
        assert dict(pool.started) == {"h2": 2, "h1": 2, "local": 1}
        # h2 runs the start it got while stopped; run hears of it and stops it there
        assert loop_until(lambda: not pool.cancel and pool.hosts["h2"].running == (0, 1), 30)
        assert pool.where == {0: "h2", 1: "h2", 2: "h1", 3: "h1"}
        assert pool.tally(local=1) == "local 1, h1 2, h2 2"
        assert "stopping robots [3] (run r1 asked)" in h2.output()
        # the run's router restarts: every host token goes and comes back
        router.signal(signal.SIGKILL)
        router.wait(10)
        router = procs.swarmcover("router", "--listen", ep)
        router.wait_line("READY router", timeout=20)
        assert loop_until(lambda: {("h1", False), ("h2", False)} <= set(seen)
                          and set(pool.hosts) == {"h1", "h2"}, 40), (seen, pool.hosts)
        assert pool.where == {0: "h2", 1: "h2", 2: "h1", 3: "h1"} and pool.lost == {}
        pool.stop_all()
        assert pool.where == {} and not _agents_of(h1) and not _agents_of(h2)
        rep = pool.report()
        assert rep["h1"]["agents_started"] == 2 and rep["h2"]["lost_with"] is None
    finally:
        for sub in subs:
            sub.undeclare()
        s.close()

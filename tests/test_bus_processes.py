"""Real processes over a real `swarmcover router` on a free loopback port."""
from __future__ import annotations

import json
import re
import signal
import time

from procs import SWARMCOVER, client_session, free_port, pids_with


def test_two_processes_exchange_through_router(procs, router, zargs):
    demo = procs.swarmcover("demo", *zargs, "--rate", "20")
    demo.wait_line("READY demo")
    echo = procs.swarmcover("topics", "echo", "demo", *zargs, "--count", "5", "--duration", "20")
    assert echo.wait(30) == 0
    msgs = [json.loads(line) for line in echo.lines if line.startswith("{")]
    assert len(msgs) == 5
    assert all(m["_t"] == "Demo" and m["_v"] == 1 for m in msgs)
    seqs = [m["seq"] for m in msgs]
    assert seqs == sorted(seqs) and len(set(seqs)) == 5


def test_topics_list_hz_alive(procs, router, zargs):
    demo = procs.swarmcover("demo", *zargs, "--rate", "10")
    demo.wait_line("READY demo")
    time.sleep(0.5)
    lst = procs.swarmcover("topics", "list", *zargs, "--window", "2")
    assert lst.wait(30) == 0
    row = next(line for line in lst.lines if line.startswith("demo "))
    _, typ, n, rate, senders = row.split()
    assert typ == "Demo" and 10 <= int(n) <= 30 and 5.0 <= float(rate) <= 15.0 and senders == "1"

    hz = procs.swarmcover("topics", "hz", "demo", *zargs, "--duration", "3.5")
    assert hz.wait(30) == 0
    rates = [float(m.group(1)) for line in hz.lines if (m := re.match(r"rate ([\d.]+) Hz", line))]
    assert rates and all(6.0 <= r <= 14.0 for r in rates), hz.output()

    alive = procs.swarmcover("topics", "alive", *zargs)
    assert alive.wait(30) == 0
    assert f"demo/{demo.pid}" in alive.lines, alive.output()

    demo.signal(signal.SIGINT)
    assert demo.wait(10) == 0
    alive2 = procs.swarmcover("topics", "alive", *zargs)
    assert alive2.wait(30) == 0
    assert f"demo/{demo.pid}" not in alive2.lines


def test_alive_watch_sees_departure(procs, router, zargs):
    watch = procs.swarmcover("topics", "alive", *zargs, "--watch", "--duration", "15")
    time.sleep(1.5)
    demo = procs.swarmcover("demo", *zargs)
    demo.wait_line("READY demo")
    watch.wait_line(f"+ demo/{demo.pid}", timeout=10)
    demo.signal(signal.SIGTERM)
    assert demo.wait(10) == 0
    watch.wait_line(f"- demo/{demo.pid}", timeout=10)


def test_invalid_payload_echoed_as_error_not_crash(procs, router, zargs):
    swarm = zargs[zargs.index("--swarm") + 1]
    echo = procs.swarmcover("topics", "echo", "robot/*/sense", *zargs, "--count", "2",
                            "--duration", "40")
    echo.wait_line("# echo", timeout=30)   # subscribed (a fixed 1.5 s lost the race under load)
    time.sleep(0.5)                        # ... and the declaration reached the router
    s = client_session(router, swarm)
    try:
        s.put(f"sc/{swarm}/robot/3/sense", b"\x81\xa2_t\xa5Sense")  # truncated map
        s.put(f"sc/{swarm}/robot/3/sense", b"\xff\x00garbage")
    finally:
        s.close()
    assert echo.wait(30) == 0
    errs = [json.loads(line) for line in echo.lines if line.startswith("{")]
    assert len(errs) == 2 and all("_error" in e for e in errs), echo.output()
    assert "Sense._v" in errs[0]["_error"] or "Sense.robot" in errs[0]["_error"]


def test_sigint_closes_cleanly_and_leaves_nothing(procs, router, zargs):
    demo = procs.swarmcover("demo", *zargs)
    demo.wait_line("READY demo")
    echo = procs.swarmcover("topics", "echo", "**", *zargs)
    time.sleep(1.0)
    for p in (echo, demo):
        p.signal(signal.SIGINT)
    assert echo.wait(10) == 0 and demo.wait(10) == 0
    assert not [p for p in pids_with(f"--swarm {zargs[-1]}")]


def test_client_without_router_fails_fast_with_clear_error(procs):
    dead = f"tcp/127.0.0.1:{free_port()}"
    p = procs.swarmcover("topics", "list", "--connect", dead, "--connect-timeout", "1")
    assert p.wait(30) == 2
    assert "swarmcover router" in p.output() and dead in p.output()


def test_bad_flags_name_the_flag(procs):
    p = procs.swarmcover("demo", "--cfg", "no_colon_here")
    assert p.wait(30) == 2
    assert "--cfg" in p.output()
    p = procs.swarmcover("demo", "--swarm", "bad/name")
    assert p.wait(30) != 0
    assert "--swarm" in p.output()


def test_router_sigterm_exits_zero(procs):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    r = procs.start(SWARMCOVER + ["router", "--listen", endpoint])
    r.wait_line("READY router")
    r.signal(signal.SIGTERM)
    assert r.wait(10) == 0


STUCK_ON_STOP = """
import sys, time
sys.path.insert(0, {root!r})
from swarmcover.bus.session import Shutdown
with Shutdown(grace_s=1.0) as stop:
    print("READY stuck", flush=True)
    stop.wait()
    time.sleep(600)  # stands for a close or a put that never returns
"""


def test_a_process_stuck_after_sigint_is_ended_by_the_watchdog_with_its_stack(procs, tmp_path):
    import os
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    script = tmp_path / "stuck.py"
    script.write_text(STUCK_ON_STOP.format(root=root))
    p = procs.start([sys.executable, str(script)])
    p.wait_line("READY stuck")
    t0 = time.monotonic()
    p.signal(signal.SIGINT)
    assert p.wait(20) == 0
    assert time.monotonic() - t0 < 10
    out = p.output()
    assert "still running 1 s after the stop request" in out
    assert "time.sleep(600)" in out  # where the main thread was stuck


def test_query_world_info_skips_invalid_replies_and_honours_stop(router, caplog):
    """bus.session.query_world_info: None without a world or after a stop request; with a
    world, its first valid reply (an invalid reply is logged, skipped and asked again)."""
    import threading
    import uuid

    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import WorldInfo
    from swarmcover.bus.session import Shutdown, query_world_info
    swarm = "wi" + uuid.uuid4().hex[:8]
    k = Keys(swarm)
    ask, serve_s = client_session(router, swarm), client_session(router, swarm)
    done = threading.Event()
    try:
        assert query_world_info(ask, k, 0.5) is None            # no world yet
        stopped = Shutdown(signals=())
        stopped.set()
        assert query_world_info(ask, k, 30.0, stop=stopped) is None

        q = serve_s.declare_queryable(k.world_info)
        info = WorldInfo(name="qwi", rv=1.0, robot_radius=0.06, dt=0.05).validate().encode()

        answered = []

        def serve():   # the first query gets garbage, the next ones the WorldInfo
            while not done.is_set():
                query = q.try_recv()
                if query is None:
                    time.sleep(0.01)
                    continue
                query.reply(k.world_info, info if answered else b"\xff\x00garbage")
                answered.append(1)
                query.drop()

        th = threading.Thread(target=serve, daemon=True)
        th.start()
        caplog.set_level("WARNING", logger="swarmcover.bus")
        got = query_world_info(ask, k, 20.0, per_query=1.0)
        assert got is not None and got.name == "qwi" and got.dt == 0.05
        assert len(answered) >= 2
        assert any("world/info reply invalid" in r.getMessage() for r in caplog.records)
    finally:
        done.set()
        ask.close()
        serve_s.close()


def test_run_node_hands_what_prepare_built_to_serve(router):
    """run_node's prepare: its value reaches serve as the fifth argument; a ValueError in it
    is exit 2 before any session (here: no router at the given endpoint)."""
    from swarmcover.bus.node import run_node
    seen = []

    def serve(args, session, keys, stop, prepared):
        seen.append((prepared, keys.prefix))
        return 3

    argv = ["--connect", router, "--swarm", "prep", "--connect-timeout", "5"]
    assert run_node("t", None, lambda p: None, serve, argv=argv,
                    prepare=lambda a: {"swarm": a.swarm}) == 3
    assert seen == [({"swarm": "prep"}, "sc/prep")]

    def bad(args):
        raise ValueError("--x 1: bad")
    dead = f"tcp/127.0.0.1:{free_port()}"
    assert run_node("t", None, lambda p: None, serve, argv=["--connect", dead],
                    prepare=bad) == 2
    assert len(seen) == 1


_DIES_WITH_A_ROUTER = """
import sys, time
sys.path.insert(0, sys.argv[1])
from procs import Proc, SWARMCOVER
r = Proc(SWARMCOVER + ["router", "--listen", sys.argv[2]])
r.wait_line("READY router", timeout=20)
print("ROUTER", r.pid, flush=True)
time.sleep(120)
"""


def _running(pid: int) -> bool:
    """pid exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_children_of_a_killed_test_process_stop_too(procs):
    """A test process killed without its teardown (SIGKILL, a CI timeout) leaves no child:
    tests/procs.Proc starts children watching their parent (SWARMCOVER_WATCH_PARENT). A
    router of test_lab_security once outlived a SIGTERMed pytest by an hour."""
    import os
    import sys
    from pathlib import Path
    ep = f"tcp/127.0.0.1:{free_port()}"
    holder = procs.start([sys.executable, "-c", _DIES_WITH_A_ROUTER,
                          str(Path(__file__).resolve().parent), ep])
    pid = int(holder.wait_line("ROUTER", timeout=30).split()[1])
    holder.signal(signal.SIGKILL)
    end = time.monotonic() + 10
    while time.monotonic() < end and _running(pid):
        time.sleep(0.1)
    alive = _running(pid)
    if alive:
        os.kill(pid, signal.SIGKILL)
    assert not alive, "the router outlived the process that started it"


def test_the_router_takes_a_swarm_of_clients(router):
    """A swarm is hundreds of client sessions: `swarmcover router` takes 500 (with Zenoh's
    shared memory on, a router refused every client after the 351st)."""
    sessions = []
    try:
        for _ in range(500):
            sessions.append(client_session(router, "many"))
        assert len(sessions) == 500
    finally:
        for s in sessions:
            s.close()

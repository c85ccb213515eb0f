"""How `swarmcover run` ends, with real processes on the tiny map: forged certificates and
spawns are refused, agents that fail at start end the run with their error, a wall
timeout, robots_max and a dead world end it promptly, and summary.json (strict JSON) says
why every time."""
from __future__ import annotations

import json
import re
import signal
import time
from pathlib import Path

import pytest

from procs import client_session, free_port, no_leftovers, pids_with, wait_cycle


def _strict(path: Path) -> dict:
    def bad(c):
        raise ValueError(f"summary.json holds {c}")
    return json.loads(path.read_text(), parse_constant=bad)


def _forged_certificate():
    from swarmcover.bus.messages import Complex
    # a well-formed certified square: what one packet needed to end a run "CERTIFIED"
    return Complex(cycle=99, epoch=1, vertices=[0, 1, 2, 3], occupants=[0, 1, 2, 3],
                   edges=[0, 1, 0, 2, 1, 2, 1, 3, 2, 3], triangles=[0, 1, 2, 1, 2, 3],
                   frontier=[], obstacle=[0, 1, 3, 4], certified=True, state="certified",
                   robots=4)


@pytest.mark.timeout(150)
def test_forged_certificate_and_spawn_are_refused_and_the_run_ends_with_the_true_answer(
        procs, tmp_path):
    from swarmcover.bus.keys import Keys
    from swarmcover.bus.messages import Spawn
    out = tmp_path / "run"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", out, "--quiet", "--port", port,
                         "--wall-timeout", "45")
    wait_cycle(out, 1, 60)
    ready = next(ln for ln in (out / "logs" / "coordinator.log").read_text().splitlines()
                 if "READY coordinator" in ln)
    zid = ready.split("zid ")[1].split()[0]
    keys = Keys("tiny")
    forged = _forged_certificate().encode()
    s = client_session(ep, "tiny")
    try:
        s.put(keys.complex, forged)                       # a plain put
        s.put(keys.spawn, Spawn(robot=900, source=0).encode())
        pub = s.declare_publisher(keys.complex)          # with source_info of its own
        import zenoh
        pub.put(forged, source_info=zenoh.SourceInfo(pub.id, 1))
        pub.undeclare()
    finally:
        s.close()
    # a session that takes the coordinator's own zid: only the run key tells them apart
    # (zenoh's router refuses a second session with a zid it has, as measured here, so
    # this part runs only if a router ever lets it in; the unit test checks the key)
    spoofed = 0
    try:
        s2 = client_session(ep, "tiny")
        s2.close()
        import argparse

        from swarmcover.bus.session import add_zenoh_args, open_session
        ap = argparse.ArgumentParser()
        add_zenoh_args(ap)
        s2 = open_session(ap.parse_args(["--connect", ep, "--swarm", "tiny",
                                         "--cfg", f'id:"{zid}"']))
    except Exception:
        s2 = None   # the router refused a second session with that id: nothing to spoof
    if s2 is not None:
        try:
            import zenoh
            pub = s2.declare_publisher(keys.complex)
            assert str(pub.id.zid) == zid
            pub.put(forged, source_info=zenoh.SourceInfo(pub.id, 1))
            pub.undeclare()
            spoofed = 1
        finally:
            s2.close()
    rc = p.wait(120)
    s = _strict(out / "summary.json")
    # the true answer: certified by the coordinator (covered), or not yet at the timeout
    if s["certified"]:
        assert rc == 0 and s["stop_reason"] == "certified" and s["coverage"] >= 0.99, s
        assert s["certificate_recheck"]["ok"]
    else:
        assert rc == 1 and s["stop_reason"] == "wall_timeout", (rc, s, p.output()[-2000:])
        assert s["ratio"] is None and s["robots_per_bound"] is None
    refused = s["refused_messages"]
    assert sum(n for k, n in refused.items() if k.startswith("complex: not from")) >= 2, refused
    if spoofed:
        assert refused.get("complex: bad or missing run-key signature", 0) >= 1, refused
    assert sum(n for k, n in refused.items() if k.startswith("spawn:")) >= 1, refused
    assert not (out / "logs" / "agent-900.log").exists()
    assert s["robots_max_from"].startswith("map:") and s["euler_bound"] > 0
    no_leftovers(out)


@pytest.mark.timeout(90)
def test_an_agent_failing_at_start_ends_the_run_with_its_error(procs, tmp_path):
    """Every agent gets a bad parameter (through run's env hook for agent arguments, since
    the config itself is validated before anything starts): run exits 2 with the agent's
    error instead of waiting for its wall timeout."""
    out = tmp_path / "run"
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", out, "--quiet", "--port",
                         free_port(), env={"SWARMCOVER_AGENT_EXTRA_ARGS": "--param kp=fast"})
    assert p.wait(75) == 2, p.output()[-3000:]
    text = p.output()
    # the first agent to fail: robot 0's, or one run started ahead (its reserve)
    assert re.search(r"agent-\d+ exited at start \(exit 2\)", text) and "kp" in text, \
        text[-2000:]
    assert "Traceback" not in text
    s = _strict(out / "summary.json")
    assert s["stop_reason"] == "agents_failed" and s["certified"] is False
    assert s["exit_code"] == 2
    no_leftovers(out)


@pytest.mark.timeout(150)
def test_robots_max_ends_the_run_uncertified_with_the_reason(procs, tmp_path):
    out = tmp_path / "run"
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", out, "--port", free_port(),
                         "--robots-max", "4", "--wall-timeout", "120")
    assert p.wait(140) == 1, p.output()[-3000:]
    s = _strict(out / "summary.json")
    assert s["stop_reason"] == "robots_max" and not s["certified"], s
    assert s["robots_max"] == 4 and s["robots_max_from"] == "config"
    assert "robots_max" in s["stop_detail"]
    assert s["ratio"] is None and s["ratio_same_spacing"] is None
    # the progress line and the last line say why
    assert "NOT certified (robots_max" in p.output()
    no_leftovers(out)


@pytest.mark.timeout(90)
def test_a_dead_world_still_leaves_a_summary(procs, tmp_path):
    out = tmp_path / "run"
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", out, "--quiet", "--port",
                         free_port())
    wait_cycle(out, 1, 60)
    mine = set(pids_with(str(out)))
    world = [pid for pid in pids_with("swarmcover world") if pid in mine]
    assert len(world) == 1
    import os
    os.kill(world[0], signal.SIGKILL)
    assert p.wait(60) == 3, p.output()[-3000:]
    s = _strict(out / "summary.json")
    assert s["stop_reason"] == "world_died" and "world" in s["stop_detail"]
    assert s["cycles"] >= 1
    no_leftovers(out)


@pytest.mark.timeout(60)
def test_a_wall_timeout_ends_the_run_uncertified_with_its_reason(procs, tmp_path):
    """Eight wall seconds cannot certify the tiny map (it takes about a minute): run stops at
    its wall timeout with exit 1, and summary.json (strict JSON) says why, with null ratios."""
    out = tmp_path / "run"
    t0 = time.monotonic()
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", out, "--quiet", "--port",
                         free_port(), "--wall-timeout", "8")
    rc = p.wait(45)
    s = _strict(out / "summary.json")
    assert s["stop_reason"] == "wall_timeout", (rc, s, p.output()[-2000:])
    assert rc == 1 and s["exit_code"] == 1 and s["certified"] is False, s
    assert s["stop_detail"] == "wall timeout 8 s" and 8.0 <= s["wall_time_s"] < 30.0, s
    assert s["ratio"] is None and s["ratio_same_spacing"] is None
    assert s["robots_per_bound"] is None
    assert "NOT certified (wall_timeout" in p.output()
    # the timeout is recorded with the config the run used
    assert (out / "resolved.toml").read_text().startswith("# swarmcover run --wall-timeout 8 (s)")
    assert time.monotonic() - t0 < 40
    no_leftovers(out)

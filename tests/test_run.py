"""`swarmcover run` end to end: a router, the world, the coordinator and one OS process per
robot over real Zenoh, in lockstep, on the tiny map."""
from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest

from procs import free_port, no_leftovers, pids_with, wait_cycle


def _run(procs, out: Path, *extra):
    return procs.swarmcover("run", "configs/tiny.toml", "--out", str(out), "--quiet",
                            "--port", str(free_port()), *extra)


def _of_run(out: Path, needle: str) -> list[int]:
    """Pids of this run's processes whose command line contains ``needle``."""
    mine = set(pids_with(str(out)))
    return [pid for pid in pids_with(needle) if pid in mine]


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


@pytest.mark.timeout(300)
def test_run_certifies_and_writes_the_report(procs, tmp_path):
    out = tmp_path / "run"
    p = _run(procs, out)
    assert p.wait(280) == 0, p.output()[-3000:]
    s = _summary(out)
    for key in ("certified", "robots_used", "ideal_count", "ratio", "mean_spacing",
                "ideal_count_same_spacing", "ratio_same_spacing", "coverage", "cycles",
                "sim_time_s", "wall_time_s", "failures_healed"):
        assert key in s, key
    assert s["certified"] is True and s["coverage"] >= 0.99
    assert s["ideal_count"] == 7 and s["robots_used"] >= s["ideal_count"]
    assert 0.3 < s["mean_spacing"] <= 1.0
    assert (out / "final.png").stat().st_size > 10_000
    rows = [json.loads(x) for x in (out / "cycles.jsonl").read_text().splitlines()]
    assert rows[-1]["state"] == "certified" and rows[-1]["frontier"] == 0
    assert [r["cycle"] for r in rows] == sorted(r["cycle"] for r in rows)
    logs = {f.name for f in (out / "logs").iterdir()}
    assert {"router.log", "world.log", "coordinator.log", "agent-0.log"} <= logs
    no_leftovers(out)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGHUP], ids=["ctrl-c", "hangup"])
def test_ctrl_c_stops_every_process(procs, tmp_path, sig):
    """Ctrl-C, and SIGHUP (the terminal that ran it closed; it used to kill run before it
    wrote summary.json), stop every process and leave the report."""
    out = tmp_path / "run"
    p = _run(procs, out)
    wait_cycle(out, 2, 60)
    assert len(pids_with(str(out))) >= 4  # router, world, coordinator, agents
    p.signal(sig)
    assert p.wait(40) == 130
    # the report survives the interruption, with its reason, as strict JSON
    s = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: 1 / 0)
    assert s["stop_reason"] == "interrupted" and s["certified"] is False and s["cycles"] >= 2
    assert s["stop_detail"] == f"signal {signal.Signals(sig).name}"
    no_leftovers(out)


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_killed_agents_and_coordinator_are_healed(procs, tmp_path):
    """10% of the agents die mid-run (here: one of ~10), then the coordinator is killed;
    run restarts it, it rebuilds from the agents' statuses, and the holes are refilled."""
    out = tmp_path / "run"
    p = _run(procs, out)
    wait_cycle(out, 8, 150)
    agent = _of_run(out, "agent --id 3 ")
    assert len(agent) == 1, "agent 3 is not running"
    os.kill(agent[0], signal.SIGKILL)
    wait_cycle(out, 10, 120)
    coord = _of_run(out, "swarmcover coordinator")
    assert len(coord) == 1
    os.kill(coord[0], signal.SIGKILL)
    assert p.wait(280) == 0, p.output()[-3000:]
    s = _summary(out)
    assert s["certified"] and s["coverage"] >= 0.99
    assert s["coordinator_restarts"] == 1
    # cycles count across the restart (the restarted coordinator counts from 0 again)
    rows = [json.loads(x) for x in (out / "cycles.jsonl").read_text().splitlines()]
    assert len({r["epoch"] for r in rows}) == 2 and s["cycles"] >= 10
    assert [r["cycle"] for r in rows] == sorted(r["cycle"] for r in rows)
    log = (out / "logs" / "coordinator.log").read_text()
    assert "robot 3 failed" in log
    assert "resuming with" in log
    no_leftovers(out)


def test_live_agents_plan_with_the_bridge_limits_and_a_bad_bridge_stops_run_first(tmp_path,
                                                                                  capsys):
    from swarmcover.bus.messages import Spawn
    from swarmcover.run import _agent_args, _live_limits, build_parser, main, resolve_config
    args = build_parser().parse_args(["configs/mixed.toml"])
    cfg, resolved = resolve_config("configs/mixed.toml", args)
    limits = _live_limits(cfg, resolved, "configs/mixed.toml")
    assert set(limits) == {1, 2}
    a = _agent_args(Spawn(robot=1, source=0, kind="diffdrive", live=True), "r.toml", limits)
    assert a[a.index("--v-max") + 1] == "0.3" and a[a.index("--param") + 1] == "w_max=2.0"
    v = _agent_args(Spawn(robot=5, source=0, kind="holonomic"), "r.toml", limits)
    assert "--v-max" not in v and "--live" not in v
    # the bridge's own parser checks [hwbridge] before any process starts
    bad = tmp_path / "bad.toml"
    bad.write_text(Path("configs/mixed.toml").read_text().replace("v_max = 0.3", "v_max = -1", 1))
    assert main([str(bad), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "v_max" in err and "-1" in err
    assert not (tmp_path / "run" / "logs").exists()


# ---- the shared Zenoh flags (bus.session.add_zenoh_args), as `run` reads them

def _closed_port() -> int:
    return free_port()   # bound and released: nobody listens there


CONFLICTS = [
    # (flags, what the one line must name)
    (["--connect", "tcp/127.0.0.1:{a}", "--router", "tcp/127.0.0.1:{b}"],
     ["--connect = 'tcp/127.0.0.1:{a}'", "--router", "not both"]),
    (["--connect", "tcp/127.0.0.1:{a}", "--port", "{b}"], ["--connect", "--port", "not both"]),
    (["--listen", "tcp/127.0.0.1:{a}", "--port", "{b}"], ["--listen", "--port", "not both"]),
    (["--listen", "tcp/127.0.0.1:{a}", "--router", "tcp/127.0.0.1:{b}"],
     ["--listen", "--router", "not both"]),
    (["--listen", "tcp/127.0.0.1:{a}", "--connect", "tcp/127.0.0.1:{b}"],
     ["--listen", "--connect", "not both"]),
    (["--mode", "router"], ["--mode = 'router'", "--router ENDPOINT"]),
    (["--connect", "localhost"], ["--connect = 'localhost'", "expected a Zenoh endpoint"]),
    (["--listen", "tcp/127.0.0.1:99999"], ["--listen = 'tcp/127.0.0.1:99999'"]),
    (["--connect", "tcp/127.0.0.1:{a}"], ["--connect = 'tcp/127.0.0.1:{a}'", "no router answers"]),
    (["--config", "{tmp}/no.json5"], ["--config {tmp}/no.json5", "no such file"]),
    (["--config", "{tmp}/bad.json5"], ["--config {tmp}/bad.json5"]),
    (["--cfg", "nocolon"], ["--cfg 'nocolon'", "PATH:JSON5"]),
]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("flags,needles", CONFLICTS, ids=[" ".join(f) for f, _ in CONFLICTS])
def test_shared_flags_that_contradict_run_exit_2_naming_them(tmp_path, flags, needles):
    import subprocess
    import sys
    (tmp_path / "bad.json5").write_text('{ mode: "client", oops')
    subs = dict(a=_closed_port(), b=_closed_port(), tmp=tmp_path)
    argv = [sys.executable, "-m", "swarmcover", "run", "configs/tiny.toml", "--quiet",
            "--out", str(tmp_path / "run")] + [f.format(**subs) for f in flags]
    p = subprocess.run(argv, capture_output=True, text=True, timeout=100,
                       cwd=Path(__file__).resolve().parent.parent)
    out = p.stdout + p.stderr
    assert p.returncode == 2, out
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    for n in needles:
        assert n.format(**subs) in out, (n.format(**subs), out)
    assert ".rs:" not in out  # zenoh's own source location is no part of a message
    assert not (tmp_path / "run" / "logs").exists()  # nothing started


def test_children_get_the_shared_flags_and_the_router_its_endpoints():
    from swarmcover.bus.session import zenoh_argv
    from swarmcover.run import _local, _router_args, build_parser, session_args
    args = build_parser().parse_args([
        "configs/tiny.toml", "--listen", "tcp/0.0.0.0:7999", "--cfg", "transport/link/tx/lease:9000",
        "--connect-timeout", "20", "--multicast-scouting", "--mode", "peer", "--config", "z.json5",
        "--role", "viewer"])
    assert args.run_config == "configs/tiny.toml" and args.config == "z.json5"
    assert args.swarm is None       # the config's name, decided by check_run
    connect = [_local(e) for e in args.listen]
    assert connect == ["tcp/127.0.0.1:7999"]
    child = zenoh_argv(session_args(args, connect, "tiny"))
    assert child == ["--config", "z.json5", "--mode", "peer", "--connect", "tcp/127.0.0.1:7999",
                     "--multicast-scouting", "--cfg", "transport/link/tx/lease:9000",
                     "--swarm", "tiny", "--connect-timeout", "20.0"]
    assert "--listen" not in child and "--role" not in child   # the router's; run's own
    assert _router_args(args, args.listen) == ["--listen", "tcp/0.0.0.0:7999",
                                               "--multicast-scouting"]
    own = session_args(args, connect, "tiny")
    assert own.listen is None and own.connect == connect and own.role == "viewer"
    assert args.listen == ["tcp/0.0.0.0:7999"]   # the copy leaves run's own flags alone
    assert _local("tcp/[::]:7447") == "tcp/[::1]:7447"
    assert _local("tls/10.0.0.2:7447#iface=eth0") == "tls/10.0.0.2:7447#iface=eth0"
    # the clock flags no longer share a destination with the Zenoh --mode
    a = build_parser().parse_args(["configs/tiny.toml", "--realtime", "--mode", "client"])
    assert a.clock == "realtime" and a.mode == "client"


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_run_with_shared_flags_reaches_every_process(procs, tmp_path):
    """A whole tiny run with the embedded router on --listen and --cfg/--swarm/
    --connect-timeout: every process gets them, and the run certifies."""
    out = tmp_path / "run"
    port = free_port()
    p = procs.swarmcover("run", "configs/tiny.toml", "--out", str(out), "--quiet",
                         "--listen", f"tcp/0.0.0.0:{port}", "--swarm", "flags_run",
                         "--cfg", "transport/link/tx/lease:12000", "--connect-timeout", "20")
    wait_cycle(out, 2, 90)
    cmdlines = []
    for pid in pids_with(str(out)):
        try:
            cmdlines.append(Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0"))
        except OSError:
            pass
    kids = [c for c in cmdlines if b"world" in c or b"coordinator" in c or b"agent" in c]
    assert len(kids) >= 3, cmdlines
    for c in kids:
        text = b" ".join(c).decode()
        for flag in (f"--connect tcp/127.0.0.1:{port}", "--swarm flags_run",
                     "--cfg transport/link/tx/lease:12000", "--connect-timeout 20.0"):
            assert flag in text, (flag, text)
    assert p.wait(280) == 0, p.output()[-3000:]
    assert f"READY router tcp/0.0.0.0:{port}" in (out / "logs" / "router.log").read_text()
    assert f"(router tcp/127.0.0.1:{port}, swarm flags_run)" in p.output()
    s = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: 1 / 0)
    assert s["certified"] and s["stop_reason"] == "certified"
    no_leftovers(out)


@pytest.mark.timeout(300)
def test_agents_started_by_hand_join_a_run_and_are_used(procs, tmp_path, router):
    """Issue 18: agents started by hand before the run (``swarmcover spawn``, any terminal or
    host) are available; the coordinator places them before it asks run for new processes,
    run starts no process for them, and the run certifies using them."""
    import uuid
    swarm = "j" + uuid.uuid4().hex[:8]
    hand = procs.swarmcover("spawn", "3", "--first-id", "100", "--info-timeout", "60",
                            "--connect", router, "--swarm", swarm)
    hand.wait_line("READY spawn 3", timeout=30)
    out = tmp_path / "run"
    p = procs.swarmcover("run", "configs/tiny.toml", "--router", router, "--swarm", swarm,
                         "--out", str(out), "--quiet")
    assert p.wait(280) == 0, p.output()[-3000:]
    s = _summary(out)
    assert s["certified"] is True and s["coverage"] >= 0.99
    assert s["robots_joined"] == 3 and s["robots_spawned"] >= 1
    coord = (out / "logs" / "coordinator.log").read_text()
    for rid in (100, 101, 102):
        assert f"placing available robot {rid} " in coord, coord[-2000:]
        assert not (out / "logs" / f"agent-{rid}.log").exists()   # run started none of them
    # the hand-started agents drove: they got tasks from the coordinator
    assert "swarmcover.agent.100: task" in hand.output(), hand.output()[-2000:]

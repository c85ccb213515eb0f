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
def test_ctrl_c_stops_every_process(procs, tmp_path):
    out = tmp_path / "run"
    p = _run(procs, out)
    wait_cycle(out, 2, 60)
    assert len(pids_with(str(out))) >= 4  # router, world, coordinator, agents
    p.signal(signal.SIGINT)
    assert p.wait(40) == 130
    # the report survives the interruption, with its reason, as strict JSON
    s = json.loads((out / "summary.json").read_text(), parse_constant=lambda c: 1 / 0)
    assert s["stop_reason"] == "interrupted" and s["certified"] is False and s["cycles"] >= 2
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
    from bus.messages import Spawn
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

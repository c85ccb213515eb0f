"""Certified means covered, end to end (swarmcover.simloop, in process): the cases of
issue 21 that once certified while whole rooms were uncovered."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from procs import LOCKSTEP_ROBOTS_TOML
from swarmcover.simloop import SimLoop
from swarmcover.world.config import load_config
from swarmcover.world.groundtruth import coverage_fraction

_BASE = """
name = "{name}"
rv = 1.0

[map]
boundary = {boundary}
obstacles = {obstacles}
sources = [{source}]

""" + LOCKSTEP_ROBOTS_TOML + """seed = 0
"""


def _write(tmp_path: Path, name: str, **kw) -> Path:
    p = tmp_path / f"{name}.toml"
    p.write_text(_BASE.format(name=name, **kw))
    return p


def _coverage(sim, res) -> float:
    alive = [r for r in res.positions if r in sim.agents]
    P = np.array([res.positions[r] for r in alive]).reshape(-1, 2)
    return coverage_fraction(sim.wm, P, sim.cfg.rv)


@pytest.mark.timeout(300)
def test_a_lone_robot_facing_a_wall_does_not_certify_the_room(tmp_path):
    """5 m x 4 m room, the source 0.3 m from the wall it faces: the first drive touches. It
    used to be the lone robot's only direction, and the empty fence certified 10.9%."""
    path = _write(tmp_path, "facing_wall", boundary="[[0, 0], [5, 0], [5, 4], [0, 4]]",
                  obstacles="[]", source="{x = 0.3, y = 2.0, theta = 3.14159}")
    sim = SimLoop(load_config(path), seed=0)
    seen = []

    def on_cycle(s, cx):
        seen.append((cx.cycle, len(cx.vertices), cx.certified, cx.state))

    # bounded: far enough to see the run go on past the touch with more robots
    res = sim.run(max_sim_s=150, max_wall_s=150, on_cycle=on_cycle)
    dep = res.deployer
    assert any(r.touched and r.kind == "isolated" for r in dep.evidence.records), \
        "the first drive did not touch: the test shows nothing"
    assert not any(c for _, _, c, _ in seen), seen
    assert res.robots_spawned >= 3 and max(n for _, n, _, _ in seen) >= 3, seen


def _two_rooms(tmp_path: Path, door: float) -> Path:
    # room A 1.5 m x 2 m (source), room B 1.2 m x 2 m behind a 0.1 m wall; the door's
    # centre 0.6 m up. Before probes (seed 0): certified at 68.1% (0.8 m) and 64.2% (0.7 m)
    lo, hi = 0.6 - door / 2, 0.6 + door / 2
    obstacles = (f'[{{type = "rect", min = [1.5, 0.0], max = [1.6, {lo}]}}, '
                 f'{{type = "rect", min = [1.5, {hi}], max = [1.6, 2.0]}}]')
    return _write(tmp_path, f"door{int(door * 100)}", boundary="[[0, 0], [2.8, 0], [2.8, 2], [0, 2]]",
                  obstacles=obstacles, source="{x = 0.3, y = 1.0, theta = 0.0}")


@pytest.mark.timeout(400)
@pytest.mark.parametrize("door", [0.7, 0.8])
def test_a_room_behind_a_door_narrower_than_rv_is_covered_before_certifying(tmp_path, door):
    """Two rooms joined by a 0.7 m or 0.8 m door (rv = 1 m), source in room A: both used to
    be certified at about 53% coverage (the door edge closed by the test-drive rule)."""
    sim = SimLoop(load_config(_two_rooms(tmp_path, door)), seed=0)
    res = sim.run(max_sim_s=3000, max_wall_s=350)
    cov = _coverage(sim, res)
    if res.certified:
        assert cov >= 0.995, (cov, res.cycles)
    else:
        # bounded by wall time on a loaded machine: never certified below 99.5% either
        assert not any(c.certified for c in res.complexes)
    assert res.certified, (res.stop_reason, cov)

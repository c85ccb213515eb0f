"""Ground truth (coverage fraction, ideal lattice counts) and the clock logic."""
from __future__ import annotations

import math

import numpy as np
import pytest

from swarmcover.world.clock import LockstepGate, Pacer, RtfMeter
from swarmcover.world.groundtruth import coverage_fraction, ideal_count, lattice, mean_edge_length
from swarmcover.world.maps import WorldMap, map_from_path


def room(w, h, obstacles=()):
    return WorldMap("r", np.array([[0, 0], [w, 0], [w, h], [0, h]], float), list(obstacles),
                    np.array([[w / 2, h / 2, 0.0]]), True)


def test_coverage_of_one_robot_in_open_space():
    wm = room(10, 10)
    f = coverage_fraction(wm, [[5.0, 5.0]], 1.0)
    assert f == pytest.approx(math.pi / 100, rel=0.02)
    assert coverage_fraction(wm, np.zeros((0, 2)), 1.0) == 0.0


def test_walls_cast_shadows():
    # a thin wall right of the robot hides what is behind it
    wall = np.array([[5.2, 4.0], [5.3, 4.0], [5.3, 6.0], [5.2, 6.0]])
    wm = room(10, 10, [wall])
    f, cov, r = coverage_fraction(wm, [[5.0, 5.0]], 1.0, return_mask=True)
    assert f < math.pi / 100 * 0.8
    iy, ix = int((5.0 - r.y0) / r.cell), int((5.8 - r.x0) / r.cell)
    assert not cov[iy, ix] and cov[iy, int((4.4 - r.x0) / r.cell)]


def test_a_lattice_at_spacing_rv_covers_everything():
    cfg, wm = map_from_path("configs/structured.toml")
    p = lattice(0.9, 0.0, (0.05, 0.05), wm.bounds)
    p = p[wm.is_free(p)]
    assert coverage_fraction(wm, p, 1.0) > 0.98
    assert coverage_fraction(wm, p[:20], 1.0) < 0.4
    assert mean_edge_length(p, 1.0, wm) == pytest.approx(0.9)


def test_ideal_counts_of_the_shipped_maps():
    for name, target in (("open_room", 78), ("structured", 82)):
        ic = ideal_count(map_from_path(f"configs/{name}.toml")[1], 1.0)
        assert ic["area_formula"] == pytest.approx(target, abs=1.0)
        assert ic["lattice_points"] <= ic["lattice_points_max"]
        assert abs(ic["lattice_points"] - target) < 0.15 * target
    small = ideal_count(map_from_path("configs/small.toml")[1], 1.0)
    assert 12 <= small["area_formula"] <= 15
    # spacing scales the formula with 1/d^2
    wm = room(10, 10)
    assert ideal_count(wm, 0.5)["area_formula"] == pytest.approx(
        4 * ideal_count(wm, 1.0)["area_formula"])
    with pytest.raises(ValueError, match="spacing"):
        ideal_count(wm, 0.0)


def test_lockstep_gate():
    g = LockstepGate(timeout_s=2.0)
    g.open(5, {1, 2, 3}, now=100.0)
    assert not g.ready(100.1)
    assert not g.answer(1, 4)          # an old tick does not count
    assert g.answer(1, 5) and g.answer(2, -1)
    assert g.waiting == {3} and not g.ready(100.2)
    g.forget(3)                        # its agent left
    assert g.ready(100.2)
    g.open(6, {1, 2}, now=200.0)
    g.answer(1, 6)
    assert not g.ready(201.9) and g.ready(202.0) and g.late() == {2}
    assert g.remaining(201.0) == pytest.approx(1.0)


def test_pacer_and_rtf_meter():
    p = Pacer(dt=0.05, rtf=2.0, now=0.0)
    assert not p.due(0.02) and p.due(0.025)
    p.done(0.025)
    assert p.wait_time(0.03) == pytest.approx(0.02)
    p.done(10.0)                       # far behind: the backlog is dropped
    assert p.next_due() > 10.0
    m = RtfMeter()
    for k in range(10):
        m.add(k * 0.05, k * 0.1)
    assert m.rtf == pytest.approx(0.5)

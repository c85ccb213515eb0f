"""pymunk dynamics: kinematics, limits, walls, robot contacts, spawning near an occupied source."""
from __future__ import annotations

import math

import numpy as np
import pytest

from swarmcover.world.maps import map_from_path
from swarmcover.world.physics import Physics

R = 0.06


@pytest.fixture
def ph():
    wm = map_from_path("configs/small.toml")[1]   # 4 x 3 m, obstacle [2,2.5]x[1.25,1.75]
    return Physics(wm, radius=R, v_max=0.5, w_max=2.0, dt=0.05, substeps=4)


def run(ph, cmd, n):
    for _ in range(n):
        ph.step(np.asarray(cmd, float))


def test_differential_drive_follows_the_unicycle_arc(ph):
    x0, y0, th0 = ph.add(1, 1.0, 1.0, 0.3, "diffdrive", exact=True)
    v, w, T = 0.2, 0.8, 1.5
    run(ph, [[v, 0.0, w]], int(round(T / 0.05)))
    _, pos, th = ph.state()
    ex = x0 + v / w * (math.sin(th0 + w * T) - math.sin(th0))
    ey = y0 - v / w * (math.cos(th0 + w * T) - math.cos(th0))
    lag = 0.05 / 4   # velocities take effect one substep late
    assert th[0] == pytest.approx(th0 + w * (T - lag), abs=1e-6)
    assert math.hypot(pos[0, 0] - ex, pos[0, 1] - ey) < 2 * v * lag


def test_diffdrive_limits_and_no_sideways_motion(ph):
    ph.add(1, 1.0, 1.0, 0.0, "diffdrive", exact=True)
    run(ph, [[5.0, 3.0, 0.0]], 20)          # vy ignored, vx clamped to v_max
    _, pos, th = ph.state()
    assert pos[0, 1] == pytest.approx(1.0, abs=1e-9)
    assert 1.0 + 0.5 * 0.95 - 0.02 < pos[0, 0] <= 1.0 + 0.5 * 1.0 + 1e-9
    run(ph, [[0.0, 0.0, 50.0]], 10)         # wz clamped to w_max
    _, _, th = ph.state()
    assert th[0] == pytest.approx(2.0 * 0.5, abs=0.03)


def test_holonomic_robots_never_rotate_and_speed_is_clamped(ph):
    ph.add(1, 1.0, 1.0, 1.2, "holonomic", exact=True)
    run(ph, [[3.0, 4.0, 2.0]], 20)          # |v| = 5 -> 0.5 along (0.6, 0.8)
    _, pos, th = ph.state()
    assert th[0] == 0.0
    d = pos[0] - [1.0, 1.0]
    assert d / np.linalg.norm(d) == pytest.approx([0.6, 0.8], abs=1e-9)
    assert 0.45 < np.linalg.norm(d) <= 0.5 + 1e-9


def test_walls_stop_robots_and_they_slide_along(ph):
    ph.add(1, 0.5, 2.5, 0.0, "holonomic", exact=True)
    run(ph, [[0.0, 0.5, 0.0]], 60)          # into the top wall (y = 3)
    _, pos, _ = ph.state()
    assert 3.0 - R - 0.005 < pos[0, 1] <= 3.0 - R + 2e-3
    run(ph, [[0.3, 0.3, 0.0]], 20)          # slides right along the wall
    _, pos2, _ = ph.state()
    assert pos2[0, 0] - pos[0, 0] > 0.25 and pos2[0, 1] <= 3.0 - R + 2e-3
    ph.add(2, 1.5, 1.5, 0.0, "holonomic", exact=True)
    run(ph, [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]], 60)   # into the obstacle's left face x = 2
    _, pos, _ = ph.state()
    assert 2.0 - R - 0.005 < pos[1, 0] <= 2.0 - R + 2e-3


def test_robots_collide_and_push(ph):
    ph.add(1, 0.5, 0.5, 0.0, "holonomic", exact=True)
    ph.add(2, 0.8, 0.5, 0.0, "holonomic", exact=True)
    run(ph, [[0.4, 0.0, 0.0], [0.0, 0.0, 0.0]], 30)
    _, pos, _ = ph.state()
    assert np.linalg.norm(pos[1] - pos[0]) > 2 * R - 0.005   # no overlap
    assert pos[1, 0] > 0.85                                  # the standing one was pushed


def test_spawning_at_an_occupied_source_never_overlaps(ph):
    src = ph.wm.sources[0]
    placed = [ph.add(k, src[0], src[1], 0.0, "holonomic")[:2] for k in range(12)]
    assert placed[0] == pytest.approx(tuple(src[:2]))
    p = np.array(placed)
    d = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, 9)
    assert d.min() >= 2 * R
    assert ph.wm.is_free(p, margin=R).all()
    assert np.linalg.norm(p - src[:2], axis=1).max() < 0.5    # nearest free spots


def test_spawn_near_a_wall_keeps_clearance_and_remove(ph):
    x, y, _ = ph.add(5, 0.01, 1.0, 0.0, "holonomic")
    assert x >= R and ph.wm.is_free([[x, y]], margin=R)[0]
    assert ph.remove(5) and not ph.has(5) and not ph.remove(5)
    assert ph.ids == []
    with pytest.raises(ValueError, match="already"):
        ph.add(1, 1, 1, 0, "holonomic")
        ph.add(1, 1, 1, 0, "holonomic")


def test_same_operations_same_trajectories():
    def once():
        wm = map_from_path("configs/small.toml")[1]
        p = Physics(wm, radius=R, v_max=0.5, w_max=2.0, dt=0.05, actuation_noise=0.1,
                    rng=np.random.default_rng(4))
        for k in range(6):
            p.add(k, 0.3, 1.5, 0.0, "diffdrive" if k % 2 else "holonomic")
        rng = np.random.default_rng(9)
        for _ in range(100):
            p.step(rng.uniform(-0.5, 0.5, (6, 3)))
        return p.state()
    a, b = once(), once()
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])

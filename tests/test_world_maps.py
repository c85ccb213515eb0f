"""Maps: ROS map_server loading (walls where the image is dark), robustness, rasters."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from swarmcover.world.config import ConfigError, load_config
from swarmcover.world.maps import (WorldMap, build_map, fill_ring, load_ros_map, points_in_polygon,
                        segments_intersect)

FREE, OCC, UNK = 254, 0, 205


def ros_map(tmp_path, img: np.ndarray, res=0.1, origin=(1.0, 2.0, 0.0), negate=0, fmt="pgm",
            extra=""):
    name = f"m.{fmt}"
    Image.fromarray(img.astype(np.uint8)).save(tmp_path / name)
    y = tmp_path / "m.yaml"
    y.write_text(f"image: {name}\nresolution: {res}\norigin: {list(origin)}\n"
                 f"negate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra}")
    return y


def world_of(path, **kw):
    b, holes, info = load_ros_map(path, **kw)
    return WorldMap("t", b, holes, np.zeros((0, 3)), True, info)


def test_pgm_walls_where_the_image_is_dark(tmp_path):
    img = np.full((80, 100), FREE)           # 10 m x 8 m, lower-left corner at (1, 2)
    img[20:40, 30:50] = OCC                  # rows 20..39 from the top, cols 30..49
    img[60:80, 0:10] = UNK                   # unknown bottom-left corner: not free
    img[5, 80] = OCC                         # a one-cell speck: noise, dropped
    wm = world_of(ros_map(tmp_path, img))
    # the dark block spans x in [1+3.0, 1+5.0], y in [2+8-4.0, 2+8-2.0] = [6, 8]
    assert len(wm.obstacles) == 1
    ob = wm.obstacles[0]
    assert np.allclose(ob.min(0), [4.0, 6.0], atol=0.1)
    assert np.allclose(ob.max(0), [6.0, 8.0], atol=0.1)
    assert not wm.contains([[5.0, 7.0]])[0]                   # inside the block
    assert wm.contains([[3.0, 7.0], [8.0, 4.0], [9.05, 9.5]]).all()
    assert not wm.contains([[1.5, 2.5]])[0]                  # unknown corner
    assert not wm.contains([[0.5, 5.0], [11.5, 5.0]]).any()  # outside the image
    # the open image border is closed by the boundary: the map extent is the image
    x0, y0, x1, y1 = wm.bounds
    assert (x0, y0, x1, y1) == pytest.approx((1.0, 2.0, 11.0, 10.0), abs=0.1)
    # free area: 80 m^2 - 4 (block) - 2 (unknown corner), up to chamfered corners
    assert wm.free_area == pytest.approx(74.0, abs=0.3)


def test_negate_origin_yaw_and_png(tmp_path):
    img = np.full((40, 60), FREE)
    img[10:20, 10:20] = OCC
    inv = 255 - img
    a = world_of(ros_map(tmp_path, img, origin=(0, 0, 0)))
    b = world_of(ros_map(tmp_path, inv, origin=(0, 0, 0), negate=1, fmt="png"))
    assert np.allclose(a.obstacles[0].min(0), b.obstacles[0].min(0))
    # yaw = 90 deg: the map is rotated CCW about the origin
    c = world_of(ros_map(tmp_path, img, origin=(0, 0, math.pi / 2)))
    x0, y0, x1, y1 = c.bounds
    assert (x0, y0, x1, y1) == pytest.approx((-4.0, 0.0, 0.0, 6.0), abs=0.1)


def test_region_with_the_source_is_traced_and_others_ignored(tmp_path):
    img = np.full((50, 100), OCC)
    img[5:45, 5:40] = FREE        # small room (left)
    img[5:45, 50:95] = FREE       # larger room (right)
    y = ros_map(tmp_path, img, origin=(0, 0, 0))
    big = world_of(y)
    assert big.bounds[0] > 4.5                                   # largest room by default
    small = world_of(y, seeds=[(1.0, 2.5)])
    assert small.bounds[2] < 4.5                                 # the room of the source
    with pytest.raises(ConfigError, match="not on a free cell"):
        world_of(y, seeds=[(4.5, 2.5)])


def test_many_blobs_and_a_vertex_cap(tmp_path):
    rng = np.random.default_rng(0)
    img = np.full((300, 300), FREE)
    for _ in range(400):
        r, c = rng.integers(5, 290, 2)
        s = rng.integers(1, 7)
        img[r:r + s, c:c + s] = OCC
    y = ros_map(tmp_path, img, res=0.05)
    wm = world_of(y, max_vertices=400)
    assert wm.n_vertices <= 400
    unc = world_of(y)
    assert 50 < len(unc.obstacles) <= 400 and unc.n_vertices <= 20_000
    # blobs below min_hole_area vanish
    assert len(world_of(y, min_hole_area=0.05).obstacles) < len(unc.obstacles)


def test_huge_image_is_block_reduced(tmp_path):
    img = np.full((2000, 2000), FREE, np.uint8)
    img[500:1000, 500:1000] = OCC
    y = ros_map(tmp_path, img, res=0.01, origin=(0, 0, 0))
    b, holes, info = load_ros_map(y, max_cells=250_000)
    assert info["reduce"] == 4 and info["cells"] == (500, 500)
    assert len(holes) == 1
    assert np.allclose(holes[0].min(0), [5.0, 10.0], atol=0.06)
    assert np.allclose(holes[0].max(0), [10.0, 15.0], atol=0.06)


def test_config_points_at_a_ros_map_and_adds_obstacles(tmp_path):
    img = np.full((40, 60), FREE)
    ros_map(tmp_path, img, origin=(0, 0, 0))
    c = tmp_path / "c.toml"
    c.write_text('[map]\nros_map = "m.yaml"\nobstacles = [{type="rect", min=[2, 1], max=[3, 2]}]\n'
                 'sources = [{x = 0.5, y = 0.5}]\n')
    wm = build_map(load_config(c))
    assert not wm.contains([[2.5, 1.5]])[0] and wm.contains([[4.0, 3.0]])[0]
    assert wm.free_area == pytest.approx(24.0 - 1.0, abs=0.05)


def test_shipped_office_map():
    from swarmcover.world.maps import map_from_path
    cfg, wm = map_from_path("configs/office_ros.toml")
    assert len(wm.obstacles) == 2                 # pillar and desk; noise specks dropped
    assert not wm.contains([[2.6, 3.1], [7.2, 4.3], [5.05, 1.0], [8.0, 0.7]]).any()
    assert wm.contains([[5.05, 3.0], [1.0, 1.0], [8.0, 3.0]]).all()   # door is open
    assert 48 < wm.free_area < 50


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.3, 1.0), min_size=3, max_size=12),
       st.floats(-0.3, 0.3), st.floats(0.04, 0.2))
def test_raster_fill_matches_point_in_polygon(radii, shift, cell):
    n = len(radii)
    a = np.arange(n) * 2 * math.pi / n
    poly = np.stack([2 + shift + np.array(radii) * np.cos(a), 2 + np.array(radii) * np.sin(a)], 1)
    nx = ny = int(4 / cell)
    m = fill_ring(poly, 0.0, 0.0, cell, nx, ny)
    jj, ii = np.mgrid[0:ny, 0:nx]
    c = np.stack([(ii.ravel() + 0.5) * cell, (jj.ravel() + 0.5) * cell], 1)
    ref = points_in_polygon(c, poly).reshape(ny, nx)
    assert (m != ref).sum() <= 2   # only centres lying on an edge may differ


def test_segments_intersect_basic():
    p0, p1 = np.array([[0.0, 0.0]]), np.array([[2.0, 0.0]])
    assert segments_intersect(p0, p1, np.array([[1.0, -1.0]]), np.array([[1.0, 1.0]]))[0]
    assert not segments_intersect(p0, p1, np.array([[3.0, -1.0]]), np.array([[3.0, 1.0]]))[0]
    assert segments_intersect(p0, p1, np.array([[1.0, 0.0]]), np.array([[1.0, 1.0]]))[0]


def test_map_from_world_info_round_trip():
    from swarmcover.bus.messages import WorldInfo, decode
    from swarmcover.world.maps import map_from_info, map_from_path
    cfg, wm = map_from_path("configs/structured.toml")
    info = decode(WorldInfo(name=wm.name, rv=1.0, dt=0.05, **wm.info_fields()).validate().encode())
    wm2 = map_from_info(info)
    assert np.array_equal(wm2.boundary, wm.boundary) and len(wm2.obstacles) == 4
    assert wm2.free_area == wm.free_area and np.array_equal(wm2.sources, wm.sources)
    assert np.array_equal(wm2.walls, wm.walls)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000))
def test_ray_lengths_stop_at_the_first_wall_a_fine_march_meets(seed):
    """ray_lengths against a march in 1 mm steps over random segments: the ray's free run
    ends in the first step that crosses a wall (or at the cap)."""
    from swarmcover.world.maps import ray_lengths
    rng = np.random.default_rng(seed)
    walls = rng.uniform(-2, 2, (int(rng.integers(1, 8)), 4))
    o = rng.uniform(-1, 1, (5, 2))
    a = rng.uniform(-math.pi, math.pi, 5)
    d = np.c_[np.cos(a), np.sin(a)]
    got = ray_lengths(o, d, walls, 3.0)
    t = np.arange(0.0, 3.0005, 0.001)
    for k in range(5):
        pts = o[k] + t[:, None] * d[k]
        hit = segments_intersect(pts[:-1, None, :], pts[1:, None, :],
                                 walls[None, :, 0:2], walls[None, :, 2:4]).any(1)
        want = t[1:][np.argmax(hit)] if hit.any() else 3.0
        assert got[k] == pytest.approx(want, abs=0.0011)

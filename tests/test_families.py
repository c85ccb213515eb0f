"""bench/families.py: random maps of the judged families (caves, corridors, pillar halls,
office floors) at the judged scale, written as ROS map_server maps with their run configs.
The campaign's runs are the bench's; here, that what it writes is the map it means."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from bench import families
from swarmcover.world.config import load_config
from swarmcover.world.groundtruth import euler_bound
from swarmcover.world.maps import build_map


@pytest.mark.parametrize("index", range(8))
def test_each_family_writes_one_connected_map_at_the_judged_scale(tmp_path, index):
    """Maps 0-7 of campaign 0 (two of each family, in order) load as written: one free
    component, the source in it with 0.4 m clearance, the family's noise, and an Euler
    bound of 100-300 robots at rv = 1 m (the judged maps hold 150-700 robots; a swarm
    uses 1.2-1.6 times the bound)."""
    path, m = families.write_config(0, index, tmp_path)
    assert m.family == families.FAMILIES[index % 4]
    _, parts = ndimage.label(m.free)
    assert parts == 1
    cfg = load_config(str(path))
    wm = build_map(cfg)
    assert wm.free_area == pytest.approx(m.free.sum() * families.RES ** 2, rel=0.02)
    x, y, _ = cfg.map.sources[0]
    clear = ndimage.distance_transform_edt(m.free) * families.RES
    assert clear[int(y / families.RES), int(x / families.RES)] >= 0.4 - families.RES
    assert cfg.sensing.noise_deg == (0.5 if index % 2 else 0.0)
    assert 100 <= euler_bound(wm, 1.0)["robots"] <= 300


def test_the_same_seed_and_index_give_the_same_map_and_another_seed_another():
    a, b = families.make_family_map(3, 5), families.make_family_map(3, 5)
    assert np.array_equal(a.free, b.free) and a.source == b.source and a.about == b.about
    c = families.make_family_map(4, 5)
    assert c.family == a.family and not (c.free.shape == a.free.shape
                                         and np.array_equal(c.free, a.free))


def test_families_flag_picks_the_families_in_turn():
    fams = ("office", "cave")
    assert [families.make_family_map(0, i, fams).family for i in range(4)] == \
        ["office", "cave", "office", "cave"]


@pytest.mark.parametrize("argv", [["--maps", "0"], ["--jobs", "0"], ["--families", "maze"]])
def test_bad_flags_are_usage_errors_naming_the_flag(argv, capsys):
    with pytest.raises(SystemExit) as e:
        families.main(argv)
    assert e.value.code == 2
    assert argv[0] in capsys.readouterr().err


def _room_with_wall(door: bool) -> np.ndarray:
    """A 6 m x 4 m room (0.2 m rim) split at x = 3 m by a wall 0.1 m (two cells) thick,
    with a 0.4 m door in it or none."""
    xx, yy = families._grid(6.4, 4.4)
    free = (xx > 0.2) & (xx < 6.2) & (yy > 0.2) & (yy < 4.2)
    free &= ~((xx > 3.15) & (xx < 3.25))
    if door:
        free |= (xx > 3.1) & (xx < 3.3) & (yy > 2.0) & (yy < 2.4)
    return free


@pytest.mark.parametrize("deg", [-40.0, -23.0, -5.0, 5.0, 17.0, 31.0, 40.0, 45.0])
def test_a_turned_map_keeps_its_walls_closed_and_its_doors_open(deg):
    """turn_raster draws the map again on its grid: the area stays (within a cell's
    width along the boundary), a wall two cells thick still divides the room, and a
    0.4 m door in it still joins the halves for a robot of radius 0.06 m."""
    shut, door = _room_with_wall(False), _room_with_wall(True)
    turned = families.turn_raster(shut, deg)
    # the wall stays closed: without the door the largest half is all that is kept
    assert turned.sum() == pytest.approx(shut.sum() / 2, rel=0.06)
    t_door = families.turn_raster(door, deg)
    assert t_door.sum() == pytest.approx(door.sum(), rel=0.03)
    reach = ndimage.binary_erosion(t_door, structure=np.ones((3, 3)), iterations=1)
    assert ndimage.label(reach)[1] == 1


def test_turned_maps_are_the_same_maps_turned_and_named_so(tmp_path):
    """Maps 0-3 of campaign 0, turned: each has the area of its unturned map (within
    1%), one free part, a source with 0.4 m clearance, its own name; the unturned map is
    unchanged by the option's existence (its own random stream)."""
    for index in range(4):
        m0 = families.make_family_map(0, index)
        path, m1 = families.write_config(0, index, tmp_path, turn=True)
        assert path.name.endswith("_turned.toml") and "turned" in m1.about
        assert m1.family == m0.family and m1.noise_deg == m0.noise_deg
        assert m1.free.sum() == pytest.approx(m0.free.sum(), rel=0.01)
        assert ndimage.label(m1.free)[1] == 1
        wm = build_map(load_config(str(path)))
        assert wm.free_area == pytest.approx(m1.free.sum() * families.RES ** 2, rel=0.02)
        assert not (m1.free.shape == m0.free.shape and np.array_equal(m1.free, m0.free))
        x, y, _ = m1.source
        clear = ndimage.distance_transform_edt(m1.free) * families.RES
        assert clear[int(y / families.RES), int(x / families.RES)] >= 0.4 - families.RES
        again = families.make_family_map(0, index)
        assert np.array_equal(again.free, m0.free) and again.source == m0.source

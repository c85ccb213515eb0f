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

"""bench/unseen.py: the whole swarm on bench/truth.py's random maps, written as run configs
(polygons, or turned ROS map_server maps) and judged by the world's ground truth."""
from __future__ import annotations

import math

import pytest

from bench import unseen
from bench.truth import _area, make_map
from swarmcover.world.config import load_config
from swarmcover.world.maps import build_map


def _free(pm) -> float:
    return abs(_area(pm.outer)) - sum(abs(_area(h)) for h in pm.holes)


@pytest.mark.parametrize("index, ros", [(0, False), (1, True), (5, True), (6, False)])
def test_a_map_written_as_a_config_loads_as_the_same_free_area_and_source(tmp_path, index, ros):
    """The config (boundary and polygon obstacles, or PGM + YAML at 0.05 m) is what the
    world loads: the same free area as the campaign's map, the source where it was, its
    heading inside the config's range (map 6's faces the wall at exactly pi)."""
    path, case = unseen.write_config(0, index, ros, tmp_path)
    cfg = load_config(str(path))
    wm = build_map(cfg)
    want = _free(make_map(0, index, unseen.CELL if ros else 0.0).pm)
    assert wm.free_area == pytest.approx(want, abs=1e-3)       # vertices written to 0.1 mm
    assert tuple(wm.sources[0][:2]) == pytest.approx(case.source, abs=1e-4)
    assert abs(cfg.map.sources[0][2]) <= math.pi
    assert cfg.sensing.noise_deg == case.noise_deg


@pytest.mark.parametrize("index", [0, 145])
def test_doors_writes_the_door_campaign_s_map(tmp_path, index):
    """--doors: the config is bench/truth.py --doors's map (two rooms, a 0.40-0.50 rv
    door; map 145 is the flush door of a 0.3 m wall that was once certified at 59.3%), not
    the default campaign's map of that index."""
    path, case = unseen.write_config(0, index, False, tmp_path, doors=True)
    assert path.name == f"unseen_s0_m{index}_doors.toml"
    assert case.kind == "two_rooms" and 0.40 <= case.door_w <= 0.50
    wm = build_map(load_config(str(path)))
    assert wm.free_area == pytest.approx(_free(make_map(0, index, doors=True).pm), abs=1e-3)
    assert wm.free_area != pytest.approx(_free(make_map(0, index).pm), abs=1e-3)


def test_one_map_runs_the_swarm_to_a_certificate_ground_truth_agrees_with(tmp_path):
    """Map 2 (a 12.7 m^2 room, 25 robots) end to end, in-process: certified, its complex
    covering the room by ground truth, no false certificate, and the row names its config."""
    row = unseen.run_map((0, 2, False, str(tmp_path), 300.0))
    assert "error" not in row, row.get("error")
    assert row["certified"] and not row["false_certificate"]
    assert row["coverage_complex"] >= 0.995      # the certified complex's own robots
    assert row["config"].endswith("unseen_s0_m2.toml")
    s = unseen.summarise([row, dict(row, index=3, certified=False, false_certificate=False),
                          dict(index=4, error="boom")])
    assert (s["certified"], s["errors"], s["not_certified"], s["false_certificates"]) == \
        (1, 1, [3], 0)
    # every side the certificate rests on is audited by ground truth, per reason
    assert row["fence_audit"] and sum(a["sides"] for a in row["fence_audit"].values()) > 0
    assert s["closed_sides"] == {
        why: dict(sides=a["sides"], room_behind=a["room_behind"],
                  room_uncovered=a["room_uncovered"], maps=1)
        for why, a in row["fence_audit"].items()}


def test_set_writes_coordinator_fields_the_config_check_reads(tmp_path):
    """--set FIELD=VALUE lands in every map's [coordinator] section, and the run config's
    own validation reads it (an experiment on the product, not on a copy of its rules)."""
    from swarmcover.coordinator.config import CoordinatorConfig

    def coord(path):
        return CoordinatorConfig.from_section(load_config(str(path)).section("coordinator"), 1.0)
    path, _ = unseen.write_config(0, 3, False, tmp_path, ("sweep_lenses = false",))
    assert coord(path).sweep_lenses is False and coord(path).topology().sweep_lenses is False
    path, _ = unseen.write_config(0, 3, False, tmp_path)
    assert coord(path).sweep_lenses is True


@pytest.mark.parametrize("argv", [["--maps", "0"], ["--jobs", "0"], ["--ros", "-1"],
                                  ["--set", "sweep_lenses"]])
def test_bad_flags_are_usage_errors_naming_the_flag(argv, capsys):
    with pytest.raises(SystemExit) as e:
        unseen.main(argv)
    assert e.value.code == 2
    assert argv[0] in capsys.readouterr().err

"""Run-config loading: defaults, round trip, and errors that name file, section, field, value."""
from __future__ import annotations

from pathlib import Path

import pytest

from swarmcover.world.config import ConfigError, load_config, loads_config, to_toml
from swarmcover.world.maps import build_map, map_from_path, read_ros_yaml

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"

BASE = """
name = "t"
rv = 1.0
[map]
boundary = [[0, 0], [4, 0], [4, 3], [0, 3]]
sources = [{x = 0.5, y = 1.5}]
"""


def write(tmp_path, text, name="c.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("name", ["open_room", "structured", "small", "office_ros"])
def test_shipped_configs_load_and_round_trip(name):
    cfg = load_config(CONFIGS / f"{name}.toml")
    assert cfg.rv == 1.0
    again = loads_config(to_toml(cfg))
    assert again.map == cfg.map and again.robots == cfg.robots
    assert again.sensing == cfg.sensing and again.world == cfg.world
    assert again.name == cfg.name and again.sections == cfg.sections


@pytest.mark.parametrize("path", sorted((ROOT / "bench" / "configs").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_bench_configs_load_and_build_their_maps(path):
    """The scale benchmarks' configs (not run in the tests: each takes minutes to tens of
    minutes) stay valid as the config schema changes."""
    cfg = load_config(path)
    wm = build_map(cfg)
    assert cfg.rv == 1.0 and len(wm.sources) >= 1


def test_the_stored_office_floor_is_what_its_generator_writes(tmp_path):
    import subprocess
    import sys
    maps = ROOT / "bench" / "configs" / "maps"
    subprocess.run([sys.executable, str(maps / "make_office.py"), "0", str(tmp_path / "o")],
                   check=True, capture_output=True, timeout=120)
    assert (tmp_path / "o.pgm").read_bytes() == (maps / "office_floor.pgm").read_bytes()


def test_defaults_and_foreign_sections_kept_raw(tmp_path):
    cfg = load_config(write(tmp_path, BASE + '[coordinator]\nfoo = 1\n[agent]\nbar = {x = 2}\n'))
    assert cfg.world.mode == "lockstep" and cfg.world.dt == 0.05
    assert cfg.robots.kind == "holonomic" and cfg.sensing.n_touch == 8
    assert cfg.section("coordinator") == {"foo": 1}
    assert cfg.section("agent") == {"bar": {"x": 2}}
    assert cfg.section("hwbridge") == {}
    assert loads_config(to_toml(cfg)).sections == cfg.sections


@pytest.mark.parametrize("extra,section,field,value", [
    ("[world]\nmodee = 'lockstep'\n", "world", "modee", "lockstep"),
    ("[world]\nmode = 'fast'\n", "world", "mode", "fast"),
    ("[world]\ndt = -0.1\n", "world", "dt", -0.1),
    ("[robots]\nkind = 'tank'\n", "robots", "kind", "tank"),
    ("[robots]\nradius = 'big'\n", "robots", "radius", "big"),
    ("[sensing]\ndropout = 1.5\n", "sensing", "dropout", 1.5),
    ("[sensing]\nn_touch = 0\n", "sensing", "n_touch", 0),
    ("[world]\nspawn = [{robot = 1, source = 3}]\n", "world", "spawn[0].source", 3),
])
def test_bad_values_name_file_section_field_value(tmp_path, extra, section, field, value):
    p = write(tmp_path, BASE + extra)
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    e = ei.value
    assert (e.section, e.field, e.value) == (section, field, value)
    msg = str(e)
    assert str(p) in msg and f"[{section}]" in msg and field in msg and repr(value) in msg


def test_map_errors(tmp_path):
    with pytest.raises(ConfigError, match=r"\[map\] obstacles\[0\]\.type = 'blob'"):
        load_config(write(tmp_path, BASE.replace("sources", "obstacles = [{type='blob'}]\nsources")))
    with pytest.raises(ConfigError, match="either boundary or ros_map"):
        load_config(write(tmp_path, BASE.replace("sources", "ros_map = 'x.yaml'\nsources")))
    with pytest.raises(ConfigError, match=r"ros_map = 'nope.yaml': file not found"):
        load_config(write(tmp_path, '[map]\nros_map = "nope.yaml"\n'))
    with pytest.raises(ConfigError, match="missing"):
        load_config(write(tmp_path, 'name = "x"\n'))
    with pytest.raises(ConfigError, match=r"\[map\] boundary"):
        load_config(write(tmp_path, '[map]\nboundary = [[0, 0], [1, 1]]\n'))
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(write(tmp_path, '[map\n'))
    with pytest.raises(ConfigError, match="unknown top-level field"):
        load_config(write(tmp_path, 'speed = 3\n' + BASE))
    # a source inside an obstacle is not in free space
    cfg = load_config(write(tmp_path, BASE.replace(
        "sources", "obstacles = [{type='circle', center=[0.5, 1.5], radius=0.3}]\nsources")))
    with pytest.raises(ConfigError, match=r"\[map\] sources\[0\].*not in free space"):
        build_map(cfg)


def test_ros_yaml_errors(tmp_path):
    img = tmp_path / "m.pgm"
    img.write_bytes(b"P5\n2 2\n255\n" + bytes([254, 254, 254, 0]))
    cases = [
        ("image: m.pgm\norigin: [0, 0, 0]\n", "resolution", None),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", "resolution", -1),
        ("image: m.pgm\nresolution: 0.05\norigin: zero\n", "origin", "zero"),
        ("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", "image", "gone.pgm"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 2\n", "negate", 2),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.9\n",
         "free_thresh", 0.9),
    ]
    for text, field, value in cases:
        y = tmp_path / "m.yaml"
        y.write_text(text)
        with pytest.raises(ConfigError) as ei:
            read_ros_yaml(y)
        assert (ei.value.field, ei.value.value) == (field, value), text
        assert str(y) in str(ei.value)


def test_bare_ros_yaml_gets_defaults_and_an_automatic_source():
    cfg, wm = map_from_path(CONFIGS / "maps" / "office.yaml")
    assert cfg.map.ros_map.endswith("office.yaml") and cfg.world.mode == "lockstep"
    assert len(wm.sources) == 1 and wm.info.get("auto_source")
    assert wm.is_free(wm.sources[:, :2], margin=0.5).all()   # well clear of every wall


@pytest.mark.parametrize("extra,section,field,value", [
    ("[coordinater]\nrobots_max = 5\n", "coordinater", "", None),
    ("[run]\nx = 1\n", "run", "", None),
])
def test_unknown_sections_are_errors(tmp_path, extra, section, field, value):
    p = write(tmp_path, BASE + extra)
    with pytest.raises(ConfigError, match="unknown section") as ei:
        load_config(p)
    assert (ei.value.section, ei.value.field, ei.value.value) == (section, field, value)
    assert f"[{section}]" in str(ei.value) and str(p) in str(ei.value)


@pytest.mark.parametrize("text,field", [
    ("rv = nan\n", "rv"),
    ("rv = inf\n", "rv"),
    ("[world]\ndt = nan\n", "dt"),
    ("[world]\ntick_timeout_s = inf\n", "tick_timeout_s"),
    ("[robots]\nv_max = -inf\n", "v_max"),
    ("[sensing]\nnoise_deg = nan\n", "noise_deg"),
])
def test_nan_and_infinities_are_refused(tmp_path, text, field):
    base = BASE.replace('rv = 1.0\n', '') if text.startswith("rv") else BASE
    text = text + base if text.startswith("rv") else base + text
    with pytest.raises(ConfigError, match="not finite") as ei:
        load_config(write(tmp_path, text))
    assert ei.value.field == field


def test_polygons_must_be_simple(tmp_path):
    bowtie = BASE.replace("[[0, 0], [4, 0], [4, 3], [0, 3]]", "[[0, 0], [4, 3], [4, 0], [0, 2]]")
    with pytest.raises(ConfigError, match=r"\[map\] boundary = .*not a simple polygon: edge 0"):
        load_config(write(tmp_path, bowtie))
    obst = BASE.replace("sources", "obstacles = [{type = 'polygon', points = "
                                   "[[1, 1], [2, 2], [2, 1], [1, 2]]}]\nsources")
    with pytest.raises(ConfigError, match=r"\[map\] obstacles\[0\]\.points = .*not a simple"):
        load_config(write(tmp_path, obst))
    # collinear vertices and a non-convex simple polygon are fine
    ok = BASE.replace("[[0, 0], [4, 0], [4, 3], [0, 3]]",
                      "[[0, 0], [2, 0], [4, 0], [4, 3], [2, 1], [0, 3]]")
    assert len(load_config(write(tmp_path, ok)).map.boundary) == 6


def test_map_size_is_bounded_with_the_limit_stated(tmp_path):
    from swarmcover.world.maps import MAX_MAP_AREA_RV2, MAX_MAP_SIDE_RV
    huge = BASE.replace("[[0, 0], [4, 0], [4, 3], [0, 3]]",
                        "[[0, 0], [1e6, 0], [1e6, 1e6], [0, 1e6]]")
    with pytest.raises(ConfigError, match=f"limit of {MAX_MAP_SIDE_RV:g} rv") as ei:
        build_map(load_config(write(tmp_path, huge)))
    assert (ei.value.section, ei.value.field) == ("map", "boundary")
    wide = BASE.replace("[[0, 0], [4, 0], [4, 3], [0, 3]]",
                        "[[0, 0], [1000, 0], [1000, 100], [0, 100]]")
    with pytest.raises(ConfigError, match=f"limit of {MAX_MAP_AREA_RV2:g} rv"):
        build_map(load_config(write(tmp_path, wide)))
    # the same map is fine with a larger rv (the limits are in rv)
    assert build_map(load_config(write(tmp_path, wide.replace("rv = 1.0", "rv = 5.0")))) \
        .bounds == (0.0, 0.0, 1000.0, 100.0)


def test_ros_map_size_is_bounded_before_pixels_are_read(tmp_path):
    img = tmp_path / "m.pgm"
    img.write_bytes(b"P5\n20000 20000\n255\n" + bytes(1000))     # 1 KB claiming 400 M pixels
    y = tmp_path / "m.yaml"
    y.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(ConfigError, match="limit") as ei:
        map_from_path(y)
    assert (ei.value.section, ei.value.field) == ("ros_map", "image")
    img.write_bytes((CONFIGS / "maps" / "office.pgm").read_bytes())
    y.write_text("image: m.pgm\nresolution: 100000\norigin: [0, 0, 0]\n")
    with pytest.raises(ConfigError, match="limit of 2000 rv") as ei:
        map_from_path(y)
    assert (ei.value.section, ei.value.field, ei.value.value) == ("ros_map", "resolution", 100000)


def test_one_style_for_every_section():
    """[map]..[world], [agent], [coordinator] and [hwbridge] raise the same ConfigError with
    the same one-line message: file: [section] field = value: reason."""
    from swarmcover.agents.params import ParamError, from_toml_text
    from swarmcover.bus.configcheck import ConfigError as Common
    from swarmcover.bus.configcheck import self_crossing
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.hwbridge import config as hwconfig
    assert ConfigError is Common and hwconfig.ConfigError is Common
    assert issubclass(ParamError, Common)
    errs = []
    for make in (lambda: loads_config(BASE + "[world]\ndt = nan\n", "f.toml"),
                 lambda: from_toml_text(BASE + "[agent]\ng0 = nan\n", "f.toml"),
                 lambda: CoordinatorConfig.from_section({"settle_s": float("nan")}, 1.0, "f.toml"),
                 lambda: hwconfig.loads(BASE + '[hwbridge]\nkp = nan\n[[hwbridge.robots]]\n'
                                                'id = 1\nbody = "b"\n', "f.toml")):
        with pytest.raises(Common) as ei:
            make()
        errs.append((ei.value.file, ei.value.section, str(ei.value)))
    assert errs == [("f.toml", "world", "f.toml: [world] dt = nan: not finite"),
                    ("f.toml", "agent", "f.toml: [agent] g0 = nan: not finite"),
                    ("f.toml", "coordinator", "f.toml: [coordinator] settle_s = nan: not finite"),
                    ("f.toml", "hwbridge", "f.toml: [hwbridge] kp = nan: not finite")]
    # simple-polygon test: collinear runs are fine, folds and touching edges are not
    assert self_crossing([[0, 0], [1, 0], [2, 0], [2, 1], [0, 1]]) is None
    assert self_crossing([[0, 0], [2, 0], [1, 0], [1, 1]]) is not None        # folds back
    assert self_crossing([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]]) is not None  # a vertex on an edge

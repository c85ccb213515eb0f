"""The config reference: `swarmcover config defaults` is a complete, valid run config with
every field of every section; docs/config.md is current; `config check` names errors."""
from __future__ import annotations

import dataclasses
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from swarmcover.configref import check_text, defaults_toml, docs_markdown, sections

ROOT = Path(__file__).resolve().parent.parent


def _uncomment_optional(text: str) -> str:
    """Turn the commented-out [hwbridge] tables on (as a user would for live robots)."""
    out, on = [], False
    for line in text.splitlines():
        if line.startswith("# [hwbridge]"):
            on = True
        if on and line.startswith("# ") and not line.startswith(("# ----", "# Only", "#      ")):
            line = line[2:]
        out.append(line)
    return "\n".join(out) + "\n"


def test_defaults_parse_back_as_a_valid_config_with_every_default():
    from swarmcover.agents.params import AgentParams, from_config
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.world.config import RobotsConfig, SensingConfig, WorldConfig, loads_config
    text = defaults_toml()
    assert check_text(text) == ["map", "robots", "sensing", "world", "agent", "coordinator"]
    raw = tomllib.loads(text)
    cfg = loads_config(text)
    assert cfg.robots == RobotsConfig() and cfg.sensing == SensingConfig()
    assert cfg.world == WorldConfig()
    assert from_config(raw) == AgentParams()
    assert CoordinatorConfig.from_section(raw["coordinator"], 1.0) == CoordinatorConfig()
    # every field of every owner's dataclass is in the file
    assert set(raw["agent"]) == {f.name for f in dataclasses.fields(AgentParams)} - {
        "kind", "v_max", "w_max", "radius", "rv", "n_touch", "dt"}
    assert set(raw["coordinator"]) == {f.name for f in dataclasses.fields(CoordinatorConfig)} - {"rv"}
    assert set(raw["world"]) == {f.name for f in dataclasses.fields(WorldConfig)}


def test_the_commented_hwbridge_tables_are_valid_once_uncommented():
    from swarmcover.hwbridge.config import BridgeConfig, loads
    text = _uncomment_optional(defaults_toml())
    assert "hwbridge" in check_text(text)
    b = loads(text)
    assert b.robots[0].id == 100 and b.robots[0].body == "scarab1"
    assert (b.kp, b.deadman_s, b.fake) == (3.0, 0.3, BridgeConfig(
        path="", name="", rv=1.0, robots=()).fake)


def test_every_field_has_an_explanation_and_a_unit_column():
    for sec in sections():
        for f in sec.fields:
            assert f.doc.strip(), f"[{sec.name}] {f.name}: no explanation"
            assert f.unit, f"[{sec.name}] {f.name}: no unit"


def test_docs_config_md_is_current():
    assert (ROOT / "docs" / "config.md").read_text(encoding="utf-8") == docs_markdown(), (
        "docs/config.md is stale: swarmcover config docs > docs/config.md")


def test_cli_defaults_and_check(tmp_path):
    out = subprocess.run([sys.executable, "-m", "swarmcover", "config", "defaults"],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 0 and out.stdout == defaults_toml()
    good = tmp_path / "good.toml"
    good.write_text(out.stdout)
    ok = subprocess.run([sys.executable, "-m", "swarmcover", "config", "check", str(good)],
                        capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert ok.returncode == 0 and "valid" in ok.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(out.stdout.replace("eps_rv = 0.1", "eps_rv = 1.5"))
    r = subprocess.run([sys.executable, "-m", "swarmcover", "config", "check", str(bad)],
                       capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 2 and "eps_rv = 1.5" in r.stderr and "bad.toml" in r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("name", ["small.toml", "tiny.toml", "mixed.toml"])
def test_shipped_configs_check(name):
    path = ROOT / "configs" / name
    check_text(path.read_text(), str(path), str(path.parent))


def test_examples_config_checks_and_topology_example_certifies():
    path = ROOT / "examples" / "l_room.toml"
    checked = check_text(path.read_text(), str(path), str(path.parent))
    assert "coordinator" in checked
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "topology_core.py")],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "10 vertices" in out.stdout and "bounds a 2-chain: True" in out.stdout


def test_completed_resolved_toml_holds_every_agent_and_coordinator_value():
    from swarmcover.agents.params import AgentParams, from_config
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.configref import complete_resolved_toml
    from swarmcover.world.config import load_config, to_toml
    cfg = load_config(ROOT / "configs" / "small.toml")
    full = complete_resolved_toml(to_toml(cfg))
    raw = tomllib.loads(full)
    assert len(raw["agent"]) == len(dataclasses.fields(AgentParams)) - 7
    assert len(raw["coordinator"]) == len(dataclasses.fields(CoordinatorConfig)) - 1
    # the values are the ones the components resolve from the original file
    orig = tomllib.loads((ROOT / "configs" / "small.toml").read_text())
    assert from_config(raw) == from_config(orig)
    assert (CoordinatorConfig.from_section(raw["coordinator"], cfg.rv)
            == CoordinatorConfig.from_section(orig.get("coordinator"), cfg.rv))
    check_text(full)


def test_completed_resolved_toml_holds_every_hwbridge_value_of_a_mixed_run():
    """Every key the bridge reads ([hwbridge], each [[hwbridge.robots]], [hwbridge.fake],
    the transform) is written with the value used, and the file still validates as the same
    config. A robot's ``start`` has no value to write: unset, the fake robot starts at its
    source."""
    from swarmcover.hwbridge.config import FAKE_KEYS, ROBOT_KEYS, TOP_KEYS, TRANSFORM_KEYS, from_dict
    from swarmcover.configref import complete_resolved_toml
    from swarmcover.world.config import load_config, loads_config, to_toml
    src = ROOT / "configs" / "mixed.toml"
    cfg = load_config(src)
    full = complete_resolved_toml(to_toml(cfg), header="swarmcover run: wall timeout 8 s")
    assert full.startswith("# swarmcover run: wall timeout 8 s\n")
    hb = tomllib.loads(full)["hwbridge"]
    assert set(hb) == TOP_KEYS, TOP_KEYS ^ set(hb)
    assert set(hb["transform"]) == TRANSFORM_KEYS and set(hb["fake"]) == FAKE_KEYS
    assert [set(r) for r in hb["robots"]] == [ROBOT_KEYS - {"start"}] * 2
    assert hb["silence_s"] == 0.5 and hb["cmd_ttl_s"] == 0.3 and hb["ros_domain"] == 0
    assert hb["robots"][0]["ros_namespace"] == "/scarab1"  # the "/<body>" default, resolved
    # the same config: the bridge, the world and every other owner read the same values
    orig = tomllib.loads(src.read_text())
    same = dict(path="", raw={})
    assert (dataclasses.replace(from_dict(tomllib.loads(full)), **same)
            == dataclasses.replace(from_dict(orig), **same))
    world = dataclasses.replace(loads_config(full, str(src), str(src.parent)), sections={})
    assert world == dataclasses.replace(cfg, sections={})
    assert "hwbridge" in check_text(full)


def test_the_run_defaults_are_the_topology_cores_but_the_test_drive():
    """One copy of the algorithm's defaults: CoordinatorConfig() hands the topology core
    exactly TopologyParams()'s values, except the test-drive distance (d_td_rv 0.9 against
    the spec's 0.25, a departure the field's comment argues)."""
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.coordinator.topology.params import TopologyParams
    run, core = CoordinatorConfig().topology(), TopologyParams()
    assert dataclasses.replace(run, d_td=core.d_td) == core
    assert run.d_td == pytest.approx(0.9) and core.d_td == pytest.approx(0.25)

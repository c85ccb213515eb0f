"""agents/params.py: defaults, reading the run config, rejecting unknown [agent] keys with
file, section, field and value, and CLI overrides."""
from __future__ import annotations

import math

import pytest

from swarmcover.agents.params import AgentParams, ParamError, from_config, from_toml_text, parse_override


def test_defaults_match_the_brief():
    p = AgentParams()
    assert (p.v_max, p.g0, p.arrive_deg, p.arrive_ticks, p.lost_timeout_s) == (0.5, 0.15, 1.5, 10, 2.0)
    assert (p.scale_step_rv, p.test_drive_speed_frac, p.k_w, p.k_v) == (0.02, 0.5, 1.5, 1.0)
    assert abs(p.tau - math.pi / 8) < 1e-12 and not p.aligned
    assert AgentParams(kind="diffdrive").aligned


def test_reads_shared_sections_and_agent_section():
    p = from_toml_text('rv = 2.0\n[robots]\nkind = "diffdrive"\nv_max = 0.3\nradius = 0.1\n'
                       'extra_world_key = 1\n[sensing]\nn_touch = 16\n[world]\ndt = 0.1\n'
                       '[agent]\ng0 = 0.2\nhold_window = 7\nalign = "off"\n', "run.toml")
    assert (p.rv, p.kind, p.v_max, p.radius, p.n_touch, p.dt) == (2.0, "diffdrive", 0.3, 0.1, 16, 0.1)
    assert (p.g0, p.hold_window, p.align, p.aligned) == (0.2, 7, "off", False)


@pytest.mark.parametrize("text, needle", [
    ('[agent]\nspeed = 1\n', "run.toml: [agent] speed = 1: unknown field"),
    ('[agent]\nv_max = 1.0\n', "run.toml: [agent] v_max = 1.0: unknown field (set it in [robots])"),
    ('[agent]\ng0 = "big"\n', "run.toml: [agent] g0 = 'big': expected a number"),
    ('[agent]\ng0 = -1\n', "g0 = -1.0: must be > 0"),
    ('[robots]\nkind = "legged"\n', "[robots] kind = 'legged': not one of holonomic, diffdrive"),
    ('[agent]\nhold_window = 2.5\n', "run.toml: [agent] hold_window = 2.5: expected an integer"),
    ('agent = 3\n', "[agent]: expected a table"),
    ('rv = [1\n', "run.toml: not valid TOML"),
])
def test_errors_name_file_section_field_and_value(text, needle):
    with pytest.raises(ParamError) as e:
        from_toml_text(text, "run.toml")
    assert needle in str(e.value)


def test_cli_overrides():
    p = parse_override("g0=0.25", AgentParams())
    p = parse_override("align=on", p)
    assert p.g0 == 0.25 and p.align == "on" and p.aligned
    with pytest.raises(ParamError, match=r"--param: \[agent\] nope"):
        parse_override("nope=1", p)
    with pytest.raises(ParamError, match="expected NAME=VALUE"):
        parse_override("g0", p)
    with pytest.raises(ParamError, match="arrive_ticks = 0: must be >= 1"):
        parse_override("arrive_ticks=0", p)
    assert from_config({}, "x") == AgentParams()


def test_the_inproc_loop_and_an_agent_process_read_the_same_params():
    """swarmcover.simloop takes the agents' parameters from the resolved config as a dict;
    an agent process (run --run-config) parses the same config written as resolved.toml.
    On every shipped config the two must agree (issue 17: one runtime)."""
    from pathlib import Path

    from swarmcover.world.config import load_config, to_dict, to_toml
    paths = sorted((Path(__file__).resolve().parent.parent / "configs").glob("*.toml"))
    assert len(paths) >= 8
    for path in paths:
        cfg = load_config(str(path))
        assert from_config(to_dict(cfg), str(path)) == from_toml_text(to_toml(cfg), str(path)), path

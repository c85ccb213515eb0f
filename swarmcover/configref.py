"""``swarmcover config``: the run config reference, from the code that reads the config.

  swarmcover config defaults     a complete, commented TOML: every section and field with
                                 its unit and default (a valid run config on a 3 m x 2 m room)
  swarmcover config docs         the same as Markdown (docs/config.md is this output)
  swarmcover config check FILE   validate a run config the way ``run`` does, section by section

Field names and defaults are read from the dataclasses that validate each section
(world/config.py, agents/params.py, coordinator/config.py, hwbridge/config.py); the
explanations from their inline comments where they have one, else from the table below.
A test fails when a field has neither, or when docs/config.md is out of date.
"""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import io
import re
import sys
import textwrap
import tokenize
from dataclasses import dataclass

from swarmcover.ground.toml import dumps_toml, toml_value

# --------------------------------------------------------------------------- doc table
# (unit, explanation) for fields whose class has no inline comment, and units everywhere
# the name does not say them. "x rv": a multiple of the visibility radius.

DOCS: dict[str, dict[str, tuple[str, str]]] = {
    "": {
        "name": ("-", "run name: the run folder's name and the map's title"),
        "rv": ("m", "visibility radius: robots see (bearings) and link within rv"),
    },
    "map": {
        "boundary": ("m", "outer polygon [[x, y], ...] in the world frame; required unless "
                          "ros_map (no default: the value shown is an example room)"),
        "ros_map": ("path", "a ROS map_server YAML instead of boundary (relative to this file)"),
        "obstacles": ("m", "list of {type = rect, min, max} | {type = circle, center, radius} "
                           "| {type = polygon, points}"),
        "sources": ("m, rad", "base stations [{x, y, theta}, ...]; default [] = the world picks "
                              "one (the value shown is the example's)"),
        "simplify": ("m", "ros_map: Douglas-Peucker tolerance of traced walls; 0 = half a cell"),
        "min_hole_area": ("m^2", "ros_map: ignore non-free specks smaller than this; < 0 = 4 cells"),
        "max_vertices": ("-", "ros_map: cap on traced polygon vertices (tolerance grows)"),
        "max_cells": ("-", "ros_map: larger images are block-reduced to this many cells"),
        "circle_segments": ("-", "polygon sides drawn for a circle obstacle"),
    },
    "robots": {
        "radius": ("m", "body radius"),
        "kind": ("-", "holonomic or diffdrive"),
        "v_max": ("m/s", "speed limit"),
        "w_max": ("rad/s", "turn-rate limit (diffdrive)"),
        "actuation_noise": ("-", "relative Gaussian noise on virtual robots' commanded speeds"),
    },
    "sensing": {
        "rate_hz": ("Hz", "camera (Sense) rate"),
        "noise_deg": ("deg", "bearing noise sigma"),
        "dropout": ("-", "probability a sighting is lost"),
        "robots_occlude": ("-", "robots block lines of sight"),
        "n_touch": ("-", "touch sectors around the body"),
        "touch_skin": ("m", "a contact is felt while the gap to a surface is below this"),
        "idle_keepalive_s": ("sim s", "lockstep: an idle robot (holding still, nothing to do) "
                             "is sensed at least this often; 0: every robot every tick"),
        "idle_wake_s": ("sim s", "lockstep: an idle robot is sensed every tick while it or "
                        "a robot within rv moved within this"),
    },
    "world": {
        "dt": ("s", "control tick"),
        "mode": ("-", "lockstep (wait for every agent each tick) or realtime"),
        "rtf": ("-", "real-time factor in realtime mode (sim s per wall s)"),
        "seed": ("-", "random seed of noise and dropout"),
        "tick_timeout_s": ("wall s", "lockstep: give up waiting for an agent after this"),
        "stale_cmd_s": ("sim s", "a velocity command older than this stops the robot"),
        "pose_rate_hz": ("Hz", "odometry (robot/<id>/odom) rate"),
        "substeps": ("-", "physics substeps per tick"),
        "spawn": ("-", "bodies made at start: [{robot, source, kind, live, pose}, ...]"),
    },
    "agent": {
        "test_drive_speed_frac": ("x v_max", "test-drive (open-loop) speed; 1.0 saved 5-38% of "
                                  "the simulated time but cost 0.7-5.6% more robots (tiny, "
                                  "small, corridor_doors; 21 runs)"),
        "scale_speed_frac": ("x v_max", "scale-correction speed"),
        "stall_s": ("s", "homing whose largest bearing error has not dropped by stall_deg "
                         "within stall_s has stalled (wall, crowd)"),
        "stall_deg": ("deg", "see stall_s"),
        "k_w": ("1/s", "diffdrive heading gain (spec 4.8)"),
        "k_v": ("-", "diffdrive forward-speed gain (spec 4.8)"),
    },
    "coordinator": {
        "n_touch": ("-", "touch sectors the coordinator assumes (match [sensing].n_touch)"),
        "test_drive": ("-", "test-drive new frontier robots to find walls (spec 3.4(iv))"),
        "max_cycles": ("cycles", "stop (not certified) after this many deployment cycles"),
        "eps_rv": ("x rv", "separation margin eps as a fraction of rv (spacing d0 = rv - eps)"),
        "robots_max": ("robots", "stop (not certified) if more robots would be needed"),
    },
    "hwbridge": {
        "mocap": ("-", 'mocap source: {type = "zenoh"} | {type = "scripted", bodies = [...]} '
                       '| {type = "motioncapture", system = ..., hostname = ...}'),
        "up_axis": ("-", 'mocap vertical axis: "z" or "y"'),
        "transform": ("m, rad", "mocap floor -> world: {yaw, tx, ty, scale}"),
        "kp": ("1/s", "twin position gain"),
        "k_theta": ("1/s", "twin heading gain"),
        "feedforward": ("-", "add the measured robot's velocity to the twin command"),
        "teleport_dist": ("x rv", "teleport the twin beyond this position error"),
        "deadman_s": ("s", "stop a live robot after this much command or mocap silence"),
        "geofence": ("m", '"map" (the map boundary), [[x, y], ...] (world) or "none"'),
        "geofence_margin": ("m", "kept from the fence edge"),
        "rate_band_hz": ("Hz", "warn when a body's mocap rate leaves this band"),
        "silence_s": ("s", "warn when a body is silent this long"),
        "rate_hz": ("Hz", "twin sync loop"),
        "cmd_rate_hz": ("Hz", "command output to robots, zeros included"),
        "cmd_ttl_s": ("s", "each LiveCmd's expiry, counted from its receipt: the robot's driver "
                           "stops when it passes, whoever failed (>= 2 command periods)"),
        "pose_rate_hz": ("Hz", "robot/<id>/odom of live robots"),
        "k_omega": ("1/s", "unicycle mapping of a body-frame vy (spec 4.8)"),
        "k_v": ("-", "unicycle mapping gain on vx"),
        "ros_domain": ("-", "ROS_DOMAIN_ID: rmw_zenoh key prefix"),
        "ros_bridge_namespace": ("-", "zenoh-bridge-ros2dds `namespace` setting"),
    },
    "hwbridge.robots": {
        "id": ("-", "robot id (the agent's --id; the coordinator spawns it live)"),
        "body": ("-", "mocap rigid-body name"),
        "kind": ("-", "diffdrive"),
        "output": ("-", '"zenoh" (LiveCmd on live/<id>/cmd) or "ros2" (CDR Twist)'),
        "ros_mapping": ("-", '"ros2dds" or "rmw_zenoh" (output = "ros2")'),
        "ros_namespace": ("-", 'the robot\'s ROS namespace (default "/<body>")'),
        "v_max": ("m/s", "speed limit (default [robots].v_max)"),
        "w_max": ("rad/s", "turn-rate limit (default [robots].w_max)"),
        "source": ("-", "source index its twin spawns at"),
        "fake": ("-", "true: `swarmcover run` starts a stand-in fake-robot"),
        "start": ("m, rad", "fake robot start pose [x, y, theta]; default: the source pose"),
    },
    "hwbridge.fake": {
        "latency_s": ("s", "command latency"),
        "v_noise": ("-", "relative actuation noise (sigma) on v"),
        "w_noise": ("-", "relative actuation noise (sigma) on omega"),
        "slip": ("-", "mean fraction of commanded motion lost to wheel slip"),
        "mocap_rate_hz": ("Hz", "fake mocap rate"),
        "mocap_noise_m": ("m", "fake mocap position noise (sigma)"),
        "mocap_noise_rad": ("rad", "fake mocap heading noise (sigma)"),
        "seed": ("-", "random seed of the stand-in robots"),
        "cmd_timeout_s": ("s", "the stand-in driver's own command timeout: caps any ttl, and "
                               "applies to a Twist or a LiveCmd without one"),
    },
}

_SUFFIX_UNITS = (("_deg", "deg"), ("_hz", "Hz"), ("_s", "s"), ("_rv", "x rv"),
                 ("_frac", "x v_max"), ("_m", "m"), ("_ticks", "ticks"), ("_steps", "steps"),
                 ("_period", "cycles"), ("_cycles", "cycles"))
_UNITS = {"agent": {"g0": "rad", "error_alpha": "-", "hold_window": "ticks", "k_w": "1/s",
                    "k_v": "-", "status_every": "ticks", "align": "-", "hold_rehome": "-"},
          "coordinator": {"w_obstacle": "-", "n_touch": "-", "max_paths": "-",
                          "td_retries": "-", "robots_max": "robots", "redundancy_period": "cycles",
                          "scale_correct_period": "cycles", "push_mode": "-"}}

# fields of a class that a section does not take (owned elsewhere)
_AGENT_SKIP = {"kind", "v_max", "w_max", "radius", "rv", "n_touch", "dt"}


@dataclass
class Field:
    name: str
    default: object          # None: no default (written commented out)
    unit: str
    doc: str


@dataclass
class Section:
    name: str                # "" = top level; "hwbridge.robots" = array of tables
    doc: str
    fields: list[Field]
    optional: bool = False   # written commented out in `config defaults`
    array: bool = False      # [[name]]


def _inline_comments(cls) -> dict[str, str]:
    """{field: the comment after it and on the comment-only lines that follow}."""
    src = inspect.getsource(cls)
    out: dict[str, str] = {}
    current = None
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type == tokenize.NAME and tok.start[1] == 4 and tok.string.isidentifier():
            line = tok.line.strip()
            current = tok.string if re.match(rf"{tok.string}\s*:", line) else None
        elif tok.type == tokenize.COMMENT and current is not None:
            text = tok.string.lstrip("#").strip()
            if tok.start[1] == 4 and not tok.line[:4].strip():  # a comment line between fields
                current = None
                continue
            out[current] = (out.get(current, "") + " " + text).strip()
    return out


def _unit(section: str, name: str, comment: str) -> str:
    u = _UNITS.get(section, {}).get(name)
    if u:
        return u
    for suf, unit in _SUFFIX_UNITS:
        if name.endswith(suf):
            return unit
    m = re.match(r"^(m/s|rad/s|1/s|rad|m|s)(,|\s*$)", comment)
    return m.group(1) if m else "-"


def _from_class(section: str, cls, skip=(), inst=None) -> list[Field]:
    table = DOCS.get(section, {})
    comments = _inline_comments(cls)
    inst = inst if inst is not None else cls()
    out = []
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        default = getattr(inst, f.name)
        unit, doc = table.get(f.name, (None, None))
        if doc is None:
            doc = comments.get(f.name, "")
            unit = _unit(section, f.name, doc)
            doc = re.sub(r"^(m/s|rad/s|1/s|rad|m|s)(,\s*|\s*$)", "", doc)
        out.append(Field(f.name, default, unit or "-", doc))
    return out


def sections() -> list[Section]:
    """Every section of a run config, in file order, with fields, units and defaults."""
    from swarmcover.agents.params import AgentParams
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.hwbridge.config import BridgeConfig, FakeParams, LiveRobot
    from swarmcover.world.config import MapConfig, RobotsConfig, SensingConfig, WorldConfig

    top = [Field("name", "run", *DOCS[""]["name"]), Field("rv", 1.0, *DOCS[""]["rv"])]
    mp = _from_class("map", MapConfig)
    for f in mp:  # a runnable default: the tiny room with one source
        if f.name == "boundary":
            f.default = [[0.0, 0.0], [3.0, 0.0], [3.0, 2.0], [0.0, 2.0]]
        elif f.name == "sources":
            f.default = [{"x": 0.3, "y": 1.0, "theta": 0.0}]
        elif f.name == "obstacles":
            f.default = []
    bridge = _from_class("hwbridge", BridgeConfig,
                         skip={"path", "name", "rv", "robots", "fake", "map_boundary",
                               "map_sources", "raw"},
                         inst=BridgeConfig(path="", name="", rv=1.0, robots=()))
    for f in bridge:
        if f.name == "transform":
            f.default = {"yaw": 0.0, "tx": 0.0, "ty": 0.0, "scale": 1.0}
        elif f.name == "rate_band_hz":
            f.default = list(f.default)
    robot = _from_class("hwbridge.robots", LiveRobot,
                        inst=LiveRobot(id=100, body="scarab1", ros_namespace="/scarab1"))
    for f in robot:
        if f.name == "start":
            f.default = None
    return [
        Section("", "top level", top),
        Section("map", "the environment (world/config.py MapConfig)", mp),
        Section("robots", "robot bodies (world/config.py RobotsConfig)",
                _from_class("robots", RobotsConfig)),
        Section("sensing", "emulated cameras and touch (world/config.py SensingConfig)",
                _from_class("sensing", SensingConfig)),
        Section("world", "the simulator (world/config.py WorldConfig)",
                _from_class("world", WorldConfig)),
        Section("agent", "each robot's controller and behaviours (agents/params.py "
                         "AgentParams; body values come from [robots], [sensing], [world])",
                _from_class("agent", AgentParams, skip=_AGENT_SKIP)),
        Section("coordinator", "deployment cycles, fence and certificate "
                               "(coordinator/config.py CoordinatorConfig)",
                _from_class("coordinator", CoordinatorConfig, skip={"rv"})),
        Section("hwbridge", "live robots mixed in (hwbridge/config.py; only with live robots)",
                bridge, optional=True),
        Section("hwbridge.robots", "one table per live robot", robot, optional=True,
                array=True),
        Section("hwbridge.fake", "stand-in robots (swarmcover fake-robot)",
                _from_class("hwbridge.fake", FakeParams), optional=True),
    ]


# --------------------------------------------------------------------------- writers

def defaults_toml() -> str:
    """A complete, commented run config with every default (valid as it is)."""
    out = ["# swarmcover run config: every section and field, with its unit and default.",
           "# Generated by `swarmcover config defaults` from the code that validates each",
           "# section; docs/config.md explains the same fields. Units: metres, seconds and",
           "# radians unless a field's unit says otherwise; 'x rv' = times the visibility",
           "# radius. This file runs as it is: a 3 m x 2 m room with one source.",
           ""]
    for sec in sections():
        pre = "# " if sec.optional else ""
        if sec.name:
            out += textwrap.wrap(f"[{sec.name}]: {sec.doc}", 86, initial_indent="# ---- ",
                                 subsequent_indent="#      ")
            if sec.name == "hwbridge":
                out.append("# Only for runs with live robots: uncomment, and add one "
                           "[[hwbridge.robots]] per robot.")
            out.append(f"{pre}[[{sec.name}]]" if sec.array else f"{pre}[{sec.name}]")
        width = max(len(f"{f.name} = {toml_value(f.default)}") for f in sec.fields
                    if f.default is not None) if sec.fields else 0
        width = min(width, 34)
        for f in sec.fields:
            note = f"({f.unit}) {f.doc}".strip() if f.unit != "-" else f.doc
            if f.default is None:
                example = {"ros_map": '"maps/office.yaml"', "kind": '"diffdrive"',
                           "start": "[0.3, 1.0, 0.0]"}.get(f.name, '""')
                line = f"# {f.name} = {example}"
                note += "; no default"
            else:
                line = f"{f.name} = {toml_value(f.default)}"
            if len(line) + len(note) > 86:  # a long explanation goes above its field
                out += [f"{pre}# {w}" for w in textwrap.wrap(note, 84)]
                out.append(f"{pre}{line}")
            else:
                out.append(f"{pre}{line:<{width}}  # {note}")
        out.append("")
    return "\n".join(out)


def docs_markdown() -> str:
    """docs/config.md: one table per section."""
    out = ["# Run config reference", "",
           "Generated by `swarmcover config docs` (do not edit; "
           "`tests/test_configref.py` checks it is current). `swarmcover config defaults` "
           "prints the same as a commented TOML file that runs as it is. Units: metres, "
           "seconds and radians unless stated; `x rv` = times the visibility radius `rv`.",
           ""]
    for sec in sections():
        title = "top level" if not sec.name else (f"[[{sec.name}]]" if sec.array
                                                   else f"[{sec.name}]")
        out += [f"## {title}", "", sec.doc[0].upper() + sec.doc[1:] + ".", "",
                "| field | default | unit | meaning |", "|---|---|---|---|"]
        for f in sec.fields:
            d = "(none)" if f.default is None else f"`{toml_value(f.default)}`"
            doc = f.doc.replace("|", "\\|")
            out.append(f"| `{f.name}` | {d} | {f.unit} | {doc} |")
        out.append("")
    return "\n".join(out)


def _toml_ready(v):
    """A resolved value as TOML takes it: dataclasses (the transform) as tables, tuples as
    arrays."""
    if dataclasses.is_dataclass(v):
        return {f.name: _toml_ready(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, (list, tuple)):
        return [_toml_ready(x) for x in v]
    return v


def _resolved_hwbridge(raw: dict, path: str) -> dict:
    """[hwbridge] with every value the bridge and the stand-in robots use: the fields of the
    reference's [hwbridge], [[hwbridge.robots]] and [hwbridge.fake] sections, read from the
    BridgeConfig that hwbridge/config.py resolves (defaults, [robots].v_max/w_max and
    "/<body>" namespaces included). A robot's ``start`` stays out when unset: the fake robot
    then starts at its source, found when it starts."""
    from swarmcover.hwbridge.config import from_dict
    bc = from_dict(raw, path)
    secs = {s.name: s.fields for s in sections()}

    def table(obj, fields) -> dict:
        vals = {f.name: _toml_ready(getattr(obj, f.name)) for f in fields}
        return {k: v for k, v in vals.items() if v is not None}

    hb = table(bc, secs["hwbridge"])
    if bc.geofence is None:
        hb["geofence"] = "none"
    hb["robots"] = [table(r, secs["hwbridge.robots"]) for r in bc.robots]
    hb["fake"] = table(bc.fake, secs["hwbridge.fake"])
    return hb


def complete_resolved_toml(text: str, path: str = "<resolved>", header: str = "") -> str:
    """A resolved run config (world/config.py ``to_toml``) with its [agent], [coordinator]
    and (when present) [hwbridge] tables filled in with every value their readers use
    (defaults included), so ``resolved.toml`` records the whole run. Other tables are kept
    as they are. header: comment lines put first (values of the run that are not config)."""
    import tomllib

    from swarmcover.agents.params import from_config
    from swarmcover.coordinator.config import CoordinatorConfig
    raw = tomllib.loads(text)
    agent = from_config(raw, path)
    coord = CoordinatorConfig.from_section(raw.get("coordinator"), raw.get("rv", 1.0), path)
    raw["agent"] = {f.name: getattr(agent, f.name) for f in dataclasses.fields(agent)
                    if f.name not in _AGENT_SKIP}
    raw["coordinator"] = {f.name: getattr(coord, f.name) for f in dataclasses.fields(coord)
                          if f.name != "rv"}
    if "hwbridge" in raw:
        raw["hwbridge"] = _resolved_hwbridge(raw, path)
    head = "".join(f"# {ln}\n" for ln in header.splitlines())
    return head + dumps_toml(raw)


def check_text(text: str, path: str = "<config>", base_dir: str = ".") -> list[str]:
    """Validate a run config as its owners do; returns the sections checked. Raises
    ValueError (the owners' errors) naming file, section, field and value."""
    import tomllib

    from swarmcover.agents.params import from_config
    from swarmcover.coordinator.config import CoordinatorConfig
    from swarmcover.world.config import loads_config
    cfg = loads_config(text, path, base_dir)
    raw = tomllib.loads(text)
    from_config(raw, path)
    CoordinatorConfig.from_section(raw.get("coordinator"), cfg.rv, path)
    checked = ["map", "robots", "sensing", "world", "agent", "coordinator"]
    if "hwbridge" in raw:
        from swarmcover.hwbridge.config import loads as bridge_loads
        bridge_loads(text, path)
        checked.append("hwbridge")
    return checked


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="swarmcover config", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("defaults", help="print a complete, commented run config with every default")
    sub.add_parser("docs", help="print the reference as Markdown (docs/config.md)")
    c = sub.add_parser("check", help="validate a run config file")
    c.add_argument("file", metavar="FILE.toml")
    args = p.parse_args(argv)
    if args.cmd == "defaults":
        sys.stdout.write(defaults_toml())
        return 0
    if args.cmd == "docs":
        sys.stdout.write(docs_markdown())
        return 0
    from pathlib import Path
    path = Path(args.file)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        print(f"swarmcover config check: {args.file}: {e.strerror or e}", file=sys.stderr)
        return 2
    try:
        checked = check_text(text, str(path), str(path.parent))
    except ValueError as e:  # every owner's error type derives from ValueError
        print(f"swarmcover config check: {e}", file=sys.stderr)
        return 2
    print(f"{args.file}: valid ({', '.join(checked)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

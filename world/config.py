"""The shared run config: TOML (or a bare ROS map_server YAML) into frozen dataclasses.

``load_config(path) -> RunConfig`` parses and validates the sections the world owns
([map], [robots], [sensing], [world]) plus the top-level ``name`` and ``rv``; the tables
other components own ([agent], [coordinator], [hwbridge]) are kept as raw dicts in
``RunConfig.sections`` for their owners to validate (``swarmcover.validate`` runs every
owner's check before a run starts). Unknown sections, and unknown keys inside the world's
sections, are errors that name the file, the section, the field and the value.

``to_toml(cfg)`` writes the resolved config (absolute ros_map path, every default filled
in) as TOML text; this is what the world serves in ``WorldInfo.config``, and
``loads_config(text)`` reads it back. Units: metres, seconds, radians unless a field's name
says otherwise (``noise_deg``).
"""
from __future__ import annotations

import copy
import math
import os
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

# one style for every section (ConfigError is re-exported for the world's callers)
from swarmcover.bus.configcheck import Checker, ConfigError
from swarmcover.bus.messages import ROBOT_KINDS  # the wire's list, the one copy
from swarmcover.ground.toml import dumps_toml  # noqa: F401  (re-exported: configref, tests)

MODES = ("lockstep", "realtime")
WORLD_SECTIONS = ("map", "robots", "sensing", "world")
# tables other components own and validate: [agent] (agents/params.py), [coordinator]
# (coordinator/config.py), [hwbridge] (hwbridge/config.py). Any other table is an error.
OTHER_SECTIONS = ("agent", "coordinator", "hwbridge")


# --------------------------------------------------------------------------- dataclasses

@dataclass(frozen=True)
class Obstacle:
    """One obstacle of [map].obstacles (world frame, m).

    type "rect": points = (min, max) corners; "circle": center, radius; "polygon": points.
    """
    type: str
    points: tuple = ()
    center: tuple = ()
    radius: float = 0.0

    def to_dict(self) -> dict:
        if self.type == "rect":
            return {"type": "rect", "min": list(self.points[0]), "max": list(self.points[1])}
        if self.type == "circle":
            return {"type": "circle", "center": list(self.center), "radius": self.radius}
        return {"type": "polygon", "points": [list(p) for p in self.points]}


@dataclass(frozen=True)
class MapConfig:
    """[map]: exactly one of ``boundary`` (outer polygon) or ``ros_map`` (absolute path of a
    ROS map_server YAML). ROS tracing knobs: ``simplify`` (Douglas-Peucker tolerance, m;
    0 = half a map cell), ``min_hole_area`` (m^2; smaller non-free specks inside free space are
    ignored; < 0 = 4 cells), ``max_vertices`` (cap on traced polygon vertices, tolerance
    grows until met), ``max_cells`` (images larger than this are block-reduced, unknown and
    occupied winning). ``circle_segments``: polygon sides used for circle obstacles."""
    boundary: tuple | None = None
    ros_map: str | None = None
    obstacles: tuple = ()
    sources: tuple = ()             # ((x, y, theta), ...); () = world picks one
    simplify: float = 0.0
    min_hole_area: float = -1.0
    max_vertices: int = 20_000
    max_cells: int = 16_000_000
    circle_segments: int = 32


@dataclass(frozen=True)
class RobotsConfig:
    """[robots]: body radius (m), kind, speed limits (m/s, rad/s); ``actuation_noise``:
    relative Gaussian noise on commanded speeds of virtual robots (0 = exact)."""
    radius: float = 0.06
    kind: str = "holonomic"
    v_max: float = 0.5
    w_max: float = 2.0
    actuation_noise: float = 0.0


@dataclass(frozen=True)
class SensingConfig:
    """[sensing]: camera rate (Hz), bearing noise sigma (degrees), dropout probability per
    sighting, whether robots block lines of sight, touch sectors, and the touch skin (m):
    a contact is felt while the gap to a wall or robot surface is below it. Lockstep with
    the coordinator in the barrier: an idle robot (holding still, nothing to do) is sensed
    only while it or a robot near it moved within idle_wake_s (sim s), when asked, and once
    every idle_keepalive_s (sim s); 0 senses every robot every tick (world/wake.py)."""
    rate_hz: float = 20.0
    noise_deg: float = 0.5
    dropout: float = 0.0
    robots_occlude: bool = False
    n_touch: int = 8
    touch_skin: float = 0.015
    idle_keepalive_s: float = 2.0
    idle_wake_s: float = 0.5


@dataclass(frozen=True)
class SpawnSpec:
    """One body created at start ([world].spawn): at source ``source``, or at ``pose``."""
    robot: int
    source: int = 0
    kind: str | None = None        # None: [robots].kind
    live: bool = False
    pose: tuple | None = None      # (x, y, theta) world frame, overrides source


@dataclass(frozen=True)
class WorldConfig:
    """[world]: control tick dt (s), clock mode, real-time factor, seed, lockstep per-tick
    timeout (wall s), stale-command age (sim s), odometry rate (Hz), physics substeps per
    tick, and bodies to create at start."""
    dt: float = 0.05
    mode: str = "lockstep"
    rtf: float = 1.0
    seed: int = 0
    tick_timeout_s: float = 2.0
    stale_cmd_s: float = 0.5
    pose_rate_hz: float = 5.0
    substeps: int = 4
    spawn: tuple = ()


@dataclass(frozen=True)
class RunConfig:
    """A whole run config. ``sections``: raw dicts of the tables other components own."""
    name: str = "run"
    rv: float = 1.0
    map: MapConfig = field(default_factory=MapConfig)
    robots: RobotsConfig = field(default_factory=RobotsConfig)
    sensing: SensingConfig = field(default_factory=SensingConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    sections: dict = field(default_factory=dict)
    path: str = "<config>"
    base_dir: str = "."

    def section(self, name: str) -> dict:
        """A raw section owned by another component ({} if absent)."""
        return copy.deepcopy(self.sections.get(name, {}))


# --------------------------------------------------------------------------- checks

class _Ctx(Checker):
    """The world's sections use the common checks (finite numbers, simple polygons)."""

    def tables(self, d: dict, key: str, expected: str):
        """(name, table) for each table of the list ``d[key]`` (absent: none)."""
        v = d.get(key, [])
        if not isinstance(v, list):
            raise self.err(key, v, expected)
        for k, t in enumerate(v):
            name = f"{key}[{k}]"
            self.table(name, t)
            yield name, t


class _Section(_Ctx):
    """A section whose fields are those of a dataclass: unknown keys are refused, and each
    field is read with the dataclass's default when the section leaves it out."""

    def __init__(self, file: str, section: str, d: dict, cls: type):
        super().__init__(file, section)
        self.unknown(d, {f.name for f in fields(cls)})
        self.d, self.dflt = d, cls()

    def _get(self, name: str):
        return self.d.get(name, getattr(self.dflt, name))

    def field_num(self, name: str, lo: float, hi: float, **open_ends) -> float:
        return self.num(name, self._get(name), lo, hi, **open_ends)

    def field_int(self, name: str, lo: int, hi: int) -> int:
        return self.int_(name, self._get(name), lo, hi)

    def field_bool(self, name: str) -> bool:
        return self.bool_(name, self._get(name))

    def field_choice(self, name: str, choices) -> str:
        return self.choice(name, self._get(name), choices)


# --------------------------------------------------------------------------- sections

def _parse_map(d: dict, file: str, base_dir: str) -> MapConfig:
    ctx = _Ctx(file, "map")
    allowed = {f.name for f in fields(MapConfig)}
    ctx.unknown(d, allowed)
    boundary = ros_map = None
    if "boundary" in d and "ros_map" in d:
        raise ctx.err("ros_map", d["ros_map"], "give either boundary or ros_map, not both")
    if "boundary" in d:
        boundary = ctx.polygon("boundary", d["boundary"])
    elif "ros_map" in d:
        v = d["ros_map"]
        if not isinstance(v, str) or not v:
            raise ctx.err("ros_map", v, "expected a path to a ROS map_server YAML")
        p = Path(v)
        if not p.is_absolute():
            p = Path(base_dir) / p
        p = p.resolve()
        if not p.is_file():
            raise ctx.err("ros_map", v, f"file not found ({p})")
        ros_map = str(p)
    else:
        raise ctx.err("boundary", None, "missing: give boundary (a polygon) or ros_map")
    obstacles = []
    for name, o in ctx.tables(d, "obstacles", "expected a list of tables"):
        t = o.get("type")
        if t == "rect":
            ctx.unknown(o, {"type", "min", "max"})
            lo = ctx.point(f"{name}.min", o.get("min"))
            hi = ctx.point(f"{name}.max", o.get("max"))
            if not (hi[0] > lo[0] and hi[1] > lo[1]):
                raise ctx.err(f"{name}.max", o.get("max"), "must exceed min in x and y")
            obstacles.append(Obstacle("rect", points=(lo, hi)))
        elif t == "circle":
            ctx.unknown(o, {"type", "center", "radius"})
            c = ctx.point(f"{name}.center", o.get("center"))
            r = ctx.num(f"{name}.radius", o.get("radius"), 0.0, 1e6, lo_open=True)
            obstacles.append(Obstacle("circle", center=c, radius=r))
        elif t == "polygon":
            ctx.unknown(o, {"type", "points"})
            obstacles.append(Obstacle("polygon", points=ctx.polygon(f"{name}.points",
                                                                    o.get("points"))))
        else:
            raise ctx.err(f"{name}.type", t, "expected rect, circle or polygon")
    sources = []
    for name, s in ctx.tables(d, "sources", "expected a list of tables {x, y, theta}"):
        ctx.unknown(s, {"x", "y", "theta"})
        if "x" not in s or "y" not in s:
            raise ctx.err(name, s, "needs x and y")
        sources.append((ctx.num(f"{name}.x", s["x"], -1e6, 1e6),
                        ctx.num(f"{name}.y", s["y"], -1e6, 1e6),
                        ctx.num(f"{name}.theta", s.get("theta", 0.0), -math.pi, math.pi)))
    return MapConfig(
        boundary=boundary, ros_map=ros_map, obstacles=tuple(obstacles), sources=tuple(sources),
        simplify=ctx.num("simplify", d.get("simplify", 0.0), 0.0, 1e3),
        min_hole_area=ctx.num("min_hole_area", d.get("min_hole_area", -1.0), -1.0, 1e6),
        max_vertices=ctx.int_("max_vertices", d.get("max_vertices", 20_000), 16, 10_000_000),
        max_cells=ctx.int_("max_cells", d.get("max_cells", 16_000_000), 1_000, 10**9),
        circle_segments=ctx.int_("circle_segments", d.get("circle_segments", 32), 6, 1024))


def _parse_robots(d: dict, file: str) -> RobotsConfig:
    sec = _Section(file, "robots", d, RobotsConfig)
    return RobotsConfig(
        radius=sec.field_num("radius", 0.0, 100.0, lo_open=True),
        kind=sec.field_choice("kind", ROBOT_KINDS),
        v_max=sec.field_num("v_max", 0.0, 100.0, lo_open=True),
        w_max=sec.field_num("w_max", 0.0, 100.0, lo_open=True),
        actuation_noise=sec.field_num("actuation_noise", 0.0, 1.0))


def _parse_sensing(d: dict, file: str) -> SensingConfig:
    sec = _Section(file, "sensing", d, SensingConfig)
    return SensingConfig(
        rate_hz=sec.field_num("rate_hz", 0.0, 1e4, lo_open=True),
        noise_deg=sec.field_num("noise_deg", 0.0, 90.0),
        dropout=sec.field_num("dropout", 0.0, 1.0),
        robots_occlude=sec.field_bool("robots_occlude"),
        n_touch=sec.field_int("n_touch", 1, 360),
        touch_skin=sec.field_num("touch_skin", 0.0, 10.0),
        idle_keepalive_s=sec.field_num("idle_keepalive_s", 0.0, 3600.0),
        idle_wake_s=sec.field_num("idle_wake_s", 0.0, 3600.0))


def _parse_world(d: dict, file: str) -> WorldConfig:
    ctx = _Section(file, "world", d, WorldConfig)
    spawn = []
    seen = set()
    for name, s in ctx.tables(d, "spawn",
                              "expected a list of tables {robot, source, kind, live, pose}"):
        ctx.unknown(s, {"robot", "source", "kind", "live", "pose"})
        if "robot" not in s:
            raise ctx.err(name, s, "needs robot (an id)")
        rid = ctx.int_(f"{name}.robot", s["robot"], 0, 2**62)
        if rid in seen:
            raise ctx.err(f"{name}.robot", rid, "duplicate robot id")
        seen.add(rid)
        pose = None
        if "pose" in s:
            p = s["pose"]
            if not isinstance(p, list) or len(p) not in (2, 3):
                raise ctx.err(f"{name}.pose", p, "expected [x, y] or [x, y, theta]")
            pose = tuple(ctx.num(f"{name}.pose", v, -1e6, 1e6) for v in p)
            if len(pose) == 2:
                pose = pose + (0.0,)
        spawn.append(SpawnSpec(
            robot=rid, source=ctx.int_(f"{name}.source", s.get("source", 0), 0, 1000),
            kind=ctx.choice(f"{name}.kind", s["kind"], ROBOT_KINDS) if "kind" in s else None,
            live=ctx.bool_(f"{name}.live", s.get("live", False)), pose=pose))
    return WorldConfig(
        dt=ctx.field_num("dt", 0.0, 10.0, lo_open=True),
        mode=ctx.field_choice("mode", MODES),
        rtf=ctx.field_num("rtf", 0.0, 1e4, lo_open=True),
        seed=ctx.field_int("seed", 0, 2**63 - 1),
        tick_timeout_s=ctx.field_num("tick_timeout_s", 0.0, 3600.0, lo_open=True),
        stale_cmd_s=ctx.field_num("stale_cmd_s", 0.0, 1e6, lo_open=True),
        pose_rate_hz=ctx.field_num("pose_rate_hz", 0.0, 1e4),
        substeps=ctx.field_int("substeps", 1, 100),
        spawn=tuple(spawn))


# --------------------------------------------------------------------------- loading

def parse_config(d: dict, path: str = "<config>", base_dir: str = ".") -> RunConfig:
    """Validate a config dict (as from tomllib). Relative paths resolve against base_dir."""
    ctx = _Ctx(path, "")
    if not isinstance(d, dict):
        raise ctx.err("<top>", d, "expected a table")
    sections = {}
    for k, v in d.items():
        if k in ("name", "rv") or k in WORLD_SECTIONS:
            continue
        if not isinstance(v, dict):
            raise ctx.err(k, v, "unknown top-level field (known: name, rv, and tables)")
        if k not in OTHER_SECTIONS:
            raise ConfigError(path, k, "", None, "unknown section (known: " + ", ".join(
                f"[{n}]" for n in WORLD_SECTIONS + OTHER_SECTIONS) + ")")
        sections[k] = copy.deepcopy(v)
    for s in WORLD_SECTIONS:
        if s in d and not isinstance(d[s], dict):
            raise ctx.err(s, d[s], "expected a table")
    name = d.get("name", Path(path).stem if path and not path.startswith("<") else "run")
    if not isinstance(name, str) or not name or len(name) > 200:
        raise ctx.err("name", name, "expected a non-empty string (at most 200 characters)")
    rv = ctx.num("rv", d.get("rv", 1.0), 0.0, 1e6, lo_open=True)
    if "map" not in d:
        raise ConfigError(path, "map", "<section>", None, "missing [map] section")
    cfg = RunConfig(
        name=name, rv=rv,
        map=_parse_map(d["map"], path, base_dir),
        robots=_parse_robots(d.get("robots", {}), path),
        sensing=_parse_sensing(d.get("sensing", {}), path),
        world=_parse_world(d.get("world", {}), path),
        sections=sections, path=path, base_dir=base_dir)
    for k, s in enumerate(cfg.world.spawn):
        if s.pose is None and cfg.map.sources and s.source >= len(cfg.map.sources):
            raise ConfigError(path, "world", f"spawn[{k}].source", s.source,
                              f"only {len(cfg.map.sources)} source(s) in [map].sources")
    return cfg


def load_config(path: str | os.PathLike) -> RunConfig:
    """Load a run config TOML, or a bare ROS map_server YAML (defaults built around it)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(str(path), "", "<file>", str(path), "file not found")
    if p.suffix.lower() in (".yaml", ".yml"):
        return parse_config({"name": p.stem, "map": {"ros_map": str(p.resolve())}},
                            str(p), str(p.resolve().parent))
    try:
        d = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(str(path), "", "<toml>", None, f"not valid TOML: {e}") from None
    return parse_config(d, str(p), str(p.resolve().parent))


def loads_config(text: str, path: str = "<text>", base_dir: str = ".") -> RunConfig:
    """Parse TOML text, e.g. ``WorldInfo.config`` served by the world."""
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "", "<toml>", None, f"not valid TOML: {e}") from None
    return parse_config(d, path, base_dir)


def with_sources(cfg: RunConfig, sources) -> RunConfig:
    """A copy of cfg with [map].sources replaced (e.g. by the world's automatic pick)."""
    src = tuple((float(x), float(y), float(t)) for x, y, t in sources)
    return replace(cfg, map=replace(cfg.map, sources=src))


# --------------------------------------------------------------------------- TOML out

def to_dict(cfg: RunConfig) -> dict:
    """The resolved config as a plain dict (every default filled in)."""
    m = cfg.map
    md: dict[str, Any] = {}
    if m.boundary is not None:
        md["boundary"] = [list(p) for p in m.boundary]
    else:
        md["ros_map"] = m.ros_map
    md["obstacles"] = [o.to_dict() for o in m.obstacles]
    md["sources"] = [{"x": x, "y": y, "theta": t} for x, y, t in m.sources]
    for k in ("simplify", "min_hole_area", "max_vertices", "max_cells", "circle_segments"):
        md[k] = getattr(m, k)
    wd = {f.name: getattr(cfg.world, f.name) for f in fields(WorldConfig) if f.name != "spawn"}
    spawn = []
    for s in cfg.world.spawn:
        e: dict[str, Any] = {"robot": s.robot, "source": s.source, "live": s.live}
        if s.kind is not None:
            e["kind"] = s.kind
        if s.pose is not None:
            e["pose"] = list(s.pose)
        spawn.append(e)
    wd["spawn"] = spawn
    out: dict[str, Any] = {"name": cfg.name, "rv": cfg.rv, "map": md,
                           "robots": {f.name: getattr(cfg.robots, f.name)
                                      for f in fields(RobotsConfig)},
                           "sensing": {f.name: getattr(cfg.sensing, f.name)
                                       for f in fields(SensingConfig)},
                           "world": wd}
    for k, v in cfg.sections.items():
        out[k] = copy.deepcopy(v)
    return out


def to_toml(cfg: RunConfig) -> str:
    """The resolved config as TOML text (round-trips through loads_config)."""
    return dumps_toml(to_dict(cfg))

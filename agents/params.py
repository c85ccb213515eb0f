"""Agent parameters: one frozen dataclass, filled from the run config and CLI overrides.

Sources, later ones win: the defaults below; the run config's ``rv``, ``[robots]`` (radius,
kind, v_max, w_max), ``[sensing].n_touch`` and ``[world].dt``; its ``[agent]`` section (every
field of :class:`AgentParams` except those owned by [robots], unknown keys rejected); then
command-line flags. Angles in the config are in degrees where the name ends in ``_deg``.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from typing import Any, Mapping

from swarmcover.bus.configcheck import Checker, ConfigError
from swarmcover.bus.messages import ROBOT_KINDS  # the wire's list, re-exported for agents.node


class ParamError(ConfigError):
    """A bad parameter; the message names the source, section, field and value."""


@dataclass(frozen=True)
class AgentParams:
    # robot body and shared run values ([robots], rv, [sensing], [world])
    kind: str = "holonomic"          # "holonomic" (never rotates) or "diffdrive"
    v_max: float = 0.5               # m/s
    w_max: float = 2.0               # rad/s (diffdrive)
    radius: float = 0.06             # m, body radius
    rv: float = 1.0                  # m, visibility radius
    n_touch: int = 8                 # touch sectors; tau = pi / n_touch
    dt: float = 0.05                 # s, nominal control tick (until measured from Sense.t)
    # homing (spec 4.5)
    g0: float = 0.15                 # gain saturation knee: K = v_max / max(|g|, g0). 0.3 ->
                                     # 0.15: moves settle sooner, and stop 0.04 cm short of
                                     # their vertex on average along their way, not 0.28
    arrive_deg: float = 1.5          # stop when every filtered bearing error < this ...
    arrive_ticks: int = 10           # ... for this many consecutive ticks
    arrive_offset: bool = True       # ... and so does the offset they put the robot at (x
                                     # landmark distance): two landmarks 60 deg apart
                                     # left it 2.3 cm off, 1.3 cm with this
    error_alpha: float = 0.3         # low-pass weight of new bearing-error samples (stop rule)
    lost_timeout_s: float = 2.0      # fail "lost landmarks" after this long with < 2 in view
    # holding (station keeping on the recorded snapshot)
    hold_window: int = 5             # ticks averaged into the bearing snapshot
    hold_rehome: bool = False        # station keeping: home back after a felt bump. Off by
                                     # default: a holding robot is the swarm's fixed reference,
                                     # and re-homing on neighbours that are themselves being
                                     # pushed made robots chase them; the coordinator re-plans
                                     # from what robots see instead
    hold_deadband_deg: float = 3.0   # re-home when a landmark drifts beyond this ...
    hold_second_deg: float = 1.0     # ... and another beyond this (else that landmark moved)
    hold_gate_deg: float = 25.0      # a landmark off by more than this has moved: re-record it
    # open-loop motion, test drive, scale correction (spec 3.4(iv), 4.6)
    deploy_speed_frac: float = 1.0   # open-loop deploy speed, fraction of v_max
    test_drive_speed_frac: float = 0.5
    scale_speed_frac: float = 0.5
    scale_step_rv: float = 0.02      # back-up step of scale correction, fraction of rv
    scale_max_rv: float = 1.5        # give up moving outward after this far (fraction of rv)
    scale_margin_steps: int = 6      # extra back-up steps once every link is back: 6 x 0.02 rv
                                     # = 0.12 rv ~ eps / cos 30 deg, spacing back to ~ rv - eps
    link_lost_ticks: int = 3         # a link counts as lost after this many ticks unseen
    settle_ticks: int = 3            # ticks to wait still after each back-up step
    blocked_s: float = 1.0           # open-loop motion blocked by a wall this long ends it
    stall_s: float = 4.0             # homing whose largest bearing error has not dropped by
    stall_deg: float = 0.5           # stall_deg within stall_s has stalled (wall, crowd)
    contact_clear_rv: float = 0.1    # a sticky contact clears after moving this far (x rv)
    # wall sweep (a test drive with Task.sweep_side; agents/sweep.py)
    sweep_press_deg: float = 35.0    # slide along the wall this far into it: more than the
                                     # touch sectors' half width (180 / n_touch), so the
                                     # wall is pressed wherever its normal lies in the sector
    sweep_lost_m: float = 0.03       # no wall felt on the pressed side for this far while
                                     # sweeping: the wall ended, turn one touch sector round
                                     # its end (135 deg of such turns: an opening)
    sweep_budget_rv: float = 2.0     # each half of a sweep gives up after this far (x rv)
    sweep_speed_frac: float = 0.5    # sliding along the wall, fraction of v_max. The doors a
                                     # sweep finds were measured at 0.5: at 1.0 it found 12 of
                                     # 14 doors 0.18 m wide and 8 of 14 at 0.17 m (14 / 12 at 0.5)
    return_speed_frac: float = 1.0   # open-loop legs back to the vertex after a test drive's
                                     # touch, a sweep or a probe's approach, fraction of v_max:
                                     # they retrace what was just driven, and only the way out
                                     # feels for walls (homing back corrects the rest)
    # differential drive (spec 4.8)
    k_w: float = 1.5                 # 1/s
    k_v: float = 1.0
    align: str = "auto"              # frame alignment from mutual bearings: auto|on|off
    # process
    status_every: int = 4            # publish Status every this many Sense ticks

    # ---------------------------------------------------------------- derived values
    @property
    def tau(self) -> float:
        """Touch-direction resolution pi / n_touch (rad)."""
        return math.pi / self.n_touch

    @property
    def arrive(self) -> float:
        return math.radians(self.arrive_deg)

    @property
    def deadband(self) -> float:
        return math.radians(self.hold_deadband_deg)

    @property
    def second(self) -> float:
        return math.radians(self.hold_second_deg)

    @property
    def gate(self) -> float:
        return math.radians(self.hold_gate_deg)

    @property
    def press(self) -> float:
        """sweep_press_deg in rad."""
        return math.radians(self.sweep_press_deg)

    @property
    def aligned(self) -> bool:
        """Whether to estimate frame rotation from mutual bearings (rotating robots)."""
        return self.align == "on" or (self.align == "auto" and self.kind == "diffdrive")

    def replace(self, **kw: Any) -> "AgentParams":
        return check(dataclasses.replace(self, **kw), "override")


_FIELDS = {f.name: f for f in dataclasses.fields(AgentParams)}
# owned by other sections of the run config, not settable from [agent]
_NOT_IN_AGENT = {"kind", "v_max", "w_max", "radius", "rv", "n_touch", "dt"}
_POSITIVE = {"v_max", "w_max", "rv", "dt", "g0", "arrive_deg", "lost_timeout_s",
             "hold_deadband_deg", "hold_second_deg", "hold_gate_deg", "deploy_speed_frac", "test_drive_speed_frac",
             "scale_speed_frac", "scale_step_rv", "scale_max_rv", "blocked_s",
             "stall_s", "stall_deg",
             "contact_clear_rv", "k_w", "k_v", "error_alpha", "sweep_press_deg",
             "sweep_lost_m", "sweep_budget_rv", "sweep_speed_frac", "return_speed_frac"}


# the section of the run config each field is read from
_SECTION_OF = {"kind": "robots", "v_max": "robots", "w_max": "robots", "radius": "robots",
               "rv": "", "n_touch": "sensing", "dt": "world"}


def _err(where: str, name: str, value: Any, reason: str) -> ParamError:
    return ParamError(where, _SECTION_OF.get(name, "agent"), name, value, reason)


def _coerce(name: str, value: Any, where: str, section: str | None = None) -> Any:
    """Type-check one value (finite floats, ints that are not bools, strings, bools)."""
    ck = Checker(where, _SECTION_OF.get(name, "agent") if section is None else section)
    typ = _FIELDS[name].type
    try:
        if typ == "float":
            return ck.num(name, value)
        if typ == "int":
            return ck.int_(name, value)
        if typ == "str":
            return ck.str_(name, value)
        if typ == "bool":
            return ck.bool_(name, value)
    except ConfigError as e:
        raise ParamError(e.file, e.section, e.field, e.value, e.reason) from None
    return value


def check(p: AgentParams, where: str = "params") -> AgentParams:
    """Range checks; raises ParamError naming the field and value."""
    for name, f in _FIELDS.items():
        if f.type == "float" and not math.isfinite(getattr(p, name)):
            raise _err(where, name, getattr(p, name), "not finite")
    for name in _POSITIVE:
        if getattr(p, name) <= 0:
            raise _err(where, name, getattr(p, name), "must be > 0")
    if p.kind not in ROBOT_KINDS:
        raise _err(where, "kind", p.kind, f"not one of {', '.join(ROBOT_KINDS)}")
    if p.align not in ("auto", "on", "off"):
        raise _err(where, "align", p.align, "not one of auto, on, off")
    if p.error_alpha > 1:
        raise _err(where, "error_alpha", p.error_alpha, "must be <= 1")
    if p.sweep_press_deg >= 90:
        raise _err(where, "sweep_press_deg", p.sweep_press_deg, "must be < 90")
    for name in ("n_touch", "arrive_ticks", "hold_window", "link_lost_ticks", "settle_ticks",
                 "status_every"):
        if getattr(p, name) < 1:
            raise _err(where, name, getattr(p, name), "must be >= 1")
    if p.scale_margin_steps < 0:
        raise _err(where, "scale_margin_steps", p.scale_margin_steps, "must be >= 0")
    if p.radius < 0:
        raise _err(where, "radius", p.radius, "must be >= 0")
    return p


def from_config(cfg: Mapping[str, Any], source: str = "run config",
                base: AgentParams | None = None) -> AgentParams:
    """Parameters from a parsed run config (dict from TOML). ``source`` names the file (or
    'world/info') in errors. Unknown keys in [agent] are rejected; other sections are only
    read (their owners validate them)."""
    kw: dict[str, Any] = {}

    def take(section: Mapping[str, Any] | None, key: str, name: str, sec: str):
        if section is not None and key in section:
            kw[name] = _coerce(name, section[key], source, sec)

    if not isinstance(cfg, Mapping):
        raise ParamError(source, "", "", None, "expected a TOML table")
    take(cfg, "rv", "rv", "")
    for sec_name, pairs in (("robots", (("radius", "radius"), ("kind", "kind"),
                                        ("v_max", "v_max"), ("w_max", "w_max"))),
                            ("sensing", (("n_touch", "n_touch"),)),
                            ("world", (("dt", "dt"),))):
        sec = cfg.get(sec_name)
        if sec is None:
            continue
        if not isinstance(sec, Mapping):
            raise ParamError(source, sec_name, "", None, "expected a table")
        for key, name in pairs:
            take(sec, key, name, sec_name)
    agent = cfg.get("agent")
    if agent is not None:
        if not isinstance(agent, Mapping):
            raise ParamError(source, "agent", "", None, "expected a table")
        ck = Checker(source, "agent")
        try:
            ck.unknown(agent, set(_FIELDS) - _NOT_IN_AGENT,
                       hint={k: " (set it in [robots])" for k in ("kind", "v_max", "w_max",
                                                                   "radius")})
        except ConfigError as e:
            raise ParamError(e.file, e.section, e.field, e.value, e.reason) from None
        for key, value in agent.items():
            kw[key] = _coerce(key, value, source, "agent")
    p = dataclasses.replace(base or AgentParams(), **kw)
    return check(p, source)


def from_toml_text(text: str, source: str) -> AgentParams:
    try:
        cfg = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ParamError(source, "", "", None, f"not valid TOML: {e}") from None
    return from_config(cfg, source)


def parse_override(item: str, p: AgentParams) -> AgentParams:
    """Apply one ``--param NAME=VALUE`` (VALUE parsed as a TOML value, bare words as strings)."""
    if "=" not in item:
        raise ParamError("--param", "", "", item, "expected NAME=VALUE")
    name, raw = item.split("=", 1)
    name = name.strip()
    if name not in _FIELDS:
        raise ParamError("--param", "agent", name, raw, "unknown field (known: "
                         f"{', '.join(sorted(_FIELDS))})")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return check(dataclasses.replace(p, **{name: _coerce(name, value, "--param", "agent")}),
                 "--param")

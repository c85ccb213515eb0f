"""Zenoh key expressions of swarmcover, scoped by swarm (experiment) name.

Every key starts with ``sc/<swarm>/`` so two runs on one network never mix. ``TOPICS`` is
the topic table (the README's table is generated from it and checked against it in tests).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from . import messages as m

ROOT = "sc"
_SWARM_RE = re.compile(r"^[A-Za-z0-9_\-]{1,64}$")


def check_swarm(name: str) -> str:
    """Validate a swarm name: 1-64 of letters, digits, '_' or '-' (one key chunk)."""
    return check_name(name, "swarm name")


def check_name(name: str, what: str = "host name") -> str:
    """Validate a name that is one key chunk (a swarm's, a host's): 1-64 of letters,
    digits, '_' or '-'."""
    if not isinstance(name, str) or not _SWARM_RE.match(name):
        raise ValueError(f"{what} {name!r} is invalid: use 1-64 letters, digits, '_' or '-'")
    return name


@dataclass(frozen=True)
class Topic:
    """One row of the topic table. ``pattern`` uses {swarm} and {id}/{body} placeholders."""
    pattern: str
    message: str          # message tag, or "liveliness" / "query"
    publisher: str
    subscribers: str
    qos: str              # "BLOCK", "DROP", "DROP express", ...
    what: str


TOPICS: tuple[Topic, ...] = (
    Topic("robot/{id}/sense", "Sense", "world", "agent {id}", "BLOCK",
          "bearings of visible robots + touch sectors, one per tick (lockstep: an idle robot "
          "only while it or a robot near it moves, when asked, and every "
          "`[sensing] idle_keepalive_s`: [docs/determinism.md](docs/determinism.md))"),
    Topic("robot/{id}/cmd_vel", "CmdVel", "agent {id}", "world (virtual) / hwbridge (live)",
          "BLOCK", "body-frame velocity command answering a Sense tick; `idle`: holding "
          "still with nothing to do"),
    Topic("robot/{id}/odom", "Pose", "world / hwbridge", "agent {id}", "DROP",
          "pose as reported by the robot's body (telemetry, never used for control)"),
    Topic("robot/{id}/pose", "Pose", "agent {id}", "recorders, viewers", "DROP",
          "the agent's relay of its body pose (telemetry only)"),
    Topic("robot/{id}/status", "Status", "agent {id}", "coordinator, viewers", "BLOCK",
          "role, vertex, neighbour bearings, sticky contact, task progress"),
    Topic("robot/{id}/task", "Task", "coordinator", "agent {id}", "BLOCK",
          "next behaviour: hold, goto, deploy, test_drive, leave"),
    Topic("robot/{id}/twin_cmd", "TwinCmd", "hwbridge", "world", "BLOCK",
          "proportional sync of a live robot's twin to its mocap pose"),
    Topic("coord/complex", "Complex", "coordinator", "run, viewers, recorders", "BLOCK",
          "per-cycle Rips complex, frontier K, obstacle O, certificate, redundant set"),
    Topic("coord/ack", "CoordAck", "coordinator", "world", "BLOCK",
          "lockstep: a tick's tasks, spawns and removes are out; the world waits for it"),
    Topic("world/clock", "Clock", "world", "all", "DROP (lockstep: BLOCK)",
          "simulation time and tick; lockstep: the roster and the statuses of the tick"),
    Topic("world/truth", "Truth", "world", "run, viewers, recorders", "DROP",
          "ground-truth poses, every tick (never used by agents)"),
    Topic("world/spawn", "Spawn", "coordinator, run", "world, run", "BLOCK",
          "create a robot body at a source"),
    Topic("world/remove", "Remove", "coordinator, tests", "world", "BLOCK",
          "delete a robot body"),
    Topic("world/info", "WorldInfo", "world (queryable)", "any (get)", "query",
          "the map and run parameters, for late joiners"),
    Topic("mocap/{body}", "MocapPose", "mocap source", "hwbridge", "DROP express",
          "rigid-body pose in the mocap frame"),
    Topic("live/{id}/cmd", "LiveCmd", "hwbridge", "live robot driver", "BLOCK express",
          "clamped unicycle command for a live robot (deadman-guarded)"),
    Topic("demo", "Demo", "swarmcover demo", "anyone", "DROP", "heartbeat for smoke tests"),
    Topic("alive/{role}/{name}", "liveliness", "every process", "coordinator, world, topics",
          "token", "presence: robot/<id>, world/main, coordinator/main, hwbridge/main, ..."),
)


class Keys:
    """Builds and parses the keys of one swarm. ``Keys("lab1").sense(7)``."""

    def __init__(self, swarm: str = "default"):
        self.swarm = check_swarm(swarm)
        self.prefix = f"{ROOT}/{swarm}"

    # -- per robot
    def sense(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/sense"

    def cmd_vel(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/cmd_vel"

    def odom(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/odom"

    def pose(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/pose"

    def status(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/status"

    def task(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/task"

    def twin_cmd(self, rid: int | str) -> str:
        return f"{self.prefix}/robot/{rid}/twin_cmd"

    # -- coordinator and world
    @property
    def complex(self) -> str:
        return f"{self.prefix}/coord/complex"

    @property
    def coord_ack(self) -> str:
        return f"{self.prefix}/coord/ack"

    @property
    def clock(self) -> str:
        return f"{self.prefix}/world/clock"

    @property
    def truth(self) -> str:
        return f"{self.prefix}/world/truth"

    @property
    def spawn(self) -> str:
        return f"{self.prefix}/world/spawn"

    @property
    def remove(self) -> str:
        return f"{self.prefix}/world/remove"

    @property
    def world_info(self) -> str:
        return f"{self.prefix}/world/info"

    @property
    def demo(self) -> str:
        return f"{self.prefix}/demo"

    # -- hardware
    def mocap(self, body: str) -> str:
        return f"{self.prefix}/mocap/{body}"

    def live_cmd(self, rid: int | str) -> str:
        return f"{self.prefix}/live/{rid}/cmd"

    # -- presence
    def alive(self, role: str, name: int | str) -> str:
        return f"{self.prefix}/alive/{role}/{name}"

    def alive_robots(self) -> str:
        return f"{self.prefix}/alive/robot/*"

    def avail(self, rid: int | str) -> str:
        """Liveliness token of an agent that has no body yet (started by hand, or by
        ``run`` ahead of its Spawn): the coordinator places such agents before it asks for
        new processes. The agent drops it with its first Sense."""
        return f"{self.prefix}/avail/robot/{rid}"

    def avail_robots(self) -> str:
        return f"{self.prefix}/avail/robot/*"

    # -- hosts (``swarmcover host``: a machine that offers to start agents for a run)
    def host(self, name: str) -> str:
        """A host's queryable: an empty query gets its slots, a start or stop request its
        answer (swarmcover/hosts.py)."""
        return f"{self.prefix}/host/{check_name(name)}"

    def host_event(self, name: str) -> str:
        """What a host reports on its own: one of its agents became ready or exited."""
        return f"{self.prefix}/host/{check_name(name)}/event"

    def host_events(self) -> str:
        return f"{self.prefix}/host/*/event"

    def alive_hosts(self) -> str:
        return f"{self.prefix}/alive/host/*"

    def alive_runs(self) -> str:
        """The liveliness tokens of the ``swarmcover run`` processes of this swarm: a host
        stops the agents of a run whose token went away."""
        return f"{self.prefix}/alive/run/*"

    def host_name(self, key: str) -> str | None:
        """The host name in this swarm's ``host/<name>[/...]`` or ``alive/host/<name>``."""
        parts = self.relative(key).split("/")
        if parts[:2] == ["alive", "host"]:
            parts = parts[1:]
        if len(parts) >= 2 and parts[0] == "host" and _SWARM_RE.match(parts[1]):
            return parts[1]
        return None

    @property
    def all(self) -> str:
        return f"{self.prefix}/**"

    def robot_id(self, key: str) -> int | None:
        """The robot id in ``.../robot/<id>/...`` or ``.../alive/robot/<id>``, else None."""
        parts = str(key).split("/")
        for k in range(len(parts) - 1):
            if parts[k] == "robot" and parts[k + 1].isdigit():
                return int(parts[k + 1])
        return None

    def relative(self, key: str) -> str:
        """The key without the ``sc/<swarm>/`` prefix."""
        key = str(key)
        return key[len(self.prefix) + 1:] if key.startswith(self.prefix + "/") else key


def message_for_key(key: str) -> type[m.Message] | None:
    """The message class a key carries (by its suffix), or None if unknown."""
    parts = str(key).split("/")
    tail = "/".join(parts[2:]) if len(parts) > 2 and parts[0] == ROOT else str(key)
    for t in TOPICS:
        pat = re.escape(t.pattern).replace(r"\{id\}", r"\d+").replace(r"\{body\}", r"[^/]+")
        pat = pat.replace(r"\{role\}", r"[^/]+").replace(r"\{name\}", r"[^/]+")
        if re.fullmatch(pat, tail):
            return m.REGISTRY.get(t.message)
    return None


def topic_table_markdown() -> str:
    """The topic table as Markdown, for the README."""
    rows = ["| key (under `sc/<swarm>/`) | message | publisher | subscribers | QoS | what |",
            "|---|---|---|---|---|---|"]
    for t in TOPICS:
        rows.append(f"| `{t.pattern}` | {t.message} | {t.publisher} | {t.subscribers} | "
                    f"{t.qos} | {t.what} |")
    return "\n".join(rows)

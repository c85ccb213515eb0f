"""Hosts (issue 18.4), the pure part: what ``swarmcover host`` and ``swarmcover run`` say to
each other, a host's slot book, and run's spreading rule. No Zenoh and no processes here
(``swarmcover/host.py`` is the host process, ``swarmcover/hostpool.py`` run's side of it).

Keys, under ``sc/<swarm>/`` (``bus.keys.Keys``):

  * ``alive/host/<name>``: liveliness token of a host that offers to start agents;
  * ``host/<name>``: its queryable. An empty query gets its :class:`HostInfo`; a
    :class:`HostStart` or :class:`HostStop` gets a :class:`HostReply` (which carries the
    HostInfo after the request);
  * ``host/<name>/event``: a :class:`HostEvent` (BLOCK) when one of its agents became
    ready or exited;
  * ``alive/run/<id>``: a ``swarmcover run``'s token; a host stops the agents of a run
    whose token went away.

The messages are msgpack maps with a ``type`` tag, checked by msgspec (types, bounds, no
NaN) into the frozen structs below; a payload that does not decode is a :class:`HostWireError`
naming the field. They are not robot messages (bus/messages.py): they never reach a robot,
the world or the coordinator.
"""
from __future__ import annotations

import dataclasses
import os
import shlex
from typing import Annotated, Iterable, Literal, Mapping, Union

import msgspec

from swarmcover.bus.messages import ROBOT_KINDS

RobotId = Annotated[int, msgspec.Meta(ge=0, le=2**31 - 1)]
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_\-]{1,64}$")]
RunId = Annotated[str, msgspec.Meta(min_length=1, max_length=200)]
Limit = Annotated[float, msgspec.Meta(gt=0.0, le=100.0)]
Text = Annotated[str, msgspec.Meta(max_length=2000)]
CONFIG_MAX = 1_000_000        # characters of run config text in a start request


class HostWireError(ValueError):
    """A host message that does not decode (msgspec's text names the field)."""


class HostInfo(msgspec.Struct, frozen=True, tag="HostInfo"):
    """A host's slots: ``capacity`` agents at most, ``running`` the robot ids of the agents
    it runs now. ``seq`` grows with every change (newer snapshots win)."""
    name: Name
    capacity: Annotated[int, msgspec.Meta(ge=0, le=100_000)]
    running: tuple[RobotId, ...] = ()
    seq: Annotated[int, msgspec.Meta(ge=0)] = 0

    @property
    def free(self) -> int:
        return max(0, self.capacity - len(self.running))


class HostStart(msgspec.Struct, frozen=True, tag="HostStart"):
    """run -> host: start the agent of robot ``robot`` for run ``run``. ``config`` is the
    run config's text (the agent reads it as ``--run-config``: the same parameters as an
    agent run starts itself); ``v_max``/``w_max`` a live robot's limits."""
    run: RunId
    robot: RobotId
    kind: Literal[ROBOT_KINDS] = "holonomic"
    live: bool = False
    v_max: Limit | None = None
    w_max: Limit | None = None
    config: Annotated[str, msgspec.Meta(max_length=CONFIG_MAX)] = ""


class HostStop(msgspec.Struct, frozen=True, tag="HostStop"):
    """run -> host: stop the agent of ``robot`` (-1: every agent of run ``run``)."""
    run: RunId
    robot: Annotated[int, msgspec.Meta(ge=-1, le=2**31 - 1)] = -1


class HostReply(msgspec.Struct, frozen=True, tag="HostReply"):
    """host -> run: the answer to a start or stop. ``why`` says why not when ``ok`` is
    false; ``robots`` are the robots the request started or stopped."""
    ok: bool
    info: HostInfo
    why: Text = ""
    robots: tuple[RobotId, ...] = ()


class HostEvent(msgspec.Struct, frozen=True, tag="HostEvent"):
    """host -> run: an agent it runs became ``ready``, ``failed`` (exited before it was
    ready: ``rc`` and the first error line in ``detail``) or ``exited`` later."""
    robot: RobotId
    what: Literal["ready", "failed", "exited"]
    info: HostInfo
    run: RunId = "?"
    rc: int | None = None
    detail: Text = ""
    start_s: Annotated[float, msgspec.Meta(ge=0.0, le=1e6)] | None = None  # request -> READY


_REQUEST = msgspec.msgpack.Decoder(Union[HostStart, HostStop])
_DECODERS = {t: msgspec.msgpack.Decoder(t) for t in (HostInfo, HostReply, HostEvent)}
_ENCODER = msgspec.msgpack.Encoder()


def encode(msg: msgspec.Struct) -> bytes:
    return _ENCODER.encode(msg)


def decode_request(payload: bytes) -> HostStart | HostStop:
    """A start or stop request. Raises HostWireError naming the field."""
    try:
        return _REQUEST.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError) as e:
        raise HostWireError(f"host request: {e}") from None


def decode(payload: bytes, typ: type) -> msgspec.Struct:
    """A HostInfo, HostReply or HostEvent. Raises HostWireError naming the field."""
    try:
        return _DECODERS[typ].decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError) as e:
        raise HostWireError(f"{typ.__name__}: {e}") from None


# --------------------------------------------------------------------------- refusals

def refuse_full(name: str, capacity: int, running: Iterable[int]) -> str:
    ids = sorted(running)
    return (f"host {name} is full: {len(ids)} of {capacity} slots in use (robots "
            f"{', '.join(map(str, ids)) or 'none'}); start it with a larger --capacity, or "
            f"add a host")


def refuse_running(name: str, robot: int) -> str:
    return f"robot {robot} already has an agent on host {name}"


def refuse_unknown(name: str, robot: int) -> str:
    return f"robot {robot} has no agent on host {name}"


def refuse_stopping(name: str) -> str:
    return f"host {name} is stopping: it starts no agent"


# --------------------------------------------------------------------------- the slot book

@dataclasses.dataclass
class HostBook:
    """A host's slots: which robots it runs, for which run. Every change bumps ``seq``."""
    name: str
    capacity: int
    agents: dict[int, str] = dataclasses.field(default_factory=dict)   # robot -> run id
    seq: int = 0
    stopping: bool = False

    def why_not(self, req: HostStart) -> str | None:
        """Why this start is refused (None: it may start)."""
        if self.stopping:
            return refuse_stopping(self.name)
        if req.robot in self.agents:
            return refuse_running(self.name, req.robot)
        if len(self.agents) >= self.capacity:
            return refuse_full(self.name, self.capacity, self.agents)
        return None

    def add(self, robot: int, run: str) -> None:
        self.agents[robot] = run
        self.seq += 1

    def remove(self, robot: int) -> bool:
        if self.agents.pop(robot, None) is None:
            return False
        self.seq += 1
        return True

    def to_stop(self, req: HostStop) -> tuple[list[int], str | None]:
        """The robots a stop request names (and why not, when it names none it may stop)."""
        if req.robot >= 0:
            if req.robot not in self.agents:
                return [], refuse_unknown(self.name, req.robot)
            return [req.robot], None
        return sorted(r for r, run in self.agents.items() if run == req.run), None

    def of_run(self, run: str) -> list[int]:
        return sorted(r for r, owner in self.agents.items() if owner == run)

    @property
    def free(self) -> int:
        return max(0, self.capacity - len(self.agents))

    def info(self) -> HostInfo:
        return HostInfo(name=self.name, capacity=self.capacity,
                        running=tuple(sorted(self.agents)), seq=self.seq)


# --------------------------------------------------------------------------- spreading

def pick_host(hosts: Iterable[HostInfo], exclude: Iterable[str] = ()) -> str | None:
    """The host for run's next agent: the one with the most free slots (ties: the larger
    capacity, then the name), or None when no host (outside ``exclude``) has a free slot:
    then run starts the agent on its own machine."""
    out = [h for h in hosts if h.free > 0 and h.name not in set(exclude)]
    if not out:
        return None
    return min(out, key=lambda h: (-h.free, -h.capacity, h.name)).name


def spread(n: int, hosts: Iterable[HostInfo]) -> list[str | None]:
    """Where ``n`` agents go, one after another, each taking a slot (None: run's machine)."""
    book = {h.name: h for h in hosts}
    out: list[str | None] = []
    for k in range(n):
        name = pick_host(book.values())
        out.append(name)
        if name is not None:
            h = book[name]
            book[name] = msgspec.structs.replace(h, running=h.running + (-1 - k,))
    return out


# --------------------------------------------------------------------------- the agent's flags

def agent_flags(kind: str, run_config: str | None, live: bool = False,
                limits: tuple[float, float] | None = None) -> list[str]:
    """The agent's own flags after ``agent --id N`` (run's local agents and a host's agents
    are started with the same ones): its kind, the run config (None: the agent asks the
    world's world/info), a live robot's limits, and env SWARMCOVER_AGENT_EXTRA_ARGS (e.g.
    ``--log-level DEBUG``) of the starting process."""
    a = ["--kind", kind] + (["--run-config", run_config] if run_config else [])
    if live:
        a.append("--live")
        if limits is not None:
            v_max, w_max = limits
            a += ["--v-max", str(v_max), "--param", f"w_max={float(w_max)}"]
    extra = os.environ.get("SWARMCOVER_AGENT_EXTRA_ARGS", "").strip()
    if extra:
        a += shlex.split(extra)
    return a


def tally_line(counts: Mapping[str, int]) -> str:
    """``local 2, hostA 5, hostB 4``: the progress line's agents per place (local first)."""
    items = sorted(counts.items(), key=lambda kv: (kv[0] != "local", kv[0]))
    return ", ".join(f"{k} {v}" for k, v in items)

"""The coordinator without its transport: what the coordinator process
(coordinator/node.py) and the in-process loop (swarmcover/simloop.py) both run in lockstep,
so the two cannot drift apart.

:class:`TickSync` keeps the statuses and liveliness changes that arrived, and hands the
deployer exactly those a tick's Clock announces. :class:`CoordinatorCore` is the deployer
behind the barrier: at each Clock it applies the roster's changes, then that tick's statuses
in (robot, seq) order, steps the deployer at the Clock's time, and returns its actions with
the CoordAck that lists them (the world applies the ack's spawns and removes at the next
boundary, and announces its tasks in the next Senses). No I/O, no wall clock.
"""
from __future__ import annotations

from swarmcover.bus.messages import ROBOT_KINDS, Clock, CoordAck, Status

from .actions import RemoveRobot, RequestStatus, SendTask, SpawnRobot
from .deployer import Deployer


class TickSync:
    """Lockstep book-keeping of the coordinator's half of the barrier (pure, no I/O).

    ``add_status`` buffers statuses as they arrive; ``missing(clk)`` says which robots'
    announced statuses have not arrived yet; ``take(clk)`` returns the tick's roster changes
    and its statuses in (robot, seq) order, and forgets them. Live robots (Status.live) move
    in real time and are in no roster: their statuses and liveliness changes
    (``add_alive``) are handed over at the next boundary as they came.
    """

    def __init__(self):
        self.buf: dict[int, list[Status]] = {}
        self.have: dict[int, int] = {}      # rid -> highest seq received
        self.done: dict[int, int] = {}      # rid -> highest seq handed to the deployer
        self.roster: set[int] = set()
        self.first = True
        self.live: set[int] = set()         # robots that reported live = true
        self.alive_events: list[tuple[int, bool]] = []

    def add_alive(self, rid: int, present: bool) -> None:
        """A liveliness change; only live robots' count (the roster stands for the rest)."""
        if rid in self.live:
            self.alive_events.append((rid, present))

    def add_status(self, st: Status) -> None:
        if st.live:
            self.live.add(st.robot)
        b = self.buf.setdefault(st.robot, [])
        if len(b) >= 1000:
            b.pop(0)
        b.append(st)
        self.have[st.robot] = max(self.have.get(st.robot, 0), st.seq)

    def missing(self, clk: Clock) -> list[int]:
        if self.first:
            return []   # a (re)started coordinator cannot have what was sent before it
        return [r for r, s in zip(clk.agents, clk.status_seqs)
                if s > self.done.get(r, 0) and self.have.get(r, 0) < s]

    def take(self, clk: Clock) -> tuple[list[int], list[int], list[Status]]:
        """(left, joined, statuses) of this boundary."""
        now = set(clk.agents)
        left, joined = sorted(self.roster - now), sorted(now - self.roster)
        for rid, present in self.alive_events:
            (joined if present else left).append(rid)
        self.alive_events = []
        for r in left:
            if r not in self.live:
                self.buf.pop(r, None)
        seqs = dict(zip(clk.agents, clk.status_seqs))
        for r in self.live - now:
            if self.buf.get(r):
                seqs[r] = self.buf[r][-1].seq
        out: list[Status] = []
        for r, s in sorted(seqs.items()):
            b = self.buf.get(r)
            if not b:
                continue
            lo = self.done.get(r, 0)
            out += sorted((st for st in b if lo < st.seq <= s), key=lambda st: st.seq)
            self.buf[r] = [st for st in b if st.seq > s]
            self.done[r] = max(lo, s)
        self.roster = now
        self.first = False
        return left, joined, out


def robot_kinds_from_config(cfg) -> callable:
    """Robot id -> (kind, live) from [robots].kind and the live robots of [hwbridge]."""
    default = cfg.robots.kind
    live = {}
    for r in cfg.section("hwbridge").get("robots", []) or []:
        if isinstance(r, dict) and isinstance(r.get("id"), int):
            live[r["id"]] = str(r.get("kind", "diffdrive"))
    return lambda rid: (live[rid], True) if rid in live else (default, False)


def coord_ack(tick: int, actions) -> CoordAck:
    """The ack of tick ``tick``: the tasks, spawns and removes among ``actions``, in order."""
    ack = CoordAck(tick=max(tick, 0))
    for action in actions:
        match action:
            case SendTask(robot=rid, task=task):
                ack.task_robots.append(rid)
                ack.task_ids.append(task.task_id)
            case SpawnRobot(spawn=sp):
                ack.spawn_ids.append(sp.robot)
                ack.spawn_sources.append(sp.source)
                ack.spawn_kinds.append(ROBOT_KINDS.index(sp.kind))
                ack.spawn_live.append(sp.live)
            case RemoveRobot(remove=rm):
                ack.remove_ids.append(rm.robot)
            case RequestStatus():
                ack.report = True
    return ack


class CoordinatorCore:
    """The deployer ``dep`` in the lockstep barrier (what happens after it is done, the
    caller decides: the process reopens on a failure, the in-process loop stops)."""

    def __init__(self, dep: Deployer):
        self.dep = dep
        self.sync = TickSync()

    def boundary(self, clk: Clock) -> tuple[list, CoordAck]:
        """The deployer's step of tick clk.tick, on that tick's roster changes and
        statuses alone: (its actions, their ack)."""
        dep = self.dep
        left, joined, statuses = self.sync.take(clk)
        for rid in left:
            dep.on_alive(rid, False, clk.t)
        for rid in joined:
            dep.on_alive(rid, True, clk.t)
        for st in statuses:
            dep.on_status(st)
        actions = dep.step(clk.t)
        return actions, coord_ack(clk.tick, actions)

"""Who is in the swarm: one :class:`Robot` record per robot id, and the agents waiting for a body.

Pure book-keeping, no I/O: the deployer (coordinator/deployer.py) feeds it liveliness
changes, "available" tokens and Status messages, asks it for new robot ids, and asks which
robots are dead (spec 6 [P]). Units: times are simulated seconds, cycles are counts.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Container
from dataclasses import dataclass
from typing import Callable

from swarmcover.bus.messages import Spawn, Status
from swarmcover.ground.angles import wrap

log = logging.getLogger("swarmcover.coordinator")


@dataclass
class Robot:
    rid: int
    kind: str = "holonomic"
    live: bool = False
    alive: bool = False          # liveliness token present
    status: Status | None = None
    status_cycle: int = -1       # cycle in which the last status arrived
    spawned_t: float = 0.0
    dead: bool = False
    gone_since: float | None = None  # sim time its liveliness token vanished


class Roster:
    """The robots by id, the agents up without a body, and the ids this deployer asked for.

    robot_kind: robot id -> (kind, live) for a robot first seen here."""

    def __init__(self, robot_kind: Callable[[int], tuple[str, bool]] | None = None):
        self.robot_kind = robot_kind or (lambda rid: ("holonomic", False))
        self.robots: dict[int, Robot] = {}
        self.next_robot = 0
        # agents up without a body (avail/robot/<id>: started by hand, any host), placed
        # before new robots are asked for; lowest id first
        self.available: set[int] = set()
        self.joined = 0                              # robots placed from self.available
        self.spawned: set[int] = set()               # ids this deployer asked bodies for

    def get(self, rid: int) -> Robot | None:
        return self.robots.get(rid)

    def _new(self, rid: int, kind: str | None = None, live: bool | None = None) -> Robot:
        k, lv = self.robot_kind(rid)
        r = self.robots[rid] = Robot(rid, kind=kind or k, live=lv if live is None else live)
        self.next_robot = max(self.next_robot, rid + 1)
        return r

    # ------------------------------------------------------------------ events
    def on_available(self, rid: int, present: bool, placed: Container[int]) -> None:
        """An agent with no body came (``present``) or went, or got its body (it is ours
        when it holds a vertex, in ``placed``, or we spawned it)."""
        if not present:
            self.available.discard(rid)
            return
        r = self.robots.get(rid)
        if r is not None and (rid in placed or rid in self.spawned or r.dead):
            return  # ours already: the token outlived the body's first Sense
        if r is not None:  # its alive token or first status came first
            del self.robots[rid]
        self.available.add(rid)
        self.next_robot = max(self.next_robot, rid + 1)
        log.info("robot %d is available (an agent without a body): %d waiting",
                 rid, len(self.available))

    def admit(self, st: Status, cycle: int) -> Robot | None:
        """Record a Status (arrived in ``cycle``) on its robot; None when it does not count:
        from an agent without a body, a dead robot, or older than the one held."""
        if st.robot in self.available:
            return None
        r = self.robots.get(st.robot)
        if r is None:
            r = self._new(st.robot, kind=st.kind or None, live=st.live)
        if r.dead:
            return None
        if r.status is not None and st.seq < r.status.seq and st.t <= r.status.t:
            return None  # stale
        r.status = st
        r.status_cycle = cycle
        r.alive = True
        r.gone_since = None
        return r

    def on_alive(self, rid: int, present: bool, now: float) -> None:
        """A liveliness token came or went at sim time ``now``."""
        if rid in self.available:
            if not present:
                self.available.discard(rid)
            return
        r = self.robots.get(rid)
        if present:
            if r is None:
                r = self._new(rid)
            if not r.dead:
                r.alive = True
                r.gone_since = None
            return
        if r is None or r.dead:
            return
        # not dead yet: a router restart or a network hiccup removes every token at once.
        # Death needs the token to stay gone for dead_grace_s of *simulated* time, and the
        # world's clock does not reach us while the router is down.
        r.alive = False
        if r.gone_since is None:
            r.gone_since = now

    # ------------------------------------------------------------------ spawns
    def spawn(self, source: int, now: float) -> Spawn:
        """A new robot at ``source``: an available agent if there is one (lowest id), else
        a new id for ``run`` to start an agent under. Returns the Spawn message to send."""
        if self.available:
            rid = min(self.available)
            self.available.discard(rid)
            self.joined += 1
            log.info("placing available robot %d at source %d (%d more waiting)", rid, source,
                     len(self.available))
        else:
            rid = self.next_robot
            while rid in self.robots:
                rid += 1
            self.next_robot = rid + 1
        self.spawned.add(rid)
        kind, live = self.robot_kind(rid)
        self.robots[rid] = Robot(rid, kind=kind, live=live, spawned_t=now)
        return Spawn(robot=rid, source=source, kind=kind, live=live)

    # ------------------------------------------------------------------ deaths
    def token_gone(self, now: float, grace_s: float) -> list[Robot]:
        """Robots whose liveliness token has been gone for ``grace_s`` sim seconds."""
        return [r for r in self.robots.values()
                if not r.dead and r.gone_since is not None and now - r.gone_since >= grace_s]

    def silent(self, cycle: int, after_cycles: int, placed: Container[int]) -> list[Robot]:
        """Alive robots holding a vertex (in ``placed``) with no status for
        ``after_cycles`` cycles."""
        return [r for r in self.robots.values()
                if r.alive and not r.dead and r.rid in placed
                and cycle - r.status_cycle >= after_cycles]

    @staticmethod
    def mark_dead(r: Robot) -> None:
        r.dead = True
        r.alive = False

    # ------------------------------------------------------------------ queries
    def live(self, rid: int) -> bool:
        """Known and not dead (its token may be briefly gone)."""
        r = self.robots.get(rid)
        return r is not None and not r.dead

    def in_use(self) -> int:
        """Robots not dead (what robots_max bounds)."""
        return sum(1 for r in self.robots.values() if not r.dead)

    def alive_count(self) -> int:
        return sum(1 for r in self.robots.values() if r.alive and not r.dead)

    def mutual(self, a: int, b: int) -> float | None:
        """heading(a) - heading(b) (rad) from the robots' current Status (mutual bearings),
        or None."""
        ra, rb = self.robots.get(a), self.robots.get(b)
        if ra is None or rb is None or ra.status is None or rb.status is None:
            return None
        sa = dict(zip(ra.status.nbr_ids, ra.status.nbr_bearings))
        sb = dict(zip(rb.status.nbr_ids, rb.status.nbr_bearings))
        if b not in sa or a not in sb:
            return None
        return wrap(sb[a] - sa[b] + math.pi)

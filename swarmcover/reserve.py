"""Agents started ahead of their robots (``swarmcover run --reserve N``). Pure book-keeping.

In lockstep a spawned body's first tick waits for its agent's process to start: on a loaded
two-core machine that is 0.2-1 s of wall time per robot, a sixth of a small room's whole
distributed run. So ``run`` keeps a few agent processes running ahead, for the ids the
coordinator will give its next robots: a new robot id is the highest id seen so far plus
one (coordinator.roster.Roster: spawned robots, and agents that joined by hand). A reserved
agent does not offer itself as available (``swarmcover agent --reserve``): the coordinator
never learns of it before its body exists, so its decisions, and the run, are the same with
a reserve or without; only the waiting goes. A guess that turns out wrong (a restarted
coordinator, an agent joining by hand) costs an idle process, which is stopped.
"""
from __future__ import annotations

from collections.abc import Iterable

__all__ = ["AgentReserve"]


class AgentReserve:
    """The ids reserved ahead of the coordinator's next spawns.

    size: how many agents to keep ahead (0: none). ``ids``: the reserved ids whose agents
    run now. Feed :meth:`saw` every robot id the run learns of (spawned, joined by hand);
    :meth:`take` when a Spawn comes; :meth:`plan` says what to start and what to stop."""

    def __init__(self, size: int):
        self.size = max(0, int(size))
        self.ids: set[int] = set()
        self.passed: set[int] = set()   # reserved ids passed over (their agents stopped)
        self.started = False   # the caller's: whether it reserves yet
        self.top = -1          # highest robot id seen (spawned or joined)

    def saw(self, ids: Iterable[int]) -> None:
        for r in ids:
            self.top = max(self.top, int(r))

    def take(self, rid: int) -> bool:
        """Robot ``rid`` was spawned: True if its agent is already running (reserved)."""
        self.saw((rid,))
        if rid in self.ids:
            self.ids.discard(rid)
            return True
        return False

    def plan(self) -> tuple[list[int], list[int]]:
        """(ids to start, ids to stop): keep top + 1 .. top + size reserved; a reserved id
        at or below the top was passed over and its agent is not needed."""
        stop = sorted(r for r in self.ids if r <= self.top)
        self.ids -= set(stop)
        self.passed |= set(stop)
        start = [r for r in range(self.top + 1, self.top + 1 + self.size) if r not in self.ids]
        self.ids |= set(start)
        return start, stop

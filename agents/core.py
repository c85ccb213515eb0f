"""One robot's agent without its transport: what the agent process (agents/node.py) and
the in-process loop (swarmcover/simloop.py) both run, so the two cannot drift apart.

:class:`AgentCore` owns the :class:`agents.behaviours.Behaviour`, numbers the Status
messages (``seq``), publishes one every ``status_every`` of its own Sense ticks, on every
state, task-state or contact change and when the Sense asks for one (``Sense.report``), and
stops the robot (no command) when the behaviour raises, logging the first error. After each
step, :attr:`AgentCore.idle` says whether the robot holds still with nothing to do (the
command's ``idle`` flag: a lockstep world may then sense it less often). No I/O, no clock:
``Sense.t`` is the only time.
"""
from __future__ import annotations

import logging

from swarmcover.bus.messages import Sense, Status

from .behaviours import Behaviour, Command
from .params import AgentParams


class AgentCore:
    """The Behaviour plus the Status numbering and cadence of one robot.

    live: the Status's live flag (a live robot's agent). status_every: Sense ticks between
    periodic statuses (default: the params'). log: where the first behaviour error goes."""

    def __init__(self, params: AgentParams, robot: int, *, live: bool = False,
                 status_every: int | None = None, log: logging.Logger | None = None):
        self.beh = Behaviour(params, robot)
        self.live = live
        self.every = int(status_every or params.status_every)
        self.log = log or logging.getLogger("swarmcover.agent")
        self.seq = 0          # last Status sequence number
        self.ticks = 0        # Sense ticks stepped
        self.errors = 0       # behaviour errors (the robot stopped on each)
        self.last_t = 0.0     # Sense.t of the last tick stepped (s)
        self.idle = False     # after the last step: holding still with nothing to do

    def status(self, tick: int = -1, pose: list | None = None) -> Status:
        """The next Status (its seq counts up), for tick ``tick`` (-1: outside a tick,
        e.g. at start-up or as a heartbeat); ``pose``: a live body's telemetry."""
        self.seq += 1
        st = self.beh.status_message(self.seq, self.last_t, tick, self.live, pose)
        self.beh.changed = False
        return st

    def step(self, sense: Sense, pose: list | None = None) -> tuple[Command | None, Status | None]:
        """Step on one Sense: (the command, None if the behaviour failed and the robot must
        stop; the Status this tick publishes, before its command, or None)."""
        try:
            cmd = self.beh.step(sense)
        except Exception:  # a bug must not take the robot down: stop and say so once
            self.errors += 1
            if self.errors == 1:
                self.log.exception("behaviour error at tick %d (robot stops)", sense.tick)
            cmd = None
        self.ticks += 1
        self.last_t = sense.t
        self.idle = cmd is not None and self.beh.idle
        st = None
        if self.beh.changed or self.ticks % self.every == 0 or sense.report:
            st = self.status(sense.tick, pose)
        return cmd, st

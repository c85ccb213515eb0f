"""``swarmcover run``'s side of the hosts (issue 18.4): which hosts offer slots, on which
one each agent starts, and stopping them all at the end. Thin: the rule is
``swarmcover.hosts.pick_host``; the wire is ``swarmcover.hosts``.

Called from run's main loop only (its Zenoh callbacks hand token and event samples to the
loop's queue); each request is a Zenoh query answered in milliseconds, bounded by
``timeout``.
"""
from __future__ import annotations

import logging
import statistics
import time
from collections import Counter

from swarmcover.bus.keys import Keys
from swarmcover.bus.messages import Spawn
from swarmcover.hosts import (HostEvent, HostInfo, HostReply, HostStart, HostStop,
                              HostWireError, decode, encode, pick_host, tally_line)

LOCAL = "local"
SILENT_S = 30.0     # a host that did not answer a start is not asked again for this long
MEET_RETRY_S = 2.0  # a host whose token is there but whose slots are unknown: asked again
log = logging.getLogger("swarmcover.run")


class HostPool:
    """The hosts of a swarm as run sees them, and the agents run placed on them.

    hosts: name -> its latest slots (HostInfo); where: robot -> host, for the agents run
    started on a host and that have not exited (placed: every robot it started on one);
    started: place ("local" or a host's name) -> agents run started there; lost: host that
    went away -> the robots it had then."""

    def __init__(self, session, keys: Keys, run_id: str, config_text: str,
                 timeout: float = 5.0):
        self.session, self.keys, self.run_id = session, keys, run_id
        self.config = config_text
        self.timeout = timeout
        self.hosts: dict[str, HostInfo] = {}
        self.where: dict[int, str] = {}
        self.placed: set[int] = set()        # every robot run ever started on a host
        self.started: Counter = Counter()
        self.lost: dict[str, list[int]] = {}
        self.capacity: dict[str, int] = {}
        self.start_s: dict[str, list[float]] = {}
        self.silent: dict[str, float] = {}   # host -> until when it is not asked
        self.tokens: set[str] = set()        # hosts whose token is present
        self.cancel: dict[str, set[int]] = {}  # host -> robots of starts it did not answer
        self._full_said = False

    # -- what the hosts say
    def on_token(self, name: str, present: bool) -> None:
        """A host's liveliness token came (ask its slots) or went (its agents went with it)."""
        if present:
            self.tokens.add(name)
            if name not in self.hosts:
                self.silent.pop(name, None)
                self._meet(name, first=True)
            return
        self.tokens.discard(name)
        info = self.hosts.pop(name, None)
        if info is None:
            return
        robots = sorted(r for r, h in self.where.items() if h == name)
        for r in robots:
            del self.where[r]
        self.lost[name] = robots
        log.warning("host %s went away with %d of run's agents (robots %s): the coordinator "
                    "refills their holes", name, len(robots), robots)

    def _meet(self, name: str, first: bool = False) -> None:
        """Ask a host whose token is there for its slots (the route to its queryable may
        lag its token by a moment: asked again after MEET_RETRY_S, by refresh)."""
        info = self._ask(name, b"", HostInfo, silent_s=MEET_RETRY_S, quiet=not first)
        if info is not None:
            self._saw(info, fresh=True)
            self._back(info)
            self._cancel(name)
            log.info("host %s offers %d agent slots (%d free)", name, info.capacity, info.free)

    def refresh(self) -> None:
        """Ask again the hosts whose token is present and whose slots are unknown."""
        now = time.monotonic()
        for name in sorted(self.tokens - set(self.hosts)):
            if self.silent.get(name, 0.0) <= now:
                self._meet(name)

    def on_event(self, payload: bytes) -> tuple[HostEvent | None, bool]:
        """A host's event, and whether it is about an agent run placed there (a start that
        timed out may still have run late: that agent is not run's, and is stopped)."""
        try:
            ev = decode(payload, HostEvent)
        except HostWireError as e:
            log.warning("dropping a host event: %s", e)
            return None, False
        name = ev.info.name
        ours = self.where.get(ev.robot) == name
        if name in self.hosts:
            self._saw(ev.info)
            self.silent.pop(name, None)
            self._cancel(name)
        if ev.what == "ready" and ev.start_s is not None:
            self.start_s.setdefault(name, []).append(ev.start_s)
        elif ev.what in ("failed", "exited") and ours:
            del self.where[ev.robot]
        return ev, ours

    def wait(self, n: int, timeout: float, stop) -> bool:
        """Wait up to ``timeout`` s until ``n`` hosts announced themselves."""
        end = time.monotonic() + timeout
        while len(self.hosts) < n and time.monotonic() < end and not stop.is_set():
            try:
                replies = list(self.session.liveliness().get(self.keys.alive_hosts(),
                                                             timeout=1.0))
            except Exception as e:  # a closing session
                log.debug("host query failed: %s", e)
                replies = []
            for r in replies:
                if r.ok is not None:
                    name = self.keys.host_name(str(r.ok.key_expr))
                    if name:
                        self.on_token(name, True)
            stop.wait(0.3)
        return len(self.hosts) >= n

    # -- placing agents
    def place(self, sp: Spawn, limits: tuple[float, float] | None) -> str | None:
        """Start robot ``sp.robot``'s agent on the host with the most free slots (the next
        one if it refuses or does not answer); the host's name, or None: start it locally."""
        req = HostStart(run=self.run_id, robot=sp.robot, kind=sp.kind, live=sp.live,
                        v_max=limits[0] if limits else None,
                        w_max=limits[1] if limits else None, config=self.config)
        self.refresh()
        now = time.monotonic()
        tried = {n for n, until in self.silent.items() if until > now}
        while (name := pick_host(self.hosts.values(), tried)) is not None:
            tried.add(name)
            reply = self._ask(name, encode(req), HostReply)
            if reply is None:  # it may still start it, late: stopped when it is heard of
                self.cancel.setdefault(name, set()).add(sp.robot)
                continue
            self._saw(reply.info)
            if reply.ok:
                self.where[sp.robot] = name
                self.placed.add(sp.robot)
                self.started[name] += 1
                return name
            log.warning("host %s refused robot %d: %s", name, sp.robot, reply.why)
        if self.hosts and not self._full_said:
            self._full_said = True
            log.warning("no host has a free slot (%s): starting robot %d's agent on this "
                        "machine, and any more that do not fit", self.tally(), sp.robot)
        self.started[LOCAL] += 1
        return None

    def stop_all(self) -> None:
        """Ask every host to stop this run's agents (each answers once they exited)."""
        for name in list(self.hosts):
            reply = self._ask(name, encode(HostStop(run=self.run_id)), HostReply,
                              timeout=self.timeout + 10.0)
            if reply is not None:
                self._saw(reply.info)
                if reply.robots:
                    log.info("host %s stopped robots %s", name, list(reply.robots))
        self.where.clear()

    # -- what run reports
    def running(self) -> int:
        return len(self.where)

    def tally(self, local: int | None = None) -> str:
        """``local 2, A 5, B 4``: agents of this run running where, now."""
        counts = Counter(self.where.values())
        for name in self.hosts:
            counts.setdefault(name, 0)
        if local is not None:
            counts[LOCAL] = local
        return tally_line(counts)

    def report(self) -> dict:
        """summary.json's ``hosts``: per host, its capacity, the agents run started there,
        the robots it had when it went away (null if it did not), and its agents' median
        start time (request to READY, s)."""
        out = {}
        for name in sorted(set(self.capacity) | set(self.lost)):
            s = self.start_s.get(name) or []
            out[name] = dict(capacity=self.capacity.get(name), agents_started=self.started[name],
                             lost_with=self.lost.get(name),
                             agent_start_s_median=statistics.median(s) if s else None)
        return out

    def _cancel(self, name: str) -> None:
        """Stop what the starts ``name`` did not answer may have started there since."""
        for r in sorted(self.cancel.pop(name, ())):
            if self.where.get(r) != name:
                rep = self._ask(name, encode(HostStop(run=self.run_id, robot=r)), HostReply,
                                silent_s=0.0, quiet=True)
                if rep is not None and rep.ok:
                    log.warning("host %s started robot %d late (its start had timed out and "
                                "the robot went elsewhere): stopped it there", name, r)

    def _back(self, info: HostInfo) -> None:
        """A host that went away is back (its link to the run's router flapped: a router
        restart): the robots it still runs are run's again, not lost."""
        robots = self.lost.get(info.name)
        if not robots:
            return
        kept = [r for r in robots if r in info.running]
        for r in kept:
            self.where[r] = info.name
        self.lost[info.name] = [r for r in robots if r not in kept]
        if not self.lost[info.name]:
            del self.lost[info.name]
        if kept:
            log.info("host %s is back with robots %s", info.name, kept)

    # -- the wire
    def _saw(self, info: HostInfo, fresh: bool = False) -> None:
        old = self.hosts.get(info.name)
        if fresh or old is None or info.seq >= old.seq:
            self.hosts[info.name] = info
            self.capacity[info.name] = info.capacity

    def _ask(self, name: str, payload: bytes, typ, timeout: float | None = None,
             silent_s: float = SILENT_S, quiet: bool = False):
        """One query to host ``name``; its decoded answer, or None (logged, and the host is
        not asked again for ``silent_s``: a hung host must not cost every spawn a timeout)."""
        why = f"no answer within {timeout or self.timeout:.0f} s"
        try:
            for r in self.session.get(self.keys.host(name), payload=payload or None,
                                      timeout=timeout or self.timeout):
                if r.ok is not None:
                    return decode(r.ok.payload.to_bytes(), typ)
                why = r.err.payload.to_bytes().decode(errors="replace")  # "Timeout", ...
                break
        except HostWireError as e:
            why = str(e)
        except Exception as e:  # a closing session, a host that went away meanwhile
            why = str(e)
        (log.debug if quiet else log.warning)(
            "host %s did not answer (%s): not asked again for %.0f s", name, why, silent_s)
        if silent_s > 0:
            self.silent[name] = time.monotonic() + silent_s
        return None

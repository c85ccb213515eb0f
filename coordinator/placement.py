"""Where the robots are in the complex: which robot holds which vertex, and the cycle's snapshot.

Pure book-keeping, no I/O. Vertices are integer ids (sources first: vertex k is source k);
bearings are radians in the recording robot's frame; drive lengths are metres. The
deployer's :meth:`coordinator.deployer.Deployer.build_snapshot` is :meth:`Placement.snapshot`.
"""
from __future__ import annotations

from swarmcover.ground.angles import wrap

from .planner import Snapshot, source_component
from .roster import Roster

SETTLED_STATES = ("holding", "idle")


def near_any(bearing: float, bearings, tol: float = 0.02) -> bool:
    """Whether ``bearing`` is within ``tol`` rad of one of ``bearings`` (a contact seen
    again: the agent keeps reporting a pinned contact)."""
    return any(abs(wrap(bearing - b)) < tol for b in bearings)


class Placement:
    """Robots on vertices, the vertex ids handed out, and what is known about the vertices."""

    def __init__(self, n_sources: int):
        self.vertex_of: dict[int, int] = {}          # robot -> vertex
        self.next_vertex = n_sources
        self.known: list[tuple[int, int, float]] = []  # (f, new vertex, clear drive length)
        self.contact: dict[int, float] = {}          # vertex -> sticky contact bearing
        self.td_contacts: dict[int, list[float]] = {}  # vertex -> contacts of failed drives
        self.redundant: set[int] = set()             # vertices
        self.left: set[int] = set()                  # robots sent away (redundant, idle)
        self.cut_off: set[int] = set()               # of those, sent away as cut off

    def new_vertex(self) -> int:
        v = self.next_vertex
        self.next_vertex += 1
        return v

    def note_contact(self, v: int, st, td_failed: bool) -> None:
        """The contact a Status from the robot at vertex ``v`` reports. ``td_failed``: the
        status ends a test drive that touched (of a push in flight).

        Back from a test drive that touched, its contact is the drive's (the agent pins it),
        felt out there, not a wall at the vertex. Recorded on the first status that reports
        the failure: the job hears of it only later, and this status used to be adopted as
        a resting contact first (corridor_doors, eps_rv = 0.05: 46 of 53 adopted contacts
        were test-drive contacts, and a door was closed by one, certified at 81% coverage)."""
        if st.contact and st.task_state == "failed" and td_failed:
            tdc = self.td_contacts.setdefault(v, [])
            if not near_any(st.contact_bearing, tdc):
                tdc.append(st.contact_bearing)
        if (st.contact and st.state == "holding" and st.vertex == v
                and st.task_state != "running"
                and not near_any(st.contact_bearing, self.td_contacts.get(v, ()))):
            self.contact[v] = st.contact_bearing

    def vacate(self, rid: int) -> None:
        """Robot ``rid`` is gone: its vertex is free, and the contact felt there forgotten."""
        v = self.vertex_of.pop(rid, None)
        if v is not None:
            self.contact.pop(v, None)

    def members(self, roster: Roster) -> list[int]:
        """Robots in the complex: alive, holding a vertex, not sent away (sorted ids)."""
        out = []
        for rid, v in self.vertex_of.items():
            r = roster.get(rid)
            if r is None or r.dead or not r.alive or r.status is None or rid in self.left:
                continue
            out.append(rid)
        return sorted(out)

    def rejoin(self, roster: Roster, sources: list[float]) -> list[tuple[int, int]]:
        """Robots sent away as cut off that a robot linked to a source sees again, and that
        see it (their Status, both ways): each holds a new vertex again, where it stands.
        Returns (robot, vertex) pairs; the caller tells each to hold it."""
        if not self.cut_off:
            return []
        snap = self.snapshot(roster, sources)
        linked = {snap.occupant[v] for v in source_component(snap)}
        out = []
        for rid in sorted(self.cut_off):
            r = roster.get(rid)
            if r is None or r.dead or not r.alive or r.status is None:
                continue
            sees = set(r.status.nbr_ids) & linked
            if any(rid in roster.get(m).status.nbr_ids for m in sees):
                self.cut_off.discard(rid)
                self.left.discard(rid)
                self.vertex_of[rid] = v = self.next_vertex
                self.next_vertex += 1
                linked.add(rid)
                out.append((rid, v))
        return out

    def cut_off_triangle(self, roster: Roster) -> tuple[int, int, int] | None:
        """Three robots sent away as cut off (alive) that all see one another (their Status,
        both ways), or None. Such robots stand in free space and cover area together, and
        none of them sees a robot of the complex that sees it back (else it would link
        again, :meth:`rejoin`): a part of the swarm the certificate cannot count.
        bench/unseen.py seed 7 map 17: the 24 robots of the room behind a 0.30 rv door
        were cut off at once, and the room was certified with the complex covering 59% of
        the map."""
        live = {}
        for rid in sorted(self.cut_off):
            r = roster.get(rid)
            if r is not None and not r.dead and r.alive and r.status is not None:
                live[rid] = set(r.status.nbr_ids)
        mutual = {a: {b for b in live[a] if b in live and a in live[b]} for a in live}
        for a in sorted(mutual):
            for b in sorted(x for x in mutual[a] if x > a):
                for c in sorted(x for x in mutual[a] & mutual[b] if x > b):
                    return (a, b, c)
        return None

    def all_settled(self, roster: Roster, skip=()) -> bool:
        """Every member's agent (but those in ``skip``) reports no running task and a
        settled state."""
        for rid in self.members(roster):
            if rid in skip:
                continue
            st = roster.get(rid).status
            if st.task_state == "running" or st.state not in SETTLED_STATES:
                return False
        return True

    def holders(self, roster: Roster) -> dict[int, int]:
        """vertex -> the live robot holding it now (not one sent away)."""
        return {u: r for r, u in self.vertex_of.items()
                if roster.live(r) and r not in self.left}

    def snapshot(self, roster: Roster, sources: list[float]) -> Snapshot:
        """The complex as the members see it now (``sources``: base headings by index)."""
        members = self.members(roster)
        vert: dict[int, int] = {}
        taken: set[int] = set()
        for rid in members:
            v = self.vertex_of[rid]
            if v in taken:
                # two robots claim one vertex (a restart after an interrupted push): the
                # second one is a position of its own
                v = self.vertex_of[rid] = self.next_vertex
                self.next_vertex += 1
            taken.add(v)
            vert[rid] = v
        nbrs: dict[int, dict[int, float]] = {}
        for rid in members:
            st = roster.get(rid).status
            d = {}
            for n, b in zip(st.nbr_ids, st.nbr_bearings):
                if n in vert and n != rid:
                    d[vert[n]] = b
            nbrs[vert[rid]] = d
        occupant = {v: r for r, v in vert.items()}
        contact = {v: b for v, b in self.contact.items() if v in occupant}
        kinds = {v: roster.get(r).kind for v, r in occupant.items()}
        known = [(a, b, d) for a, b, d in self.known if a in occupant and b in occupant]
        return Snapshot(occupant=occupant, nbrs=nbrs, contact=contact, kinds=kinds,
                        sources=[k for k in range(len(sources)) if k in occupant],
                        source_dirs=sources, known=known)


def stray_vertices(snap: Snapshot, n_sources: int) -> set[int]:
    """Vertices in components of the (mutual-visibility) graph that hold no source: robots
    that lost the swarm (a failed move, a failure that cut the graph). No path can reach
    them, so their frontier could never close; they are sent away instead."""
    if not any(k in snap.occupant for k in range(n_sources)):
        return set()
    return set(snap.occupant) - source_component(snap, n_sources)

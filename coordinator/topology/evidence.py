"""Evidence before a fence side closes: the book-keeping of test drives and probes.

Pure: no I/O, no clock, no positions. The deployer records every drive's outcome here, and
an independent harness that executes the same drives geometrically can do the same; both
then pass :meth:`Evidence.fence_kwargs` to :func:`coordinator.topology.fence.detect_fence`.

The rule it serves (spec 3.4, amendment 2026-11). A fence side whose two ENDS say "no room"
(the test-drive rule: both ends' drives touched, or the both-touch rule: both ends rest on a
wall facing the open side) is not closed on that alone: a door narrower than rv between the
ends would be closed with it. The side closes only once every PROBE of the side touched. A
probe is a test drive that first moves from its end p to the point at fraction ``via_frac``
of the edge p -> q (bearing-only: visual homing on q and on the covered-side apex k, whose
bearings from that point follow from the triangle's angles), then drives perpendicular to
the edge into the open side for ``depth_rv`` (x rv). Fractions are spaced so that every
opening at least ``door_min_rv`` wide *measured along the edge* lying in front of the edge
(edge length <= rv) is passed by some probe's line with the robot's body clear of both jambs.
A door of width w in a wall at angle theta to the edge is w * cos(theta) wide along it: at
45 deg a 0.44 rv door is 0.31 rv, and bench/truth.py (seed 1, maps 267 and 496) certified
rooms behind two such doors with the default 0.4. The spacing:
spacing s = door_min_rv - 2 * robot_radius_rv, fractions 0, 1/n, ..., 1 with n = ceil(1/s).
(door_min_rv = 0.4, radius 0.06 rv: s = 0.28, fractions 0, 0.25, 0.5, 0.75, 1; the ends
0 and 1 are the edge's own end points.)

Oblique walls (amendment 2026-11-25). A perpendicular probe line passes an opening of
width w in a wall at angle theta to the edge only if w cos(theta) - 2r exceeds the line
spacing: at 45 deg a 0.44 rv door was missed. A probe that touches tells which touch sector
stopped it; the wall's normal lies within tau (= pi / N_T, 22.5 deg) of that sector's
centre. So a touched interior probe whose sector centre is more than
``TopologyParams.tilt_min`` (default tau: not in the line's own sector) off the direction
driven is driven again from the same point on the edge, along that centre (a TILTED probe,
Deployment.tilt), and so is every touched probe of a side whose end rests on a wall that
far off (a corner). A re-driven line is within tau of the wall's normal; a line not
re-driven is within tau + tilt_min. The lines of one side are at most L/n apart along the
edge (less across tilted lines), so every opening in a wall the side felt at least
(L/n + 2r) / cos(tau + tilt_min) wide (:func:`tilted_door_rv`: 0.52 rv at the defaults,
whatever the wall's angle; 0.41 with tilt_min 3 deg, at a measured cost in TopologyParams)
is passed by one of them. The side closes once every interior probe touched and, where
needed, its tilted probes touched too.

coordinator.topology.fence asks only for the interior fractions (0 < f < 1): the ends' own drives
or contacts made the side a candidate, and interior probes at most s apart and less than s
from the ends cross every opening >= door_min_rv within the edge's span. A recorded probe
with via_frac 0 (a perpendicular drive from an end) counts as a failed direction at that
vertex, like any drive. Interior probes are keyed by (edge, side, fraction): probes of
different fractions driven by one robot in one direction do not stand in for each other.

Wall sweeps (amendment 2026-11-27, TopologyParams.sweep, the default). Probe lines at any
spacing leave openings between them, and a door straddling an edge's end beside neither
edge's lines (bench/truth.py seed 0 maps 70 and 381, seed 1 five more: 0.30 rv doors that
a 0.12 rv robot drives through). So each END of a candidate side drives its own "no
room" direction into the wall, and on the touch slides along the wall, pressing into it
(the contact's touch sector gives its normal within tau), first towards the other end
until it crosses the edge's perpendicular at fraction ``far`` (1/2 + sweep_overlap / 2),
then back past its own end until it crosses the ray there ``stop`` beyond the end's
perpendicular (the neighbouring fence side's perpendicular, so the wall in front of the
vertex between the two sides is swept too). It tracks both lines bearing-only (its
position from the bearings of the robots around its vertex, whose shape the triangles'
angles give; between fixes by dead reckoning that never runs ahead of it). It keeps the
wall on one hand and turns with it: into concave corners, and round the end of a wall it
loses (one touch sector per agents' sweep_lost_m without a touch). Going round a wall's end
by 135 deg or more since its last turn into a wall is an OPENING at least a body wide (a
narrower gap stops the body on its far side: a turn into a wall); the robot stays there as
a new robot (like a clear probe: its own deployments explore what lies beyond), and so
does one whose wall recedes beyond TopologyParams.sweep_depth. (With the experimental
TopologyParams.sweep_lenses, out of every lens at its end: the edge's and those of the
segments from the end to the robots round it, each of which puts a point in it as near one
of two robots as the edge's lens does (ground.geometry.lens_radii; their union is
star-shaped from the end, so a wall followed in it encloses only what it holds; the far line
lies in the edge's own lens); the first drive then goes on while in them, at most d0.) Driving into an opening, a
wall that blocks the body within its own length is a turn into a wall, not an opening,
unless the robot went round to the back of the wall it followed (turned back 135 deg since
its normal last held for a body length): a bump's face or a raster wall's step is then
swept past, a door in a followed wall stays an opening whatever stands behind it. A jagged or bending wall, a
niche, a box's corner turn it back as far as forward, or less. Measured in the world's own
physics and touch sensors (tests/test_agent_sweep.py; robot radius r = 0.06 m, touch skin
0.015 m, the agent's defaults): every door at least 0.18 m = 2 r + 0.06 m wide in a 0.1 m
wall was found at every wall angle tried (0-45 deg in 7.5 deg steps, two noise seeds);
bench/sweep.py's emulation finds every one at least 0.17 m. A sweep reports the part of
the edge it joined: from its end's ray (-inf in that end's fractions) or the fraction
where it stopped short, to the farthest fraction it reached. The side closes on evidence
once the joined intervals of its two ends cover the whole line of fractions (-inf, +inf):
the wall in front of it, from the ray at one end to the ray at the other, was followed by
a robot's body that went round no wall's end.

Keys are node ids of the complex (the deployer's vertex ids, or a harness's point ids).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Container, Iterable, Mapping

__all__ = ["ProbeKey", "SideKey", "DriveRecord", "Evidence", "probe_fractions",
           "probe_depth_rv", "probe_key", "needs_tilt", "tilted_door_rv", "TILT_MATCH",
           "FOUND_TOUCH_LIMIT",
           "sweep_interval", "sweep_gaps"]

# (u, v, sigma, frac): edge u < v (node ids), canonical open side sigma (coordinator.topology.fence's
# convention: +1 is counter-clockwise from v as seen by u), fraction measured from u.
ProbeKey = tuple[int, int, int, float]

# (u, v, sigma): a side (edge u < v, canonical open side sigma)
SideKey = tuple[int, int, int]

_FRAC_DIGITS = 3
INF = math.inf

# A tilted probe that touched stands for any needed tilt within this (rad) of its own: the
# same direction, up to the bearing noise in the edge's perpendicular.
TILT_MATCH = math.radians(5.0)

# Probes that may touch at a key where a drive found room (Evidence.found_rooms) before the
# side stops offering it: then nothing closes that side, and the run ends uncertified
# unless a robot gets into the room another way.
FOUND_TOUCH_LIMIT = 2


def probe_fractions(door_min_rv: float = 0.4, robot_radius_rv: float = 0.06) -> tuple[float, ...]:
    """Fractions of an edge (from one end, 0 and 1 included) where probes go.

    Spacing s = door_min_rv - 2 * robot_radius_rv (x rv; edge lengths <= rv): an opening of
    width w >= door_min_rv whose span along the edge lies within the edge holds an interval
    of length w - 2 r >= s where a robot's centre line clears both jambs, and one probe
    line falls in it. Raises ValueError (naming the field) when s <= 0."""
    s = float(door_min_rv) - 2.0 * float(robot_radius_rv)
    if not s > 0.0 or not math.isfinite(s):
        raise ValueError(f"[coordinator] door_min_rv = {door_min_rv!r}: must exceed the robot's "
                         f"diameter ({2.0 * robot_radius_rv:.3g} rv)")
    n = max(1, math.ceil(1.0 / s - 1e-9))
    return tuple(round(k / n, _FRAC_DIGITS) for k in range(n + 1))


def probe_depth_rv(frac: float, d0_rv: float, d_td_rv: float, lean: float = 0.0) -> float:
    """How far (x rv) a probe at ``frac`` drives from its edge into the open side.

    End probes (0 or 1) drive the test-drive length. Interior probes keep their end point
    within d0 of both ends of an edge of length rv, at least a quarter of d0 (for very fine
    fractions). ``lean``: the drive's unit vector's component along the edge, toward the
    end the fraction is measured to (0 for a perpendicular probe: sqrt(d0^2 - max(f, 1 -
    f)^2); sin of the tilt for a tilted one). A probe that does not touch has found room:
    its robot stays there as the new vertex."""
    f = float(frac)
    if f <= 1e-9 or f >= 1.0 - 1e-9:
        return float(d_td_rv)
    sx = max(-1.0, min(1.0, float(lean)))
    c2 = 1.0 - sx * sx
    # |(f, 0) + t (sx, cy) - (e, 0)|^2 <= d0^2 for both ends e = 0, 1
    reach = min(-a * sx + math.sqrt(max(d0_rv * d0_rv - a * a * c2, 0.0))
                for a in (f, f - 1.0))
    return max(reach, 0.25 * d0_rv)


def needs_tilt(offset: float | None, tilt_min: float) -> bool:
    """Whether a touched probe whose touch sector centre is ``offset`` (rad, from the
    direction driven) is driven again along that centre: more than ``tilt_min`` (rad,
    TopologyParams.tilt_min) off (see the module docstring)."""
    return offset is not None and abs(float(offset)) > float(tilt_min)


def tilted_door_rv(fractions, robot_radius_rv: float, tau: float, tilt_min: float) -> float:
    """Narrowest opening (x rv), at any angle of a wall the side's robots felt, that a side
    closed on evidence cannot have: (largest gap between fractions + 2r) / cos(tau +
    tilt_min): the re-driven lines are within tau of the wall's normal, those not
    re-driven within tau + tilt_min. Edges at most rv long."""
    fr = sorted(float(f) for f in fractions)
    gap = max(b - a for a, b in zip(fr, fr[1:]))
    return (gap + 2.0 * float(robot_radius_rv)) / math.cos(float(tau) + float(tilt_min))


def probe_key(vertex: int, edge: tuple[int, int], sigma: int, via_frac: float) -> ProbeKey:
    """Canonical key of the probe of ``edge`` (u < v) on side ``sigma`` driven from
    ``vertex`` (u or v) at ``via_frac`` from it."""
    u, v = int(edge[0]), int(edge[1])
    f = float(via_frac) if int(vertex) == u else 1.0 - float(via_frac)
    return (u, v, int(sigma), round(f, _FRAC_DIGITS))


def sweep_interval(vertex: int, edge: tuple[int, int], hi: float, lo: float
                   ) -> tuple[float, float]:
    """The part of edge (u, v) (u < v) a sweep from ``vertex`` joined, in fractions from u:
    ``hi`` is the farthest fraction (from ``vertex``) it reached towards the other end,
    ``lo`` where it stopped on its way back (-inf: it crossed the ray at its own end).
    The ray at u is -inf, the ray at v +inf."""
    u, v = int(edge[0]), int(edge[1])
    a, b = float(lo), float(hi)
    if int(vertex) == u:
        return (a, b)
    return (1.0 - b, 1.0 - a)


def sweep_gaps(intervals) -> list[tuple[float, float]]:
    """The parts of (-inf, +inf) that no interval (lo, hi) covers, in order (intervals that
    touch or overlap join)."""
    gaps: list[tuple[float, float]] = []
    cur = -INF
    for lo, hi in sorted((float(a), float(b)) for a, b in intervals):
        if lo > cur:
            gaps.append((cur, lo))
        cur = max(cur, hi)
    if cur < INF:
        gaps.append((cur, INF))
    return gaps


@dataclass(frozen=True)
class DriveRecord:
    """One drive's outcome. vertex: the node it was driven from. direction: the direction
    driven (rad, that robot's body frame; the perpendicular or tilted leg for a probe).
    kind: Deployment.kind. via_frac: fraction of the approach leg (probes; 0 otherwise).
    tilt: Deployment.tilt (rad; 0 for a perpendicular probe). contact_offset: a touch's
    sector centre minus ``direction`` (rad; 0 when clear). swept: a sweep's (hi, lo)
    (:func:`sweep_interval`), None for other drives or a sweep that found room."""

    vertex: int
    direction: float
    kind: str
    edge: tuple[int, int] | None
    sigma: int
    via_frac: float
    touched: bool
    tilt: float = 0.0
    contact_offset: float = 0.0
    swept: tuple[float, float] | None = None


class Evidence:
    """Every drive's outcome, turned into detect_fence keyword arguments.

    door_min_rv: narrowest opening (x rv) a closed side is guaranteed to have been probed
    for. robot_radius_rv: the robot's body radius (x rv).
    """

    def __init__(self, *, door_min_rv: float = 0.4, robot_radius_rv: float = 0.06):
        self.door_min_rv = float(door_min_rv)
        self.robot_radius_rv = float(robot_radius_rv)
        self.fractions = probe_fractions(door_min_rv, robot_radius_rv)
        self.records: list[DriveRecord] = []
        self._failed: dict[int, list[float]] = {}
        # touched perpendicular interior probes: key -> touch sector centre - direction (rad)
        self._offsets: dict[ProbeKey, float] = {}
        # key -> tilts (rad) of its tilted probes that touched
        self._tilted: dict[ProbeKey, list[float]] = {}
        self._clear: set[ProbeKey] = set()
        # clear probe or sweep -> the vertex its robot stayed at (the room it found is
        # evidence only while that vertex stands beyond the side: :meth:`lost_rooms`)
        self._room_at: dict[ProbeKey, int] = {}
        # interior probes a FREE probe (no path, nobody refills its vertex) drove clear and
        # came back from: no evidence, the side stays open; never offered free again
        self._returned: set[ProbeKey] = set()
        # (probe key, end it was driven from) -> approach legs that failed from that end
        self._approach_fails: dict[tuple[ProbeKey, int], int] = {}
        # wall sweeps: side -> joined intervals (fractions from u, rays -inf / +inf), and
        # probe key (fraction 0 or 1: the end) -> sweeps driven from that end
        self._swept: dict[SideKey, list[tuple[float, float]]] = {}
        self._sweep_tries: dict[ProbeKey, int] = {}
        # side -> robot id that stopped one of its sweeps -> the vertex it held, standing
        # still, when it did (None: moving, or not known; :meth:`stopper_vertices`)
        self._sweep_by: dict[SideKey, dict[int, int | None]] = {}
        self._placed_n: dict[ProbeKey, int] = {}       # sweeps from that end whose robot stayed
        # interior probes a drive went clear at (room found beyond the side) -> the probes
        # that touched there since: no evidence of a wall (:meth:`found_rooms`)
        self._found: dict[ProbeKey, int] = {}
        # sides the planner asked to be swept before deploying (CyclePlan.sweep_first)
        self._asked: set[SideKey] = set()

    # ---------------------------------------------------------------- recording
    def record(self, dep, touched: bool, *, direction: float | None = None,
               returned: bool = False, contact_offset: float = 0.0,
               swept: tuple[float, float] | None = None,
               placed: int | None = None, by=()) -> DriveRecord:
        """Record the outcome of driving ``dep`` (a coordinator.topology.fence.Deployment, or anything
        with its fields). ``direction`` overrides dep.bearing (the direction actually driven,
        e.g. after lattice placement). ``touched``: the drive failed with a touch before it
        found room (a touch far enough out to keep the robot there is room, not a touch).
        ``returned``: a clear drive whose robot went back to its vertex (a free probe, see
        coordinator.planner.plan_cycle): nobody stayed in the room it found, so it is not a
        clear probe (those close a still one-sided side as the inference 'probe_clear'); its
        key goes to :meth:`returned_probes` only and the side stays open.
        ``contact_offset``: for a touch, the touch sector's centre minus the direction driven
        (rad; the agent's Status.touch_offset): a perpendicular interior probe whose offset
        :func:`needs_tilt` is then offered again, tilted along that centre.
        ``swept``: a wall sweep's (hi, lo) (fractions from its vertex, lo -inf for its
        end's ray; :func:`sweep_interval`) when it touched and swept; a sweep that found
        room or an opening is a clear drive (``touched`` False, its robot stays).
        ``placed``: for a clear drive, the vertex its robot stays at as a new robot.
        ``by``: a wall sweep's stoppers, the robot ids seen where a touch stopped it
        (:meth:`sweep_stoppers`), or a mapping robot id -> the vertex it held, standing
        still, at the stop (None when it was moving; :meth:`stopper_vertices`). A plain
        sequence books each robot as standing nowhere known."""
        d = float(dep.bearing if direction is None else direction)
        frac = float(getattr(dep, "via_frac", 0.0) or 0.0)
        edge = tuple(int(x) for x in dep.edge) if dep.edge is not None else None
        tilt = float(getattr(dep, "tilt", 0.0) or 0.0)
        rec = DriveRecord(int(dep.vertex), d, str(dep.kind), edge, int(dep.sigma), frac,
                          bool(touched), tilt, float(contact_offset) if touched else 0.0,
                          (float(swept[0]), float(swept[1])) if swept is not None else None)
        self.records.append(rec)
        if float(getattr(dep, "sweep_far", 0.0) or 0.0) > 0.0 and edge is not None:
            self._record_sweep(rec, returned, placed)
            if touched and by:
                held = by if isinstance(by, Mapping) else dict.fromkeys(by)
                seen = self._sweep_by.setdefault((*edge, rec.sigma), {})
                for r, v in held.items():
                    # a robot booked twice stands for the side only if it stood still at the
                    # same vertex both times
                    v = None if v is None else int(v)
                    seen[int(r)] = v if seen.get(int(r), v) == v else None
            return rec
        interior = rec.kind == "probe" and edge is not None and frac > 1e-9
        if touched:
            if interior:
                key = probe_key(rec.vertex, edge, rec.sigma, frac)
                if key in self._found:
                    self._found[key] += 1
                if tilt:
                    self._tilted.setdefault(key, []).append(tilt)
                else:
                    self._offsets[key] = rec.contact_offset
            else:
                self.add_failed_direction(rec.vertex, d)
        elif interior and returned:
            key = probe_key(rec.vertex, edge, rec.sigma, frac)
            self._returned.add(key)
            self._found.setdefault(key, 0)
        elif interior:
            # a clear interior probe found room (its robot stays there): that fraction is
            # done, it is never offered again (re-offering it stacked robots: issue 21)
            key = probe_key(rec.vertex, edge, rec.sigma, frac)
            self._clear.add(key)
            self._found.setdefault(key, 0)
            if placed is not None:
                self._room_at[key] = int(placed)
        return rec

    def record_unreached(self, dep) -> int:
        """An interior probe whose approach leg failed (its robot never reached the point on
        the edge: "via (...)"). Returns how often that probe has failed so from this end;
        from UNREACHED_LIMIT on it is given up from this end (``probe_unreachable``). An
        unreached probe is no evidence: the fence then offers it from the other end only;
        given up from both ends, its side closes only as an inference ('probe_unreachable',
        reported with the certificate), never as evidence."""
        frac = float(getattr(dep, "via_frac", 0.0) or 0.0)
        if dep.edge is None or frac <= 1e-9:
            return 0
        k = (probe_key(int(dep.vertex), tuple(int(x) for x in dep.edge), int(dep.sigma), frac),
             int(dep.vertex))
        self._approach_fails[k] = self._approach_fails.get(k, 0) + 1
        return self._approach_fails[k]

    UNREACHED_LIMIT = 2

    def _record_sweep(self, rec: DriveRecord, returned: bool, placed: int | None = None) -> None:
        """A wall sweep's outcome: its end's try, the interval it joined, or room found."""
        key = probe_key(rec.vertex, rec.edge, rec.sigma, 0.0)
        self._sweep_tries[key] = self._sweep_tries.get(key, 0) + 1
        if rec.touched:
            self.add_failed_direction(rec.vertex, rec.direction)
            if rec.swept is not None:
                u, v = rec.edge
                self._swept.setdefault((u, v, rec.sigma), []).append(
                    sweep_interval(rec.vertex, rec.edge, *rec.swept))
        elif returned:
            self._returned.add(key)
        else:
            self._clear.add(key)
            if placed is not None:
                self._room_at[key] = int(placed)
                self._placed_n[key] = self._placed_n.get(key, 0) + 1

    def lost_rooms(self, beyond: Callable[[ProbeKey, int], bool]) -> frozenset[ProbeKey]:
        """Clear probes and sweeps whose robot no longer stands beyond their side:
        ``beyond(key, vertex)`` says whether the vertex the drive's robot stayed at is seen
        from the side's ends on that side (coordinator.jobs.beyond_side). Such a drive is
        no evidence, and its try is given back (:meth:`fence_kwargs`): the inference
        'probe_clear' rests on a robot standing in the room the drive found. Without this,
        corridor_doors seed 1 certified 85% coverage: a sweep's robot stood in a doorway,
        the robots after it drifted back into the corridor, and the side before the door
        stayed closed. A lost room gives back the tries of every sweep from its end whose
        robot stayed (not the last one's only: bench/unseen.py seed 7 map 17, two of them
        at a 0.30 rv door)."""
        return frozenset(k for k in self._clear
                         if k in self._room_at and not beyond(k, self._room_at[k]))

    def rooms(self, clear: Iterable[ProbeKey]) -> dict[ProbeKey, int]:
        """Clear probe or sweep -> the vertex whose robot holds the room it found, for the
        keys ``clear`` (fence_kwargs' ``probe_clear``: those still counted) that placed a
        robot (coordinator.jobs.lone_room_holders)."""
        return {k: self._room_at[k] for k in clear if k in self._room_at}

    def add_failed_direction(self, vertex: int, direction: float) -> None:
        """A drive from ``vertex`` along ``direction`` touched (no Deployment at hand)."""
        lst = self._failed.setdefault(int(vertex), [])
        if not any(abs(math.remainder(direction - x, 2 * math.pi)) < 1e-9 for x in lst):
            lst.append(float(direction))

    # ---------------------------------------------------------------- queries
    def failed_directions(self, present: Container[int] | None = None) -> dict[int, list[float]]:
        """node -> directions of drives from it that touched (edge, single-file, isolated
        and end-probe drives): detect_fence's ``test_drive_failures``."""
        return {v: list(b) for v, b in self._failed.items() if present is None or v in present}

    def failed_probes(self, present: Container[int] | None = None) -> frozenset[ProbeKey]:
        """Keys of interior probes that touched: detect_fence's ``probe_failures`` (which
        sets aside those of :meth:`found_rooms` on sides a cut-off robot stopped a sweep
        of)."""
        return frozenset(k for k in self._offsets
                         if present is None or (k[0] in present and k[1] in present))

    def found_rooms(self, present: Container[int] | None = None) -> dict[ProbeKey, int]:
        """Interior probe keys a drive went clear at (a free probe that came back, or a
        clear probe whose robot stayed) -> how many probes touched there since. Room lies
        beyond the side there, so on a side a robot cut off from the swarm stopped a sweep
        of, a later touch at that key (a jamb clipped on the way in, that robot in the
        door) is no evidence of a wall (coordinator.topology.fence_probes):
        bench/families.py seed 0 map 1 certified a room behind a 0.30 m door uncovered
        after a free probe at fraction 0.25 had driven through the door and come back,
        and a probe at 0.25 from the other end touched. detect_fence's ``probe_found``
        (less the rooms still held)."""
        return {k: n for k, n in self._found.items()
                if present is None or (k[0] in present and k[1] in present)}

    def probe_offsets(self, present: Container[int] | None = None) -> dict[ProbeKey, float]:
        """Touched perpendicular interior probes: key -> touch sector centre - direction
        (rad): detect_fence's ``probe_offsets``."""
        return {k: o for k, o in self._offsets.items()
                if present is None or (k[0] in present and k[1] in present)}

    def tilt_failures(self, present: Container[int] | None = None
                      ) -> dict[ProbeKey, tuple[float, ...]]:
        """key -> tilts (rad) of its tilted probes that touched: detect_fence's
        ``tilt_failures``."""
        return {k: tuple(t) for k, t in self._tilted.items()
                if present is None or (k[0] in present and k[1] in present)}

    def clear_probes(self, present: Container[int] | None = None) -> frozenset[ProbeKey]:
        """Keys of interior probes that found room: detect_fence's ``probe_clear``."""
        return frozenset(k for k in self._clear
                         if present is None or (k[0] in present and k[1] in present))

    def returned_probes(self, present: Container[int] | None = None) -> frozenset[ProbeKey]:
        """Keys of interior probes a free probe drove clear and came back from (no evidence;
        not part of :meth:`fence_kwargs`): the planner's ``returned_probes``, which it never
        offers as free probes again (a push along a path may still take them)."""
        return frozenset(k for k in self._returned
                         if present is None or (k[0] in present and k[1] in present))

    def unreachable_probes(self, present: Container[int] | None = None
                           ) -> frozenset[tuple[int, int, int, float, int]]:
        """(u, v, sigma, frac, end): interior probes whose approach from ``end`` failed
        UNREACHED_LIMIT times (given up from that end only)."""
        return frozenset((*k, end) for (k, end), n in self._approach_fails.items()
                         if n >= self.UNREACHED_LIMIT
                         and (present is None or (k[0] in present and k[1] in present)))

    def sweeps(self, present: Container[int] | None = None
               ) -> dict[SideKey, tuple[tuple[float, float], ...]]:
        """side (u, v, sigma) -> the intervals its wall sweeps joined (fractions from u, the
        rays at u and v -inf and +inf): detect_fence's ``sweeps``."""
        return {k: tuple(iv) for k, iv in self._swept.items()
                if present is None or (k[0] in present and k[1] in present)}

    def sweep_tries(self, present: Container[int] | None = None) -> dict[ProbeKey, int]:
        """(u, v, sigma, end fraction 0 or 1) -> sweeps driven from that end (whatever they
        found): detect_fence's ``sweep_tries``."""
        return {k: n for k, n in self._sweep_tries.items()
                if present is None or (k[0] in present and k[1] in present)}

    def ask_sweeps(self, sides: Iterable[SideKey]) -> None:
        """Keep the sides (u, v, sigma) a plan asked to be swept first
        (``TopologyParams.sweep_fallbacks``): detect_fence's ``sweep_first`` from now on."""
        self._asked.update((int(k[0]), int(k[1]), int(k[2])) for k in sides)

    def asked_sweeps(self, present: Container[int] | None = None) -> frozenset[SideKey]:
        """The sides asked (:meth:`ask_sweeps`) whose ends are in ``present``."""
        return frozenset(k for k in self._asked
                         if present is None or (k[0] in present and k[1] in present))

    def sweep_stoppers(self, present: Container[int] | None = None
                       ) -> dict[SideKey, frozenset[int]]:
        """side (u, v, sigma) -> the robots (ids, not nodes) seen where a touch stopped one
        of its wall sweeps (a wall there may have been one of them)."""
        return {k: frozenset(r) for k, r in self._sweep_by.items()
                if present is None or (k[0] in present and k[1] in present)}

    def stopper_vertices(self, present: Container[int] | None = None
                         ) -> dict[SideKey, frozenset[int]]:
        """side (u, v, sigma) -> the vertices robots that stopped one of its wall sweeps
        held, standing still, when they did (a robot that was moving then, or booked by id
        alone, gives none). A vertex is a place of the fixed graph: a push that takes its
        robot on puts the next one there (coordinator.jobs.evidence_kwargs: 'sweep_blocked'
        counts a side while one of these is held by a robot of the swarm)."""
        out = {}
        for k, held in self._sweep_by.items():
            if present is not None and (k[0] not in present or k[1] not in present):
                continue
            at = frozenset(v for v in held.values() if v is not None)
            if at:
                out[k] = at
        return out

    def fence_kwargs(self, present: Container[int] | None = None,
                     beyond: Callable[[ProbeKey, int], bool] | None = None) -> dict:
        """Keyword arguments for detect_fence: test_drive_failures, probe_failures,
        probe_offsets, tilt_failures, probe_clear, probe_found, probe_unreachable,
        probe_fracs, sweeps, sweep_tries, sweep_first and sweep_home (restricted to nodes in ``present`` when
        given; with ``beyond``, less the :meth:`lost_rooms` and their tries)."""
        lost = self.lost_rooms(beyond) if beyond is not None else frozenset()
        tries = self.sweep_tries(present)
        for k in lost & tries.keys():
            tries[k] = max(0, tries[k] - self._placed_n.get(k, 1))
        clear = self.clear_probes(present) - lost
        asked = self.asked_sweeps(present)
        return dict(test_drive_failures=self.failed_directions(present),
                    probe_failures=self.failed_probes(present),
                    probe_offsets=self.probe_offsets(present),
                    tilt_failures=self.tilt_failures(present),
                    probe_clear=clear,
                    probe_found={k: n for k, n in self.found_rooms(present).items()
                                 if k not in clear},
                    probe_unreachable=self.unreachable_probes(present),
                    probe_fracs=self.fractions,
                    sweeps=self.sweeps(present),
                    sweep_tries=tries,
                    sweep_first=asked,
                    sweep_home=frozenset(k for k in self.returned_probes(present)
                                         if k[:3] in asked))

    def merge_failures(self, failures: Mapping[int, list[float]]) -> None:
        """Adopt failed directions kept elsewhere (e.g. a restarted coordinator)."""
        for v, lst in failures.items():
            for d in lst:
                self.add_failed_direction(int(v), float(d))

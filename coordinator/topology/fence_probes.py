"""Evidence before a fence side closes (spec 3.4 amendment 2026-11): the probes of the
candidate sides, a stage of :func:`coordinator.topology.fence.detect_fence`.

Ends that have no room are not enough. A side the ends would close (a candidate, from
:mod:`coordinator.topology.fence_sides`) becomes O only once every probe of it touched:
at the ends, the evidence u and v already have (a failed drive or a counted wall contact
within _FAILED_CONE of the perpendicular; the ends are not driven again), and the interior
probes, by key
(u, v, sigma, fraction from u; node ids u < v, the fraction rounded to 3 decimals). A
touched probe is driven again TILTED along each wall normal known at the side
(coordinator.topology.evidence). Until then the side stays frontier ('probing') and
offers its missing probes as deployments (kind 'probe'); with none left it closes on
evidence ('probes') or as an inference ('probe_clear', 'probe_unreachable'), or stays
frontier with no deployment.

Units: bearings, tilts and offsets in rad (body frame of the robot named; a tilt from
the probe's perpendicular, counter-clockwise), depths in rv. Marks map (e, sigma) (edge
id, canonical side) to a reason string; probing maps it to the side's probe
deployments, by via_frac.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from swarmcover.ground.angles import wrap
from .complex import Complex
from .evidence import (FOUND_TOUCH_LIMIT, TILT_MATCH, needs_tilt, probe_depth_rv,
                       probe_fractions, sweep_gaps)
from .fence_local import _Local
from .fence_sides import Marks, Room, Sides
from .fence_types import EVIDENCE, Deployment
from .params import TopologyParams

__all__: list[str] = []

# TopologyParams.corner_probes: convex-corner marks (spec 3.3 ii) make a side a probing
# candidate rather than closing it (True), or close it as inferred 'convex_corner' (False).
# Off by default: bench/truth.py seed 0 maps 0-12 with it on (and clear_infers on) ran
# clutter maps 10, 11, 12 to the robot cap (99, 81, 80 robots; clear probes off box corners
# place robots that form new corners), so tests/test_truth.py cannot pass either way; map
# 11 (a free-standing box) is then still a false certificate by this rule (issue 21).
# TopologyParams.clear_infers: a side whose probes are all done, some clear (room found,
# its robot stayed) while the side is still one-sided: False leaves it frontier with no
# deployment (uncertified); True closes it as inferred ('probe_clear'). bench/truth.py seed
# 0 (corner probes off): False, maps 0-39: 14 fixed (all certified), 26 stuck (22 of them
# >= 99.9 % covered: unreached probes from both ends, or a clear probe), 0 livelock, 0 cap,
# 46.2 robots; True, maps 0-36: 21 certified, 16 stuck, no false certificate beyond False's
# (#11 convex corner, #18 a 0.30 rv door). On by default: with it off, corridor_doors (seed
# 0, in-process) stopped uncertified after 114 cycles with one such side left ("no
# feasible push"). The closure is reported as inferred.


def _tilts_todo(needed, done) -> list[float]:
    """The tilts (rad) of ``needed``, merged within evidence.TILT_MATCH, that no touched
    tilt in ``done`` stands for."""
    todo: list[float] = []
    for t in needed:
        if any(abs(wrap(t - d)) <= TILT_MATCH for d in (*done, *todo)):
            continue
        todo.append(float(t))
    return todo


def _key(k) -> tuple[int, int, int, float]:
    return (int(k[0]), int(k[1]), int(k[2]), round(float(k[3]), 3))


@dataclass(frozen=True)
class ProbeEvidence:
    """The probe outcomes given to detect_fence, by normalised key.

    fracs: fractions of the edge where probes go. failed: keys of interior probes that
    touched. offsets: key -> touch sector centre minus the direction driven (rad).
    tilt_failed: key -> tilts (rad) of its tilted probes that touched. clear: keys of
    probes that found room (a sweep's: fraction 0 or 1, its end). unreached: (key, end
    node id) given up from that end. sweeps: (u, v, sigma) -> intervals its wall sweeps
    joined (fractions from u, rays -inf / +inf). sweep_tries: (u, v, sigma, 0 or 1) ->
    sweeps driven from that end. foreign: sides (u, v, sigma) one of whose sweeps a robot
    outside the sources' part of the complex stopped. found: key -> probes touched there
    since a drive went clear at it (room found; no robot holds it now). blocked: sides
    (u, v, sigma) one of whose sweeps a robot of the swarm (linked to a source) stopped.
    home: sweep keys (u, v, sigma, end) of sides asked to be swept first whose free sweep
    drove clear and came home: done for that asked side only (:func:`_side_sweeps`).
    """

    fracs: tuple
    failed: frozenset
    offsets: dict
    tilt_failed: dict
    clear: frozenset
    unreached: frozenset
    sweeps: dict = None
    sweep_tries: dict = None
    foreign: frozenset = frozenset()
    found: dict = None
    blocked: frozenset = frozenset()
    home: frozenset = frozenset()

    def gave_up(self, key, end: int) -> bool:
        return (key, end) in self.unreached

    def found_at(self, side) -> list:
        """The keys of ``side`` (u, v, sigma) where a drive found room no robot holds."""
        return [k for k in (self.found or {}) if k[:3] == tuple(side)]


def probe_evidence(probe_failures=(), probe_fracs=None, probe_unreachable=(), probe_clear=(),
                   probe_offsets=None, tilt_failures=(), sweeps=None,
                   sweep_tries=None, sweep_foreign=(), probe_found=None,
                   sweep_blocked=(), sweep_home=()) -> ProbeEvidence:
    """detect_fence's probe keywords (same names and meaning) as a :class:`ProbeEvidence`;
    the fractions default to ``evidence.probe_fractions()``."""
    fracs = tuple(probe_fracs) if probe_fracs is not None else probe_fractions()
    pfail = {_key(k) for k in probe_failures}
    poff = {_key(k): float(o) for k, o in (probe_offsets or {}).items()}
    tfail = {_key(k): tuple(float(x) for x in t) for k, t in (tilt_failures or {}).items()}
    pclear = {_key(k) for k in probe_clear}
    # unreached: (key, end) given up from that end
    punreach = {(_key(k), int(k[4])) for k in probe_unreachable}
    swept = {(int(k[0]), int(k[1]), int(k[2])): tuple((float(a), float(b)) for a, b in iv)
             for k, iv in (sweeps or {}).items()}
    tries = {_key(k): int(n) for k, n in (sweep_tries or {}).items()}
    foreign = frozenset((int(k[0]), int(k[1]), int(k[2])) for k in sweep_foreign)
    # room found at a key of a side a robot cut off from the swarm stopped a sweep of: it
    # stands in free space the complex does not hold, and the room is there; a touch at
    # that key since (a jamb clipped on the way in, that robot in the door) is no wall.
    # Elsewhere a later touch still counts (a clear drive past a pocket of a curved wall:
    # holding those sides open left cave seed 0 uncertified, "no feasible push")
    found = {_key(k): int(n) for k, n in (probe_found or {}).items()
             if (int(k[0]), int(k[1]), int(k[2])) in foreign}
    pfail -= found.keys()
    blocked = frozenset((int(k[0]), int(k[1]), int(k[2])) for k in sweep_blocked)
    home = frozenset(_key(k) for k in sweep_home)
    return ProbeEvidence(fracs, frozenset(pfail), poff, tfail, frozenset(pclear),
                         frozenset(punreach), swept, tries, foreign, found, blocked, home)


def corner_candidates(marks: Marks, ends: Marks, open_sides: Sides) -> tuple[Marks, Marks]:
    """(marks, ends) with TopologyParams.corner_probes: the convex-corner rule (spec 3.3
    ii) assumes an obstacle corner sticking out of a wall; a free-standing box breaks it
    (clutter map 11 of bench/truth.py certified at 21.8 % coverage): its marks only make a
    side a candidate ('convex_corner' in ends), probed like the others."""
    marks, ends = dict(marks), dict(ends)
    for (e, sg), why in list(marks.items()):
        if why == "convex_corner":
            del marks[(e, sg)]
            if e in open_sides and any(r[0] == sg for r in open_sides[e]):
                ends.setdefault((e, sg), "convex_corner")
    return marks, ends


def _side_probes(cx: Complex, L: _Local, P: TopologyParams, room: Room, ev: ProbeEvidence,
                 e: int, sg: int, fracs=None) -> tuple[list[Deployment], int, int]:
    """(probe deployments still to drive, n_open, n_clear) of side sg of edge e: n_open
    interior probes not done, n_clear found room. ``fracs``: the fractions to probe
    (default ``ev.fracs``; :func:`_gap_fracs` for a swept side's gaps)."""
    ids = cx.ids
    d0_rv, dtd_rv = P.d0 / P.rv, P.d_td / P.rv
    u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
    iu, iv = int(ids[u]), int(ids[v])
    pu = wrap(L.bearings(u)[v] + sg * math.pi / 2.0)
    pv = wrap(L.bearings(v)[u] - sg * math.pi / 2.0)
    inner: list[Deployment] = []
    n_clear = n_open = 0
    # wall normals the ends rest against, pointing into the open side: each interior
    # probe that touched is driven along them too (a door in a wall the side cuts
    # obliquely, e.g. at a corner, is widest along its normal)
    end_tilts = []
    for p, perp in ((u, pu), (v, pv)):
        c = room.contact(p)
        if c is not None:
            t = wrap(c - perp)
            if needs_tilt(t, P.tilt_min) and abs(t) < math.pi / 2.0 - P.tau:
                end_tilts.append(t)
    for g in (ev.fracs if fracs is None else fracs):
        if g <= 1e-9 or g >= 1.0 - 1e-9:
            # the ends: their own failed drives / contacts made the side a candidate. The
            # interior fractions alone pass every opening >= door_min_rv within the span
            # (gaps L/n <= s, and the end gaps L/n - r < s), so a perpendicular drive at
            # an end is not asked for (driving them placed 76 robots in covered corners
            # of the small map, seed 0)
            continue
        key = (iu, iv, sg, round(g, 3))
        tilt = 0.0
        if key in ev.failed:
            # touched: driven again from the same point along each known wall normal
            # oblique to the probe line (its own touch sector's centre, the ends'
            # contacts) until each of those touched too
            off = ev.offsets.get(key)
            todo = _tilts_todo(([off] if needs_tilt(off, P.tilt_min) else []) + end_tilts,
                               ev.tilt_failed.get(key, ()))
            if not todo:
                continue                  # touched along every one: evidence of a wall
            tilt = todo[0]
        if key in ev.clear:
            n_clear += 1                  # found room (its robot stays): done, not evidence
            continue
        n_open += 1
        if (ev.found or {}).get(key, 0) >= FOUND_TOUCH_LIMIT:
            continue                      # room found, no probe since got in: none more
        # the tilted drive's component along the edge, toward v (sigma +1: open side CCW
        # of u -> v, so a CCW tilt leans back toward u)
        depth = probe_depth_rv(g, d0_rv, dtd_rv, lean=-sg * math.sin(tilt))
        bu, bv = wrap(pu + tilt), wrap(pv + tilt)
        # either end can drive it, the nearer one first; an end whose approach leg kept
        # failing (it clips a jamb) has given up: the other end tries it
        a = None if ev.gave_up(key, iu) else Deployment(
            iu, bu, (iu, iv), sg, wrap(sg * math.pi / 2.0 + tilt), L.clearance(u, bu), "probe",
            round(g, 3), depth, tilt)
        b = None if ev.gave_up(key, iv) else Deployment(
            iv, bv, (iu, iv), sg, wrap(-sg * math.pi / 2.0 + tilt), L.clearance(v, bv),
            "probe", round(1.0 - g, 3), depth, tilt)
        inner.extend(d for d in ((a, b) if g <= 0.5 else (b, a)) if d is not None)
    return inner, n_open, n_clear


def _end_ray(L: _Local, p: int, q: int, s: int, margin: float) -> float:
    """How far (rad) past the perpendicular at p, away from q, p's sweep of edge p-q on
    side s (as seen at p) goes: to the perpendicular of the next fence edge at p on that
    side (p's open wedge W from q, less pi), plus ``margin``; at least ``margin``, at most
    pi / 2 (along the edge's own line)."""
    bp = L.bearings(p)
    t0 = bp[q]
    wedge = min(((s * (t - t0)) % (2.0 * math.pi) for l, t in bp.items() if l != q),
                default=2.0 * math.pi)
    return min(max(wedge - math.pi, 0.0) + margin, math.pi / 2.0)


def _no_room_direction(L: _Local, room: Room, p: int, q: int, s: int,
                       borrow: bool = False) -> float:
    """The direction (rad, p's frame) a sweep from p on side s of edge p-q first drives:
    of p's failed drives and its wall contact on that side, the one nearest the edge's
    perpendicular (it met the wall before); with none and ``borrow``, q's wall contact
    turned into p's frame (by the two robots' bearings of each other), when it points into
    the side: the normal of the wall q rests on; else the perpendicular."""
    t0 = L.bearings(p)[q]
    perp = wrap(t0 + s * math.pi / 2.0)
    cands = list(room.failed.get(p, ()))
    c = room.contact(p)
    if c is not None:
        cands.append(c)
    on_side = [d for d in cands if 0.0 < s * wrap(d - t0) < math.pi]
    if not on_side and borrow:
        cq = room.contact(q)
        if cq is not None:
            d = wrap(cq + t0 - L.bearings(q)[p] - math.pi)
            if 0.0 < s * wrap(d - t0) < math.pi:
                return d
    return min(on_side, key=lambda d: abs(wrap(d - perp))) if on_side else perp


def _side_sweeps(cx: Complex, L: _Local, P: TopologyParams, room: Room, ev: ProbeEvidence,
                 e: int, sg: int, borrow: bool = False) -> tuple[list[Deployment], int, int]:
    """(sweeps still to drive, n_open, n_clear) of side sg of edge e (wall sweeps,
    coordinator.topology.evidence): closed on evidence (no deployment, n_open 0, n_clear
    0) once its ends' joined intervals cover (-inf, +inf); else a sweep from each end
    whose part is not covered and that has tries left, its far line sweep_overlap / 2
    past where the other end's joined part begins (the middle before it has one). With
    none left, n_open counts the gaps (an inference closes the side) and n_clear the ends
    that found room."""
    ids = cx.ids
    u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
    iu, iv = int(ids[u]), int(ids[v])
    gaps = sweep_gaps(ev.sweeps.get((iu, iv, sg), ()) if ev.sweeps else ())
    if not gaps:
        return [], 0, 0
    half = P.sweep_overlap / 2.0
    # u sweeps (-inf, far_u]: to past the right end of the leftmost gap; v, in its own
    # fractions, to past the left end of the rightmost gap
    right = gaps[0][1]
    left = gaps[-1][0]
    far_u = min(1.0, max(half, (right if right < math.inf else 0.5) + half))
    far_v = min(1.0, max(half, 1.0 - (left if left > -math.inf else 0.5) + half))
    tries = ev.sweep_tries or {}
    out: list[Deployment] = []
    n_clear = 0
    for p, q, end, s, far in ((u, v, 0.0, sg, far_u), (v, u, 1.0, -sg, far_v)):
        key = (iu, iv, sg, end)
        if key in ev.clear or (borrow and key in ev.home):
            # found room from this end: its robot stayed there; or, the side asked to be
            # swept first (borrow), its free sweep came home clear: done, no evidence,
            # and the side goes back to its deployments (keep_evidence) rather than wait
            # for a push to leave a robot wherever that sweep went. Only while asked: a
            # side that became a candidate of its own counts such a sweep as nothing
            n_clear += 1
            continue
        lo, hi = (-math.inf, far_u) if end == 0.0 else (1.0 - far_v, math.inf)
        if not any(a < hi and b > lo for a, b in gaps) or tries.get(key, 0) >= P.sweep_tries:
            continue
        d = _no_room_direction(L, room, p, q, s, borrow)
        out.append(Deployment(int(ids[p]), d, (iu, iv), sg, wrap(d - L.bearings(p)[q]),
                              L.clearance(p, d), "probe", 0.0, P.sweep_depth / P.rv, 0.0,
                              round(far, 3), _end_ray(L, p, q, s, P.sweep_margin)))
    return out, (0 if out else len(gaps)), n_clear


def _gap_fracs(ev: ProbeEvidence, side) -> tuple[float, ...]:
    """The interior probe fractions (``ev.fracs`` strictly between 0 and 1) that lie inside
    a gap the sweeps of ``side`` (u, v, sigma) left (evidence.sweep_gaps). A swept interval
    is wall a robot's body followed, so an opening lies in the gaps; one at least
    door_min_rv wide there holds a stretch s = door_min_rv - 2 r long where a body clears
    both jambs, and the probe lines are at most s apart: one of these fractions crosses it.
    Empty when no fraction lies in a gap (every gap narrower than s, or beyond the edge's
    span, in front of its ends)."""
    gaps = sweep_gaps(ev.sweeps.get(tuple(side), ()) if ev.sweeps else ())
    return tuple(g for g in ev.fracs if 1e-9 < g < 1.0 - 1e-9
                 and any(a < g < b for a, b in gaps))


def _unbounded_gap(ev: ProbeEvidence, side) -> bool:
    """A gap the sweeps of ``side`` (u, v, sigma) left runs to a ray at an end (-inf or
    +inf: in front of u or v, where only the end's own evidence speaks)."""
    gaps = sweep_gaps(ev.sweeps.get(tuple(side), ()) if ev.sweeps else ())
    return any(a == -math.inf or b == math.inf for a, b in gaps)


def _side_key(cx: Complex, e: int, sg: int) -> tuple[int, int, int]:
    """(u, v, sigma) of side sg of edge e, node ids (evidence's SideKey)."""
    return int(cx.ids[int(cx.edges[e, 0])]), int(cx.ids[int(cx.edges[e, 1])]), int(sg)


def plan_probes(cx: Complex, L: _Local, P: TopologyParams, room: Room, ev: ProbeEvidence,
                ends: Marks, marks: Marks, open_sides=None
                ) -> tuple[dict[tuple[int, int], list[Deployment]], Marks]:
    """(probing, marks) for the candidate sides ``ends`` not already marked, in (e,
    sigma) order: a side with probes left is probing (its deployments by via_frac); one
    with none left is marked closed ('probes', 'gap_probes', 'probe_clear',
    'probe_unreachable', 'sweep_blocked', 'sweep_gap') or, with
    ``TopologyParams.clear_infers`` off and some probe clear, probing with no deployment
    (the run ends uncertified). With ``TopologyParams.sweep``
    a side of an edge with a triangle (one open side in ``open_sides``) is swept
    (:func:`_side_sweeps`); a dangling edge's sides are probed, and so is a side whose
    sweeps are over when a robot cut off from the swarm stopped one (``ev.foreign``)."""
    marks = dict(marks)
    probing: dict[tuple[int, int], list[Deployment]] = {}
    for e, sg in sorted(ends):
        if (e, sg) in marks:
            continue
        sweep = P.sweep and open_sides is not None and len(open_sides.get(e, ())) == 1
        key = _side_key(cx, e, sg)
        gap_fracs = None
        # how a side whose sweeps stopped short, with no room found, closes: 'sweep_gap'
        # unless a robot of the swarm stood in the way of one ('sweep_blocked', below)
        gap_why = "sweep_blocked" if P.gap_probes and key in ev.blocked else "sweep_gap"
        if sweep:
            asked = ends[(e, sg)] == "sweep_first"
            # an asked side's end with no wall of its own drives along its partner's wall
            # normal: the side's own normal may cross the strip along that wall obliquely,
            # deeper than the no-room depth (docs/measured.md, "Where the robots go")
            inner, n_open, n_clear = _side_sweeps(cx, L, P, room, ev, e, sg, borrow=asked)
            over = not inner and n_open > 0     # sweeps over, a gap left
            if over and asked and (key in ev.foreign or _unbounded_gap(ev, key)):
                # a side asked to be swept (asked_candidates) has no end's evidence of a
                # wall: the probe rule's lines (which leave the ends to that evidence)
                # prove nothing of it, nor do gap lines when a gap runs past an end. Left
                # unmarked and undriven, it goes back to its deployments (keep_evidence)
                continue
            if over and key in ev.foreign:
                # a robot cut off from the swarm stopped one: it stands in free space the
                # complex does not hold, perhaps in the gap, and no inference closes that.
                # The probe rule drives into the side at every fraction instead: a probe
                # that finds room there stays, seen by that robot, which then links again
                # (closed, the room behind a 0.30 rv door was certified at 54% coverage:
                # bench/unseen.py seed 0 map 8)
                sweep = False
            elif over and n_clear == 0 and P.gap_probes and gap_why == "sweep_gap":
                # no end found room, no robot of the swarm stood in the way, and the gaps
                # are no evidence of a wall: the probe lines that fall in them are driven
                # (a touch at each, tilted as the probe rule asks, closes the side on
                # evidence: 'gap_probes'); a gap no line falls in is narrower than
                # door_min_rv, or in front of an end
                gap_fracs = _gap_fracs(ev, key)
                sweep = not gap_fracs
        if not sweep:
            inner, n_open, n_clear = _side_probes(cx, L, P, room, ev, e, sg, gap_fracs)
        if inner:
            probing[(e, sg)] = sorted(inner, key=lambda d: d.via_frac)
        elif not sweep and ev.found_at(key):
            # a cut-off robot stopped its sweeps, a drive found room beyond it, and no probe
            # since got in (each touched, a jamb or a robot in the door, FOUND_TOUCH_LIMIT
            # times): neither evidence nor an inference closes it. Frontier with no
            # deployment: the run ends uncertified unless a robot reaches the room another
            # way (bench/families.py seed 0 map 1 certified the room behind a 0.30 m door
            # uncovered through 'probes')
            probing[(e, sg)] = []
        elif n_open == 0 and n_clear == 0:
            # every probe touched: closed on evidence (the probes of a swept side's gaps:
            # the sweeps followed the wall elsewhere)
            marks[(e, sg)] = "gap_probes" if gap_fracs else "probes"
        elif sweep and n_clear == 0:
            # sweeps stopped short (lost landmarks, the budget, a robot in the way) from
            # both ends as often as they may, and a gap is left: closed, as an INFERENCE.
            # 'sweep_blocked': a robot of the swarm (linked to a source) stood in the way
            # of one, and the space in front of the side is where it stands (probing such
            # gaps placed robots there: seed 0, small 25 -> 33 robots, pillar_hall 122 ->
            # 141, cave 128 -> 138; docs/measured.md, "A gap the sweeps left is probed").
            # 'sweep_gap': no probe line falls in the gap (or TopologyParams.gap_probes
            # is off)
            marks[(e, sg)] = gap_why
        elif sweep and P.clear_infers:
            marks[(e, sg)] = "probe_clear"    # inferred: an end's sweep found room
        elif n_open == 0 and P.clear_infers:
            marks[(e, sg)] = "probe_clear"    # inferred: some probe found room
        elif n_clear == 0:
            # every probe touched or was unreached from both ends (its approach leg clips a
            # jamb from either side): closed, but as an INFERENCE, reported with the
            # certificate ('probe_unreachable'). Leaving such sides open stopped real runs
            # uncertified at 100% coverage (the 0.8 m door map: "no feasible push")
            marks[(e, sg)] = "probe_unreachable"
        elif P.clear_infers:
            # nothing left to try: some probe found room (its robot stands beyond the side
            # yet forms no triangle with it: something between them blocks the view) and the
            # others' approach legs clip an obstacle on the edge from both ends. Closed as
            # the inference 'probe_unreachable', like either case alone. Left open, 95 of
            # bench/truth.py's 500 maps (seed 0) ended stuck uncertified, every one of them
            # fully covered by the oracle's raster
            marks[(e, sg)] = "probe_unreachable"
        else:
            # clear_infers off: no evidence closes it and nothing is left to try. Frontier
            # with no deployment: the run ends uncertified (honest), never a closure
            probing[(e, sg)] = []
    return probing, marks


def asked_candidates(cx: Complex, open_sides: Sides, ends: Marks, marks: Marks,
                     sweep_first=()) -> Marks:
    """``ends`` plus 'sweep_first' for each side in ``sweep_first`` (u, v, sigma node ids)
    that is open, of an edge with a triangle (so it is swept), and neither a candidate nor
    marked already. The planner asks this of a side whose deployment found no free lattice
    point at a robot resting on a wall (coordinator.planner,
    ``TopologyParams.sweep_fallbacks``): swept first, it closes only on the sweeps'
    evidence (:func:`keep_evidence`), never by an inference it would not have met as a
    plain frontier side."""
    want = {(int(k[0]), int(k[1]), int(k[2])) for k in sweep_first}
    if not want:
        return ends
    ends = dict(ends)
    for e, recs in open_sides.items():
        if len(recs) != 1:
            continue
        sg = recs[0][0]
        if (e, sg) not in ends and (e, sg) not in marks and _side_key(cx, e, sg) in want:
            ends[(e, sg)] = "sweep_first"
    return ends


def keep_evidence(ends: Marks, marks: Marks, probing: dict) -> tuple[Marks, dict]:
    """``marks`` and ``probing`` with each side ``ends`` holds as 'sweep_first'
    (:func:`asked_candidates`) left a plain frontier side unless its sweeps closed it on
    evidence (``fence_types.EVIDENCE``) or it still has sweeps or probes to drive: an
    inference ('sweep_blocked', 'sweep_gap', 'probe_clear', ...) or nothing left to try
    sends it back to its deployments."""
    asked = [side for side, why in ends.items() if why == "sweep_first"]
    if not asked:
        return marks, probing
    marks, probing = dict(marks), dict(probing)
    for side in asked:
        if side in marks and marks[side] not in EVIDENCE:
            del marks[side]
        if side in probing and not probing[side]:
            del probing[side]
    return marks, probing


def forced_marks(cx: Complex, forced_obstacle, marks: Marks) -> Marks:
    """``marks`` with both sides of each ``forced_obstacle`` edge (node-id pairs; pairs
    not in the complex are ignored) set to 'forced'."""
    marks = dict(marks)
    for pair in forced_obstacle:
        a, b = (int(x) for x in pair)
        if a in cx and b in cx:
            e2 = int(cx.edge_index(cx.index_of(a), cx.index_of(b)))
            if e2 >= 0:
                for sg in (1, -1):
                    marks[(e2, sg)] = "forced"
    return marks

"""Fence detection: frontier edges K and obstacle edges O (spec section 3).

Everything is computed from the complex, the body-frame bearings and the touch flags
stored in it: no positions.

Exception set E (edges with all their triangles on one side that are nevertheless
covered on the other side by overlapping triangles): the tightened rule of spec 3.2. An
edge {i, j} is in E when, for a common neighbour k, a monotone chain i -> m1 -> ... -> j
of k's neighbours inside k's wedge from i to j, consecutive ones adjacent, exists with
*every* m_t beyond the segment ij (the spec asks for at least one): a chain that dips
inside triangle ijk leaves part of ij on the boundary, and marking such edges E broke the
fence cycle on random swarms.
On complexes with crossing edges the one-sided edges can still leave odd-degree
vertices; ``Fence.z`` is then repaired into a cycle (see ``Fence.z_repair``).

Sides. For an edge with node ids u < v, side sigma = +1 is the side counter-clockwise
from v as seen by u (sign of theta^u_{v k} for an apex k on that side); seen from v the
same physical side has sign -sigma. All sides in the results use this canonical
orientation.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ground.angles import circular_mean, wrap, wrap_array
from .complex import Complex
from .evidence import TILT_MATCH, needs_tilt, probe_depth_rv, probe_fractions
from .fence_local import (_DEEP, _REFLEX, _Local, _canon, _corner, _is_exception,  # noqa: F401
                          _reflex, _sgn, _touch_ok)
from .fence_types import Deployment, Fence, FenceEdge, FenceSide
from .params import TopologyParams

__all__ = ["Deployment", "FenceSide", "FenceEdge", "Fence", "detect_fence"]

_I64 = np.int64
_PI3 = math.pi / 3.0
# A robot resting against a wall has no room within 90 deg of its contact. A failed test
# drive says only that its own direction is blocked (the touch may be a door jamb to the
# side): it blocks deployments within 30 deg of the direction driven. 90 deg cones around
# the felt contact closed 0.9 m doors (corridor_doors certified at 77-84%).
_FAILED_CONE = math.pi / 6.0
_CONTACT_CONE = math.pi / 2.0
# Both-touch rule (spec 3.4 i): each contact must point clearly into the open side, at
# least _TOUCH_MARGIN off the edge's line. Two robots across the mouth of a passage touch
# its two sides: their contacts point along the edge, away from each other, and the spec's
# sign test then closed the passage on bearing noise. (With the margin the two contacts
# are also within 120 deg of each other: one wall, or two walls meeting at a corner.)
_TOUCH_MARGIN = math.pi / 6.0
# Single-file ends offer every direction of their open wedge 60 deg apart that keeps this
# far from every neighbour (a little under 60 deg, for bearing noise).
_SINGLE_CLEAR = math.radians(50.0)
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



def _repair_cycle(cx: Complex, z: np.ndarray, band: np.ndarray) -> np.ndarray:
    """Edge ids to toggle so that ``z`` (edge ids) gets even degree at every vertex.

    Greedy T-join: odd vertices are paired through a multi-source Dijkstra (Voronoi
    cells); edges inside the band cost 1, others 10.
    """
    n, E = cx.n, cx.n_edges
    zm = np.zeros(E, dtype=bool)
    zm[z] = True
    toggled = np.zeros(E, dtype=bool)
    u, v = cx.edges[:, 0], cx.edges[:, 1]
    w = np.where(band[u] & band[v], 1.0, 10.0)
    g = csr_matrix((np.concatenate([w, w]), (np.concatenate([u, v]), np.concatenate([v, u]))), shape=(n, n))
    for _ in range(8):
        cur = zm ^ toggled
        odd = np.nonzero(np.bincount(cx.edges[cur].ravel(), minlength=n) & 1)[0]
        if odd.size < 2:
            break
        dist, pred, src = dijkstra(g, directed=True, indices=odd, min_only=True, return_predecessors=True)
        ok = np.isfinite(dist[u]) & np.isfinite(dist[v]) & (src[u] != src[v]) & (src[u] >= 0) & (src[v] >= 0)
        cand = np.nonzero(ok)[0]
        if cand.size == 0:
            break
        cost = dist[u[cand]] + w[cand] + dist[v[cand]]
        matched: set[int] = set()
        progress = False
        for e in cand[np.argsort(cost, kind="stable")].tolist():
            a, b = int(src[u[e]]), int(src[v[e]])
            if a in matched or b in matched:
                continue
            matched.update((a, b))
            progress = True
            toggled[e] ^= True
            for x in (int(u[e]), int(v[e])):
                while pred[x] >= 0:
                    y = int(pred[x])
                    toggled[int(cx.edge_index(x, y))] ^= True
                    x = y
        if not progress:
            break
    return np.nonzero(toggled)[0]


def _tilts_todo(needed, done) -> list[float]:
    """The tilts (rad) of ``needed``, merged within evidence.TILT_MATCH, that no touched
    tilt in ``done`` stands for."""
    todo: list[float] = []
    for t in needed:
        if any(abs(wrap(t - d)) <= TILT_MATCH for d in (*done, *todo)):
            continue
        todo.append(float(t))
    return todo


def detect_fence(
    cx: Complex,
    params: TopologyParams | None = None,
    *,
    test_drive_failures: Mapping[int, float] | None = None,
    forced_obstacle=(),
    default_bearing: float | Mapping[int, float] = 0.0,
    probe_failures=(),
    probe_fracs=None,
    probe_unreachable=(),
    probe_clear=(),
    probe_offsets=None,
    tilt_failures=(),
) -> Fence:
    """Frontier and obstacle edges with their deployment bearings (spec 3.1-3.4).

    How a side closes (spec 3.4 with the amendment of 2026-11, "evidence before a side
    closes"). The ends' rules only make a side a CANDIDATE:
      * test-drive rule: both ends have no room on it -- each end's deployment into it lies
        within 30 deg of a failed drive of that robot, or within 90 deg of the wall contact
        it rests against; an end whose open wedge on that side is reflex (> 210 deg) also
        needs its second probe, 120 deg off the edge, to have failed;
      * both-touch rule (spec 3.4 i): both ends rest on a wall (no neighbour within tau of
        the contact) pointing into the open side, each at least 30 deg off the edge's line.
    A candidate side becomes O (reason 'probes') only once every PROBE of it touched: at
      the interior fractions ``probe_fracs`` (coordinator.topology.evidence, from [coordinator]
      door_min_rv and the robot's radius: 0.25, 0.5, 0.75 by default) of the edge, a drive
      that approaches that point along the edge, then goes perpendicular into the open
      side; done when its key (u, v, sigma, fraction from u) is in ``probe_failures``. The
      fractions 0 and 1 are the ends, whose own drives or contacts made the side a
      candidate: no perpendicular drive is asked of them (the interior probes are at most
      L/n <= s apart and L/n - r < s from the ends, so they alone pass every opening
      >= door_min_rv within the edge's span).
      Until then the side stays frontier (reason 'probing') and offers only its missing
      probes as deployments (kind 'probe', from either end for interior ones). A probe in
      ``probe_clear`` found room (its robot stayed there) and is never offered again; an
      interior probe given up from one end in ``probe_unreachable`` (its approach leg kept
      failing) is offered from the other end only. Neither is evidence of a wall: a side
      whose probes are all touched or unreached from both ends closes as the inference
      'probe_unreachable'; with some clear and none left, as 'probe_clear' (all others
      touched) or 'probe_unreachable' (some unreached) -- with
      ``TopologyParams.clear_infers`` off those stay frontier with no deployment, and the
      run ends uncertified.
    Inferred closures (no probe): the convex-corner / occlusion rule (pi/3 - 2 beta, reason
      'convex_corner': p's nearest neighbour k on the open side is under the threshold from
      q, and q does not see k; with ``TopologyParams.corner_wait``, when only one end sees
      such a corner and the other end's open wedge on that side is reflex, that end deploys
      there first and the side closes once it has no room) and ``forced_obstacle``
      ('forced'); ``Fence.inferred`` lists them.
    Guarantee: with edges <= rv, for a side closed on evidence, every opening at least
    door_min_rv wide *along the edge* whose span lies within the edge's was crossed by a
    perpendicular probe line with the robot's body clear of both jambs, and that probe
    touched within the deployer's wall_keep_rv (0.45 rv) of the edge: no such opening
    exists that close. In a wall the side's robots felt (a probe's touch, an end's
    contact), at whatever angle to the edge, every opening at least
    ``evidence.tilted_door_rv`` wide (0.52 rv at the defaults) whose span along the probe
    lines lies within the edge's was crossed the same way by a probe line within
    tau + TopologyParams.tilt_min of the wall's normal. Limits: narrower openings; openings
    straddling an edge's end with less than that on each of the two edges; doors in a wall
    no robot of the side felt; a dangling edge's interior probes approach open loop (its
    length assumed d0).

    test_drive_failures: node id -> direction, or list of directions (rad, that robot's
      body frame), of drives that touched an obstacle (spec 3.4(iv)), end probes included;
      its deployments within 30 deg of a failed direction are dropped (probes excepted).
    probe_failures: keys (u, v, sigma, fraction from u) of interior probes that touched.
    probe_fracs: fractions where probes go (default ``evidence.probe_fractions()``).
    probe_unreachable: (u, v, sigma, fraction, end): interior probes given up from that
      end (their approach kept failing).
    probe_clear: keys of interior probes that found room (done, not offered again).
    probe_offsets: key -> touch sector centre minus the direction driven (rad) of touched
      perpendicular probes. Missing: the sector is unknown (no tilt from it).
    tilt_failures: key -> tilts (rad, from the perpendicular) of its TILTED probes that
      touched. A touched perpendicular probe is done only once a tilted probe from the same
      point touched (or one found room: ``probe_clear``) along each wall normal known at the
      side (those ``evidence.needs_tilt`` keeps): its own touch sector's centre, and the
      wall contact of either end that points into the open side. So every wall the side's
      robots have felt is probed along (within tau of) its normal, where an oblique door
      is widest (coordinator.topology.evidence).
    forced_obstacle: edges (pairs of node ids) whose open sides are obstacle sides,
      e.g. edges reclassified after a failed test drive in an earlier cycle.
    default_bearing: first deployment direction (rad, body frame) of a robot with no
      neighbour at all (the others follow 60 deg apart: six in all); a float, or node id ->
      direction (missing ids use 0).
    Single-file robots (in no triangle, neighbours on one side) offer every direction of
    their open wedge 60 deg apart, once their dangling edges' deployments are gone.
    """
    P = params or TopologyParams()
    E = cx.n_edges
    te, B = cx.tri_edges, cx.bearings
    # ---- one-sided test, vectorised over all triangle-edge incidences
    pos = np.zeros(E, dtype=bool)
    neg = np.zeros(E, dtype=bool)
    if cx.n_triangles:
        ab, ac, bc = te[:, 0], te[:, 1], te[:, 2]
        s_ab = np.sign(wrap_array(B[ac, 0] - B[ab, 0]))  # apex c of edge ab, at a
        s_ac = np.sign(wrap_array(B[ab, 0] - B[ac, 0]))  # apex b of edge ac, at a
        s_bc = np.sign(wrap_array(B[ab, 1] - B[bc, 0]))  # apex a of edge bc, at b
        e_all = np.concatenate([ab, ac, bc])
        s_all = np.concatenate([s_ab, s_ac, s_bc])
        pos[e_all[s_all > 0]] = True
        neg[e_all[s_all < 0]] = True
    cand = np.nonzero(~(pos & neg))[0]

    L = _Local(cx)
    eptr, etri = cx.edge_triangles
    tri = cx.triangles
    ids = cx.ids
    thr = P.corner_threshold
    n_tri_at = np.diff(cx.vertex_triangles[0])

    exceptions: list[int] = []
    # per candidate: list of (sigma, offset_u, offset_v) and corner marks
    open_sides: dict[int, list[list]] = {}
    marks: dict[tuple[int, int], str] = {}
    # convex corners seen from one end whose far end has a reflex open wedge on that side:
    # (e, sigma) -> (far end, near end, far end's offset); closed once the far end has no
    # room, a frontier side deployed from the far end only until then
    corner_wait: dict[tuple[int, int], tuple[int, int, float | None]] = {}
    for e in cand.tolist():
        u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
        sides = ([1] if not pos[e] else []) + ([-1] if not neg[e] else [])
        if len(sides) == 1:
            tris = etri[eptr[e]:eptr[e + 1]]
            apexes = (tri[tris].sum(1) - u - v).tolist()
            if apexes and _is_exception(L, u, v, sides[0], apexes):
                exceptions.append(e)
                continue
        recs = []
        for sg in sides:
            rec = [sg, None, None]
            ku, gu = L.nearest_on_side(u, v, sg, thin=thr)
            kv, gv = L.nearest_on_side(v, u, -sg, thin=thr)
            cu = _corner(L, u, v, ku, gu, thr)
            cv = _corner(L, v, u, kv, gv, thr)
            if not cu:
                rec[1] = sg * min(_PI3, (gu if gu is not None else math.pi) / 2.0)
            if not cv:
                rec[2] = -sg * min(_PI3, (gv if gv is not None else math.pi) / 2.0)
            for near, far, k, s_near, off_far in ((u, v, ku, sg, rec[2]), (v, u, kv, -sg, rec[1])):
                if not (cu if near == u else cv):
                    continue
                # the occlusion argument covers the wedge far-near-k only; a far end whose
                # own open wedge on this side is reflex sees free space beyond it (a robot
                # in a doorway): the side closes only once that end has no room either
                if (cu and cv) or not P.corner_wait or not _reflex(L, far, near, -s_near):
                    marks[(e, sg)] = "convex_corner"
                else:
                    corner_wait[(e, sg)] = (far, near, off_far)
                e2 = int(cx.edge_index(near, k))
                if not (P.corner_wait and _reflex(L, k, near, s_near)):
                    marks.setdefault((e2, _canon(near, k, -s_near)), "convex_corner")
            recs.append(rec)
        open_sides[e] = recs

    # ---- both-touch rule: ends evidence only (see "evidence" below)
    ends: dict[tuple[int, int], str] = {}
    tau = P.tau
    touch_cache: dict[int, float | None] = {}

    def contact(p: int):
        if p not in touch_cache:
            touch_cache[p] = _touch_ok(cx, L, p, tau)
        return touch_cache[p]

    for e, recs in open_sides.items():
        u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
        if not (cx.touch[u] and cx.touch[v]):
            continue
        ou, ov = contact(u), contact(v)
        if ou is None or ov is None:
            continue
        au, av = wrap(ou - L.bearings(u)[v]), wrap(ov - L.bearings(v)[u])
        if not (_TOUCH_MARGIN <= abs(au) <= math.pi - _TOUCH_MARGIN
                and _TOUCH_MARGIN <= abs(av) <= math.pi - _TOUCH_MARGIN):
            continue
        for rec in recs:
            sg = rec[0]
            if _sgn(au) == sg and _sgn(av) == -sg:
                ends[(e, sg)] = "both_touch"

    # ---- test-drive failures (spec 3.4(iv)): a drive along phi that touched blocks the
    # deployments within _FAILED_CONE of phi; the fence sides deploying into it become O
    # once both ends have no room
    failed: dict[int, list[float]] = {}
    if test_drive_failures:
        for nid, phis in test_drive_failures.items():
            if int(nid) not in cx:
                continue
            p = cx.index_of(int(nid))
            failed[p] = [float(x) for x in (phis if isinstance(phis, (list, tuple)) else [phis])]
    def _blocked(p: int, d: float) -> bool:
        return any(abs(wrap(d - phi)) < _FAILED_CONE for phi in failed.get(p, ()))

    def _deep(p: int, q: int, off):
        """The second probe of p on the side of edge p-q deploying at ``off``, or None. A
        robot in no triangle (single file) has the straight-ahead fallback instead."""
        if off is None or abs(off) < _PI3 - 1e-9 or n_tri_at[p] == 0:
            return None
        sg = 1 if off > 0 else -1
        return wrap(L.bearings(p)[q] + sg * _DEEP) if _reflex(L, p, q, sg) else None

    def _side_closed(p: int, q: int, off) -> bool:
        """p has no room on this side: its 60-deg direction, and a reflex side's deep probe."""
        if off is None:
            return True
        if not _no_room(p, wrap(L.bearings(p)[q] + off)):
            return False
        deep = _deep(p, q, off)
        return deep is None or _no_room(p, deep)

    def _no_room(p: int, d: float) -> bool:
        # p cannot deploy along d: a failed test drive's cone, or p rests against a wall
        # facing that way (its sticky contact)
        if _blocked(p, d):
            return True
        c = contact(p)
        return c is not None and abs(wrap(d - c)) < _CONTACT_CONE

    if failed:
        for e, recs in open_sides.items():
            u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
            if u not in failed and v not in failed:
                continue
            for sg, off_u, off_v in recs:
                # both ends must have no room: one touch (a door jamb, a pillar) says
                # nothing about the other end's deployment, which goes on (a single end's
                # failure closing the side left whole rooms behind doors uncovered)
                if _side_closed(u, v, off_u) and _side_closed(v, u, off_v):
                    ends.setdefault((e, sg), "test_drive")

    for (e, sg), (far, near, off) in corner_wait.items():
        if (e, sg) not in marks and _side_closed(far, near, off):
            marks[(e, sg)] = "convex_corner"

    # ---- evidence (spec 3.4 amendment 2026-11): ends that have no room are not enough. A
    # side the ends would close becomes O only once every probe of it touched: the end
    # probes (perpendicular drives from u and from v: a failed drive or a counted wall
    # contact within _FAILED_CONE of the perpendicular) and the interior probes (by key).
    fracs = tuple(probe_fracs) if probe_fracs is not None else probe_fractions()

    def _key(k) -> tuple[int, int, int, float]:
        return (int(k[0]), int(k[1]), int(k[2]), round(float(k[3]), 3))

    pfail = {_key(k) for k in probe_failures}
    poff = {_key(k): float(o) for k, o in (probe_offsets or {}).items()}
    tfail = {_key(k): tuple(float(x) for x in t) for k, t in (tilt_failures or {}).items()}
    pclear = {_key(k) for k in probe_clear}
    # unreached: (key, end) given up from that end
    punreach = {(_key(k), int(k[4])) for k in probe_unreachable}

    def _gave_up(key, end: int) -> bool:
        return (key, end) in punreach

    d0_rv, dtd_rv = P.d0 / P.rv, P.d_td / P.rv

    if P.corner_probes:
        # the convex-corner rule (spec 3.3 ii) assumes an obstacle corner sticking out of a
        # wall; a free-standing box breaks it (clutter map 11 of bench/truth.py certified at
        # 21.8 % coverage): its marks only make a side a candidate, probed like the others
        for (e, sg), why in list(marks.items()):
            if why == "convex_corner":
                del marks[(e, sg)]
                if e in open_sides and any(r[0] == sg for r in open_sides[e]):
                    ends.setdefault((e, sg), "convex_corner")

    probing: dict[tuple[int, int], list[Deployment]] = {}
    for (e, sg), why in sorted(ends.items()):
        if (e, sg) in marks:
            continue
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
            c = contact(p)
            if c is not None:
                t = wrap(c - perp)
                if needs_tilt(t, P.tilt_min) and abs(t) < math.pi / 2.0 - tau:
                    end_tilts.append(t)
        for g in fracs:
            if g <= 1e-9 or g >= 1.0 - 1e-9:
                # the ends: their own failed drives / contacts made the side a candidate. The
                # interior fractions alone pass every opening >= door_min_rv within the span
                # (gaps L/n <= s, and the end gaps L/n - r < s), so a perpendicular drive at
                # an end is not asked for (driving them placed 76 robots in covered corners
                # of the small map, seed 0)
                continue
            key = (iu, iv, sg, round(g, 3))
            tilt = 0.0
            if key in pfail:
                # touched: driven again from the same point along each known wall normal
                # oblique to the probe line (its own touch sector's centre, the ends'
                # contacts) until each of those touched too
                off = poff.get(key)
                todo = _tilts_todo(([off] if needs_tilt(off, P.tilt_min) else []) + end_tilts,
                                   tfail.get(key, ()))
                if not todo:
                    continue                  # touched along every one: evidence of a wall
                tilt = todo[0]
            if key in pclear:
                n_clear += 1                  # found room (its robot stays): done, not evidence
                continue
            n_open += 1
            # the tilted drive's component along the edge, toward v (sigma +1: open side CCW
            # of u -> v, so a CCW tilt leans back toward u)
            depth = probe_depth_rv(g, d0_rv, dtd_rv, lean=-sg * math.sin(tilt))
            bu, bv = wrap(pu + tilt), wrap(pv + tilt)
            # either end can drive it, the nearer one first; an end whose approach leg kept
            # failing (it clips a jamb) has given up: the other end tries it
            a = None if _gave_up(key, iu) else Deployment(
                iu, bu, (iu, iv), sg, wrap(sg * math.pi / 2.0 + tilt), L.clearance(u, bu), "probe",
                round(g, 3), depth, tilt)
            b = None if _gave_up(key, iv) else Deployment(
                iv, bv, (iu, iv), sg, wrap(-sg * math.pi / 2.0 + tilt), L.clearance(v, bv),
                "probe", round(1.0 - g, 3), depth, tilt)
            inner.extend(d for d in ((a, b) if g <= 0.5 else (b, a)) if d is not None)
        if inner:
            probing[(e, sg)] = sorted(inner, key=lambda d: d.via_frac)
        elif n_open == 0 and n_clear == 0:
            marks[(e, sg)] = "probes"         # every probe touched: closed on evidence
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

    for pair in forced_obstacle:
        a, b = (int(x) for x in pair)
        if a in cx and b in cx:
            e2 = int(cx.edge_index(cx.index_of(a), cx.index_of(b)))
            if e2 >= 0:
                for sg in (1, -1):
                    marks[(e2, sg)] = "forced"

    # ---- assemble
    fence_edges: list[FenceEdge] = []
    K: list[int] = []
    O: list[int] = []
    z: list[int] = []
    deps: dict[int, list[Deployment]] = {}
    single = (n_tri_at == 0) & (cx.degree > 0)
    for e, recs in open_sides.items():
        u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
        Bu, Bv = L.bearings(u), L.bearings(v)
        sides = []
        for sg, off_u, off_v in recs:
            why = marks.get((e, sg))
            if why is not None:
                sides.append(FenceSide(sg, "obstacle", why))
                continue
            if (e, sg) in probing:
                sides.append(FenceSide(sg, "frontier", "probing"))
                for d in probing[(e, sg)]:
                    deps.setdefault(cx.index_of(d.vertex), []).append(d)
                continue
            # an end that sees a convex corner on this side (corner_wait) does not deploy
            du = None if off_u is None else wrap(Bu[v] + off_u)
            dv = None if off_v is None else wrap(Bv[u] + off_v)
            sides.append(FenceSide(sg, "frontier", "open", du, dv, off_u, off_v))
            edge_ids = (int(ids[u]), int(ids[v]))
            for p, q, d, off in ((u, v, du, off_u), (v, u, dv, off_v)):
                if off is None:
                    continue
                deps.setdefault(p, []).append(
                    Deployment(int(ids[p]), d, edge_ids, sg, off, L.clearance(p, d), "edge"))
                deep = _deep(p, q, off) if _blocked(p, d) else None
                if deep is not None:
                    deps[p].append(Deployment(int(ids[p]), deep, edge_ids, sg,
                                              wrap(deep - L.bearings(p)[q]),
                                              L.clearance(p, deep), "edge"))
        fe = FenceEdge(int(ids[u]), int(ids[v]), e, tuple(sides))
        fence_edges.append(fe)
        if fe.is_frontier:
            K.append(e)
        if fe.is_obstacle:
            O.append(e)
        if len(recs) == 1:
            z.append(e)

    # single-file robots (no triangle, spec 3.3): away from the circular mean of the
    # neighbours -- the end of a chain; a robot between two opposite neighbours (resultant
    # < 0.5) is inside the chain and has no single-file direction
    K_arr = np.array(sorted(K), dtype=_I64)
    # Every direction of the open wedge is offered (spec 3.4 amendment: a robot with one
    # or no neighbour probes every free direction before it gives up): away from the
    # neighbours, then 60, 120 deg either side, each at least _SINGLE_CLEAR from every
    # neighbour. A failed drive blocks 30 deg either side, so each touch removes one.
    for p in np.nonzero(single)[0].tolist():
        mean, res = circular_mean(L.bearings(p).values())
        if res < 0.5:
            continue
        for k in (0, 1, -1, 2, -2):
            d = wrap(mean + math.pi + k * _PI3)
            c = L.clearance(p, d)
            if k == 0 or c >= _SINGLE_CLEAR:
                deps.setdefault(p, []).append(
                    Deployment(int(ids[p]), d, None, 0, 0.0, c, "single_file"))
    # a robot with no neighbour: six directions 60 deg apart from its default bearing
    for p in np.nonzero(cx.degree == 0)[0].tolist():
        if isinstance(default_bearing, Mapping):
            d0_ = wrap(float(default_bearing.get(int(ids[p]), 0.0)))
        else:
            d0_ = wrap(float(default_bearing))
        for k in range(6):
            deps.setdefault(p, []).append(Deployment(int(ids[p]), wrap(d0_ + k * _PI3), None, 0,
                                                     0.0, math.pi, "isolated"))
    # test-drive failures also drop deployments pointing into the failed gap
    for p in failed:
        if p in deps:
            keep = [dp for dp in deps[p] if dp.kind == "probe" or not _blocked(p, dp.bearing)]
            if keep:
                deps[p] = keep
            else:
                del deps[p]

    # a robot with a frontier edge deploys off the edge (60 deg, triangles); the single-file
    # direction is its fallback once those are gone (a corridor too narrow for triangles
    # makes the edge deployments fail their test drives)
    for p, lst in deps.items():
        if any(d.kind == "edge" for d in lst):
            deps[p] = [d for d in lst if d.kind != "single_file"]
    deployments = {
        int(ids[p]): tuple(sorted(lst, key=lambda d: (-d.clearance, d.edge or (0, 0), d.sigma)))
        for p, lst in sorted(deps.items())
    }
    fence_edges.sort(key=lambda f: f.index)
    z_raw = np.array(sorted(z), dtype=_I64)
    band = np.zeros(cx.n, dtype=bool)
    if open_sides or exceptions:
        band[cx.edges[np.array(list(open_sides) + exceptions, dtype=_I64)].ravel()] = True
    repair = _repair_cycle(cx, z_raw, band) if z_raw.size else np.zeros(0, _I64)
    zmask = np.zeros(E, dtype=bool)
    zmask[z_raw] = True
    zmask[repair] ^= True
    O_arr = np.array(sorted(O), dtype=_I64)
    fv_K = frozenset(ids[cx.edges[K_arr]].ravel().tolist()) if K_arr.size else frozenset()
    fv_O = frozenset(ids[cx.edges[O_arr]].ravel().tolist()) if O_arr.size else frozenset()
    frontier_vertices = fv_K | frozenset(deployments)
    inferred = tuple((f.index, sd.reason) for f in fence_edges for sd in f.sides if sd.inferred)
    return Fence(
        inferred=inferred,
        edges=tuple(fence_edges),
        frontier=K_arr,
        obstacle=O_arr,
        exceptions=np.array(sorted(exceptions), dtype=_I64),
        z=np.nonzero(zmask)[0],
        z_raw=z_raw,
        z_repair=repair,
        deployments=deployments,
        frontier_vertices=frontier_vertices,
        obstacle_vertices=fv_O,
        fence_vertices=fv_K | fv_O,
        by_index={f.index: f for f in fence_edges},
    )

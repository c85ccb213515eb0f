"""The open sides of the fence edges and what the ends' own drives and contacts say
about them: the first stages of :func:`coordinator.topology.fence.detect_fence`.

In order:

1. :func:`one_sided`: which sides of each edge have a triangle (vectorised over every
   triangle-edge incidence);
2. :func:`find_open_sides`: the candidate edges (not two-sided) minus the exception set
   E (spec 3.2), each open side with its ends' 60-deg deployment offsets, and the
   convex-corner marks (spec 3.3 ii);
3. the ends' rules that make a side a candidate for closing (spec 3.4): the both-touch
   rule (:func:`both_touch`) and the test-drive rule (:func:`test_drive_rule`), both
   read through :class:`Room` (a robot's failed drives and the wall it rests against);
   :func:`corner_wait_marks` closes the sides a corner waits on once the far end has no
   room.

Units and shapes: bearings, offsets and cones in rad (body frame of the robot named);
pos / neg bool (E,) over ``Complex.edges``; e an edge id; u < v, p, q, k local vertex
indices; sides sigma +1/-1 canonical (fence.py's docstring). A side's record is the list
[sigma, offset_u, offset_v] (offsets None at an end that sees a convex corner there);
marks and ends map (e, sigma) to a reason string.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from swarmcover.ground.angles import wrap, wrap_array
from .complex import Complex
from .fence_local import _DEEP, _Local, _canon, _corner, _is_exception, _reflex, _sgn, _touch_ok
from .params import TopologyParams

__all__: list[str] = []

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

Sides = dict[int, list[list]]
Marks = dict[tuple[int, int], str]


def one_sided(cx: Complex) -> tuple[np.ndarray, np.ndarray]:
    """(pos, neg), bool (E,): the edges with a triangle on side +1 / -1 (canonical), by
    the sign of the angle at an end from the other end to the triangle's apex."""
    E = cx.n_edges
    te, B = cx.tri_edges, cx.bearings
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
    return pos, neg


def find_open_sides(cx: Complex, L: _Local, P: TopologyParams, pos: np.ndarray, neg: np.ndarray
                    ) -> tuple[Sides, list[int], Marks, dict]:
    """(open sides, exceptions, marks, corner_wait) of the edges not two-sided.

    open sides: edge id -> its side records, in edge id order; an edge with no triangle
    has both sides. exceptions: edge ids of E (one-sided, covered on the open side).
    marks: (e, sigma) -> 'convex_corner' for the sides the occlusion rule closes (at an
    end's corner, and the side of the near end's edge to its nearest neighbour k).
    corner_wait: (e, sigma) -> (far end, near end, far end's offset): convex corners seen
    from one end whose far end has a reflex open wedge on that side
    (``TopologyParams.corner_wait``); closed once the far end has no room, a frontier side
    deployed from the far end only until then.
    """
    cand = np.nonzero(~(pos & neg))[0]
    eptr, etri = cx.edge_triangles
    tri = cx.triangles
    thr = P.corner_threshold

    exceptions: list[int] = []
    # per candidate: list of (sigma, offset_u, offset_v) and corner marks
    open_sides: Sides = {}
    marks: Marks = {}
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
    return open_sides, exceptions, marks, corner_wait


class Room:
    """Where a robot has no room to deploy, by its own evidence: its failed test drives
    (spec 3.4(iv); each blocks the directions within _FAILED_CONE of the one driven) and
    the wall it rests against (a counted contact, :func:`_touch_ok` with tau, blocks
    _CONTACT_CONE around it).

    test_drive_failures: node id -> direction, or list of directions (rad, that robot's
    body frame); ids not in the complex are ignored. ``failed``: local index -> directions.
    """

    def __init__(self, cx: Complex, L: _Local, tau: float,
                 test_drive_failures: Mapping[int, float] | None):
        self.cx, self.L, self.tau = cx, L, tau
        self.n_tri_at = np.diff(cx.vertex_triangles[0])
        self._touch: dict[int, float | None] = {}
        failed: dict[int, list[float]] = {}
        if test_drive_failures:
            for nid, phis in test_drive_failures.items():
                if int(nid) not in cx:
                    continue
                p = cx.index_of(int(nid))
                failed[p] = [float(x) for x in (phis if isinstance(phis, (list, tuple)) else [phis])]
        self.failed = failed

    def contact(self, p: int) -> float | None:
        """p's counted wall contact bearing (rad), or None."""
        if p not in self._touch:
            self._touch[p] = _touch_ok(self.cx, self.L, p, self.tau)
        return self._touch[p]

    def blocked(self, p: int, d: float, cone: float = _FAILED_CONE) -> bool:
        """A failed test drive of p lies within ``cone`` (rad; _FAILED_CONE) of direction d."""
        return any(abs(wrap(d - phi)) < cone for phi in self.failed.get(p, ()))

    def deep(self, p: int, q: int, off):
        """The second probe of p on the side of edge p-q deploying at ``off``, or None. A
        robot in no triangle (single file) has the straight-ahead fallback instead."""
        if off is None or abs(off) < _PI3 - 1e-9 or self.n_tri_at[p] == 0:
            return None
        sg = 1 if off > 0 else -1
        return wrap(self.L.bearings(p)[q] + sg * _DEEP) if _reflex(self.L, p, q, sg) else None

    def side_closed(self, p: int, q: int, off) -> bool:
        """p has no room on this side: its 60-deg direction, and a reflex side's deep probe."""
        if off is None:
            return True
        if not self.no_room(p, wrap(self.L.bearings(p)[q] + off)):
            return False
        deep = self.deep(p, q, off)
        return deep is None or self.no_room(p, deep)

    def no_room(self, p: int, d: float) -> bool:
        # p cannot deploy along d: a failed test drive's cone, or p rests against a wall
        # facing that way (its sticky contact)
        if self.blocked(p, d):
            return True
        c = self.contact(p)
        return c is not None and abs(wrap(d - c)) < _CONTACT_CONE


def both_touch(cx: Complex, L: _Local, open_sides: Sides, room: Room) -> Marks:
    """Both-touch rule (spec 3.4 i), ends' evidence only: (e, sigma) -> 'both_touch' for
    the sides both of whose ends rest on a wall pointing into that side, each contact at
    least _TOUCH_MARGIN off the edge's line."""
    ends: Marks = {}
    for e, recs in open_sides.items():
        u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
        if not (cx.touch[u] and cx.touch[v]):
            continue
        ou, ov = room.contact(u), room.contact(v)
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
    return ends


def test_drive_rule(cx: Complex, open_sides: Sides, room: Room, ends: Marks) -> Marks:
    """``ends`` plus (e, sigma) -> 'test_drive' (where not already there) for the sides
    whose ends both have no room (:meth:`Room.side_closed`), one of them after a failed
    test drive (spec 3.4(iv))."""
    ends = dict(ends)
    failed = room.failed
    if failed:
        for e, recs in open_sides.items():
            u, v = int(cx.edges[e, 0]), int(cx.edges[e, 1])
            if u not in failed and v not in failed:
                continue
            for sg, off_u, off_v in recs:
                # both ends must have no room: one touch (a door jamb, a pillar) says
                # nothing about the other end's deployment, which goes on (a single end's
                # failure closing the side left whole rooms behind doors uncovered)
                if room.side_closed(u, v, off_u) and room.side_closed(v, u, off_v):
                    ends.setdefault((e, sg), "test_drive")
    return ends


def corner_wait_marks(corner_wait: dict, marks: Marks, room: Room) -> Marks:
    """``marks`` plus 'convex_corner' for each side a corner waits on (see
    :func:`find_open_sides`) whose far end now has no room."""
    marks = dict(marks)
    for (e, sg), (far, near, off) in corner_wait.items():
        if (e, sg) not in marks and room.side_closed(far, near, off):
            marks[(e, sg)] = "convex_corner"
    return marks

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

Modules (one per stage, pure functions of the complex): ``fence_types`` (Deployment,
FenceSide, FenceEdge, Fence), ``fence_local`` (per-vertex bearings and the local tests:
exception, corner, reflex, touch), ``fence_sides`` (one-sidedness, open sides, the ends'
rules), ``fence_probes`` (the evidence before a side closes), ``fence_deploy`` (the sides
resolved and the deployments); here :func:`detect_fence` runs them in order and
assembles z_raw, z_repair and z.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .complex import Complex
from .fence_deploy import resolve_sides, robot_deployments
from .fence_local import _Local
from .fence_probes import (asked_candidates, corner_candidates, forced_marks, keep_evidence,
                           plan_probes, probe_evidence)
from .fence_sides import (Room, both_touch, corner_wait_marks, find_open_sides, one_sided,
                          test_drive_rule)
from .fence_types import Deployment, Fence, FenceEdge, FenceSide
from .params import TopologyParams

__all__ = ["Deployment", "FenceSide", "FenceEdge", "Fence", "detect_fence"]

_I64 = np.int64


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
    probe_found=None,
    probe_offsets=None,
    tilt_failures=(),
    sweeps=None,
    sweep_tries=None,
    sweep_foreign=(),
    sweep_blocked=(),
    sweep_first=(),
    sweep_home=(),
) -> Fence:
    """Frontier and obstacle edges with their deployment bearings (spec 3.1-3.4).

    How a side closes (spec 3.4 with the amendment of 2026-11, "evidence before a side
    closes"; with ``TopologyParams.sweep``, the default, a candidate side of an edge with a
    triangle closes on WALL SWEEPS from both ends instead of the probes below: once the
    intervals ``sweeps`` joined cover it, as coordinator.topology.evidence says, each end
    offering a sweep until its tries are used up, then the probe lines in the gaps left
    ('gap_probes' on evidence; see ``sweep_blocked``), the inference 'sweep_gap' or, an end
    having found room, 'probe_clear'). The ends' rules only make a side a CANDIDATE:
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
    touched within TopologyParams.no_room_depth (0.45 rv with probes) of the edge: no such opening
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
    probe_found: key -> probes touched there since: interior probes a drive went clear at
      whose room no robot holds (a free probe came back, or its robot left). On a side in
      ``sweep_foreign`` (a robot cut off from the swarm stopped one of its sweeps) a touch
      there later is no evidence of a wall: the key is offered again, and after
      evidence.FOUND_TOUCH_LIMIT touches no more; the side then closes neither on
      evidence nor by inference (frontier with no deployment: the run ends uncertified
      unless a robot reaches the room another way). On other sides a later touch counts.
    probe_offsets: key -> touch sector centre minus the direction driven (rad) of touched
      perpendicular probes. Missing: the sector is unknown (no tilt from it).
    tilt_failures: key -> tilts (rad, from the perpendicular) of its TILTED probes that
      touched. A touched perpendicular probe is done only once a tilted probe from the same
      point touched (or one found room: ``probe_clear``) along each wall normal known at the
      side (those ``evidence.needs_tilt`` keeps): its own touch sector's centre, and the
      wall contact of either end that points into the open side. So every wall the side's
      robots have felt is probed along (within tau of) its normal, where an oblique door
      is widest (coordinator.topology.evidence).
    sweeps: (u, v, sigma) -> intervals (lo, hi) of the side the wall sweeps of its ends
      joined, in fractions from u, the ray at u -inf and the ray at v +inf
      (evidence.sweep_interval).
    sweep_tries: (u, v, sigma, 0.0 or 1.0: the end u or v) -> sweeps driven from that end.
    sweep_foreign: sides (u, v, sigma) a sweep of which a robot outside the complex's
      sources' part stopped: their gaps are never closed as the inference 'sweep_gap'.
    sweep_blocked: sides (u, v, sigma) a sweep of which a robot of the swarm (linked to a
      source) stopped. With ``TopologyParams.gap_probes`` a side whose sweeps are over with
      a gap left and no room found is probed on the probe lines in its gaps (closed on
      evidence, 'gap_probes', once they all touched) unless it is blocked: then it closes
      as the inference 'sweep_blocked'; a gap no probe line falls in as 'sweep_gap'.
    sweep_first: sides (u, v, sigma) the planner asked to be swept before deploying
      (``TopologyParams.sweep_fallbacks``): an open side of an edge with a triangle that
      is no candidate becomes one ('sweep_first'), and closes only on evidence; an
      inference its sweeps would lead to, or nothing left to drive, leaves it a plain
      frontier side (fence_probes.keep_evidence). sweep_home: sweep keys (u, v, sigma,
      end) of asked sides whose free sweep drove clear and came home: that end is done
      while the side is asked, and nothing otherwise.
    forced_obstacle: edges (pairs of node ids) whose open sides are obstacle sides,
      e.g. edges reclassified after a failed test drive in an earlier cycle.
    default_bearing: first deployment direction (rad, body frame) of a robot with no
      neighbour at all (the others follow 60 deg apart: six in all); a float, or node id ->
      direction (missing ids use 0).
    Single-file robots (in no triangle, neighbours on one side) offer every direction of
    their open wedge 60 deg apart, once their dangling edges' deployments are gone.
    """
    P = params or TopologyParams()
    L = _Local(cx)
    pos, neg = one_sided(cx)
    open_sides, exceptions, marks, corner_wait = find_open_sides(cx, L, P, pos, neg)
    # the ends' rules make a side a candidate (ends); marks close sides
    room = Room(cx, L, P.tau, test_drive_failures)
    ends = both_touch(cx, L, open_sides, room)
    ends = test_drive_rule(cx, open_sides, room, ends)
    marks = corner_wait_marks(corner_wait, marks, room)
    ev = probe_evidence(probe_failures, probe_fracs, probe_unreachable, probe_clear,
                        probe_offsets, tilt_failures, sweeps, sweep_tries, sweep_foreign,
                        probe_found, sweep_blocked, sweep_home)
    if P.corner_probes:
        marks, ends = corner_candidates(marks, ends, open_sides)
    ends = asked_candidates(cx, open_sides, ends, marks, sweep_first)
    probing, marks = plan_probes(cx, L, P, room, ev, ends, marks, open_sides)
    marks, probing = keep_evidence(ends, marks, probing)
    marks = forced_marks(cx, forced_obstacle, marks)
    fence_edges, K, O, z, deps = resolve_sides(cx, L, open_sides, marks, probing, room)
    deployments = robot_deployments(cx, L, room, deps, default_bearing)
    return _fence(cx, fence_edges, K, O, z, deployments, list(open_sides), exceptions)


def _fence(cx: Complex, fence_edges: list[FenceEdge], K: list[int], O: list[int], z: list[int],
           deployments: Mapping[int, tuple[Deployment, ...]], open_edges: list[int],
           exceptions: list[int]) -> Fence:
    """The Fence: edge id arrays sorted, z_raw the one-sided edges z, z_repair the T-join
    that makes it a cycle (:func:`_repair_cycle`, cheap inside the band of the open and
    exception edges' ends), z = z_raw XOR z_repair, and the vertex sets."""
    ids = cx.ids
    K_arr = np.array(sorted(K), dtype=_I64)
    fence_edges.sort(key=lambda f: f.index)
    z_raw = np.array(sorted(z), dtype=_I64)
    band = np.zeros(cx.n, dtype=bool)
    if open_edges or exceptions:
        band[cx.edges[np.array(open_edges + exceptions, dtype=_I64)].ravel()] = True
    repair = _repair_cycle(cx, z_raw, band) if z_raw.size else np.zeros(0, _I64)
    zmask = np.zeros(cx.n_edges, dtype=bool)
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

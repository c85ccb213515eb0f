"""Desired bearings for the robots of a push (spec section 4.4).

Keys are vertex ids (the coordinator's vertex -> occupant map turns them into robot
ids); all bearings are radians in the body frame of the robot they are for. The frame
rotation psi of spec 4.7 is left to the agent (psi = 0 for non-rotating robots).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from swarmcover.ground.angles import wrap

__all__ = ["MoveTarget", "frontier_desired_bearings", "push_desired_bearings", "plan_push_targets",
           "probe_via_bearings", "star_shape"]


@dataclass(frozen=True)
class MoveTarget:
    """Desired bearings for one moving robot.

    robot: the mover's robot id. from_vertex: vertex it leaves. to_vertex: vertex it
    takes (None for the frontier robot, which goes to the new position).
    by_vertex: landmark vertex -> desired bearing (rad). by_robot: the same keyed by the
    robot that holds each landmark vertex after the push (landmarks left empty dropped).
    """

    robot: int
    from_vertex: int
    to_vertex: int | None
    by_vertex: Mapping[int, float] = field(default_factory=dict)
    by_robot: Mapping[int, float] = field(default_factory=dict)


def frontier_desired_bearings(
    neighbour_bearings: Mapping[int, float],
    deploy_bearing: float,
    *,
    d0: float,
    rv: float,
    old_vertex: int,
) -> dict[int, float]:
    """Desired bearings of the frontier robot at its new position (assumed geometry).

    neighbour_bearings: vertex -> bearing (rad, the frontier robot's frame) of its
    current neighbours. deploy_bearing: direction of the new position (rad, same frame),
    i.e. theta_j + theta_new. The old position is the origin, neighbour l sits at
    d0 * b_l, the target at p = d0 * b(deploy_bearing). Returns vertex -> desired bearing
    for every neighbour with |q_l - p| <= rv, plus ``old_vertex`` -> angle(-p).
    """
    px, py = d0 * math.cos(deploy_bearing), d0 * math.sin(deploy_bearing)
    out: dict[int, float] = {}
    for l, th in neighbour_bearings.items():
        qx, qy = d0 * math.cos(th) - px, d0 * math.sin(th) - py
        if math.hypot(qx, qy) <= rv + 1e-12:
            out[int(l)] = wrap(math.atan2(qy, qx))
    out[int(old_vertex)] = wrap(math.atan2(-py, -px))
    return out


def _after_push(path: Sequence[int], occupant: Mapping[int, int], new_robot: int | None):
    """Vertex -> robot holding it once the push is over (None when left empty)."""
    pos = {v: i for i, v in enumerate(path)}

    def holder(w: int):
        i = pos.get(w)
        if i is None:
            return occupant.get(w)
        if i == 0:
            return new_robot
        return occupant.get(path[i - 1])

    return holder


def push_desired_bearings(
    path: Sequence[int],
    recorded: Mapping[int, Mapping[int, float]],
    occupant: Mapping[int, int],
    *,
    new_robot: int | None = None,
) -> list[MoveTarget]:
    """Desired bearings of the robots moving p_t -> p_{t+1}, t = 0 .. m-1.

    recorded: vertex -> {neighbour vertex: bearing (rad)} as last measured by that
    vertex's occupant. occupant: vertex -> robot id before the push. new_robot: robot
    that enters at p0 (a source), or None (p0 is a redundant vertex left empty).
    The robot from p_t takes the recorded bearings of p_{t+1}; each landmark vertex is
    mapped to the robot that holds it after the push.
    """
    path = [int(v) for v in path]
    holder = _after_push(path, occupant, new_robot)
    out = []
    for t in range(len(path) - 1):
        a, b = path[t], path[t + 1]
        by_v = {int(w): float(th) for w, th in recorded.get(b, {}).items() if int(w) != b}
        by_r = {}
        for w, th in by_v.items():
            r = holder(w)
            if r is not None:
                by_r[int(r)] = th
        out.append(MoveTarget(int(occupant[a]), a, b, by_v, by_r))
    return out


def plan_push_targets(
    path: Sequence[int],
    recorded: Mapping[int, Mapping[int, float]],
    occupant: Mapping[int, int],
    deploy_bearing: float,
    *,
    d0: float,
    rv: float,
    new_robot: int | None = None,
) -> list[MoveTarget]:
    """All movers of a push: the followers (:func:`push_desired_bearings`) and, last,
    the frontier robot going to the new position (``to_vertex`` None), whose landmarks
    include its old vertex (held by the follower afterwards)."""
    path = [int(v) for v in path]
    f = path[-1]
    holder = _after_push(path, occupant, new_robot)
    movers = push_desired_bearings(path, recorded, occupant, new_robot=new_robot)
    by_v = frontier_desired_bearings(recorded.get(f, {}), deploy_bearing, d0=d0, rv=rv, old_vertex=f)
    by_r = {}
    for w, th in by_v.items():
        r = holder(w)
        if r is not None:
            by_r[int(r)] = th
    movers.append(MoveTarget(int(occupant[f]), f, None, by_v, by_r))
    return movers


def probe_via_bearings(
    bearings_p: Mapping[int, float],
    bearings_q: Mapping[int, float],
    p: int,
    q: int,
    frac: float,
) -> dict[int, float]:
    """Desired bearings (rad, p's body frame) at the point x = p + frac (q - p) of the edge
    p-q: the start of a probe's perpendicular drive (coordinator.topology.evidence).

    Bearing-only: q is seen from x where p sees it. For a common neighbour k (a triangle
    p, q, k) the angles at p and at q fix the triangle's shape (law of sines:
    |pk| / |pq| = sin(angle at q) / sin(angle at p + angle at q)), hence k's bearing from x.
    Of the common neighbours the one seen most nearly at right angles to q from x is used
    (two landmarks fix the point best there). Returns {q: bearing} plus {k: bearing} when
    some k gives a well-conditioned triangle; just {q: bearing} for a dangling edge.
    """
    tq = float(bearings_p[q])
    out = {int(q): wrap(tq)}
    if not p in bearings_q:
        return out
    tqp = float(bearings_q[p])
    best = None
    for k, tk in bearings_p.items():
        if k in (p, q) or k not in bearings_q:
            continue
        a = abs(wrap(tk - tq))                  # angle at p, between q and k
        b = abs(wrap(float(bearings_q[k]) - tqp))  # angle at q, between p and k
        if a < 1e-3 or b < 1e-3 or a + b > math.pi - 1e-3:
            continue
        r = math.sin(b) / math.sin(a + b)       # |pk| / |pq|
        kx, ky = r * math.cos(tk) - frac * math.cos(tq), r * math.sin(tk) - frac * math.sin(tq)
        bk = math.atan2(ky, kx)
        score = abs(math.sin(bk - tq))
        if best is None or score > best[0]:
            best = (score, int(k), wrap(bk))
    if best is not None and best[0] > math.sin(math.radians(15.0)):
        out[best[1]] = best[2]
    return out


def star_shape(nbrs: Mapping[int, Mapping[int, float]], p: int, q: int, reach: float = 2.5
               ) -> dict[int, tuple[float, float]]:
    """Where the robots around p stand, in p's body frame with p at the origin and |pq| = 1,
    from bearings alone: q on its bearing at distance 1, then, breadth-first, every vertex
    w that two placed vertices a, b seeing each other both see: the triangle's angles at a
    and at b (each robot's bearings in its own frame, so only differences of one robot's
    bearings are used) fix w on the side of ab it is seen on. The landmarks of a wall sweep
    from p (coordinator.topology.evidence): vertices farther than ``reach`` (|pq| units)
    from p, and triangles too thin (an angle under 5 deg) to fix a point, are left out."""
    bp = nbrs.get(p, {})
    if q not in bp or p not in nbrs.get(q, {}):
        return {}
    pos: dict[int, tuple[float, float]] = {p: (0.0, 0.0), q: (math.cos(bp[q]), math.sin(bp[q]))}
    thin = math.radians(5.0)
    edges = [(p, q)]
    k = 0
    while k < len(edges):
        a, b = edges[k]
        k += 1
        ba, bb = nbrs.get(a, {}), nbrs.get(b, {})
        if b not in ba or a not in bb:
            continue
        for w in sorted(set(ba) & set(bb)):
            if w in pos:
                continue
            ta = wrap(float(ba[w]) - float(ba[b]))     # at a, from b to w (signed)
            tb = wrap(float(bb[w]) - float(bb[a]))     # at b, from a to w
            A, B = abs(ta), abs(tb)
            if A < thin or B < thin or A + B > math.pi - thin or (ta > 0) == (tb > 0):
                continue
            (ax, ay), (bx, by) = pos[a], pos[b]
            ab = math.hypot(bx - ax, by - ay)
            d = ab * math.sin(B) / math.sin(A + B)     # |aw|, law of sines
            ang = math.atan2(by - ay, bx - ax) + ta    # the direction a -> w
            wx, wy = ax + d * math.cos(ang), ay + d * math.sin(ang)
            if math.hypot(wx, wy) > reach:
                continue
            pos[w] = (wx, wy)
            edges += [(a, w), (b, w)]
    del pos[p]
    return pos

"""Desired bearings for the robots of a push (spec section 4.4).

Keys are vertex ids (the coordinator's vertex -> occupant map turns them into robot
ids); all bearings are radians in the body frame of the robot they are for. The frame
rotation psi of spec 4.7 is left to the agent (psi = 0 for non-rotating robots).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from .angles import wrap

__all__ = ["MoveTarget", "frontier_desired_bearings", "push_desired_bearings", "plan_push_targets"]


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

"""The fence's data types: what :func:`coordinator.topology.fence.detect_fence` returns.

``Deployment`` (where a robot would send a new robot), ``FenceSide`` (one open side of an
edge and how it got its kind), ``FenceEdge`` (an edge of K or O with its sides) and
``Fence`` (the whole result). Node ids are the robots' ids (``Complex.ids``), edge ids
index ``Complex.edges``; bearings and offsets are rad in the body frame of the robot
named; sides sigma are +1/-1 in the canonical orientation of fence.py's docstring.
Arrays of edge ids are int64 (k,), sorted.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

__all__ = ["Deployment", "FenceSide", "FenceEdge", "Fence", "EVIDENCE"]

# the reasons an obstacle side closes on evidence (every other reason is an inference,
# reported with the certificate): 'probes' (every probe touched, or a side's wall sweeps
# joined from ray to ray) and 'gap_probes' (the probe lines in the gaps a side's sweeps
# left all touched: coordinator.topology.fence_probes)
EVIDENCE = frozenset({"probes", "gap_probes"})


@dataclass(frozen=True)
class Deployment:
    """Where a robot at ``vertex`` would send a new robot.

    bearing: direction (rad) in the body frame of the robot at ``vertex``.
    edge: fence edge (u, v) node ids with u < v, or None (single file / isolated robot).
    sigma: canonical open side of ``edge`` (+1/-1), 0 when edge is None.
    offset: theta_new, the signed angle (rad) from the edge direction to ``bearing``.
    clearance: smallest |angle| (rad) between ``bearing`` and any neighbour bearing
      (pi when the robot has no neighbour).
    kind: 'edge', 'single_file', 'isolated' or 'probe'.
    via_frac: probes only: the drive first goes from ``vertex`` to the point at this
      fraction of the way toward the edge's other end (0: no approach leg, a plain
      perpendicular test drive from ``vertex``), then along ``bearing``, perpendicular to
      the edge into the open side ``sigma``.
    depth_rv: how far (x rv) the drive along ``bearing`` goes; 0 for non-probes (the
      configured test-drive length or the planner's placement).
    tilt: probes only: 0 for a probe perpendicular to the edge; for a TILTED probe (its
      perpendicular probe touched, coordinator.topology.evidence) the CCW angle (rad) from
      the perpendicular to ``bearing``: the touch sector's centre, near the wall's normal.
    sweep_far: a WALL SWEEP (coordinator.topology.evidence, TopologyParams.sweep) when > 0:
      the drive along ``bearing`` (its end's own "no room" direction, via_frac 0) is
      followed, on a touch, by a slide along the wall pressing into it until the robot
      crosses the perpendicular to the edge at this fraction of the edge from ``vertex``,
      then back past ``vertex`` until it crosses the ray from ``vertex`` ``sweep_stop``
      (rad) beyond the edge's perpendicular there (away from the other end).
    A geometric harness executes a probe as: x = p + via_frac * (q - p), then drive from x
    along the perpendicular for depth_rv * rv; a touch within the deployer's wall keep
    (CoordinatorConfig.wall_keep) sends the robot home (evidence of a wall), no touch leaves it there.
    """

    vertex: int
    bearing: float
    edge: tuple[int, int] | None
    sigma: int
    offset: float
    clearance: float
    kind: str
    via_frac: float = 0.0
    depth_rv: float = 0.0
    tilt: float = 0.0
    sweep_far: float = 0.0
    sweep_stop: float = 0.0


@dataclass(frozen=True)
class FenceSide:
    """One open side of a fence edge.

    kind: 'frontier' or 'obstacle'. reason (also ``why``): for obstacle sides 'probes'
    (evidence: every probe of the side touched), or an inference: 'convex_corner' (the
    occlusion rule of spec 3.3, pi/3 - 2 beta) or 'forced' (carried over by the caller); for
    frontier sides 'open', or 'probing' (its ends say "no room", some probe is still
    untried: only probes are offered on it). deploy_u / deploy_v: deployment bearings (rad)
    in the body frames of u and v (None for obstacle and probing sides). offset_u / offset_v:
    theta_new at u and at v.
    """

    sigma: int
    kind: str
    reason: str
    deploy_u: float | None = None
    deploy_v: float | None = None
    offset_u: float | None = None
    offset_v: float | None = None

    @property
    def why(self) -> str:
        """How the side got its kind (the same as ``reason``)."""
        return self.reason

    @property
    def inferred(self) -> bool:
        """An obstacle side closed by inference, not by evidence (``EVIDENCE``)."""
        return self.kind == "obstacle" and self.reason not in EVIDENCE


@dataclass(frozen=True)
class FenceEdge:
    """A fence edge: node ids u < v, its edge id in the complex, and its open sides."""

    u: int
    v: int
    index: int
    sides: tuple[FenceSide, ...]

    @property
    def one_sided(self) -> bool:
        return len(self.sides) == 1

    @property
    def is_frontier(self) -> bool:
        return any(s.kind == "frontier" for s in self.sides)

    @property
    def is_obstacle(self) -> bool:
        return any(s.kind == "obstacle" for s in self.sides)


@dataclass(frozen=True, eq=False)
class Fence:
    """Result of :func:`detect_fence`.

    edges: every fence edge (in K or O), by edge id order.
    frontier / obstacle / exceptions: edge ids (into ``Complex.edges``) of K, O and the
      exception set E.
    z_raw: edge ids of the one-sided fence edges: the certificate's target
      (coordinator.topology.certificate).
    z_repair: edge ids of a shortest T-join pairing z_raw's odd vertices (the closure
      certify tries first); z = z_raw XOR z_repair, a cycle (for figures and viewers).
    deployments: node id -> deployments available at that robot, best clearance first.
    frontier_vertices / obstacle_vertices / fence_vertices: node ids.
    inferred: (edge id, why) for every obstacle side closed by inference rather than by
      probes ('convex_corner', 'forced', 'probe_clear'), by edge id.
    """

    edges: tuple[FenceEdge, ...]
    frontier: np.ndarray
    obstacle: np.ndarray
    exceptions: np.ndarray
    z: np.ndarray
    z_raw: np.ndarray
    z_repair: np.ndarray
    deployments: Mapping[int, tuple[Deployment, ...]]
    frontier_vertices: frozenset[int]
    obstacle_vertices: frozenset[int]
    fence_vertices: frozenset[int]
    by_index: Mapping[int, FenceEdge] = field(default_factory=dict)
    inferred: tuple[tuple[int, str], ...] = ()

    @property
    def done(self) -> bool:
        """True when there is no frontier left (K empty and no deploying robot)."""
        return not self.deployments

    @property
    def gap_probed(self) -> tuple[int, ...]:
        """Edge ids of the obstacle edges closed on the evidence of the probe lines driven
        in the gaps their sweeps left ('gap_probes'), by edge id: the Complex message's
        ``gap_probed``, so that an audit tells them from 'probes'."""
        return tuple(fe.index for fe in self.edges
                     if any(s.kind == "obstacle" and s.reason == "gap_probes" for s in fe.sides))

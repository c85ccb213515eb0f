"""swarmcover coordinator: the topology core (pure functions, no I/O).

Works on node ids, neighbour bearings (rad, body frame) and touch flags; never measured
positions (``shape`` estimates the swarm's shape from those bearings).
"""
from .angles import circular_mean, wrap
from .certificate import (Certificate, boundary_of, certify, certificate_from_chain, closure_zone, fence_cycle,
                          is_cocycle, verify_certificate)
from .complex import Complex, RobotReport, add_robot, as_report, build_complex, remove_robot
from .fence import Deployment, Fence, FenceEdge, FenceSide, detect_fence
from .gvg import GVG, compute_gvg, gvg_thin, gvg_wavefront, obstacle_segments
from .params import TopologyParams
from .paths import PushPath, deployment_point, plan_pushes
from .redundancy import Redundancy, find_redundant, link_is_acyclic
from .shape import Lattice, align_headings, estimate_shape, lattice_target
from .targets import MoveTarget, frontier_desired_bearings, plan_push_targets, push_desired_bearings

__all__ = [
    "TopologyParams",
    "wrap",
    "circular_mean",
    "RobotReport",
    "as_report",
    "Complex",
    "build_complex",
    "add_robot",
    "remove_robot",
    "Deployment",
    "FenceSide",
    "FenceEdge",
    "Fence",
    "detect_fence",
    "Certificate",
    "certify",
    "verify_certificate",
    "boundary_of",
    "is_cocycle",
    "fence_cycle",
    "closure_zone",
    "certificate_from_chain",
    "Redundancy",
    "find_redundant",
    "link_is_acyclic",
    "PushPath",
    "plan_pushes",
    "deployment_point",
    "MoveTarget",
    "frontier_desired_bearings",
    "push_desired_bearings",
    "plan_push_targets",
    "GVG",
    "gvg_wavefront",
    "gvg_thin",
    "compute_gvg",
    "obstacle_segments",
    "align_headings",
    "estimate_shape",
    "Lattice",
    "lattice_target",
]

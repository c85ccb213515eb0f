"""Parameters of the topology core (spec section 1.8), in one frozen dataclass.

Lengths are in the same unit as the visibility radius ``rv`` (normalised to 1);
angles are in radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["TopologyParams", "PROBE_NO_ROOM_RV"]

PROBE_NO_ROOM_RV = 0.45   # the probe rule's no-room depth (x rv): TopologyParams.no_room_depth


@dataclass(frozen=True)
class TopologyParams:
    """Tunable constants of the coverage algorithm.

    rv: visibility radius. eps: separation margin (target spacing d0 = rv - eps);
    defaults to 0.1*rv. beta: bearing-noise bound (rad). n_touch: number of binary
    contact sensors N_T (tau = pi/N_T). w_obstacle: path cost of an obstacle edge (> 1).
    d_td: test-drive distance, defaults to 0.25*rv. gamma: concave-corner angle
    threshold (rad). redundancy_period: T_H, deployment cycles between redundancy passes.

    Evidence rules (issue 21; measured in coordinator/topology/fence.py's notes):
    corner_probes: convex-corner marks (spec 3.3 ii) only make a side a probing candidate
      (True) instead of closing it as the reported inference 'convex_corner' (False).
    clear_infers: a side whose probes are all done, some clear, while it stays one-sided,
      closes as the reported inference 'probe_clear' (the others touched) or
      'probe_unreachable' (some unreached from both ends) (True), or stays frontier with no
      deployment left (False: the run cannot certify).
    corner_wait: a convex corner seen from one end only, whose other end has a reflex open
      wedge on that side (a robot in a doorway), closes only once that end's own drives
      there touched (True), or at once (False). On by default since 2026-12-04: off,
      bench/truth.py seed 3 map 399 certified the room behind a 0.44 rv door uncovered
      (58.8% coverage; the side from the doorway robot back into the first room closed as
      'convex_corner'), a door the guarantee covers. Before, off: it removed map 70's false
      certificate (a 0.30 rv door), and corridor_doors (seed 0, in-process, before wall
      sweeps) took 94 robots / 150 cycles with it against 75 / 85 without; with today's
      rules that run is the same both ways (docs/measured.md, "A robot in a doorway").
    tilt_min: a probe that touched with its touch sector's centre more than this (rad) off
      the direction driven is driven again along that centre, near the wall's normal, and
      so is each probe of a side whose end rests on a wall that far off
      (coordinator.topology.evidence); below it the perpendicular line is already within
      tau + tilt_min of the normal. Default tau: a touch in the line's own sector is not
      re-driven. Measured (corridor_doors, seed 0, in-process; truth campaigns in
      docs/measured.md): 3 deg gave 0.41 rv doors at any angle but 90 robots / 4,231 s against 75 /
      1,785 s (every re-drive disturbs the swarm a little, and more sides get probed);
      11.25 deg 3,824 s; tau 2,155 s. pi never re-drives (the rules before 2026-11-25).
      Not used when ``sweep`` is on (a sweep follows the wall at whatever angle).
    sweep: a candidate side closes on WALL SWEEPS (coordinator.topology.evidence): each end
      drives into its wall, slides along it pressing into it to the line ``sweep_overlap``
      / 2 past the edge's middle, then back past its own end to the neighbouring side's
      perpendicular (plus ``sweep_margin``, rad); going round the end of a wall on the way is
      an opening the robot stays in. False: the perpendicular and tilted probes at
      door_min_rv spacing (the rules before 2026-11-27).
    sweep_overlap: fraction of the edge by which the two ends' sweeps overlap (each goes
      this / 2 past the middle), so bearing noise in where a sweep stops leaves no gap.
    sweep_margin: how far (rad) past the ray at its end a sweep goes: 10 deg, about 5 cm
      at a wall 0.3 m out, twice the error of an agent's place from two landmarks seen
      0.9 m away with 0.5 deg of bearing noise.
    sweep_tries: sweeps from one end of one side (a sweep stopped short, e.g. by a robot in
      its way, is tried again with a farther target, up to this many in all).
    sweep_lenses: a sweep's room test also counts the lens of each segment from its vertex to
      another of its landmarks, and its first drive goes on while in them, up to d0
      (agents.sweep.SweepGeom.held, ground.geometry.lens_radii). On by default since
      2026-12-03: seed 0 in process it took 755 -> 703 robots over the eight configs; the
      false certificate bench/truth.py met with it (seed 0 map 429) came from the bench's
      booking of rooms, not the rule: booked as the deployer books them (run_map's
      ``hold_rooms``, now the bench's default), 500 of 500 maps certified, 0 false, on
      seeds 0 and 1 each (docs/measured.md, issue 19).
    gap_probes: a side whose sweeps are over with a gap left and no end's room found drives
      the probe lines that fall in the gaps (coordinator.topology.fence_probes) and closes
      on their touches ('gap_probes', evidence) or as the probe rule's inferences, unless a
      robot of the swarm stopped one of its sweeps (the inference 'sweep_blocked': the
      space in front of the side is where that robot stands); a gap no line falls in
      (narrower than door_min_rv, or in front of an end) still closes as the inference
      'sweep_gap'. False: every such side closes as 'sweep_gap' (the rule until 2026-12-03).
    sweep_fallbacks: a push whose deployment finds no free lattice point (the planner's
      fallback, the spec's direction at the spacing) from a robot resting on a wall (its
      contact) is not driven: its side is asked to be swept first
      (coordinator.planner, detect_fence's ``sweep_first``) and closes only on the sweeps'
      evidence; else it is deployed as before. The fallbacks laid second rows of robots
      along the walls (docs/measured.md, "Where the robots go").
    """

    rv: float = 1.0
    eps: float | None = None
    beta: float = math.radians(2.0)
    n_touch: int = 8
    w_obstacle: float = 3.0
    d_td: float | None = None
    gamma: float = 3.0 * math.pi / 4.0
    redundancy_period: int = 10
    corner_probes: bool = False
    clear_infers: bool = True
    corner_wait: bool = True
    tilt_min: float | None = None
    sweep: bool = True
    sweep_overlap: float = 0.1
    sweep_margin: float = math.radians(10.0)
    sweep_tries: int = 2
    sweep_lenses: bool = True
    gap_probes: bool = True
    sweep_fallbacks: bool = False

    def __post_init__(self) -> None:
        if self.eps is None:
            object.__setattr__(self, "eps", 0.1 * self.rv)
        if self.d_td is None:
            object.__setattr__(self, "d_td", 0.25 * self.rv)
        if self.tilt_min is None:
            object.__setattr__(self, "tilt_min", self.tau)
        if not self.rv > 0:
            raise ValueError("rv must be positive")
        if not 0 <= self.eps < self.rv:
            raise ValueError("eps must be in [0, rv)")
        if self.n_touch < 1:
            raise ValueError("n_touch must be >= 1")
        if not self.w_obstacle >= 1:
            raise ValueError("w_obstacle must be >= 1")
        if not 0 <= self.sweep_overlap < 1:
            raise ValueError("sweep_overlap must be in [0, 1)")
        if self.sweep_tries < 1:
            raise ValueError("sweep_tries must be >= 1")

    @property
    def tau(self) -> float:
        """Touch-direction resolution pi/N_T (rad)."""
        return math.pi / self.n_touch

    @property
    def d0(self) -> float:
        """Assumed inter-robot spacing rv - eps."""
        return self.rv - self.eps

    @property
    def sweep_depth(self) -> float:
        """How far (rv's unit) from the edge a sweep may follow its wall, and how far its
        first drive goes: sqrt(d0^2 - (rv / 2)^2), the depth of the lens both ends' d0-disks
        cover at the middle of an edge rv long (0.75 rv at the defaults). A wall that
        recedes beyond it leaves room in front of the side: the robot stays there."""
        return math.sqrt(max(self.d0 ** 2 - 0.25 * self.rv ** 2, 0.0625 * self.rv ** 2))

    def no_room_depth(self, wall_keep_rv: float = 0.0) -> float:
        """A test drive that touches nearer than this (rv's unit) to its vertex found no
        room: it fails and goes home; a touch farther out leaves its robot at the wall.
        ``wall_keep_rv`` x rv when that is > 0 (the deployer's ``[coordinator]
        wall_keep_rv``); else with sweeps :attr:`sweep_depth` (the two ends see everything
        that close to the edge, and the sweep then follows the wall there and finds any
        opening in it; a wall receding farther is room), with the probe rule
        PROBE_NO_ROOM_RV x rv, what its probe lines' guarantee was measured at."""
        if wall_keep_rv > 0:
            return wall_keep_rv * self.rv
        return self.sweep_depth if self.sweep else PROBE_NO_ROOM_RV * self.rv

    @property
    def corner_threshold(self) -> float:
        """Convex-corner / occlusion threshold pi/3 - 2*beta (rad)."""
        return math.pi / 3.0 - 2.0 * self.beta

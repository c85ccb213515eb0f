"""The ``[coordinator]`` section of a run config, validated into a frozen dataclass.

Lengths in metres (relative values are multiplied by rv), times in simulated seconds.
"""
from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass
from enum import StrEnum

from swarmcover.bus.configcheck import ConfigError, check_fields

from .topology.params import TopologyParams

# The topology core's defaults, resolved (eps = 0.1 rv): the fields the two share take
# theirs from here, so a default changed in the core is the run's default too.
_CORE = TopologyParams()


class PushMode(StrEnum):
    """How the movers along a push's path go (``push_mode``; equal to its TOML string)."""
    PARALLEL = "parallel"      # at once where >= 2 static landmarks exist
    SEQUENTIAL = "sequential"  # strictly from the front, each once the one ahead arrived


@dataclass(frozen=True)
class CoordinatorConfig:
    """Deployment-cycle settings (spec sections 1.8, 4 and 5)."""

    rv: float = _CORE.rv
    eps_rv: float = _CORE.eps / _CORE.rv  # separation margin as a fraction of rv (d0 = rv - eps)
    beta_deg: float = math.degrees(_CORE.beta)  # bearing-noise bound
    n_touch: int = _CORE.n_touch
    w_obstacle: float = _CORE.w_obstacle  # path cost of an obstacle edge
    test_drive: bool = True        # spec 3.4(iv)
    d_td_rv: float = 0.9           # test-drive distance as a fraction of rv. The spec's [P]
                                   # 0.25 missed walls between 0.25 and 0.9 rv: the new robot
                                   # then stopped against the wall 0.3-0.5 rv from its parent.
                                   # Driving the whole spacing (d0 = rv - eps) halved the
                                   # excess robots on a 6 m x 4 m room (62-68 -> 35-40 robots,
                                   # ideal 27.7) at >= 99.4% coverage
    wall_keep_rv: float = 0.0      # a test-drive touch closer than this (x rv) is "no room":
                                   # the drive fails and the robot returns (spec 3.4(iv)); a
                                   # touch farther out keeps the robot there, against the wall,
                                   # as the new vertex. 0: TopologyParams.no_room_depth, the
                                   # sweep depth (0.75 rv) with sweeps, whose evidence covers
                                   # that strip (0.45 rv with the probe rule). 0.45 -> 0 with
                                   # sweeps_last: tiny seeds 0-8 133 -> 113 robots, office_ros
                                   # 112 -> 98, pillar_hall 139 -> 119, small 300 -> 310; more
                                   # sweeps: +13-53% simulated time on the small maps
    lattice: bool = True           # new positions on one triangular lattice of spacing d0
                                   # through the source, from the swarm's bearing-only shape
                                   # estimate (holonomic swarms; README "departures"); off:
                                   # the spec's 60-deg rule. Seeds 0-2, robots / cycles,
                                   # 60-deg rule -> lattice: open_room 152.7 / 80.7 ->
                                   # 129.7 / 76.7, pillar_hall 137.7 / 86.7 -> 134.0 / 78.7,
                                   # office_ros 104.0 / 139.7 -> 106.7 / 117.7
    refine_deploy: bool = False    # re-home a new robot on the assumed geometry of spec 4.4
                                   # (equilateral on its parent edge, then scale correction)
                                   # after a clear test drive. Off: it stays where the drive
                                   # ended, d0 from its parent (when d_td >= d0). The assumed
                                   # geometry inherits the parent edge's length, so spacing
                                   # shrank cycle after cycle: 6 m x 4 m room, seeds 0-3,
                                   # mean: 57.8 -> 51.2 robots
    redundancy_period: int = _CORE.redundancy_period  # T_H: cycles between redundancy
                                   # passes. Every config seeds 0-2 against 10: at 3,
                                   # +2.3% robots, +3.1% time; at 30, +1.9% robots, +2.8%
                                   # time
    scale_correct_period: int = 5  # run scale correction on a new frontier robot every N cycles
    push_mode: str = "parallel"    # "parallel": movers along a path go at once where >= 2 static
                                   # landmarks exist; "sequential": strictly from the front
    max_paths: int = 8             # pushes per cycle (vertex-disjoint paths)
    td_retries: int = 2            # a push whose test drive touched is re-planned within its
                                   # cycle up to this many times (spec 3.4(iv)); 0: it waits
                                   # for the next cycle
    robots_max: int = 400          # stop (not certified) if more would be needed
    task_timeout_s: float = 40.0   # per task, simulated seconds
    spawn_timeout_s: float = 60.0  # new agent must report within this (sim s)
    settle_moves: bool = True      # a mover that homed on < 2 landmarks homes again on all of
                                   # its vertex's landmarks once its push is over
    settle_s: float = 0.6          # wait after a cycle's last task before re-planning (sim s)
    dead_after_cycles: int = 3     # heartbeat: robot with no status for this many cycles is dead
    stray_cycles: int = 3          # robots cut off from every source stay members this many
                                   # plans (a refilled hole links them again), then are sent away
    dead_grace_s: float = 3.0      # a robot whose liveliness token stays gone this long (sim s)
                                   # is dead; shorter gaps (router restart) are forgiven
    door_min_rv: float = 0.4       # a fence side that its ends' drives or contacts would close
                                   # (no room at either end) is closed only once probes
                                   # perpendicular to it at every interior fraction k/n of its
                                   # length touched; spacing door_min_rv - 2 x robot radius
                                   # (x rv), so any opening at least this wide in front of it
                                   # is driven through (coordinator.topology.evidence). 0.4 with a
                                   # 0.06 m radius at rv = 1 m: probes at 1/4, 1/2, 3/4. A probe
                                   # whose touch sector is not its line's own, or whose side's
                                   # end rests on a wall that oblique, is driven again along
                                   # that wall's normal: 0.52 rv doors at any wall angle
    sweep: bool = _CORE.sweep      # a fence side its ends would close (no room at either end)
                                   # closes once both ends swept the wall in front of it: each
                                   # drives into its wall and slides along it, pressing into
                                   # it, past the edge's middle and back past its own end to
                                   # the next side's perpendicular; going round the end of a
                                   # wall on the way is an opening the robot stays in
                                   # (coordinator.topology.evidence). Every opening in that
                                   # wall at least 2 x radius + 0.06 m wide is found (0.18 m
                                   # with the default body and [agent] sweep_*), whatever its
                                   # width in rv. false: door_min_rv's probe lines
    sweep_lenses: bool = _CORE.sweep_lenses  # a sweep's wall may also recede into the lens of a
                                   # segment from its vertex to another robot round it
                                   # before it is room, and its first drive goes on while in
                                   # them (up to d0): fewer wall robots
                                   # (coordinator.topology.params). false: the edge's lens
                                   # alone (the rule until 2026-12-03)
    gap_probes: bool = _CORE.gap_probes  # a side whose sweeps left a gap and found no room,
                                   # none stopped by a robot of the swarm, drives the probe
                                   # lines in the gap and closes on their touches
                                   # (evidence, 'gap_probes'), not as the inference
                                   # 'sweep_gap' (coordinator.topology.params). false: the
                                   # rule until 2026-12-03
    sweep_fallbacks: bool = _CORE.sweep_fallbacks  # a push whose deployment finds no free lattice point,
                                   # from a robot resting on a wall, sweeps its side first
                                   # instead; the side closes only on the sweeps' evidence
                                   # (coordinator.topology.params). false: deployed at the
                                   # spec's direction (the rule until 2026-12-03)
    corner_wait: bool = _CORE.corner_wait  # a side the occlusion rule would close from
                                   # one end ('convex_corner') while its other end's open
                                   # wedge there is reflex (a robot in a doorway) closes
                                   # only once that end drove into it and found no room
                                   # (coordinator.topology.params). false: at once (the
                                   # rule until 2026-12-04)
    free_probes: bool = True       # frontier robots off every push probe their sides in the
                                   # same cycle without a path, and come back home whatever
                                   # they found (a clear one is no evidence; a push takes that
                                   # side later). Seed 0, in-process, off -> on: corridor_doors
                                   # 77 robots / 98 cycles / 1,935 s -> 75 / 85 / 1,785 s,
                                   # small 33 / 31 / 746 s -> 34 / 27 / 582 s
    free_probes_max: int = 0       # free probes out at once at most; 0: no cap (each needs
                                   # its vertex and neighbours off every mover, which bounds
                                   # them). Was max_paths (8): with sweeps_free, every config
                                   # seeds 0-2 -0.4% -> -3.2% simulated time
    free_probes_rolling: bool = True  # free probes also start within a cycle, whenever one of
                                   # its jobs ends and the fence (recomputed with the evidence
                                   # since) offers a probe at a robot off every push path and
                                   # not next to one or to a probe still out; before, only at
                                   # the cycle's start (two neighbours never probe at once, so
                                   # a wall's robots probed one in two per cycle)
    free_probes_carry: bool = True  # a cycle ends once its pushes are over: free probes still
                                   # out go on into the next cycle, which plans around them
                                   # (no path through a prober's vertex or its neighbours, no
                                   # free probe next to it; the snapshot keeps the prober's
                                   # edges as they were when it left) and never certifies
                                   # while one is out; a probe whose vertex and neighbours
                                   # would cut the next pushes off a deployment is waited
                                   # for (planner.carryable). false: the cycle waits for all
    sweeps_last: bool = True       # pushes go to deployments that may leave a robot while the
                                   # fence offers any; wall sweeps (which mostly come home) run
                                   # beside them as free probes, and by pushes once only sweeps
                                   # are left. Off -> on (wall_keep_rv 0.45): simulated time
                                   # -29% tiny, -20% small (seeds 0-8), -23% corridor_doors,
                                   # -25% on the five larger configs; robots about the same
    sweeps_free: bool = True       # wall sweeps go to free probes first (with free_probes):
                                   # once only sweeps are left, a cycle's free probes take
                                   # every sweep they can, many at once, and pushes the rest;
                                   # a push whose test drive touched is not re-planned to a
                                   # sweep at another vertex. false: pushes take sweeps, and
                                   # re-plan to one sweep after another (up to 12) while
                                   # their paths wait (tiny seed 0: 9 sweeps in a row, 62 s).
                                   # In-process, with free_probes_max 0: every config seeds
                                   # 0-2, 34,065 -> 32,950 s simulated (-3.3%), 2,175 -> 2,190
                                   # robots; tiny -12.5%, small +3.4%
    pipeline: bool = True          # a push fed by an earlier push at the same source (its
                                   # robot at p0 is the one that push brings in) test-drives
                                   # at once, beside that push; its movers wait for the robot.
                                   # false: the whole push waits for it. In-process, every
                                   # config seeds 0-2, against false before the settle fix
                                   # (Pushes._claimed_elsewhere): 2,357 -> 2,351 robots,
                                   # 44,295 -> 40,710 s simulated (hall300: docs/measured.md)
    max_cycles: int = 100000
    final_recheck: bool = True     # after K is empty: redistribute redundant robots, re-certify

    def __post_init__(self):
        # one table of ranges and choices for the file and for code that builds one directly
        check_fields(type(self), {f.name: getattr(self, f.name) for f in dataclasses.fields(self)},
                     "CoordinatorConfig", "coordinator", bounds=_BOUNDS, choices=_CHOICES)

    @property
    def free_max(self) -> int:
        """Free probes out at once at most (free_probes_max; 0: no cap)."""
        return self.free_probes_max or 10**9

    @property
    def d0(self) -> float:
        return self.rv * (1.0 - self.eps_rv)

    @property
    def wall_keep(self) -> float:
        """A test drive's touch nearer than this (m) fails; farther, its robot stays at the
        wall (TopologyParams.no_room_depth)."""
        return self.topology().no_room_depth(self.wall_keep_rv)

    def topology(self) -> TopologyParams:
        return TopologyParams(rv=self.rv, eps=self.eps_rv * self.rv,
                              beta=math.radians(self.beta_deg), n_touch=self.n_touch,
                              w_obstacle=self.w_obstacle, d_td=self.d_td_rv * self.rv,
                              redundancy_period=self.redundancy_period, sweep=self.sweep,
                              sweep_lenses=self.sweep_lenses, gap_probes=self.gap_probes,
                              sweep_fallbacks=self.sweep_fallbacks,
                              corner_wait=self.corner_wait)

    @classmethod
    def from_section(cls, section: dict | None, rv: float, where: str = "config") -> "CoordinatorConfig":
        """Build from a raw ``[coordinator]`` dict. Unknown keys, wrong types, non-finite
        numbers and values out of range are ConfigErrors naming file, section, field, value."""
        vals = check_fields(cls, section, where, "coordinator", bounds=_BOUNDS,
                            choices=_CHOICES, skip=("rv",))
        try:
            return cls(rv=rv, **vals)
        except ConfigError as e:   # rv (from the run config) out of range
            raise ConfigError(where, e.section, e.field, e.value, e.reason) from None


# (lo, hi[, lo_open, hi_open]) per field; fields not listed only need a finite value of
# their type. Lengths in rv, times in simulated seconds.
_BOUNDS = {
    "rv": (0.0, 1e6, True),
    "eps_rv": (0.0, 1.0, False, True),
    "beta_deg": (0.0, 30.0),
    "n_touch": (1, 360),
    "w_obstacle": (0.0, 1e6, True),
    "d_td_rv": (0.0, 10.0, True),
    "wall_keep_rv": (0.0, 10.0),
    "redundancy_period": (1, 10**9),
    "scale_correct_period": (1, 10**9),
    "max_paths": (1, 10**6),
    "free_probes_max": (0, 10**6),
    "td_retries": (0, 1000),
    "robots_max": (1, 10**6),
    "task_timeout_s": (0.0, 1e9, True),
    "spawn_timeout_s": (0.0, 1e9, True),
    "settle_s": (0.0, 1e6),
    "dead_after_cycles": (1, 10**9),
    "stray_cycles": (1, 10**9),
    "dead_grace_s": (0.0, 1e6),
    "max_cycles": (1, 10**12),
    "door_min_rv": (0.0, 2.0, True),
}
_CHOICES = {"push_mode": tuple(m.value for m in PushMode)}

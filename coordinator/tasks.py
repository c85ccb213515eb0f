"""The Task messages a push sends its robots (spec 4.4-4.7), built from the cycle's snapshot.

Pure functions of their arguments, no I/O and no state: :class:`TaskBuilder` reads the
snapshot, the roster (who is alive, their current mutual bearings) and the configuration,
and returns :class:`bus.messages.Task` objects without ids (the outbox numbers them). The
caller says which vertices are moving this cycle. Units: distances in metres, bearings and
frame offsets in radians, timeouts in seconds.
"""
from __future__ import annotations

import math

from swarmcover.bus.messages import Task
from swarmcover.ground.angles import wrap
from swarmcover.ground.geometry import lens_radii, lens_reach

from .config import CoordinatorConfig
from .planner import JobSpec, Snapshot
from .roster import Roster


def td_length(spec: JobSpec, params) -> float:
    """How far a job's test drive goes: the planner's distance, else the configured d_td."""
    return params.d_td if spec.distance is None else spec.distance


class TaskBuilder:
    """Task builders for one snapshot. ``moving``: the vertices whose occupants move this
    cycle (their robots are no landmarks)."""

    def __init__(self, cfg: CoordinatorConfig, params, roster: Roster, snap: Snapshot):
        self.cfg = cfg
        self.params = params
        self.roster = roster
        self.snap = snap
        self.snap_vertex_of = {r: v for v, r in snap.occupant.items()}  # robot -> vertex

    # ------------------------------------------------------------------ frames
    def ref_offsets(self, recorder_vertex: int, landmark_vertices: list[int]) -> list[float]:
        """Frame alignment data (spec 4.7): heading of the recorder minus each landmark's
        heading, from mutual bearings. [] when every robot is holonomic (frames parallel)."""
        snap = self.snap
        if all(k == "holonomic" for k in snap.kinds.values()):
            return []
        out = []
        for u in landmark_vertices:
            if u < 0:
                return []
            a = snap.nbrs.get(recorder_vertex, {}).get(u)
            b = snap.nbrs.get(u, {}).get(recorder_vertex)
            if a is None or b is None:
                return []
            out.append(wrap(b - a + math.pi))
        return out

    def chained_offsets(self, f: int, lm: list[int]) -> list[float]:
        """ref_offsets for bearings recorded by f's occupant in the snapshot (spec 4.7).
        Landmarks that held a neighbour vertex of f then: from the snapshot's mutual
        bearings; a robot that moved there since (the one now holding f, or the robot
        ahead on a push): chained through a static landmark and the robots' current Status.
        [] when every robot is holonomic, or when some landmark cannot be aligned."""
        snap = self.snap
        if all(k == "holonomic" for k in snap.kinds.values()):
            return []
        static = {}
        for r in lm:
            u = self.snap_vertex_of.get(r, -1)
            if u >= 0 and u != f:
                o = self.ref_offsets(f, [u])
                if o:
                    static[r] = o[0]
        out = []
        for r in lm:
            if r in static:
                out.append(static[r])
                continue
            got = None
            for s, o in static.items():
                m = self.roster.mutual(s, r)
                if m is not None:
                    got = wrap(o + m)
                    break
            if got is None:
                return []
            out.append(got)
        return out

    # ------------------------------------------------------------------ landmarks
    def vertex_landmarks(self, v: int, exclude: set[int], holder: dict[int, int] | None = None,
                         skip: int | None = None) -> tuple[list[int], list[float]]:
        """The live robots holding v's neighbour vertices (minus ``exclude``; ``holder``:
        vertex -> the robot there now, None: the snapshot's occupants; never robot
        ``skip``) and v's recorded bearings of those vertices."""
        snap = self.snap
        holder = snap.occupant if holder is None else holder
        lm, br = [], []
        for u, b in sorted(snap.nbrs.get(v, {}).items()):
            r = holder.get(u)
            if u in exclude or r is None or r == skip or not self.roster.live(r):
                continue
            lm.append(r)
            br.append(b)
        return lm, br

    def _static_landmarks(self, spec: JobSpec, moving: set[int], at_f: int | None = None):
        """The landmarks of the assumed geometry (spec.deploy_landmarks) held by a live
        robot that stays put; vertex f itself only as ``at_f``, the robot now there."""
        occ = self.snap.occupant
        f = spec.path[-1]
        lm, br = [], []
        for v, b in zip(spec.deploy_landmarks, spec.deploy_bearings):
            if v == f:
                if at_f is not None:
                    lm.append(at_f)
                    br.append(b)
            elif v in occ and v not in moving and self.roster.live(occ[v]):
                lm.append(occ[v])
                br.append(b)
        return lm, br

    # ------------------------------------------------------------------ tasks
    def goto(self, v: int, lm: list[int], br: list[float]) -> Task:
        """The goto task to vertex v on the landmark robots ``lm`` at v's recorded bearings
        ``br`` (their chained frame offsets, the configured timeout)."""
        return Task(kind="goto", vertex=v, landmarks=lm, bearings=br,
                    ref_offsets=self.chained_offsets(v, lm), timeout_s=self.cfg.task_timeout_s)

    def test_drive(self, spec: JobSpec, moving: set[int] = frozenset()) -> Task:
        """The test drive at f (a probe's approach first; a wall sweep's fields when
        ``spec.sweep_far``, its landmarks off the ``moving`` vertices; the landmarks it
        keeps in sight, ``sight``, off them too, and only when nobody refills f: two
        pushes side by side saw each other's robot all the way out and ended cut off from
        the swarm, corridor_doors seed 2)."""
        f = spec.path[-1]
        # home back on robots that stay put: another push's robots move meanwhile, and
        # homing on one that moved pulled the robot off its vertex (corridor_doors seed 2:
        # 0.52 m, then "lost landmarks", and 17 robots beyond it cut off from the source)
        static, br = self.vertex_landmarks(f, exclude=set(moving))
        lm = static
        if len(static) < 2:
            lm, br = self.vertex_landmarks(f, exclude=set())
        # f left empty (the push starts at f itself, a redundant robot): the new robot must
        # see f's neighbours. Otherwise the robot that refills f sees it (a clear drive
        # from f ends less than rv from it, along a free line), and keeping f's neighbours
        # in sight would stop drives along a corridor short.
        left_empty = len(spec.path) == 1 and spec.enter_source is None
        task = Task(kind="test_drive", vertex=f, landmarks=lm, bearings=br,
                    sight=list(static) if left_empty else [],
                    ref_offsets=self.chained_offsets(f, lm),
                    direction=spec.direction,
                    distance=td_length(spec, self.params),
                    keep_after=self.cfg.wall_keep,
                    timeout_s=self.cfg.task_timeout_s)
        if spec.kind == "probe":
            # a probe's touch anywhere within its depth is evidence (the ends' disks cover
            # the way there): it goes home rather than stay against the wall (keep_after 0)
            task.keep_after = 0.0
        if spec.via_frac > 0:
            # a probe: first to the point at via_frac of the edge, on landmarks that stay
            # put (the push's movers wait for the test drive)
            occ = self.snap.occupant
            for v, b in zip(spec.via_landmarks, spec.via_bearings):
                r = occ.get(v)
                if r is not None and self.roster.live(r) and r in lm:
                    task.via_landmarks.append(r)
                    task.via_bearings.append(b)
            task.via_distance = spec.via_frac * self.cfg.d0
        if spec.sweep_far > 0:
            self._sweep_fields(task, spec, moving)
        return task

    def _sweep_fields(self, task: Task, spec: JobSpec, moving: set[int]) -> None:
        """A wall sweep's fields (bus.messages.Task): its landmarks are the live robots of
        the vertices whose place in f's frame the bearings fix (``spec.sweep_points``) and
        that no other push moves, the other end first, at d0 metres per edge length (the
        coordinator's estimate of it: only the depth limit depends on it, the lines a sweep
        ends on are ratios). Twice the task timeout: the sweep's two halves may each take
        up to the agent's sweep_budget_rv."""
        occ = self.snap.occupant
        q = spec.frontier_edge[1] if spec.frontier_edge[0] == spec.path[-1] else spec.frontier_edge[0]
        order = [q] + sorted(v for v in spec.sweep_points if v != q)
        for v in order:
            r = occ.get(v)
            if r is not None and v not in moving and self.roster.live(r):
                x, y = spec.sweep_points[v]
                task.sweep_landmarks.append(r)
                task.sweep_points += [x * self.cfg.d0, y * self.cfg.d0]
        if not task.sweep_landmarks or task.sweep_landmarks[0] != occ.get(q):
            task.sweep_landmarks, task.sweep_points = [], []
            return                         # no other end in view: a plain test drive
        task.sweep_side = spec.sweep_side            # +1 / -1, set by the planner
        task.sweep_edge = spec.sweep_edge
        task.sweep_far = spec.sweep_far
        task.sweep_stop = spec.sweep_stop
        task.sweep_depth = spec.distance if spec.distance is not None else self.params.d_td
        task.timeout_s = 2.0 * self.cfg.task_timeout_s
        if not self.params.sweep_lenses:
            return
        # the first drive goes on while it is in the lenses at f (the sweep's room test,
        # agents.sweep.SweepGeom.held: a touch there is swept, not taken for room), at most d0
        task.sweep_lenses = True
        pts = task.sweep_points
        lenses = lens_radii((pts[0], pts[1]), task.sweep_depth,
                            [(pts[k], pts[k + 1]) for k in range(2, len(pts), 2)])
        task.distance = max(task.distance, lens_reach(task.direction, lenses, cap=self.cfg.d0))

    def deploy(self, spec: JobSpec, moving: set[int]) -> Task:
        """Frontier robot to the new position (spec 4.4): homing on the static landmarks of
        the assumed geometry if there are >= 2, else open loop along the deployment
        direction (spec 4.6), keeping the single landmark in sight."""
        f = spec.path[-1]
        lm, br = self._static_landmarks(spec, moving)
        dist = ((self.cfg.d0 if spec.distance is None else spec.distance)
                - (td_length(spec, self.params) if spec.test_drive else 0.0))
        task = Task(kind="deploy", vertex=spec.new_vertex, landmarks=lm, bearings=br,
                    direction=spec.direction, distance=max(0.0, dist),
                    timeout_s=self.cfg.task_timeout_s)
        if len(lm) >= 2:
            task.ref_offsets = self.chained_offsets(f, lm)
        return task

    def refine(self, spec: JobSpec, moving: set[int], at_f: int | None) -> Task | None:
        """The deployed robot re-homes on every landmark of the assumed geometry now that a
        robot holds f again (``at_f``, None if none arrived; equilateral on |fj|, spec 4.4),
        with scale correction when due. None with fewer than 2 landmarks."""
        f = spec.path[-1]
        lm, br = self._static_landmarks(spec, moving, at_f)
        if len(lm) < 2:
            return None
        return Task(kind="deploy", vertex=spec.new_vertex, landmarks=lm, bearings=br,
                    ref_offsets=self.chained_offsets(f, lm),
                    scale_correct=spec.scale_correct or len(lm) == 2,
                    timeout_s=self.cfg.task_timeout_s)

    def settle(self, rid: int, v: int, busy: set[int], holder: dict[int, int]) -> Task | None:
        """goto v on the robots holding v's neighbour vertices now (``holder``: vertex ->
        robot; None if < 2), leaving out the ``busy`` vertices other unfinished pushes are
        still moving."""
        lm, br = self.vertex_landmarks(v, busy, holder, skip=rid)
        if len(lm) < 2:
            return None
        return self.goto(v, lm, br)

    def move(self, path: list[int], t: int, moving: set[int], ahead: int | None,
             holder: dict[int, int] | None = None,
             beyond: tuple[int, float] | None = None) -> Task | None:
        """Task for the robot moving p_t -> p_{t+1} (t = -1: the new robot entering p0).

        Landmarks: the robots holding the target's neighbour vertices, but for the
        ``moving`` ones (``holder``: vertex -> the robot there now; None: the snapshot's
        occupants); plus ``ahead``, the robot now at p_{t+2} once it has arrived
        (sequential fallback). The bearings are the target's recorded ones; ``beyond`` (the
        robot a test drive placed out from the target, its bearing from there) is the one
        landmark when none of those is left (with one of them, it cost robots: small seed 0,
        27 -> 37). Returns None when no landmark at all is available.
        """
        target = path[t + 1]
        lm, br = self.vertex_landmarks(target, moving, holder)
        if ahead is not None and t + 2 < len(path) and ahead not in lm:
            b = self.snap.nbrs.get(target, {}).get(path[t + 2])
            if b is not None:
                lm.append(ahead)
                br.append(b)
        if beyond is not None and not lm:
            lm.append(beyond[0])
            br.append(beyond[1])
        if not lm:
            return None
        task = self.goto(target, lm, br)
        # direction hint: the target vertex as seen from the mover's vertex; the agent
        # creeps along it while fewer than 2 landmarks are in view (spec 4.6)
        src = path[t] if t >= 0 else None
        d = self.snap.nbrs.get(src, {}).get(target) if src is not None else None
        if d is not None:
            task.direction = d
            task.distance = self.cfg.d0
        return task

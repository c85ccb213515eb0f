"""Running the cycle's push jobs (spec 4.3): start steps, end them from statuses, retry, cancel.

:class:`Pushes` holds the cycle's :class:`coordinator.jobs.PushJob` s and advances them at
each deployer step. No I/O and no clock of its own: it is told the sim time ``now``
(seconds), sends tasks and asks for robots through an :class:`coordinator.actions.Outbox`,
reads the :class:`coordinator.roster.Roster`, books occupancy in the
:class:`coordinator.placement.Placement` and drive outcomes in the
:class:`coordinator.topology.evidence.Evidence`, and builds tasks with a
:class:`coordinator.tasks.TaskBuilder` on the cycle's snapshot.
"""
from __future__ import annotations

import logging

from swarmcover.bus.messages import Status, Task, parse_sweep_reason, sweep_stoppers

from .actions import Outbox
from .config import CoordinatorConfig, PushMode
from .jobs import (FINISHED, OVER, PushJob, Step, StepName, StepState, drive_failures,
                   evidence_kwargs, make_job)
from .placement import Placement
from .planner import JobSpec, Snapshot, carryable, more_free_probes, replan_push
from .roster import Roster
from .tasks import TaskBuilder, td_length
from .topology.evidence import Evidence

log = logging.getLogger("swarmcover.coordinator")

_PROBE_RETRIES = 12   # drives one push may make within a cycle while its probes touch

S, N = StepState, StepName


class Pushes:
    """The push jobs of the current cycle and their collaborators (all explicit)."""

    def __init__(self, cfg: CoordinatorConfig, params, roster: Roster, placement: Placement,
                 evidence: Evidence, out: Outbox):
        self.cfg = cfg
        self.params = params
        self.roster = roster
        self.placement = placement
        self.evidence = evidence
        self.out = out
        self.jobs: list[PushJob] = []
        self.cycle = 0                   # the deployment cycle (for the log)
        self.retried = 0                 # pushes re-planned within their cycle
        self.done_s: dict[str, list[float]] = {}   # step name -> [steps done, their sim s]
        self._snapshot: Snapshot | None = None
        self.tasks: TaskBuilder | None = None
        self._rolled: tuple[int, int] = (-1, -1)   # (cycle, jobs over) last rolled at
        self._carry_at: tuple = (None, False)      # (cycle, probes out), may all stay out

    @property
    def snapshot(self) -> Snapshot | None:
        """The cycle's snapshot: what the pushes were planned on."""
        return self._snapshot

    @snapshot.setter
    def snapshot(self, snap: Snapshot | None) -> None:
        # the task builders read the snapshot as it is taken (its robot -> vertex map too)
        self._snapshot = snap
        self.tasks = None if snap is None else TaskBuilder(self.cfg, self.params,
                                                            self.roster, snap)

    # ------------------------------------------------------------------ statuses
    def is_test_drive(self, rid: int, task_id: int) -> bool:
        """Whether ``task_id`` is the test drive of a push in flight (it still is when the
        status reporting its failure arrives: that status is what ends the step)."""
        return any(s.name == N.TEST_DRIVE and s.robot == rid and s.task_id == task_id
                   for j in self.jobs for s in j.steps)

    def track(self, rid: int, st: Status) -> None:
        """End the running step that robot ``rid``'s status reports done or failed."""
        for job in self.jobs:
            for s in job.steps:
                if s.robot == rid and s.task_id == st.task_id and s.state == S.RUNNING:
                    if st.task_state == "done":
                        s.state, s.reason = S.DONE, st.reason
                        n_t = self.done_s.setdefault(str(s.name), [0, 0.0])
                        n_t[0] += 1
                        n_t[1] += max(0.0, st.t - s.started_t)
                        self._step_done(job, s)
                    elif st.task_state == "failed":
                        s.state, s.reason = S.FAILED, st.reason
                        s.touch_offset = st.touch_offset
                        self._step_done(job, s)

    def mean_done_s(self, name: str) -> float:
        """Mean simulated s from start to report of the steps ``name`` done so far (0:
        none yet)."""
        n, t = self.done_s.get(str(name), (0, 0.0))
        return t / n if n else 0.0

    def robot_died(self, rid: int) -> None:
        """Abort every push with a step of robot ``rid`` to do; its running step failed."""
        for job in self.jobs:
            if any(s.robot == rid and s.state in (S.PENDING, S.RUNNING) for s in job.steps):
                job.aborted = True
                for s in job.steps:
                    if s.robot == rid and s.state == S.RUNNING:
                        s.state, s.reason = S.FAILED, "robot died"

    @property
    def finished(self) -> bool:
        return all(j.finished for j in self.jobs)

    def carried(self, plan=None) -> list[PushJob] | None:
        """The free probes that go on into the next cycle (``free_probes_carry``) once every
        push of the cycle is over: the unfinished ones, when each may stay out
        (:func:`coordinator.planner.carryable` on ``plan``, the cycle's CyclePlan; without
        one, each may). None: the cycle still waits (a push runs, a probe may not stay
        out, or the cycle has free probes alone, whose next plan would find them out)."""
        if not (self.cfg.free_probes and self.cfg.free_probes_carry):
            return None
        pushes = [j for j in self.jobs if not j.spec.free]
        if not pushes or not all(j.finished for j in pushes):
            return None
        out = [j for j in self.jobs if not j.finished]
        if out and plan is not None and self.snapshot is not None:
            # asked every step while the cycle waits: the search runs once per set out
            key = (self.cycle, tuple(id(j) for j in out))
            if self._carry_at[0] != key:
                ok = carryable(plan.edges, self.snapshot.sources, plan.open_vertices,
                               [j.spec.path[-1] for j in out])
                self._carry_at = (key, all(j.spec.path[-1] in ok for j in out))
            if not self._carry_at[1]:
                return None
        return out

    def out_robots(self, jobs: list[PushJob] | None) -> set[int]:
        """The robots of ``jobs`` (free probes) with a step still to do."""
        return {s.robot for j in jobs or () for s in j.to_do() if s.robot >= 0}

    # ------------------------------------------------------------------ advance
    def _moving(self) -> set[int]:
        """Vertices on the path of a push not aborted (their occupants are moving)."""
        out = set()
        for j in self.jobs:
            if not j.aborted:
                out.update(j.spec.path)
        return out

    def advance(self, job: PushJob, now: float) -> None:
        """Start every step of a push whose preconditions hold (spec 4.3).

        Order: test drive at f (by default a clear drive of d0 places the new robot, and
        deploy and refine are skipped; a touch past wall_keep_rv leaves it at the wall);
        otherwise deploy f's robot (open loop, or homing when >= 2 static landmarks);
        movers from the front (p_{m-1} -> f first), each at once in parallel mode when its
        target has >= 2 static landmarks, else when the robot ahead arrived; a new robot
        enters p0 from the base; finally (refine_deploy, or a test drive shorter than d0)
        the deployed robot refines its position with every landmark, including the robot
        now at f (and scale correction); once every step is over, movers that homed on
        fewer than two landmarks settle on all of them (``settle_moves``).
        """
        spec = job.spec
        path = spec.path
        for s in job.steps:
            if s.state == S.RUNNING:
                self._check_timeout(s, now)
        if job.aborted:
            for s in job.steps:
                if s.state == S.PENDING:
                    s.state = S.CANCELLED
            return
        # a secondary job at a shared source moves with the robot the previous one brought
        # in (or, when that job stopped before its robot left p0, with that robot). Its
        # test drive, at its own frontier vertex, runs at once (``pipeline``): small map,
        # seeds 0-8, 310 -> 277 robots and 5,497 -> 4,186 s simulated. Its movers still
        # wait: starting them too (robots homing while the source is refilled behind them)
        # made tiny's seeds 0-8 cost 113 -> 124 robots.
        first = job.steps_at_source()
        if first is not None and first.robot < 0:
            rid = job.source_robot()
            if rid is False:
                job.cancel("source feed failed")
                return
            if rid is None and (len(path) == 1 or not self.cfg.pipeline):
                return
            first.robot = -1 if rid is None else rid
            if len(path) == 1:  # that robot itself deploys (and refines)
                for s in job.steps:
                    if s.name in (N.TEST_DRIVE, N.DEPLOY, N.REFINE):
                        s.robot = rid
        td = job.step(N.TEST_DRIVE)
        dep = job.step(N.DEPLOY)
        if td is not None:
            if td.state == S.PENDING:
                # a wall sweep homes on robots that stay put: not on other pushes' paths
                others = {v for j in self.jobs if j is not job and not j.aborted
                          for v in (*j.spec.path, j.spec.new_vertex)}
                self.start(td, self.tasks.test_drive(spec, others), now)
                return
            if td.state == S.RUNNING:
                return
            if td.state == S.FAILED:
                if not job.aborted:
                    self._test_drive_failed(job, td)
                return
            if spec.free:
                self._free_probe_home(job, td, now)
                return
            placed = self._placed_by(td, spec)
            if placed and dep.state == S.PENDING:
                # the robot is the new vertex where its drive ended: no deploy, no refine
                self._record(spec, touched=False, placed=spec.new_vertex)
                if placed != "wall" and spec.via_frac <= 0:
                    # a clear drive from f: the new vertex is as far from f as it drove
                    self.placement.known.append(
                        (path[-1], spec.new_vertex, td.distance or td_length(spec, self.params)))
                dep.state, dep.reason = S.DONE, placed
                self._step_done(job, dep)
                ref = job.step(N.REFINE)
                if ref is not None and ref.state == S.PENDING:
                    ref.state, ref.reason = S.CANCELLED, placed
        if first is not None and first.robot < 0:
            return   # the rest waits for p0's robot, which the source's earlier push brings
        if dep.state == S.PENDING:
            self.start(dep, self.tasks.deploy(spec, self._moving()), now)
        sequential = self.cfg.push_mode == PushMode.SEQUENTIAL
        prev = dep  # the step ahead of the current mover
        for t in range(len(path) - 2, -1, -1):
            mv = job.step(N.MOVE, t)
            if mv.state == S.PENDING:
                ahead_done = prev.state in OVER
                ahead_started = prev.state != S.PENDING
                task = self._task_move(job, t, arrived=ahead_done)
                static_ok = task is not None and len(task.landmarks) >= 2
                if ahead_done or (not sequential and ahead_started and static_ok):
                    if task is None:
                        log.warning("cycle %d: robot %d to vertex %d: no landmark of it in "
                                    "place: booked there without moving", self.cycle,
                                    mv.robot, path[t + 1])
                        task = Task(kind="hold", vertex=path[t + 1])
                    self.start(mv, task, now)
                else:
                    break
            prev = mv
        ent = job.step(N.ENTER)
        # the step that brings a robot to f: the mover p_{m-1} -> f (not the last mover
        # visited above, which is p0 -> p1), or the entering robot on a one-vertex path
        at_f = job.step(N.MOVE, len(path) - 2) if len(path) >= 2 else prev
        if ent is not None:
            if ent.state == S.PENDING and prev.state != S.PENDING:
                self._advance_enter(job, ent, prev, sequential, now)
            if len(path) == 1:
                at_f = ent
        ref = job.step(N.REFINE)
        if ref.state == S.PENDING and dep.state in OVER and at_f.state in FINISHED:
            at = at_f.robot if at_f.state == S.DONE and at_f.robot >= 0 else None
            task = self.tasks.refine(spec, self._moving(), at)
            if task is None:
                ref.state = S.CANCELLED
            else:
                self.start(ref, task, now)
        if self.cfg.settle_moves:
            self._settle_moves(job, now)

    def _task_move(self, job: PushJob, t: int, arrived: bool) -> Task | None:
        """The task of the robot moving p_t -> p_{t+1} (t = -1: entering p0); ``arrived``:
        the robot ahead is there, a landmark too.

        Its landmarks are the robots holding the target's neighbour vertices now, but for
        the vertices still in motion (:meth:`_in_motion`). A vertex a push has finished
        with counts, held by the robot that moved there: before, every vertex on a path of
        this cycle was left out until the cycle ended. With pushes streaming from the
        source, that left the source's own neighbours out: robots entered it homing on one
        bearing (structured seed 0: 19 of 161 entries), and the source vertex drifted
        0.2-0.4 m from where robots are placed."""
        path = job.spec.path
        mover = job.step(N.MOVE, t + 1) if arrived and t + 2 < len(path) else None
        holder = self.placement.holders(self.roster)
        return self.tasks.move(path, t, self._in_motion(holder),
                               None if mover is None else mover.robot, holder=holder,
                               beyond=self._beyond(job) if t >= 0 and t + 2 == len(path) else None)

    def _beyond(self, job: PushJob) -> tuple[int, float] | None:
        """(robot, its bearing from f in f's frame, rad) of the robot the push's test drive
        placed straight out from f (a clear drive or one kept at a wall, not a probe's or a
        sweep's): a landmark of f for the robot that moves there, at the drive's direction
        (not for a robot entering a source vertex: it starts there; homing on that one
        bearing drew entering robots off the source, small seed 0 27 -> 35 robots).
        None otherwise. Without it, f's only neighbour being the mover's own vertex left
        the mover no landmark at all: it was booked at f without moving (bench/unseen.py
        seed 0 map 8: a vertex in a 0.30 m door, its new robot beyond the door then cut off
        from every source, sent away, and a false certificate over the door)."""
        spec, dep = job.spec, job.step(N.DEPLOY)
        td = job.step(N.TEST_DRIVE)
        if (td is None or dep is None or dep.state != S.DONE or spec.via_frac > 0
                or spec.sweep_far > 0 or not self.roster.live(td.robot)
                or dep.reason not in ("wall", "placed by the test drive")):
            return None
        return td.robot, float(spec.direction)

    def _in_motion(self, holder: dict[int, int]) -> set[int]:
        """Vertices whose robot is not a landmark now (``holder``: vertex -> robot): a
        step to do fills them, or their robot has a step to do (it will leave, drive out or
        re-home), or a step that moves a robot ended there failed (the robot is somewhere
        near, not known where). An aborted push's pending steps never start."""
        held = {r: v for v, r in holder.items()}
        out: set[int] = set()
        for j in self.jobs:
            failed = [o for o in j.steps if o.state == S.FAILED and o.name != N.TEST_DRIVE]
            for o in j.to_do() + failed:
                out.add(o.target)
                if o.robot in held:
                    out.add(held[o.robot])
        return out

    def _free_probe_home(self, job: PushJob, td: Step, now: float) -> None:
        """A free probe that drove clear (no path: nobody would refill its vertex) goes back
        home on its vertex's landmarks, as after a touch; its probe is booked as returned
        (evidence.returned_probes): no evidence, the side stays open, and it is not offered
        free again. The deploy and refine steps never run."""
        if job.step(N.HOME) is not None:
            return
        spec = job.spec
        f = spec.path[-1]
        if spec.deployment is not None:
            self.evidence.record(spec.deployment, False, direction=float(spec.direction),
                                 returned=True)
        for s in job.steps:
            if s.state == S.PENDING:
                s.state, s.reason = S.CANCELLED, "free probe goes home"
        home = Step(N.HOME, td.robot, f)
        job.steps.append(home)
        lm, br = self.tasks.vertex_landmarks(f, exclude=set())   # f's neighbours: never td.robot
        task = self.tasks.goto(f, lm, br)
        log.info("cycle %d: free probe from vertex %d at %.2f of %s found room: back home",
                 self.cycle, f, spec.via_frac, spec.frontier_edge)
        self.start(home, task, now)

    def _settle_moves(self, job: PushJob, now: float) -> None:
        """Once a push is over, every robot that moved to its vertex on fewer than two
        landmarks, and is still there, homes again on all of that vertex's landmarks, now
        static.

        One bearing fixes a ray, not a point: a mover whose other landmarks were moving
        (the source being refilled behind it, the robot ahead on the path) stops wherever
        it first meets that ray, and the vertex drifts from where the graph has it."""
        if job.aborted or any(s.state in (S.PENDING, S.RUNNING) for s in job.steps
                              if s.name != N.SETTLE):
            return
        for s in list(job.steps):
            if (s.name in (N.MOVE, N.ENTER) and s.state == S.DONE and 0 <= s.n_landmarks < 2
                    and job.step(N.SETTLE, s.t_index) is None and self.roster.live(s.robot)
                    and self.placement.vertex_of.get(s.robot) == s.target
                    and not self._claimed_elsewhere(job, s.robot)):
                st = Step(N.SETTLE, s.robot, s.target, t_index=s.t_index)
                job.steps.append(st)
                busy: set[int] = set()   # what other unfinished pushes are still moving
                for j in self.jobs:
                    if j is not job and not j.aborted and not j.finished:
                        busy.update(j.spec.path)
                        busy.add(j.spec.new_vertex)
                task = self.tasks.settle(s.robot, s.target, busy,
                                         self.placement.holders(self.roster))
                if task is None:
                    st.state, st.reason = S.CANCELLED, "fewer than 2 landmarks"
                else:
                    self.start(st, task, now)

    def _claimed_elsewhere(self, job: PushJob, rid: int) -> bool:
        """Whether another push has robot ``rid`` to move: a step of it to do, or a push fed
        by ``job`` that will take it from the source (the robot ``job`` brought in). Such a
        robot is not settled: the agent runs one task at a time, so the other push's task
        would cut the settle short, and the settle step, never reported, held the cycle for
        its whole timeout (hall300 seed 1 with pipelining: 6 settles, 50 s each); sent
        second, the settle cut the move short and took the robot back to the source."""
        for j in self.jobs:
            if j is job:
                continue
            if any(o.robot == rid for o in j.to_do()):
                return True
            if j.aborted:
                continue
            first = j.steps_at_source()
            if (j.feed is job and first is not None and first.state == S.PENDING
                    and first.robot < 0 and j.source_robot() == rid):
                return True
        return False

    def _advance_enter(self, job: PushJob, ent: Step, prev: Step, sequential: bool,
                       now: float) -> None:
        path = job.spec.path
        ahead_done = prev.state in OVER
        if sequential and not ahead_done:
            return
        if ent.robot < 0:
            if self.roster.in_use() >= self.cfg.robots_max:
                ent.state, ent.reason = S.CANCELLED, "robots_max"
                log.warning("robots_max = %d reached: not refilling the source",
                            self.cfg.robots_max)
                return
            ent.robot = self.out.spawn(self.roster.spawn(job.spec.enter_source, now))
            ent.started_t = now
        r = self.roster.get(ent.robot)
        if r is None or r.status is None:
            if now - ent.started_t > self.cfg.spawn_timeout_s:
                ent.state, ent.reason = S.FAILED, "new robot never reported"
            return
        task = self._task_move(job, -1, arrived=ahead_done)
        if task is None or len(task.landmarks) < 2:
            if not ahead_done:
                return
        if task is None:
            task = Task(kind="hold", vertex=path[0])
        self.placement.vertex_of[ent.robot] = path[0]
        self.start(ent, task, now)

    def start(self, s: Step, task: Task, now: float) -> None:
        """Send step ``s``'s task: it runs from ``now``. A settle of the same robot still
        running ends here (the agent drops it for this task; it would never report)."""
        for j in self.jobs:
            for o in j.steps:
                if (o is not s and o.name == N.SETTLE and o.robot == s.robot
                        and o.state == S.RUNNING):
                    o.state, o.reason = S.CANCELLED, f"superseded by {s.name}"
        if task.kind in ("goto", "hold"):
            s.n_landmarks = len(task.landmarks)
        s.task_id = self.out.send(s.robot, task)
        s.state = S.RUNNING
        s.started_t = now
        s.timeout_s = task.timeout_s
        s.distance = task.distance

    def _check_timeout(self, s: Step, now: float) -> None:
        r = self.roster.get(s.robot)
        if r is None or r.dead:
            s.state, s.reason = S.FAILED, "robot died"
        elif now - s.started_t > max(self.cfg.task_timeout_s, s.timeout_s) + 10.0:
            s.state, s.reason = S.FAILED, "no report from the agent"

    def _step_done(self, job: PushJob, s: Step) -> None:
        """Book-keeping of occupancy when a step ends (done or failed: the robot is there
        or near; the next cycle's complex is rebuilt from observations anyway)."""
        if s.name == N.TEST_DRIVE:
            return
        if s.state == S.FAILED:
            log.info("cycle %d: %s of robot %d to vertex %d failed: %s", self.cycle, s.name,
                     s.robot, s.target, s.reason)
        self.placement.vertex_of[s.robot] = s.target
        if s.name == N.MOVE and s.t_index == 0 and job.spec.enter_source is None:
            # p0 was a redundant vertex: it is left empty
            self.placement.redundant.discard(job.spec.path[0])

    def _placed_by(self, td: Step, spec: JobSpec) -> str:
        """Why a finished test drive already placed the new robot, or "": it stopped at a
        wall past wall_keep_rv ("wall"), or it drove clear all the way to the position the
        planner chose (``spec.distance``) or to d0, and refine_deploy is off (a shorter
        drive goes on with the deploy and refine steps)."""
        if td.reason == "wall":
            return "wall"
        if self.cfg.refine_deploy:
            return ""
        if spec.distance is not None or self.params.d_td >= self.cfg.d0 - 1e-3 * self.cfg.rv:
            return "placed by the test drive"
        return ""

    def roll_free_probes(self, now: float) -> None:
        """Start free probes within the running cycle (``free_probes_rolling``): each time
        one of its jobs is over, while a push is still running, at the robots the fence
        still offers a probe to and that are off every push path, every probe still out and
        every robot that left its vertex, and next to none of them
        (:func:`coordinator.planner.more_free_probes`). A vertex probes free at most once a
        cycle. Nothing starts once the pushes are over: the cycle ends, and the next one
        plans its free probes afresh."""
        snap = self.snapshot
        if snap is None or not (self.cfg.free_probes and self.cfg.free_probes_rolling):
            return
        over = sum(1 for j in self.jobs if j.finished)
        if (self.cycle, over) == self._rolled:
            return
        self._rolled = (self.cycle, over)
        if over == 0 or all(j.finished or j.spec.free for j in self.jobs):
            return
        out = [j for j in self.jobs if j.spec.free and not j.finished]
        room = self.cfg.free_max - len(out)
        if room <= 0:
            return
        pl = self.placement
        movers = set(snap.sources)
        for j in self.jobs:
            if not (j.spec.free and j.finished):
                movers.update(j.spec.path)
        movers |= {v for v, rid in snap.occupant.items()
                   if not self.roster.live(rid) or rid in pl.left or pl.vertex_of.get(rid) != v}
        specs = more_free_probes(
            snap, self.params, movers=movers,
            skip={j.spec.path[-1] for j in self.jobs if j.spec.free},
            test_drive_failures=drive_failures(self.evidence, snap), new_vertex=pl.next_vertex,
            max_n=room,
            evidence=evidence_kwargs(self.evidence, snap, self.placement.cut_off),
            returned=self.evidence.returned_probes(snap.occupant))
        for spec in specs:
            pl.next_vertex += 1
            self.jobs.append(make_job(spec, snap.occupant))
            log.info("cycle %d: free probe from vertex %d within the cycle (%s)", self.cycle,
                     spec.path[-1], spec.frontier_edge)

    # ------------------------------------------------------------------ touches
    def _test_drive_failed(self, job: PushJob, td: Step) -> None:
        spec = job.spec
        if td.reason.startswith("via"):
            # a probe that never reached its point on the edge: no evidence either way; it
            # is tried again, and given up (reported as inferred) after evidence's limit
            n = self.evidence.record_unreached(spec.deployment) if spec.deployment else 0
            log.info("cycle %d: probe from vertex %d at %.2f of %s did not reach the edge "
                     "(%s, %d times)", self.cycle, spec.path[-1], spec.via_frac,
                     spec.frontier_edge, td.reason, n)
        swept = parse_sweep_reason(td.reason)
        if td.reason.startswith("touch") or swept is not None:
            # the direction driven is what failed: the fence blocks deployments near it. The
            # contact was felt where the robot touched, up to wall_keep_rv out, not at the
            # vertex (a door jamb felt "above" is ahead and to the side): on_status keeps it
            # in td_contacts, never as a wall the robot at the vertex rests against. A wall
            # sweep ("swept HI LO") also books the part of the edge it joined
            self._record(spec, touched=True, contact_offset=td.touch_offset, swept=swept,
                         by=self._stopper_places(sweep_stoppers(td.reason)))
            log.info("cycle %d: test drive from vertex %d touched an obstacle (%s): fence "
                     "side of %s", self.cycle, spec.path[-1], td.reason, spec.frontier_edge)
            if "(return" not in td.reason and self._retry(job):
                return
        job.cancel("test drive touched an obstacle")

    def _stopper_places(self, robots: tuple[int, ...]) -> dict[int, int | None]:
        """A sweep's stoppers -> the vertex each holds standing still now (None: it is
        moving, or holds none): only a robot standing at a place of the fixed graph vouches
        for the space in front of the side (Evidence.stopper_vertices)."""
        holder = self.placement.holders(self.roster)
        moving = self._in_motion(holder)
        out = {}
        for r in robots:
            v = self.placement.vertex_of.get(int(r))
            out[int(r)] = v if v is not None and holder.get(v) == r and v not in moving else None
        return out

    def _record(self, spec, touched: bool, contact_offset: float = 0.0,
                swept: tuple[float, float] | None = None, placed: int | None = None,
                by=()) -> None:
        """Book a drive's outcome (coordinator.topology.evidence): the direction actually
        driven, for a touch the agent's touch_offset (sector centre - direction), for a
        wall sweep the (hi, lo) it joined and the robots seen where a touch stopped it."""
        dep = spec.deployment
        if dep is None:
            if touched:
                self.evidence.add_failed_direction(spec.path[-1], float(spec.direction))
            return
        self.evidence.record(dep, touched, direction=float(spec.direction),
                             contact_offset=contact_offset, swept=swept, placed=placed, by=by)

    def _retry(self, job: PushJob) -> bool:
        """Re-plan a push whose test drive touched, within this cycle (spec 3.4(iv): the
        next-best frontier). Nothing of it has moved: the drive came back to f before
        reporting. The new push starts where the old one did (a source feeds its pushes in
        order), avoids this cycle's other pushes and every robot no longer where the
        snapshot has it. False when retries are used up or nothing is left to push to."""
        probe = job.spec.kind == "probe"
        if (self.cfg.td_retries == 0 or (not probe and job.retries >= self.cfg.td_retries)
                or job.retries >= _PROBE_RETRIES):
            # a probe that touched moved nothing: the next one goes at once (up to a bound)
            return False
        snap = self.snapshot
        pl = self.placement
        busy = [j.spec for j in self.jobs if j is not job and (not j.aborted or any(
            s.state not in (S.PENDING, S.CANCELLED) for s in j.steps if s.name != N.TEST_DRIVE))]
        gone = {v for v, rid in snap.occupant.items()
                if not self.roster.live(rid) or rid in pl.left or pl.vertex_of.get(rid) != v}
        if job.spec.free:
            # a free probe keeps its vertex (nobody refills it): only its next probe
            gone |= set(snap.occupant) - {job.spec.path[0]}
        spec = replan_push(
            snap, self.params, start=job.spec.path[0], busy=busy, exclude=gone,
            test_drive_failures=drive_failures(self.evidence, snap),
            new_vertex=pl.next_vertex, scale_correct=job.spec.scale_correct,
            test_drive=True, lattice_spacing=self.cfg.d0 if self.cfg.lattice else None,
            evidence=evidence_kwargs(self.evidence, snap, self.placement.cut_off),
            skip_probes=(self.evidence.returned_probes(snap.occupant) if job.spec.free
                         else frozenset()),
            sweeps_last=self.cfg.sweeps_last and not job.spec.free)
        if spec is None or (job.spec.free and spec.kind != "probe"):
            return False
        if (not job.spec.free and spec.sweep_far > 0 and spec.path[-1] != job.spec.path[-1]
                and self.cfg.free_probes and self.cfg.sweeps_free):
            # the nearest sweep is at another vertex: it would run alone while the path
            # waits; free probes take it beside others (this cycle's, rolling, or the
            # next's). Offering only this end's sweeps instead (a filter in replan_push)
            # kept pushes sweeping there: every config seeds 0-2, +4.8% simulated time
            return False
        spec.free = job.spec.free
        pl.next_vertex += 1
        fresh = make_job(spec, snap.occupant)
        log.info("cycle %d: push re-planned after the touch: %s -> %s", self.cycle,
                 job.spec.path, spec.path)
        job.spec, job.steps = spec, fresh.steps
        job.retries += 1
        self.retried += 1
        if job.feed is not None:
            first = job.steps_at_source()
            if first is not None:
                first.robot = -1             # resolved again from the feed (source_robot)
        return True

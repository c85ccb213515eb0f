"""The deployment cycle (spec 4.1) as a pure state machine: events in, actions out.

No Zenoh and no clocks of its own: the process (coordinator/node.py) feeds it agent Status
messages, liveliness changes and the simulated time, and executes the actions it returns
(send a Task, spawn or remove a robot, publish the Complex). That keeps the logic testable
and makes a restarted coordinator rebuild its state from the agents' statuses alone.

Vertices (positions) are the complex's nodes; robots occupy them (spec 2.3). A push along a
path p0 -> ... -> pm = f moves the robot at f to a new vertex beyond the frontier and every
robot at p_t to p_{t+1}; if p0 is a source vertex a new robot enters from the base to p0
(spec 4.3). The covered graph never changes; only occupants move along it.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Callable

from bus.messages import Complex, Remove, Spawn, Status, Task

from ground.angles import wrap
from .actions import Action, Done, PublishComplex, RemoveRobot, SendTask, SpawnRobot
from .config import CoordinatorConfig
from .topology.evidence import Evidence
from .planner import CyclePlan, JobSpec, Snapshot, plan_cycle, replan_push

log = logging.getLogger("swarmcover.coordinator")


class Phase(StrEnum):
    """Where the deployment cycle is; each has one ``_phase_<name>`` method (the dispatch
    table :attr:`Deployer._phases`). A StrEnum: equal to its name as a string."""
    INIT = "init"          # who is there: resume from their statuses, or spawn the firsts
    FIRST = "first"        # the first robot at each source reports, then holds its vertex
    EXECUTE = "execute"    # the cycle's pushes and probes run until all robots settle
    SETTLE = "settle"      # wait settle_s and fresh statuses, then plan the next cycle
    FINAL = "final"        # redundant robots were sent away: re-certify once they are idle


def td_length(spec: JobSpec, params) -> float:
    """How far a job's test drive goes: the planner's distance, else the configured d_td."""
    return params.d_td if spec.distance is None else spec.distance


SETTLED_STATES = ("holding", "idle")
_PROBE_RETRIES = 12   # drives one push may make within a cycle while its probes touch


def _near_any(bearing: float, bearings, tol: float = 0.02) -> bool:
    """Whether ``bearing`` is within ``tol`` rad of one of ``bearings`` (a contact seen
    again: the agent keeps reporting a pinned contact)."""
    return any(abs(wrap(bearing - b)) < tol for b in bearings)


@dataclass
class Robot:
    rid: int
    kind: str = "holonomic"
    live: bool = False
    alive: bool = False          # liveliness token present
    status: Status | None = None
    status_cycle: int = -1       # cycle in which the last status arrived
    spawned_t: float = 0.0
    dead: bool = False
    gone_since: float | None = None  # sim time its liveliness token vanished


@dataclass
class Step:
    """One robot's task within a push job."""
    name: str                     # "test_drive", "deploy", "move", "enter", "refine", "settle"
    robot: int                    # -1 for "enter" until the new robot exists
    target: int                   # target vertex id
    t_index: int = -1             # for "move": index t of p_t -> p_{t+1}
    task_id: int = -1
    state: str = "pending"        # pending, running, done, failed, cancelled
    reason: str = ""
    started_t: float = 0.0
    n_landmarks: int = -1         # landmarks of the goto/hold task it was started with
    touch_offset: float = 0.0     # failed test drive: touch sector centre - direction (rad)


@dataclass
class PushJob:
    spec: JobSpec
    steps: list[Step] = field(default_factory=list)
    aborted: bool = False
    feed: "PushJob | None" = None   # earlier job at the same source: its new robot moves here
    retries: int = 0                # times its test drive touched and it was re-planned

    def steps_at_source(self) -> "Step | None":
        """The step that moves the robot away from p0 (deploy when the path is just p0)."""
        if len(self.spec.path) == 1:
            return self.step("test_drive") or self.step("deploy")
        return self.step("move", 0)

    def step(self, name: str, t_index: int = -1) -> Step | None:
        for s in self.steps:
            if s.name == name and s.t_index == t_index:
                return s
        return None

    @property
    def finished(self) -> bool:
        return all(s.state in ("done", "failed", "cancelled") for s in self.steps)


class Deployer:
    """Runs deployment cycles until the frontier is empty and coverage is certified."""

    def __init__(self, cfg: CoordinatorConfig, *, sources: list[float], epoch: int = 0,
                 robot_kind: Callable[[int], tuple[str, bool]] | None = None,
                 planner: Callable[..., CyclePlan] = plan_cycle, robot_radius: float = 0.06):
        """sources: heading (rad, world frame) of each base station, by source index.
        robot_radius: the robots' body radius (m), for the probe spacing (door_min_rv)."""
        self.cfg = cfg
        self.params = cfg.topology()
        self.sources = list(sources)
        self.epoch = epoch
        self.robot_kind = robot_kind or (lambda rid: ("holonomic", False))
        self.planner = planner
        self.robots: dict[int, Robot] = {}
        self.vertex_of: dict[int, int] = {}          # robot -> vertex
        self.known: list[tuple[int, int, float]] = []  # (f, new vertex, clear drive length)
        self.contact: dict[int, float] = {}          # vertex -> sticky contact bearing
        self.td_contacts: dict[int, list[float]] = {}  # vertex -> contacts of failed drives
        # every drive's outcome: failed directions by vertex, failed probes by edge
        self.evidence = Evidence(door_min_rv=cfg.door_min_rv, robot_radius_rv=robot_radius / cfg.rv)
        self.redundant: set[int] = set()             # vertices
        self.left: set[int] = set()                  # robots sent away (redundant, idle)
        self.next_robot = 0
        # agents up without a body (avail/robot/<id>: started by hand, any host), placed
        # before new robots are asked for; lowest id first
        self.available: set[int] = set()
        self.joined = 0                              # robots placed from self.available
        self.firsts: list[int] = []                  # the first robot at each source
        self.spawned: set[int] = set()               # ids this deployer asked bodies for
        self.next_vertex = len(self.sources)
        self.next_task = 1
        self.cycle = 0
        self.phase = Phase.INIT
        self._phases = {Phase.INIT: self._phase_init, Phase.FIRST: self._phase_first,
                        Phase.EXECUTE: self._phase_execute, Phase.SETTLE: self._phase_settle,
                        Phase.FINAL: self._phase_final}
        self.phase_t = 0.0
        self.jobs: list[PushJob] = []
        self.plan: CyclePlan | None = None
        self.snapshot: Snapshot | None = None
        self._snap_vertex_of: dict[int, int] = {}     # robot -> vertex in the snapshot
        self.cycle_end_t = 0.0
        self.failures = 0
        self.failures_healed = 0
        self.retried = 0                             # pushes re-planned within their cycle
        self._pending_failures = 0
        self.done = False
        self.certified = False
        self.stop_reason = ""
        self.final_pass = False
        self.uncertified_idle = 0
        self.no_push = 0                             # consecutive plans without a push
        self.pending_holds: dict[int, int] = {}      # new robot -> source vertex to hold
        self._out: list[Action] = []
        self.started = False

    # ------------------------------------------------------------------ events
    def on_available(self, rid: int, present: bool) -> None:
        """An agent with no body came (``present``) or went, or got its body. Until it is
        placed it is no robot of the swarm: its liveliness and statuses are not counted."""
        if not present:
            self.available.discard(rid)
            return
        r = self.robots.get(rid)
        if r is not None and (rid in self.vertex_of or rid in self.spawned or r.dead):
            return  # ours already: the token outlived the body's first Sense
        if r is not None:  # its alive token or first status came first
            del self.robots[rid]
        self.available.add(rid)
        self.next_robot = max(self.next_robot, rid + 1)
        log.info("robot %d is available (an agent without a body): %d waiting",
                 rid, len(self.available))

    def on_status(self, st: Status) -> None:
        if st.robot in self.available:
            return
        r = self.robots.get(st.robot)
        if r is None:
            kind, live = self.robot_kind(st.robot)
            r = self.robots[st.robot] = Robot(st.robot, kind=st.kind or kind, live=st.live)
            self.next_robot = max(self.next_robot, st.robot + 1)
        if r.dead:
            return
        if r.status is not None and st.seq < r.status.seq and st.t <= r.status.t:
            return  # stale
        r.status = st
        r.status_cycle = self.cycle
        r.alive = True
        r.gone_since = None
        if self.phase == Phase.INIT and st.vertex >= 0:
            # restart: adopt the agent's own idea of its vertex
            self.vertex_of.setdefault(st.robot, st.vertex)
            self.next_vertex = max(self.next_vertex, st.vertex + 1)
        if st.task_id >= 0:
            self.next_task = max(self.next_task, (st.task_id % 1_000_000) + 1)
        v = self.vertex_of.get(st.robot)
        if (v is not None and st.contact and st.task_state == "failed"
                and self._is_test_drive(st.robot, st.task_id)):
            # back from a test drive that touched: its contact is the drive's (the agent
            # pins it), felt out there, not a wall at the vertex. Recorded here, on the
            # first status that reports the failure: the job hears of it only later, and
            # this status used to be adopted as a resting contact first (corridor_doors,
            # eps_rv = 0.05: 46 of 53 adopted contacts were test-drive contacts, and a
            # door was closed by one, certified at 81% coverage)
            tdc = self.td_contacts.setdefault(v, [])
            if not _near_any(st.contact_bearing, tdc):
                tdc.append(st.contact_bearing)
        if (v is not None and st.contact and st.state == "holding"
                and st.vertex == v and st.task_state != "running"
                and not _near_any(st.contact_bearing, self.td_contacts.get(v, ()))):
            self.contact[v] = st.contact_bearing
        self._track_tasks(r)

    @property
    def td_failures(self) -> dict[int, list[float]]:
        """vertex -> directions of drives from it that touched (from ``evidence``)."""
        return self.evidence.failed_directions()

    def _evidence_kw(self, snap: Snapshot) -> dict:
        kw = self.evidence.fence_kwargs(snap.occupant)
        kw.pop("test_drive_failures")
        return kw

    def _is_test_drive(self, rid: int, task_id: int) -> bool:
        """Whether ``task_id`` is the test drive of a push in flight (it still is when the
        status reporting its failure arrives: that status is what ends the step)."""
        return any(s.name == "test_drive" and s.robot == rid and s.task_id == task_id
                   for j in self.jobs for s in j.steps)

    def on_alive(self, rid: int, present: bool, now: float) -> None:
        if rid in self.available:
            if not present:
                self.available.discard(rid)
            return
        r = self.robots.get(rid)
        if present:
            if r is None:
                kind, live = self.robot_kind(rid)
                r = self.robots[rid] = Robot(rid, kind=kind, live=live)
                self.next_robot = max(self.next_robot, rid + 1)
            if not r.dead:
                r.alive = True
                r.gone_since = None
            return
        if r is None or r.dead:
            return
        # not dead yet: a router restart or a network hiccup removes every token at once.
        # Death needs the token to stay gone for dead_grace_s of *simulated* time, and the
        # world's clock does not reach us while the router is down.
        r.alive = False
        if r.gone_since is None:
            r.gone_since = now

    def reopen_if_needed(self, now: float) -> bool:
        """After certification, a robot failure re-opens the cycles (its hole is refilled)."""
        if self.done and self.certified and self._pending_failures:
            log.info("a robot failed after certification: resuming deployment cycles")
            self.done = self.certified = False
            self.final_pass = False
            self._set_phase(Phase.SETTLE, now)
            return True
        return False

    # ------------------------------------------------------------------ main
    def step(self, now: float) -> list[Action]:
        """Advance the state machine at simulated time ``now``; return the actions to
        execute, in order (coordinator/actions.py)."""
        self._out = []
        if self.done:
            return self._out
        self._heartbeat(now)
        self._phases[self.phase](now)
        return self._out

    # ------------------------------------------------------------------ phases
    def _phase_init(self, now: float) -> None:
        if not self.started:
            self.started = True
            self.phase_t = now
            return
        # a restart: robots already alive (liveliness history) must all report first
        alive = [r for r in self.robots.values() if r.alive and not r.dead]
        known = [r for r in alive if r.status is not None]
        if alive and len(known) < len(alive) and now - self.phase_t < 5.0:
            return
        if known and now - self.phase_t >= 0.5:
            log.info("resuming with %d robots already deployed", len(known))
            for r in known:
                if r.rid not in self.vertex_of and r.status.vertex >= 0:
                    self.vertex_of[r.rid] = r.status.vertex
            self._set_phase(Phase.EXECUTE, now)  # wait for running tasks, then plan
            return
        if not known and now - self.phase_t >= 1.0:
            self.firsts = [self._spawn(k, now) for k in range(len(self.sources))]
            self._set_phase(Phase.FIRST, now)

    def _phase_first(self, now: float) -> None:
        """Wait until the first robot(s) report, then make them hold the source vertices."""
        firsts = [self.robots.get(rid) for rid in self.firsts]
        if all(r is not None and r.status is not None for r in firsts):
            for k, r in enumerate(firsts):
                self.vertex_of[r.rid] = k
                self._send(r.rid, Task(kind="hold", vertex=k, timeout_s=self.cfg.task_timeout_s), now)
            self._set_phase(Phase.EXECUTE, now)
        elif now - self.phase_t > self.cfg.spawn_timeout_s:
            self._stop(f"first robot never reported (is an agent started for robot "
                       f"{', '.join(map(str, self.firsts))}?)")

    def _phase_execute(self, now: float) -> None:
        for rid, k in list(self.pending_holds.items()):
            r = self.robots.get(rid)
            if r is None or r.dead:
                self.pending_holds.pop(rid)
            elif r.status is not None:
                self._send(rid, Task(kind="hold", vertex=k, timeout_s=self.cfg.task_timeout_s), now)
                self.pending_holds.pop(rid)
        for job in self.jobs:
            self._advance_job(job, now)
        if all(j.finished for j in self.jobs) and not self.pending_holds and self._all_settled():
            self.jobs = []
            self.cycle_end_t = now
            self._set_phase(Phase.SETTLE, now)

    def _phase_settle(self, now: float) -> None:
        if now - self.phase_t < self.cfg.settle_s:
            return
        members = self._members()
        fresh = all(self.robots[r].status.t >= self.phase_t for r in members)
        if not fresh and now - self.phase_t < self.cfg.settle_s + 5.0:
            return
        self._plan(now)

    def _phase_final(self, now: float) -> None:
        """Redundant robots were sent away; re-certify once they are idle."""
        if now - self.phase_t < self.cfg.settle_s:
            return
        if not self._all_settled():
            return
        self._plan(now)

    # ------------------------------------------------------------------ planning
    def _members(self) -> list[int]:
        """Robots in the complex: alive, holding a vertex, not sent away."""
        out = []
        for rid, v in self.vertex_of.items():
            r = self.robots.get(rid)
            if r is None or r.dead or not r.alive or r.status is None or rid in self.left:
                continue
            out.append(rid)
        return sorted(out)

    def build_snapshot(self) -> Snapshot:
        members = self._members()
        vert: dict[int, int] = {}
        taken: set[int] = set()
        for rid in members:
            v = self.vertex_of[rid]
            if v in taken:
                # two robots claim one vertex (a restart after an interrupted push): the
                # second one is a position of its own
                v = self.vertex_of[rid] = self.next_vertex
                self.next_vertex += 1
            taken.add(v)
            vert[rid] = v
        nbrs: dict[int, dict[int, float]] = {}
        back: dict[int, dict[int, float]] = {}
        for rid in members:
            st = self.robots[rid].status
            d = {}
            for n, b in zip(st.nbr_ids, st.nbr_bearings):
                if n in vert and n != rid:
                    d[vert[n]] = b
            nbrs[vert[rid]] = d
        occupant = {v: r for r, v in vert.items()}
        contact = {v: b for v, b in self.contact.items() if v in occupant}
        kinds = {v: self.robots[r].kind for v, r in occupant.items()}
        known = [(a, b, d) for a, b, d in self.known if a in occupant and b in occupant]
        return Snapshot(occupant=occupant, nbrs=nbrs, contact=contact, kinds=kinds,
                        sources=[k for k in range(len(self.sources)) if k in occupant],
                        source_dirs=self.sources, known=known)

    def _take_snapshot(self) -> Snapshot:
        snap = self.snapshot = self.build_snapshot()
        self._snap_vertex_of = {r: v for v, r in snap.occupant.items()}
        return snap

    def _strays(self, snap: Snapshot) -> set[int]:
        """Vertices in components of the (mutual-visibility) graph that hold no source: robots
        that lost the swarm (a failed move, a failure that cut the graph). No path can reach
        them, so their frontier could never close; they are sent away instead."""
        present = [k for k in range(len(self.sources)) if k in snap.occupant]
        if not present:
            return set()
        seen = set(present)
        stack = list(present)
        while stack:
            v = stack.pop()
            for u in snap.nbrs.get(v, {}):
                if u not in seen and v in snap.nbrs.get(u, {}):
                    seen.add(u)
                    stack.append(u)
        return set(snap.occupant) - seen

    def _plan(self, now: float) -> None:
        snap = self._take_snapshot()
        strays = self._strays(snap)
        if strays:
            for v in sorted(strays):
                rid = snap.occupant[v]
                self.left.add(rid)
                self._send(rid, Task(kind="leave", vertex=-1, timeout_s=self.cfg.task_timeout_s),
                           now)
            log.warning("cycle %d: robots %s are cut off from every source: sent away",
                        self.cycle, sorted(snap.occupant[v] for v in strays))
            snap = self._take_snapshot()
        run_redundancy = (self.cycle % max(1, self.cfg.redundancy_period) == 0)
        moving: set[int] = set()
        plan = self.plan = self.planner(
            snap, self.params, cycle=self.cycle, redundancy=run_redundancy or self.final_pass,
            test_drive_failures={v: b for v, b in self.td_failures.items() if v in snap.occupant},
            previous_redundant=self.redundant, protected=moving, max_paths=self.cfg.max_paths,
            scale_correct=(self.cfg.scale_correct_period > 0
                           and self.cycle % self.cfg.scale_correct_period == 0),
            test_drive=self.cfg.test_drive, next_vertex=self.next_vertex,
            lattice_spacing=self.cfg.d0 if self.cfg.lattice else None,
            evidence=self._evidence_kw(snap), free_probes=self.cfg.free_probes,
            returned_probes=self.evidence.returned_probes(snap.occupant))
        self.next_vertex += len(plan.jobs)
        self.redundant = set(plan.redundant)
        self._out.append(PublishComplex(self._complex_msg(plan, now, "running")))
        if self._pending_failures and plan.certified:
            self.failures_healed += self._pending_failures
            self._pending_failures = 0
        if not snap.occupant:
            # nobody to certify with (everyone was lost): a certificate would be vacuous
            if self._robots_in_use() < self.cfg.robots_max and not self.pending_holds:
                for k in range(len(self.sources)):
                    rid = self._spawn(k, now)
                    self.vertex_of[rid] = k
                    self.pending_holds[rid] = k
            self._set_phase(Phase.EXECUTE, now)
            return
        if not plan.frontier and not plan.open_vertices:
            if plan.certified:
                self._finish(plan, now)
                return
            self.uncertified_idle += 1
            log.warning("cycle %d: no frontier edge but coverage is not certified (%d hole "
                        "edges); re-planning", self.cycle, len(plan.hole_edges))
            if self.uncertified_idle > 5:
                self._stop("no frontier left but the certificate fails")
                return
        else:
            self.uncertified_idle = 0
        if self.cycle >= self.cfg.max_cycles:
            self._stop(f"max_cycles = {self.cfg.max_cycles} reached")
            return
        self.final_pass = False
        self.jobs = []
        feeds: dict[int, PushJob] = {}
        for spec in plan.jobs:
            job = self._make_job(spec)
            if spec.enter_source is not None:
                job.feed = feeds.get(spec.path[0])   # the source's previous job this cycle
                feeds[spec.path[0]] = job
                if job.feed is not None:
                    first = job.steps_at_source()
                    if first is not None:
                        first.robot = -1             # the robot that entered in job.feed
            self.jobs.append(job)
        missing = [k for k in range(len(self.sources)) if k not in snap.occupant]
        if missing and (plan.frontier or plan.open_vertices):
            # the robot at a base died, or a restart found nobody there: re-establish the
            # source vertex with a new robot from the base (paths start there)
            for k in missing:
                if self._robots_in_use() < self.cfg.robots_max:
                    rid = self._spawn(k, now)
                    self.vertex_of[rid] = k
                    log.info("cycle %d: source %d is empty: robot %d enters to hold it",
                             self.cycle, k, rid)
                    self.pending_holds[rid] = k
        if (plan.frontier or plan.open_vertices) and not self.jobs and not missing:
            self.no_push += 1
            log.warning("cycle %d: %d frontier edges but no feasible push (%d in a row)",
                        self.cycle, len(plan.frontier), self.no_push)
            if self.no_push >= 20:
                self._stop("no feasible push for 20 cycles (frontier unreachable from the "
                           "sources and redundant robots)")
                return
        else:
            self.no_push = 0
        self.cycle += 1
        self._set_phase(Phase.EXECUTE, now)

    def _finish(self, plan: CyclePlan, now: float) -> None:
        if self.cfg.final_recheck and plan.redundant:
            # spec 5.4: the redundant robots go idle, then the rest re-certify with another
            # redundancy pass; repeated until a pass finds none (each pass removes >= 1).
            # (The last pass's finds used to stay in the complex and count as used.)
            self.final_pass = True
            for v in sorted(plan.redundant):
                rid = self.snapshot.occupant.get(v)
                if rid is None:
                    continue
                self.left.add(rid)
                self._send(rid, Task(kind="leave", vertex=-1,
                                     timeout_s=self.cfg.task_timeout_s), now)
            self.redundant = set()
            self._set_phase(Phase.FINAL, now)
            return
        if self.cfg.final_recheck and not self.final_pass:
            self.final_pass = True
            self._set_phase(Phase.FINAL, now)
            return
        self.certified = True
        self.done = True
        self.stop_reason = "certified"
        self._out.append(PublishComplex(self._complex_msg(plan, now, "certified")))
        self._out.append(Done(True))

    def _stop(self, why: str) -> None:
        log.error("stopping: %s", why)
        self.done = True
        self.stop_reason = why
        if self.plan is not None:
            self._out.append(PublishComplex(self._complex_msg(self.plan, 0.0, "stopped")))
        self._out.append(Done(False))

    def _complex_msg(self, plan: CyclePlan, now: float, state: str) -> Complex:
        snap = self.snapshot
        verts = sorted(snap.occupant)
        return Complex(
            cycle=self.cycle, t=now, epoch=self.epoch, vertices=verts,
            occupants=[snap.occupant[v] for v in verts],
            edges=[int(x) for e in plan.edges for x in e],
            triangles=[int(x) for t in plan.triangles for x in t],
            frontier=list(plan.frontier), obstacle=list(plan.obstacle),
            redundant=sorted(plan.redundant), sources=list(snap.sources),
            certified=bool(plan.complete),
            robots=sum(1 for r in self.robots.values() if r.alive and not r.dead), state=state,
            failures_healed=self.failures_healed, reason=self.stop_reason[:200],
            inferred=[int(e) for e, _ in getattr(plan, "inferred", ())],
            inferred_why=[str(w) for _, w in getattr(plan, "inferred", ())],
            exceptions=[int(e) for e in getattr(plan, "exceptions", ())])

    # ------------------------------------------------------------------ jobs
    def _make_job(self, spec: JobSpec) -> PushJob:
        job = PushJob(spec)
        path = spec.path
        occ = self.snapshot.occupant
        f = path[-1]
        if spec.test_drive:
            job.steps.append(Step("test_drive", occ[f], f))
        job.steps.append(Step("deploy", occ[f], spec.new_vertex))
        for t in range(len(path) - 2, -1, -1):
            job.steps.append(Step("move", occ[path[t]], path[t + 1], t_index=t))
        if spec.enter_source is not None:
            job.steps.append(Step("enter", -1, path[0]))
        job.steps.append(Step("refine", occ[f], spec.new_vertex))
        return job

    def _moving_vertices(self) -> set[int]:
        out = set()
        for j in self.jobs:
            if not j.aborted:
                out.update(j.spec.path)
        return out

    def _advance_job(self, job: PushJob, now: float) -> None:
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
            if s.state == "running":
                self._check_timeout(s, now)
        if job.aborted:
            for s in job.steps:
                if s.state == "pending":
                    s.state = "cancelled"
            return
        # a secondary job at a shared source starts with the robot the previous one brought
        # in (or, when that job stopped before its robot left p0, with that robot). Starting
        # its test drive and front movers before then cost robots (small map, seeds 0-3,
        # with the old 90-deg failure cones: 36.3 against 32.3), robots running while the
        # source is refilled behind them.
        first = job.steps_at_source()
        if first is not None and first.robot < 0:
            rid = self._source_robot(job)
            if rid is False:
                self._cancel(job, "source feed failed")
                return
            if rid is None:
                return
            first.robot = rid
            if len(path) == 1:  # that robot itself deploys (and refines)
                for s in job.steps:
                    if s.name in ("test_drive", "deploy", "refine"):
                        s.robot = rid
        td = job.step("test_drive")
        dep = job.step("deploy")
        if td is not None:
            if td.state == "pending":
                self._start(td, self._task_test_drive(spec), now)
                return
            if td.state == "running":
                return
            if td.state == "failed":
                if not job.aborted:
                    self._test_drive_failed(job, td)
                return
            if spec.free:
                self._free_probe_home(job, td, now)
                return
            placed = self._placed_by(td, spec)
            if placed and dep.state == "pending":
                # the robot is the new vertex where its drive ended: no deploy, no refine
                self._record(spec, touched=False)
                if placed != "wall" and spec.via_frac <= 0:
                    # a clear drive from f: the new vertex is that far from f
                    self.known.append((path[-1], spec.new_vertex, td_length(spec, self.params)))
                dep.state, dep.reason = "done", placed
                self._step_done(job, dep)
                ref = job.step("refine")
                if ref is not None and ref.state == "pending":
                    ref.state, ref.reason = "cancelled", placed
        if dep.state == "pending":
            self._start(dep, self._task_deploy(spec, job), now)
        sequential = self.cfg.push_mode == "sequential"
        prev = dep  # the step ahead of the current mover
        for t in range(len(path) - 2, -1, -1):
            mv = job.step("move", t)
            if mv.state == "pending":
                ahead_done = prev.state in ("done", "failed")
                ahead_started = prev.state != "pending"
                task = self._task_move(job, t, arrived=ahead_done)
                static_ok = task is not None and len(task.landmarks) >= 2
                if ahead_done or (not sequential and ahead_started and static_ok):
                    if task is None:
                        task = Task(kind="hold", vertex=path[t + 1])
                    self._start(mv, task, now)
                else:
                    break
            prev = mv
        ent = job.step("enter")
        # the step that brings a robot to f: the mover p_{m-1} -> f (not the last mover
        # visited above, which is p0 -> p1), or the entering robot on a one-vertex path
        at_f = job.step("move", len(path) - 2) if len(path) >= 2 else prev
        if ent is not None:
            if ent.state == "pending" and prev.state != "pending":
                self._advance_enter(job, ent, prev, sequential, now)
            if len(path) == 1:
                at_f = ent
        ref = job.step("refine")
        if ref.state == "pending" and dep.state in ("done", "failed") and \
                at_f.state in ("done", "failed", "cancelled"):
            task = self._task_refine(spec, job, at_f)
            if task is None:
                ref.state = "cancelled"
            else:
                self._start(ref, task, now)
        if self.cfg.settle_moves:
            self._settle_moves(job, now)

    def _free_probe_home(self, job: PushJob, td: Step, now: float) -> None:
        """A free probe that drove clear (no path: nobody would refill its vertex) goes back
        home on its vertex's landmarks, as after a touch; its probe is booked as returned
        (evidence.returned_probes): no evidence, the side stays open, and it is not offered
        free again. The deploy and refine steps never run."""
        if job.step("home") is not None:
            return
        spec = job.spec
        f = spec.path[-1]
        if spec.deployment is not None:
            self.evidence.record(spec.deployment, False, direction=float(spec.direction),
                                 returned=True)
        for s in job.steps:
            if s.state == "pending":
                s.state, s.reason = "cancelled", "free probe goes home"
        home = Step("home", td.robot, f)
        job.steps.append(home)
        lm, br = self._vertex_landmarks(f, exclude=set())   # f's neighbours: never td.robot
        task = self._goto(f, lm, br)
        log.info("cycle %d: free probe from vertex %d at %.2f of %s found room: back home",
                 self.cycle, f, spec.via_frac, spec.frontier_edge)
        self._start(home, task, now)

    @staticmethod
    def _source_robot(job: PushJob):
        """The robot that leaves p0 in ``job`` (fed by an earlier job at the same source):
        its id, None while it is still entering, False if it never will.

        An earlier job that stopped before its own robot left p0 (a failed test drive: the
        robot drove back) hands that robot on, so one touch no longer cancels every later
        push from the source."""
        feed = job.feed
        while feed is not None:
            s0 = feed.steps_at_source()
            if feed.aborted and s0 is not None and (
                    s0.state in ("pending", "cancelled")
                    or (s0.name == "test_drive" and s0.state == "failed"
                        and s0.reason.startswith("touch"))):
                if s0.robot >= 0:
                    return s0.robot
                feed = feed.feed
                continue
            ent = feed.step("enter")
            if ent is None or feed.aborted or ent.state in ("failed", "cancelled"):
                return False
            return ent.robot if ent.state == "done" else None
        return False

    def _settle_moves(self, job: PushJob, now: float) -> None:
        """Once a push is over, every robot that moved to its vertex on fewer than two
        landmarks homes again on all of that vertex's landmarks, now static.

        One bearing fixes a ray, not a point: a mover whose other landmarks were moving
        (the source being refilled behind it, the robot ahead on the path) stops wherever
        it first meets that ray, and the vertex drifts from where the graph has it."""
        if job.aborted or any(s.state in ("pending", "running") for s in job.steps
                              if s.name != "settle"):
            return
        for s in list(job.steps):
            if (s.name in ("move", "enter") and s.state == "done" and 0 <= s.n_landmarks < 2
                    and job.step("settle", s.t_index) is None and self._live(s.robot)):
                st = Step("settle", s.robot, s.target, t_index=s.t_index)
                job.steps.append(st)
                task = self._task_settle(job, s.robot, s.target)
                if task is None:
                    st.state, st.reason = "cancelled", "fewer than 2 landmarks"
                else:
                    self._start(st, task, now)

    def _advance_enter(self, job: PushJob, ent: Step, prev: Step, sequential: bool,
                       now: float) -> None:
        path = job.spec.path
        ahead_done = prev.state in ("done", "failed")
        if sequential and not ahead_done:
            return
        if ent.robot < 0:
            if self._robots_in_use() >= self.cfg.robots_max:
                ent.state, ent.reason = "cancelled", "robots_max"
                log.warning("robots_max = %d reached: not refilling the source",
                            self.cfg.robots_max)
                return
            ent.robot = self._spawn(job.spec.enter_source, now)
            ent.started_t = now
        r = self.robots.get(ent.robot)
        if r is None or r.status is None:
            if now - ent.started_t > self.cfg.spawn_timeout_s:
                ent.state, ent.reason = "failed", "new robot never reported"
            return
        task = self._task_move(job, -1, arrived=ahead_done)
        if task is None or len(task.landmarks) < 2:
            if not ahead_done:
                return
        if task is None:
            task = Task(kind="hold", vertex=path[0])
        self.vertex_of[ent.robot] = path[0]
        self._start(ent, task, now)

    def _cancel(self, job: PushJob, why: str) -> None:
        job.aborted = True
        for s in job.steps:
            if s.state == "pending":
                s.state, s.reason = "cancelled", why

    def _start(self, s: Step, task: Task, now: float) -> None:
        if task.kind in ("goto", "hold"):
            s.n_landmarks = len(task.landmarks)
        s.task_id = self._send(s.robot, task, now)
        s.state = "running"
        s.started_t = now

    def _check_timeout(self, s: Step, now: float) -> None:
        r = self.robots.get(s.robot)
        if r is None or r.dead:
            s.state, s.reason = "failed", "robot died"
        elif now - s.started_t > self.cfg.task_timeout_s + 10.0:
            s.state, s.reason = "failed", "no report from the agent"

    def _track_tasks(self, r: Robot) -> None:
        st = r.status
        for job in self.jobs:
            for s in job.steps:
                if s.robot == r.rid and s.task_id == st.task_id and s.state == "running":
                    if st.task_state == "done":
                        s.state, s.reason = "done", st.reason
                        self._step_done(job, s)
                    elif st.task_state == "failed":
                        s.state, s.reason = "failed", st.reason
                        s.touch_offset = st.touch_offset
                        self._step_done(job, s)

    def _step_done(self, job: PushJob, s: Step) -> None:
        """Book-keeping of occupancy when a step ends (done or failed: the robot is there
        or near; the next cycle's complex is rebuilt from observations anyway)."""
        if s.name == "test_drive":
            return
        if s.state == "failed":
            log.info("cycle %d: %s of robot %d to vertex %d failed: %s", self.cycle, s.name,
                     s.robot, s.target, s.reason)
        self.vertex_of[s.robot] = s.target
        if s.name == "move" and s.t_index == 0 and job.spec.enter_source is None:
            # p0 was a redundant vertex: it is left empty
            self.redundant.discard(job.spec.path[0])

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

    def _test_drive_failed(self, job: PushJob, td: Step) -> None:
        spec = job.spec
        if td.reason.startswith("via"):
            # a probe that never reached its point on the edge: no evidence either way; it
            # is tried again, and given up (reported as inferred) after evidence's limit
            n = self.evidence.record_unreached(spec.deployment) if spec.deployment else 0
            log.info("cycle %d: probe from vertex %d at %.2f of %s did not reach the edge "
                     "(%s, %d times)", self.cycle, spec.path[-1], spec.via_frac,
                     spec.frontier_edge, td.reason, n)
        if td.reason.startswith("touch"):
            # the direction driven is what failed: the fence blocks deployments near it. The
            # contact was felt where the robot touched, up to wall_keep_rv out, not at the
            # vertex (a door jamb felt "above" is ahead and to the side): on_status keeps it
            # in td_contacts, never as a wall the robot at the vertex rests against
            self._record(spec, touched=True, contact_offset=td.touch_offset)
            log.info("cycle %d: test drive from vertex %d touched an obstacle: fence side "
                     "of %s -> O", self.cycle, spec.path[-1], spec.frontier_edge)
            if td.reason == "touch" and self._retry(job):
                return
        self._cancel(job, "test drive touched an obstacle")

    def _record(self, spec, touched: bool, contact_offset: float = 0.0) -> None:
        """Book a drive's outcome (coordinator.topology.evidence): the direction actually
        driven, and for a touch the agent's touch_offset (sector centre - direction)."""
        dep = spec.deployment
        if dep is None:
            if touched:
                self.evidence.add_failed_direction(spec.path[-1], float(spec.direction))
            return
        self.evidence.record(dep, touched, direction=float(spec.direction),
                             contact_offset=contact_offset)

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
        busy = [j.spec for j in self.jobs if j is not job and (not j.aborted or any(
            s.state not in ("pending", "cancelled") for s in j.steps if s.name != "test_drive"))]
        gone = {v for v, rid in snap.occupant.items()
                if not self._live(rid) or rid in self.left or self.vertex_of.get(rid) != v}
        if job.spec.free:
            # a free probe keeps its vertex (nobody refills it): only its next probe
            gone |= set(snap.occupant) - {job.spec.path[0]}
        spec = replan_push(
            snap, self.params, start=job.spec.path[0], busy=busy, exclude=gone,
            test_drive_failures={v: b for v, b in self.td_failures.items() if v in snap.occupant},
            new_vertex=self.next_vertex, scale_correct=job.spec.scale_correct,
            test_drive=True, lattice_spacing=self.cfg.d0 if self.cfg.lattice else None,
            evidence=self._evidence_kw(snap),
            skip_probes=(self.evidence.returned_probes(snap.occupant) if job.spec.free
                         else frozenset()))
        if spec is None or (job.spec.free and spec.kind != "probe"):
            return False
        spec.free = job.spec.free
        self.next_vertex += 1
        fresh = self._make_job(spec)
        log.info("cycle %d: push re-planned after the touch: %s -> %s", self.cycle,
                 job.spec.path, spec.path)
        job.spec, job.steps = spec, fresh.steps
        job.retries += 1
        self.retried += 1
        if job.feed is not None:
            first = job.steps_at_source()
            if first is not None:
                first.robot = -1             # resolved again from the feed (_source_robot)
        return True

    # ------------------------------------------------------------------ tasks
    def _ref_offsets(self, recorder_vertex: int, landmark_vertices: list[int]) -> list[float]:
        """Frame alignment data (spec 4.7): heading of the recorder minus each landmark's
        heading, from mutual bearings. [] when every robot is holonomic (frames parallel)."""
        snap = self.snapshot
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

    def _task_test_drive(self, spec: JobSpec) -> Task:
        f = spec.path[-1]
        lm, br = self._vertex_landmarks(f, exclude=set())
        task = Task(kind="test_drive", vertex=f, landmarks=lm, bearings=br,
                    ref_offsets=self._chained_offsets(f, lm),
                    direction=spec.direction,
                    distance=td_length(spec, self.params),
                    keep_after=self.cfg.wall_keep_rv * self.cfg.rv,
                    timeout_s=self.cfg.task_timeout_s)
        if spec.kind == "probe":
            # a probe's touch anywhere within its depth is evidence (the ends' disks cover
            # the way there): it goes home rather than stay against the wall (keep_after 0)
            task.keep_after = 0.0
        if spec.via_frac > 0:
            # a probe: first to the point at via_frac of the edge, on landmarks that stay
            # put (the push's movers wait for the test drive)
            occ = self.snapshot.occupant
            for v, b in zip(spec.via_landmarks, spec.via_bearings):
                r = occ.get(v)
                if r is not None and self._live(r) and r in lm:
                    task.via_landmarks.append(r)
                    task.via_bearings.append(b)
            task.via_distance = spec.via_frac * self.cfg.d0
        return task

    def _live(self, rid: int) -> bool:
        r = self.robots.get(rid)
        return r is not None and not r.dead

    def _snap_vertex(self, rid: int) -> int:
        """The vertex robot ``rid`` held in this cycle's snapshot (-1 if none)."""
        return self._snap_vertex_of.get(rid, -1)

    def _static(self, v: int) -> bool:
        """Vertex v's occupant stays put this cycle (not on any path, not a new position)."""
        return v not in self._moving_vertices()

    def _task_deploy(self, spec: JobSpec, job: PushJob) -> Task:
        """Frontier robot to the new position (spec 4.4): homing on the static landmarks of
        the assumed geometry if there are >= 2, else open loop along the deployment
        direction (spec 4.6), keeping the single landmark in sight."""
        occ = self.snapshot.occupant
        f = spec.path[-1]
        lm, br = [], []
        for v, b in zip(spec.deploy_landmarks, spec.deploy_bearings):
            if v != f and v in occ and self._static(v) and self._live(occ[v]):
                lm.append(occ[v])
                br.append(b)
        dist = ((self.cfg.d0 if spec.distance is None else spec.distance)
                - (td_length(spec, self.params) if spec.test_drive else 0.0))
        task = Task(kind="deploy", vertex=spec.new_vertex, landmarks=lm, bearings=br,
                    direction=spec.direction, distance=max(0.0, dist),
                    timeout_s=self.cfg.task_timeout_s)
        if len(lm) >= 2:
            task.ref_offsets = self._chained_offsets(f, lm)
        return task

    def _task_refine(self, spec: JobSpec, job: PushJob, at_f: Step) -> Task | None:
        """The deployed robot re-homes on every landmark of the assumed geometry now that a
        robot holds f again (equilateral on |fj|, spec 4.4), with scale correction when due."""
        occ = self.snapshot.occupant
        f = spec.path[-1]
        lm, br = [], []
        for v, b in zip(spec.deploy_landmarks, spec.deploy_bearings):
            if v == f:
                if at_f.state == "done" and at_f.robot >= 0:
                    lm.append(at_f.robot)
                    br.append(b)
            elif v in occ and self._static(v) and self._live(occ[v]):
                lm.append(occ[v])
                br.append(b)
        if len(lm) < 2:
            return None
        return Task(kind="deploy", vertex=spec.new_vertex, landmarks=lm, bearings=br,
                    ref_offsets=self._chained_offsets(f, lm),
                    scale_correct=spec.scale_correct or len(lm) == 2,
                    timeout_s=self.cfg.task_timeout_s)

    def _mutual(self, a: int, b: int):
        """heading(a) - heading(b) from the robots' current Status (mutual bearings), or None."""
        ra, rb = self.robots.get(a), self.robots.get(b)
        if ra is None or rb is None or ra.status is None or rb.status is None:
            return None
        sa = dict(zip(ra.status.nbr_ids, ra.status.nbr_bearings))
        sb = dict(zip(rb.status.nbr_ids, rb.status.nbr_bearings))
        if b not in sa or a not in sb:
            return None
        return wrap(sb[a] - sa[b] + math.pi)

    def _chained_offsets(self, f: int, lm: list[int]) -> list[float]:
        """ref_offsets for bearings recorded by f's occupant in the snapshot (spec 4.7).
        Landmarks that held a neighbour vertex of f then: from the snapshot's mutual
        bearings; a robot that moved there since (the one now holding f, or the robot
        ahead on a push): chained through a static landmark and the robots' current Status.
        [] when every robot is holonomic, or when some landmark cannot be aligned."""
        snap = self.snapshot
        if all(k == "holonomic" for k in snap.kinds.values()):
            return []
        static = {}
        for r in lm:
            u = self._snap_vertex(r)
            if u >= 0 and u != f:
                o = self._ref_offsets(f, [u])
                if o:
                    static[r] = o[0]
        out = []
        for r in lm:
            if r in static:
                out.append(static[r])
                continue
            got = None
            for s, o in static.items():
                m = self._mutual(s, r)
                if m is not None:
                    got = wrap(o + m)
                    break
            if got is None:
                return []
            out.append(got)
        return out

    def _task_settle(self, job: PushJob, rid: int, v: int) -> Task | None:
        """goto v on the robots holding v's neighbour vertices now (None if < 2), leaving
        out the vertices other unfinished pushes are still moving."""
        busy: set[int] = set()
        for j in self.jobs:
            if j is not job and not j.aborted and not j.finished:
                busy.update(j.spec.path)
                busy.add(j.spec.new_vertex)
        holder = {u: r for r, u in self.vertex_of.items() if self._live(r)}
        lm, br = [], []
        for u, b in sorted(self.snapshot.nbrs.get(v, {}).items()):
            r = holder.get(u)
            if u in busy or r is None or r == rid:
                continue
            lm.append(r)
            br.append(b)
        if len(lm) < 2:
            return None
        return self._goto(v, lm, br)

    def _goto(self, v: int, lm: list[int], br: list[float]) -> Task:
        """The goto task to vertex v on the landmark robots ``lm`` at v's recorded bearings
        ``br`` (their chained frame offsets, the configured timeout)."""
        return Task(kind="goto", vertex=v, landmarks=lm, bearings=br,
                    ref_offsets=self._chained_offsets(v, lm), timeout_s=self.cfg.task_timeout_s)

    def _vertex_landmarks(self, v: int, exclude: set[int]) -> tuple[list[int], list[float]]:
        """Occupants of v's neighbour vertices (minus ``exclude``) and v's recorded bearings."""
        snap = self.snapshot
        lm, br = [], []
        for u, b in sorted(snap.nbrs.get(v, {}).items()):
            if u in exclude or u not in snap.occupant or not self._live(snap.occupant[u]):
                continue
            lm.append(snap.occupant[u])
            br.append(b)
        return lm, br

    def _task_move(self, job: PushJob, t: int, arrived: bool) -> Task | None:
        """Task for the robot moving p_t -> p_{t+1} (t = -1: the new robot entering p0).

        Landmarks: occupants of the target's neighbours that are not moving this cycle;
        plus, once it has arrived, the robot now at p_{t+2} (sequential fallback).
        Returns None when no landmark at all is available (the mover then just holds).
        """
        path = job.spec.path
        target = path[t + 1]
        moving = self._moving_vertices()
        for j in self.jobs:
            moving.add(j.spec.new_vertex)
        lm, br = self._vertex_landmarks(target, exclude=moving)
        if arrived and t + 2 < len(path):
            ahead = path[t + 2]
            b = self.snapshot.nbrs.get(target, {}).get(ahead)
            mover = job.step("move", t + 1) if t + 1 <= len(path) - 2 else None
            rid = mover.robot if mover is not None else None
            if b is not None and rid is not None:
                lm.append(rid)
                br.append(b)
        if not lm:
            return None
        task = self._goto(target, lm, br)
        # direction hint: the target vertex as seen from the mover's vertex; the agent
        # creeps along it while fewer than 2 landmarks are in view (spec 4.6)
        src = path[t] if t >= 0 else None
        d = self.snapshot.nbrs.get(src, {}).get(target) if src is not None else None
        if d is not None:
            task.direction = d
            task.distance = self.cfg.d0
        return task

    # ------------------------------------------------------------------ helpers
    def _send(self, rid: int, task: Task, now: float) -> int:
        task.task_id = self.epoch * 1_000_000 + self.next_task
        self.next_task += 1
        task.robot = rid
        task.epoch = self.epoch
        self._out.append(SendTask(rid, task))
        return task.task_id

    def _spawn(self, source: int, now: float) -> int:
        """A new robot at ``source``: an available agent if there is one (lowest id), else
        a new id for ``run`` to start an agent under."""
        if self.available:
            rid = min(self.available)
            self.available.discard(rid)
            self.joined += 1
            log.info("placing available robot %d at source %d (%d more waiting)", rid, source,
                     len(self.available))
        else:
            rid = self.next_robot
            while rid in self.robots:
                rid += 1
            self.next_robot = rid + 1
        self.spawned.add(rid)
        kind, live = self.robot_kind(rid)
        self.robots[rid] = Robot(rid, kind=kind, live=live, spawned_t=now)
        self._out.append(SpawnRobot(Spawn(robot=rid, source=source, kind=kind, live=live)))
        return rid

    def _robots_in_use(self) -> int:
        return sum(1 for r in self.robots.values() if not r.dead)

    def _robot_died(self, r: Robot, now: float, why: str) -> None:
        log.warning("robot %d failed (%s): dropping it; its hole becomes frontier", r.rid, why)
        r.dead = True
        r.alive = False
        self.failures += 1
        self._pending_failures += 1
        v = self.vertex_of.pop(r.rid, None)
        if v is not None:
            self.contact.pop(v, None)
        self._out.append(RemoveRobot(Remove(robot=r.rid, reason=why)))
        for job in self.jobs:
            if any(s.robot == r.rid and s.state in ("pending", "running") for s in job.steps):
                job.aborted = True
                for s in job.steps:
                    if s.robot == r.rid and s.state == "running":
                        s.state, s.reason = "failed", "robot died"

    def _heartbeat(self, now: float) -> None:
        """Spec 6 [P]: a robot whose token has been gone for dead_grace_s (sim), or with no
        status for dead_after_cycles cycles, is dead."""
        for r in list(self.robots.values()):
            if (not r.dead and r.gone_since is not None
                    and now - r.gone_since >= self.cfg.dead_grace_s):
                self._robot_died(r, now, "liveliness token gone")
        if self.phase != Phase.SETTLE:
            return
        for r in list(self.robots.values()):
            if (r.alive and not r.dead and r.rid in self.vertex_of
                    and self.cycle - r.status_cycle >= self.cfg.dead_after_cycles):
                self._robot_died(r, now, f"no status for {self.cfg.dead_after_cycles} cycles")

    def _all_settled(self) -> bool:
        for rid in self._members():
            st = self.robots[rid].status
            if st.task_state == "running" or st.state not in SETTLED_STATES:
                return False
        return True

    def _set_phase(self, phase: Phase, now: float) -> None:
        self.phase = phase
        self.phase_t = now

    # ------------------------------------------------------------------ report
    def summary(self) -> dict:
        alive = [r for r in self.robots.values() if not r.dead]
        return dict(certified=self.certified, cycles=self.cycle,
                    robots_spawned=len(self.robots), robots_alive=len(alive),
                    robots_in_complex=len(self._members()), robots_left=len(self.left),
                    failures=self.failures, failures_healed=self.failures_healed,
                    test_drive_retries=self.retried, robots_joined=self.joined,
                    robots_available=len(self.available),
                    stop_reason=self.stop_reason)

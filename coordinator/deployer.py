"""The deployment cycle (spec 4.1) as a pure state machine: events in, actions out.

No Zenoh and no clocks of its own: the process (coordinator/node.py) feeds it agent Status
messages, liveliness changes and the simulated time (seconds), and executes the actions it
returns (send a Task, spawn or remove a robot, publish the Complex). That keeps the logic
testable and makes a restarted coordinator rebuild its state from the agents' statuses alone.

Vertices (positions) are the complex's nodes; robots occupy them (spec 2.3). A push along a
path p0 -> ... -> pm = f moves the robot at f to a new vertex beyond the frontier and every
robot at p_t to p_{t+1}; if p0 is a source vertex a new robot enters from the base to p0
(spec 4.3). The covered graph never changes; only occupants move along it.

:class:`Deployer` is the facade: the phases of the cycle, planning, the complex published,
the summary. Its collaborators, each in its own module: :class:`~coordinator.roster.Roster`
(who is alive), :class:`~coordinator.placement.Placement` (who holds which vertex),
:class:`~coordinator.pushes.Pushes` (the cycle's push jobs, coordinator.jobs; their tasks
from coordinator.tasks), :class:`~coordinator.topology.evidence.Evidence` (drive outcomes)
and :class:`~coordinator.actions.Outbox` (the actions of a step).
"""
from __future__ import annotations

import logging
from enum import StrEnum
from typing import Callable

from swarmcover.bus.messages import Complex, Remove, Status, Task

from .actions import Action, Done, Outbox, PublishComplex, RemoveRobot
from .config import CoordinatorConfig
from .jobs import (PushJob, Step, StepName, StepState, drive_failures, evidence_kwargs,
                   lone_room_holders, make_job)
from .placement import SETTLED_STATES, Placement, stray_vertices
from .planner import CyclePlan, Snapshot, plan_cycle
from .pushes import Pushes
from .roster import Robot, Roster
from .tasks import td_length
from .topology.evidence import Evidence

log = logging.getLogger("swarmcover.coordinator")

__all__ = ["Deployer", "Phase", "PushJob", "Robot", "SETTLED_STATES", "Step", "StepName",
           "StepState", "td_length"]


class Phase(StrEnum):
    """Where the deployment cycle is; each has one ``_phase_<name>`` method (the dispatch
    table :attr:`Deployer._phases`). A StrEnum: equal to its name as a string."""
    INIT = "init"          # who is there: resume from their statuses, or spawn the firsts
    FIRST = "first"        # the first robot at each source reports, then holds its vertex
    EXECUTE = "execute"    # the cycle's pushes and probes run until all robots settle
    SETTLE = "settle"      # wait settle_s and fresh statuses, then plan the next cycle
    FINAL = "final"        # redundant robots were sent away: re-certify once they are idle


def _via(part: str, name: str, doc: str | None = None) -> property:
    """An attribute of the deployer kept by its collaborator ``part`` (read and write)."""
    return property(lambda self: getattr(getattr(self, part), name),
                    lambda self, value: setattr(getattr(self, part), name, value), doc=doc)


class Deployer:
    """Runs deployment cycles until the frontier is empty and coverage is certified."""

    robots = _via("roster", "robots", "robot id -> Robot")
    available = _via("roster", "available", "agents up without a body, not yet placed")
    joined = _via("roster", "joined", "robots placed from ``available``")
    spawned = _via("roster", "spawned", "ids this deployer asked bodies for")
    next_robot = _via("roster", "next_robot")
    robot_kind = _via("roster", "robot_kind")
    vertex_of = _via("placement", "vertex_of", "robot -> vertex")
    next_vertex = _via("placement", "next_vertex")
    known = _via("placement", "known", "(f, new vertex, clear drive length)")
    contact = _via("placement", "contact", "vertex -> sticky contact bearing")
    td_contacts = _via("placement", "td_contacts", "vertex -> contacts of failed drives")
    redundant = _via("placement", "redundant", "redundant vertices")
    left = _via("placement", "left", "robots sent away (redundant, idle)")
    jobs = _via("pushes", "jobs", "the cycle's push jobs")
    snapshot = _via("pushes", "snapshot", "the snapshot the cycle was planned on")
    retried = _via("pushes", "retried", "pushes re-planned within their cycle")
    cycle = _via("pushes", "cycle", "deployment cycles planned")
    next_task = _via("out", "next_task")
    epoch = _via("out", "epoch", "this coordinator's epoch (the high part of its task ids)")

    def __init__(self, cfg: CoordinatorConfig, *, sources: list[float], epoch: int = 0,
                 robot_kind: Callable[[int], tuple[str, bool]] | None = None,
                 planner: Callable[..., CyclePlan] = plan_cycle, robot_radius: float = 0.06):
        """sources: heading (rad, world frame) of each base station, by source index.
        robot_radius: the robots' body radius (m), for the probe spacing (door_min_rv)."""
        self.cfg = cfg
        self.params = cfg.topology()
        self.sources = list(sources)
        self.planner = planner
        self.roster = Roster(robot_kind)
        self.placement = Placement(len(self.sources))
        # every drive's outcome: failed directions by vertex, failed probes by edge
        self.evidence = Evidence(door_min_rv=cfg.door_min_rv, robot_radius_rv=robot_radius / cfg.rv)
        self.out = Outbox(epoch)
        self.pushes = Pushes(cfg, self.params, self.roster, self.placement, self.evidence,
                             self.out)
        self.firsts: list[int] = []                  # the first robot at each source
        self.phase = Phase.INIT
        self._phases = {Phase.INIT: self._phase_init, Phase.FIRST: self._phase_first,
                        Phase.EXECUTE: self._phase_execute, Phase.SETTLE: self._phase_settle,
                        Phase.FINAL: self._phase_final}
        self.phase_t = 0.0
        self.plan: CyclePlan | None = None
        self.cycle_end_t = 0.0
        self.failures = 0
        self.failures_healed = 0
        self._pending_failures = 0
        self.done = False
        self.certified = False
        self.stop_reason = ""
        self.final_pass = False
        self.uncertified_idle = 0
        self._cut_off_logged: tuple | None = None   # the cut-off triangle last warned of
        self.no_push = 0                             # consecutive plans without a push
        self.stray_plans: dict[int, int] = {}        # robot -> plans in a row it was cut off
        self.pending_holds: dict[int, int] = {}      # new robot -> source vertex to hold
        self.started = False

    # ------------------------------------------------------------------ events
    def on_available(self, rid: int, present: bool) -> None:
        """An agent with no body came (``present``) or went, or got its body. Until it is
        placed it is no robot of the swarm: its liveliness and statuses are not counted."""
        self.roster.on_available(rid, present, placed=self.vertex_of)

    def on_status(self, st: Status) -> None:
        r = self.roster.admit(st, self.cycle)
        if r is None:
            return
        if self.phase == Phase.INIT and st.vertex >= 0:
            # restart: adopt the agent's own idea of its vertex
            self.vertex_of.setdefault(st.robot, st.vertex)
            self.next_vertex = max(self.next_vertex, st.vertex + 1)
        if st.task_id >= 0:
            self.next_task = max(self.next_task, (st.task_id % 1_000_000) + 1)
        v = self.vertex_of.get(st.robot)
        if v is not None and st.contact:
            self.placement.note_contact(v, st, td_failed=(
                st.task_state == "failed" and self.pushes.is_test_drive(st.robot, st.task_id)))
        self.pushes.track(r.rid, st)

    @property
    def td_failures(self) -> dict[int, list[float]]:
        """vertex -> directions of drives from it that touched (from ``evidence``)."""
        return self.evidence.failed_directions()

    def on_alive(self, rid: int, present: bool, now: float) -> None:
        """A liveliness token came or went; death waits dead_grace_s (see _heartbeat)."""
        self.roster.on_alive(rid, present, now)

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
        if not self.done:
            self._heartbeat(now)
            self._phases[self.phase](now)
        # what was asked between steps (reopen_if_needed's status request) goes out too
        actions, self.out.actions = self.out.actions, []
        return actions

    # ------------------------------------------------------------------ phases
    def _phase_init(self, now: float) -> None:
        if not self.started:
            self.started = True
            self.phase_t = now
            self.out.request_status()   # a restart: robots already deployed report at once
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
                self.out.send(r.rid, Task(kind="hold", vertex=k, timeout_s=self.cfg.task_timeout_s))
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
                self.out.send(rid, Task(kind="hold", vertex=k, timeout_s=self.cfg.task_timeout_s))
                self.pending_holds.pop(rid)
        for job in self.jobs:
            self.pushes.advance(job, now)
        self.pushes.roll_free_probes(now)
        carried = self.pushes.carried(self.plan)
        if ((self.pushes.finished or carried is not None) and not self.pending_holds
                and self.placement.all_settled(self.roster,
                                               skip=self.pushes.out_robots(carried))):
            self.jobs = carried or []
            self.cycle_end_t = now
            self._set_phase(Phase.SETTLE, now)

    def _phase_settle(self, now: float) -> None:
        if now - self.phase_t < self.cfg.settle_s:
            return
        members = self.placement.members(self.roster)
        fresh = all(self.robots[r].status.t >= self.phase_t for r in members)
        if not fresh and now - self.phase_t < self.cfg.settle_s + 5.0:
            return
        # statuses were asked for when the phase began (a lockstep world senses an idle
        # robot only now and then): a robot silent for cycles has not answered that either
        for r in self.roster.silent(self.cycle, self.cfg.dead_after_cycles, self.vertex_of):
            self._robot_died(r, now, f"no status for {self.cfg.dead_after_cycles} cycles")
        self._plan(now)

    def _phase_final(self, now: float) -> None:
        """Redundant robots were sent away; re-certify once they are idle."""
        if now - self.phase_t < self.cfg.settle_s:
            return
        if not self.placement.all_settled(self.roster):
            return
        self._plan(now)

    # ------------------------------------------------------------------ planning
    def build_snapshot(self) -> Snapshot:
        """The complex as its members see it now (coordinator.placement)."""
        return self.placement.snapshot(self.roster, self.sources)

    def _take_snapshot(self) -> Snapshot:
        prev, snap = self.snapshot, self.build_snapshot()
        if prev is not None:
            self._keep_out_edges(prev, snap)
        self.snapshot = snap
        return snap

    def _out_vertices(self) -> set[int]:
        """Vertices whose robots are out on free probes carried from the last cycle."""
        return {j.spec.path[-1] for j in self.jobs if j.spec.free and not j.finished}

    def _keep_out_edges(self, prev: Snapshot, snap: Snapshot) -> None:
        """A robot out on a carried free probe comes back to its vertex, homing on the
        neighbours it saw there, which hold still until it is back (no path may use them):
        ``snap`` keeps that vertex's edges as ``prev`` had them, in both directions, not as
        the robot sees them from where it is now."""
        for f in self._out_vertices():
            rid = prev.occupant.get(f)
            if rid is None or snap.occupant.get(f) != rid:
                continue
            snap.nbrs[f] = {u: b for u, b in prev.nbrs.get(f, {}).items()
                            if snap.occupant.get(u) == prev.occupant.get(u)}
            for v, nb in snap.nbrs.items():
                if v == f:
                    continue
                nb.pop(f, None)
                if f in prev.nbrs.get(v, {}) and snap.occupant.get(v) == prev.occupant.get(v):
                    nb[f] = prev.nbrs[v][f]

    def _strays(self, snap: Snapshot) -> set[int]:
        """Vertices cut off from every source (coordinator.placement.stray_vertices)."""
        return stray_vertices(snap, len(self.sources))

    def _plan(self, now: float) -> None:
        carried = [j for j in self.jobs if not j.finished]
        out = self._out_vertices()
        for rid, v in self.placement.rejoin(self.roster, self.sources):
            # a robot cut off stands in free space the complex did not hold: seen again,
            # it is a vertex of it again (and the sides it stopped sweeps at are no longer
            # kept from closing, tests/test_sweep.py)
            log.info("cycle %d: robot %d, cut off, is linked again: it holds vertex %d",
                     self.cycle, rid, v)
            self.out.send(rid, Task(kind="hold", vertex=v, timeout_s=self.cfg.task_timeout_s))
        snap = self._take_snapshot()
        strays = self._strays(snap)
        # cut off for stray_cycles plans in a row: a failed or stalled move that cut the
        # graph is a hole the next pushes refill, which links them again. Sent away at once,
        # the robots beyond a door stood in the free space the complex no longer held
        # (bench/unseen.py seed 0 map 8: one stalled move at the door cut 14 robots off)
        now_stray = {snap.occupant[v] for v in strays}
        self.stray_plans = {r: self.stray_plans.get(r, 0) + 1 for r in now_stray}
        strays = {v for v in strays
                  if self.stray_plans[snap.occupant[v]] >= self.cfg.stray_cycles}
        waiting = len(now_stray) - len(strays)        # cut off, still members
        if strays:
            for v in sorted(strays):
                rid = snap.occupant[v]
                self.stray_plans.pop(rid, None)
                self.left.add(rid)
                self.placement.cut_off.add(rid)
                self.out.send(rid, Task(kind="leave", vertex=-1,
                                        timeout_s=self.cfg.task_timeout_s))
            log.warning("cycle %d: robots %s are cut off from every source: sent away",
                        self.cycle, sorted(snap.occupant[v] for v in strays))
            snap = self._take_snapshot()
        run_redundancy = (self.cycle % max(1, self.cfg.redundancy_period) == 0)
        evidence = evidence_kwargs(self.evidence, snap, self.placement.cut_off)
        plan = self.plan = self.planner(
            snap, self.params, cycle=self.cycle,
            redundancy=(run_redundancy or self.final_pass) and not out,
            test_drive_failures=drive_failures(self.evidence, snap),
            previous_redundant=self.redundant, protected=set(), max_paths=self.cfg.max_paths,
            scale_correct=(self.cfg.scale_correct_period > 0
                           and self.cycle % self.cfg.scale_correct_period == 0),
            test_drive=self.cfg.test_drive, next_vertex=self.next_vertex,
            lattice_spacing=self.cfg.d0 if self.cfg.lattice else None,
            evidence=evidence, free_probes=self.cfg.free_probes,
            returned_probes=self.evidence.returned_probes(snap.occupant),
            sweeps_last=self.cfg.sweeps_last, out=frozenset(out),
            sweeps_free=self.cfg.sweeps_free, free_max=self.cfg.free_max)
        self.next_vertex += len(plan.jobs)
        self.evidence.ask_sweeps(plan.sweep_first)
        self.redundant = set(plan.redundant)
        if carried or waiting:
            # nothing is certified while a probe is out (the snapshot holds its vertex's
            # edges as they were when it left), nor while robots cut off from every source
            # are still members (linked again or sent away within stray_cycles plans)
            plan.certified = False
        if plan.certified:
            # a robot alone holding a room a drive found is no redundant one
            plan.redundant = set(plan.redundant) - lone_room_holders(
                self.evidence, snap, evidence["probe_clear"], plan.redundant)
            tri = self.placement.cut_off_triangle(self.roster)
            if tri is not None:
                # robots cut off from every source see one another: they stand where the
                # complex does not reach, so "covered" cannot be claimed
                plan.certified = False
                # warned once per triangle (it may stand for tens of cycles), then debug
                (log.warning if tuple(tri) != self._cut_off_logged else log.debug)(
                    "cycle %d: robots %s, cut off from every source, see one another: no "
                    "certificate while the complex cannot count them", self.cycle, list(tri))
                self._cut_off_logged = tuple(tri)
        self.out.add(PublishComplex(self._complex_msg(plan, now, "running")))
        if self._pending_failures and plan.certified:
            self.failures_healed += self._pending_failures
            self._pending_failures = 0
        if not snap.occupant:
            # nobody to certify with (everyone was lost): a certificate would be vacuous
            if self.roster.in_use() < self.cfg.robots_max and not self.pending_holds:
                for k in range(len(self.sources)):
                    rid = self._spawn(k, now)
                    self.vertex_of[rid] = k
                    self.pending_holds[rid] = k
            self._set_phase(Phase.EXECUTE, now)
            return
        if carried and not plan.frontier and not plan.open_vertices:
            # nothing left but what the probes still out will tell: wait for them, then
            # plan (and certify) on what everyone sees
            self.jobs = carried
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
        self.jobs = carried
        feeds: dict[int, PushJob] = {}
        for spec in plan.jobs:
            job = make_job(spec, snap.occupant)
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
                if self.roster.in_use() < self.cfg.robots_max:
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
                self.out.send(rid, Task(kind="leave", vertex=-1,
                                        timeout_s=self.cfg.task_timeout_s))
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
        self.out.add(PublishComplex(self._complex_msg(plan, now, "certified")))
        self.out.add(Done(True))

    def _stop(self, why: str) -> None:
        log.error("stopping: %s", why)
        self.done = True
        self.stop_reason = why
        if self.plan is not None:
            self.out.add(PublishComplex(self._complex_msg(self.plan, 0.0, "stopped")))
        self.out.add(Done(False))

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
            robots=self.roster.alive_count(), state=state,
            failures_healed=self.failures_healed, reason=self.stop_reason[:200],
            inferred=[int(e) for e, _ in getattr(plan, "inferred", ())],
            inferred_why=[str(w) for _, w in getattr(plan, "inferred", ())],
            exceptions=[int(e) for e in getattr(plan, "exceptions", ())],
            gap_probed=[int(e) for e in getattr(plan, "gap_probed", ())],
            move_s=self.pushes.mean_done_s(StepName.MOVE),
            enter_s=self.pushes.mean_done_s(StepName.ENTER))

    # ------------------------------------------------------------------ helpers
    def _spawn(self, source: int, now: float) -> int:
        """A new robot at ``source`` (coordinator.roster.Roster.spawn); returns its id."""
        return self.out.spawn(self.roster.spawn(source, now))

    def _robot_died(self, r: Robot, now: float, why: str) -> None:
        log.warning("robot %d failed (%s): dropping it; its hole becomes frontier", r.rid, why)
        self.roster.mark_dead(r)
        self.failures += 1
        self._pending_failures += 1
        self.placement.vacate(r.rid)
        self.out.add(RemoveRobot(Remove(robot=r.rid, reason=why)))
        self.pushes.robot_died(r.rid)

    def _heartbeat(self, now: float) -> None:
        """Spec 6 [P]: a robot whose token has been gone for dead_grace_s (sim) is dead (one
        with no status for dead_after_cycles cycles too: checked before each plan,
        :meth:`_phase_settle`)."""
        for r in self.roster.token_gone(now, self.cfg.dead_grace_s):
            self._robot_died(r, now, "liveliness token gone")

    def _set_phase(self, phase: Phase, now: float) -> None:
        self.phase = Phase(phase)
        self.phase_t = now
        if self.phase in (Phase.SETTLE, Phase.FINAL):
            # the next plan reads every member's status: ask idle robots, which a lockstep
            # world senses only now and then (world/wake.py), for a fresh one
            self.out.request_status()

    # ------------------------------------------------------------------ report
    def summary(self) -> dict:
        alive = [r for r in self.robots.values() if not r.dead]
        return dict(certified=self.certified, cycles=self.cycle,
                    robots_spawned=len(self.robots), robots_alive=len(alive),
                    robots_in_complex=len(self.placement.members(self.roster)),
                    robots_left=len(self.left),
                    failures=self.failures, failures_healed=self.failures_healed,
                    test_drive_retries=self.retried, robots_joined=self.joined,
                    robots_available=len(self.available),
                    stop_reason=self.stop_reason)

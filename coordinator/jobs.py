"""A push job (spec 4.3) as data: its steps, their names and states, and the pure rules on them.

A push along a path p0 -> ... -> pm = f is a :class:`PushJob` of :class:`Step` s, one per
robot task: test drive at f, deploy f's robot, the movers p_t -> p_{t+1}, a new robot
entering p0, refine, settle. No I/O and no clock: :class:`coordinator.pushes.Pushes` runs
them. Vertex and robot ids are ints; ``Step.started_t`` is sim seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from swarmcover.ground.angles import wrap

from .planner import JobSpec, Snapshot, source_component
from .topology.evidence import Evidence


class StepName(StrEnum):
    """What a step's robot does (a StrEnum: equal to the names the logs have always used)."""
    TEST_DRIVE = "test_drive"   # drive from f along the deployment direction and back
    DEPLOY = "deploy"           # f's robot to the new vertex
    MOVE = "move"               # p_t's robot to p_{t+1}
    ENTER = "enter"             # a new robot from the base to p0
    REFINE = "refine"           # the deployed robot re-homes once f is held again
    SETTLE = "settle"           # a mover that homed on < 2 landmarks homes on all
    HOME = "home"               # a free probe that drove clear goes back to its vertex


class StepState(StrEnum):
    PENDING = "pending"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


OVER = (StepState.DONE, StepState.FAILED)                  # the robot is there or near
FINISHED = (StepState.DONE, StepState.FAILED, StepState.CANCELLED)


@dataclass
class Step:
    """One robot's task within a push job."""
    name: StepName
    robot: int                    # -1 for "enter" until the new robot exists
    target: int                   # target vertex id
    t_index: int = -1             # for "move": index t of p_t -> p_{t+1}
    task_id: int = -1
    state: StepState = StepState.PENDING
    reason: str = ""
    started_t: float = 0.0
    n_landmarks: int = -1         # landmarks of the goto/hold task it was started with
    touch_offset: float = 0.0     # failed test drive: touch sector centre - direction (rad)
    timeout_s: float = 0.0        # the task's own timeout (s), when longer than the config's
    distance: float = 0.0         # the task's distance (m): how far a test drive goes


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
            return self.step(StepName.TEST_DRIVE) or self.step(StepName.DEPLOY)
        return self.step(StepName.MOVE, 0)

    def step(self, name: str, t_index: int = -1) -> Step | None:
        for s in self.steps:
            if s.name == name and s.t_index == t_index:
                return s
        return None

    @property
    def finished(self) -> bool:
        return all(s.state in FINISHED for s in self.steps)

    def to_do(self) -> list[Step]:
        """The steps still to run or running: an aborted push's pending steps never start,
        its running ones still hold their robots."""
        states = ((StepState.RUNNING,) if self.aborted
                  else (StepState.PENDING, StepState.RUNNING))
        return [s for s in self.steps if s.state in states]

    def cancel(self, why: str) -> None:
        """Abort the push: its pending steps never start."""
        self.aborted = True
        for s in self.steps:
            if s.state == StepState.PENDING:
                s.state, s.reason = StepState.CANCELLED, why

    def source_robot(self):
        """The robot that leaves p0 in this job (fed by an earlier job at the same source):
        its id, None while it is still entering, False if it never will.

        An earlier job that stopped before its own robot left p0 (a failed test drive: the
        robot drove back) hands that robot on, so one touch no longer cancels every later
        push from the source."""
        feed = self.feed
        while feed is not None:
            s0 = feed.steps_at_source()
            if feed.aborted and s0 is not None and (
                    s0.state in (StepState.PENDING, StepState.CANCELLED)
                    or (s0.name == StepName.TEST_DRIVE and s0.state == StepState.FAILED
                        and s0.reason.startswith("touch"))):
                if s0.robot >= 0:
                    return s0.robot
                feed = feed.feed
                continue
            ent = feed.step(StepName.ENTER)
            if ent is None or feed.aborted or ent.state in (StepState.FAILED,
                                                             StepState.CANCELLED):
                return False
            return ent.robot if ent.state == StepState.DONE else None
        return False


def make_job(spec: JobSpec, occupant: dict[int, int]) -> PushJob:
    """The steps of a planned push, robots taken from the snapshot's ``occupant``."""
    job = PushJob(spec)
    path = spec.path
    f = path[-1]
    if spec.test_drive:
        job.steps.append(Step(StepName.TEST_DRIVE, occupant[f], f))
    job.steps.append(Step(StepName.DEPLOY, occupant[f], spec.new_vertex))
    for t in range(len(path) - 2, -1, -1):
        job.steps.append(Step(StepName.MOVE, occupant[path[t]], path[t + 1], t_index=t))
    if spec.enter_source is not None:
        job.steps.append(Step(StepName.ENTER, -1, path[0]))
    job.steps.append(Step(StepName.REFINE, occupant[f], spec.new_vertex))
    return job


# a robot that found room stands beyond its side when an end sees it at least this far
# (rad) off the edge's line on that side
BEYOND_MIN = math.radians(10.0)


def beyond_side(snap: Snapshot, linked: set[int] | None = None):
    """``beyond(key, w)`` on ``snap``: vertex w stands beyond side (u, v, sigma) of edge
    u-v (sigma +1: counter-clockwise of u -> v): every end that sees both w and the other
    end sees w on that side, at least BEYOND_MIN off the edge's line, and some end does;
    and w is linked to a source (when ``snap`` has sources; ``linked``: its
    :func:`source_component`, if the caller has it). A room held by a robot cut off from the
    swarm is held by nothing the certificate counts."""
    if linked is None and snap.sources:
        linked = source_component(snap)

    def beyond(key, w: int) -> bool:
        if linked is not None and w not in linked:
            return False
        u, v, sg = int(key[0]), int(key[1]), int(key[2])
        seen = []
        for p, q, s in ((u, v, sg), (v, u, -sg)):
            b = snap.nbrs.get(p, {})
            if w in b and q in b:
                a = s * wrap(b[w] - b[q])
                seen.append(BEYOND_MIN < a < math.pi - BEYOND_MIN)
        return bool(seen) and all(seen)
    return beyond


def lone_room_holders(evidence: Evidence, snap: Snapshot, clear,
                      leaving=frozenset()) -> frozenset[int]:
    """Of the vertices ``leaving`` (a redundancy pass's), those whose robots alone hold a
    room a drive found (``clear``: the fence's ``probe_clear``): no other robot that stays
    holds a room of the same side, and no other vertex beside both ends of the side that
    stays stands beyond it. Such a robot is no redundant one: the room counts only while it
    stands there (Evidence.lost_rooms), so sending it away reopens the side. The final
    pass did, the side was swept again, found the same room, and that robot was sent away
    in turn (office_ros seed 0: 53 cycles and 514 s after the first certificate, 42 robots
    more started). A side that another room's robot keeps closed (pillar_hall seed 2: one
    from each end), or another robot beyond it keeps covered, stays so without it. When
    every such robot of a side is leaving, the one of the lowest vertex stays (the
    others then have it beside them): sending them all away reopened the side once more."""
    leaving = frozenset(leaving)
    rooms = {k: h for k, h in evidence.rooms(clear).items() if h in snap.occupant}
    if not rooms or not leaving:
        return frozenset()
    holders: dict[tuple, set[int]] = {}      # side (u, v, sigma) -> its rooms' robots
    for key, h in rooms.items():
        holders.setdefault(key[:3], set()).add(h)
    beyond = beyond_side(snap)
    kept: set[int] = set()

    def stays(w) -> bool:
        return w not in leaving or w in kept

    for key, h in sorted(rooms.items(), key=lambda kh: (kh[1], repr(kh[0]))):
        if h not in leaving or h in kept or any(stays(o) for o in holders[key[:3]] - {h}):
            continue
        u, v = int(key[0]), int(key[1])
        nu, nv = snap.nbrs.get(u, {}), snap.nbrs.get(v, {})
        if not any(w != h and w in nu and w in nv and stays(w) and beyond(key, w) for w in nu):
            kept.add(h)
    return frozenset(kept)


def evidence_kwargs(evidence: Evidence, snap: Snapshot, cut_off=frozenset()) -> dict:
    """What the planner takes of the evidence on ``snap``: the fence's keyword arguments
    (less the failed directions, passed as ``test_drive_failures``); a drive that found
    room counts only while its robot's vertex stands beyond the side (:func:`beyond_side`).
    ``sweep_foreign``: the sides a sweep of which a robot cut off from the swarm stopped,
    one sent away as such (``cut_off``: robot ids) or one of ``snap`` no source reaches;
    ``sweep_blocked``: those a robot stopped standing still at a vertex that a robot of
    ``snap`` a source reaches holds now (:meth:`Evidence.stopper_vertices`)."""
    linked = source_component(snap)
    kw = evidence.fence_kwargs(snap.occupant,
                               beyond_side(snap, linked if snap.sources else None))
    kw.pop("test_drive_failures")
    # a sweep stopped by a robot cut off from the swarm: it stands in free space the complex
    # does not hold, and no inference may close the gap it left (fence_probes: 'sweep_gap').
    # A robot sent away as redundant stands where the certified complex held it
    outside = set(cut_off) | {r for v, r in snap.occupant.items() if v not in linked}
    stoppers = evidence.sweep_stoppers(snap.occupant)
    kw["sweep_foreign"] = frozenset(k for k, by in stoppers.items() if by & outside)
    # a sweep stopped by a robot of the swarm standing still at a vertex that a robot
    # linked to a source holds now (the stopper, or the one a push put in its place): the
    # space in front of the side is where it stands (fence_probes: 'sweep_blocked', not
    # probed). A stopper that was moving vouches for no place: the gap is the gap rules'
    held = {v for v, r in snap.occupant.items() if v in linked and r not in cut_off}
    places = evidence.stopper_vertices(snap.occupant)
    kw["sweep_blocked"] = frozenset(k for k, at in places.items() if at & held)
    return kw


def drive_failures(evidence: Evidence, snap: Snapshot) -> dict[int, list[float]]:
    """vertex -> directions (rad) of drives from it that touched, at ``snap``'s vertices."""
    return {v: b for v, b in evidence.failed_directions().items() if v in snap.occupant}


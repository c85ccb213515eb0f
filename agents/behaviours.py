"""A robot's task behaviours as an explicit state machine. Pure: no I/O and no clock.

Inputs: :class:`bus.messages.Sense` (bearings, back bearings and touch; ``Sense.t`` is the
only clock, so lockstep runs are reproducible) and :class:`bus.messages.Task`. Output per
Sense: a body-frame :class:`Command` and the Status fields (:meth:`Behaviour.status`). Pose
telemetry never enters here: the robot steers on bearings, identities and touch only.

:class:`Behaviour` is the facade and the task life cycle. What the robot perceives is in
:mod:`agents.perception`; each mode is one small class (:mod:`agents.modes`,
:mod:`agents.openloop`) whose tick returns a velocity and an :class:`~agents.modes.Outcome`,
which the life cycle here turns into the next mode according to the task and its
:class:`~agents.modes.Phase`.

Modes (:class:`~agents.modes.Mode`) and the Status.state (:class:`State`) they report:

* ``idle``                               -> "idle" (no task, or after ``leave``)
* ``record`` (snapshot), ``keep`` (station keeping)                    -> "holding"
* ``home`` (visual homing to task bearings)   -> "moving" (goto), "deploying", "test_driving"
* ``open`` / ``open_back`` (open-loop along a direction)   -> "deploying" / "test_driving"
* ``sweep`` (sliding along the wall a test drive touched)               -> "test_driving"
* ``scale_out`` / ``scale_back`` (scale correction)                    -> "deploying"

Task kinds (what the coordinator sends, what Status says) are documented on
:meth:`Behaviour.on_task`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from swarmcover.bus.messages import Sense, Status, Task

from .control import FrameTracker, circmean, clamp_speed, diffdrive, slide, wrap
from .modes import MOVING_MODES, Context, Home, Idle, Mode, ModeState, Outcome, Phase, Record, Tick
from .openloop import Leg, Open, OpenBack, ScaleOut
from .params import AgentParams
from .perception import Contact, Perception
from .sweep import Sweep

__all__ = ["Behaviour", "Command", "Mode", "MOVING_MODES", "Phase", "STOP", "State", "TaskState"]

PI = math.pi
# a goto starting at most this long (s) after a sweep's opening backs out of it first
OPENING_BACK_S = 2.0


class State(StrEnum):
    """Status.state: what the robot is doing, as the coordinator sees it."""
    STARTING = "starting"          # before the first Sense
    IDLE = "idle"                  # no task, or after ``leave``
    HOLDING = "holding"            # holding station (after any task but ``leave``)
    MOVING = "moving"              # a goto
    DEPLOYING = "deploying"        # a deploy, with its scale correction
    TEST_DRIVING = "test_driving"  # a test drive (probe), with its return


class TaskState(StrEnum):
    """Status.task_state: how the current task stands."""
    NONE = "none"                  # no task yet
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"              # Status.reason says why


@dataclass(slots=True)
class Command:
    """Body-frame velocity: vx forward, vy left (m/s), wz CCW (rad/s)."""
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


STOP = Command()


class Behaviour:
    """One robot's behaviour. Call :meth:`on_task` for each Task and :meth:`step` for each
    Sense; read :meth:`status` for the Status fields and :attr:`changed` (set when the
    state, the task state or the contact flag changed; the caller clears it)."""

    def __init__(self, params: AgentParams, robot: int):
        self.p = params
        self.robot = robot
        self.state = State.STARTING
        self.task: Task | None = None
        self.pending: Task | None = None
        self.task_state = TaskState.NONE
        self.reason = ""
        self.progress = 0.0
        self.vertex = -1
        self.changed = True
        self.rejected = 0            # tasks refused (wrong robot id)
        self.t0 = 0.0                # start time of the current task (s)
        self.see = Perception(robot, params.dt, params.tau)
        self.ctx = Context(params, self.see)
        self.touch = Contact()       # sticky obstacle contact (spec 3.5)
        self.cmd = STOP              # the command published for the last Sense
        self.intent: float | None = None  # body-frame direction it meant (rad)
        self._mode: ModeState = Idle()
        # the current task's life cycle
        self.phase = Phase.NONE      # why the robot homes or drives open loop
        self.frame: FrameTracker | None = None   # frame of the task's bearings/direction
        self.end_reason = ""            # deploy: why its motion ended (stalled, blocked)
        self.return_goal: dict[int, float] | None = None  # test drive: re-home after reversing
        self.return_reason = "touch"    # test drive: the failure reason once back home
        # a probe's open-loop approach leg, reversed: (direction, distance, speed) to drive
        # back before homing on the vertex (two landmarks in line with the vertex fix no
        # point along that line: homing on them alone stops wherever it starts)
        self.via_back: tuple[float, float, float] | None = None
        # a wall sweep's drive into the opening it found, reversed: (direction, distance,
        # when it ended). A goto that comes at once (a free probe sent home) creeps back
        # along it while its landmarks in view fix no point (Home's creep): from beyond a
        # door, homing straight on bearings the door hides failed "lost landmarks" and left
        # the robot in the door (bench/unseen.py seed 7 map 3: it then stopped the sweeps
        # that would have found the door, and the room behind was certified uncovered)
        self.opening_back: tuple[float, float, float] | None = None
        self.touch_offset = 0.0         # test drive: touch sector centre - direction driven (rad)
        self.press = False              # this tick's velocity presses into walls (a sweep)
        self.target: dict[int, float] = {}  # holding: the snapshot kept (rad, its frame)

    @property
    def mode(self) -> Mode:
        """The current mode."""
        return self._mode.mode

    @property
    def idle(self) -> bool:
        """Whether the robot holds still with nothing to do until what it senses changes:
        no task waiting or running, no motion commanded, and a mode that only watches (no
        task, or keeping a finished snapshot without station keeping). A lockstep world may
        then stop sending it every Sense (world.wake); a task, a touch, a push or motion
        nearby brings them back."""
        return (self.pending is None and self.task_state is not TaskState.RUNNING
                and self.cmd is STOP and self._mode.watching())

    @property
    def contact(self) -> bool:
        """Whether an obstacle contact is reported."""
        return self.touch.active

    # ================================================================== inputs

    def on_task(self, task: Task) -> bool:
        """Take a new task (it replaces the current one at the next Sense). Returns False if
        the task is for another robot (counted in ``rejected``) or repeats the current one.

        Semantics (landmarks/bearings exclude this robot's own id if listed):

        * ``hold``: stop, average bearings over ``hold_window`` ticks into a snapshot, then
          keep station on it: re-home when one landmark's averaged bearing drifts beyond
          hold_deadband_deg and another beyond hold_second_deg (a bump); a landmark that
          alone drifts, or is off by more than hold_gate_deg, has moved itself and is
          re-recorded once steady; new neighbours are adopted, neighbours unseen for
          lost_timeout_s dropped. task_state: running while recording, done once the
          snapshot exists; no timeout. Status.nbr_bearings: the window average while
          still.
        * ``goto``: visual homing to ``bearings`` (reference frame, see ``ref_offsets``).
          done when every bearing error stays < arrive_deg for arrive_ticks; failed
          "lost landmarks" when fewer than 2 (or all, if fewer are given) are in view for
          lost_timeout_s; failed "timeout" after timeout_s (0: none).
        * ``deploy``: with >= 2 landmarks like goto; with fewer, open loop along
          ``direction`` for ``distance`` (with 1 landmark: if it is lost, back up until it is
          seen again, then done with reason "link lost, backed up"); then, if
          ``scale_correct``, scale correction; then done.
        * ``test_drive``: open loop along ``direction`` for ``distance`` at
          test_drive_speed_frac * v_max; done if no blocking obstacle touch. On a touch
          that blocks the motion: the contact is kept (pinned) in Status, the robot homes
          back to ``bearings`` (or reverses open loop if none are given) and the task
          fails with reason "touch" (or "touch (return: <why>)" if the return failed).
          With ``sweep_side`` a touch starts a wall sweep (:mod:`agents.sweep`): done
          "opening" / "room" where it stands, or back home failing "swept HI LO".
        * ``leave``: stop; task done at once; state idle, vertex -1.

        After any task ends (done or failed) the robot holds station where it is (state
        "holding"), except after ``leave``.
        """
        if task.robot != self.robot:
            self.rejected += 1
            return False
        for cur in (self.pending, self.task):
            if cur is not None and cur.task_id == task.task_id and cur.epoch == task.epoch \
                    and cur.kind == task.kind:
                return False
        self.pending = task
        return True

    def step(self, s: Sense) -> Command:
        """Handle one Sense tick; returns the command to publish for it."""
        p, c = self.p, self.cmd
        moving = self._mode.mode in MOVING_MODES
        dt = self.see.update(s, c, self.intent)
        if dt > 0 and (c.vx or c.vy or c.wz) and moving:
            self.touch.travel(math.hypot(c.vx, c.vy) * dt)
        if self.state is State.STARTING:
            self._set_state(State.IDLE)
        if self.pending is not None:
            task, self.pending = self.pending, None
            self._start(task)
        if self.touch.update(self.see, p.aligned, p.contact_clear_rv * p.rv):
            self.changed = True
        task = self.task
        if (task is not None and self.task_state is TaskState.RUNNING and task.timeout_s > 0
                and task.kind not in ("hold", "leave") and self.see.t - self.t0 > task.timeout_s):
            self._finish(TaskState.FAILED, self._fail_reason("timeout"))
        self.intent = None
        self.press = False
        ux, uy = self._tick()
        self.cmd = self._output(ux, uy, self.press)
        return self.cmd

    # ================================================================== status

    def status_message(self, seq: int, t: float, tick: int = -1, live: bool = False,
                       pose: list | None = None) -> Status:
        """The Status this robot publishes: its behaviour's fields plus the caller's
        sequence number, sim time, answered tick, live flag and body pose (the agent
        process and the in-process loop both build it here)."""
        return Status(robot=self.robot, seq=seq, t=t, kind=self.p.kind, live=live,
                      pose=list(pose or []), tick=tick, **self.status())

    def status(self) -> dict:
        """Status fields (robot, seq, t, kind, live, pose are the caller's). The neighbours
        are those whose link is not lost (seen within link_lost_ticks): a camera frame that
        misses one does not take its edge out of the coordinator's complex."""
        seen = self.see.recent(self.p.link_lost_ticks)
        ids = list(seen)
        window = self._mode.still_window()
        if window is not None:   # holding still: the window averages
            bearings = []
            for i in ids:
                w = window.get(i)
                m = circmean(w) if w else None
                bearings.append(wrap(seen[i] if m is None else m))
        else:
            bearings = [seen[i] for i in ids]
        return dict(state=self.state.value, vertex=self.vertex,
                    task_id=self.task.task_id if self.task is not None else -1,
                    task_state=self.task_state.value, reason=self.reason,
                    progress=min(1.0, max(0.0, self.progress)), nbr_ids=ids,
                    nbr_bearings=bearings, contact=self.touch.active,
                    contact_bearing=self.touch.body_bearing(self.see),
                    touch_offset=self.touch_offset)

    # ================================================================== internals

    def _set_state(self, state: State) -> None:
        if state != self.state:
            self.state = state
            self.changed = True

    def _set_task_state(self, ts: TaskState, reason: str = "") -> None:
        reason = reason[:200]              # Status.reason's limit: a longer one is refused
        if ts != self.task_state or reason != self.reason:
            self.task_state = ts
            self.reason = reason
            self.changed = True

    def _output(self, ux: float, uy: float, press: bool = False) -> Command:
        """The command for a body-frame velocity (m/s): slid along walls (``press``: not,
        a sweep presses into them), clamped to v_max, and for a diffdrive robot turned into
        forward speed and turn rate."""
        p = self.p
        if (ux or uy) and not press:
            ux, uy = slide(ux, uy, self.see.obst, p.tau)
        if ux or uy:
            ux, uy = clamp_speed(ux, uy, p.v_max)
        if not (ux or uy):
            return STOP
        if p.kind == "diffdrive":
            v, w = diffdrive(ux, uy, p.k_w, p.k_v, p.v_max, p.w_max)
            return Command(v, 0.0, w)
        return Command(ux, uy, 0.0)

    def _fail_reason(self, why: str) -> str:
        if self.task is not None and self.task.kind == "test_drive" and self.phase is Phase.RETURN:
            return f"{self.return_reason} (return: {why})"
        if self.task is not None and self.task.kind == "test_drive" and self.phase is Phase.VIA:
            return f"via ({why})"
        return why

    def _task_frame(self, task: Task) -> FrameTracker | None:
        if not self.p.aligned:
            return None
        if task.ref_offsets:
            return FrameTracker(dict(zip(task.landmarks, task.ref_offsets)), self.see.heading)
        return self.see.snapshot_frame()

    def _task_goal(self, task: Task) -> dict[int, float]:
        return {l: b for l, b in zip(task.landmarks, task.bearings) if l != self.robot}

    # ------------------------------------------------------------------ modes

    def _tick(self) -> tuple[float, float]:
        """Tick the current mode and act on its outcome; returns the body-frame velocity
        (m/s) to command, zero when the mode ended a leg."""
        mode = self._mode
        r = mode.tick(self.ctx)
        if r.progress is not None:
            self.progress = r.progress
        match r.outcome:
            case Outcome.RUNNING:
                self.intent = r.intent
                self.press = not r.slide
                return r.ux, r.uy
            case Outcome.SWITCH:
                self._mode = r.next
                return self._tick()
            case Outcome.TOUCH:
                self.touch_offset = r.offset
                self._test_touch(mode)
                return self._tick()
        self._end_leg(mode, r)
        return 0.0, 0.0

    def _end_leg(self, mode: ModeState, r: Tick) -> None:
        """What follows a mode's outcome other than running on (see :class:`Outcome`)."""
        phase = self.phase
        if phase is Phase.VIA and isinstance(mode, Open):
            self.via_back = (wrap(mode.leg.direction + PI), mode.travelled(self.see),
                             self._return_speed)
        match r.outcome:
            case Outcome.HELD:
                self._mode = r.next
                self.target = r.next.target
                if mode.reports:     # a hold task: done once the snapshot exists
                    self.progress = 1.0
                    self._set_task_state(TaskState.DONE)
            case Outcome.ARRIVED:
                self._home_done()
            case Outcome.DRIVEN:
                self._open_done()
            case Outcome.FAILED:
                self._home_failed(r.reason)
            case Outcome.STALLED if phase is Phase.DEPLOY:
                self.end_reason = "stalled"
                self._after_deploy_motion()
            case Outcome.STALLED:
                self._home_failed("stalled")
            case Outcome.BLOCKED if phase is Phase.DEPLOY:
                self.end_reason = "blocked"
                self._after_deploy_motion()
            case Outcome.BLOCKED if phase is Phase.RETURN:
                self._finish(TaskState.FAILED, f"{self.return_reason} (return: blocked)")
            case Outcome.BLOCKED:    # via (a test leg is never stopped by walls)
                self._via_failed("blocked")
            case Outcome.WALL:       # far enough out: stay against the wall as the vertex
                self.touch.pinned = True
                self._finish(TaskState.DONE, "wall")
            case Outcome.SWEPT:      # the wall swept, no opening: back to the vertex
                self._sweep_back(mode, r.reason)
            case Outcome.DONE:
                if r.reason == "opening" and self.p.kind == "holonomic":
                    if isinstance(mode, Sweep) and mode.into is not None:
                        self.opening_back = (wrap(mode.into + PI), mode.travelled, self.see.t)
                    elif isinstance(mode, OpenBack):   # backed out until one was in view
                        self.opening_back = (wrap(mode.leg.direction + PI),
                                             mode.left(self.see), self.see.t)
                self._finish(TaskState.DONE, r.reason)
            case Outcome.GAVE_UP:
                self._finish(TaskState.FAILED, r.reason)
            case _:
                raise ValueError(f"unhandled outcome {r.outcome!r} of mode {mode.mode}")

    def _enter_record(self) -> None:
        task = self.task
        reports = (task is not None and task.kind == "hold"
                   and self.task_state is TaskState.RUNNING)
        self._mode = Record(reports)
        self._set_state(State.HOLDING)
        self.target = {}

    def _enter_home(self, goal: dict[int, float], phase: Phase,
                    creep_dir: float | None = None, creep_dist: float | None = None) -> None:
        """Home on ``goal``; a goto creeps along the task's direction hint, or along
        ``creep_dir`` for at most ``creep_dist`` (m) when given (see :class:`Home`)."""
        self.phase = phase
        task = self.task
        self._mode = Home(goal, phase, self.frame, self.ctx,
                          task.direction if creep_dir is None else creep_dir,
                          task.distance if creep_dist is None else creep_dist)

    @property
    def _return_speed(self) -> float:
        """Speed (m/s) of an open-loop leg back to the vertex: it retraces a leg just driven."""
        return self.p.return_speed_frac * self.p.v_max

    def _enter_open(self, direction: float, distance: float, speed: float, phase: Phase,
                    single: int | None = None) -> None:
        self.phase = phase
        # a test leg keeps in sight one of the task's sight landmarks in view as it starts
        keep = (tuple(l for l in self.task.sight if l != self.robot and l in self.see.seen)
                if phase is Phase.TEST else ())
        leg = Leg(direction, distance, speed, phase, self.frame, single, self.task.keep_after,
                  keep)
        self._mode = Open(leg, self.see)

    # ------------------------------------------------------------------ task life cycle

    def _start(self, task: Task) -> None:
        self.task = task
        self.t0 = self.see.t
        self.vertex = task.vertex
        self.progress = 0.0
        self.phase = Phase.NONE
        self.end_reason = ""
        self.via_back = None
        self._set_task_state(TaskState.RUNNING)
        self.frame = self._task_frame(task)
        kind = task.kind
        if kind == "hold":
            self._enter_record()
        elif kind == "goto":
            self._clear_contact()
            self._set_state(State.MOVING)
            back, self.opening_back = self.opening_back, None
            if back is not None and self.see.t - back[2] <= OPENING_BACK_S and not task.distance:
                # Home's creep hint: out along the drive back while the goal landmarks in
                # view fix no point, at most as far as the drive went in
                self._enter_home(self._task_goal(task), Phase.GOTO, back[0], back[1])
            else:
                self._enter_home(self._task_goal(task), Phase.GOTO)
        elif kind == "deploy":
            self._clear_contact()
            self._set_state(State.DEPLOYING)
            goal = self._task_goal(task)
            if len(goal) >= 2:
                self._enter_home(goal, Phase.DEPLOY)
            else:
                single = next(iter(goal)) if goal else None
                if single is not None and single not in self.see.seen:
                    single = None  # not in view at the start: nothing to keep in sight
                self._enter_open(task.direction, task.distance,
                                 self.p.deploy_speed_frac * self.p.v_max, Phase.DEPLOY, single)
        elif kind == "test_drive":
            self.touch.pinned = False
            self._set_state(State.TEST_DRIVING)
            self.return_reason = "touch"
            self.touch_offset = 0.0
            via = {l: b for l, b in zip(task.via_landmarks, task.via_bearings) if l != self.robot}
            if len(via) >= 2:
                # a probe: home to the point on the edge first (bearing-only, spec 4.5)
                self._enter_home(via, Phase.VIA)
            elif via and task.via_distance > 0:
                self._enter_open(next(iter(via.values())), task.via_distance,
                                 self.p.test_drive_speed_frac * self.p.v_max, Phase.VIA)
            else:
                self._start_test_leg()
        else:  # leave
            self.vertex = -1
            self._mode = Idle()
            self._set_state(State.IDLE)
            self.progress = 1.0
            self._set_task_state(TaskState.DONE)

    def _clear_contact(self) -> None:
        if self.touch.clear():
            self.changed = True

    def _start_test_leg(self) -> None:
        self._enter_open(self.task.direction, self.task.distance,
                         self.p.test_drive_speed_frac * self.p.v_max, Phase.TEST)

    def _finish(self, task_state: TaskState, reason: str = "") -> None:
        """End the current task and hold station where the robot is."""
        if task_state is TaskState.DONE:
            self.progress = 1.0
        self._set_task_state(task_state, reason)
        self._enter_record()

    def _home_done(self) -> None:
        phase = self.phase
        if phase is Phase.DEPLOY:
            self._after_deploy_motion()
        elif phase is Phase.RETURN:
            self._finish(TaskState.FAILED, self.return_reason)
        elif phase is Phase.VIA:
            self._start_test_leg()
        else:  # goto
            self._finish(TaskState.DONE)

    def _home_failed(self, why: str) -> None:
        if self.phase is Phase.VIA:
            self._via_failed(why)
        else:
            self._finish(TaskState.FAILED, self._fail_reason(why))

    def _open_done(self) -> None:
        phase = self.phase
        if phase is Phase.DEPLOY:
            self._after_deploy_motion()
        elif phase is Phase.RETURN:
            goal, self.return_goal = self.return_goal, None
            self._home_back(goal)
        elif phase is Phase.VIA:
            self._start_test_leg()
        else:  # test drive completed without a blocking touch
            self._finish(TaskState.DONE)

    def _test_touch(self, out: Open) -> None:
        """Test drive hit an obstacle: keep the contact, go back, fail with "touch" (or,
        with Task.sweep_side, sweep the wall from there)."""
        self.touch.pinned = True
        self.changed = True
        if self.task.sweep_side and self.task.sweep_landmarks:
            self._mode = Sweep.after(out, self.task, self.touch_offset, self.ctx)
            return
        # first reverse what was driven (always possible: open loop), then re-home on the
        # vertex's bearings if any; a landmark lost during the drive cannot strand us
        travelled = out.travelled(self.see)
        self.return_goal = self._task_goal(self.task)
        self._enter_open(wrap(out.leg.direction + PI), max(0.0, travelled), self._return_speed,
                         Phase.RETURN)

    def _sweep_back(self, sweep: Sweep, reason: str) -> None:
        """A sweep found no opening: home back to the vertex (open loop towards where it
        believes it lies first, with fewer than two of its landmarks in view) and fail with
        ``reason``."""
        self.return_reason, goal = reason, self._task_goal(self.task)
        if sum(1 for l in goal if l in self.see.seen) >= min(2, len(goal)) or sweep.R is None:
            return self._home_back(goal)
        self.return_goal = goal
        self._enter_open(math.atan2(-sweep.R[1], -sweep.R[0]), math.hypot(*sweep.R),
                         self._return_speed, Phase.RETURN)

    def _via_failed(self, why: str) -> None:
        """A probe's approach to its point on the edge failed: home back to the vertex and
        fail with reason "via (<why>)" (no evidence either way)."""
        self.return_reason = f"via ({why})"
        self._home_back(self._task_goal(self.task))

    def _home_back(self, goal: dict[int, float] | None) -> None:
        """Home back to the vertex on ``goal`` if enough of it is in view, else fail with
        the return reason. An open-loop approach leg is driven back first."""
        if self.via_back is not None:
            (d, dist, speed), self.via_back = self.via_back, None
            if dist > 0.0:
                self.return_goal = goal
                self._enter_open(d, dist, speed, Phase.RETURN)
                return
        if goal and sum(1 for l in goal if l in self.see.seen) >= min(2, len(goal)):
            self._enter_home(goal, Phase.RETURN)
        else:
            self._finish(TaskState.FAILED, self.return_reason)

    def _after_deploy_motion(self) -> None:
        task = self.task
        if task is not None and task.scale_correct:
            self._enter_scale()
        else:
            self._finish(TaskState.DONE, self.end_reason)

    def _enter_scale(self) -> None:
        goal = self._task_goal(self.task)
        refs = [l for l in goal if l in self.see.seen]
        if not refs:
            self._finish(TaskState.DONE, "scale skipped: no reference in view")
            return
        self._mode = ScaleOut(refs, self.see, self.end_reason)

"""A robot's task behaviours as an explicit state machine. Pure: no I/O and no clock.

Inputs: :class:`bus.messages.Sense` (bearings, back bearings and touch; ``Sense.t`` is the
only clock, so lockstep runs are reproducible) and :class:`bus.messages.Task`. Output per
Sense: a body-frame :class:`Command` and the Status fields (:meth:`Behaviour.status`). Pose
telemetry never enters here: the robot steers on bearings, identities and touch only.

Modes (internal) and the Status.state they report:

* ``idle``                               -> "idle" (no task, or after ``leave``)
* ``record`` (snapshot), ``keep`` (station keeping)                    -> "holding"
* ``home`` (visual homing to task bearings)   -> "moving" (goto), "deploying", "test_driving"
* ``open`` / ``open_back`` (open-loop along a direction)   -> "deploying" / "test_driving"
* ``scale_out`` / ``scale_back`` (scale correction)                    -> "deploying"

Task kinds (what the coordinator sends, what Status says) are documented on
:meth:`Behaviour.on_task`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import StrEnum

from bus.messages import Sense, Status, Task

from .control import (FrameTracker, StopRule, away_direction, blocks, bearing_errors,
                      circmean, clamp_speed, diffdrive, homing_velocity, resultant, slide, unit,
                      wrap)
from .params import AgentParams

PI = math.pi


class Mode(StrEnum):
    """What the behaviour does this tick; each has one ``_tick_<mode>`` method (the
    dispatch table :attr:`Behaviour._ticks`). A StrEnum: equal to its name as a string."""
    IDLE = "idle"              # no task
    RECORD = "record"          # holding: recording the landmarks' bearings
    KEEP = "keep"              # holding: keeping them (station keeping if enabled)
    HOME = "home"              # homing on target bearings (goto, deploy, return)
    OPEN = "open"              # driving out on a heading (test drive, probe, spawn entry)
    OPEN_BACK = "open_back"    # back along it after a touch or a lost link
    SCALE_OUT = "scale_out"    # rv scale measurement: out until a neighbour is lost
    SCALE_BACK = "scale_back"  # and back until it is seen again


MOVING_MODES = frozenset({Mode.HOME, Mode.OPEN, Mode.OPEN_BACK, Mode.SCALE_OUT, Mode.SCALE_BACK})


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
        p = self.p = params
        self.robot = robot
        self.state = "starting"
        self.mode = Mode.IDLE
        self._ticks = {Mode.IDLE: self._tick_idle, Mode.RECORD: self._tick_record,
                       Mode.KEEP: self._tick_keep, Mode.HOME: self._tick_home,
                       Mode.OPEN: self._tick_open, Mode.OPEN_BACK: self._tick_open_back,
                       Mode.SCALE_OUT: self._tick_scale_out, Mode.SCALE_BACK: self._tick_scale_back}
        self.task: Task | None = None
        self.pending: Task | None = None
        self.task_state = "none"
        self.reason = ""
        self.progress = 0.0
        self.vertex = -1
        self.changed = True
        self.rejected = 0            # tasks refused (wrong robot id)
        # perception, refreshed every tick
        self.n = 0                   # Sense ticks handled
        self.t: float | None = None  # Sense.t of the current tick (s)
        self.t0 = 0.0                # start time of the current task (s)
        self.dt = p.dt               # last measured tick length (s)
        self.seen: dict[int, float] = {}
        self.back: dict[int, float] = {}
        self.obst: list[float] = []
        self.last_seen: dict[int, int] = {}   # landmark -> tick index last seen
        self.last_seen_t: dict[int, float] = {}
        # dead reckoning of our own commands (open-loop modes and fallbacks only)
        self.cmd = STOP
        self.intent: float | None = None  # body-frame direction the last command meant
        self.heading = 0.0           # integral of commanded wz (rad)
        self.advance = 0.0           # integral of commanded velocity along `intent` (m)
        # sticky obstacle contact (spec 3.5)
        self.contact = False
        self.contact_bearing = 0.0   # body frame at the time of contact (rad)
        self.contact_frame: FrameTracker | None = None
        self.contact_pinned = False
        self.bumped_t = -1e18           # last time another robot touched us (s)
        self.home_mark = 0.0            # dead-reckoned advance when homing started (m)
        self.return_goal: dict[int, float] | None = None  # test drive: re-home after reversing
        self.return_reason = "touch"    # test drive: the failure reason once back home
        self.touch_offset = 0.0         # test drive: touch sector centre - direction driven (rad)
        self.contact_moved = 0.0
        # homing
        self.stop = StopRule(p.arrive, p.arrive_ticks, p.error_alpha)
        self.goal: dict[int, float] = {}
        self.frame: FrameTracker | None = None   # frame of the task's bearings/direction
        self.purpose = ""
        self.lost_since: float | None = None
        self.err0: float | None = None
        # holding
        self.window: dict[int, deque] = {}
        self.record_n = 0
        self.target: dict[int, float] = {}
        self.target_frame: FrameTracker | None = None
        self.station = False         # station keeping is homing back
        # open loop and scale correction
        self.ol_dir = 0.0            # reference-frame direction (rad)
        self.ol_dist = 0.0
        self.ol_speed = 0.0
        self.mark = 0.0              # `advance` at the start of the current leg (m)
        self.out_dist = 0.0
        self.blocked_since: float | None = None
        self.single: int | None = None
        self.refs: list[int] = []
        self.ref_bearing: dict[int, float] = {}
        self.ref_heading: dict[int, float] = {}
        self.step_left = 0.0
        self.step_mark = 0.0
        self.settle_left = 0
        self.margin_left = 0
        self.back_dist = 0.0
        self.end_reason = ""

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
        self._perceive(s)
        if self.pending is not None:
            task, self.pending = self.pending, None
            self._start(task)
        self._update_contact()
        task = self.task
        if (task is not None and self.task_state == "running" and task.timeout_s > 0
                and task.kind not in ("hold", "leave") and self.t - self.t0 > task.timeout_s):
            self._finish("failed", self._fail_reason("timeout"))
        self.intent = None
        ux, uy = self._ticks[self.mode]()
        self.cmd = self._output(ux, uy)
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
        """Status fields (robot, seq, t, kind, live, pose are the caller's)."""
        holding_still = self.mode in (Mode.RECORD, Mode.KEEP) and not self.station
        ids = list(self.seen)
        if holding_still:
            bearings = []
            for i in ids:
                w = self.window.get(i)
                m = circmean(w) if w else None
                bearings.append(wrap(self.seen[i] if m is None else m))
        else:
            bearings = [self.seen[i] for i in ids]
        cb = self.contact_bearing
        if self.contact and self.contact_frame is not None:
            cb = wrap(cb + self.contact_frame.update(self.seen, self.back, self.heading))
        return dict(state=self.state, vertex=self.vertex,
                    task_id=self.task.task_id if self.task is not None else -1,
                    task_state=self.task_state, reason=self.reason,
                    progress=min(1.0, max(0.0, self.progress)), nbr_ids=ids,
                    nbr_bearings=bearings, contact=self.contact,
                    contact_bearing=wrap(cb) if self.contact else 0.0,
                    touch_offset=self.touch_offset)

    # ================================================================== internals

    def _set_state(self, state: str) -> None:
        if state != self.state:
            self.state = state
            self.changed = True

    def _set_task_state(self, ts: str, reason: str = "") -> None:
        if ts != self.task_state or reason != self.reason:
            self.task_state = ts
            self.reason = reason
            self.changed = True

    def _perceive(self, s: Sense) -> None:
        dt = 0.0 if self.t is None else s.t - self.t
        dt = min(1.0, max(0.0, dt))
        if dt > 0:
            self.dt = dt
        self.t = s.t
        self.n += 1
        # dead-reckon the previous command over the elapsed interval
        c = self.cmd
        if dt > 0 and (c.vx or c.vy or c.wz):
            self.heading += c.wz * dt
            if self.intent is not None:
                ix, iy = unit(self.intent)
                self.advance += (c.vx * ix + c.vy * iy) * dt
            if self.contact and not self.contact_pinned and self.mode in MOVING_MODES:
                self.contact_moved += math.hypot(c.vx, c.vy) * dt
        seen: dict[int, float] = {}
        back: dict[int, float] = {}
        me = self.robot
        for i, b, bb in zip(s.ids, s.bearings, s.back_bearings):
            if i == me or i in seen:
                continue
            seen[i] = b
            back[i] = bb
        self.seen = seen
        self.back = back
        n, t = self.n, s.t
        for i in seen:
            self.last_seen[i] = n
            self.last_seen_t[i] = t
        self.obst = [a for a, r in zip(s.touch, s.touch_robot) if not r]
        if any(s.touch_robot):
            self.bumped_t = s.t
        if self.state == "starting":
            self._set_state("idle")

    def _update_contact(self) -> None:
        if self.obst:
            if not self.contact:
                self.changed = True
            self.contact = True
            self.contact_bearing = circmean(self.obst) or self.obst[0]
            self.contact_frame = (FrameTracker.snapshot(self.seen, self.back, self.heading)
                                  if self.p.aligned else None)
            self.contact_moved = 0.0
        elif (self.contact and not self.contact_pinned
              and self.contact_moved > self.p.contact_clear_rv * self.p.rv):
            self._clear_contact()

    def _clear_contact(self) -> None:
        if self.contact:
            self.changed = True
        self.contact = False
        self.contact_pinned = False
        self.contact_frame = None
        self.contact_moved = 0.0

    def _psi(self, frame: FrameTracker | None) -> float:
        if frame is None:
            return 0.0
        return frame.update(self.seen, self.back, self.heading)

    def _task_frame(self, task: Task) -> FrameTracker | None:
        if not self.p.aligned:
            return None
        if task.ref_offsets:
            return FrameTracker(dict(zip(task.landmarks, task.ref_offsets)), self.heading)
        return FrameTracker.snapshot(self.seen, self.back, self.heading)

    def _task_goal(self, task: Task) -> dict[int, float]:
        return {l: b for l, b in zip(task.landmarks, task.bearings) if l != self.robot}

    def _output(self, ux: float, uy: float) -> Command:
        p = self.p
        if ux or uy:
            ux, uy = slide(ux, uy, self.obst, p.tau)
            ux, uy = clamp_speed(ux, uy, p.v_max)
        if not (ux or uy):
            return STOP
        if p.kind == "diffdrive":
            v, w = diffdrive(ux, uy, p.k_w, p.k_v, p.v_max, p.w_max)
            return Command(v, 0.0, w)
        return Command(ux, uy, 0.0)

    def _fail_reason(self, why: str) -> str:
        if self.task is not None and self.task.kind == "test_drive" and self.purpose == "return":
            return f"{self.return_reason} (return: {why})"
        if self.task is not None and self.task.kind == "test_drive" and self.purpose == "via":
            return f"via ({why})"
        return why

    # ------------------------------------------------------------------ task life cycle

    def _start(self, task: Task) -> None:
        self.task = task
        self.t0 = self.t
        self.vertex = task.vertex
        self.progress = 0.0
        self.station = False
        self.purpose = ""
        self.end_reason = ""
        self._set_task_state("running")
        self.frame = self._task_frame(task)
        kind = task.kind
        if kind == "hold":
            self._enter_record()
        elif kind == "goto":
            self._clear_contact()
            self._set_state("moving")
            self._enter_home(self._task_goal(task), "goto")
        elif kind == "deploy":
            self._clear_contact()
            self._set_state("deploying")
            goal = self._task_goal(task)
            if len(goal) >= 2:
                self._enter_home(goal, "deploy")
            else:
                single = next(iter(goal)) if goal else None
                if single is not None and single not in self.seen:
                    single = None  # not in view at the start: nothing to keep in sight
                self._enter_open(task.direction, task.distance,
                                 self.p.deploy_speed_frac * self.p.v_max, "deploy", single)
        elif kind == "test_drive":
            self.contact_pinned = False
            self._set_state("test_driving")
            self.return_reason = "touch"
            self.touch_offset = 0.0
            via = {l: b for l, b in zip(task.via_landmarks, task.via_bearings) if l != self.robot}
            if len(via) >= 2:
                # a probe: home to the point on the edge first (bearing-only, spec 4.5)
                self._enter_home(via, "via")
            elif via and task.via_distance > 0:
                self._enter_open(next(iter(via.values())), task.via_distance,
                                 self.p.test_drive_speed_frac * self.p.v_max, "via")
            else:
                self._start_test_leg()
        else:  # leave
            self.vertex = -1
            self.mode = Mode.IDLE
            self._set_state("idle")
            self.progress = 1.0
            self._set_task_state("done")

    def _start_test_leg(self) -> None:
        task = self.task
        self._enter_open(task.direction, task.distance,
                         self.p.test_drive_speed_frac * self.p.v_max, "test")

    def _via_failed(self, why: str) -> None:
        """A probe's approach to its point on the edge failed: home back to the vertex and
        fail with reason "via (<why>)" (no evidence either way)."""
        self.return_reason = f"via ({why})"
        goal = self._task_goal(self.task)
        if goal and sum(1 for l in goal if l in self.seen) >= min(2, len(goal)):
            self._enter_home(goal, "return")
        else:
            self._finish("failed", self.return_reason)

    def _finish(self, task_state: str, reason: str = "") -> None:
        """End the current task and hold station where the robot is."""
        if task_state == "done":
            self.progress = 1.0
        self._set_task_state(task_state, reason)
        self._enter_record()

    # ------------------------------------------------------------------ idle

    def _tick_idle(self):
        return 0.0, 0.0

    # ------------------------------------------------------------------ holding

    def _enter_record(self) -> None:
        self.mode = Mode.RECORD
        self._set_state("holding")
        self.window = {}
        self.record_n = 0
        self.station = False
        self.target = {}
        self.target_frame = None

    def _push_window(self) -> None:
        size = self.p.hold_window
        win = self.window
        for i, b in self.seen.items():
            w = win.get(i)
            if w is None:
                w = win[i] = deque(maxlen=size)
            w.append(b)

    def _tick_record(self):
        self._push_window()
        self.record_n += 1
        if self.task is not None and self.task.kind == "hold" and self.task_state == "running":
            self.progress = self.record_n / self.p.hold_window
        if self.record_n >= self.p.hold_window:
            need = max(1, self.p.hold_window // 2)
            self.target = {i: m for i, w in self.window.items()
                           if len(w) >= need and (m := circmean(w)) is not None}
            self.target_frame = (FrameTracker.snapshot(self.seen, self.back, self.heading)
                                 if self.p.aligned else None)
            self.mode = Mode.KEEP
            if self.task is not None and self.task.kind == "hold" and self.task_state == "running":
                self._finish_hold()
        return 0.0, 0.0

    def _finish_hold(self) -> None:
        self.progress = 1.0
        self._set_task_state("done")

    def _tick_keep(self):
        p = self.p
        psi = self._psi(self.target_frame)
        target = self.target
        if self.station:
            vis = {l: b for l, b in self.seen.items() if l in target}
            errs = bearing_errors(vis, target, psi)
            valid = {l: e for l, e in errs.items() if abs(e) <= p.gate}
            arrived = self.stop.update(valid)
            if arrived or not valid:
                self.station = False
                self.window = {}
                return 0.0, 0.0
            return homing_velocity({l: vis[l] for l in valid}, target, p.v_max, p.g0, psi)
        self._push_window()
        need = max(1, p.hold_window // 2)
        means: dict[int, float] = {}
        for l in self.seen:
            w = self.window.get(l)
            if w is not None and len(w) >= need:
                m = circmean(w)
                if m is not None:
                    means[l] = m
        errs = bearing_errors(means, target, psi)
        valid = {l: e for l, e in errs.items() if abs(e) <= p.gate}
        mags = sorted((abs(e) for e in valid.values()), reverse=True)
        # A bump moves every bearing except those along the bump, so at least two landmarks
        # show an error; a landmark that moved itself leaves the others unchanged. Only a
        # felt bump (another robot touched us lately) counts: a holding robot is the
        # swarm's static reference and must never chase neighbours that move on purpose.
        bumped = p.hold_rehome and self.t - self.bumped_t <= p.lost_timeout_s
        if bumped and len(mags) >= 2 and mags[0] > p.deadband and mags[1] > p.second:
            self.station = True
            self.stop.reset()
            return homing_velocity({l: self.seen[l] for l in valid}, target, p.v_max, p.g0, psi)
        # still: adopt new neighbours and re-record moved ones once they are steady
        half = p.deadband / 2
        for l, m in means.items():
            w = self.window[l]
            if len(w) < p.hold_window or any(abs(wrap(x - m)) > half for x in w):
                continue
            e = errs.get(l)
            if e is None or abs(e) > p.deadband:
                target[l] = wrap(m - psi)
                if self.target_frame is not None and l in self.back:
                    self.target_frame.adopt(l, self.seen[l], self.back[l], psi)
        horizon = self.t - p.lost_timeout_s
        for l in [l for l in target if self.last_seen_t.get(l, -1e18) < horizon]:
            del target[l]
            self.window.pop(l, None)
        return 0.0, 0.0

    # ------------------------------------------------------------------ homing

    def _enter_home(self, goal: dict[int, float], purpose: str) -> None:
        self.mode = Mode.HOME
        self.home_mark = self.advance
        self.stall_best = math.inf     # smallest max bearing error so far (rad)
        self.stall_t = self.t          # when it last improved by stall_deg
        self.goal = goal
        self.purpose = purpose
        self.stop.reset()
        self.lost_since = None
        self.err0 = None

    def _tick_home(self):
        p = self.p
        goal = self.goal
        psi = self._psi(self.frame)
        vis = {l: b for l, b in self.seen.items() if l in goal}
        need = min(2, len(goal))
        if len(vis) < need or not goal:
            # too few landmarks in view: a goto with a direction hint (the bearing of the
            # target vertex seen from the start) creeps along it, at most ``distance``, until
            # enough of the target's landmarks come into view
            task = self.task
            if (goal and self.purpose == "goto" and task is not None and task.distance > 0
                    and self.advance - self.home_mark < task.distance):
                self.lost_since = None
                d = wrap(task.direction + psi)
                speed = p.scale_speed_frac * p.v_max
                self.intent = d
                return speed * math.cos(d), speed * math.sin(d)
            if self.lost_since is None:
                self.lost_since = self.t
            if not goal or self.t - self.lost_since > p.lost_timeout_s:
                self._home_failed("lost landmarks")
                return 0.0, 0.0
        else:
            self.lost_since = None
        if not vis:
            return 0.0, 0.0
        arrived = self.stop.update(bearing_errors(vis, goal, psi))
        emax = self.stop.max_error()
        if self.err0 is None:
            self.err0 = max(emax, 2 * p.arrive)
        if self.purpose != "return":
            self.progress = 1.0 - max(0.0, emax - p.arrive) / max(self.err0 - p.arrive, 1e-9)
        if arrived and len(vis) >= need:
            self._home_done()
            return 0.0, 0.0
        # stall: the error has stopped shrinking (pressed against a wall, or a target that
        # lies beyond one). A deploy accepts the spot it reached (it is on the obstacle
        # side); a goto or a return fails with "stalled" instead of waiting for its timeout.
        if emax < self.stall_best - math.radians(p.stall_deg):
            self.stall_best = emax
            self.stall_t = self.t
        elif self.t - self.stall_t > p.stall_s and len(vis) >= need:
            if self.purpose == "deploy":
                self.end_reason = "stalled"
                self._after_deploy_motion()
            else:
                self._home_failed("stalled")
            return 0.0, 0.0
        ux, uy = homing_velocity(vis, goal, p.v_max, p.g0, psi)
        return ux, uy

    def _home_done(self) -> None:
        if self.purpose == "goto":
            self._finish("done")
        elif self.purpose == "deploy":
            self._after_deploy_motion()
        elif self.purpose == "return":
            self._finish("failed", self.return_reason)
        elif self.purpose == "via":
            self._start_test_leg()
        else:
            self._finish("done")

    def _home_failed(self, why: str) -> None:
        if self.purpose == "via":
            self._via_failed(why)
            return
        self._finish("failed", self._fail_reason(why))

    # ------------------------------------------------------------------ open loop

    def _enter_open(self, direction: float, distance: float, speed: float, purpose: str,
                    single: int | None = None) -> None:
        self.mode = Mode.OPEN
        self.ol_dir = direction
        self.ol_dist = distance
        self.ol_speed = speed
        self.purpose = purpose
        self.single = single
        self.mark = self.advance
        self.blocked_since = None

    def _open_direction(self) -> float:
        return wrap(self.ol_dir + self._psi(self.frame))

    def _tick_open(self):
        p = self.p
        d = self._open_direction()
        done = self.advance - self.mark
        remaining = self.ol_dist - done
        if self.purpose != "return":
            self.progress = done / self.ol_dist if self.ol_dist > 0 else 1.0
        if remaining <= 1e-4 * p.rv:
            self._open_done()
            return 0.0, 0.0
        if self.purpose == "test" and any(blocks(d, c, p.tau) for c in self.obst):
            task = self.task
            if task is not None and 0 < task.keep_after <= done:
                # far enough out: the robot stays against the wall as the new vertex
                self.contact_pinned = True
                self._finish("done", "wall")
                return 0.0, 0.0
            # the blocking sector nearest the direction driven: the wall's normal is within
            # tau of its centre, which the fence uses to re-drive the probe along it
            self.touch_offset = min((wrap(c - d) for c in self.obst if blocks(d, c, p.tau)),
                                    key=abs)
            self._test_touch()
            return self._ticks[self.mode]()
        if self.single is not None and self.n - self.last_seen.get(self.single, -10**9) \
                >= p.link_lost_ticks:
            self.mode = Mode.OPEN_BACK
            self.out_dist = done
            self.mark = self.advance
            return self._tick_open_back()
        speed = min(self.ol_speed, remaining / max(self.dt, 1e-3))
        ux, uy = speed * math.cos(d), speed * math.sin(d)
        if self._blocked(ux, uy, d):
            if self.purpose == "deploy":
                self.end_reason = "blocked"
                self._after_deploy_motion()
                return 0.0, 0.0
            if self.purpose == "return":
                self._finish("failed", f"{self.return_reason} (return: blocked)")
                return 0.0, 0.0
            if self.purpose == "via":
                self._via_failed("blocked")
                return 0.0, 0.0
        self.intent = d
        return ux, uy

    def _blocked(self, ux: float, uy: float, d: float) -> bool:
        """Whether walls have kept the motion along d below 10% of the command for
        blocked_s."""
        if self.obst:
            sx, sy = slide(ux, uy, self.obst, self.p.tau)
            if sx * math.cos(d) + sy * math.sin(d) < 0.1 * math.hypot(ux, uy):
                if self.blocked_since is None:
                    self.blocked_since = self.t
                return self.t - self.blocked_since >= self.p.blocked_s
        self.blocked_since = None
        return False

    def _tick_open_back(self):
        """Single-landmark deploy lost its link: reverse until the landmark is seen again."""
        p = self.p
        back = self.advance - self.mark
        if self.single in self.seen and self.n - self.last_seen.get(self.single, -10**9) == 0 \
                and back > 0:
            self._finish("done", "link lost, backed up")
            return 0.0, 0.0
        if back >= self.out_dist:
            self._finish("failed", "lost landmarks")
            return 0.0, 0.0
        d = wrap(self._open_direction() + PI)
        speed = min(self.ol_speed, (self.out_dist - back) / max(self.dt, 1e-3))
        self.intent = d
        return speed * math.cos(d), speed * math.sin(d)

    def _open_done(self) -> None:
        if self.purpose == "deploy":
            self._after_deploy_motion()
        elif self.purpose == "return":
            goal, self.return_goal = self.return_goal, None
            if goal and sum(1 for l in goal if l in self.seen) >= min(2, len(goal)):
                self._enter_home(goal, "return")
            else:
                self._finish("failed", self.return_reason)
        elif self.purpose == "via":
            self._start_test_leg()
        else:  # test drive completed without a blocking touch
            self._finish("done")

    def _test_touch(self) -> None:
        """Test drive hit an obstacle: keep the contact, go back, fail with "touch"."""
        self.contact_pinned = True
        self.changed = True
        # first reverse what was driven (always possible: open loop), then re-home on the
        # vertex's bearings if any; a landmark lost during the drive cannot strand us
        travelled = self.advance - self.mark
        self.return_goal = self._task_goal(self.task)
        self._enter_open(wrap(self.ol_dir + PI), max(0.0, travelled), self.ol_speed, "return")

    # ------------------------------------------------------------------ scale correction

    def _after_deploy_motion(self) -> None:
        task = self.task
        if task is not None and task.scale_correct:
            self._enter_scale()
        else:
            self._finish("done", self.end_reason)

    def _enter_scale(self) -> None:
        goal = self._task_goal(self.task)
        self.refs = [l for l in goal if l in self.seen]
        if not self.refs:
            self._finish("done", "scale skipped: no reference in view")
            return
        self.ref_bearing = {l: self.seen[l] for l in self.refs}
        self.ref_heading = {l: self.heading for l in self.refs}
        self.mode = Mode.SCALE_OUT
        self.mark = self.advance
        self.blocked_since = None

    def _tick_scale_out(self):
        p = self.p
        for l in self.refs:
            if l in self.seen:
                self.ref_bearing[l] = self.seen[l]
                self.ref_heading[l] = self.heading
        out = self.advance - self.mark
        lost = [l for l in self.refs if self.n - self.last_seen.get(l, -10**9) >= p.link_lost_ticks]
        if lost:
            self.mode = Mode.SCALE_BACK
            self.out_dist = out
            self.mark = self.advance
            self.step_left = 0.0
            self.settle_left = 0
            self.margin_left = p.scale_margin_steps
            self._start_back_step()
            return self._tick_scale_back()
        if out >= p.scale_max_rv * p.rv:
            self._finish("done", "scale: no link lost")
            return 0.0, 0.0
        known = self._ref_now()
        d = away_direction(known)
        if d is None or resultant(known) < 0.2:
            self._finish("done", "scale skipped: references surround the robot")
            return 0.0, 0.0
        speed = p.scale_speed_frac * p.v_max
        ux, uy = speed * math.cos(d), speed * math.sin(d)
        if self._blocked(ux, uy, d):
            self._finish("done", "scale: blocked")
            return 0.0, 0.0
        self.intent = d
        self.progress = min(0.5, 0.5 * out / (p.scale_max_rv * p.rv))
        return ux, uy

    def _ref_now(self) -> list[float]:
        """Reference bearings in the current body frame: a landmark out of view keeps its
        last bearing, turned by the (dead-reckoned) rotation since it was seen."""
        return [wrap(b - (self.heading - self.ref_heading.get(l, self.heading)))
                for l, b in self.ref_bearing.items()]

    def _start_back_step(self) -> None:
        self.step_left = self.p.scale_step_rv * self.p.rv
        self.step_mark = self.advance

    def _tick_scale_back(self):
        p = self.p
        for l in self.refs:
            if l in self.seen:
                self.ref_bearing[l] = self.seen[l]
                self.ref_heading[l] = self.heading
        self.back_dist = self.advance - self.mark
        self.progress = 0.5 + 0.5 * min(1.0, self.back_dist / max(self.out_dist, 1e-9))
        if self.step_left > 0:
            left = self.step_left - (self.advance - self.step_mark)
            if left > 1e-6:
                d = circmean(self._ref_now())
                if d is None:
                    self._finish("failed", "lost landmarks")
                    return 0.0, 0.0
                speed = min(p.scale_speed_frac * p.v_max, left / max(self.dt, 1e-3))
                self.intent = d
                return speed * math.cos(d), speed * math.sin(d)
            self.step_left = 0.0
            self.settle_left = p.settle_ticks
            return 0.0, 0.0
        if self.settle_left > 1:
            self.settle_left -= 1
            return 0.0, 0.0
        self.settle_left = 0
        if all(l in self.seen for l in self.refs):
            if self.margin_left <= 0:
                self._finish("done", self.end_reason)
                return 0.0, 0.0
            self.margin_left -= 1
        elif self.back_dist > self.out_dist + 0.1 * p.rv:
            self._finish("failed", "lost landmarks")
            return 0.0, 0.0
        self._start_back_step()
        return self._tick_scale_back()

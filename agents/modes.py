"""The behaviour's modes: one small class each, pure (no I/O, no clock but ``Sense.t``).

A mode object holds only its own state and is made when the mode is entered. Each tick,
:meth:`ModeState.tick` gets the shared :class:`Context` (parameters and
:class:`~agents.perception.Perception`) and returns a :class:`Tick`: a body-frame velocity
(m/s) with the direction it means (rad), the task's progress if the mode reports it, and an
:class:`Outcome` saying what happened. Outcomes that end a leg (arrived, blocked, ...) are
turned into the next mode by the task life cycle in :mod:`agents.behaviours`, which knows
the task and its :class:`Phase`; a mode that simply goes on in another mode returns it in
``Tick.next``.

This module has the shared types and the holding and homing modes; the open-loop modes are
in :mod:`agents.openloop`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import StrEnum

from .control import (FIX_SPREAD, FrameTracker, StopRule, bearing_errors, bearing_spread, circmean,
                      homing_velocity, wrap)
from .params import AgentParams
from .perception import Perception


class Mode(StrEnum):
    """What the behaviour does this tick; each has one :class:`ModeState` class. A StrEnum:
    equal to its name as a string."""
    IDLE = "idle"              # no task
    RECORD = "record"          # holding: recording the landmarks' bearings
    KEEP = "keep"              # holding: keeping them (station keeping if enabled)
    HOME = "home"              # homing on target bearings (goto, deploy, return)
    OPEN = "open"              # driving out on a heading (test drive, probe, spawn entry)
    OPEN_BACK = "open_back"    # back along it after a touch or a lost link
    SCALE_OUT = "scale_out"    # rv scale measurement: out until a neighbour is lost
    SCALE_BACK = "scale_back"  # and back until it is seen again
    SWEEP = "sweep"            # sliding along a wall a test drive touched (agents.sweep)


MOVING_MODES = frozenset({Mode.HOME, Mode.OPEN, Mode.OPEN_BACK, Mode.SCALE_OUT, Mode.SCALE_BACK,
                          Mode.SWEEP})


class Phase(StrEnum):
    """Why the robot is homing or driving open loop within its task."""
    NONE = ""              # no homing or open-loop leg yet (or holding, idle)
    GOTO = "goto"          # a goto task's homing
    DEPLOY = "deploy"      # a deploy task's motion (homing, or open loop with < 2 landmarks)
    VIA = "via"            # a probe's approach to its point on the edge
    TEST = "test"          # a test drive's leg along its direction
    RETURN = "return"      # back to the vertex after a test drive's touch or failed approach


class Outcome(StrEnum):
    """What a mode's tick reports besides its velocity (the task life cycle acts on it)."""
    RUNNING = "running"    # go on in this mode
    SWITCH = "switch"      # go on in ``Tick.next``, ticking it at once
    HELD = "held"          # record: the snapshot exists; keep it (``Tick.next``) from now on
    ARRIVED = "arrived"    # home: every bearing error stayed within arrive_deg
    DRIVEN = "driven"      # open: the leg's distance is covered
    FAILED = "failed"      # home: ``reason`` (its phase decides what follows)
    STALLED = "stalled"    # home: the error stopped shrinking
    BLOCKED = "blocked"    # open: walls kept the motion below 10% for blocked_s
    TOUCH = "touch"        # open (test leg): a touch blocks the direction (``Tick.offset``)
    WALL = "wall"          # open (test leg): the touch came past keep_after: stay there
    SWEPT = "swept"        # sweep: no opening found; ``reason`` says what it joined
    DONE = "done"          # the task is done, with ``reason``
    GAVE_UP = "gave_up"    # the task failed, with ``reason``


@dataclass(slots=True)
class Tick:
    """One mode tick's result. ``ux``, ``uy``: body-frame velocity (m/s) before wall
    sliding and clamping; ``intent``: the body-frame direction (rad) it means, for dead
    reckoning (None: none); ``progress``: the task's progress in [0, 1], or None to leave it;
    ``outcome``, with ``reason`` (DONE, GAVE_UP, FAILED, SWEPT), ``next`` (SWITCH, HELD)
    and ``offset`` (TOUCH: touch sector centre - direction driven, rad); ``slide``: False
    for a velocity meant to press into the walls it touches (a sweep), not slid along
    them."""
    ux: float = 0.0
    uy: float = 0.0
    intent: float | None = None
    progress: float | None = None
    outcome: Outcome = Outcome.RUNNING
    reason: str = ""
    next: ModeState | None = None
    offset: float = 0.0
    slide: bool = True


def drive(speed: float, d: float, progress: float | None = None) -> Tick:
    """Move at ``speed`` (m/s) along body-frame direction ``d`` (rad)."""
    return Tick(speed * math.cos(d), speed * math.sin(d), intent=d, progress=progress)


@dataclass(slots=True)
class Context:
    """What every mode reads: the agent's parameters and its perception."""
    p: AgentParams
    see: Perception


class ModeState:
    """Base of the mode classes: ``mode`` names it; :meth:`tick` runs one Sense tick."""
    mode: Mode = Mode.IDLE

    def tick(self, ctx: Context) -> Tick:
        return Tick()

    def still_window(self) -> dict[int, deque] | None:
        """Per landmark, the window of recent bearings (rad) while holding still (Status
        reports their means); None when not holding still."""
        return None

    def watching(self) -> bool:
        """Whether this mode, left alone, only watches: it commands no motion and changes
        nothing until what the robot senses changes (the agent is then idle)."""
        return False


class Idle(ModeState):
    """No task (or after ``leave``): stand still."""
    mode = Mode.IDLE

    def watching(self) -> bool:
        return True


def push_window(window: dict[int, deque], seen: dict[int, float], size: int) -> None:
    """Append this tick's bearings (rad) to each landmark's window of ``size`` ticks."""
    for i, b in seen.items():
        w = window.get(i)
        if w is None:
            w = window[i] = deque(maxlen=size)
        w.append(b)


class Record(ModeState):
    """Holding: stand still for hold_window ticks and average each landmark's bearing into
    the snapshot that :class:`Keep` then keeps. ``reports``: the task is a running hold,
    whose progress this is and which is done once the snapshot exists."""
    mode = Mode.RECORD

    def __init__(self, reports: bool):
        self.reports = reports
        self.window: dict[int, deque] = {}
        self.count = 0               # ticks recorded

    def still_window(self):
        return self.window

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        push_window(self.window, see.seen, p.hold_window)
        self.count += 1
        progress = self.count / p.hold_window if self.reports else None
        if self.count < p.hold_window:
            return Tick(progress=progress)
        need = max(1, p.hold_window // 2)
        target = {i: m for i, w in self.window.items()
                  if len(w) >= need and (m := circmean(w)) is not None}
        frame = see.snapshot_frame() if p.aligned else None
        return Tick(progress=progress, outcome=Outcome.HELD,
                    next=Keep(self.window, target, frame))


class Keep(ModeState):
    """Holding: keep the snapshot ``target`` (landmark -> bearing, rad, in ``frame``).

    Re-home (station keeping) when a felt bump moved two landmarks' averaged bearings
    beyond hold_deadband_deg and hold_second_deg; otherwise adopt new neighbours and
    re-record moved ones once steady, and drop those unseen for lost_timeout_s."""
    mode = Mode.KEEP

    def __init__(self, window: dict[int, deque], target: dict[int, float],
                 frame: FrameTracker | None):
        self.window = window
        self.target = target
        self.frame = frame
        self.station = False         # station keeping is homing back
        self.stop: StopRule | None = None

    def still_window(self):
        return None if self.station else self.window

    def watching(self) -> bool:
        return not self.station

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        psi = see.psi(self.frame)
        target = self.target
        if self.station:
            return self._rehome(ctx, psi)
        push_window(self.window, see.seen, p.hold_window)
        need = max(1, p.hold_window // 2)
        means: dict[int, float] = {}
        for l in see.seen:
            w = self.window.get(l)
            if w is not None and len(w) >= need:
                m = circmean(w)
                if m is not None:
                    means[l] = m
        errs = bearing_errors(means, target, psi)
        # A bump moves every bearing except those along the bump, so at least two landmarks
        # show an error; a landmark that moved itself leaves the others unchanged. Only a
        # felt bump (another robot touched us lately) counts: a holding robot is the
        # swarm's static reference and must never chase neighbours that move on purpose.
        if p.hold_rehome and see.t - see.bumped_t <= p.lost_timeout_s:
            valid = {l: e for l, e in errs.items() if abs(e) <= p.gate}
            mags = sorted((abs(e) for e in valid.values()), reverse=True)
            if len(mags) >= 2 and mags[0] > p.deadband and mags[1] > p.second:
                self.station = True
                self.stop = StopRule(p.arrive, p.arrive_ticks, p.error_alpha)
                ux, uy = homing_velocity({l: see.seen[l] for l in valid}, target, p.v_max,
                                         p.g0, psi)
                return Tick(ux, uy)
        # still: adopt new neighbours and re-record moved ones once they are steady (a
        # landmark within the deadband of its target needs neither: checked first, cheaply)
        half = p.deadband / 2
        for l, m in means.items():
            e = errs.get(l)
            if e is not None and abs(e) <= p.deadband:
                continue
            w = self.window[l]
            if len(w) < p.hold_window or any(abs(wrap(x - m)) > half for x in w):
                continue
            target[l] = wrap(m - psi)
            if self.frame is not None and l in see.back:
                self.frame.adopt(l, see.seen[l], see.back[l], psi)
        horizon = see.t - p.lost_timeout_s
        for l in [l for l in target if see.last_seen_t.get(l, -1e18) < horizon]:
            del target[l]
            self.window.pop(l, None)
        return Tick()

    def _rehome(self, ctx: Context, psi: float) -> Tick:
        """Station keeping: home back onto the snapshot until the stop rule holds."""
        p, target = ctx.p, self.target
        vis = {l: b for l, b in ctx.see.seen.items() if l in target}
        errs = bearing_errors(vis, target, psi)
        valid = {l: e for l, e in errs.items() if abs(e) <= p.gate}
        arrived = self.stop.update(valid)
        if arrived or not valid:
            self.station = False
            self.window = {}
            return Tick()
        ux, uy = homing_velocity({l: vis[l] for l in valid}, target, p.v_max, p.g0, psi)
        return Tick(ux, uy)


class Home(ModeState):
    """Visual homing on ``goal`` (landmark -> bearing, rad, in ``frame``), for ``phase``.

    Fails ("lost landmarks") when fewer than 2 (or all, if fewer) goal landmarks stay out of
    view for lost_timeout_s; a goto with a direction hint first goes along ``creep_dir``
    (rad, reference frame) for at most ``creep_dist`` (m): slowly until enough come into
    view, at the deploy speed while those in view fix no point (one, or all in line with
    the target). Stalls when the largest error has not shrunk by stall_deg for stall_s
    (arrives instead when that error is within the arrival tolerance)."""
    mode = Mode.HOME

    def __init__(self, goal: dict[int, float], phase: Phase, frame: FrameTracker | None,
                 ctx: Context, creep_dir: float = 0.0, creep_dist: float = 0.0):
        p, see = ctx.p, ctx.see
        self.goal = goal
        self.phase = phase
        self.frame = frame
        self.creep_dir = creep_dir
        self.creep_dist = creep_dist
        self.mark = see.advance        # dead-reckoned advance when homing started (m)
        self.stall_best = math.inf     # smallest max bearing error so far (rad)
        self.stall_t = see.t           # when it last improved by stall_deg (s)
        self.stop = StopRule(p.arrive, p.arrive_ticks, p.error_alpha)
        self.lost_since: float | None = None
        self.err0: float | None = None

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        goal = self.goal
        psi = see.psi(self.frame)
        vis = {l: b for l, b in see.seen.items() if l in goal}
        need = min(2, len(goal))
        few = len(vis) < need
        if (goal and self.phase is Phase.GOTO and self.creep_dist > 0
                and see.advance - self.mark < self.creep_dist
                and (few or bearing_spread(goal[l] for l in vis) < FIX_SPREAD)):
            # the landmarks in view do not fix the target: too few (it creeps, slowly,
            # until enough come into view), or all in line with it (one bearing fixes a
            # ray, and in single file the mover saw the target's bearings from its start
            # already: it drives, at the deploy speed). A goto with a direction hint (the
            # bearing of the target vertex seen from the start) goes along it open loop, at
            # most ``distance`` (spec 4.6, "only one landmark"), then homes on what it sees
            self.lost_since = None
            speed = p.scale_speed_frac if few else p.deploy_speed_frac
            return drive(speed * p.v_max, wrap(self.creep_dir + psi))
        if len(vis) < need or not goal:
            if self.lost_since is None:
                self.lost_since = see.t
            if not goal or see.t - self.lost_since > p.lost_timeout_s:
                return Tick(outcome=Outcome.FAILED, reason="lost landmarks")
        else:
            self.lost_since = None
        if not vis:
            return Tick()
        arrived = self.stop.update(bearing_errors(vis, goal, psi),
                                   {l: goal[l] + psi for l in vis} if p.arrive_offset else None)
        emax = self.stop.max_error()
        if self.err0 is None:
            self.err0 = max(emax, 2 * p.arrive)
        progress = None
        if self.phase is not Phase.RETURN:
            progress = 1.0 - max(0.0, emax - p.arrive) / max(self.err0 - p.arrive, 1e-9)
        if arrived and len(vis) >= need:
            return Tick(progress=progress, outcome=Outcome.ARRIVED)
        # stall: the error has stopped shrinking (pressed against a wall, or a target that
        # lies beyond one). A deploy accepts the spot it reached (it is on the obstacle
        # side); a goto or a return fails with "stalled" instead of waiting for its timeout.
        if emax < self.stall_best - math.radians(p.stall_deg):
            self.stall_best = emax
            self.stall_t = see.t
        elif see.t - self.stall_t > p.stall_s and len(vis) >= need:
            if emax < p.arrive:
                # every bearing is within the tolerance and only the offset test is not
                # met: the robot is as near as these bearings tell, not stalled
                return Tick(progress=progress, outcome=Outcome.ARRIVED)
            return Tick(progress=progress, outcome=Outcome.STALLED)
        ux, uy = homing_velocity(vis, goal, p.v_max, p.g0, psi)
        return Tick(ux, uy, progress=progress)

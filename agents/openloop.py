"""The open-loop modes: legs driven on dead reckoning, and the rv scale correction.

See :mod:`agents.modes` for the shared types. Directions are in rad (a leg's in its
reference frame, the commands' in the body frame), distances in m, speeds in m/s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .control import FrameTracker, away_direction, blocks, circmean, resultant, slide, wrap
from .modes import Context, Mode, ModeState, Outcome, Phase, Tick, drive
from .perception import Perception

PI = math.pi
# a leg that lost sight of the landmarks it keeps backs up this much (x rv) past where one
# came back into view (a test leg's, a sweep's opening)
SIGHT_MARGIN_RV = 0.1


class BlockTimer:
    """Whether walls have kept the motion along a direction below 10% of the command for
    blocked_s (s)."""

    __slots__ = ("since",)

    def __init__(self):
        self.since: float | None = None   # when the motion was first held back (s)

    def blocked(self, ctx: Context, ux: float, uy: float, d: float) -> bool:
        """Update with this tick's command (body frame, m/s) along direction ``d`` (rad)."""
        see, p = ctx.see, ctx.p
        if see.obst:
            sx, sy = slide(ux, uy, see.obst, p.tau)
            if sx * math.cos(d) + sy * math.sin(d) < 0.1 * math.hypot(ux, uy):
                if self.since is None:
                    self.since = see.t
                return see.t - self.since >= p.blocked_s
        self.since = None
        return False


@dataclass(frozen=True, slots=True)
class Leg:
    """An open-loop leg: ``distance`` (m) along ``direction`` (rad, in reference frame
    ``frame``; the body frame at the start without one) at ``speed`` (m/s), for ``phase``.
    ``single``: the one landmark a deploy keeps in sight (None: none); ``keep_after``: a
    test leg touching a wall past this distance (m, 0: never) stays there; ``keep``: the
    landmarks a test leg keeps in sight (its vertex's: at least one of them, or the new
    robot is cut off from the swarm; empty: none)."""
    direction: float
    distance: float
    speed: float
    phase: Phase
    frame: FrameTracker | None = None
    single: int | None = None
    keep_after: float = 0.0
    keep: tuple[int, ...] = ()

    @property
    def watched(self) -> tuple[int, ...]:
        """The landmarks the leg must not lose all of: ``single``'s, else ``keep``."""
        return (self.single,) if self.single is not None else self.keep

    def body_direction(self, see: Perception) -> float:
        """The leg's direction in the current body frame (rad)."""
        return wrap(self.direction + see.psi(self.frame))


class Open(ModeState):
    """Drive a :class:`Leg`.

    The test leg (phase TEST) reports a touch that blocks its direction (WALL once past
    ``keep_after``); with a ``single`` landmark, losing it for link_lost_ticks turns into
    :class:`OpenBack`, and so does a test leg losing every landmark of ``keep`` (the
    thesis's stop when about to lose sight); deploy, return and via legs stop when
    blocked."""
    mode = Mode.OPEN
    STOPS_WHEN_BLOCKED = frozenset({Phase.DEPLOY, Phase.RETURN, Phase.VIA})

    def __init__(self, leg: Leg, see: Perception):
        self.leg = leg
        self.mark = see.advance          # dead-reckoned advance at the start (m)
        self.timer = BlockTimer()

    def travelled(self, see: Perception) -> float:
        """Distance driven along the leg so far (m)."""
        return see.advance - self.mark

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        leg = self.leg
        d = leg.body_direction(see)
        done = self.travelled(see)
        remaining = leg.distance - done
        progress = None
        if leg.phase is not Phase.RETURN:
            progress = done / leg.distance if leg.distance > 0 else 1.0
        if remaining <= 1e-4 * p.rv:
            return Tick(progress=progress, outcome=Outcome.DRIVEN)
        if leg.phase is Phase.TEST and any(blocks(d, c, p.tau) for c in see.obst):
            if 0 < leg.keep_after <= done:
                # far enough out: the robot stays against the wall as the new vertex
                return Tick(progress=progress, outcome=Outcome.WALL)
            # the blocking sector nearest the direction driven: the wall's normal is within
            # tau of its centre, which the fence uses to re-drive the probe along it
            offset = min((wrap(c - d) for c in see.obst if blocks(d, c, p.tau)), key=abs)
            return Tick(progress=progress, outcome=Outcome.TOUCH, offset=offset)
        watched = leg.watched
        if watched and all(see.ticks_unseen(l) >= p.link_lost_ticks for l in watched):
            # a single-landmark deploy backs up until it is in view; a test leg a margin more
            margin = 0.0 if leg.single is not None else SIGHT_MARGIN_RV * p.rv
            return Tick(progress=progress, outcome=Outcome.SWITCH,
                        next=OpenBack(leg, done, see, margin=margin))
        speed = min(leg.speed, remaining / max(see.dt, 1e-3))
        ux, uy = speed * math.cos(d), speed * math.sin(d)
        if self.timer.blocked(ctx, ux, uy, d) and leg.phase in self.STOPS_WHEN_BLOCKED:
            return Tick(progress=progress, outcome=Outcome.BLOCKED)
        return Tick(ux, uy, intent=d, progress=progress)


class OpenBack(ModeState):
    """A leg lost sight of the landmarks it keeps (a single-landmark deploy's ``single``, a
    test leg's or a sweep's opening ``keep``): reverse the ``out_dist`` (m) driven out until
    one is seen again and ``margin`` (m) farther (DONE with ``reason``), or fail if none is
    by then (with ``stay``: DONE with ``reason`` there all the same)."""
    mode = Mode.OPEN_BACK

    def __init__(self, leg: Leg, out_dist: float, see: Perception, margin: float = 0.0,
                 reason: str = "link lost, backed up", stay: bool = False):
        self.leg = leg
        self.out_dist = out_dist         # distance driven out (m)
        self.mark = see.advance
        self.keep = leg.watched
        self.margin = margin
        self.reason, self.stay = reason, stay
        self.seen_at: float | None = None   # backed up when one came back into view (m)

    def left(self, see: Perception) -> float:
        """What is still to reverse of the way driven out (m, >= 0)."""
        return max(0.0, self.out_dist - (see.advance - self.mark))

    def tick(self, ctx: Context) -> Tick:
        see, leg = ctx.see, self.leg
        back = see.advance - self.mark
        if self.seen_at is None and back > 0 and any(
                l in see.seen and see.ticks_unseen(l) == 0 for l in self.keep):
            self.seen_at = back
        if self.seen_at is not None and (back >= self.seen_at + self.margin
                                         or back >= self.out_dist):
            return Tick(outcome=Outcome.DONE, reason=self.reason)
        if back >= self.out_dist:
            if self.stay:
                return Tick(outcome=Outcome.DONE, reason=self.reason)
            return Tick(outcome=Outcome.GAVE_UP, reason="lost landmarks")
        d = wrap(leg.body_direction(see) + PI)
        return drive(min(leg.speed, (self.out_dist - back) / max(see.dt, 1e-3)), d)


class Refs:
    """Scale correction's reference landmarks ``ids`` with their last seen bearings (rad,
    body frame then) and the dead-reckoned heading (rad) they were seen at."""

    __slots__ = ("ids", "bearing", "heading")

    def __init__(self, ids: list[int], see: Perception):
        self.ids = ids
        self.bearing = {l: see.seen[l] for l in ids}
        self.heading = {l: see.heading for l in ids}

    def track(self, see: Perception) -> None:
        for l in self.ids:
            if l in see.seen:
                self.bearing[l] = see.seen[l]
                self.heading[l] = see.heading

    def now(self, see: Perception) -> list[float]:
        """Reference bearings in the current body frame: a landmark out of view keeps its
        last bearing, turned by the (dead-reckoned) rotation since it was seen."""
        return [wrap(b - (see.heading - self.heading.get(l, see.heading)))
                for l, b in self.bearing.items()]


class ScaleOut(ModeState):
    """rv scale measurement: drive away from the references (``refs``, all in view at the
    start) until one is lost for link_lost_ticks, then :class:`ScaleBack`. ``end_reason``:
    the deploy's own reason, reported when the correction ends normally."""
    mode = Mode.SCALE_OUT

    def __init__(self, refs: list[int], see: Perception, end_reason: str):
        self.refs = Refs(refs, see)
        self.end_reason = end_reason
        self.mark = see.advance
        self.timer = BlockTimer()

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        self.refs.track(see)
        out = see.advance - self.mark
        if any(see.ticks_unseen(l) >= p.link_lost_ticks for l in self.refs.ids):
            return Tick(outcome=Outcome.SWITCH, next=ScaleBack(self, out, ctx))
        if out >= p.scale_max_rv * p.rv:
            return Tick(outcome=Outcome.DONE, reason="scale: no link lost")
        known = self.refs.now(see)
        d = away_direction(known)
        if d is None or resultant(known) < 0.2:
            return Tick(outcome=Outcome.DONE, reason="scale skipped: references surround the robot")
        speed = p.scale_speed_frac * p.v_max
        ux, uy = speed * math.cos(d), speed * math.sin(d)
        if self.timer.blocked(ctx, ux, uy, d):
            return Tick(outcome=Outcome.DONE, reason="scale: blocked")
        return Tick(ux, uy, intent=d, progress=min(0.5, 0.5 * out / (p.scale_max_rv * p.rv)))


class ScaleBack(ModeState):
    """Back towards the references in steps of scale_step_rv * rv, settling settle_ticks
    after each, until all are seen again and scale_margin_steps more steps are made (DONE),
    or fail once ``out_dist`` + 0.1 rv is exceeded without them."""
    mode = Mode.SCALE_BACK

    def __init__(self, out: ScaleOut, out_dist: float, ctx: Context):
        self.refs = out.refs
        self.end_reason = out.end_reason
        self.out_dist = out_dist         # distance driven out (m)
        self.mark = ctx.see.advance
        self.settle_left = 0             # ticks still to stand after a step
        self.margin_left = ctx.p.scale_margin_steps
        self._start_step(ctx)

    def _start_step(self, ctx: Context) -> None:
        self.step_left = ctx.p.scale_step_rv * ctx.p.rv   # length of the step (m)
        self.step_mark = ctx.see.advance

    def tick(self, ctx: Context) -> Tick:
        p, see = ctx.p, ctx.see
        self.refs.track(see)
        back = see.advance - self.mark
        progress = 0.5 + 0.5 * min(1.0, back / max(self.out_dist, 1e-9))
        if self.step_left > 0:
            left = self.step_left - (see.advance - self.step_mark)
            if left > 1e-6:
                d = circmean(self.refs.now(see))
                if d is None:
                    return Tick(progress=progress, outcome=Outcome.GAVE_UP,
                                reason="lost landmarks")
                return drive(min(p.scale_speed_frac * p.v_max, left / max(see.dt, 1e-3)), d,
                             progress)
            self.step_left = 0.0
            self.settle_left = p.settle_ticks
            return Tick(progress=progress)
        if self.settle_left > 1:
            self.settle_left -= 1
            return Tick(progress=progress)
        self.settle_left = 0
        if all(l in see.seen for l in self.refs.ids):
            if self.margin_left <= 0:
                return Tick(progress=progress, outcome=Outcome.DONE, reason=self.end_reason)
            self.margin_left -= 1
        elif back > self.out_dist + 0.1 * p.rv:
            return Tick(progress=progress, outcome=Outcome.GAVE_UP, reason="lost landmarks")
        self._start_step(ctx)
        return self.tick(ctx)

"""The wall sweep: a test drive's touch followed along the wall (Task.sweep_*).

Pure, like every mode (see :mod:`agents.modes`): no I/O, ``Sense.t`` the only clock. The
rule is the coordinator's (coordinator.topology.evidence); bench/sweep.py emulates it on
a polygon map.

Where the robot is comes from bearings alone: the task gives the positions of some of its
vertex's neighbours (``Task.sweep_landmarks`` / ``sweep_points``: the reference frame, the
vertex at the origin, metres on the coordinator's estimate of the edge's length), and the
lines through them along the bearings they are seen at meet where the robot stands
(:func:`locate`). Only the fractions along the edge and the angle at the vertex are used to
end the sweep, and both are ratios: the scale's error does not move them. Between fixes it
dead-reckons (from the vertex, along the first drive, before any): free, its command; along
a wall it felt, the slowest progress the wall allows, cos(press + tau) cos(tau) of its
speed along the tangent it believes in (the true normal lies within tau of the felt
sector's centre), so it never believes itself farther along than it is: it then sweeps
farther than needed, never less. A fix moves the dead-reckoned place _BLEND of the way to
it (one tick's fix from two landmarks 0.9 m away, with 0.5 deg of noise, is off by a few
centimetres; the blend averages that out over the ticks).

The robot keeps the wall on one hand. Its wall normal n (reference frame) starts as the
centre of the touch sector that stopped the test drive; it moves along cos(press) t +
sin(press) n (t the tangent towards where it goes) without wall sliding, so it presses
into the wall and slides along it (press > 180 / n_touch deg: whatever the true normal in
that sector). n turns towards walls ahead: to the sector 90 deg ahead (a concave corner),
or to the one 45 deg ahead when n's own sector feels nothing (the wall bending towards the
robot; a jamb's tip is felt 45 deg ahead while the wall it ends still touches at n). No
wall felt from 45 deg behind n to 90 deg ahead for sweep_lost_m of travel: the wall ended
or bent away, and n turns one sector back, so the robot goes round the wall's end. Turns
back that add up to 135 deg since the last turn into a wall (the robot is going round the
end of a wall, into what lies behind it: a door, the back of a box) are an opening at
least a body wide: a narrower gap stops the body on its far side, a turn into a wall. A
jagged or bending wall, a niche or a box's corner turn it back as far as forward, or less.
Into an opening the robot drives on along the normal of the wall whose end it went round
(through a door: straight through the wall) until it is ``sweep_depth`` from the edge, or
a touch blocks it, and stays there as a new robot (a clear probe). A wall's touch that
blocks it within a body length (2 radius) is no opening when the robot has not gone round
to the back of the wall it followed last (the normal turned back less than 135 deg since it
last held for a body length: a bump's face or a jagged wall's step was all it went round):
that is a turn into a wall, and the sweep goes on along it. Through a door in a wall
followed for a body length the turn back is 135 deg, and the robot stays, whatever blocks
it behind the door (tests/test_agent_sweep.py). When the wall it went round was a face
shorter than a body length (a bump standing out of the wall: it turned into the bump's
face, then round the bump), neither to the back of the wall held last nor past it, a drive
clear for a body length runs along that wall, not into an opening: it turns to that wall's
normal, meets the wall (a turn into it) and sweeps on; a door there it drives through, an
opening all the same. It stays in sight of its
vertex's landmarks: with none in view it backs out until one is, and a little farther (a
robot that sees nobody is cut off from every source, and the coordinator sends it away).

Phase 1 goes towards the edge's other end until it crosses the edge's perpendicular at
``sweep_far``; phase 2 back past the vertex until it crosses the ray ``sweep_stop`` beyond
the perpendicular there. Room is where the wall leaves the edge's lens (within
``sweep_depth`` of it; :meth:`SweepGeom.held`). With ``Task.sweep_lenses`` (the default
``[coordinator] sweep_lenses``) it must also leave the lens of each segment from the vertex
to another landmark, which keeps the same guarantee (a point in it is as near the vertex or
that landmark as a point of the edge's lens is to an end); the far line must still lie in
the edge's own lens, and the coordinator's first drive goes on while in them (at most d0):
a wall 0.8 m out in front of the next fence side at the vertex is then swept, not taken for
room (pillar_hall seed 0: a row of robots laid along the wall that way). A phase stops
short after sweep_budget_rv of travel, or when a robot's touch sector blocks the way (a robot seen in its span: a wall there may be one).
The edge's other end blocking phase 1 counts as reaching ``sweep_far`` (no third body fits
between them) only when a robot says it touches there (``Perception.told``) and the other
end is the only robot seen that way, on two Sense ticks in a row (the robot holds still
for the second): a wall touched in the sector the other end is seen in, 0.4 m short of it,
once counted, and closed the fence side over a door behind it; so would a third robot
standing in the way, or one whose sighting a single tick dropped
(tests/test_agent_sweep.py).
"""
from __future__ import annotations

import math
from typing import Mapping

from swarmcover.bus.messages import Task, sweep_reason
from swarmcover.ground.geometry import in_lenses, lens_radii

from .control import FrameTracker, blocks, wrap
from .modes import Context, Mode, ModeState, Outcome, Phase, Tick
from .openloop import SIGHT_MARGIN_RV, Leg, OpenBack

PI = math.pi
# two landmarks whose bearings are closer than this to parallel do not fix a point
_MIN_SPREAD = 1.0 - math.cos(math.radians(30.0))
_BLEND = 0.3
# turns round a wall's end (since the last turn into a wall) that make an opening
OPEN_TURN = 3.0 * PI / 4.0


def _only_other(c: float, seen: Mapping[int, float], other: int, tau: float) -> bool:
    """Whether the robot touching in the sector centred on ``c`` (rad, body; +-tau) is
    ``other``: it is seen in that span, and no other robot is seen within 2 tau of c (a
    toucher's bearing lies in the span; a tau's margin for the bearings' noise)."""
    return abs(wrap(seen[other] - c)) <= tau and not any(
        i != other and abs(wrap(b - c)) <= 2.0 * tau for i, b in seen.items())


def locate(bearings: Mapping[int, float], points: Mapping[int, tuple[float, float]]
           ) -> tuple[float, float] | None:
    """Where a robot stands that sees each landmark l of ``points`` at ``bearings[l]``
    (rad, the points' frame): the least-squares meeting point of the lines through the
    points along those bearings (the points' unit). None with fewer than two such
    landmarks, or when their bearings are all within about 30 deg of parallel."""
    sxx = sxy = syy = bx = by = 0.0
    n = 0
    for l, b in bearings.items():
        pt = points.get(l)
        if pt is None:
            continue
        nx, ny = -math.sin(b), math.cos(b)        # the line's normal: n . (R - P) = 0
        c = nx * pt[0] + ny * pt[1]
        sxx += nx * nx
        sxy += nx * ny
        syy += ny * ny
        bx += nx * c
        by += ny * c
        n += 1
    if n < 2:
        return None
    half = 0.5 * (sxx + syy)
    lam = half - math.sqrt(max(half * half - (sxx * syy - sxy * sxy), 0.0))
    if lam < _MIN_SPREAD:
        return None
    det = sxx * syy - sxy * sxy
    return ((syy * bx - sxy * by) / det, (sxx * by - sxy * bx) / det)


class SweepGeom:
    """A sweep's edge in the task's reference frame: the vertex at the origin, the other
    end at ``q`` (the first sweep landmark's point), the side swept ``side`` (+1 CCW of
    the edge's direction), ``far`` (fraction), ``stop`` (rad), ``depth`` (m)."""

    __slots__ = ("ex", "ey", "nx", "ny", "length", "far", "stop", "depth", "points", "other",
                 "lenses")

    def __init__(self, task: Task):
        pts = task.sweep_points
        self.points = {int(l): (float(pts[2 * k]), float(pts[2 * k + 1]))
                       for k, l in enumerate(task.sweep_landmarks)}
        self.other = int(task.sweep_landmarks[0]) if task.sweep_landmarks else -1
        qx, qy = self.points.get(self.other, (math.cos(task.sweep_edge), math.sin(task.sweep_edge)))
        self.length = math.hypot(qx, qy) or 1.0
        self.ex, self.ey = math.cos(task.sweep_edge), math.sin(task.sweep_edge)
        s = 1.0 if task.sweep_side > 0 else -1.0
        self.nx, self.ny = -s * self.ey, s * self.ex
        self.far, self.stop, self.depth = task.sweep_far, task.sweep_stop, task.sweep_depth
        # the landmarks' lenses (the edge's own is depth_of's), none without Task.sweep_lenses
        self.lenses = lens_radii((qx, qy), self.depth,
                                 [pt for l, pt in self.points.items() if l != self.other]
                                 if task.sweep_lenses else [])[1:]

    def frac(self, R) -> float:
        """R's projection on the edge, as a fraction from the vertex."""
        return (R[0] * self.ex + R[1] * self.ey) / self.length

    def phi(self, R) -> float:
        """Angle (rad) at the vertex from the edge's perpendicular to R, positive away from
        the other end."""
        return math.atan2(-(R[0] * self.ex + R[1] * self.ey), R[0] * self.nx + R[1] * self.ny)

    def offset(self, R) -> float:
        """R's signed distance from the edge's line, positive on the side swept (the
        points' unit). Only a place in front of the line (>= -radius / 2) joins the edge:
        a wall that leads behind it (under the vertex, past the edge's end) is in front of
        no part of the edge, though R's projection on it grows there (bench/truth.py
        --doors seed 0 map 145: a floor running under the vertex took a sweep to fraction
        0.35 behind the line, past a 0.47 rv door at the vertex, and the side closed over
        it). A phase that was in front (>= 0) stops short once behind by a radius."""
        return R[0] * self.nx + R[1] * self.ny

    def depth_of(self, R) -> float:
        """Distance from R to the edge segment (the points' unit)."""
        t = min(1.0, max(0.0, self.frac(R))) * self.length
        return math.hypot(R[0] - t * self.ex, R[1] - t * self.ey)

    def held(self, R) -> bool:
        """Whether R lies in the lens of the edge (within ``depth`` of it) or in that of a
        segment from the vertex to another landmark (ground.geometry.lens_radii: the same
        guarantee, within the edge's reach of the vertex or of that landmark). The lenses
        are convex and hold the vertex, so their union is star-shaped from it: a wall
        followed inside it, closed by the edge's perpendicular at ``far`` (inside the edge's
        own lens) and the ray at ``stop``, encloses only what the union holds. A wall that
        leaves every lens leaves room in front of the side."""
        return self.depth_of(R) <= self.depth or in_lenses(R[0], R[1], self.lenses)


class Sweep(ModeState):
    """Slide along the wall touched at body bearing ``n_body`` (rad): see the module
    docstring. ``start``: where the touch happened, dead-reckoned from the vertex (the
    reference frame, m), for when no two landmarks are in view there. Ends DONE "opening"
    / "room" (the robot stays where it is) or SWEPT with the reason
    :func:`bus.messages.sweep_reason`; ``R`` is the last position found (the reference
    frame, m), for the way back."""
    mode = Mode.SWEEP

    def __init__(self, task: Task, frame: FrameTracker | None, n_body: float, ctx: Context,
                 start: tuple[float, float] | None = None):
        see = ctx.see
        self.geom = SweepGeom(task)
        self.frame = frame
        psi = see.psi(frame)
        self.n = wrap(n_body - psi)          # wall normal, reference frame (rad)
        tx, ty = math.cos(self.n - PI / 2.0), math.sin(self.n - PI / 2.0)
        along = tx * self.geom.ex + ty * self.geom.ey
        away = tx * self.geom.nx + ty * self.geom.ny
        # phase 1 keeps the wall on the hand that moves it towards the other end
        self.h = 1 if along > 1e-9 or (abs(along) <= 1e-9 and away > 0.0) else -1
        self.phase = 1
        self.R: tuple[float, float] | None = start   # where it is (reference frame, m)
        self.hi, self.lo = -math.inf, math.inf
        self.last_phi: float | None = None   # phi at the last tick of phase 2 (rad)
        self.armed = False                   # in front of the edge's line since the phase began
        self.lost = 0.0                      # travel with no wall felt (m)
        self.turned = 0.0                    # turned round a wall's end (rad)
        # the turn back (rad, + round a wall's end) since n last held for a body length
        # (a wall followed, not a bump's face), and the travel since n last turned (m)
        self.wound = 0.0
        self.steady = 0.0
        self.before = 0.0                    # the phase's travel before an into-drive (m)
        self.n0 = self.n                     # the normal of the wall it goes round (rad)
        self.n0_held = False                 # that wall was followed for a body length
        self.ref = self.n                    # the normal last held for a body length (rad)
        self.ref_at: tuple[float, float] | None = None   # where it held ``ref`` (m)
        self.turned_in = False               # this into-drive may not turn to ``ref`` (it did, or
                                             # the wall it went round was held, or it is past it)
        self.into: float | None = None       # an opening found: driving into it (rad)
        # landmarks no push moves: an opening's robot keeps one of them in view
        self.keep = tuple(dict.fromkeys(int(l) for l in (*task.sight, *task.sweep_landmarks)))
        self.travelled = 0.0                 # travel in this phase (m)
        self.mark = see.advance
        self.v = (0.0, 0.0)                  # last command (reference frame, m/s)
        self.heard = False                   # the other end said it blocks us, last tick
        self.by: set[int] = set()            # robots seen where a touch stopped a phase

    @classmethod
    def after(cls, out, task: Task, offset: float, ctx: Context) -> "Sweep":
        """The sweep that follows the touch ending ``out``, an :class:`agents.openloop.Open`
        test leg whose blocking touch sector lies ``offset`` (rad) off its direction: the
        wall's normal is that sector, the touch point ``out`` 's travel along its direction
        from the vertex."""
        went, d = out.travelled(ctx.see), out.leg.direction
        return cls(task, out.leg.frame, wrap(out.leg.body_direction(ctx.see) + offset), ctx,
                   (went * math.cos(d), went * math.sin(d)))

    def _felt(self, psi: float, obst) -> dict[int, float]:
        """Touching sectors on the pressed side, by their angle from n towards the tangent
        (-45, 0, 45 or 90 deg, the nearest class) -> the sector (reference frame, rad)."""
        out: dict[int, float] = {}
        for c in obst:
            cr = wrap(c - psi)
            a = math.degrees(-self.h * wrap(cr - self.n))
            k = int(round(a / 45.0)) * 45
            if -45 <= k <= 90 and k not in out:
                out[k] = cr
        return out

    def _end(self, why: str = "") -> Tick:
        lo = -math.inf if why == "end" else self.lo
        hi = self.hi
        if not math.isfinite(hi):
            hi = lo = 0.0                    # never in front of the edge: nothing joined
        return Tick(outcome=Outcome.SWEPT, reason=sweep_reason(hi, lo, self.by))

    def _phase_two(self) -> None:
        """Back towards the vertex: the other hand, counts from zero."""
        self.phase, self.h, self.heard = 2, -self.h, False
        self.last_phi, self.armed = None, False
        self.lost = self.travelled = self.turned = self.wound = self.steady = 0.0
        self.ref, self.ref_at = self.n, self.R

    def _turn(self, n: float, into_wall: bool) -> None:
        """The wall normal becomes ``n`` (reference frame, rad); ``into_wall``: a turn into
        a wall, which ends any count round a wall's end."""
        self.wound += self.h * wrap(n - self.n)
        self.n, self.steady = n, 0.0
        if into_wall:
            self.turned = 0.0

    def _drive_into(self, ctx: Context, psi: float) -> Tick:
        """Into an opening along ``into``: done "opening" (the robot stays there) at
        ``depth`` from the edge or after that far, or when a touch sector, a wall's or a
        robot's, blocks the way. It must stay in sight of the swarm (a robot that sees none
        of its vertex's landmarks is cut off from every source and sent away): once none
        of ``keep`` has been in view for link_lost_ticks it backs out the way it came
        (:class:`agents.openloop.OpenBack`) until one is, then SIGHT_MARGIN_RV farther, and
        stays there, done "opening" all the same."""
        p, see, g = ctx.p, ctx.see, self.geom
        speed = p.sweep_speed_frac * p.v_max
        if (self.keep and self.travelled > 0.0
                and all(see.ticks_unseen(l) >= p.link_lost_ticks for l in self.keep)):
            leg = Leg(self.into, self.travelled, speed, Phase.TEST, self.frame, keep=self.keep)
            return Tick(outcome=Outcome.SWITCH, next=OpenBack(
                leg, self.travelled, see, margin=SIGHT_MARGIN_RV * p.rv, reason="opening",
                stay=True))
        body = wrap(self.into + psi)
        walls = [c for c in see.obst if blocks(body, c, p.tau)]
        bumped = any(blocks(body, c, p.tau) for c in see.bump)
        if (walls and not bumped and self.travelled < 2.0 * p.radius
                and self.wound < OPEN_TURN - 1e-9):
            # a wall across the way within a body length: no opening (a bump's face, a
            # jagged wall), and the robot has not gone round to the back of the wall it
            # followed: a turn into this wall, and the sweep goes on along it
            self._turn(wrap(min(walls, key=lambda c: abs(wrap(c - body))) - psi), True)
            self.lost = 0.0
            self.into, self.travelled = None, self.before + self.travelled
            self.v = (0.0, 0.0)
            return Tick()
        if (not (walls or bumped) and self.travelled >= 2.0 * p.radius
                and not self.turned_in and self.wound < OPEN_TURN - 1e-9):
            # clear for a body length past a face shorter than that (a bump's), not round to
            # the back of the wall followed last and not past it: into along that wall's
            # normal instead (beside a bump it meets that wall, a turn into it; a door in it
            # is driven through, and an opening all the same)
            self.into, self.turned_in = self.ref, True
            self.before, self.travelled = self.before + self.travelled, 0.0
            return Tick()
        if (g.depth_of(self.R) >= g.depth or self.travelled >= g.depth or walls or bumped):
            return Tick(outcome=Outcome.DONE, reason="opening")
        self.v = (speed * math.cos(self.into), speed * math.sin(self.into))
        return Tick(speed * math.cos(body), speed * math.sin(body), intent=body)

    def tick(self, ctx: Context) -> Tick:
        p, see, g = ctx.p, ctx.see, self.geom
        psi = see.psi(self.frame)
        step = max(0.0, see.advance - self.mark)
        self.mark = see.advance
        self.travelled += step
        felt = self._felt(psi, see.obst)
        fix = locate({l: wrap(b - psi) for l, b in see.seen.items() if l in g.points}, g.points)
        if self.R is None:
            if fix is None:
                self.hi = self.lo = 0.0      # never found where it is: nothing joined
                return self._end()
            self.R = fix
        # dead reckoning, along a felt wall at the slowest progress it allows; then the fix
        vx, vy = self.v
        if felt and self.into is None:
            t = self.n - self.h * PI / 2.0
            k = math.hypot(vx, vy) * math.cos(p.press + p.tau) * math.cos(p.tau)
            vx, vy = k * math.cos(t), k * math.sin(t)
        R = (self.R[0] + vx * see.dt, self.R[1] + vy * see.dt)
        if fix is not None:
            R = (R[0] + _BLEND * (fix[0] - R[0]), R[1] + _BLEND * (fix[1] - R[1]))
        self.R = R
        if self.into is not None:
            return self._drive_into(ctx, psi)
        f = g.frac(R)
        off = g.offset(R)
        ahead = off >= -0.5 * p.radius
        if ahead:
            self.hi, self.lo = max(self.hi, f), min(self.lo, f)
        self.steady += step
        if self.steady >= 2.0 * p.radius:
            self.wound = 0.0                 # a wall followed a body length: the reference
            self.ref, self.ref_at = self.n, R
        if felt:
            self.lost = 0.0
            if 90 in felt:
                self._turn(felt[90], True)   # a wall across the way: a corner
            elif 45 in felt and 0 not in felt:
                self._turn(felt[45], True)   # the wall bends towards the robot
        else:
            self.lost += step
            if self.lost >= p.sweep_lost_m:
                # the wall ended or bent away: one sector back, round its end
                if self.turned == 0.0:
                    self.n0, self.n0_held = self.n, self.steady >= 2.0 * p.radius
                self._turn(wrap(self.n + self.h * 2.0 * p.tau), False)
                self.turned += 2.0 * p.tau
                self.lost = 0.0
        if self.phase == 1 and f >= g.far and ahead:
            if g.depth_of(R) > g.depth:
                # the far line from the edge to here must lie in the edge's own lens
                return Tick(outcome=Outcome.DONE, reason="room")
            self._phase_two()
        ph = g.phi(R)
        if self.phase == 2:
            # it ends where it crosses the ray, going round the vertex from the edge's front
            # (a phase that starts past the ray has swept nothing between)
            crossed = self.last_phi is not None and self.last_phi < g.stop <= ph
            self.last_phi = ph
            if crossed and math.hypot(*R) > 1e-6:
                return self._end("end")
        self.armed = self.armed or off >= 0.0
        if self.armed and off < -p.radius:
            # the wall led behind the edge's line: in front of no part of the edge; the
            # phase stops short there
            if self.phase == 2:
                return self._end()
            self._phase_two()
        if not g.held(R):
            return Tick(outcome=Outcome.DONE, reason="room")
        t = self.n - self.h * PI / 2.0
        d = wrap(math.atan2(math.cos(p.press) * math.sin(t) + math.sin(p.press) * math.sin(self.n),
                            math.cos(p.press) * math.cos(t) + math.sin(p.press) * math.cos(self.n)))
        body = wrap(d + psi)
        bumps = [c for c in see.bump if blocks(body, c, p.tau)]
        if self.travelled >= p.sweep_budget_rv * p.rv or bumps:
            if bumps:
                # who may stand there: the coordinator infers nothing over a gap a robot
                # outside the complex stopped (a robot cut off from the swarm stands in the
                # free space the complex does not hold: bench/unseen.py seed 0 maps 8, 18)
                self.by.update(i for i, b in see.seen.items()
                               if any(abs(wrap(b - c)) <= see.half for c in bumps))
            if self.phase == 2:
                return self._end()
            says = g.other in see.seen and any(
                _only_other(c, see.seen, g.other, p.tau)
                for c in see.told if blocks(body, c, p.tau))
            if says and not self.heard:
                # one Sense tick's word (its sightings may have dropped a third robot):
                # hold still, and hear it again on the next before it closes anything
                self.heard, self.v = True, (0.0, 0.0)
                return Tick()
            if says:
                # the other end's body, by its own word: the wall goes on there
                self.hi = max(self.hi, g.far)
            self._phase_two()
            return Tick()
        self.heard = False
        if self.turned >= OPEN_TURN - 1e-9:
            # an opening: into it along the normal of the wall it went round
            self.into, self.before, self.travelled = self.n0, self.travelled, 0.0
            # not past the wall held last (a bump's top, not through a door): may turn to it
            self.turned_in = self.n0_held or self.ref_at is None or (
                (R[0] - self.ref_at[0]) * math.cos(self.ref)
                + (R[1] - self.ref_at[1]) * math.sin(self.ref) > p.radius)
            return self._drive_into(ctx, psi)
        speed = p.sweep_speed_frac * p.v_max
        self.v = (speed * math.cos(d), speed * math.sin(d))
        return Tick(speed * math.cos(body), speed * math.sin(body), intent=body, slide=False)

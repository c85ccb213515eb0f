"""A wall sweep executed geometrically, for bench/truth.py's harness.

The same rule as the agent's sweep mode (agents/sweep.py; coordinator.topology.evidence
states it), emulated on true positions and a polygon map without world/ or agents/ code: a
disk of radius r slides along the walls it presses into, feeling them through N_TOUCH
touch sectors within r + SKIN (only a sector's centre is known).

From the point where its first drive touched, the robot keeps the wall on one hand: its
wall normal n is the centre of the touch sector that stopped it; it moves along
cos(PRESS) t + sin(PRESS) n (t the tangent towards where it goes) and a frictionless wall
stops the part into it. n turns towards walls ahead: to the sector 90 deg ahead (along t: a
concave corner) when it touches, or to the one 45 deg ahead when it touches and n's own
does not (the wall bends towards the robot; a jamb's tip is felt 45 deg ahead only while
the wall it ends is still felt at n). When no sector from 45 deg behind n to 90 deg ahead
of it has touched for LOST metres, the wall has ended or bent away: n turns 45 deg back,
towards where it was, so the robot goes round the wall's end. OPEN_TURNS such turns since
the last turn into a wall (135 deg: the robot is going round the end of a wall, into what
lies behind it - a door, the back of a box) are an opening at least a body wide (a
narrower one stops the body on its far side, a turn into a wall): the robot drives on into
it along the normal of the wall whose end it went round (through a door: straight through
the wall) until it is ``depth`` from the edge, a touch blocks it or a robot is in its way,
and stays there as a new robot (a clear probe: its own deployments explore what lies
beyond); unless a wall's touch blocks it within a body length (2 r) and n turned back less
than 135 deg since it last held for a body length (it went round a bump's face or a jagged
wall's step, not to the back of the wall it followed): a turn into that wall, and the
sweep goes on along it. Past a face shorter than a body length (a bump's), not round to
the back of the wall held last nor past it, a drive clear for a body length turns to that
wall's normal (the agent's rule, agents/sweep.py). A jagged or bending
wall, a niche, a box's corner turn the robot back as often as forward, or less than 135.

Phase 1 goes towards the edge's other end until the robot crosses the edge's perpendicular
at fraction ``far`` (from its own end); phase 2 goes back, past its own end, until it
crosses the ray from its end at ``stop`` (rad) beyond the end's perpendicular. Either
phase stops short when another robot within touch (2 r + SKIN) blocks its way, or after
BUDGET metres; phase 1 stopped by the edge's other
end has reached ``far`` (between the two bodies there is no room for a third).
Fractions and depths are read off true positions (the agent reads them off its landmarks'
bearings). Units: metres, radians, world frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmcover.ground.angles import wrap
from swarmcover.ground.geometry import in_lenses, lens_radii

# mirrors of the agent's and the world's defaults (tests/test_truth.py checks them)
PRESS = math.radians(35.0)   # AgentParams.sweep_press_deg
LOST = 0.03                  # AgentParams.sweep_lost_m
OPEN_TURNS = 3               # 45-deg turns round a wall's end that make an opening
BUDGET_RV = 2.0              # AgentParams.sweep_budget_rv, per phase
SKIN = 0.015                 # [sensing] touch_skin
STEP = 0.005                 # integration step (m)


def _unit(a: float) -> np.ndarray:
    return np.array([math.cos(a), math.sin(a)])


def _nearest(q: np.ndarray, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance (S,), nearest point (S, 2)) from q to each wall segment."""
    a = segs[:, 0:2]
    d = segs[:, 2:4] - a
    L2 = np.maximum((d * d).sum(-1), 1e-18)
    t = np.clip(((q - a) * d).sum(-1) / L2, 0.0, 1.0)
    c = a + t[:, None] * d
    return np.linalg.norm(c - q, axis=1), c


def push_out(q: np.ndarray, segs: np.ndarray, r: float) -> np.ndarray:
    """q moved out of every wall to distance r (frictionless contact), deepest first."""
    for _ in range(6):
        dist, c = _nearest(q, segs)
        k = int(np.argmin(dist))
        if dist[k] >= r - 1e-9:
            break
        v = q - c[k]
        nv = float(np.linalg.norm(v))
        if nv < 1e-12:
            break
        q = q + (r - dist[k] + 1e-7) * v / nv
    return q


@dataclass
class SweepResult:
    """How a sweep ended. ``kind``: 'swept' (back home: ``hi``, ``lo`` the fractions of
    the edge from its own end it joined, lo -inf when it crossed its end's ray) or 'room'
    (it stays at ``pos``: the wall receded beyond the depth limit, or it drove into an
    opening; ``opening`` says which). ``travelled``: metres driven."""
    kind: str
    pos: np.ndarray
    hi: float = 0.0
    lo: float = 0.0
    opening: bool = False
    travelled: float = 0.0
    why: str = ""
    entered: np.ndarray | None = None   # an opening: where its last leg into it began
    by: tuple = ()      # indices into ``others`` of the robots a stop short met (the
                        # agent's ``swept HI LO by IDS``, bus.messages.sweep_stoppers)


class Sweeper:
    """One sweep of the edge from ``E`` (the robot's home vertex) to ``Q`` (the other
    end) on the side whose normal is ``side`` (+1: counter-clockwise of E -> Q).

    segs: (S, 4) wall segments; others: (M, 2) the other robots' centres; r: body radius;
    heading: the robot's body heading (rad; touch sectors are fixed to the body); depth:
    how far from the edge segment the wall may recede before it is room (m), unless it
    recedes into the lens of a segment from E to one of ``landmarks`` ((K, 2): the agent's
    sweep landmarks but Q; the agent's SweepGeom.held); n_touch: touch sectors."""

    def __init__(self, segs, others, E, Q, side: int, *, r: float, heading: float,
                 depth: float, n_touch: int = 8, rv: float = 1.0, landmarks=()):
        self.segs = np.asarray(segs, float)
        self.others = np.asarray(others, float).reshape(-1, 2)
        self._by: set[int] = set()      # the robots stops short met (SweepResult.by)
        self.E, self.Q = np.asarray(E, float), np.asarray(Q, float)
        self.L = float(np.linalg.norm(self.Q - self.E))
        self.e = (self.Q - self.E) / max(self.L, 1e-12)
        self.ns = np.array([-self.e[1], self.e[0]]) * (1 if side > 0 else -1)
        self.r, self.heading, self.depth = float(r), float(heading), float(depth)
        self.w = 2.0 * math.pi / n_touch
        self.budget = BUDGET_RV * rv
        # the landmarks' lenses, E at the origin (the edge's own is depth_of's)
        self.lenses = lens_radii(tuple(self.Q - self.E), self.depth, [
            tuple(p - self.E) for p in np.asarray(landmarks, float).reshape(-1, 2)])[1:]

    # ------------------------------------------------------------------ geometry
    def frac(self, R) -> float:
        """R's projection on the edge, as a fraction from E."""
        return float((R - self.E) @ self.e) / self.L

    def phi(self, R) -> float:
        """Angle (rad) at E from the edge's perpendicular to R, positive away from Q."""
        d = R - self.E
        return math.atan2(float(d @ -self.e), float(d @ self.ns))

    def offset(self, R) -> float:
        """R's signed distance (m) from the edge's line, positive on the side swept: only a
        place in front of it (>= -r / 2) joins the edge; a phase that was in front (>= 0)
        stops short once behind by r (agents.sweep.SweepGeom.offset)."""
        return float((R - self.E) @ self.ns)

    def depth_of(self, R) -> float:
        """Distance (m) from R to the edge segment."""
        t = min(1.0, max(0.0, self.frac(R)))
        return float(np.linalg.norm(R - (self.E + t * self.L * self.e)))

    def held(self, R) -> bool:
        """Whether R lies in the edge's lens or a landmark's (agents.sweep.SweepGeom.held)."""
        return self.depth_of(R) <= self.depth or in_lenses(
            float(R[0] - self.E[0]), float(R[1] - self.E[1]), self.lenses)

    def sectors(self, R) -> list[float]:
        """World directions of the centres of the touch sectors that feel a wall at R."""
        dist, c = _nearest(R, self.segs)
        out = []
        for k in np.nonzero(dist < self.r + SKIN)[0].tolist():
            v = c[k] - R
            body = math.atan2(v[1], v[0]) - self.heading
            centre = round(body / self.w) * self.w
            a = wrap(centre + self.heading)
            if all(abs(wrap(a - b)) > 1e-9 for b in out):
                out.append(a)
        return out

    def robot_ahead(self, R, d) -> str:
        """'' or what blocks motion along the unit vector d: 'Q' (the edge's other end) or
        'robot', another robot within touch (2 r + SKIN) whose direction from R is within
        pi/2 - pi/N of d, or whose body it would overlap: the agent stops when a robot's
        touch sector blocks its way (it knows Q by its bearing, and only when no other robot
        is there too); robots do not overlap."""
        return self._blocker(self.robots_ahead(R, d))

    def _blocker(self, k: np.ndarray) -> str:
        """'' / 'Q' / 'robot' for the blocking robots ``k`` (:meth:`robots_ahead`)."""
        if not len(k):
            return ""
        if len(k) == 1 and np.linalg.norm(self.others[k[0]] - self.Q) < 1e-9:
            return "Q"
        return "robot"

    def robots_ahead(self, R, d) -> np.ndarray:
        """Indices into ``others`` of the robots that block motion along d from R
        (:meth:`robot_ahead`)."""
        if not self.others.size:
            return np.zeros(0, np.int64)
        v = self.others - R
        dist = np.linalg.norm(v, axis=1)
        near = (dist < 2.0 * self.r + SKIN) & (
            (v @ d > math.cos(math.pi / 2.0 - self.w / 2.0) * dist) | (dist < 2.0 * self.r))
        return np.nonzero(near)[0]

    # ------------------------------------------------------------------ the sweep
    def _into(self, R, n: float, limit: float = math.inf):
        """Drive from R along n (world, rad) into an opening: until ``depth`` from the edge
        (at most that far), a touch sector blocking the way (within pi/2 - pi/N of it) or a
        robot ahead. Returns (end point, metres, the blocking wall sector nearest n or None
        when a robot or nothing blocked)."""
        u = _unit(n)
        half = math.pi / 2.0 - self.w / 2.0
        went = 0.0
        while self.depth_of(R) < self.depth and went < min(self.depth, limit):
            if self.robot_ahead(R, u):
                return R, went, None
            walls = [c for c in self.sectors(R) if abs(wrap(c - n)) < half]
            if walls:
                return R, went, min(walls, key=lambda c: abs(wrap(c - n)))
            R = push_out(R + STEP * u, self.segs, self.r)
            went += STEP
        return R, went, None

    def run(self, R0, touch_dir: float, far: float, stop: float) -> SweepResult:
        """Sweep from R0, where the first drive touched a wall in world direction
        ``touch_dir`` (its touch sector's centre is the first normal)."""
        res = self._run(R0, touch_dir, far, stop)
        if res.kind == "swept" and not math.isfinite(res.hi):
            res.hi = res.lo = 0.0        # never in front of the edge: nothing joined
        return res

    def _run(self, R0, touch_dir: float, far: float, stop: float) -> SweepResult:
        body = touch_dir - self.heading
        n = wrap(round(body / self.w) * self.w + self.heading)
        R = np.asarray(R0, float).copy()
        # only a place in front of the edge's line joins the edge (the agent's rule)
        hi, lo = ((self.frac(R), self.frac(R)) if self.offset(R) >= -0.5 * self.r
                  else (-math.inf, math.inf))
        # phase 1 keeps the wall on the hand that moves it towards Q
        t = _unit(n - math.pi / 2.0)
        h = 1 if (t @ self.e > 1e-9 or (abs(t @ self.e) <= 1e-9 and t @ self.ns > 0)) else -1
        total = 0.0
        why: list[str] = []
        for phase in (1, 2):
            if phase == 2:
                h = -h
            lost = travelled = 0.0
            turned = 0           # 45-deg turns round a wall's end since the last one into a wall
            wound = 0.0          # turned back (rad) since n last held for a body length
            steady = 0.0         # travel since n last turned (m)
            ref, ref_at = n, R.copy()   # the normal last held for a body length, and where
            n0_held = False      # the wall whose end it goes round was held a body length
            armed = False        # in front of the edge's line since the phase began
            last_phi = self.phi(R)
            while True:
                f = self.frac(R)
                off = self.offset(R)
                ahead = off >= -0.5 * self.r
                if ahead:
                    hi, lo = max(hi, f), min(lo, f)
                if phase == 1 and f >= far and ahead:
                    if self.depth_of(R) > self.depth:
                        # the far line from the edge to here lies in the edge's own lens
                        return SweepResult("room", R, hi, lo, False, total)
                    break
                ph = self.phi(R)
                if (phase == 2 and last_phi < stop <= ph
                        and np.linalg.norm(R - self.E) > 1e-6):
                    return SweepResult("swept", R, hi, -math.inf, False, total, " ".join(why),
                                       by=tuple(sorted(self._by)))
                last_phi = ph
                armed = armed or off >= 0.0
                if armed and off < -self.r:
                    # the wall led behind the edge's line: what it follows there is in
                    # front of no part of the edge; the phase stops short
                    why.append(f"{phase}:behind")
                    if phase == 1:
                        break
                    return SweepResult("swept", R, hi, lo, False, total, " ".join(why),
                                       by=tuple(sorted(self._by)))
                if not self.held(R):
                    return SweepResult("room", R, hi, lo, False, total)
                t = _unit(n - h * math.pi / 2.0)
                d = math.cos(PRESS) * t + math.sin(PRESS) * _unit(n)
                over = travelled >= self.budget
                ahead = np.zeros(0, np.int64) if over else self.robots_ahead(R, d)
                block = "budget" if over else self._blocker(ahead)
                if block:
                    why.append(f"{phase}:{block}")
                    if block == "robot":
                        self._by.update(int(x) for x in ahead)
                    if phase == 1:
                        if block == "Q":
                            # the other end's body: it rests where the wall goes on
                            hi = max(hi, far)
                        break
                    return SweepResult("swept", R, hi, lo, False, total, " ".join(why),
                                       by=tuple(sorted(self._by)))
                if turned >= OPEN_TURNS:
                    # an opening: into it along the normal of the wall it went round
                    # round a face shorter than a body length, not to the back of the wall
                    # held last and not past it (a bump's top, not through a door)
                    short = (not n0_held and wound < OPEN_TURNS * self.w - 1e-9
                             and float((R - ref_at) @ _unit(ref)) <= self.r)
                    entered = R.copy()
                    R, went, wall = self._into(R, n0, 2.0 * self.r if short else math.inf)
                    total += went
                    if short and wall is None and went >= 2.0 * self.r - 1e-9:
                        # clear for a body length past a face shorter than that (a bump's),
                        # not round to the back of the wall held last: along its normal
                        travelled += went
                        entered = R.copy()
                        R, more, wall = self._into(R, ref)
                        total += more
                        went = more
                    if (wall is None or went >= 2.0 * self.r
                            or wound >= OPEN_TURNS * self.w - 1e-9):
                        return SweepResult("room", R, hi, lo, True, total, entered=entered)
                    # a wall across the way within a body length, not behind the wall it
                    # followed: no opening; a turn into this wall, and on along it
                    travelled += went
                    wound += h * wrap(wall - n)
                    n, turned, lost, steady = wall, 0, 0.0, 0.0
                    continue
                R = push_out(R + STEP * d, self.segs, self.r)
                travelled += STEP
                total += STEP
                steady += STEP
                if steady >= 2.0 * self.r - 1e-9:
                    wound, ref, ref_at = 0.0, n, R.copy()   # a wall followed a body length
                felt = {round(math.degrees(-h * wrap(c - n))): c for c in self.sectors(R)}
                felt = {a: c for a, c in felt.items() if -45 <= a <= 90}
                if felt:
                    lost = 0.0
                    if 90 in felt:
                        # a wall across the way: a concave corner
                        wound += h * wrap(felt[90] - n)
                        n, turned, steady = felt[90], 0, 0.0
                    elif 45 in felt and 0 not in felt:
                        # the wall bends towards the robot
                        wound += h * wrap(felt[45] - n)
                        n, turned, steady = felt[45], 0, 0.0
                else:
                    lost += STEP
                    if lost >= LOST - 1e-9:
                        if turned == 0:
                            n0 = n                 # the wall whose end it goes round
                            n0_held = steady >= 2.0 * self.r - 1e-9
                        n = wrap(n + h * self.w)  # the wall ended: round its end
                        turned, lost, steady = turned + 1, 0.0, 0.0
                        wound += self.w
        return SweepResult("swept", R, hi, lo, False, total)  # pragma: no cover

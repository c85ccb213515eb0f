"""Bearing-only control laws (spec sections 4.5-4.8), as pure functions.

Frames: every bearing and velocity here is in the robot's current body frame (x forward,
y left, angles CCW positive, wrapped to [-pi, pi)) unless a name says otherwise. Units:
metres, seconds, radians. Desired bearings are given in a *reference frame*; ``psi`` is the
rotation from that frame to the body frame (heading(reference) - heading(body)), so a
desired bearing ``b*`` reads ``b* + psi`` in the body frame (psi = 0 for holonomic robots,
whose frames never rotate).

Plain ``math`` on dicts, no numpy: a robot has ~6 landmarks, for which array set-up costs
more than the arithmetic (the agent process must stay under ~1 ms per tick).
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping, Sequence

from swarmcover.ground.angles import PI, bearing_spread, circmean, resultant, wrap  # noqa: F401  (re-exported)




# --------------------------------------------------------------------------- homing (4.5)

def bearing_errors(bearings: Mapping[int, float], desired: Mapping[int, float],
                   psi: float = 0.0) -> dict[int, float]:
    """Per landmark seen now and desired: wrap(bearing - (desired + psi)) (rad)."""
    return {l: wrap(b - desired[l] - psi) for l, b in bearings.items() if l in desired}


def homing_gradient(bearings: Mapping[int, float], desired: Mapping[int, float],
                    psi: float = 0.0) -> tuple[float, float, int]:
    """g = sum over landmarks seen and desired of (b_l - R(psi) b*_l); returns (gx, gy, n).

    g is minus the gradient of the convex cost sum_l d_l (1 - cos(angle(b_l, b*_l))), so
    moving along g descends it (spec 4.5, the sign fixed against ICRA's print).
    """
    gx = gy = 0.0
    n = 0
    for l, b in bearings.items():
        d = desired.get(l)
        if d is None:
            continue
        d += psi
        gx += math.cos(b) - math.cos(d)
        gy += math.sin(b) - math.sin(d)
        n += 1
    return gx, gy, n


def saturating_gain(gnorm: float, v_max: float, g0: float) -> float:
    """K(g) = v_max / max(|g|, g0): speed v_max far away, linear slow-down for |g| < g0."""
    return v_max / max(gnorm, g0)


def homing_velocity(bearings: Mapping[int, float], desired: Mapping[int, float], v_max: float,
                    g0: float, psi: float = 0.0) -> tuple[float, float]:
    """u = K(g) g (m/s, body frame); |u| <= v_max. Zero without a common landmark."""
    gx, gy, n = homing_gradient(bearings, desired, psi)
    if n == 0:
        return 0.0, 0.0
    k = saturating_gain(math.hypot(gx, gy), v_max, g0)
    return k * gx, k * gy


FIX_SPREAD = 0.05   # ground.angles.bearing_spread under which bearings fix no point: two
                    # landmarks under 13 deg apart (or opposite), one alone


def bearing_offset(errors: Mapping[int, float], directions: Mapping[int, float]) -> float | None:
    """How far the bearing errors put the robot from its goal, in units of the landmarks'
    distance (taken equal; rad-like, comparable with a bearing error): the least-squares
    offset x with e_l = -n_l . x, n_l the unit normal of landmark l's desired bearing. None
    when the landmarks do not fix a point (fewer than two, or all in line)."""
    sxx = sxy = syy = bx = by = 0.0
    for l, e in errors.items():
        t = directions.get(l)
        if t is None:
            continue
        nx, ny = -math.sin(t), math.cos(t)
        sxx += nx * nx
        sxy += nx * ny
        syy += ny * ny
        bx -= nx * e
        by -= ny * e
    det = sxx * syy - sxy * sxy   # = ground.angles.bearing_spread of the directions, in O(n)
    if det < FIX_SPREAD:
        return None
    x = (syy * bx - sxy * by) / det
    y = (sxx * by - sxy * bx) / det
    return math.hypot(x, y)


class StopRule:
    """Arrival test with filtering: arrived once the largest low-passed bearing error stays
    below ``delta`` (rad) for ``ticks`` consecutive updates, and so does the offset those
    errors put the robot at when ``directions`` are given.

    Each landmark's wrapped error is smoothed by an exponential filter (weight ``alpha`` on
    the new sample) so that bearing noise of ~0.5-1 deg does not keep resetting the count;
    a landmark that drops out of view is forgotten. ``reset()`` restarts the count.

    The offset (:func:`bearing_offset`): the same bearing error is a larger miss along a
    direction few landmarks see across. Two landmarks 60 deg apart see a step along their
    bisector at sin 30 deg of its size: stopping on the bearings alone left a robot homing
    on two such landmarks a mean 2.3 cm off its vertex, 1.3 cm with the offset test, for
    0.7 s more (tests/test_agent_behaviours.py); three spread landmarks leave it 0.4 cm off.
    """

    def __init__(self, delta: float, ticks: int, alpha: float = 0.3):
        self.delta = delta
        self.ticks = max(1, int(ticks))
        self.alpha = alpha
        self.filtered: dict[int, float] = {}
        self.count = 0

    def reset(self) -> None:
        self.filtered.clear()
        self.count = 0

    def update(self, errors: Mapping[int, float],
               directions: Mapping[int, float] | None = None) -> bool:
        """errors: landmark -> bearing error (rad); directions: landmark -> its desired
        bearing (rad, the frame the errors are in), for the offset test (None: none)."""
        a = self.alpha
        f = self.filtered
        new: dict[int, float] = {}
        for l, e in errors.items():
            old = f.get(l)
            new[l] = e if old is None else wrap(old + a * wrap(e - old))
        self.filtered = new
        ok = bool(new) and max(abs(e) for e in new.values()) < self.delta
        if ok and directions is not None:
            off = bearing_offset(new, directions)
            ok = off is None or off < self.delta
        self.count = self.count + 1 if ok else 0
        return self.count >= self.ticks

    def max_error(self) -> float:
        """Largest filtered error magnitude (rad), 0 if none."""
        return max((abs(e) for e in self.filtered.values()), default=0.0)


# --------------------------------------------------------------------------- walls (4.6)

def blocks(direction: float, contact: float, tau: float) -> bool:
    """Whether a contact at bearing ``contact`` (+-tau) blocks motion along ``direction``:
    the blocked sector is contact +- (pi/2 - tau)."""
    return abs(wrap(direction - contact)) < PI / 2 - tau


def slide(ux: float, uy: float, contacts: Sequence[float], tau: float) -> tuple[float, float]:
    """Project u so that it does not push into any obstacle contact (wall sliding, 4.6).

    For each blocking contact at bearing c, u is replaced by max(0, u.r) r with r the edge
    of the blocked sector (c +- (pi/2 - tau)) nearer to u. If the result is still blocked
    by another contact (a corner), the robot stops.
    """
    if not contacts or (ux == 0.0 and uy == 0.0):
        return ux, uy
    half = PI / 2 - tau
    for c in contacts:
        if ux == 0.0 and uy == 0.0:
            return 0.0, 0.0
        if not blocks(math.atan2(uy, ux), c, tau):
            continue
        best = None
        for edge in (c + half, c - half):
            rx, ry = math.cos(edge), math.sin(edge)
            dot = ux * rx + uy * ry
            if best is None or dot > best[0]:
                best = (dot, rx, ry)
        dot, rx, ry = best
        dot = max(0.0, dot)
        ux, uy = dot * rx, dot * ry
    if ux == 0.0 and uy == 0.0:
        return 0.0, 0.0
    ang = math.atan2(uy, ux)
    # a tolerance so that a vector lying on a sector edge counts as allowed
    if any(abs(wrap(ang - c)) < half - 1e-9 for c in contacts):
        return 0.0, 0.0
    return ux, uy


# --------------------------------------------------------------------------- diff drive (4.8)

def diffdrive(ux: float, uy: float, k_w: float, k_v: float, v_max: float,
              w_max: float) -> tuple[float, float]:
    """Unicycle command (v m/s forward, w rad/s CCW) tracking the body-frame velocity u:
    alpha = atan2(uy, ux), w = k_w alpha, v = k_v |u| max(0, cos alpha), both clamped."""
    speed = math.hypot(ux, uy)
    if speed < 1e-12:
        return 0.0, 0.0
    alpha = math.atan2(uy, ux)
    w = max(-w_max, min(w_max, k_w * alpha))
    v = min(v_max, k_v * speed * max(0.0, math.cos(alpha)))
    return v, w


def clamp_speed(ux: float, uy: float, v_max: float) -> tuple[float, float]:
    """Scale u down to |u| <= v_max."""
    s = math.hypot(ux, uy)
    if s > v_max > 0.0:
        f = v_max / s
        return ux * f, uy * f
    return ux, uy


# --------------------------------------------------------------------------- frames (4.7)

def heading_offset(bearing: float, back_bearing: float) -> float:
    """phi_l - phi_i from mutual bearings: i sees l at ``bearing`` (i's frame), l sees i at
    ``back_bearing`` (l's frame). Since bearing = a - phi_i and back = a + pi - phi_l, with
    a the world direction from i to l: phi_l - phi_i = wrap(bearing - back + pi)."""
    return wrap(bearing - back_bearing + PI)


def frame_psi(ref_offsets: Mapping[int, float], bearings: Mapping[int, float],
              back_bearings: Mapping[int, float]) -> float | None:
    """psi = heading(ref) - heading(self) = circular mean over landmarks l seen now of
    ref_offsets[l] + (phi_l - phi_i)_now, where ref_offsets[l] = heading(ref) - phi_l.

    None when no landmark with an offset is seen with its back bearing.
    """
    vals = [ref_offsets[l] + heading_offset(b, back_bearings[l])
            for l, b in bearings.items() if l in ref_offsets and l in back_bearings]
    return circmean(vals)


def snapshot_offsets(bearings: Mapping[int, float],
                     back_bearings: Mapping[int, float]) -> dict[int, float]:
    """ref_offsets that make the robot's frame *now* the reference frame:
    heading(self now) - phi_l = -(phi_l - phi_i) for every landmark seen both ways."""
    return {l: -heading_offset(b, back_bearings[l]) for l, b in bearings.items()
            if l in back_bearings}


# --------------------------------------------------------------------------- helpers

def unit(angle: float) -> tuple[float, float]:
    return math.cos(angle), math.sin(angle)


def away_direction(bearings: Iterable[float]) -> float | None:
    """Direction (rad) opposite the circular mean of ``bearings``, None if they cancel."""
    m = circmean(bearings)
    return None if m is None else wrap(m + PI)


class FrameTracker:
    """psi (heading(reference frame) - heading(body)) tracked over time without a gyro.

    ``offsets``: per landmark, heading(reference) - heading(landmark) (rad), e.g. a Task's
    ref_offsets, or :func:`snapshot_offsets` to make the body frame at creation the
    reference. Each :meth:`update` recomputes psi from mutual bearings (spec 4.7); while no
    such landmark is seen, psi is dead-reckoned from the integrated commanded turn rate
    ``heading`` (rad): psi = psi_last - (heading - heading_last).
    """

    __slots__ = ("offsets", "psi", "h")

    def __init__(self, offsets: Mapping[int, float], heading: float = 0.0, psi: float = 0.0):
        self.offsets = dict(offsets)
        self.psi = psi
        self.h = heading

    @classmethod
    def snapshot(cls, bearings: Mapping[int, float], back_bearings: Mapping[int, float],
                 heading: float = 0.0) -> "FrameTracker":
        return cls(snapshot_offsets(bearings, back_bearings), heading, 0.0)

    def update(self, bearings: Mapping[int, float], back_bearings: Mapping[int, float],
               heading: float) -> float:
        psi = frame_psi(self.offsets, bearings, back_bearings)
        if psi is None:
            return wrap(self.psi - (heading - self.h))
        self.psi = psi
        self.h = heading
        return psi

    def adopt(self, landmark: int, bearing: float, back_bearing: float, psi: float) -> None:
        """Add a landmark's offset from the current psi: heading(ref) - phi_l =
        psi - (phi_l - phi_i)."""
        self.offsets[landmark] = wrap(psi - heading_offset(bearing, back_bearing))

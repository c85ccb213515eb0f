"""What a robot perceives, kept between ticks. Pure: no I/O and no clock but ``Sense.t``.

* :class:`Perception`: the current Sense tick digested (neighbours' bearings and back
  bearings, touch sectors read three ways (walls; maybe a robot, where one is seen; a
  robot that says it touches us), when each neighbour was last seen, when another robot
  last touched us) plus the dead reckoning of the robot's own commands (integrated turn
  ``heading`` and ``advance`` along the commanded direction).
* :class:`Contact`: the sticky obstacle contact reported in Status (spec 3.5).

All bearings are in the body frame (rad, CCW, 0 = forward); distances in m, times in s.
"""
from __future__ import annotations

from swarmcover.bus.messages import Sense

from .control import FrameTracker, circmean, unit, wrap


class Perception:
    """One robot's view of the world, refreshed by :meth:`update` once per Sense tick."""

    __slots__ = ("robot", "half", "n", "t", "tick", "dt", "seen", "back", "obst", "bump", "told",
                 "last_seen", "last_seen_t", "last_b", "bumped_t", "heading", "advance")

    def __init__(self, robot: int, dt: float, half: float):
        self.robot = robot
        self.half = half             # a touch sector's half-width (rad): pi / n_touch
        self.n = 0                   # Sense ticks handled
        self.t: float | None = None  # Sense.t of the current tick (s)
        self.tick = -1               # Sense.tick of the current tick
        self.dt = dt                 # last measured tick length (s), the nominal dt at first
        self.seen: dict[int, float] = {}   # neighbour id -> bearing (rad, body frame)
        self.back: dict[int, float] = {}   # neighbour id -> its bearing of us (rad, its frame)
        # touch sectors (centre bearings, rad, body frame), three ways:
        self.obst: list[float] = []        # no robot seen in their span: obstacles
        self.bump: list[float] = []        # a robot seen in their span, or told: maybe a robot
        self.told: list[float] = []        # another robot says it touches us there
        self.last_seen: dict[int, int] = {}      # neighbour id -> tick index last seen
        self.last_seen_t: dict[int, float] = {}  # neighbour id -> Sense.t last seen (s)
        self.last_b: dict[int, float] = {}       # neighbour id -> bearing last seen at (rad)
        self.bumped_t = -1e18        # last time another robot touched us (s)
        # dead reckoning of our own commands (open-loop modes and fallbacks only)
        self.heading = 0.0           # integral of commanded wz (rad)
        self.advance = 0.0           # integral of commanded velocity along the intent (m)

    def update(self, s: Sense, cmd, intent: float | None) -> float:
        """Take one Sense tick. ``cmd`` (body-frame vx, vy in m/s, wz in rad/s) is the
        command published for the previous tick and ``intent`` the body-frame direction
        (rad) it meant, or None; both are dead-reckoned over the elapsed time. Returns that
        elapsed time (s, clamped to [0, 1]). ``dt`` becomes the length of one tick: the
        elapsed time over the ticks elapsed, as a robot that holds still may be sensed only
        every few ticks (world.wake)."""
        raw = 0.0 if self.t is None else s.t - self.t
        dt = min(1.0, max(0.0, raw))
        if dt > 0:
            ticks = s.tick - self.tick if self.tick >= 0 else 1
            self.dt = min(1.0, raw / ticks) if ticks > 1 else dt
        self.t = s.t
        self.tick = s.tick
        self.n += 1
        c = cmd
        if dt > 0 and (c.vx or c.vy or c.wz):
            self.heading += c.wz * dt
            if intent is not None:
                ix, iy = unit(intent)
                self.advance += (c.vx * ix + c.vy * iy) * dt
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
        self.last_seen.update(dict.fromkeys(seen, self.n))
        self.last_seen_t.update(dict.fromkeys(seen, s.t))
        self.last_b.update(seen)
        told: list[float] = []
        bump: list[float] = []
        obst: list[float] = []
        h = self.half
        for a, r in zip(s.touch, s.touch_robot):
            if r:
                told.append(a)
                bump.append(a)
            elif any(abs(wrap(b - a)) <= h for b in seen.values()):
                bump.append(a)
            else:
                obst.append(a)
        self.told, self.bump, self.obst = told, bump, obst
        if bump:
            self.bumped_t = s.t
        return dt

    def recent(self, ticks: int) -> dict[int, float]:
        """The neighbours seen within the last ``ticks`` ticks (``ticks_unseen`` < ticks: a
        link not yet lost) -> the bearing each was last seen at (rad, body frame); this
        tick's first. One frame that misses a neighbour does not drop it."""
        out = dict(self.seen)
        n = self.n
        for i, k in self.last_seen.items():
            if n - k < ticks and i not in out:
                out[i] = self.last_b[i]
        return out

    def ticks_unseen(self, landmark: int) -> int:
        """Ticks since ``landmark`` was last seen (0: seen this tick; huge: never)."""
        return self.n - self.last_seen.get(landmark, -10**9)

    def psi(self, frame: FrameTracker | None) -> float:
        """Heading of ``frame`` relative to the body (rad), updated on this tick's bearings;
        0 without a frame."""
        if frame is None:
            return 0.0
        return frame.update(self.seen, self.back, self.heading)

    def snapshot_frame(self) -> FrameTracker:
        """A reference frame that is the body frame now."""
        return FrameTracker.snapshot(self.seen, self.back, self.heading)


class Contact:
    """Sticky obstacle contact (spec 3.5): set by an obstacle touch, kept until the robot
    has moved ``clear`` metres in a moving mode without touching (or for good once
    ``pinned``, a test drive's touch), turned with the body through ``frame`` when
    reference frames are tracked."""

    __slots__ = ("active", "bearing", "frame", "pinned", "moved")

    def __init__(self):
        self.active = False
        self.bearing = 0.0           # body frame at the time of contact (rad)
        self.frame: FrameTracker | None = None
        self.pinned = False
        self.moved = 0.0             # distance moved since the last touch (m)

    def travel(self, distance: float) -> None:
        """The robot moved ``distance`` (m) in a moving mode."""
        if self.active and not self.pinned:
            self.moved += distance

    def update(self, see: Perception, aligned: bool, clear: float) -> bool:
        """Take this tick's touch; ``clear`` is the distance (m) that clears an unpinned
        contact. Returns whether the contact flag changed."""
        if see.obst:
            changed = not self.active
            self.active = True
            self.bearing = circmean(see.obst) or see.obst[0]
            self.frame = see.snapshot_frame() if aligned else None
            self.moved = 0.0
            return changed
        if self.active and not self.pinned and self.moved > clear:
            return self.clear()
        return False

    def clear(self) -> bool:
        """Forget the contact; returns whether it was set."""
        changed = self.active
        self.active = False
        self.pinned = False
        self.frame = None
        self.moved = 0.0
        return changed

    def body_bearing(self, see: Perception) -> float:
        """The contact's bearing in the current body frame (rad); 0 without a contact."""
        cb = self.bearing
        if self.active and self.frame is not None:
            cb = wrap(cb + self.frame.update(see.seen, see.back, see.heading))
        return wrap(cb) if self.active else 0.0

"""Clock logic of the world, free of I/O (wall times are passed in, in seconds).

* :class:`LockstepGate`: tick k+1 may run once every expected robot answered tick k, or
  once ``timeout_s`` wall seconds passed (the missing ones are then "late").
* :class:`Pacer`: real-time pacing, one tick every dt/rtf wall seconds; if the world falls
  behind by more than ``max_lag`` ticks it drops the backlog instead of bursting.
* :class:`RtfMeter`: measured real-time factor (sim s per wall s) over a sliding window.
"""
from __future__ import annotations

from collections import deque


class LockstepGate:
    """Book-keeping of one lockstep tick."""

    def __init__(self, timeout_s: float):
        self.timeout_s = float(timeout_s)
        self.tick = -1
        self.expected: set[int] = set()
        self.answered: set[int] = set()
        self.opened = 0.0

    def open(self, tick: int, expected, now: float) -> None:
        """Start waiting for tick ``tick``'s answers from ``expected`` robot ids."""
        self.tick = int(tick)
        self.expected = set(expected)
        self.answered = set()
        self.opened = float(now)

    def answer(self, robot: int, tick: int) -> bool:
        """Record robot's command for ``tick`` (-1 = untagged, counts for the open tick).
        Returns whether it counted."""
        if tick != self.tick and tick != -1:
            return False
        if robot in self.expected:
            self.answered.add(robot)
        return True

    def forget(self, robot: int) -> None:
        """Stop waiting for a robot (its agent left, or its body was removed)."""
        self.expected.discard(robot)
        self.answered.discard(robot)

    @property
    def waiting(self) -> set[int]:
        return self.expected - self.answered

    def all_answered(self) -> bool:
        return not (self.expected - self.answered)

    def timed_out(self, now: float) -> bool:
        return now - self.opened >= self.timeout_s

    def ready(self, now: float) -> bool:
        return self.all_answered() or self.timed_out(now)

    def remaining(self, now: float) -> float:
        return max(0.0, self.opened + self.timeout_s - now)

    def late(self) -> set[int]:
        return self.expected - self.answered


class Pacer:
    """Wall-clock schedule: tick k is due at start + k * dt / rtf."""

    def __init__(self, dt: float, rtf: float, now: float, max_lag: int = 5):
        self.period = float(dt) / float(rtf)
        self.start = float(now)
        self.k = 0
        self.max_lag = int(max_lag)

    def next_due(self) -> float:
        return self.start + (self.k + 1) * self.period

    def due(self, now: float) -> bool:
        return now >= self.next_due()

    def wait_time(self, now: float) -> float:
        return max(0.0, self.next_due() - now)

    def done(self, now: float) -> None:
        """One tick ran; re-anchor the schedule if we are too far behind."""
        self.k += 1
        if now - self.next_due() > self.max_lag * self.period:
            self.start = now - self.k * self.period

    def reset(self, now: float) -> None:
        self.start = float(now)
        self.k = 0


class RtfMeter:
    """Sim seconds per wall second over the last ``window`` ticks."""

    def __init__(self, window: int = 50):
        self.samples: deque = deque(maxlen=window)

    def add(self, sim_t: float, wall_t: float) -> None:
        self.samples.append((float(sim_t), float(wall_t)))

    @property
    def rtf(self) -> float:
        if len(self.samples) < 2:
            return 0.0
        (s0, w0), (s1, w1) = self.samples[0], self.samples[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 0.0

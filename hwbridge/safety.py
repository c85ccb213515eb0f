"""Safety of the command path to live robots (pure: no I/O, time is passed in).

Rules, checked on every output tick for each live robot:

  1. never forward a command for a robot that is not configured as live;
  2. deadman: if the agent's commands or the robot's mocap pose have been silent for
     longer than ``deadman_s`` (default 0.3 s), output zero -- actively, every tick;
  3. geofence: if the last mocap pose is outside the fence polygon (world frame), or
     closer than ``margin`` (m) to its edge, output zero;
  4. clamp: |v| <= v_max (m/s), |omega| <= w_max (rad/s); both are scaled by the same
     factor so the commanded curvature (the path) is kept.

Times are seconds on one monotonic clock chosen by the caller (receipt times).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Sequence

from swarmcover.ground.geometry import edge_distance, point_in_polygon  # noqa: F401  (hwbridge.node)

REASONS = ("ok", "clamped", "no_command", "command_stale", "no_mocap", "mocap_stale",
           "geofence")


def clamp_unicycle(v: float, omega: float, v_max: float, w_max: float) -> tuple[float, float]:
    """Scale (v, omega) by one factor so that |v| <= v_max and |omega| <= w_max.

    Non-finite inputs give (0, 0).
    """
    if not (math.isfinite(v) and math.isfinite(omega)):
        return 0.0, 0.0
    s = 1.0
    if abs(v) > v_max:
        s = min(s, v_max / abs(v))
    if abs(omega) > w_max:
        s = min(s, w_max / abs(omega))
    return v * s, omega * s


def inside_fence(x: float, y: float, poly: Sequence[tuple[float, float]] | None,
                 margin: float = 0.0) -> bool:
    """True if there is no fence, or (x, y) is inside it and at least ``margin`` from its edge."""
    if not poly:
        return True
    return point_in_polygon(x, y, poly) and (margin <= 0 or edge_distance(x, y, poly) >= margin)


def check_polygon(poly: Iterable, what: str = "geofence") -> list[tuple[float, float]]:
    """Validate a polygon given as [[x, y], ...]; raise ValueError naming ``what``."""
    try:
        pts = [(float(p[0]), float(p[1])) for p in poly]
        bad = any(len(p) != 2 for p in poly)
    except (TypeError, ValueError, IndexError, KeyError):
        raise ValueError(f"{what}: expected a list of [x, y] points, got {poly!r}") from None
    if bad or len(pts) < 3:
        raise ValueError(f"{what}: expected at least 3 [x, y] points, got {poly!r}")
    if not all(math.isfinite(c) for p in pts for c in p):
        raise ValueError(f"{what}: coordinates must be finite, got {poly!r}")
    return pts


@dataclass(frozen=True, slots=True)
class Limits:
    """Per-robot limits: speeds (m/s, rad/s), deadman (s), fence (world polygon) and margin (m)."""
    v_max: float = 0.3
    w_max: float = 2.0
    deadman_s: float = 0.3
    geofence: tuple[tuple[float, float], ...] | None = None
    margin: float = 0.0

    def __post_init__(self):
        for name in ("v_max", "w_max", "deadman_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"geofence_margin: must be >= 0, got {self.margin!r}")


@dataclass(frozen=True, slots=True)
class Decision:
    """What to send to the robot now: unicycle (v m/s, omega rad/s) and why."""
    v: float
    omega: float
    reason: str

    @property
    def stopped(self) -> bool:
        return self.reason not in ("ok", "clamped")


@dataclass
class SafetyGate:
    """The command gate of one live robot. Feed it commands and poses; ask :meth:`decide`."""
    robot: int
    limits: Limits
    cmd: tuple[float, float] | None = None
    cmd_time: float | None = None
    pose: tuple[float, float] | None = None
    pose_time: float | None = None
    counts: dict = field(default_factory=lambda: {r: 0 for r in REASONS})

    def on_command(self, now: float, v: float, omega: float) -> None:
        """The agent's latest unicycle command (m/s, rad/s), received at ``now``."""
        self.cmd = (float(v), float(omega))
        self.cmd_time = now

    def on_pose(self, now: float, x: float, y: float) -> None:
        """The robot's latest mocap position (world frame, m), received at ``now``."""
        self.pose = (float(x), float(y))
        self.pose_time = now

    def decide(self, now: float, count: bool = True) -> Decision:
        """The command to send at ``now``; ``count``: tally the reason in ``counts``."""
        L = self.limits
        if self.cmd is None or self.cmd_time is None:
            d = Decision(0.0, 0.0, "no_command")
        elif now - self.cmd_time > L.deadman_s:
            d = Decision(0.0, 0.0, "command_stale")
        elif self.pose is None or self.pose_time is None:
            d = Decision(0.0, 0.0, "no_mocap")
        elif now - self.pose_time > L.deadman_s:
            d = Decision(0.0, 0.0, "mocap_stale")
        elif not inside_fence(self.pose[0], self.pose[1], L.geofence, L.margin):
            d = Decision(0.0, 0.0, "geofence")
        else:
            v, w = clamp_unicycle(self.cmd[0], self.cmd[1], L.v_max, L.w_max)
            d = Decision(v, w, "clamped" if (v, w) != self.cmd else "ok")
        if count:
            self.counts[d.reason] += 1
        return d


class Gates:
    """The gates of all live robots; commands for any other robot id are refused."""

    def __init__(self, limits_by_robot: dict[int, Limits]):
        self.gates = {rid: SafetyGate(rid, lim) for rid, lim in limits_by_robot.items()}
        self.refused = 0

    def is_live(self, robot: int) -> bool:
        return robot in self.gates

    def on_command(self, now: float, robot: int, v: float, omega: float) -> bool:
        """Record a command; False (and counted) if ``robot`` is not a configured live robot."""
        g = self.gates.get(robot)
        if g is None:
            self.refused += 1
            return False
        g.on_command(now, v, omega)
        return True

    def on_pose(self, now: float, robot: int, x: float, y: float) -> None:
        g = self.gates.get(robot)
        if g is not None:
            g.on_pose(now, x, y)

    def decide(self, now: float, robot: int) -> Decision | None:
        g = self.gates.get(robot)
        return None if g is None else g.decide(now)

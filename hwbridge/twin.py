"""Twin sync: drive a live robot's simulated twin toward its measured pose (pure).

The thesis (section 3.4.3, Fig. 3.13) couples each live robot to its twin by a
proportional controller on the pose; we follow spec section 8:

    v_twin  = kp (p_meas - p_twin)                  (world frame, m/s)
    wz_twin = k_theta wrap(theta_meas - theta_twin)  (rad/s)

optionally plus a feed-forward of the measured robot's own velocity (removes the
steady-state lag v/kp of a pure P loop; off by default, as in the thesis). When the
position error exceeds ``teleport_dist`` (m) the twin is placed at the measured pose
instead (first sync, mocap glitches, a robot carried by hand).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from swarmcover.ground.angles import wrap


@dataclass(frozen=True, slots=True)
class TwinGains:
    """kp (1/s), k_theta (1/s), teleport_dist (m, absolute), speed caps (m/s, rad/s)."""
    kp: float = 3.0
    k_theta: float = 3.0
    teleport_dist: float = 0.2
    v_cap: float = 5.0
    w_cap: float = 10.0
    feedforward: bool = False

    def __post_init__(self):
        for name in ("kp", "k_theta", "teleport_dist", "v_cap", "w_cap"):
            v = getattr(self, name)
            if not math.isfinite(v) or v <= 0:
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")


@dataclass(frozen=True, slots=True)
class TwinCommand:
    """One twin command: world-frame velocity, or a teleport to (x, y, theta)."""
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0
    teleport: bool = False
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


def twin_command(meas: tuple[float, float, float], twin: tuple[float, float, float],
                 gains: TwinGains,
                 meas_vel: tuple[float, float, float] | None = None) -> TwinCommand:
    """The command that moves ``twin`` toward ``meas`` (both world poses x, y, theta).

    ``meas_vel``: the measured robot's world velocity (vx, vy, wz), used only when
    ``gains.feedforward``. Speeds are capped at ``v_cap`` / ``w_cap`` (direction kept).
    """
    ex, ey = meas[0] - twin[0], meas[1] - twin[1]
    if math.hypot(ex, ey) > gains.teleport_dist:
        return TwinCommand(teleport=True, x=meas[0], y=meas[1], theta=wrap(meas[2]))
    vx, vy = gains.kp * ex, gains.kp * ey
    wz = gains.k_theta * wrap(meas[2] - twin[2])
    if gains.feedforward and meas_vel is not None:
        vx, vy, wz = vx + meas_vel[0], vy + meas_vel[1], wz + meas_vel[2]
    speed = math.hypot(vx, vy)
    if speed > gains.v_cap:
        vx, vy = vx * gains.v_cap / speed, vy * gains.v_cap / speed
    wz = max(-gains.w_cap, min(gains.w_cap, wz))
    return TwinCommand(vx=vx, vy=vy, wz=wz)


class VelocityEstimator:
    """Finite-difference world velocity of a measured pose stream, low-pass filtered.

    ``tau`` (s): filter time constant. Samples closer than ``min_dt`` (s) are merged.
    """

    def __init__(self, tau: float = 0.05, min_dt: float = 1e-3):
        self.tau = tau
        self.min_dt = min_dt
        self.last: tuple[float, float, float, float] | None = None
        self.vel = (0.0, 0.0, 0.0)

    def update(self, t: float, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        if self.last is None:
            self.last = (t, *pose)
            return self.vel
        t0, x0, y0, th0 = self.last
        dt = t - t0
        if dt < self.min_dt:
            return self.vel
        raw = ((pose[0] - x0) / dt, (pose[1] - y0) / dt, wrap(pose[2] - th0) / dt)
        a = dt / (self.tau + dt)
        self.vel = tuple(v + a * (r - v) for v, r in zip(self.vel, raw))
        self.last = (t, *pose)
        return self.vel

    def reset(self) -> None:
        self.last = None
        self.vel = (0.0, 0.0, 0.0)


def integrate(pose: tuple[float, float, float], cmd: TwinCommand, dt: float) -> tuple[float, float, float]:
    """Kinematic twin (what a world does with a TwinCmd over ``dt`` s). For tests and benches."""
    if cmd.teleport:
        return (cmd.x, cmd.y, wrap(cmd.theta))
    return (pose[0] + cmd.vx * dt, pose[1] + cmd.vy * dt, wrap(pose[2] + cmd.wz * dt))

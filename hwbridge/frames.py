"""Frame conversion between a motion-capture frame and the world frame (pure functions).

A mocap system reports a rigid body as a position (m) and a unit quaternion in its own
3-D frame. Two conventions are common:

  * ``up_axis="z"`` (Vicon, Qualisys, VRPN defaults): the floor is the x-y plane. The
    planar coordinates are (u, v) = (x, y).
  * ``up_axis="y"`` (OptiTrack Motive default, right-handed): the floor is the x-z plane.
    Seen from above (+y), the right-handed planar axes are (u, v) = (x, -z), so that
    u x v = +y and headings are counter-clockwise about the up axis.

The planar heading is the direction of the body's forward axis (its local +x) projected
on the floor: theta = atan2(f_v, f_u) with f = R(q) e_x. This is exact for a body that
only yaws and robust to small roll/pitch.

The planar mocap pose is then mapped to the world frame by a 2-D similarity
:class:`Transform2D` (rotation ``yaw``, translation ``tx, ty``, uniform ``scale``):
``p_world = scale * R(yaw) p_mocap + t`` and ``theta_world = theta_mocap + yaw``.
Quaternions are (x, y, z, w) throughout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from swarmcover.ground.angles import wrap

UP_AXES = ("z", "y")


@dataclass(frozen=True, slots=True)
class Transform2D:
    """Mocap floor plane -> world frame: rotate by ``yaw`` (rad), scale, then translate (m)."""
    yaw: float = 0.0
    tx: float = 0.0
    ty: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        for name in ("yaw", "tx", "ty", "scale"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"transform.{name}: expected a finite number, got {v!r}")
        if self.scale <= 0:
            raise ValueError(f"transform.scale: must be > 0, got {self.scale!r}")

    def apply(self, u: float, v: float, theta: float) -> tuple[float, float, float]:
        """Planar mocap pose (m, m, rad) -> world pose (m, m, rad)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        x = self.scale * (c * u - s * v) + self.tx
        y = self.scale * (s * u + c * v) + self.ty
        return x, y, wrap(theta + self.yaw)

    def inverse(self, x: float, y: float, theta: float) -> tuple[float, float, float]:
        """World pose -> planar mocap pose (the inverse of :meth:`apply`)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = (x - self.tx) / self.scale, (y - self.ty) / self.scale
        return c * dx + s * dy, -s * dx + c * dy, wrap(theta - self.yaw)


def quat_rotate(q: tuple[float, float, float, float],
                vec: tuple[float, float, float]) -> tuple[float, float, float]:
    """Rotate ``vec`` by the unit quaternion ``q = (x, y, z, w)`` (normalised here)."""
    qx, qy, qz, qw = q
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"quaternion {q!r} has zero or invalid norm")
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    vx, vy, vz = vec
    # v' = v + 2 w (q x v) + 2 q x (q x v)
    cx = qy * vz - qz * vy
    cy = qz * vx - qx * vz
    cz = qx * vy - qy * vx
    ccx = qy * cz - qz * cy
    ccy = qz * cx - qx * cz
    ccz = qx * cy - qy * cx
    return (vx + 2.0 * (qw * cx + ccx), vy + 2.0 * (qw * cy + ccy), vz + 2.0 * (qw * cz + ccz))


def yaw_quat(theta: float, up_axis: str = "z") -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a pure rotation by ``theta`` (rad, CCW seen from above)."""
    _check_up(up_axis)
    h = 0.5 * theta
    if up_axis == "z":
        return (0.0, 0.0, math.sin(h), math.cos(h))
    return (0.0, math.sin(h), 0.0, math.cos(h))


def _check_up(up_axis: str) -> None:
    if up_axis not in UP_AXES:
        raise ValueError(f"up_axis: {up_axis!r} not one of {', '.join(UP_AXES)}")


def to_plane(position: tuple[float, float, float], quat: tuple[float, float, float, float],
             up_axis: str = "z") -> tuple[float, float, float]:
    """3-D mocap pose -> planar mocap pose (u, v, theta) on the floor (m, m, rad).

    Raises ValueError if the body's forward axis points (almost) straight up or down, so
    that no heading can be read.
    """
    _check_up(up_axis)
    fx, fy, fz = quat_rotate(quat, (1.0, 0.0, 0.0))
    px, py, pz = position
    if up_axis == "z":
        u, v, fu, fv = px, py, fx, fy
    else:
        u, v, fu, fv = px, -pz, fx, -fz
    if math.hypot(fu, fv) < 1e-6:
        raise ValueError(f"body forward axis is vertical (quaternion {quat!r}): no heading")
    return u, v, math.atan2(fv, fu)


def from_plane(u: float, v: float, theta: float, up_axis: str = "z",
               height: float = 0.0) -> tuple[tuple[float, float, float],
                                              tuple[float, float, float, float]]:
    """Planar mocap pose -> (position, quaternion) in the 3-D mocap frame; inverse of
    :func:`to_plane` for a body that only yaws. ``height``: along the up axis (m)."""
    _check_up(up_axis)
    pos = (u, v, height) if up_axis == "z" else (u, height, -v)
    return pos, yaw_quat(theta, up_axis)


def mocap_to_world(position, quat, up_axis: str, transform: Transform2D) -> tuple[float, float, float]:
    """3-D mocap pose -> world pose (x, y, theta) (m, m, rad)."""
    return transform.apply(*to_plane(position, quat, up_axis))


def world_to_mocap(x: float, y: float, theta: float, up_axis: str, transform: Transform2D,
                   height: float = 0.0):
    """World pose -> (position, quaternion) in the 3-D mocap frame (for stand-in sources)."""
    return from_plane(*transform.inverse(x, y, theta), up_axis=up_axis, height=height)

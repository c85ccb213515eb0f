"""Command output to live robots: unicycle conversion and the two wire formats.

  * ``output = "zenoh"``: LiveCmd (msgpack: robot, t, v, omega, ttl) on
    ``sc/<swarm>/live/<id>/cmd``; ``ttl`` ([hwbridge] cmd_ttl_s) is how long the robot's
    driver may execute it after receipt (hwbridge/driver.py);
  * ``output = "ros2"``: geometry_msgs/Twist in CDR on the key zenoh-bridge-ros2dds or
    rmw_zenoh maps ``<ros_namespace>/cmd_vel`` to (see :mod:`hwbridge.ros2`); with
    rmw_zenoh each sample carries the attachment rmw_zenoh requires. A Twist has no
    expiry field: the robot's base controller must time out cmd_vel itself
    (hwbridge/README.md, "What a robot's driver must do").

Both publishers use congestion control BLOCK and express (a command must not be dropped
nor wait for batching).
"""
from __future__ import annotations

import math
import os
import time

from .ros2 import Twist, cmd_vel_key, encode_twist, rmw_zenoh_attachment


def to_unicycle(vx: float, vy: float, wz: float, k_omega: float = 1.5,
                k_v: float = 1.0) -> tuple[float, float]:
    """Body-frame command (vx, vy m/s; wz rad/s) -> differential-drive (v m/s, omega rad/s).

    A differential-drive agent sends vy = 0: then v = vx, omega = wz. A non-zero vy (a
    holonomic-style desired velocity u) is mapped as in spec 4.8: alpha = atan2(vy, vx),
    omega = wz + k_omega alpha, v = k_v |u| max(0, cos alpha).
    """
    if not all(math.isfinite(c) for c in (vx, vy, wz)):
        return 0.0, 0.0
    if abs(vy) < 1e-9:
        return vx, wz
    alpha = math.atan2(vy, vx)
    return k_v * math.hypot(vx, vy) * max(0.0, math.cos(alpha)), wz + k_omega * alpha


class LiveCmdOutput:
    """LiveCmd on live/<id>/cmd, each valid for ``ttl`` seconds after its receipt."""

    def __init__(self, session, keys, robot: int, ttl: float = 0.3):
        from swarmcover.bus.session import publisher
        self.robot = robot
        self.ttl = ttl
        self.key = keys.live_cmd(robot)
        self.pub = publisher(session, self.key, block=True, express=True)

    def send(self, v: float, omega: float, t: float) -> None:
        from swarmcover.bus.messages import LiveCmd
        self.pub.put(LiveCmd(robot=self.robot, t=max(0.0, t), v=v, omega=omega,
                             ttl=self.ttl).encode())

    def close(self) -> None:
        try:
            self.pub.undeclare()
        except Exception:
            pass


class Ros2TwistOutput:
    """CDR Twist on a ROS 2 key (ros2dds or rmw_zenoh mapping)."""

    def __init__(self, session, key: str, mapping: str):
        import zenoh
        self.key = key
        self.mapping = mapping
        self.pub = session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        self.seq = 0
        self.gid = os.urandom(16)

    def send(self, v: float, omega: float, t: float) -> None:
        payload = encode_twist(Twist(lx=v, az=omega))
        self.seq += 1
        if self.mapping == "rmw_zenoh":
            att = rmw_zenoh_attachment(self.seq, time.time_ns(), self.gid)
            self.pub.put(payload, attachment=att)
        else:
            self.pub.put(payload)

    def close(self) -> None:
        try:
            self.pub.undeclare()
        except Exception:
            pass


def make_output(session, keys, robot, cfg):
    """The output of one :class:`hwbridge.config.LiveRobot` under a BridgeConfig."""
    if robot.output == "zenoh":
        return LiveCmdOutput(session, keys, robot.id, cfg.cmd_ttl_s)
    key = cmd_vel_key(robot.ros_mapping, robot.ros_namespace, cfg.ros_domain,
                      cfg.ros_bridge_namespace)
    return Ros2TwistOutput(session, key, robot.ros_mapping)

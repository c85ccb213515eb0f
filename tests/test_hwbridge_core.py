"""Pure parts of the hardware bridge: frames, twin sync, safety, CDR/ROS 2 keys, config,
mocap sources (scripted, libmotioncapture adapter), metrics. No processes, no network."""
from __future__ import annotations

import math
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmcover.hwbridge import config as hwconfig
from swarmcover.hwbridge.frames import (Transform2D, from_plane, mocap_to_world, to_plane, world_to_mocap,
                             wrap)
from swarmcover.hwbridge.metrics import (TrackLog, estimate_lag, formation_discrepancy, percentile,
                              summary)
from swarmcover.hwbridge.mocap import (INSTALL_HINT, LibMotionCaptureSource, RateMonitor,
                            ScriptedMocapSource, Trajectory, import_motioncapture,
                            samples_from_rigid_bodies)
from swarmcover.hwbridge.output import to_unicycle
from swarmcover.hwbridge.ros2 import (CdrError, PoseStamped, Twist, cmd_vel_key, decode_pose_stamped,
                           decode_twist, encode_pose_stamped, encode_twist, rmw_zenoh_attachment,
                           rmw_zenoh_key, ros2dds_key, topic_name)
from swarmcover.hwbridge.safety import (Gates, Limits, SafetyGate, clamp_unicycle, edge_distance,
                             inside_fence, point_in_polygon)
from swarmcover.hwbridge.twin import TwinGains, VelocityEstimator, integrate, twin_command

finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-math.pi, math.pi, exclude_max=True)


def close_angle(a, b, tol=1e-9):
    return abs(wrap(a - b)) < tol


# --------------------------------------------------------------------------- frames

@settings(max_examples=200, deadline=None)
@given(x=finite, y=finite, th=angle, yaw=angle, tx=finite, ty=finite,
       scale=st.floats(0.1, 10), up=st.sampled_from(["z", "y"]), h=st.floats(-2, 2))
def test_world_mocap_round_trip(x, y, th, yaw, tx, ty, scale, up, h):
    T = Transform2D(yaw, tx, ty, scale)
    pos, q = world_to_mocap(x, y, th, up, T, h)
    x2, y2, th2 = mocap_to_world(pos, q, up, T)
    assert x2 == pytest.approx(x, abs=1e-7) and y2 == pytest.approx(y, abs=1e-7)
    assert close_angle(th2, th, 1e-7)


def test_z_up_vs_y_up_axes():
    # Z-up: floor is x-y; a quarter turn about +z faces +y.
    assert to_plane((1.0, 2.0, 0.3), (0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)), "z") \
        == pytest.approx((1.0, 2.0, math.pi / 2))
    # Y-up (right-handed): floor coordinates are (x, -z); height is y.
    u, v, th = to_plane((1.0, 0.3, 2.0), (0, 0, 0, 1), "y")
    assert (u, v, th) == pytest.approx((1.0, -2.0, 0.0))
    # a quarter turn about +y takes the forward axis +x to -z, i.e. +v: CCW seen from above
    u, v, th = to_plane((0, 0, 0), (0, math.sin(math.pi / 4), 0, math.cos(math.pi / 4)), "y")
    assert th == pytest.approx(math.pi / 2)
    # the same floor pose expressed in both conventions maps to the same world pose
    T = Transform2D(0.5, -1.0, 0.5)
    pz, qz = from_plane(0.4, -0.7, 1.2, "z", 0.1)
    py, qy = from_plane(0.4, -0.7, 1.2, "y", 0.1)
    assert pz != py
    assert mocap_to_world(pz, qz, "z", T) == pytest.approx(mocap_to_world(py, qy, "y", T))


def test_heading_survives_small_tilt_and_unnormalised_quaternion():
    # yaw 0.8 rad about z, then a 5 degree roll about the body x axis; quaternion scaled by 3
    yaw, roll = 0.8, math.radians(5)
    qz = (0, 0, math.sin(yaw / 2), math.cos(yaw / 2))
    qr = (math.sin(roll / 2), 0, 0, math.cos(roll / 2))
    x1, y1, z1, w1 = qz
    x2, y2, z2, w2 = qr
    q = (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
         w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)
    q = tuple(3 * c for c in q)
    assert to_plane((0, 0, 0), q, "z")[2] == pytest.approx(yaw, abs=1e-9)


def test_frame_errors_name_the_problem():
    with pytest.raises(ValueError, match="up_axis"):
        to_plane((0, 0, 0), (0, 0, 0, 1), "x")
    with pytest.raises(ValueError, match="zero or invalid norm"):
        to_plane((0, 0, 0), (0, 0, 0, 0), "z")
    with pytest.raises(ValueError, match="vertical"):   # forward axis pointing up
        to_plane((0, 0, 0), (0, -math.sin(math.pi / 4), 0, math.cos(math.pi / 4)), "z")
    with pytest.raises(ValueError, match="transform.scale"):
        Transform2D(scale=0.0)


# --------------------------------------------------------------------------- twin sync

def test_twin_p_control_is_proportional_and_teleports():
    g = TwinGains(kp=3.0, k_theta=2.0, teleport_dist=0.2)
    c = twin_command((1.1, 2.05, 0.3), (1.0, 2.0, 0.1), g)
    assert not c.teleport
    assert (c.vx, c.vy, c.wz) == pytest.approx((0.3, 0.15, 0.4))
    c = twin_command((1.0, 2.0, 3.1), (1.0, 2.0, -3.1), g)       # heading error wraps
    assert c.wz == pytest.approx(2.0 * wrap(6.2))
    c = twin_command((1.5, 2.0, 0.3), (1.0, 2.0, 0.1), g)
    assert c.teleport and (c.x, c.y, c.theta) == (1.5, 2.0, 0.3)


@settings(max_examples=100, deadline=None)
@given(ex=st.floats(-0.14, 0.14), ey=st.floats(-0.14, 0.14), eth=angle,
       kp=st.floats(0.5, 8), dt=st.floats(0.005, 0.05))
def test_twin_error_contracts_toward_a_still_target(ex, ey, eth, kp, dt):
    # w_cap above k_theta * pi: the exponential bound holds for the unsaturated loop (with
    # the default 10 rad/s cap, kp = 8 and a heading error near pi saturate it)
    g = TwinGains(kp=kp, k_theta=kp, teleport_dist=0.2, w_cap=30.0)
    target = (1.0, 1.0, 0.5)
    twin = (1.0 - ex, 1.0 - ey, wrap(0.5 - eth))
    e0 = math.hypot(ex, ey)
    for _ in range(int(3.0 / (kp * dt)) + 1):     # three time constants
        twin = integrate(twin, twin_command(target, twin, g), dt)
    e1 = math.hypot(twin[0] - 1.0, twin[1] - 1.0)
    assert e1 <= e0 * math.exp(-2.5) + 1e-12
    assert abs(wrap(twin[2] - 0.5)) <= abs(eth) * math.exp(-2.5) + 1e-12


def _track(feedforward: bool, delay_ticks: int = 2, seconds: float = 20.0):
    """Closed loop: a scripted robot on a circle at 0.3 m/s, the twin integrated by a world
    ticking at 20 Hz that sees each command ``delay_ticks`` ticks late."""
    traj = Trajectory.from_spec({"path": "circle", "center": [1.5, 1.0], "radius": 0.6,
                                 "speed": 0.3}, "t")
    g = TwinGains(kp=3.0, k_theta=3.0, teleport_dist=0.2, feedforward=feedforward)
    dt = 0.05
    twin = (0.3, 1.0, 0.0)                            # spawned at the source: far away
    est = VelocityEstimator()
    queue = [twin_command(twin, twin, g)] * delay_ticks
    errs, teleports = [], 0
    for k in range(int(seconds / dt)):
        t = k * dt
        meas = traj.pose(t)
        vel = est.update(t, meas)
        cmd = twin_command(meas, twin, g, vel)
        teleports += cmd.teleport
        queue.append(cmd)
        twin = integrate(twin, queue.pop(0), dt)
        if t > 5.0:
            errs.append(math.hypot(twin[0] - meas[0], twin[1] - meas[1]))
    return errs, teleports


def test_scripted_robot_twin_converges_with_the_p_loop():
    errs, teleports = _track(feedforward=False)
    assert teleports >= 1                 # first sync from the source
    # a pure P loop lags a moving robot by about v / kp = 0.1 m (plus the tick delay)
    assert 0.05 < np.mean(errs) < 0.16 and max(errs) < 0.2
    errs_ff, _ = _track(feedforward=True)
    assert np.mean(errs_ff) < 0.3 * np.mean(errs)


def test_velocity_estimator_recovers_a_constant_velocity():
    est = VelocityEstimator(tau=0.02)
    for k in range(100):
        t = k * 0.01
        v = est.update(t, (0.2 * t, -0.1 * t, wrap(0.5 * t)))
    assert v == pytest.approx((0.2, -0.1, 0.5), abs=1e-6)


# --------------------------------------------------------------------------- safety

@settings(max_examples=200, deadline=None)
@given(v=st.floats(-5, 5), w=st.floats(-10, 10), vm=st.floats(0.05, 2), wm=st.floats(0.1, 5))
def test_clamp_keeps_limits_and_curvature(v, w, vm, wm):
    v2, w2 = clamp_unicycle(v, w, vm, wm)
    assert abs(v2) <= vm + 1e-12 and abs(w2) <= wm + 1e-12
    assert v2 * w - w2 * v == pytest.approx(0.0, abs=1e-9)     # same direction in (v, w)
    if abs(v) <= vm and abs(w) <= wm:
        assert (v2, w2) == (v, w)


def test_clamp_rejects_non_finite():
    assert clamp_unicycle(math.nan, 1.0, 1, 1) == (0.0, 0.0)
    assert clamp_unicycle(1.0, math.inf, 1, 1) == (0.0, 0.0)


def test_deadman_stops_within_deadman_of_command_silence():
    g = SafetyGate(1, Limits(v_max=0.3, w_max=2.0, deadman_s=0.3))
    assert g.decide(0.0).reason == "no_command"
    g.on_command(10.0, 0.2, 0.5)
    g.on_pose(10.0, 0.0, 0.0)
    t = 10.0
    while t < 10.29:                         # mocap keeps flowing, commands stop
        t += 0.01
        g.on_pose(t, 0.0, 0.0)
        d = g.decide(t)
        assert (d.v, d.omega, d.reason) == (0.2, 0.5, "ok")
    g.on_pose(10.301, 0.0, 0.0)
    d = g.decide(10.301)
    assert d.stopped and (d.v, d.omega, d.reason) == (0.0, 0.0, "command_stale")
    g.on_command(10.35, 0.1, 0.0)            # commands resume: motion resumes
    assert g.decide(10.36).reason == "ok"


def test_deadman_stops_on_mocap_silence_and_clamps():
    g = SafetyGate(1, Limits(v_max=0.3, w_max=2.0, deadman_s=0.3))
    g.on_pose(0.0, 1.0, 1.0)
    for t in np.arange(0.0, 0.6, 0.05):
        g.on_command(float(t), 0.6, 1.0)
    assert g.decide(0.29).reason == "clamped"
    assert (g.decide(0.29).v, g.decide(0.29).omega) == pytest.approx((0.3, 0.5))
    assert g.decide(0.55).reason == "mocap_stale"
    assert g.counts["mocap_stale"] == 1


def test_geofence():
    square = ((0, 0), (2, 0), (2, 2), (0, 2))
    assert point_in_polygon(1, 1, square) and not point_in_polygon(2.5, 1, square)
    assert edge_distance(1, 0.25, square) == pytest.approx(0.25)
    assert inside_fence(1, 1, None) and inside_fence(1, 0.25, square, 0.2)
    assert not inside_fence(1, 0.15, square, 0.2)
    g = SafetyGate(1, Limits(geofence=square, margin=0.1))
    g.on_command(0.0, 0.2, 0.0)
    g.on_pose(0.0, 1.0, 1.0)
    assert g.decide(0.01).reason == "ok"
    g.on_pose(0.02, 2.05, 1.0)             # drove out of the fence
    d = g.decide(0.03)
    assert d.reason == "geofence" and (d.v, d.omega) == (0.0, 0.0)
    g.on_pose(0.04, 1.95, 1.0)             # inside, but within the margin
    assert g.decide(0.05).reason == "geofence"


def test_gates_refuse_robots_that_are_not_live():
    gates = Gates({3: Limits()})
    assert gates.on_command(0.0, 3, 0.1, 0.0)
    assert not gates.on_command(0.0, 4, 0.1, 0.0)
    assert gates.decide(0.0, 4) is None and gates.refused == 1 and not gates.is_live(4)


def test_to_unicycle():
    assert to_unicycle(0.2, 0.0, 0.5) == (0.2, 0.5)
    v, w = to_unicycle(0.0, 0.3, 0.0, k_omega=1.5)   # sideways: turn in place first
    assert v == pytest.approx(0.0, abs=1e-12) and w == pytest.approx(1.5 * math.pi / 2)
    v, w = to_unicycle(0.3, 0.3, 0.0, k_omega=1.0, k_v=1.0)
    assert v == pytest.approx(0.3) and w == pytest.approx(math.pi / 4)
    assert to_unicycle(math.nan, 0, 0) == (0.0, 0.0)


# --------------------------------------------------------------------------- ROS 2 / CDR

# Known CDR bytes. geometry_msgs/Twist is two geometry_msgs/Vector3 (float64 x, y, z), so
# its CDR is the 4-byte encapsulation header then six 8-aligned float64. The header
# b"\x00\x01\x00\x00" (CDR, little endian) and the float64 little-endian encodings of 128.0
# (00 00 00 00 00 00 60 40) and 1.0 (00 00 00 00 00 00 f0 3f) are the byte strings of
# ternaris/rosbags tests/test_serde.py (MSG_MAGN, a sensor_msgs/MagneticField fixture); the
# all-zero 52-byte Twist is the stop command public zenoh cmd_vel code sends
# (b'\x00\x01\x00\x00' + b'\x00' * 48).
TWIST_1_0_0_0_0_128 = bytes.fromhex(
    "00010000"
    "000000000000f03f" "0000000000000000" "0000000000000000"
    "0000000000000000" "0000000000000000" "0000000000006040")
TWIST_ZERO = b"\x00\x01\x00\x00" + b"\x00" * 48

# ternaris/rosbags tests/test_serde.py MSG_MAGN, first 84 bytes: a std_msgs/Header
# (stamp 708 s 256 ns, frame_id 'foo42'), 6 bytes of alignment padding, then float64s
# 128, 128, 128, 1, 0, 0, 0 -- exactly the layout of a geometry_msgs/PoseStamped.
ROSBAGS_MAGN_PREFIX = (
    b"\x00\x01\x00\x00"
    b"\xc4\x02\x00\x00\x00\x01\x00\x00"
    b"\x06\x00\x00\x00foo42\x00"
    b"\x00\x00\x00\x00\x00\x00"
    + b"\x00\x00\x00\x00\x00\x00\x60\x40" * 3
    + b"\x00\x00\x00\x00\x00\x00\xF0\x3F"
    + b"\x00\x00\x00\x00\x00\x00\x00\x00" * 3)
ROSBAGS_MAGN_BIG_PREFIX = (
    b"\x00\x00\x00\x00"
    b"\x00\x00\x02\xc4\x00\x00\x01\x00"
    b"\x00\x00\x00\x06foo42\x00"
    b"\x00\x00\x00\x00\x00\x00"
    + b"\x40\x60\x00\x00\x00\x00\x00\x00" * 3
    + b"\x3F\xF0\x00\x00\x00\x00\x00\x00"
    + b"\x00\x00\x00\x00\x00\x00\x00\x00" * 3)


def test_cdr_twist_matches_known_bytes():
    assert encode_twist(Twist(lx=1.0, az=128.0)) == TWIST_1_0_0_0_0_128
    assert encode_twist(Twist()) == TWIST_ZERO
    assert len(TWIST_ZERO) == 52
    assert decode_twist(TWIST_1_0_0_0_0_128) == Twist(lx=1.0, az=128.0)
    tw = Twist(0.25, -0.5, 0.0, 0.0, 0.0, -1.75)
    assert decode_twist(encode_twist(tw)) == tw
    with pytest.raises(ValueError, match="52"):
        decode_twist(TWIST_ZERO[:40])
    with pytest.raises(ValueError, match="encapsulation"):
        decode_twist(b"\x00\x07\x00\x00" + b"\x00" * 48)


def test_pose_stamped_decodes_a_known_header_layout():
    for raw in (ROSBAGS_MAGN_PREFIX, ROSBAGS_MAGN_BIG_PREFIX):
        p = decode_pose_stamped(raw)
        assert p.frame_id == "foo42"
        assert p.stamp == pytest.approx(708 + 256e-9)
        assert p.position == (128.0, 128.0, 128.0) and p.orientation == (1.0, 0.0, 0.0, 0.0)
    p = PoseStamped(12.5, "mocap", (1.0, -2.0, 0.25), (0.0, 0.0, 0.6, 0.8))
    assert decode_pose_stamped(encode_pose_stamped(p)) == p
    with pytest.raises(ValueError, match="too short"):
        decode_pose_stamped(ROSBAGS_MAGN_PREFIX[:60])


# rosbags encodes and decodes both messages now; the hand-written struct codecs they replaced
# (bench/cdr.py keeps them as the benchmark's baseline) define the wire they must keep
poses = st.builds(
    PoseStamped, st.floats(-2.0e9, 2.0e9), st.text(max_size=40),
    st.tuples(*[st.floats(width=64)] * 3), st.tuples(*[st.floats(width=64)] * 4))
finite_poses = st.builds(
    PoseStamped, st.floats(-2.0e9, 2.0e9), st.text(max_size=40),
    st.tuples(*[finite] * 3), st.tuples(*[finite] * 4))
twists = st.builds(Twist, *[st.floats(-1e300, 1e300)] * 6)


@settings(max_examples=300, deadline=None)
@given(p=poses, tw=twists)
def test_rosbags_encoders_write_the_hand_written_bytes(p, tw):
    from bench.cdr import struct_encode_pose_stamped, struct_encode_twist
    assert encode_pose_stamped(p) == struct_encode_pose_stamped(p)
    assert encode_twist(tw) == struct_encode_twist(tw)


@settings(max_examples=300, deadline=None)
@given(p=finite_poses, tw=twists)
def test_rosbags_codecs_round_trip(p, tw):
    q = decode_pose_stamped(encode_pose_stamped(p))
    assert (q.frame_id, q.position, q.orientation) == (p.frame_id, p.position, p.orientation)
    assert q.stamp == pytest.approx(p.stamp, rel=1e-15, abs=1e-9)
    assert decode_twist(encode_twist(tw)) == tw


def _outcome(fn, data):
    try:
        return fn(data)
    except CdrError as e:
        return CdrError, str(e).split(":")[0]  # the message named, not rosbags' wording


@settings(max_examples=500, deadline=None)
@given(p=finite_poses, tw=twists, big=st.booleans(), cut=st.integers(0, 200),
       at=st.integers(0, 200), byte=st.integers(0, 255),
       how=st.sampled_from(["cut", "set", "grow", "none"]))
def test_rosbags_decoders_accept_and_refuse_what_the_hand_written_ones_did(
        p, tw, big, cut, at, byte, how):
    """Valid messages of either endianness, truncated, with one byte changed or with bytes
    after them: the rosbags decoders give the same value, or raise CdrError when the struct
    decoders did. Only 4 or more bytes after the message (up to 3 may be padding) are
    refused where the struct decoders ignored them."""
    from bench.cdr import struct_decode_pose_stamped, struct_decode_twist
    from swarmcover.ros2 import typestore
    ts = typestore()
    for data, typename, new, old in (
            (encode_pose_stamped(p), "geometry_msgs/msg/PoseStamped", decode_pose_stamped,
             struct_decode_pose_stamped),
            (encode_twist(tw), "geometry_msgs/msg/Twist", decode_twist, struct_decode_twist)):
        if big:
            data = bytes(ts.serialize_cdr(ts.deserialize_cdr(data, typename), typename,
                                          little_endian=False))
            assert data[:4] == b"\x00\x00\x00\x00"
        if how == "cut":
            data = data[:cut]
        elif how == "set" and at < len(data):
            data = data[:at] + bytes([byte]) + data[at + 1:]
        elif how == "grow":
            data += bytes([byte]) * (cut % 12)
            if cut % 12 >= 4:
                assert old(data) == old(data[:len(data) - cut % 12])
                assert _outcome(new, data) == (CdrError, typename.rsplit("/", 1)[1])
                continue
        assert _outcome(new, data) == _outcome(old, data)


@pytest.mark.parametrize("data, message", [
    (ROSBAGS_MAGN_PREFIX[:3], "PoseStamped: 3 bytes, shorter than the CDR header"),
    (b"\x00\x07" + ROSBAGS_MAGN_PREFIX[2:], "PoseStamped: encapsulation 00070000 is not plain CDR"),
    (ROSBAGS_MAGN_PREFIX[:14], "PoseStamped: 14 bytes, too short"),
    (ROSBAGS_MAGN_PREFIX[:60], "PoseStamped: 60 bytes, too short"),
    (ROSBAGS_MAGN_PREFIX[:12] + b"\xe8\x03\x00\x00" + ROSBAGS_MAGN_PREFIX[16:],
     "PoseStamped: frame_id (84 bytes in all): Invalid string length 1000"),
    (ROSBAGS_MAGN_PREFIX[:12] + b"\x00\x00\x00\x00" + ROSBAGS_MAGN_PREFIX[16:],
     "PoseStamped: frame_id (84 bytes in all): Invalid string length 0"),
    (ROSBAGS_MAGN_PREFIX[:16] + b"foo42X" + ROSBAGS_MAGN_PREFIX[22:],
     "PoseStamped: frame_id (84 bytes in all): Missing string terminator"),
    (ROSBAGS_MAGN_PREFIX[:16] + b"fo\xff42\x00" + ROSBAGS_MAGN_PREFIX[22:],
     "PoseStamped: frame_id is not UTF-8"),
    (ROSBAGS_MAGN_PREFIX[:-8] + b"\x00\x00\x00\x00\x00\x00\xf8\x7f",
     "PoseStamped: non-finite value in (128.0, 128.0, 128.0, 1.0, 0.0, 0.0, nan)"),
    (ROSBAGS_MAGN_PREFIX + b"\x00" * 4, "PoseStamped: 88 bytes, longer than the message"),
    (TWIST_ZERO[:2], "Twist: 2 bytes, shorter than the CDR header"),
    (TWIST_ZERO[:51], "Twist: 51 bytes, expected 52"),
    (TWIST_ZERO[:-8] + b"\x00\x00\x00\x00\x00\x00\xf0\x7f",
     "Twist: non-finite value in (0.0, 0.0, 0.0, 0.0, 0.0, inf)"),
    (TWIST_ZERO + b"\x00" * 8, "Twist: 60 bytes, longer than the message"),
])
def test_cdr_decoders_name_what_was_wrong(data, message):
    with pytest.raises(CdrError) as e:
        (decode_twist if message.startswith("Twist") else decode_pose_stamped)(data)
    assert str(e.value).startswith(message)


def test_a_pose_with_covariance_is_not_read_as_a_pose_stamped():
    # up to 3 bytes after the message may be padding (rosbags accepts them, as ROS 2 does)
    assert decode_pose_stamped(ROSBAGS_MAGN_PREFIX + b"\x00" * 3) == \
        decode_pose_stamped(ROSBAGS_MAGN_PREFIX)
    from swarmcover.ros2 import serialize, typestore
    T = typestore().types
    msg = typestore().deserialize_cdr(ROSBAGS_MAGN_PREFIX, "geometry_msgs/msg/PoseStamped")
    cov = T["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=msg.header, pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=msg.pose, covariance=np.zeros(36)))
    data = serialize(cov, "geometry_msgs/msg/PoseWithCovarianceStamped")
    assert data[:84] == ROSBAGS_MAGN_PREFIX  # what the struct decoder read as a PoseStamped
    with pytest.raises(CdrError, match="PoseStamped: 372 bytes, longer than the message"):
        decode_pose_stamped(data)


def test_ros2_key_mappings():
    topic = topic_name("/scarab1")
    assert topic == "/scarab1/cmd_vel" and topic_name("/") == "/cmd_vel"
    # zenoh-bridge-ros2dds: strip the leading '/', prefix the bridge namespace if not "/"
    assert ros2dds_key(topic) == "scarab1/cmd_vel"
    assert ros2dds_key(topic, "/lab") == "lab/scarab1/cmd_vel"
    # rmw_zenoh: <domain>/<name>/<dds type>/<RIHS01 type hash>
    assert rmw_zenoh_key(topic, 0) == (
        "0/scarab1/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
    assert cmd_vel_key("rmw_zenoh", "/a/b", 7).startswith("7/a/b/cmd_vel/")
    with pytest.raises(ValueError, match="ros_namespace"):
        topic_name("scarab1")
    with pytest.raises(ValueError, match="ros_mapping"):
        cmd_vel_key("dds", "/x")
    import zenoh
    for mapping in ("ros2dds", "rmw_zenoh"):
        zenoh.KeyExpr(cmd_vel_key(mapping, "/scarab1"))       # valid Zenoh keys


def test_rmw_zenoh_attachment_is_zenoh_ext_serialisation():
    from zenoh.ext import Int64, UInt8, z_serialize
    gid = bytes(range(16))
    expected = z_serialize((Int64(42), Int64(1_700_000_000_123_456_789),
                            [UInt8(b) for b in gid])).to_bytes()
    assert rmw_zenoh_attachment(42, 1_700_000_000_123_456_789, gid) == expected


# --------------------------------------------------------------------------- config

BASE = """
name = "t"
rv = 2.0
[map]
boundary = [[0, 0], [3, 0], [3, 2], [0, 2]]
sources = [{x = 0.5, y = 1.0, theta = 0.0}]
[robots]
v_max = 0.4
[hwbridge]
up_axis = "y"
transform = {yaw = 0.5, tx = 1.0}
[[hwbridge.robots]]
id = 4
body = "scarab4"
"""


def test_config_defaults_and_mixed_toml():
    cfg = hwconfig.loads(BASE, "t.toml")
    r = cfg.robot(4)
    assert (r.kind, r.output, r.ros_namespace, r.v_max, r.w_max) == ("diffdrive", "zenoh",
                                                                       "/scarab4", 0.4, 2.0)
    assert cfg.teleport_m == pytest.approx(0.4)          # 0.2 x rv
    assert cfg.fence_polygon() == ((0, 0), (3, 0), (3, 2), (0, 2))
    assert cfg.transform == Transform2D(0.5, 1.0, 0.0, 1.0) and cfg.up_axis == "y"
    assert cfg.map_sources == ((0.5, 1.0, 0.0),)
    mixed = hwconfig.load("configs/mixed.toml")
    assert mixed.live_ids == (1, 2) and all(r.fake for r in mixed.robots)
    assert {r.output for r in mixed.robots} == {"zenoh", "ros2"}


@pytest.mark.parametrize("patch, needle", [
    ('kp = -1', "[hwbridge] kp = -1"),
    ('kpp = 3', "[hwbridge] kpp = 3: unknown field"),
    ('up_axis = "x"', "[hwbridge] up_axis = 'x'"),
    ('geofence = [[0, 0], [1, 0]]', "[hwbridge] geofence"),
    ('rate_band_hz = [200, 50]', "[hwbridge] rate_band_hz = [200, 50]"),
    ('mocap = {type = "vicon"}', "[hwbridge] mocap.type = 'vicon'"),
    ('transform = {yaw = 0.5, rot = 1}\nup_axis = "y"', "[hwbridge.transform] rot = 1: unknown field"),
    ('fake = {slip = 2.0}', "[hwbridge.fake] slip = 2.0"),
])
def test_config_errors_name_file_section_field_value(patch, needle):
    text = BASE.replace('up_axis = "y"\ntransform = {yaw = 0.5, tx = 1.0}', patch)
    with pytest.raises(hwconfig.ConfigError) as e:
        hwconfig.loads(text, "t.toml")
    assert str(e.value).startswith("t.toml: ") and needle in str(e.value)


@pytest.mark.parametrize("extra, needle", [
    ('output = "serial"', "[hwbridge.robots[1]] output = 'serial'"),
    ('kind = "holonomic"', "[hwbridge.robots[1]] kind = 'holonomic'"),
    ('ros_namespace = "scarab5"', "ros_namespace = 'scarab5'"),
    ('speed = 1', "[hwbridge.robots[1]] speed = 1: unknown field"),
    ('start = [1, 2]', "[hwbridge.robots[1]] start = [1, 2]"),
])
def test_config_robot_errors(extra, needle):
    text = BASE + f'[[hwbridge.robots]]\nid = 5\nbody = "scarab5"\n{extra}\n'
    with pytest.raises(hwconfig.ConfigError, match=None) as e:
        hwconfig.loads(text, "t.toml")
    assert needle in str(e.value)


def test_config_duplicates_and_missing_section():
    dup = BASE + '[[hwbridge.robots]]\nid = 4\nbody = "other"\n'
    with pytest.raises(hwconfig.ConfigError, match="duplicate live robot id"):
        hwconfig.loads(dup, "t.toml")
    with pytest.raises(hwconfig.ConfigError, match=r"t.toml: no \[hwbridge\] section"):
        hwconfig.loads('rv = 1.0\n', "t.toml")
    with pytest.raises(hwconfig.ConfigError, match="cannot read"):
        hwconfig.load("/nonexistent/x.toml")


# --------------------------------------------------------------------------- mocap sources

class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_scripted_source_rate_latency_frames_rename_gaps_dropout():
    clock = FakeClock()
    T = Transform2D(0.5, -1.0, 0.5)
    spec = {"type": "scripted", "rate_hz": 100, "latency_s": 0.05, "rename": {"b": "b_renamed"},
            "bodies": [{"body": "a", "path": "circle", "center": [1, 1], "radius": 0.5, "speed": 0.25},
                       {"body": "b", "path": "static", "pose": [2, 1, 0.3], "gaps": [[0.5, 0.8]]},
                       {"body": "c", "path": "line", "start": [0, 0], "end": [1, 0], "speed": 0.5}]}
    src = ScriptedMocapSource(spec, "y", T, clock=clock, wall=lambda: 0.0)
    clock.t += 0.04
    assert src.poll() == []                    # nothing older than the latency yet
    got = []
    for _ in range(100):                       # 1 s in 10 ms steps
        clock.t += 0.01
        got += src.poll()
    by = {}
    for s in got:
        by.setdefault(s.body, []).append(s)
    assert set(by) == {"a", "b_renamed", "c"}
    assert 90 <= len(by["a"]) <= 101             # 100 Hz, minus the latency
    assert 60 <= len(by["b_renamed"]) <= 72      # 0.3 s gap
    for s in by["a"]:                            # samples in the mocap frame map back to truth
        x, y, th = mocap_to_world(s.position, s.quat, "y", T)
        tx, ty, tth = src.truth("a", s.t)
        assert (x, y) == pytest.approx((tx, ty), abs=1e-9) and close_angle(th, tth, 1e-9)
    assert all(s.position[1] == 0.0 for s in by["c"])   # Y-up: height is y
    # dropouts drop about the requested fraction
    clock2 = FakeClock()
    src2 = ScriptedMocapSource({"type": "scripted", "dropout": 0.3, "seed": 3,
                                "bodies": [{"body": "a"}]}, clock=clock2)
    n = 0
    for _ in range(500):
        clock2.t += 0.01
        n += len(src2.poll())
    assert 0.6 * 500 < n < 0.8 * 500


def test_trajectories():
    line = Trajectory.from_spec({"path": "line", "start": [0, 0], "end": [2, 0], "speed": 1.0}, "t")
    assert line.pose(1.0)[:2] == pytest.approx((1.0, 0.0))
    assert line.pose(3.0)[:2] == pytest.approx((1.0, 0.0)) and close_angle(line.pose(3.0)[2], math.pi)
    wp = Trajectory.from_spec({"path": "waypoints", "points": [[0, 0], [1, 0], [1, 1]],
                               "speed": 1.0}, "t")
    assert wp.pose(1.5)[:2] == pytest.approx((1.0, 0.5)) and close_angle(wp.pose(1.5)[2], math.pi / 2)
    circ = Trajectory.from_spec({"path": "circle", "center": [0, 0], "radius": 1, "speed": 1}, "t")
    assert circ.pose(math.pi / 2)[:2] == pytest.approx((0.0, 1.0), abs=1e-12)
    assert close_angle(circ.pose(math.pi / 2)[2], math.pi)
    with pytest.raises(ValueError, match="t.radius"):
        Trajectory.from_spec({"path": "circle", "radius": -1}, "t")
    with pytest.raises(ValueError, match="t.path"):
        Trajectory.from_spec({"path": "spiral"}, "t")


class StandInQuat:
    """Same attributes as libmotioncapture's Python Quaternion (x, y, z, w properties)."""

    def __init__(self, x, y, z, w):
        self.x, self.y, self.z, self.w = x, y, z, w


class StandInRigidBody:
    """Same attributes as libmotioncapture's RigidBody: name, position (numpy), rotation."""

    def __init__(self, name, position, q):
        self.name = name
        self.position = np.asarray(position, dtype=np.float32)
        self.rotation = StandInQuat(*q)


def test_libmotioncapture_adapter_maps_rigid_bodies():
    q = (0.0, 0.0, math.sin(0.25), math.cos(0.25))
    bodies = {"scarab1": StandInRigidBody("scarab1", [1.0, 2.0, 0.1], q),
              "occluded": StandInRigidBody("occluded", [math.nan] * 3, (0, 0, 0, 1))}
    out = samples_from_rigid_bodies(bodies, 12.0, 3.0)
    assert len(out) == 1
    s = out[0]
    assert (s.body, s.t, s.recv) == ("scarab1", 12.0, 3.0)
    assert s.position == pytest.approx((1.0, 2.0, 0.1)) and s.quat == pytest.approx(q)
    assert mocap_to_world(s.position, s.quat, "z", Transform2D())[2] == pytest.approx(0.5)
    # also accepts a list of bodies
    assert samples_from_rigid_bodies(list(bodies.values()), 0.0, 0.0)[0].body == "scarab1"


def test_libmotioncapture_source_with_a_stand_in_module():
    calls = []

    class StandInMocap:
        def __init__(self):
            self.frames = 0

        def waitForNextFrame(self):
            import time as _t
            _t.sleep(0.005)
            self.frames += 1

        @property
        def rigidBodies(self):
            return {"b1": StandInRigidBody("b1", [0.5, 0.5, 0.0], (0, 0, 0, 1))}

    def connect(system, cfg):
        calls.append((system, cfg))
        return StandInMocap()

    src = LibMotionCaptureSource("optitrack", {"hostname": "10.0.0.2", "port": 1511},
                                 module=types.SimpleNamespace(connect=connect))
    try:
        got = src.poll(timeout=2.0)
        assert got and got[0].body == "b1"
        assert calls == [("optitrack", {"hostname": "10.0.0.2", "port": "1511"})]  # strings
    finally:
        src.close()


def test_missing_motioncapture_says_how_to_install():
    try:
        import motioncapture  # noqa: F401
        pytest.skip("motioncapture is installed here")
    except Exception:
        pass
    with pytest.raises(ImportError) as e:
        import_motioncapture()
    assert "pip install motioncapture" in str(e.value) and INSTALL_HINT in str(e.value)


def test_rate_monitor_reports_missing_unknown_silent_and_off_rate_bodies():
    m = RateMonitor({"scarab1": 1, "scarab2": 2}, band=(50, 200), silence_s=0.5)
    t = 0.0
    for k in range(150):                       # scarab1 at 100 Hz, scarab2 at 20 Hz
        t = k * 0.01
        m.on_sample("scarab1", t)
        if k % 5 == 0:
            m.on_sample("scarab2", t)
        m.on_sample("scarab_1", t)             # a renamed body
    w = "\n".join(m.check(t, started=0.0))
    assert "scarab2' (robot 2) rate 20.0 Hz outside [50, 200]" in w
    assert not any(line.startswith("mocap body 'scarab1'") for line in w.splitlines())
    assert "'scarab_1' is not configured" in w
    assert m.rate("scarab1", t) == pytest.approx(100, rel=0.05)
    assert m.check(t + 0.1, 0.0) == []         # repeated at most every repeat_s
    w2 = "\n".join(m.check(t + 6.0, 0.0))
    assert "scarab1' (robot 1) silent for 6.00 s" in w2
    m2 = RateMonitor({"ghost": 9})
    assert "'ghost' (robot 9) not seen; bodies seen: none" in m2.check(1.0, 0.0)[0]


# --------------------------------------------------------------------------- metrics

def test_metrics_lag_formation_summary():
    tm = [k * 0.01 for k in range(500)]
    pm = [(0.3 * t, 0.0, 0.0) for t in tm]
    tt = [k * 0.05 for k in range(20, 90)]
    pt = [(0.3 * (t - 0.12), 0.0, 0.0) for t in tt]       # twin 0.12 s behind
    assert estimate_lag(tm, pm, tt, pt) == pytest.approx(0.12, abs=0.006)
    sim = {1: (0.0, 0.0, 0.0), 2: (0.5, 0.0, 0.0), 7: (0.0, 0.5, 0.0), 9: (5.0, 5.0, 0.0)}
    assert formation_discrepancy(sim, sim, [1], 1.0) == [0.0, 0.0]    # 9 is out of range
    real = dict(sim)
    real[1] = (0.0, 0.0, 0.1)                                        # live robot turned
    assert formation_discrepancy(real, sim, [1], 1.0) == pytest.approx([0.1, 0.1])
    assert percentile([1, 2, 3, 4, 5], 50) == 3 and summary([])["n"] == 0
    log = TrackLog(settle_s=0.5)
    for k in range(200):
        t = k * 0.01
        log.on_mocap(1, t, (t * 0.1, 0.0, 0.0))
        if k % 5 == 0:
            log.on_twin(1, t, (t * 0.1 - 0.01, 0.0, 0.0))
    rep = log.report()["1"]
    assert rep["position_error_m"]["mean"] == pytest.approx(0.01)
    assert rep["position_error_m"]["n"] == 30           # 2 s at 20 Hz, minus 0.5 s settle


# ---------------------------------------------------------------------- stand-in room
ROOM_BOX = [(0, 0), (2.5, 0), (2.5, 2.0), (0, 2.0)]


def _drive(sim, v, w, seconds, dt=0.005, t0=0.0):
    sim.command(t0, v, w)
    t = t0
    while t < t0 + seconds:
        t += dt
        sim.step(t, dt)
    return t


def test_room_pushes_the_body_out_of_walls_and_corners():
    from swarmcover.hwbridge.room import Room
    room = Room.from_polygons(ROOM_BOX, [[(1, 1), (1.5, 1), (1.5, 1.5), (1, 1.5)]], radius=0.06)
    assert len(room) == 8
    assert room.collide(1.0, 0.5) == (1.0, 0.5, False)            # free: untouched
    x, y, hit = room.collide(-0.01, 0.5, prev=(0.07, 0.5))         # through the left wall
    assert hit and (x, y) == pytest.approx((0.06, 0.5))
    x, y, hit = room.collide(0.0, 0.5, prev=(0.07, 0.5))           # exactly on it
    assert hit and (x, y) == pytest.approx((0.06, 0.5))
    x, y, hit = room.collide(0.02, 0.03)                           # into the corner
    assert hit and x >= 0.06 - 1e-9 and y >= 0.06 - 1e-9
    x, y, hit = room.collide(1.25, 0.97)                           # against the obstacle
    assert hit and (x, y) == pytest.approx((1.25, 0.94))
    assert room.collide(5.0, 1.0) == (5.0, 1.0, False)             # outside stays outside


@settings(max_examples=60, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(0.1, 0.6), st.floats(-1.0, 1.0),
       st.floats(0.01, 0.2))
def test_walled_stand_in_never_leaves_the_map(theta, v, w, dt):
    """A stand-in driven at (and through) the walls for seconds stays inside, its centre at
    least the body radius from every wall -- so a geofence at the map boundary never trips
    for a robot that only touches walls, whatever the control period (dt up to 0.2 s)."""
    from swarmcover.hwbridge.fake_robot import DiffDriveSim, DriveParams
    from swarmcover.hwbridge.room import Room
    room = Room.from_polygons(ROOM_BOX, radius=0.06)
    sim = DiffDriveSim((0.3, 1.0, theta), DriveParams(latency_s=0.0), seed=1, room=room)
    _drive(sim, v, w, 8.0, dt=dt)
    assert point_in_polygon(sim.x, sim.y, ROOM_BOX)
    assert edge_distance(sim.x, sim.y, ROOM_BOX) >= 0.06 - 1e-6
    assert inside_fence(sim.x, sim.y, tuple(ROOM_BOX), 0.0)


def test_stand_in_slides_along_a_wall_and_backs_off_it():
    from swarmcover.hwbridge.fake_robot import DiffDriveSim, DriveParams
    from swarmcover.hwbridge.room import Room
    room = Room.from_polygons(ROOM_BOX, radius=0.06)
    p = DriveParams(latency_s=0.0, v_noise=0.0, w_noise=0.0, slip=0.0)
    sim = DiffDriveSim((0.3, 0.4, math.pi - 0.3), p, room=room)     # toward the left wall
    t = _drive(sim, 0.3, 0.0, 3.0)
    assert sim.x == pytest.approx(0.06, abs=1e-6)                   # pressed against it
    assert 0.4 < sim.y < 2.0 - 0.06                                  # slid up along it
    assert sim.wall_time > 1.0
    _drive(sim, -0.3, 0.0, 0.5, t0=t)                                # reverse: comes off
    assert sim.x > 0.15
    free = DiffDriveSim((0.3, 0.4, math.pi - 0.3), p)               # no room: leaves the map
    _drive(free, 0.3, 0.0, 3.0)
    assert not point_in_polygon(free.x, free.y, ROOM_BOX)


def test_geofence_passes_a_robot_touching_the_wall_and_stops_one_beyond_it():
    box = tuple(ROOM_BOX)
    g = SafetyGate(1, Limits(geofence=box, margin=0.0))
    g.on_command(0.0, 0.2, 0.0)
    g.on_pose(0.0, 0.06, 0.06)               # body radius 0.06 against two walls: a corner
    assert g.decide(0.01).reason == "ok"
    g.on_pose(0.02, -0.005, 0.4)             # centre beyond the wall: left the map
    assert g.decide(0.03).reason == "geofence"


def test_stand_in_room_comes_from_the_run_config_map(tmp_path):
    from swarmcover.hwbridge.fake_robot import make_room
    cfg = tmp_path / "room.toml"
    cfg.write_text('name = "room"\nrv = 1.0\n[map]\nboundary = [[0, 0], [2.5, 0], [2.5, 2], [0, 2]]\n'
                   'obstacles = [{type = "rect", min = [1, 1], max = [1.5, 1.5]}]\n'
                   'sources = [{x = 0.3, y = 1.0}]\n[robots]\nradius = 0.08\n')
    room = make_room("map", str(cfg), None, None)
    assert len(room) == 8 and room.radius == 0.08
    assert make_room("none", str(cfg), None, None) is None
    assert ROOT_CONFIG.is_file()
    mixed = make_room("map", str(ROOT_CONFIG), None, None)
    assert len(mixed) == 4 and mixed.radius == 0.06


ROOT_CONFIG = __import__("pathlib").Path(__file__).resolve().parent.parent / "configs" / "mixed.toml"

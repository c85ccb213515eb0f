"""ROS 2 over Zenoh without ROS: CDR encoding of the few messages we need, and the Zenoh
keys on which ROS 2 topics appear (pure functions, no ROS installation needed).

Key mapping (checked against the sources, see docs in hwbridge/README.md):

  * zenoh-bridge-ros2dds (eclipse-zenoh/zenoh-plugin-ros2dds, ``ros2_name_to_key_expr`` in
    src/ros2_utils.rs): the ROS name without its leading '/', prefixed by the bridge's
    ``namespace`` setting (also without '/') when it is not "/". Topic ``/scarab1/cmd_vel``
    -> key ``scarab1/cmd_vel``. The payload is the CDR bytes as DDS carries them.
  * rmw_zenoh (ros2/rmw_zenoh, docs/design.md "Topic and Service name mapping"):
    ``<domain_id>/<fully qualified name without leading '/'>/<DDS type name>/<type hash>``,
    e.g. ``0/scarab1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45bf16...``. The
    payload is CDR; every sample must carry an attachment (rmw_subscription_data.cpp drops
    samples without one: "Unable to obtain attachment"), serialised with zenoh-ext as
    int64 sequence_number, int64 source_timestamp (ns), then the 16-byte publisher gid as
    a length-prefixed sequence (attachment_helpers.cpp).

CDR (OMG CDR v1 as used by ROS 2): a 4-byte encapsulation header ``00 01 00 00`` (little
endian; ``00 00 00 00`` is big endian), then each primitive aligned to its size relative
to the end of the header.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass

CDR_LE = b"\x00\x01\x00\x00"
CDR_BE = b"\x00\x00\x00\x00"

TWIST_DDS_TYPE = "geometry_msgs::msg::dds_::Twist_"
# REP-2011 type hash of geometry_msgs/msg/Twist (Iron, Jazzy, Rolling), as used in rmw_zenoh
# keys by public rmw_zenoh-compatible code (e.g. "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/
# RIHS01_9c45bf16...").
TWIST_TYPE_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
ROS_MAPPINGS = ("ros2dds", "rmw_zenoh")


class CdrError(ValueError):
    """A CDR payload that cannot be decoded (too short, bad header, bad string)."""


# --------------------------------------------------------------------------- names / keys

def check_ros_name(name: str, what: str = "ros name") -> str:
    """A fully qualified ROS name: starts with '/', no empty or trailing components."""
    if not isinstance(name, str) or not name.startswith("/"):
        raise ValueError(f"{what}: {name!r} must start with '/'")
    if name != "/" and (name.endswith("/") or "//" in name):
        raise ValueError(f"{what}: {name!r} has an empty component")
    for ch in "*$?#":
        if ch in name:
            raise ValueError(f"{what}: {name!r} contains {ch!r}, illegal in a Zenoh key")
    return name


def topic_name(namespace: str, topic: str = "cmd_vel") -> str:
    """Fully qualified topic: ``/scarab1`` + ``cmd_vel`` -> ``/scarab1/cmd_vel``."""
    check_ros_name(namespace, "ros_namespace")
    return (namespace.rstrip("/") + "/" + topic.strip("/")) if namespace != "/" else "/" + topic.strip("/")


def ros2dds_key(topic: str, bridge_namespace: str = "/") -> str:
    """Zenoh key of a ROS 2 topic routed by zenoh-bridge-ros2dds."""
    check_ros_name(topic, "topic")
    check_ros_name(bridge_namespace, "ros_bridge_namespace")
    if bridge_namespace == "/":
        return topic[1:]
    return bridge_namespace[1:].rstrip("/") + "/" + topic[1:]


def rmw_zenoh_key(topic: str, domain_id: int = 0, dds_type: str = TWIST_DDS_TYPE,
                  type_hash: str = TWIST_TYPE_HASH) -> str:
    """Zenoh key of a ROS 2 topic published with rmw_zenoh (data plane, not liveliness)."""
    check_ros_name(topic, "topic")
    if not isinstance(domain_id, int) or isinstance(domain_id, bool) or not 0 <= domain_id <= 232:
        raise ValueError(f"ros_domain: {domain_id!r} not an integer in [0, 232]")
    return f"{domain_id}/{topic[1:]}/{dds_type}/{type_hash}"


def cmd_vel_key(mapping: str, namespace: str, domain_id: int = 0, bridge_namespace: str = "/") -> str:
    """The key a ROS 2 robot's ``<namespace>/cmd_vel`` listens on, for ``mapping``."""
    topic = topic_name(namespace, "cmd_vel")
    if mapping == "ros2dds":
        return ros2dds_key(topic, bridge_namespace)
    if mapping == "rmw_zenoh":
        return rmw_zenoh_key(topic, domain_id)
    raise ValueError(f"ros_mapping: {mapping!r} not one of {', '.join(ROS_MAPPINGS)}")


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def rmw_zenoh_attachment(seq: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """The attachment rmw_zenoh requires on every sample (zenoh-ext serialisation)."""
    if len(gid) != 16:
        raise ValueError(f"gid: expected 16 bytes, got {len(gid)}")
    return struct.pack("<qq", seq, source_timestamp_ns) + _leb128(16) + bytes(gid)


# --------------------------------------------------------------------------- Twist

@dataclass(frozen=True, slots=True)
class Twist:
    """geometry_msgs/Twist: linear (m/s) and angular (rad/s) velocity, body frame."""
    lx: float = 0.0
    ly: float = 0.0
    lz: float = 0.0
    ax: float = 0.0
    ay: float = 0.0
    az: float = 0.0


def encode_twist(tw: Twist) -> bytes:
    """CDR little endian: header 00 01 00 00, then 6 float64 (52 bytes in all), serialised by
    rosbags' typestore (the maintained CDR library swarmcover/ros2.py also uses)."""
    vals = (tw.lx, tw.ly, tw.lz, tw.ax, tw.ay, tw.az)
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"Twist: non-finite value in {vals}")
    from swarmcover.ros2 import serialize, typestore
    T = typestore().types
    V3 = T["geometry_msgs/msg/Vector3"]
    msg = T["geometry_msgs/msg/Twist"](linear=V3(x=float(tw.lx), y=float(tw.ly), z=float(tw.lz)),
                                       angular=V3(x=float(tw.ax), y=float(tw.ay), z=float(tw.az)))
    return serialize(msg, "geometry_msgs/msg/Twist")


# rosbags builds its type store and generates the Twist serialiser on first use (0.75 s
# measured): do it at import, so the first command a robot gets is not late by that
encode_twist(Twist())


def _endian(data: bytes, what: str) -> str:
    if len(data) < 4:
        raise CdrError(f"{what}: {len(data)} bytes, shorter than the CDR header")
    if data[0] != 0 or data[1] not in (0, 1):
        raise CdrError(f"{what}: encapsulation {data[:4].hex()} is not plain CDR (00 00 / 00 01)")
    return "<" if data[1] == 1 else ">"


def decode_twist(data: bytes) -> Twist:
    """Inverse of :func:`encode_twist`; also accepts big endian. Raises CdrError."""
    data = bytes(data)
    e = _endian(data, "Twist")
    if len(data) < 52:
        raise CdrError(f"Twist: {len(data)} bytes, expected 52")
    vals = struct.unpack_from(e + "6d", data, 4)
    if not all(math.isfinite(v) for v in vals):
        raise CdrError(f"Twist: non-finite value in {vals}")
    return Twist(*vals)


# --------------------------------------------------------------------------- PoseStamped

@dataclass(frozen=True, slots=True)
class PoseStamped:
    """geometry_msgs/PoseStamped: stamp (s), frame id, position (m), orientation (x, y, z, w)."""
    stamp: float
    frame_id: str
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]


def encode_pose_stamped(p: PoseStamped) -> bytes:
    """CDR little endian (for stand-in mocap publishers and tests)."""
    sec = math.floor(p.stamp)
    nsec = min(int(round((p.stamp - sec) * 1e9)), 999_999_999)
    fid = p.frame_id.encode() + b"\x00"
    body = bytearray(struct.pack("<iI", sec, nsec) + struct.pack("<I", len(fid)) + fid)
    body += b"\x00" * (-len(body) % 8)
    body += struct.pack("<7d", *p.position, *p.orientation)
    return CDR_LE + bytes(body)


def decode_pose_stamped(data: bytes) -> PoseStamped:
    """Decode a CDR geometry_msgs/PoseStamped (either endianness). Raises CdrError."""
    data = bytes(data)
    e = _endian(data, "PoseStamped")
    body = data[4:]
    if len(body) < 12:
        raise CdrError(f"PoseStamped: {len(data)} bytes, too short for a header")
    sec, nsec, n = struct.unpack_from(e + "iII", body, 0)
    if n < 1 or 12 + n > len(body):
        raise CdrError(f"PoseStamped: frame_id length {n} does not fit in {len(data)} bytes")
    raw = body[12:12 + n]
    if raw[-1:] != b"\x00":
        raise CdrError("PoseStamped: frame_id is not NUL-terminated")
    try:
        frame_id = raw[:-1].decode()
    except UnicodeDecodeError:
        raise CdrError("PoseStamped: frame_id is not UTF-8") from None
    off = 12 + n
    off += -off % 8
    if off + 56 > len(body):
        raise CdrError(f"PoseStamped: {len(data)} bytes, too short for the pose")
    vals = struct.unpack_from(e + "7d", body, off)
    if not all(math.isfinite(v) for v in vals):
        raise CdrError(f"PoseStamped: non-finite value in {vals}")
    return PoseStamped(sec + nsec * 1e-9, frame_id, vals[:3], vals[3:])

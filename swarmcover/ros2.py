"""The swarm as standard ROS 2 messages over Zenoh, the way rmw_zenoh carries them.

``swarmcover view --ros2`` publishes, for a ROS 2 (Jazzy or later) user running
``RMW_IMPLEMENTATION=rmw_zenoh_cpp`` against the same Zenoh router:

  <ns>/poses    geometry_msgs/msg/PoseArray        ground-truth robot poses (frame ``map``)
  <ns>/complex  visualization_msgs/msg/MarkerArray the scene of recording/scene.py as RViz
                markers: walls, sources, robots (virtual / live twin), robot ids, mocap,
                Rips edges, frontier K, obstacle O, redundant robots, coverage

(``<ns>`` = ``--ros-namespace``, default ``/swarmcover``). ``ros2 topic list`` lists them
and RViz (fixed frame ``map``) draws them.

Wire format, from ros2/rmw_zenoh (rmw_zenoh_cpp/src/detail/liveliness_utils.cpp):
  * data key: ``<domain>/<topic without leading '/'>/<DDS type>/<RIHS01 type hash>``,
    e.g. ``0/swarmcover/poses/geometry_msgs::msg::dds_::PoseArray_/RIHS01_af0c...``;
    payload: CDR (encapsulation header + body), serialised by ``rosbags``' typestore,
    which also computes the REP-2011 type hashes; every sample carries rmw_zenoh's
    attachment (sequence number, source timestamp, publisher gid; hwbridge/ros2.py);
  * liveliness tokens (the ROS graph): a node
    ``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/%/<ns>/<node>`` and per publisher
    ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/MP/%/<ns>/<node>/<topic>/<type>/<hash>/<qos>``,
    '/' in names written '%', qos ``::,:,:,:,,`` (rmw_zenoh's defaults: reliable,
    volatile, keep last).

The message builders (:func:`pose_array`, :func:`marker_array`) are pure; :class:`Ros2Out`
owns the Zenoh declarations.
"""
from __future__ import annotations

import itertools
import os
import threading

from rosbags.typesys import Stores, get_typestore

from swarmcover.bus import messages as m
from swarmcover.ground.geometry import flat_to_points

POSE_ARRAY = "geometry_msgs/msg/PoseArray"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
ADMIN_SPACE = "@ros2_lv"
DEFAULT_QOS = "::,:,:,:,,"
FRAME = "map"

_TS = None
_TS_LOCK = threading.Lock()


def typestore():
    """rosbags' ROS 2 Jazzy type store (message classes, CDR, type hashes); built once."""
    global _TS
    with _TS_LOCK:
        if _TS is None:
            _TS = get_typestore(Stores.ROS2_JAZZY)
        return _TS


def dds_type(typename: str) -> str:
    """``geometry_msgs/msg/PoseArray`` -> ``geometry_msgs::msg::dds_::PoseArray_``."""
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def type_hash(typename: str) -> str:
    return typestore().hash_rihs01(typename)


def mangle(name: str) -> str:
    return name.replace("/", "%")


def data_key(topic: str, typename: str, domain: int = 0) -> str:
    return f"{domain}/{topic.strip('/')}/{dds_type(typename)}/{type_hash(typename)}"


def node_token(domain: int, zid: str, nid: int, namespace: str, node: str) -> str:
    return f"{ADMIN_SPACE}/{domain}/{zid}/{nid}/{nid}/NN/%/{mangle(namespace)}/{node}"


def publisher_token(domain: int, zid: str, nid: int, eid: int, namespace: str, node: str,
                    topic: str, typename: str, qos: str = DEFAULT_QOS) -> str:
    return (f"{ADMIN_SPACE}/{domain}/{zid}/{nid}/{eid}/MP/%/{mangle(namespace)}/{node}/"
            f"{mangle(topic)}/{dds_type(typename)}/{type_hash(typename)}/{qos}")


def check_namespace(ns: str) -> str:
    if not ns.startswith("/") or (ns != "/" and ns.endswith("/")) or "//" in ns:
        raise ValueError(f"--ros-namespace {ns!r}: a ROS namespace like /swarmcover")
    for ch in "*$?#% ":
        if ch in ns:
            raise ValueError(f"--ros-namespace {ns!r}: {ch!r} is not allowed")
    return ns


# --------------------------------------------------------------------------- builders

def _header(stamp_ns: int):
    T = typestore().types
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                               nanosec=int(stamp_ns % 1_000_000_000)),
        frame_id=FRAME)


def _pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0):
    import math
    T = typestore().types
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z)),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                       w=math.cos(yaw / 2)))


def pose_array(truth: m.Truth, stamp_ns: int):
    """geometry_msgs/PoseArray of the bodies in ``truth`` (order of truth.ids)."""
    T = typestore().types
    return T[POSE_ARRAY](header=_header(stamp_ns),
                         poses=[_pose(x, y, 0.0, th)
                                for x, y, th in zip(truth.x, truth.y, truth.theta)])


_RGBA = {
    "wall": (0.25, 0.25, 0.25, 1.0), "source": (1.0, 0.55, 0.0, 1.0),
    "virtual": (0.12, 0.47, 0.71, 1.0), "live": (0.17, 0.63, 0.17, 1.0),
    "outside": (0.6, 0.75, 0.9, 1.0), "redundant": (0.58, 0.40, 0.74, 1.0),
    "mocap": (0.84, 0.15, 0.16, 1.0), "edge": (0.2, 0.2, 0.2, 0.8),
    "frontier": (0.89, 0.10, 0.11, 1.0), "obstacle": (0.0, 0.35, 0.85, 1.0),
    "coverage": (0.55, 0.80, 0.55, 0.35), "text": (0.05, 0.05, 0.05, 1.0),
}


def marker_array(info: m.WorldInfo | None, truth: m.Truth | None, cx: m.Complex | None,
                 mocap: dict | None, stamp_ns: int):
    """visualization_msgs/MarkerArray of the scene: a DELETEALL, then one marker per layer
    (namespaces walls, sources, robots, ids, redundant, mocap, edges, frontier, obstacle,
    coverage), so each array replaces the previous one in RViz."""
    from swarmcover.viz.geometry import build_scene
    T = typestore().types
    Marker, Point, Color = (T["visualization_msgs/msg/Marker"], T["geometry_msgs/msg/Point"],
                            T["std_msgs/msg/ColorRGBA"])
    V3, Dur = T["geometry_msgs/msg/Vector3"], T["builtin_interfaces/msg/Duration"]
    Img, MeshFile = T["sensor_msgs/msg/CompressedImage"], T["visualization_msgs/msg/MeshFile"]
    hdr = _header(stamp_ns)
    rv = info.rv if info is not None else 1.0
    rad = info.robot_radius if info is not None and info.robot_radius > 0 else 0.05 * rv
    lw = max(0.01, 0.02 * rv)
    sc = build_scene(truth, cx, {r: p[:2] for r, p in (mocap or {}).items()})
    ids = itertools.count()

    def col(name):
        r, g, b, a = _RGBA[name]
        return Color(r=r, g=g, b=b, a=a)

    def marker(ns, kind, *, pose=None, scale=(1.0, 1.0, 1.0), colour="edge", points=(),
               text="", action=0):
        return Marker(header=hdr, ns=ns, id=next(ids), type=kind, action=action,
                      pose=pose or _pose(), scale=V3(x=scale[0], y=scale[1], z=scale[2]),
                      color=col(colour), lifetime=Dur(sec=0, nanosec=0), frame_locked=False,
                      points=list(points), colors=[], texture_resource="",
                      texture=Img(header=hdr, format="", data=_u8()), uv_coordinates=[],
                      text=text, mesh_resource="",
                      mesh_file=MeshFile(filename="", data=_u8()),
                      mesh_use_embedded_materials=False)

    def pts(pairs, z=0.0):
        return [Point(x=float(x), y=float(y), z=z) for x, y in pairs]

    out = [marker("swarmcover", Marker.DELETEALL, action=Marker.DELETEALL)]
    if info is not None:
        walls = []
        for flat in [info.boundary, *info.obstacles]:
            ring = flat_to_points(flat)
            for a, b in zip(ring, ring[1:] + ring[:1]):
                walls += [a, b]
        out.append(marker("walls", Marker.LINE_LIST, scale=(1.5 * lw, 0, 0), colour="wall",
                          points=pts(walls)))
        for k in range(0, len(info.sources) - 2, 3):
            x, y, th = info.sources[k:k + 3]
            out.append(marker("sources", Marker.ARROW, pose=_pose(x, y, 0.0, th),
                              scale=(0.8 * rv, 0.08 * rv, 0.08 * rv), colour="source"))
    groups: dict[str, list] = {"virtual": [], "live": [], "outside": []}
    for i, (x, y), lv, inc, red in zip(sc.ids, sc.xy, sc.live, sc.in_complex, sc.redundant):
        groups["live" if lv else ("virtual" if inc else "outside")].append((x, y))
        out.append(marker("ids", Marker.TEXT_VIEW_FACING, pose=_pose(x, y, 3 * rad),
                          scale=(0, 0, 2.5 * rad), colour="text", text=str(int(i))))
    d = 2 * rad
    for name, xy in groups.items():
        if xy:
            out.append(marker(f"robots/{name}", Marker.SPHERE_LIST, scale=(d, d, d),
                              colour=name, points=pts(xy, rad)))
    red = [tuple(p) for p, r in zip(sc.xy, sc.redundant) if r]
    if red:
        out.append(marker("redundant", Marker.CUBE_LIST, scale=(1.6 * d, 1.6 * d, 0.4 * d),
                          colour="redundant", points=pts(red, rad)))
    if sc.mocap:
        out.append(marker("mocap", Marker.SPHERE_LIST, scale=(0.6 * d,) * 3, colour="mocap",
                          points=pts(sorted(sc.mocap.values()), rad)))
    for name, segs, width in (("edges", sc.edges, 0.5 * lw), ("frontier", sc.frontier, 2 * lw),
                              ("obstacle", sc.obstacle, 2 * lw)):
        if len(segs):
            out.append(marker(name, Marker.LINE_LIST, scale=(width, 0, 0), colour=name
                              if name != "edges" else "edge",
                              points=pts([tuple(p) for s in segs for p in s], 0.01)))
    if len(sc.triangles):
        out.append(marker("coverage", Marker.TRIANGLE_LIST, colour="coverage",
                          points=pts([tuple(p) for t in sc.triangles for p in t], -0.01)))
    return T[MARKER_ARRAY](markers=out)


def _u8():
    import numpy as np
    return np.zeros(0, dtype=np.uint8)


def serialize(msg, typename: str) -> bytes:
    """CDR (little endian, with the encapsulation header) by rosbags."""
    return bytes(typestore().serialize_cdr(msg, typename))


def deserialize(data: bytes, typename: str):
    return typestore().deserialize_cdr(bytes(data), typename)


# --------------------------------------------------------------------------- Zenoh edge

class Ros2Out:
    """Declares the ROS 2 node and publishers on an open session and publishes to them.

    ``publish(info, truth, cx, mocap, stamp_ns)`` sends a PoseArray (when there is a Truth)
    and, at most ``marker_hz`` times a second, a MarkerArray (building one takes ~50x a
    PoseArray's time with rosbags). Call from the owner's loop, never from a Zenoh callback.
    """

    def __init__(self, session, *, domain: int = 0, namespace: str = "/swarmcover",
                 node: str = "swarmcover_view", marker_hz: float = 2.0):
        from swarmcover.hwbridge.ros2 import rmw_zenoh_attachment
        if not isinstance(domain, int) or not 0 <= domain <= 232:
            raise ValueError(f"--ros-domain {domain!r}: an integer in [0, 232]")
        self.session = session
        self.domain = domain
        self.namespace = check_namespace(namespace)
        self.node = node
        self._attachment = rmw_zenoh_attachment
        zid = str(session.info.zid())
        ns = "" if namespace == "/" else namespace
        self.topics = {POSE_ARRAY: f"{ns}/poses", MARKER_ARRAY: f"{ns}/complex"}
        self.keys = {t: data_key(topic, t, domain) for t, topic in self.topics.items()}
        nid = int.from_bytes(os.urandom(4), "little") & 0x7FFFFFFF
        self._gid = {t: os.urandom(16) for t in self.topics}
        self._seq = {t: 0 for t in self.topics}
        lv = session.liveliness()
        self.tokens = [node_token(domain, zid, nid, namespace, node)]
        self.tokens += [publisher_token(domain, zid, nid, nid + 1 + k, namespace, node, topic, t)
                        for k, (t, topic) in enumerate(self.topics.items())]
        self._decl = [lv.declare_token(k) for k in self.tokens]
        self._pubs = {t: session.declare_publisher(k) for t, k in self.keys.items()}
        self.sent = 0
        self.marker_dt = 1.0 / marker_hz if marker_hz > 0 else 0.0
        self._marker_at = -1e18

    def _put(self, typename: str, msg, stamp_ns: int) -> None:
        self._seq[typename] += 1
        att = self._attachment(self._seq[typename], stamp_ns, self._gid[typename])
        self._pubs[typename].put(serialize(msg, typename), attachment=att)
        self.sent += 1

    def publish(self, info, truth, cx, mocap, stamp_ns: int) -> None:
        if truth is not None:
            self._put(POSE_ARRAY, pose_array(truth, stamp_ns), stamp_ns)
        if (info is not None or truth is not None) and (
                stamp_ns - self._marker_at >= self.marker_dt * 1e9):
            self._marker_at = stamp_ns
            self._put(MARKER_ARRAY, marker_array(info, truth, cx, mocap, stamp_ns), stamp_ns)

    def close(self) -> None:
        for d in [*self._pubs.values(), *self._decl]:
            try:
                d.undeclare()
            except Exception:
                pass
        self._pubs.clear()
        self._decl.clear()

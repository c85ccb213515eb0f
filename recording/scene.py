"""The swarm as a Foxglove scene: ``foxglove.SceneUpdate`` messages built with foxglove-sdk.

One SceneUpdate on topic ``/swarmcover/scene`` (frame ``map``: the world frame, metres,
z up) holds every entity, each replaced in full by the next update, so any single message
draws the whole swarm (a 3D panel needs no plugin and no history):

  walls       grey lines: the map boundary and the obstacles (WorldInfo)
  sources     orange arrows: the source (base station) poses
  robots      spheres, one per body in the latest Truth: blue virtual robots, green twins
              of live robots; light when the robot holds no vertex of the complex.
              metadata ``ids`` / ``live`` list the robot ids drawn (comma separated)
  robot_ids   the id of each robot as a text label
  redundant   purple cubes on robots whose vertex is redundant (being removed)
  removed     grey cubes on robots removed as redundant (outside the complex since)
  mocap       red spheres: measured (motion-capture) poses of live robots
  edges       thin dark lines: the Rips edges of the latest Complex
  frontier    red lines: frontier edges K
  obstacle    blue lines: obstacle edges O
  coverage    the complex's triangles in one translucent colour (overlaps do not darken
              more than the colour's alpha: Foxglove draws each triangle once)

:class:`SceneState` is the pure part: it is fed decoded messages and builds updates;
``record`` writes them into the MCAP beside the raw channels, and ``view --foxglove``
logs them to foxglove-sdk's WebSocket server.
"""
from __future__ import annotations

import math

import foxglove.messages as fm
from foxglove import Schema

from swarmcover.bus import messages as m
from swarmcover.ground.geometry import flat_to_points
from swarmcover.viz.geometry import redundant_robots

SCENE_TOPIC = "/swarmcover/scene"
FRAME = "map"
ENTITIES = ("walls", "sources", "robots", "robot_ids", "redundant", "removed", "mocap", "edges",
            "frontier", "obstacle", "coverage")

_C = {
    "wall": (0.25, 0.25, 0.25, 1.0), "source": (1.0, 0.55, 0.0, 1.0),
    "virtual": (0.12, 0.47, 0.71, 1.0), "live": (0.17, 0.63, 0.17, 1.0),
    "outside": (0.6, 0.75, 0.9, 1.0), "redundant": (0.58, 0.40, 0.74, 1.0),
    "removed": (0.5, 0.5, 0.5, 1.0),
    "mocap": (0.84, 0.15, 0.16, 1.0), "edge": (0.2, 0.2, 0.2, 0.8),
    "frontier": (0.89, 0.10, 0.11, 1.0), "obstacle": (0.0, 0.35, 0.85, 1.0),
    "coverage": (0.55, 0.80, 0.55, 0.35), "text": (0.05, 0.05, 0.05, 1.0),
}


def scene_schema() -> Schema:
    """foxglove.SceneUpdate's schema (protobuf FileDescriptorSet) as foxglove-sdk ships it."""
    return fm.SceneUpdate.get_schema()


_COLOURS: dict[str, fm.Color] = {}


def _col(name: str) -> fm.Color:
    c = _COLOURS.get(name)
    if c is None:
        r, g, b, a = _C[name]
        c = _COLOURS[name] = fm.Color(r=r, g=g, b=b, a=a)
    return c


def _pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=float(x), y=float(y), z=float(z)),
                   orientation=fm.Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def _ring_lines(flat, z: float) -> list[fm.Point3]:
    """Closed polygon as LINE_LIST points (a, b, b, c, ..., z, a)."""
    pts = flat_to_points(flat)
    out = []
    for a, b in zip(pts, pts[1:] + pts[:1]):
        out += [fm.Point3(x=a[0], y=a[1], z=z), fm.Point3(x=b[0], y=b[1], z=z)]
    return out


def _seg_points(segs, z: float) -> list[fm.Point3]:
    return [fm.Point3(x=float(p[0]), y=float(p[1]), z=z) for s in segs for p in s]


class SceneState:
    """The latest WorldInfo, Truth, Complex and mocap poses; builds SceneUpdates. No I/O."""

    def __init__(self):
        self.info: m.WorldInfo | None = None
        self.truth: m.Truth | None = None
        self.cx: m.Complex | None = None
        self.mocap: dict[int, tuple[float, float, float]] = {}
        self.removed: set[int] = set()   # robots marked redundant so far
        self.seq = 0   # bumped on every change that alters the scene

    def on_message(self, msg: m.Message) -> bool:
        """Take one decoded message; True if the scene changed."""
        if isinstance(msg, m.Truth):
            self.truth = msg
            live = {int(i) for i, lv in zip(msg.ids, msg.live) if lv}
            for r in [r for r in self.mocap if r not in live]:
                del self.mocap[r]
        elif isinstance(msg, m.Complex):
            self.cx = msg
            self.removed |= redundant_robots(msg)
        elif isinstance(msg, m.WorldInfo):
            self.info = msg
        elif isinstance(msg, m.Pose) and msg.source == "mocap":
            self.mocap[msg.robot] = (msg.x, msg.y, msg.theta)
        else:
            return False
        self.seq += 1
        return True

    @property
    def ready(self) -> bool:
        return self.info is not None or self.truth is not None

    def update(self, stamp_ns: int) -> fm.SceneUpdate:
        """The whole scene as one SceneUpdate stamped ``stamp_ns`` (ns since the epoch)."""
        from swarmcover.viz.geometry import build_scene

        ts = fm.Timestamp(int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000))
        info = self.info
        rv = info.rv if info is not None else 1.0
        rad = info.robot_radius if info is not None and info.robot_radius > 0 else 0.05 * rv
        line_w = max(0.01, 0.02 * rv)
        sc = build_scene(self.truth, self.cx, {r: p[:2] for r, p in self.mocap.items()},
                         removed=self.removed)

        def ent(eid: str, **kw) -> fm.SceneEntity:
            return fm.SceneEntity(timestamp=ts, frame_id=FRAME, id=eid, **kw)

        def lines(eid: str, pts: list, colour: str, width: float) -> fm.SceneEntity:
            prims = [fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList, pose=_pose(),
                                      thickness=width, points=pts, color=_col(colour))] if pts else []
            return ent(eid, lines=prims)

        walls: list[fm.Point3] = []
        arrows = []
        if info is not None:
            walls = _ring_lines(info.boundary, 0.0)
            for poly in info.obstacles:
                walls += _ring_lines(poly, 0.0)
            for k in range(0, len(info.sources) - 2, 3):
                x, y, th = info.sources[k:k + 3]
                arrows.append(fm.ArrowPrimitive(pose=_pose(x, y, 0.0, th), shaft_length=0.6 * rv,
                                                shaft_diameter=0.08 * rv, head_length=0.2 * rv,
                                                head_diameter=0.2 * rv, color=_col("source")))
        spheres, texts, cubes, gone = [], [], [], []
        d = 2 * rad
        for i, (x, y), lv, inc, red, rm in zip(sc.ids, sc.xy, sc.live, sc.in_complex,
                                               sc.redundant, sc.removed):
            colour = "live" if lv else ("virtual" if inc else "outside")
            spheres.append(fm.SpherePrimitive(pose=_pose(x, y, rad), color=_col(colour),
                                              size=fm.Vector3(x=d, y=d, z=d)))
            texts.append(fm.TextPrimitive(pose=_pose(x, y, 2.5 * rad), billboard=True,
                                          font_size=12.0, scale_invariant=True,
                                          color=_col("text"), text=str(int(i))))
            if red:
                cubes.append(fm.CubePrimitive(pose=_pose(x, y, rad), color=_col("redundant"),
                                              size=fm.Vector3(x=1.6 * d, y=1.6 * d, z=0.4 * d)))
            if rm and not inc:
                gone.append(fm.CubePrimitive(pose=_pose(x, y, rad, math.pi / 4),
                                             color=_col("removed"),
                                             size=fm.Vector3(x=1.3 * d, y=1.3 * d, z=0.3 * d)))
        mocap = [fm.SpherePrimitive(pose=_pose(x, y, rad), color=_col("mocap"),
                                    size=fm.Vector3(x=0.6 * d, y=0.6 * d, z=0.6 * d))
                 for _, (x, y, _th) in sorted(self.mocap.items())]
        ids = ",".join(str(int(i)) for i in sc.ids)
        live = ",".join(str(int(i)) for i, lv in zip(sc.ids, sc.live) if lv)
        meta = [fm.KeyValuePair(key="ids", value=ids), fm.KeyValuePair(key="live", value=live)]
        if self.cx is not None:
            meta.append(fm.KeyValuePair(key="cycle", value=str(self.cx.cycle)))
        tri_pts = [fm.Point3(x=float(p[0]), y=float(p[1]), z=-0.01)
                   for t in sc.triangles for p in t]
        coverage = ([fm.TriangleListPrimitive(pose=_pose(), points=tri_pts,
                                              color=_col("coverage"))] if tri_pts else [])
        entities = [
            lines("walls", walls, "wall", 1.5 * line_w),
            ent("sources", arrows=arrows),
            ent("robots", spheres=spheres, metadata=meta),
            ent("robot_ids", texts=texts),
            ent("redundant", cubes=cubes),
            ent("removed", cubes=gone),
            ent("mocap", spheres=mocap),
            lines("edges", _seg_points(sc.edges, 0.005), "edge", 0.5 * line_w),
            lines("frontier", _seg_points(sc.frontier, 0.01), "frontier", 2 * line_w),
            lines("obstacle", _seg_points(sc.obstacle, 0.01), "obstacle", 2 * line_w),
            ent("coverage", triangles=coverage),
        ]
        return fm.SceneUpdate(entities=entities)

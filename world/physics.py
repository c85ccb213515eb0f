"""pymunk dynamics of the swarm: disk robots, static walls, velocity commands.

World frame, metres, seconds, radians. Every robot is a dynamic disk (mass 1 kg,
frictionless, inelastic); walls are static segments. Each physics substep drives every body
to its commanded velocity (a stiff velocity controller, see below) and pymunk resolves the
contacts, so robots push each other and slide along walls.

Kinds:
  * holonomic: body-frame (vx, vy); never rotates (infinite moment, heading 0); speed
    clamped to v_max;
  * diffdrive: forward speed vx in [-v_max, v_max] along the heading, turn rate wz in
    [-w_max, w_max]; vy is ignored;
  * twins of live robots (``live=True``): world-frame (vx, vy, wz) from TwinCmd, or teleport.
Optional actuation noise (relative sigma) multiplies virtual robots' speeds, drawn from the
run's seeded generator in robot-id order. Bodies are stepped and read in batch
(pymunk.batch); iteration is always in sorted robot-id order, so runs are deterministic.

Velocity control: chipmunk integrates positions with the previous substep's solved
velocities before it integrates forces and solves contacts, so writing the velocity directly
would tunnel through walls. Instead each substep applies the force that brings the body's
velocity to the command within the substep; the contact solver then stops it at walls and
robots. A command therefore takes effect one substep (dt/substeps) late.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymunk
import pymunk.batch as pb
from scipy.spatial import cKDTree

from swarmcover.bus.messages import ROBOT_KINDS

from .maps import WorldMap

TWO_PI = 2.0 * math.pi


@dataclass
class Robot:
    rid: int
    kind: str
    live: bool
    body: pymunk.Body
    shape: pymunk.Circle


class Physics:
    """The pymunk space of one run."""

    def __init__(self, wm: WorldMap, *, radius: float, v_max: float, w_max: float,
                 dt: float, substeps: int = 4, actuation_noise: float = 0.0,
                 rng: np.random.Generator | None = None):
        self.wm = wm
        self.radius = float(radius)
        self.v_max, self.w_max = float(v_max), float(w_max)
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.noise = float(actuation_noise)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.space = pymunk.Space()
        self.space.iterations = 10
        self.space.collision_slop = min(1e-3, 0.02 * self.radius)
        self.space.use_spatial_hash(max(4 * self.radius, 0.05), 10_000)
        for x0, y0, x1, y1 in wm.walls:
            s = pymunk.Segment(self.space.static_body, (x0, y0), (x1, y1), 0.0)
            s.friction = 0.0
            s.elasticity = 0.0
            self.space.add(s)
        self.robots: dict[int, Robot] = {}
        self._order: list[int] = []
        self._dirty = True
        self._buf = pb.Buffer()

    # ------------------------------------------------------------------ bodies
    @property
    def ids(self) -> list[int]:
        """Robot ids in sorted order (the order of every array this class returns)."""
        if self._dirty:
            self._refresh()
        return self._order

    def _refresh(self):
        self._order = sorted(self.robots)
        bid = np.array([self.robots[r].body.id for r in self._order], np.uintp)
        self._bid_sort = np.argsort(bid)
        self._bid_sorted = bid[self._bid_sort]
        self._kinds = np.array([self.robots[r].kind == "diffdrive" for r in self._order], bool)
        self._live = np.array([self.robots[r].live for r in self._order], bool)
        self._dirty = False

    def has(self, rid: int) -> bool:
        return rid in self.robots

    def kind(self, rid: int) -> str:
        return self.robots[rid].kind

    def is_live(self, rid: int) -> bool:
        return self.robots[rid].live

    def free_spot(self, x: float, y: float, exclude: int | None = None) -> tuple[float, float]:
        """The free point nearest (x, y) where a body fits without touching walls or robots."""
        r = self.radius
        gap = max(1e-3, 0.05 * r)
        others = np.array([(b.body.position.x, b.body.position.y)
                           for k, b in self.robots.items() if k != exclude]).reshape(-1, 2)
        tree = cKDTree(others) if len(others) else None
        x0, y0, x1, y1 = self.wm.bounds
        reach = 4 * r
        limit = math.hypot(x1 - x0, y1 - y0) + reach
        while True:
            step = max(0.5 * r, reach / 40)          # at most ~6,000 candidates per round
            n = int(math.ceil(reach / step))
            g = np.arange(-n, n + 1) * step
            gx, gy = np.meshgrid(g, g * (math.sqrt(3) / 2))
            gx = gx + (np.arange(len(g))[:, None] % 2) * (step / 2)
            c = np.stack([x + gx.ravel(), y + gy.ravel()], 1)
            d = np.hypot(c[:, 0] - x, c[:, 1] - y)
            c = np.concatenate([[[x, y]], c[d <= reach]])
            d = np.hypot(c[:, 0] - x, c[:, 1] - y)
            c = c[np.argsort(d, kind="stable")]
            ok = np.ones(len(c), bool)
            if tree is not None:
                dist, _ = tree.query(c, k=1)
                ok &= dist >= 2 * r + gap
            if ok.any():
                idx = np.nonzero(ok)[0]
                free = self.wm.is_free(c[idx], margin=r + gap)
                if free.any():
                    p = c[idx[np.argmax(free)]]
                    return float(p[0]), float(p[1])
            if reach > limit:
                raise ValueError(f"no free spot for a robot of radius {r} near ({x}, {y})")
            reach *= 2

    def add(self, rid: int, x: float, y: float, theta: float, kind: str, live: bool = False,
            exact: bool = False) -> tuple[float, float, float]:
        """Create robot rid near (x, y) (nearest free spot unless exact); returns its pose.

        Holonomic robots get heading 0 whatever theta says."""
        if rid in self.robots:
            raise ValueError(f"robot {rid} already has a body")
        if kind not in ROBOT_KINDS:
            raise ValueError(f"robot kind {kind!r}: expected {' or '.join(ROBOT_KINDS)}")
        if not exact:
            x, y = self.free_spot(x, y)
        theta = float(theta) if kind == "diffdrive" else 0.0
        moment = pymunk.moment_for_circle(1.0, 0, self.radius) if kind == "diffdrive" else \
            float("inf")
        body = pymunk.Body(1.0, moment)
        body.position = (float(x), float(y))
        body.angle = theta
        shape = pymunk.Circle(body, self.radius)
        shape.friction = 0.0
        shape.elasticity = 0.0
        self.space.add(body, shape)
        self.robots[rid] = Robot(rid, kind, bool(live), body, shape)
        self._dirty = True
        return float(x), float(y), theta

    def remove(self, rid: int) -> bool:
        rb = self.robots.pop(rid, None)
        if rb is None:
            return False
        self.space.remove(rb.body, rb.shape)
        self._dirty = True
        return True

    def teleport(self, rid: int, x: float, y: float, theta: float) -> None:
        rb = self.robots[rid]
        rb.body.position = (float(x), float(y))
        rb.body.angle = float(theta) if rb.kind == "diffdrive" else 0.0
        rb.body.velocity = (0.0, 0.0)
        rb.body.angular_velocity = 0.0
        self.space.reindex_shapes_for_body(rb.body)

    # ------------------------------------------------------------------ state
    def _space_perm(self, fields) -> tuple[np.ndarray, np.ndarray]:
        """(our index of each space body, float data (n, k)) in the space's order."""
        self._buf.clear()
        pb.get_space_bodies(self.space, pb.BodyFields.BODY_ID | fields, self._buf)
        bids = np.frombuffer(self._buf.int_buf(), np.uintp)
        f = np.frombuffer(self._buf.float_buf(), np.float64).copy()
        f = f.reshape(len(bids), -1)
        k = np.minimum(np.searchsorted(self._bid_sorted, bids), len(self._bid_sorted) - 1)
        known = self._bid_sorted[k] == bids        # the space's static body is not ours
        ours = np.where(known, self._bid_sort[k], -1)
        return ours, f

    def state(self) -> tuple[list[int], np.ndarray, np.ndarray]:
        """(ids sorted, positions (n, 2), headings (n,) wrapped to [-pi, pi))."""
        ids = self.ids
        n = len(ids)
        pos = np.zeros((n, 2))
        th = np.zeros(n)
        if n:
            ours, f = self._space_perm(pb.BodyFields.POSITION | pb.BodyFields.ANGLE)
            m = ours >= 0
            pos[ours[m]] = f[m, 0:2]
            th[ours[m]] = (f[m, 2] + math.pi) % TWO_PI - math.pi
        return ids, pos, th

    # ------------------------------------------------------------------ stepping
    def clamp(self, cmd: np.ndarray) -> np.ndarray:
        """Clamp body-frame commands (n, 3) of virtual robots to the kinematic limits."""
        self.ids
        c = np.array(cmd, float).reshape(-1, 3)
        dd = self._kinds
        # holonomic: speed norm <= v_max, no rotation
        sp = np.hypot(c[:, 0], c[:, 1])
        scale = np.where(sp > self.v_max, self.v_max / np.maximum(sp, 1e-300), 1.0)
        hol = ~dd
        c[hol, 0:2] *= scale[hol, None]
        c[hol, 2] = 0.0
        c[dd, 0] = np.clip(c[dd, 0], -self.v_max, self.v_max)
        c[dd, 1] = 0.0
        c[dd, 2] = np.clip(c[dd, 2], -self.w_max, self.w_max)
        return c

    def step(self, cmd: np.ndarray) -> None:
        """Advance dt. cmd (n, 3) in sorted-id order: body-frame (vx, vy, wz) for virtual
        robots (clamped here), world-frame (vx, vy, wz) for live twins."""
        ids = self.ids
        n = len(ids)
        if n == 0:
            self.space.step(self.dt)
            return
        c = np.asarray(cmd, float).reshape(n, 3)
        live = self._live
        virt = self.clamp(c)
        if self.noise > 0:
            k = self.rng.normal(0.0, self.noise, (n, 2))
            virt[:, 0:2] *= 1.0 + k[:, 0:1]
            virt[:, 2] *= 1.0 + k[:, 1]
        c = np.where(live[:, None], c, virt)
        dd = self._kinds & ~live
        rot = live | dd
        h = self.dt / self.substeps
        moment = pymunk.moment_for_circle(1.0, 0, self.radius)
        fields = pb.BodyFields.ANGLE | pb.BodyFields.VELOCITY | pb.BodyFields.ANGULAR_VELOCITY
        for _ in range(self.substeps):
            # chipmunk integrates positions with the previous (solved) velocities, then
            # integrates forces and solves contacts: a force that brings the velocity to the
            # command within this substep lets the solver stop it at walls and robots.
            ours, f = self._space_perm(fields)
            m = ours >= 0
            o = ours[m]
            cm = c[o]
            # the velocity set now moves the body during the NEXT substep, while it turns
            # from ang + w h to ang + 2 w h: aim along the midpoint heading
            ang = f[m, 0] + np.where(dd[o], 1.5 * h * cm[:, 2], 0.0)
            cs, sn = np.cos(ang), np.sin(ang)
            lv = live[o]
            vx = np.where(lv, cm[:, 0], cs * cm[:, 0] - sn * cm[:, 1])
            vy = np.where(lv, cm[:, 1], sn * cm[:, 0] + cs * cm[:, 1])
            w = np.where(rot[o], cm[:, 2], 0.0)
            out = np.zeros((len(ours), 3))
            out[m, 0] = (vx - f[m, 1]) / h
            out[m, 1] = (vy - f[m, 2]) / h
            out[m, 2] = np.where(rot[o], (w - f[m, 3]) * (moment / h), 0.0)
            buf = pb.Buffer()
            buf.set_float_buf(np.ascontiguousarray(out.ravel()))
            pb.set_space_bodies(self.space, pb.BodyFields.FORCE | pb.BodyFields.TORQUE, buf)
            self.space.step(h)

"""The agent's wall sweep (agents/sweep.py): where it is from bearings, and the sweep itself
in the world's own physics and touch sensors (world.physics, world.sensing), in process.

The scene: a wall along y = 0 (0.1 m thick, a second room below it), the sweeping robot 0
at (0, Y) on a fence edge to robot 1 at (0.9, Y), more robots of the swarm behind them; the
task is what the coordinator sends (tests/test_sweep.py covers the coordinator's side):
drive towards the wall, slide along it to fraction ``far`` of the edge 0-1, then back past
robot 0's vertex to the ray 5 deg beyond the perpendicular there.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from swarmcover.agents.behaviours import Behaviour
from swarmcover.agents.params import AgentParams
from swarmcover.agents.sweep import SweepGeom, locate
from swarmcover.bus.messages import Sense, Task, parse_sweep_reason, sweep_stoppers
from swarmcover.ground.angles import wrap
from swarmcover.ground.geometry import lens_radii, lens_reach
from swarmcover.coordinator.topology.targets import star_shape
from swarmcover.world.maps import WorldMap
from swarmcover.world.physics import Physics
from swarmcover.world.sensing import Sensors

R = 0.06
Y = 0.35          # the fence line's distance from the wall
D0 = 0.9


# ----------------------------------------------------------------------- bearings alone
@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)), min_size=2, max_size=6),
       st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.2, 3.0))
def test_locate_finds_the_robot_from_the_bearings_of_known_points(pts, x, y, scale):
    """Exact bearings to points at known places give the robot's place (least squares),
    in the points' unit whatever it is; points seen nearly in line give None, never a
    wrong place."""
    pts = {k: (px, py) for k, (px, py) in enumerate(pts) if math.hypot(px - x, py - y) > 0.05}
    brg = {k: math.atan2(py - y, px - x) for k, (px, py) in pts.items()}
    got = locate(brg, pts)
    if got is not None:
        assert got == pytest.approx((x, y), abs=1e-6)
        scaled = locate(brg, {k: (scale * px, scale * py) for k, (px, py) in pts.items()})
        assert scaled == pytest.approx((scale * x, scale * y), abs=1e-6)
    else:
        # fewer than two, or all bearings within about 30 deg of one line
        ok = [b for b in brg.values()]
        assert len(ok) < 2 or all(abs(math.sin(a - ok[0])) < math.sin(math.radians(31)) for a in ok)


@settings(max_examples=100, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(0.3, 1.0), st.floats(-0.5, 1.5),
       st.floats(-0.8, 0.8), st.sampled_from([1, -1]))
def test_sweep_geometry_reads_fraction_angle_and_depth_off_the_edge(edge, length, f, h, side):
    """SweepGeom: the projection fraction along the edge, the angle at the vertex past its
    perpendicular and the distance to the segment, for a point at fraction f, offset h on
    the swept side."""
    ex, ey = math.cos(edge), math.sin(edge)
    s = side
    nx, ny = -s * ey, s * ex
    task = Task(kind="test_drive", sweep_side=s, sweep_edge=edge, sweep_landmarks=[7],
                sweep_points=[length * ex, length * ey]).validate()
    g = SweepGeom(task)
    P = (f * length * ex + h * nx, f * length * ey + h * ny)
    assert g.frac(P) == pytest.approx(f, abs=1e-9)
    if math.hypot(f * length, h) > 1e-6:       # the angle at the vertex itself is none
        assert abs(wrap(g.phi(P) - math.atan2(-f * length, h))) < 1e-9
    t = min(1.0, max(0.0, f))
    assert g.depth_of(P) == pytest.approx(math.hypot((f - t) * length, h), abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10**6))
def test_star_shape_places_the_neighbours_from_bearings_alone(seed):
    """coordinator.topology.targets.star_shape: every robot it places around p stands
    where it is, in p's body frame, |pq| = 1; the robots' own frames may be rotated."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, (14, 2))
    P[0], P[1] = (0.0, 0.0), (rng.uniform(0.4, 0.9), rng.uniform(-0.3, 0.3))
    head = rng.uniform(-math.pi, math.pi, len(P))
    nbrs = {i: {j: math.atan2(*(P[j] - P[i])[::-1]) - head[i] for j in range(len(P))
                if j != i and np.linalg.norm(P[j] - P[i]) <= 1.0} for i in range(len(P))}
    got = star_shape(nbrs, 0, 1)
    assert 1 in got
    L = float(np.linalg.norm(P[1]))
    c, s = math.cos(-head[0]), math.sin(-head[0])
    for k, (x, y) in got.items():
        tx, ty = c * P[k][0] - s * P[k][1], s * P[k][0] + c * P[k][1]
        assert (x * L, y * L) == pytest.approx((tx, ty), abs=1e-6)


# ----------------------------------------------------------------------- in the world
def _scene(door: float | None, ang: float = 0.0, others=(), *, thick: float = 0.1,
           ring=None, boxes=()):
    """The wall (a door [0.6, 0.6 + door] in it, if any, the wall ``thick`` m thick; or the
    boundary ``ring``), obstacles ``boxes`` (polygons) and the swarm, turned by ``ang``
    (deg) about the origin: (WorldMap, {robot: (x, y)}, rotation)."""
    a, T = 0.6, thick
    rot = math.radians(ang)
    M = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    if ring is not None:
        pass
    elif door is None:
        ring = [[-2, 0], [3, 0], [3, 2], [-2, 2]]
    else:
        ring = [[-2, 0], [a, 0], [a, -T], [-2, -T], [-2, -2], [3, -2], [3, -T], [a + door, -T],
                [a + door, 0], [3, 0], [3, 2], [-2, 2]]
    wm = WorldMap("sweep", np.array(ring, float) @ M.T,
                  [np.array(b, float) @ M.T for b in boxes], np.zeros((0, 3)))
    pts = {0: (0.0, Y), 1: (D0, Y), 2: (D0 / 2, Y + 0.78), 3: (-D0 / 2, Y + 0.78),
           4: (1.5 * D0, Y + 0.78), 5: (-D0, Y), 6: (2 * D0, Y), 8: (0.0, Y + 1.56)}
    pts.update(others)
    return wm, {k: tuple(np.array(p) @ M.T) for k, p in pts.items()}, rot


def _task(pts, rot, far=0.9, stop_deg=10.0, direction_deg=-70.0, depth=0.75, side=-1,
          drop=(), distance=0.75, lenses=False):
    """The sweep task the coordinator would send robot 0: landmark places from bearings
    (star_shape) at d0 per edge length, but for the robots ``drop``, its vertex's bearings
    to home back on; the first drive ``distance`` long (None: as far as it stays in the
    lenses at robot 0, at most d0, as coordinator.tasks sends it with ``lenses``, the
    Task.sweep_lenses, which the coordinator sets by default)."""
    nb = {i: {j: math.atan2(q[1] - p[1], q[0] - p[0]) for j, q in pts.items()
              if j != i and math.dist(p, q) <= 1.0} for i, p in pts.items()}
    shape = star_shape(nb, 0, 1)
    lms = [1] + sorted(k for k in shape if k != 1 and k not in drop)
    home = sorted(nb[0])
    direction = math.radians(direction_deg) + rot
    if distance is None:
        pts_ = [c * D0 for k in lms for c in shape[k]]
        lz = lens_radii((pts_[0], pts_[1]), depth,
                        [(pts_[k], pts_[k + 1]) for k in range(2, len(pts_), 2)] if lenses else [])
        distance = max(depth, lens_reach(direction, lz, cap=D0))
    return Task(task_id=1, robot=0, kind="test_drive", vertex=0, landmarks=home,
                bearings=[nb[0][k] for k in home], direction=direction,
                distance=distance, keep_after=0.0, timeout_s=80.0, sweep_side=side,
                sweep_lenses=lenses,
                sweep_edge=nb[0][1], sweep_far=far, sweep_stop=math.radians(stop_deg),
                sweep_depth=depth, sweep_landmarks=lms,
                sweep_points=[c * D0 for k in lms for c in shape[k]]).validate()


def _run(wm, pts, task, ticks=1500, noise_deg=0.5, seed=0, params=None, camera=None):
    """Robot 0 runs ``task`` with the world's physics and sensors (the others hold still),
    with ``params`` (AgentParams(), the defaults, if None); ``camera`` (if any) rewrites
    robot 0's Sense fields each tick: (behaviour, trace of robot 0's (x, y) per tick, its
    mode per tick)."""
    phys = Physics(wm, radius=R, v_max=0.5, w_max=2.0, dt=0.05)
    sens = Sensors(wm, 1.0, radius=R, noise_sigma=math.radians(noise_deg), n_touch=8,
                   skin=0.015, rng=np.random.default_rng(seed))
    for k, (x, y) in pts.items():
        phys.add(k, x, y, 0.0, "holonomic", False, exact=True)
    beh = Behaviour(params or AgentParams(), 0)
    beh.on_task(task)
    trace, modes = [], []
    for tick in range(ticks):
        ids, pos, th = phys.state()
        k0 = ids.index(0)
        per = sens.sense(pos, th).lists(ids)
        mine = camera(per[k0]) if camera else per[k0]
        cmd = beh.step(Sense(robot=0, tick=tick, t=tick * 0.05, **mine))
        trace.append(tuple(pos[k0]))
        modes.append(beh.mode)
        cmds = np.zeros((len(ids), 3))
        cmds[k0] = (cmd.vx, cmd.vy, cmd.wz)
        phys.step(cmds)
        if beh.task_state in ("done", "failed"):
            break
    ids, pos, _ = phys.state()
    trace.append(tuple(pos[ids.index(0)]))
    modes.append(beh.mode)
    return beh, np.array(trace), np.array([str(m) for m in modes])


def _local(trace, rot):
    """The trace in the scene's own axes (the wall along x, y = 0)."""
    c, s = math.cos(-rot), math.sin(-rot)
    return np.stack([c * trace[:, 0] - s * trace[:, 1], s * trace[:, 0] + c * trace[:, 1]], 1)


@pytest.mark.parametrize("ang", [0.0, 22.5])
def test_a_sweep_slides_along_the_wall_and_reports_the_part_it_joined(ang):
    """No door: the robot presses along the wall to the far line, back past its vertex to
    the ray, then home; it reports "swept HI end" with HI at least the far fraction, and
    stayed in touch with the wall all along (within r + skin), at any angle of the wall to
    the touch sectors (22.5 deg: the worst). With one landmark in view (robot 1) it
    dead-reckons at the slowest progress the wall allows, so it may go on past the far
    line; it never stops short of it."""
    wm, pts, rot = _scene(None, ang)
    beh, trace, modes = _run(wm, pts, _task(pts, rot, far=0.6))
    assert beh.task_state == "failed", beh.reason
    hi, lo = parse_sweep_reason(beh.reason)
    assert lo == -math.inf and hi >= 0.6
    order = [m for k, m in enumerate(modes) if k == 0 or modes[k - 1] != m]
    assert order[:2] == ["open", "sweep"] and order[2] in ("open", "home")
    on_wall = _local(trace, rot)[modes == "sweep"]
    assert len(on_wall) > 40
    assert on_wall[:, 1].max() < R + 0.015 + 0.005 and on_wall[:, 1].min() > R - 0.005
    # it went as far as the far line and back past the vertex (x = 0) to the ray 10 deg
    # beyond (x = -0.05 at the wall; its place from bearings is good to about 2 cm there)
    assert on_wall[:, 0].max() >= 0.6 * D0 - 0.02
    assert on_wall[:, 0].min() < -(Y - R) * math.tan(math.radians(10.0)) + 0.025
    # and is home again
    assert math.dist(trace[-1], pts[0]) < 0.03


@pytest.mark.parametrize("door, ang", [(0.20, 0.0), (0.20, 22.5), (0.30, 10.0), (0.25, 40.0)])
def test_a_door_a_body_wide_is_an_opening_the_robot_stays_in(door, ang):
    """A door 0.20 m wide or more (a 0.12 m body): the sweep goes round its jamb, drives on
    into it along the wall's normal and stays where that ends, done "opening": past the
    wall's front face, in the doorway (a jamb blocked it) or in the room beyond."""
    wm, pts, rot = _scene(door, ang)
    beh, trace, _ = _run(wm, pts, _task(pts, rot))
    assert beh.task_state == "done" and beh.reason == "opening"
    x, y = _local(trace, rot)[-1]
    assert 0.6 - 2 * R < x < 0.6 + door and y < 0.0


@pytest.mark.parametrize("thick, gap", [(0.02, 0.13), (0.02, 0.2), (0.05, 0.13), (0.1, 0.16)])
@pytest.mark.parametrize("ang", [0.0, 30.0])
def test_a_door_with_a_wall_right_behind_it_is_still_an_opening(thick, gap, ang):
    """Behind a 0.2 m door in a thin wall, a box leaves a corridor ``gap`` m wide (a body
    fits) along the wall's back: the drive into the opening is blocked within a body length,
    yet the robot went round to the back of the wall it followed (135 deg), so it stays
    there, in the doorway, done "opening" (the corridor may lead to a room; its deployments
    explore it). Taken for a wall's step, it would sweep on along the box and stop down
    the corridor (x 0.10-0.12 m in 5 of these 8 cases)."""
    box = [[0.2, -thick - gap - 0.3], [1.4, -thick - gap - 0.3], [1.4, -thick - gap],
           [0.2, -thick - gap]]
    wm, pts, rot = _scene(0.2, ang, thick=thick, boxes=[box])
    beh, trace, _ = _run(wm, pts, _task(pts, rot))
    assert beh.task_state == "done" and beh.reason == "opening"
    x, y = _local(trace, rot)[-1]
    assert 0.6 - 2 * R < x < 0.6 + 0.2 and y < 0.0


@pytest.mark.parametrize("ang", [0.0, 10.0, 40.0])
def test_a_raster_wall_s_steps_are_swept_past(ang):
    """A wall receding in 0.05 m steps every 0.15 m (a ROS map's raster at 0.05 m, the
    cave's walls): the sweep goes round each step's corner and is blocked by the next step
    within a body length; it went round no wall to its back, so that is a turn into a
    wall, not an opening: it sweeps on and joins the edge from its vertex's ray (these
    angles ended "opening" against the wall before the rule)."""
    ring = [[-2, 0], [-0.6, 0]]
    x, y = -0.6, 0.0
    for _ in range(12):
        x += 0.15
        ring += [[x, y], [x, y - 0.05]]
        y -= 0.05
    ring += [[3, y], [3, 2], [-2, 2]]
    wm, pts, rot = _scene(None, ang, ring=ring)
    beh, _, _ = _run(wm, pts, _task(pts, rot, depth=0.9))
    assert beh.task_state == "failed" and parse_sweep_reason(beh.reason)[1] == -math.inf


@pytest.mark.parametrize("bumps", [[(0.4, 0.05)], [(0.4, 0.05), (-0.3, 0.05)], [(0.3, 0.1)]])
@pytest.mark.parametrize("ang", [0.0, 45.0])
def test_a_bump_on_the_wall_is_swept_past(bumps, ang):
    """A bump 0.05 m high (one raster cell) and ``w`` m wide standing out of the wall: the
    sweep turns into its face, goes over it and round its far corner. That face was shorter
    than a body length, and the robot went round no wall it followed: the drive on along
    the face's normal runs parallel to the wall, clear, and turns to the wall held before
    the bump, which it meets: a turn into it. The sweep joins the edge from its vertex's
    ray. Before, each case ended "opening" with the robot 0.75 m along the wall."""
    ring = [[-2, 0]]
    for x, w in bumps:
        ring += [[x, 0], [x, 0.05], [x + w, 0.05], [x + w, 0]]
    ring += [[3, 0], [3, 2], [-2, 2]]
    wm, pts, rot = _scene(None, ang, ring=ring)
    beh, _, _ = _run(wm, pts, _task(pts, rot))
    assert beh.task_state == "failed" and parse_sweep_reason(beh.reason)[1] == -math.inf


def test_a_door_narrower_than_the_body_is_swept_past():
    wm, pts, rot = _scene(0.10)
    beh, _, _ = _run(wm, pts, _task(pts, rot))
    assert beh.task_state == "failed" and parse_sweep_reason(beh.reason)[1] == -math.inf


def test_a_robot_in_the_way_stops_the_sweep_short():
    """Robot 9 rests against the wall at x = 0.45: the sweep stops short of it (it never
    pushes a robot), goes back, and reports how far it got and that robot 9 stopped it (the
    coordinator infers nothing over the gap when robot 9 is cut off from the swarm)."""
    wm, pts, rot = _scene(None, 0.0, {9: (0.45, R + 0.002)})
    beh, trace, _ = _run(wm, pts, _task(pts, rot, far=0.9))
    hi, lo = parse_sweep_reason(beh.reason)
    assert lo == -math.inf and hi < 0.45 / D0
    assert 9 in sweep_stoppers(beh.reason)
    assert _local(trace, rot)[:, 0].max() < 0.45 - 2 * R + 0.01


@pytest.mark.parametrize("ang", [0.0, 22.5, 40.0])
@pytest.mark.parametrize("y1", [R + 0.002, 0.1])
def test_the_other_end_s_body_in_the_way_counts_as_the_far_line(y1, ang):
    """Robot 1, the edge's other end, rests against the wall (or 0.1 m off it): the sweep
    stops at its body, which says it touches there, and reports the edge swept to the far
    line (no third body fits between them), though it stopped short of it."""
    wm, pts, rot = _scene(None, ang, {1: (D0, y1)})
    beh, trace, _ = _run(wm, pts, _task(pts, rot, far=0.9))
    hi, lo = parse_sweep_reason(beh.reason)
    assert lo == -math.inf and hi >= 0.9
    assert _local(trace, rot)[:, 0].max() < D0 - 2 * R + 0.01


@pytest.mark.parametrize("ang", [0.0, 22.5])
@pytest.mark.parametrize("fence", [0.15, 0.2, 0.25])
def test_a_third_robot_in_the_other_end_s_sector_is_not_its_body(fence, ang):
    """Robot 9 rests against the wall at x = 0.45, in the touch sector robot 1 (the edge's
    other end, ``fence`` m off the wall) is seen in. Robot 9 says it touches; the sweep
    stops short of it and reports how far it got, not the far line: the wall beyond robot
    9 is unswept. Taking any robot's word for the other end's closed the side (0.900)."""
    wm, pts, rot = _scene(None, ang, {0: (0.0, fence), 1: (D0, fence), 9: (0.45, R + 0.002)})
    beh, _, _ = _run(wm, pts, _task(pts, rot, far=0.9))
    hi, lo = parse_sweep_reason(beh.reason)
    assert lo == -math.inf and hi < 0.45 / D0


class _DropOnce:
    """A camera that drops robot ``who`` from the first Sense tick on which a robot says it
    touches robot 0 (one packet's dropout, at the worst moment)."""

    def __init__(self, who: int):
        self.who, self.dropped = who, 0

    def __call__(self, per: dict) -> dict:
        if self.dropped or not any(per["touch_robot"]) or self.who not in per["ids"]:
            return per
        self.dropped += 1
        keep = [k for k, i in enumerate(per["ids"]) if i != self.who]
        return {**per, **{f: [per[f][k] for k in keep] for f in ("ids", "bearings", "back_bearings")}}


@pytest.mark.parametrize("ang", [0.0, 22.5])
@pytest.mark.parametrize("fence", [0.15, 0.2, 0.25])
def test_one_tick_that_drops_the_third_robot_does_not_close_the_side(fence, ang):
    """The third robot's scene, with robot 9's sighting dropped from robot 0's camera on the
    tick robot 9 first says it touches: that one tick shows the other end alone in the
    sector. The sweep hears the word again on the next tick before it closes anything, and
    reports only how far it got. On one tick's word it reported the far line (0.900)."""
    wm, pts, rot = _scene(None, ang, {0: (0.0, fence), 1: (D0, fence), 9: (0.45, R + 0.002)})
    cam = _DropOnce(9)
    beh, _, _ = _run(wm, pts, _task(pts, rot, far=0.9), camera=cam)
    hi, lo = parse_sweep_reason(beh.reason)
    assert cam.dropped == 1
    assert lo == -math.inf and hi < 0.45 / D0


@pytest.mark.parametrize("fence, high, ang", [(0.35, 0.08, 22.5), (0.25, 0.04, 0.0),
                                              (0.25, 0.08, 22.5), (0.2, 0.08, 0.0),
                                              (0.15, 0.04, 0.0)])
def test_a_wall_where_the_other_end_is_seen_is_not_its_body(fence, high, ang):
    """A step ``high`` m tall stands out of the wall at x = 0.4-0.5, and a door 0.2 m wide
    opens at x = 0.62 behind it; the fence edge 0-1 runs ``fence`` m off the wall. The
    step's face is touched in the sector robot 1 (the edge's other end) is seen in, but
    robot 1 is 0.4 m away and touches nobody. The sweep stops there (a robot may be in the
    way) and reports the edge swept only as far as it got, short of the door: the fence
    side stays open there. It used to take the step for robot 1's body and report the edge
    swept to the far line (0.9) from x = 0.34, the door unseen: a side closed over a room."""
    a, b = 0.62, 0.82
    ring = [[-2, 0], [0.4, 0], [0.4, high], [0.5, high], [0.5, 0], [a, 0], [a, -0.1],
            [-2, -0.1], [-2, -2], [3, -2], [3, -0.1], [b, -0.1], [b, 0], [3, 0], [3, 2],
            [-2, 2]]
    wm, pts, rot = _scene(None, ang, {0: (0.0, fence), 1: (D0, fence)}, ring=ring)
    beh, trace, _ = _run(wm, pts, _task(pts, rot))
    if beh.reason == "opening":                  # over the step and into the door
        x, y = _local(trace, rot)[-1]
        assert beh.task_state == "done" and a - 2 * R < x < b and y < 0.0
        return
    hi, _ = parse_sweep_reason(beh.reason)
    assert hi * D0 <= _local(trace, rot)[:, 0].max() + 0.05 and hi * D0 < a


def test_a_probe_that_touches_drives_its_approach_back_before_homing():
    """A probe's open-loop approach along its edge (one via landmark) that then touches
    the wall drives both legs back before homing on its vertex. Its vertex's landmarks
    here (robots 5 and 1 either side, a single-file corridor) are in line with it: homing
    on them alone stops anywhere on that line, and the robot used to stay where the
    approach had taken it (corridor_doors: 1.05 m off its vertex after three probes, which
    cut six robots off the source)."""
    wm, pts, rot = _scene(None)
    pts = {k: pts[k] for k in (0, 1, 5)}
    task = Task(task_id=1, robot=0, kind="test_drive", vertex=0, landmarks=[1, 5],
                bearings=[0.0, math.pi], direction=-math.pi / 2, distance=0.75,
                keep_after=0.0, timeout_s=80.0, via_landmarks=[1], via_bearings=[0.0],
                via_distance=0.45).validate()
    beh, trace, modes = _run(wm, pts, task)
    assert beh.task_state == "failed" and beh.reason == "touch"
    assert _local(trace, rot)[:, 0].max() > 0.4          # it did go along the edge
    assert math.dist(trace[-1], pts[0]) < 0.05


def test_a_robot_in_an_opening_stays_in_sight_of_its_landmarks():
    """Told to go 1.6 m into the room beyond a 0.3 m door, the robot passes out of every
    landmark's sight (1 m, the jambs occlude) and backs out until one is in view again: it
    stays in the opening, done "opening", seen by the swarm (a robot that sees none of them
    is cut off from every source and sent away)."""
    wm, pts, rot = _scene(0.30)
    task = _task(pts, rot, depth=1.6)
    beh, trace, _ = _run(wm, pts, task, ticks=3000)
    assert beh.task_state == "done" and beh.reason == "opening"
    x, y = _local(trace, rot)[-1]
    assert y < 0.0                                   # beyond the wall's front face
    assert set(task.sweep_landmarks) & set(beh.see.seen)
    deepest = _local(trace, rot)[:, 1].min()
    assert deepest < y - 0.05                        # it went deeper, then came back


def test_a_test_drive_stops_where_it_is_about_to_lose_sight_of_its_vertex():
    """A clear test drive that would leave every landmark of its vertex out of view (robots
    5 and 1, 0.9 m either side: both out of range 0.44 m up) backs up until one is seen
    again and 0.1 rv farther, and stays there, done: a new robot the swarm still sees. It
    used to drive on and stand where nobody saw it (tiny seed 1, after a sweep had brought
    it home 0.34 m short: cut off from every source and sent away)."""
    wm, pts, rot = _scene(None)
    pts = {k: pts[k] for k in (0, 1, 5)}
    task = Task(task_id=1, robot=0, kind="test_drive", vertex=0, landmarks=[1, 5],
                sight=[1, 5], bearings=[0.0, math.pi], direction=math.pi / 2, distance=0.9,
                keep_after=0.45, timeout_s=80.0).validate()
    beh, trace, _ = _run(wm, pts, task)
    assert beh.task_state == "done" and beh.reason == "link lost, backed up"
    h = _local(trace, rot)[-1][1] - Y
    reach = math.sqrt(1.0 - D0 ** 2)                 # 0.436: both landmarks at 1 m
    assert reach - 0.1 - 0.05 < h < reach
    assert {1, 5} <= set(beh.see.seen)


def test_the_sweep_slides_at_its_own_speed_whatever_the_test_drive_s():
    """The drive out to the wall goes at test_drive_speed_frac, the slide along it at
    sweep_speed_frac: the sweep's wall-end rule (sweep_lost_m without a touch) and the door
    widths it finds were measured at half speed (at full speed it found 12 of 14 doors
    0.18 m wide, against 14 of 14), the plain drive has no such limit."""
    wm, pts, rot = _scene(None, 0.0)
    p = AgentParams(test_drive_speed_frac=1.0, sweep_speed_frac=0.5)
    beh, trace, modes = _run(wm, pts, _task(pts, rot, far=0.6), params=p)
    assert beh.task_state == "failed", beh.reason
    step = np.linalg.norm(np.diff(trace, axis=0), axis=1)
    on = modes[:-1]
    v_open = step[on == "open"][:5].max() / 0.05
    v_sweep = np.median(step[on == "sweep"]) / 0.05
    assert v_open > 0.45                   # the drive out at v_max = 0.5 m/s
    assert 0.1 < v_sweep < 0.26            # the slide at half of it (pressing in: a bit less)


# the wall row's chain (pillar_hall seed 0, stop 54): robot 0 in the row 0.58 m from the
# wall, robot 1 against the wall 0.9 m from it, robot 5 the row's next robot
Y0 = 0.58
_CHAIN = {0: (0.0, Y0), 1: (-0.735, 0.06), 5: (0.87, 0.58), 9: (-0.6, 0.75),
          2: (0.45, 1.13), 3: (-0.45, 1.13), 4: (1.35, 1.13), 6: (1.8, 1.6), 8: (0.0, 1.91)}


@pytest.mark.parametrize("ang", [0.0, 22.5])
def test_a_wall_in_the_next_side_s_lens_is_swept_not_taken_for_room(ang):
    """With Task.sweep_lenses (the coordinator's default since 2026-12-03). The side 0-1
    faces the wall obliquely; the first drive, 15 deg off its perpendicular
    towards robot 5, meets the wall 0.81 m out, beyond the edge's lens (0.75 m) but within
    the lens of the segment to robot 5 (0.76 m about it; robots 0 and 5 cover it). The
    drive goes on while in the lenses (up to d0), touches, and the sweep follows the wall to
    the far line and back past robot 0 to the ray 15 deg beyond the perpendicular, 0.82 m
    from robot 0: swept, the whole of its half joined. With robot 1 its only landmark
    the drive ends clear at 0.75 m, and the robot stays there."""
    wm, pts, rot = _scene(None, ang, _CHAIN)
    e = math.degrees(math.atan2(pts[1][1] - pts[0][1], pts[1][0] - pts[0][0]) - rot)

    def task(drop=()):
        # robots 1, 2 (a fix on the way) and 5 (robot 9, 0.62 m away, would hold a disk of
        # 0.82 m round robot 0; robot 2's holds 0.80 m, short of the ray)
        return _task(pts, rot, far=0.5, stop_deg=15.0, side=1, distance=None, lenses=True,
                     drop=(3, 4, 8, 9, *drop), direction_deg=e + 90.0 + 15.0)
    assert task().distance == pytest.approx(D0) and task((2, 5)).distance == pytest.approx(0.75)
    # without Task.sweep_lenses (a message's default) the edge's lens alone: the wall is room
    assert SweepGeom(_task(pts, rot, side=1)).lenses == []
    beh, trace, modes = _run(wm, pts, task())
    assert beh.task_state == "failed", beh.reason
    hi, lo = parse_sweep_reason(beh.reason)
    assert lo == -math.inf and hi >= 0.5
    on_wall = _local(trace, rot)[modes == "sweep"]
    assert on_wall[:, 1].max() < R + 0.015 + 0.005          # it followed the wall
    assert math.hypot(on_wall[:, 0].max(), Y0 - R) > 0.81      # past the lenses of 0-1, 0-2
    assert math.dist(trace[-1], pts[0]) < 0.03
    beh, trace, modes = _run(wm, pts, task((2, 5)))
    assert (beh.task_state, beh.reason) == ("done", "")
    assert math.dist(trace[-1], pts[0]) == pytest.approx(0.75, abs=0.03)


def test_a_wall_that_leads_behind_the_edge_s_line_joins_none_of_it():
    """bench/truth.py --doors seed 0 map 145: the vertex robot 0 stands 0.13 m above a
    floor, 0.08 m in front of a 0.47 m door through a wall 0.3 m thick (a short passage
    along the floor to a second room); its edge to robot 1 climbs steeply away from the
    floor, the side swept faces the door. The first drive runs into the passage and
    touches the floor; phase 1, towards robot 1, follows the floor under the vertex and
    behind the edge's line, where the projection on the edge grows: the sweep once reported
    fraction 0.35 joined and the side closed over the door. Only a place in front of the
    line joins the edge, and a phase stops short where the wall leads behind it; phase 2
    then follows the floor through the passage into the second room and stays there."""
    ring = [[0.0, 0.0], [6.363, 0.0], [6.363, 3.787], [3.771, 3.787], [3.771, 0.469],
            [3.476, 0.469], [3.476, 3.787], [0.0, 3.787]]
    pts = {0: (3.40, 0.13), 1: (3.15, 0.99), 2: (2.53, 0.36), 3: (2.29, 1.23),
           4: (1.65, 0.60)}
    wm, pts, rot = _scene(None, 0.0, ring=ring, others=pts)
    pts = {k: pts[k] for k in (0, 1, 2, 3, 4)}
    # a first drive 60 deg below the edge's perpendicular touches the floor at the door
    # (the bench's drive at -14 deg touched there; the world's physics slides it along)
    task = _task(pts, rot, far=0.496, stop_deg=90.0, direction_deg=-60.0, side=-1,
                 distance=None, lenses=True)
    beh, trace, modes = _run(wm, pts, task, ticks=2400)
    assert beh.task_state == "done", beh.reason       # it stayed: room, not swept
    assert trace[-1][0] > 3.771, trace[-1]              # in the second room

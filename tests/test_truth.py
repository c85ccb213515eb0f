"""The independent oracle (bench/oracle.py) and a seeded sample of bench/truth.py's campaign.

The campaign tests grow the first 40 random maps of seed 0 with the system's real fence
rules and ask the oracle whether every certificate is true. They are meant to fail while the
system can call a map covered that is not (issue 21): 0 false certificates on every map,
doors of 0.30 rv included since wall sweeps (a 0.12 rv robot fits through them), and every
map must reach an end (a map that never ends makes no claim to check).
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from bench.oracle import (PolyMap, Raster, chain_boundary, coverage, in_boundary_span, judge,
                          line_of_sight, reachable, rips)
from bench import truth

RV = 1.0
R = 0.06


def _square(s):
    return np.array([[0, 0], [s, 0], [s, s], [0, s]], float)


def _two_rooms(door):
    """6 m x 3 m, a 0.1 m wall at x = 3 with a door of width ``door`` centred at y = 1.5."""
    y0, y1 = 1.5 - door / 2, 1.5 + door / 2
    return PolyMap(np.array([[0, 0], [3, 0], [3, y0], [3.1, y0], [3.1, 0], [6, 0], [6, 3],
                             [3.1, 3], [3.1, y1], [3, y1], [3, 3], [0, 3]], float))


# ------------------------------------------------------------------------- geometry
def test_line_of_sight_and_rips_respect_walls():
    pm = PolyMap(_square(4), [np.array([[1.9, 0.5], [2.1, 0.5], [2.1, 3.5], [1.9, 3.5]])])
    segs = pm.walls()
    assert not line_of_sight((1.6, 2.0), (2.4, 2.0), segs)
    assert line_of_sight((1.6, 3.8), (2.4, 3.8), segs)
    pts = np.array([[1.6, 2.0], [2.4, 2.0], [1.6, 2.9], [1.6, 3.8], [2.4, 3.8]])
    edges, tris = rips(pts, segs, RV)
    assert (0, 1) not in edges            # 0.8 apart, through the wall
    assert (3, 4) in edges and (0, 2) in edges and (2, 3) in edges
    assert (0, 3) not in edges            # 1.8 apart
    assert tris == set()                  # 2-3-4: 2 and 4 are 1.17 apart
    pts2 = np.array([[0.5, 0.5], [1.3, 0.5], [0.9, 1.1]])
    assert rips(pts2, segs, RV) == ({(0, 1), (0, 2), (1, 2)}, {(0, 1, 2)})


def test_raster_disk_in_an_empty_square():
    ras = Raster(PolyMap(_square(4)), 0.02)
    assert ras.free.sum() * ras.cell_area == pytest.approx(16.0, rel=0.01)
    cov = coverage(ras, [(2.0, 2.0)], RV)
    assert cov.sum() * ras.cell_area == pytest.approx(math.pi, rel=0.01)
    # clearance is the distance to the nearest wall: the centre cell is 2 m from all four
    r, c = ras.cell_of((2.0, 2.0))
    assert ras.clearance[r, c] == pytest.approx(2.0, abs=0.02)


def test_judge_knows_covered_from_uncovered():
    """3 m x 3 m room. One robot at the centre sees a disk of radius 1 that just fits in
    the square of points farther than 0.5 m from the walls: its four corners, 4 - pi m^2,
    are reachable, deep and uncovered. Nine robots 1 m apart cover everything."""
    pm = PolyMap(_square(3))
    ras = Raster(pm, 0.02)
    v = judge(ras, [(1.5, 1.5)], (1.5, 1.5), RV, R)
    assert not v.fully_covered
    assert len(v.holes) == 4
    for area, depth, _ in v.holes:
        assert area == pytest.approx((4 - math.pi) / 4, rel=0.1)
        assert depth == pytest.approx(0.5 + (math.sqrt(2) - 1) / math.sqrt(2), abs=0.05)
    assert v.hole_area == pytest.approx(4 - math.pi, rel=0.05)
    grid = [(x, y) for x in (0.5, 1.5, 2.5) for y in (0.5, 1.5, 2.5)]
    v9 = judge(ras, grid, (1.5, 1.5), RV, R)
    assert v9.fully_covered and v9.covered_fraction == pytest.approx(1.0)
    # a wall hides what is behind it: the same nine robots with a box in the middle of
    # the room miss nothing deep (the box leaves no deep cell) ...
    boxed = PolyMap(_square(3), [np.array([[1.2, 1.2], [1.8, 1.2], [1.8, 1.8], [1.2, 1.8]])])
    rb = Raster(boxed, 0.02)
    vb = judge(rb, [p for p in grid if p != (1.5, 1.5)], (0.5, 0.5), RV, R)
    assert vb.fully_covered
    # ... but one robot in the corner of a two-room map leaves room B uncovered
    tr = Raster(_two_rooms(0.8), 0.02)
    vt = judge(tr, [(0.5, 0.5)], (0.5, 0.5), RV, R)
    assert not vt.fully_covered and vt.hole_area > 5.0


def test_reachability_through_a_door_narrower_than_the_robot():
    narrow = Raster(_two_rooms(0.10), 0.02)     # door 0.10 m < robot diameter 0.12 m
    reach = reachable(narrow, (1.0, 1.5), R)
    assert reach[narrow.cell_of((1.0, 1.0))] and not reach[narrow.cell_of((5.0, 1.5))]
    # uncovered room B is then no false certificate's business
    v = judge(narrow, [(1.0, 1.5), (2.0, 1.5)], (1.0, 1.5), RV, R)
    assert v.holes and all(c[0] < 3.0 for _, _, c in v.holes)
    wide = Raster(_two_rooms(0.20), 0.02)
    assert reachable(wide, (1.0, 1.5), R)[wide.cell_of((5.0, 1.5))]


def test_gf2_boundary_check():
    t = [(0, 1, 2), (1, 2, 3)]
    assert in_boundary_span(t, [(0, 1), (0, 2), (1, 3), (2, 3)])       # the square's rim
    assert chain_boundary(t) == {(0, 1), (0, 2), (1, 3), (2, 3)}
    assert not in_boundary_span(t, [(0, 1), (1, 2), (0, 2), (1, 3)])   # not a cycle
    assert not in_boundary_span([], [(0, 1), (1, 2), (0, 2)])          # no triangle
    assert in_boundary_span(t, [])
    # an annulus (hexagon around a hole): the outer rim is not a boundary, outer + inner is
    ring = [(0, 1, 6), (1, 6, 7), (1, 2, 7), (2, 7, 8), (2, 3, 8), (3, 8, 9),
            (3, 4, 9), (4, 9, 10), (4, 5, 10), (5, 10, 11), (0, 5, 11), (0, 6, 11)]
    outer = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5)]
    inner = [(6, 7), (7, 8), (8, 9), (9, 10), (10, 11), (6, 11)]
    assert not in_boundary_span(ring, outer)
    assert in_boundary_span(ring, outer + inner)


# ------------------------------------------------------------------------- harness
def test_maps_are_seeded_and_sources_face_walls():
    a, b = truth.make_map(0, 7), truth.make_map(0, 7)
    assert np.array_equal(a.pm.outer, b.pm.outer) and a.source == b.source
    cases = [truth.make_map(0, i) for i in range(60)]
    assert {c.kind for c in cases} == set(truth.KINDS)
    facing = [c for c in cases if c.facing_wall]
    assert facing
    for c in facing:
        assert c.pm.wall_distance(np.array([c.source]))[0] == pytest.approx(0.3)
    doors = [c.door_w for c in cases if c.door_w is not None]
    assert min(doors) >= 0.3 and max(doors) <= 1.2



def test_door_edge_maps_put_one_door_at_the_guarantee_edge():
    """``make_map(..., doors=True)`` (``--doors``): two rooms joined by one door 0.40-0.50 rv
    wide in a wall 0.05-0.30 m thick, some flush with the outer wall; each a closed room
    a robot can cross into the second room, and seeded."""
    cases = [truth.make_map(0, i, doors=True) for i in range(40)]
    assert all(c.kind == "two_rooms" for c in cases)
    assert all(0.4 * RV <= c.door_w <= 0.5 * RV for c in cases)
    assert np.array_equal(cases[5].pm.outer, truth.make_map(0, 5, doors=True).pm.outer)
    flush = [c for c in cases if len(c.pm.outer) == 8]       # the divider's stub is gone
    assert 3 <= len(flush) <= 20
    for c in cases[:12]:
        xs = sorted({round(float(x), 9) for x in c.pm.outer[:, 0]})
        thick = xs[2] - xs[1]                                 # 0, xw, xw + t, W
        assert 0.05 - 1e-9 <= thick <= 0.30 + 1e-9
        ras = Raster(c.pm, 0.05)
        far = (xs[-1] - 0.3, float(c.pm.outer[:, 1].max()) / 2)
        assert reachable(ras, c.source, R)[ras.cell_of(far)], c.index

def test_cells_meeting_only_at_a_corner_are_joined():
    """raster_map traces free cells into rings; two that touch only at a corner would make
    a ring cross itself, so one of the block's other two cells is freed (both diagonals)."""
    for grid in ([[1, 0], [0, 1]], [[0, 1], [1, 0]], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]):
        free = truth._join_corners(np.array(grid, bool))
        a, b, c, d = free[:-1, :-1], free[:-1, 1:], free[1:, :-1], free[1:, 1:]
        assert not ((a & d & ~b & ~c) | (b & c & ~a & ~d)).any(), free
        assert (free >= np.array(grid, bool)).all()          # nothing free was closed


@pytest.mark.parametrize("index", [0, 5, 10])
def test_raster_maps_turn_the_walls_into_steps_around_the_same_room(index):
    """``make_map(..., raster=0.05)``: the map turned 5-40 deg and drawn on a 0.05 m grid,
    as a ROS map draws it (the cave's walls): every wall axis-aligned, a whole number of
    cells long, the free area within a cell's strip along the walls of the turned map's,
    the source inside."""
    flat, r = truth.make_map(0, index), truth.make_map(0, index, 0.05)
    assert (r.kind, r.door_w) == (flat.kind, flat.door_w)
    assert r.pm.contains(np.array([r.source]))[0]
    w = r.pm.walls()
    d = w[:, 2:] - w[:, :2]
    assert np.all(np.min(np.abs(d), axis=1) < 1e-9)
    cells = np.max(np.abs(d), axis=1) / 0.05
    assert np.allclose(cells, np.round(cells)) and cells.min() >= 1 - 1e-9

    def area(pm):
        return abs(truth._area(pm.outer)) - sum(abs(truth._area(h)) for h in pm.holes)

    perimeter = float(np.linalg.norm(flat.pm.walls()[:, 2:] - flat.pm.walls()[:, :2], axis=1).sum())
    assert abs(area(r.pm) - area(flat.pm)) < 0.05 * perimeter
    assert np.array_equal(truth.make_map(0, index, 0.05).pm.outer, r.pm.outer)   # seeded


def test_the_sweep_emulation_mirrors_the_agent_and_the_world():
    """bench/sweep.py copies the agent's sweep defaults and the world's touch skin (it may
    not import them: the harness shares no geometry with agents/ or world/)."""
    from bench import sweep
    from swarmcover.agents.params import AgentParams
    from swarmcover.world.config import SensingConfig
    p = AgentParams()
    assert sweep.PRESS == pytest.approx(p.press) and sweep.LOST == p.sweep_lost_m
    assert sweep.BUDGET_RV == p.sweep_budget_rv and sweep.SKIN == SensingConfig().touch_skin
    assert sweep.OPEN_TURNS * 2 * math.pi / p.n_touch == pytest.approx(3 * math.pi / 4)
    assert truth.RADIUS == p.radius and truth.N_TOUCH == p.n_touch


@pytest.mark.parametrize("ang", [10.0, 30.0])
def test_the_sweep_emulation_goes_over_a_bump_as_the_agent_does(ang):
    """bench/sweep.py's copy of the agent's rule for a face shorter than a body length
    (tests/test_agent_sweep.py: a bump on the wall is swept past): a 0.05 m bump 0.05 and
    0.1 m wide is swept over to the vertex's ray. Before the rule both were an opening."""
    from bench.sweep import Sweeper
    rot = math.radians(ang)
    M = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    for w in (0.05, 0.1):
        ring = np.array([[-2, 0], [0.4, 0], [0.4, 0.05], [0.4 + w, 0.05], [0.4 + w, 0],
                         [3, 0], [3, 2], [-2, 2]], float) @ M.T
        segs = np.hstack([ring, np.roll(ring, -1, axis=0)])
        E, Q = np.array([0.0, 0.5]) @ M.T, np.array([0.9, 0.5]) @ M.T
        sp = Sweeper(segs, np.zeros((0, 2)), E, Q, -1, r=R, heading=0.3, depth=0.75)
        res = sp.run(np.array([0.0, R + 1e-3]) @ M.T, rot - math.pi / 2, 0.9, math.radians(10))
        assert res.kind == "swept" and res.lo == -math.inf, (w, res)


def test_drive_stops_at_walls():
    sw = truth.Swarm(PolyMap(_square(3)), np.random.default_rng(0), 0.0)
    trav, end, cdir = sw.drive(np.array([0.3, 1.5]), math.pi, 0.9)
    assert cdir is not None and trav == pytest.approx(0.3 - R, abs=2e-3)
    assert cdir == pytest.approx(math.pi, abs=1e-6)
    trav, end, cdir = sw.drive(np.array([1.5, 1.5]), 0.0, 0.9)
    assert cdir is None and end == pytest.approx([2.4, 1.5])


# ------------------------------------------------------------------------- campaign
@pytest.fixture(scope="module")
def sample():
    # the maps are independent: one worker process per core (the same rows, sorted)
    rows = truth.campaign(40, 0, min(2, os.cpu_count() or 1), progress=False)
    return rows, truth.summarise(rows)


def test_sample_grows_and_agrees_with_the_oracle(sample):
    rows, s = sample
    assert s["errors"] == 0, [r["error"] for r in rows if "error" in r]
    # the system's complex is the oracle's Rips complex, and its certificate answer is the
    # oracle's own GF(2) answer (the algebra held in issue 21's audit)
    assert s["complex_mismatch"] == 0
    assert s["algebra_mismatch"] == 0


def test_sample_has_no_false_certificates(sample):
    """Certified must mean covered: no map may end certified while a robot could reach
    uncovered free area beyond 0.5 rv from walls."""
    rows, _ = sample
    bad = [(r["index"], r["kind"], r["door_w"] and round(r["door_w"], 2), r["robots"],
            r["coverage"], r["hole_area"], [h["reason"] for h in r["hid_by"][:3]])
           for r in rows if r["false_certificate"]]
    assert not bad, f"{len(bad)} false certificates (index, kind, door, robots, coverage, hole m^2, why): {bad}"


def test_sample_maps_reach_an_end(sample):
    """Every map ends where the deployer would act: no deployment left (a fixed point, or
    frontier edges with none left), not a robot cap and not a livelock (the fence offering
    again a deployment whose robots arrived: they stack on one point). A map that never
    ends makes no claim, so the false-certificate test above cannot see it."""
    rows, _ = sample
    bad = [(r["index"], r["kind"], r["end"], r["robots"], r["livelock"][:1])
           for r in rows if r["end"] not in ("fixed", "stuck")]
    assert not bad, f"{len(bad)} maps never ended (index, kind, end, robots, repeated deployment): {bad}"


@pytest.mark.parametrize("seed, index", [(1, 267), (1, 496)])
def test_oblique_doors_at_corners_are_found(seed, index):
    """bench/truth.py seed 1, maps 267 and 496: 0.43-0.44 rv doors next to a room's corner,
    behind fence edges cutting the corner at about 45 deg. Perpendicular probe lines crossed
    them with less than the robot's width to spare, and the rooms behind (7.5 m^2 on map
    267) were certified uncovered. Probes are now driven again along the wall normals the
    side's robots felt (coordinator.topology.evidence)."""
    case = truth.make_map(seed, index)
    assert case.kind == "two_rooms" and 0.4 * RV <= case.door_w < 0.45 * RV
    row = truth.run_map(case)
    assert row["end"] in ("fixed", "stuck")
    assert not row["false_certificate"], (row["coverage"], row["hole_area"],
                                          [h["reason"] for h in row["hid_by"][:4]])


def test_rooms_are_booked_as_the_deployer_books_them():
    """bench/truth.py seed 0 map 429 (two rooms, a 0.32 rv door): booked once found, a room
    behind the door counted although no robot stood beyond its side any more, and the map
    certified at 48% coverage (``--legacy-rooms``, the bench's rule until 2026-12-03).
    Booked as the deployer books it (a room counts only while its robot stands beyond the
    side: coordinator.jobs.beyond_side), the default, it certifies covered."""
    case = truth.make_map(0, 429)
    assert case.kind == "two_rooms"
    held = truth.run_map(case)
    assert held["end"] == "fixed" and not held["false_certificate"] and held["coverage"] > 0.995
    legacy = truth.run_map(case, hold_rooms=False)
    assert legacy["false_certificate"] and legacy["coverage"] < 0.6


def test_a_robot_in_a_doorway_keeps_its_side_open_until_it_drove():
    """bench/truth.py seed 3 map 399 (two rooms, a 0.44 rv door, the source facing a wall,
    0.5 deg noise): a robot stood in the doorway, and the side from it back to the first
    room's robot was closed by the occlusion rule ('convex_corner': the near end's next
    robot was hidden from it by the jamb) while the doorway robot's open wedge on that
    side was reflex. The room behind, 4.5 m^2, was certified uncovered (58.8% coverage).
    With ``corner_wait`` (the default since 2026-12-04) the doorway robot drives into its
    wedge first, and the side closes only once it has no room."""
    from swarmcover.coordinator import TopologyParams

    assert TopologyParams().corner_wait
    case = truth.make_map(3, 399)
    assert case.kind == "two_rooms" and 0.4 * RV <= case.door_w < 0.45 * RV
    row = truth.run_map(case)
    assert row["end"] == "fixed" and not row["false_certificate"] and row["coverage"] > 0.995
    old = truth.run_map(case, topology={"corner_wait": False})
    assert old["false_certificate"] and old["coverage"] < 0.6
    assert "convex_corner" in [h["reason"] for h in old["hid_by"]]


def test_a_robot_in_a_narrow_door_whose_drives_all_touched_the_jambs():
    """bench/truth.py seed 4 map 188 (two rooms, a 0.30 rv door, below door_min_rv): an
    opening found by a sweep put robot 20 in the doorway; it and the robot one of its
    drives placed back in the first room form a dangling edge. Its five other drives
    (each then excluding 30 deg either side of it; the nearest 23 and 36 deg off the
    way through the door) touched the jambs, the edge's sides closed as 'probes' and
    'convex_corner', and the room behind, 5.1 m^2, was certified uncovered (54.6%), with
    corner_wait on or off. A chain end whose single-file drives all touched now tries the
    directions between them, as a lone robot does
    (coordinator.topology.fence_deploy.robot_deployments)."""
    case = truth.make_map(4, 188)
    assert case.kind == "two_rooms" and case.door_w < 0.4 * RV
    row = truth.run_map(case)
    assert row["end"] == "fixed" and not row["false_certificate"], (row["coverage"],)
    assert row["coverage"] > 0.995



def test_a_sweep_along_a_floor_under_its_vertex_joins_none_of_the_edge():
    """bench/truth.py --doors seed 0 map 145: a 0.47 rv door flush with the floor, in a wall
    0.3 m thick, 0.08 m in front of a robot. Its sweep followed the floor under it, behind
    the edge's line, to fraction 0.35, and the sides closed on that evidence: certified at
    59.3% coverage. Only places in front of the edge's line join it now (bench/sweep.py,
    agents/sweep.py): the sweep follows the floor through the door and stays there."""
    case = truth.make_map(0, 145, doors=True)
    assert case.kind == "two_rooms" and 0.4 * RV <= case.door_w < 0.5 * RV
    row = truth.run_map(case)
    assert row["end"] == "fixed" and row["certified"]
    assert not row["false_certificate"] and row["coverage"] > 0.995, row["coverage"]

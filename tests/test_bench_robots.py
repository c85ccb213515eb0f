"""bench/robots.py's oracle for thinning wall rows (issue 19 item 3): which fence robots
could leave a certified complex if the side across them were found closed. Pure: built
from positions, no run."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench.robots import fence_thin  # noqa: E402
from swarmcover.coordinator import build_complex, certify, detect_fence  # noqa: E402
from test_topology_geom import lattice, reports  # noqa: E402

WALL = np.array([[-1.0, 0.0, 6.0, 0.0]])        # one wall along y = 0, the room above


def _swarm(extra):
    P = lattice(3, 5, 0.9, origin=(0.0, 0.1))    # bottom row 0.1 m above the wall
    P = np.vstack([P, extra])
    cx = build_complex(reports(P))
    cert = certify(cx, detect_fence(cx))
    assert cert.certified
    pos = {i: tuple(p) for i, p in enumerate(P)}
    return cx, cert, pos, len(P) - 1


def test_a_crowded_robot_against_the_wall_is_the_one_that_could_leave():
    cx, cert, pos, c = _swarm([[1.35, 0.05]])     # between two row robots 0.9 m apart
    assert fence_thin(cx, cert, [0], pos, WALL, 0.75) == [c]


def test_no_robot_leaves_where_the_side_across_it_faces_open_room():
    # the same crowding on the top row: the rays across it meet no wall
    top = 0.1 + 2 * 0.9 * np.sqrt(3) / 2
    cx, cert, pos, c = _swarm([[1.35, top + 0.05]])
    assert c not in fence_thin(cx, cert, [0], pos, WALL, 0.75)
    # with a ceiling just above that row it leaves too (so only the room kept it)
    ceiling = np.vstack([WALL, [[-1.0, top + 0.1, 6.0, top + 0.1]]])
    assert c in fence_thin(cx, cert, [0], pos, ceiling, 0.75)
    # and with no wall anywhere nothing leaves
    assert fence_thin(cx, cert, [0], pos, np.zeros((0, 4)), 0.75) == []


def test_a_protected_robot_stays():
    cx, cert, pos, c = _swarm([[1.35, 0.05]])
    assert fence_thin(cx, cert, [0, c], pos, WALL, 0.75) == []

"""bench/bounds.py: the oracle lattice tiles its rectangle with Rips triangles, and never
beats the Euler lower bound on robots (so the bound and the construction check each other)."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st
from matplotlib.path import Path as MplPath
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("bench_bounds", ROOT / "bench" / "bounds.py")
bounds = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bounds)

from swarmcover.world.maps import WorldMap  # noqa: E402


def _covered(P: np.ndarray, rv: float, pts: np.ndarray) -> np.ndarray:
    E = cKDTree(P).query_pairs(rv, output_type="ndarray")
    nb = [set() for _ in P]
    for a, b in E:
        nb[a].add(b)
        nb[b].add(a)
    cov = np.zeros(len(pts), bool)
    for a, b in E:
        for c in nb[a] & nb[b]:
            if c > b:
                cov |= MplPath(P[[a, b, c]]).contains_points(pts, radius=1e-9)
    return cov


@settings(max_examples=25, deadline=None)
@given(w=st.floats(1.0, 7.0), h=st.floats(1.0, 5.0), s=st.floats(0.6, 1.0))
@example(w=1.0000000000000002, h=1.0, s=1.0)   # a width just past a whole number of s
def test_the_oracle_lattice_tiles_its_rectangle_and_respects_the_euler_bound(w, h, s):
    rv = 1.0
    P = bounds.lattice_points(w, h, s)
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0], [w, h], size=(400, 2))
    assert _covered(P, rv, pts).all()
    wm = WorldMap("rect", np.array([[0, 0], [w, 0], [w, h], [0, h]], float), [], np.zeros((0, 3)))
    assert len(P) >= bounds.euler_bound(wm, rv)["robots"]


def test_open_room_numbers_put_the_issue_targets_out_of_reach_of_a_perfect_lattice():
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "bounds.py"),
                          str(ROOT / "configs" / "open_room.toml")],
                         capture_output=True, text=True, timeout=120, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])["rows"][0]
    assert row["ideal_count"] == 78 and row["euler_bound"] == 97
    assert row["lattice_rv"]["robots"] == 110 and row["lattice_rv"]["max_edge"] <= 1.0
    assert row["lattice_d0"]["robots"] == 135
    assert row["lowest_ratio_same_spacing"]["ratio_same_spacing"] > 1.10

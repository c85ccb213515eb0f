"""What the best possible swarm scores on the coverage benchmark's metrics (issue 6 targets).

For each config, from the map alone (no simulation):

* ``ideal_count``: the baseline of ``summary.json``, A_free / (sqrt(3)/2 rv^2).
* ``euler_bound``: a lower bound on the robots of any certifiable swarm (computed by
  ``world.groundtruth.euler_bound``, which ``summary.json`` uses too). Certified coverage
  means the free area is tiled by Rips triangles (edges <= rv, so area <= sqrt(3)/4 rv^2
  each) whose outer edges run along every wall (the fence: robots touching the walls, at
  most rv apart, at least 3 around an obstacle). A planar triangulation of a region with h
  holes, n vertices and b of them on its boundary has T = 2n - b - 2 + 2h triangles, so
  n >= (A_free / (sqrt(3)/4 rv^2) + b + 2 - 2h) / 2 with b >= sum over walls of
  max(3, ceil(length / rv)).
* ``equilateral_same``: the ratio_same_spacing of an equilateral triangulation of side s
  that tiles the free area with vertices s apart along the walls, at its lowest over
  s in [rv/sqrt(3), rv] (below rv/sqrt(3) second neighbours become edges and the mean
  edge grows): what the thesis's comparison gives a perfect swarm once walls count.
* ``lattice``: on a map that is one axis-aligned rectangle, the best triangular lattice an
  oracle could place: rows on both walls, columns on both walls, every edge <= rv, robot
  centres ``radius`` from the walls; its Rips triangles cover the room. Its robots, ratio,
  mean edge length and ratio_same_spacing use the same formulas as ``summary.json``.

Prints a table and, last, one JSON object. Usage: python bench/bounds.py [configs ...]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from swarmcover.world.config import load_config  # noqa: E402
from swarmcover.world.groundtruth import euler_bound, ideal_count, ring_lengths  # noqa: E402,F401
from swarmcover.world.maps import build_map  # noqa: E402

TRI = math.sqrt(3) / 2


def _ring_lengths(wm) -> list[float]:
    """Length (m) of the boundary ring and of each obstacle ring."""
    return ring_lengths(wm)


def _ideal(wm, d: float) -> int:
    """summary.json's baseline: the tessellation count of spacing d (area formula, rounded)."""
    return int(round(ideal_count(wm, d)["area_formula"]))


def wall_length(wm) -> float:
    """Total length (m) of the boundary and obstacle rings."""
    return sum(_ring_lengths(wm))


def equilateral_same(wm, s: float) -> float:
    """ratio_same_spacing of an equilateral triangulation of side s that tiles the free
    area with its boundary vertices s apart along every wall: n = ideal_same + (L/s + 2 -
    2h)/2 (the Euler relation above with T = 2 ideal_same)."""
    ideal_same = wm.free_area / (TRI * s * s)
    return 1.0 + (wall_length(wm) / s + 2 - 2 * len(wm.obstacles)) / (2 * ideal_same)


def _rectangle(wm) -> tuple[float, float, float, float] | None:
    if wm.obstacles:
        return None
    B = np.asarray(wm.boundary, float)
    x0, y0 = B.min(axis=0)
    x1, y1 = B.max(axis=0)
    on_edge = np.isclose(B[:, 0], x0) | np.isclose(B[:, 0], x1)
    on_edge &= np.isclose(B[:, 1], y0) | np.isclose(B[:, 1], y1)
    return (x0, y0, x1, y1) if len(B) == 4 and on_edge.all() else None


def lattice_points(w: float, h: float, s: float) -> np.ndarray:
    """A triangular lattice of nominal spacing s filling [0, w] x [0, h], rows on y = 0 and
    y = h, every row's ends on x = 0 and x = w (stretched to fit, so edges shrink below s)."""
    rows = max(1, math.ceil(h / (TRI * s) - 1e-9))
    cols = max(1, math.ceil(w / s - 1e-9))
    # the tolerance must not stretch an edge past s (w = 1.0000000000000002 at s = rv
    # gave dx > rv, and the Rips triangles no longer tiled: hypothesis found it)
    rows += h / rows > TRI * s
    cols += w / cols > s
    dy, dx = h / rows, w / cols
    pts = []
    for k in range(rows + 1):
        if k % 2 == 0:
            xs = [i * dx for i in range(cols + 1)]
        else:
            xs = [0.0] + [(i + 0.5) * dx for i in range(cols)] + [w]
        pts += [(x, k * dy) for x in xs]
    return np.array(pts)


def _edges(P: np.ndarray, rv: float) -> np.ndarray:
    E = cKDTree(P).query_pairs(rv, output_type="ndarray")
    return np.linalg.norm(P[E[:, 0]] - P[E[:, 1]], axis=1)


def lattices(wm, rect, radius: float, rv: float, max_spacing: float) -> dict:
    """Oracle lattices over nominal spacings s in [rv/2, max_spacing] and both orientations:
    ``fewest`` robots (ties: the lower ratio_same_spacing) and ``lowest_same`` (the lowest
    ratio_same_spacing). Mean edge: over every pair within rv, as in ``summary.json``
    (below s = rv/sqrt(3) second neighbours become edges too)."""
    x0, y0, x1, y1 = rect
    w, h = (x1 - x0) - 2 * radius, (y1 - y0) - 2 * radius
    fewest = lowest = None
    for s in np.linspace(0.5 * rv, max_spacing, 101):
        for flip in (False, True):
            P = lattice_points(h, w, s)[:, ::-1] if flip else lattice_points(w, h, s)
            # the lattice triangles have sides <= s <= rv (rows dy <= s sqrt(3)/2 apart,
            # points dx <= s apart): Rips triangles that tile the rectangle
            L = _edges(P, rv)
            mean = float(L.mean())
            same = _ideal(wm, mean)
            cand = dict(robots=len(P), spacing=float(s), flipped=flip, mean_edge=mean,
                        max_edge=float(L.max()), ratio_same_spacing=len(P) / same)
            if fewest is None or (cand["robots"], cand["ratio_same_spacing"]) < (
                    fewest["robots"], fewest["ratio_same_spacing"]):
                fewest = cand
            if lowest is None or cand["ratio_same_spacing"] < lowest["ratio_same_spacing"]:
                lowest = cand
    return dict(fewest=fewest, lowest_same=lowest)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("configs", nargs="*", help="default: configs/*.toml except mixed.toml")
    args = ap.parse_args(argv)
    paths = args.configs or sorted(str(p) for p in (ROOT / "configs").glob("*.toml")
                                   if p.name != "mixed.toml")
    out = []
    print("robots (ratio) of: the Euler lower bound; the fewest-robot oracle lattice with "
          "spacing <= rv and <= d0 = 0.9 rv; ratio_same_spacing: the oracle lattices' lowest, "
          "an equilateral triangulation's lowest (at spacing x rv)")
    print(f"{'config':16} {'ideal@rv':>8} {'euler bound':>12} {'lattice<=rv':>12} "
          f"{'lattice<=d0':>12} {'lowest ratio_same':>18} {'equilateral same':>16}")
    for path in paths:
        cfg = load_config(path)
        wm = build_map(cfg)
        rv = cfg.rv
        ideal = _ideal(wm, rv)
        eb = euler_bound(wm, rv)
        row = dict(name=cfg.name, free_area=wm.free_area, ideal_count=ideal,
                   euler_bound=eb["robots"], euler_ratio=eb["robots"] / ideal,
                   boundary_vertices=eb["boundary_vertices"], holes=eb["holes"])
        grid = np.linspace(rv / math.sqrt(3), rv, 60)
        eq = min((equilateral_same(wm, x), x) for x in grid)
        row["equilateral_same"] = dict(ratio_same_spacing=eq[0], spacing=eq[1])
        rect = _rectangle(wm)
        cells = [f"{eb['robots']:4d} ({eb['robots'] / ideal:4.2f})"]
        if rect:
            for key, cap in (("lattice_rv", rv), ("lattice_d0", 0.9 * rv)):
                lat = lattices(wm, rect, cfg.robots.radius, rv, cap)
                row[key] = dict(lat["fewest"], ratio=lat["fewest"]["robots"] / ideal)
                row["lowest_ratio_same_spacing"] = lat["lowest_same"]
                cells.append(f"{lat['fewest']['robots']:4d} ({row[key]['ratio']:4.2f})")
            low = row["lowest_ratio_same_spacing"]
            cells.append(f"{low['ratio_same_spacing']:.3f} at {low['robots']} robots")
        else:
            cells += ["-", "-", "- (not a rectangle)"]
        out.append(row)
        print(f"{cfg.name:16} {ideal:8d} {cells[0]:>12} {cells[1]:>12} {cells[2]:>12} "
              f"{cells[3]:>18} {eq[0]:7.3f} at {eq[1]:.2f}")
    print(json.dumps(dict(rows=out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Ground truth for reports and tests (never visible to agents): coverage and ideal counts.

* ``coverage_fraction(wm, positions, rv)``: the fraction of the free area (cells of a raster
  of side <= rv/20, tested at their centres) that lies within rv of some robot with a clear
  line of sight (walls occlude; robots do not).
* ``ideal_count(wm, d)``: the thesis's baseline, a triangular tessellation of spacing d:
  ``area_formula`` = A_free / (sqrt(3)/2 d^2), and the lattice point counts over a few
  offsets and rotations: ``lattice_points`` = the fewest points in free space of any tried
  placement (the fewest robots an ideal lattice needs), ``lattice_points_max`` = the most.
  Reports use it at d = rv and at d = the swarm's mean edge length.
* ``euler_bound(wm, rv)``: a lower bound on the robots of any certifiable swarm (Euler's
  relation for a triangulation whose Rips triangles tile the free area, walls included);
  ``default_robots_max(wm, rv)``: ``run``'s default cap, a multiple of it.
* ``reachable_uncovered(wm, covered, raster, source, radius, rv)``: the free area a robot's
  body can reach from the source, beyond 0.5 rv from any wall, that no robot covers (the
  ground-truth test of a certificate).

World frame, metres. Pure functions over numpy; the map's rasters are cached on it.
"""
from __future__ import annotations

import math

import numpy as np

from .maps import WorldMap, segments_intersect


def coverage_fraction(wm: WorldMap, positions, rv: float, cell: float | None = None,
                      return_mask: bool = False):
    """Fraction of free cells within rv of a robot with line of sight (0..1).

    positions: (n, 2) world frame (m). cell: raster side, at most rv/20 (default rv/20).
    With return_mask, returns (fraction, covered bool raster, Raster).
    """
    cell = rv / 20.0 if cell is None else min(float(cell), rv / 20.0)
    r = wm.raster(cell)
    free = r.free
    ny, nx = free.shape
    covered = np.zeros_like(free)
    pos = np.asarray(positions, float).reshape(-1, 2)
    grid = wm.segment_grid(rv, rv * (1 + 1e-9) + 1e-9) if len(wm.walls) else None
    k = int(math.ceil(rv / cell)) + 1
    rv2 = rv * rv
    for p in pos:
        cx = int(math.floor((p[0] - r.x0) / cell))
        cy = int(math.floor((p[1] - r.y0) / cell))
        i0, i1 = max(0, cx - k), min(nx, cx + k + 1)
        j0, j1 = max(0, cy - k), min(ny, cy + k + 1)
        if i0 >= i1 or j0 >= j1:
            continue
        jj, ii = np.mgrid[j0:j1, i0:i1]
        xs = r.x0 + (ii + 0.5) * cell
        ys = r.y0 + (jj + 0.5) * cell
        todo = free[j0:j1, i0:i1] & ~covered[j0:j1, i0:i1]
        todo &= (xs - p[0]) ** 2 + (ys - p[1]) ** 2 <= rv2
        if not todo.any():
            continue
        cj, ci = np.nonzero(todo)
        tgt = np.stack([xs[cj, ci], ys[cj, ci]], 1)
        if grid is not None:
            _, w = grid.candidates(p[None, :])
            if len(w):
                wl = grid.walls[w]
                src = np.broadcast_to(p, tgt.shape)
                hit = segments_intersect(src[:, None, :], tgt[:, None, :],
                                         wl[None, :, 0:2], wl[None, :, 2:4]).any(1)
                cj, ci = cj[~hit], ci[~hit]
        covered[j0 + cj, i0 + ci] = True
    nfree = int(free.sum())
    frac = float(covered.sum()) / nfree if nfree else 0.0
    if return_mask:
        return frac, covered, r
    return frac


TRI = math.sqrt(3) / 2
ROBOTS_MAX_PER_BOUND = 3.0     # run's default robots_max = ceil(this x the Euler bound)


def ring_lengths(wm: WorldMap) -> list[float]:
    """Length (m) of the boundary ring and of each obstacle ring."""
    out = []
    for ring in [wm.boundary] + list(wm.obstacles):
        ring = np.asarray(ring, float)
        out.append(float(np.sum(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1))))
    return out


def euler_bound(wm: WorldMap, rv: float) -> dict:
    """Lower bound on the robots of a swarm whose Rips triangles tile the free area.

    Certified coverage means the free area is tiled by Rips triangles (edges <= rv, so area
    <= sqrt(3)/4 rv^2 each) whose outer edges run along every wall (robots touching the
    walls, at most rv apart, at least 3 around an obstacle). A planar triangulation of a
    region with h holes, n vertices and b of them on its boundary has T = 2n - b - 2 + 2h
    triangles, so n >= (A_free / (sqrt(3)/4 rv^2) + b + 2 - 2h) / 2 with b >= sum over
    walls of max(3, ceil(length / rv)). Returns robots, boundary_vertices, holes, triangles.
    """
    b = sum(max(3, math.ceil(length / rv - 1e-9)) for length in ring_lengths(wm))
    h = len(wm.obstacles)
    triangles = wm.free_area / (TRI / 2 * rv * rv)
    return dict(robots=max(1, math.ceil((triangles + b + 2 - 2 * h) / 2)), boundary_vertices=b,
                holes=h, triangles=triangles)


def default_robots_max(wm: WorldMap, rv: float, per_bound: float = ROBOTS_MAX_PER_BOUND) -> int:
    """``run``'s default robots_max: ceil(per_bound x the Euler bound), so the cap grows with
    the map (a fixed number stopped a 20 m x 12 m hall short)."""
    return int(math.ceil(per_bound * euler_bound(wm, rv)["robots"]))


def reachable_uncovered(wm: WorldMap, covered: np.ndarray, r, source, radius: float,
                        rv: float, wall_margin_rv: float = 0.5) -> dict:
    """Free area (m^2) that no robot covers although a robot's body could reach it from the
    source, beyond ``wall_margin_rv`` x rv from every wall (issue 21's false-certificate
    test). ``covered``, ``r``: the mask and Raster of :func:`coverage_fraction` (with
    ``return_mask``). Walls are dilated by the robot radius, the body's free space is
    flood-filled from the source cell, and cells within 0.5 rv of a wall are masked out
    (grooves narrower than rv are the method's stated blind spots).

    Returns uncovered_reachable_m2, reachable_m2 and the uncovered cells' bounding box
    (``where``: [x0, y0, x1, y1] or None).
    """
    from scipy import ndimage
    cell = r.cell
    free = r.free
    # distance (m) of each free cell centre to the nearest non-free cell (walls, outside)
    dist = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1] * cell
    body = dist >= max(radius, 0.5 * cell)
    sx = int(math.floor((float(source[0]) - r.x0) / cell))
    sy = int(math.floor((float(source[1]) - r.y0) / cell))
    ny, nx = free.shape
    out = dict(uncovered_reachable_m2=0.0, reachable_m2=0.0, where=None)
    if not (0 <= sx < nx and 0 <= sy < ny):
        return out
    if not body[sy, sx]:  # the source hugs a wall: start from the nearest body cell
        jj, ii = np.nonzero(body)
        if not len(jj):
            return out
        k = int(np.argmin((jj - sy) ** 2 + (ii - sx) ** 2))
        sy, sx = int(jj[k]), int(ii[k])
    lab, _ = ndimage.label(body)
    reach = lab == lab[sy, sx]
    # a body centre reaches its cell; the cells it covers extend radius further, but the
    # check masks 0.5 rv along walls anyway
    interior = reach & (dist > wall_margin_rv * rv)
    miss = interior & ~covered
    area = cell * cell
    out["reachable_m2"] = float(reach.sum() * area)
    out["uncovered_reachable_m2"] = float(miss.sum() * area)
    if miss.any():
        jj, ii = np.nonzero(miss)
        out["where"] = [float(r.x0 + ii.min() * cell), float(r.y0 + jj.min() * cell),
                        float(r.x0 + (ii.max() + 1) * cell), float(r.y0 + (jj.max() + 1) * cell)]
    return out


def lattice(d: float, rotation: float, offset, bounds) -> np.ndarray:
    """Points of a triangular lattice (spacing d, rotated, offset) covering bounds."""
    x0, y0, x1, y1 = bounds
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2]) + np.asarray(offset, float)
    a1 = d * np.array([math.cos(rotation), math.sin(rotation)])
    a2 = d * np.array([math.cos(rotation + math.pi / 3), math.sin(rotation + math.pi / 3)])
    n = int(math.ceil(math.hypot(x1 - x0, y1 - y0) / (d * math.sqrt(3) / 2))) + 2
    i, j = np.mgrid[-n:n + 1, -n:n + 1]
    p = c + i.ravel()[:, None] * a1 + j.ravel()[:, None] * a2
    keep = (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
    return p[keep]


def ideal_count(wm: WorldMap, d: float, *, offsets: int = 4, rotations: int = 6,
                clearance: float = 0.0) -> dict:
    """The ideal triangular-tessellation counts of the free area at spacing d (m).

    Tries offsets x offsets placements within the lattice cell and ``rotations`` angles in
    [0, 60 deg). Lattice points count when they are in free space (with ``clearance`` m to
    every wall). Returns area_formula, lattice_points (fewest), lattice_points_max,
    free_area, d, best_rotation, best_offset.
    """
    if not (d > 0 and math.isfinite(d)):
        raise ValueError(f"ideal_count: spacing d = {d!r} must be a positive number")
    A = wm.free_area
    area_formula = A / (math.sqrt(3) / 2 * d * d)
    bounds = wm.bounds
    best = (None, None, None)
    counts = []
    use_raster = None
    for ri in range(rotations):
        rot = ri * (math.pi / 3) / rotations
        a1 = d * np.array([math.cos(rot), math.sin(rot)])
        a2 = d * np.array([math.cos(rot + math.pi / 3), math.sin(rot + math.pi / 3)])
        for u in range(offsets):
            for v in range(offsets):
                off = (u / offsets) * a1 + (v / offsets) * a2
                p = lattice(d, rot, off, bounds)
                if use_raster is None:
                    use_raster = len(p) * wm.n_vertices > 5e7
                if use_raster:
                    free = _raster_free(wm, p, d / 20.0, clearance)
                else:
                    free = wm.is_free(p, margin=clearance)
                cnt = int(free.sum())
                counts.append(cnt)
                if best[0] is None or cnt < best[0]:
                    best = (cnt, rot, off)
    return {"area_formula": float(area_formula), "lattice_points": int(best[0]),
            "lattice_points_max": int(max(counts)), "free_area": float(A), "d": float(d),
            "best_rotation": float(best[1]), "best_offset": [float(x) for x in best[2]]}


def _raster_free(wm: WorldMap, p: np.ndarray, cell: float, clearance: float) -> np.ndarray:
    """Free test by raster look-up (for huge maps); clearance by a distance transform."""
    r = wm.raster(cell)
    ny, nx = r.free.shape
    ix = np.floor((p[:, 0] - r.x0) / cell).astype(np.int64)
    iy = np.floor((p[:, 1] - r.y0) / cell).astype(np.int64)
    ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    out = np.zeros(len(p), bool)
    mask = r.free
    if clearance > 0:
        from scipy import ndimage
        key = ("edt", float(cell))
        if key not in wm._cache:
            wm._cache[key] = ndimage.distance_transform_edt(np.pad(r.free, 1))[1:-1, 1:-1] * cell
        mask = wm._cache[key] >= clearance
    out[ok] = mask[iy[ok], ix[ok]]
    return out


def mean_edge_length(positions, rv: float, wm: WorldMap | None = None) -> float:
    """Mean length (m) of the visibility graph's edges (pairs within rv, walls occluding)."""
    from .sensing import visible_pairs
    pos = np.asarray(positions, float).reshape(-1, 2)
    grid = wm.segment_grid(rv / 2, rv / 2 * (1 + 1e-9) + 1e-9) if wm is not None else None
    pr = visible_pairs(pos, grid, rv)
    if len(pr) == 0:
        return float("nan")
    return float(np.hypot(*(pos[pr[:, 1]] - pos[pr[:, 0]]).T).mean())

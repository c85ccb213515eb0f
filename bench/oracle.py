"""An independent coverage oracle: geometry and GF(2) from first principles.

It shares no code with ``coordinator/`` or ``world/`` (nothing is imported from them), so
a bug there cannot hide here. From true robot positions and a polygon map it gives:

* ``rips``: the Rips complex with line of sight (edge when the centres are at most rv
  apart and the segment between them crosses no wall; triangles are the 3-cliques);
* ``Raster`` / ``coverage``: raster ground truth of what the robots see, the union over
  robots of (disk of radius rv) intersected with (the robot's line-of-sight region),
  on a grid of ``cell`` metres (2 cm by default), against the free space;
* ``reachable``: the free cells a robot body of radius r can reach from the source
  (walls dilated by r, flood fill from the source's cell);
* ``judge``: the false-certificate test. Uncovered free cells that are reachable and
  farther than ``deep`` (0.5 rv) from every wall are grouped into 8-connected
  components; any component larger than ``min_area`` (0.01 m^2, 25 cells of 2 cm)
  is a hole a certificate must not claim covered;
* ``in_boundary_span`` / ``chain_boundary``: a GF(2) check that a target edge chain is the
  boundary of a set of triangles (own elimination over Python-int bit rows).

A map is an outer boundary polygon plus obstacle polygons, each an (k, 2) array of
vertices in metres (either orientation). Free space is inside the outer polygon and
outside every obstacle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

__all__ = [
    "PolyMap",
    "segments_cross",
    "line_of_sight",
    "rips",
    "Raster",
    "coverage",
    "reachable",
    "judge",
    "Verdict",
    "in_boundary_span",
    "chain_boundary",
]


# ------------------------------------------------------------------------------ map
@dataclass
class PolyMap:
    """Outer boundary polygon and obstacle polygons (metres)."""

    outer: np.ndarray
    holes: list[np.ndarray] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.outer = np.asarray(self.outer, dtype=float).reshape(-1, 2)
        self.holes = [np.asarray(h, dtype=float).reshape(-1, 2) for h in self.holes]

    @property
    def rings(self) -> list[np.ndarray]:
        return [self.outer] + list(self.holes)

    def walls(self) -> np.ndarray:
        """(S, 4) wall segments x0, y0, x1, y1 of every ring."""
        out = [np.hstack([r, np.roll(r, -1, axis=0)]) for r in self.rings]
        return np.vstack(out)

    def contains(self, pts) -> np.ndarray:
        """True for points inside the free space (even-odd rule per ring)."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        inside = _in_ring(pts, self.outer)
        for h in self.holes:
            inside &= ~_in_ring(pts, h)
        return inside

    def wall_distance(self, pts) -> np.ndarray:
        """Euclidean distance from each point to the nearest wall segment."""
        return _dist_to_segments(np.asarray(pts, float).reshape(-1, 2), self.walls())


def _in_ring(pts: np.ndarray, ring: np.ndarray) -> np.ndarray:
    x, y = pts[:, 0:1], pts[:, 1:2]
    a = ring
    b = np.roll(ring, -1, axis=0)
    ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    straddle = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = ax + (y - ay) * (bx - ax) / (by - ay)
    hit = straddle & (x < xc)
    return (hit.sum(axis=1) & 1).astype(bool)


def _dist_to_segments(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """(M,) distance from each point to the nearest of the (S, 4) segments."""
    if segs.shape[0] == 0:
        return np.full(p.shape[0], np.inf)
    a = segs[None, :, 0:2]
    d = segs[None, :, 2:4] - a
    q = p[:, None, :] - a
    L2 = np.maximum((d * d).sum(-1), 1e-18)
    t = np.clip((q * d).sum(-1) / L2, 0.0, 1.0)
    r = q - t[..., None] * d
    return np.sqrt((r * r).sum(-1)).min(axis=1)


def segments_cross(P: np.ndarray, Q: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """(M,) True where segment P[m]-Q[m] meets any wall segment (touching counts)."""
    P = np.asarray(P, float).reshape(-1, 2)
    Q = np.asarray(Q, float).reshape(-1, 2)
    if segs.shape[0] == 0 or P.shape[0] == 0:
        return np.zeros(P.shape[0], dtype=bool)
    ax, ay, bx, by = (segs[None, :, k] for k in range(4))
    px, py = P[:, 0:1], P[:, 1:2]
    qx, qy = Q[:, 0:1], Q[:, 1:2]

    def orient(ux, uy, vx, vy, wx, wy):
        return (vx - ux) * (wy - uy) - (vy - uy) * (wx - ux)

    d1 = orient(ax, ay, bx, by, px, py)
    d2 = orient(ax, ay, bx, by, qx, qy)
    d3 = orient(px, py, qx, qy, ax, ay)
    d4 = orient(px, py, qx, qy, bx, by)
    hit = (d1 * d2 <= 0) & (d3 * d4 <= 0)
    # exactly collinear, disjoint segments give four zeros: not a crossing
    col = (d1 == 0) & (d2 == 0)
    if np.any(col):
        ox = (np.maximum(np.minimum(px, qx), np.minimum(ax, bx)) <= np.minimum(np.maximum(px, qx), np.maximum(ax, bx)))
        oy = (np.maximum(np.minimum(py, qy), np.minimum(ay, by)) <= np.minimum(np.maximum(py, qy), np.maximum(ay, by)))
        hit = np.where(col, ox & oy, hit)
    return hit.any(axis=1)


def line_of_sight(a, b, segs: np.ndarray) -> bool:
    """True when the segment a-b crosses no wall."""
    return not bool(segments_cross(np.asarray(a, float)[None], np.asarray(b, float)[None], segs)[0])


# ------------------------------------------------------------------------ complex
def rips(pts, segs: np.ndarray, rv: float):
    """Rips complex with line of sight over points ``pts`` (n, 2).

    Returns (edges, triangles): sets of sorted index tuples (i < j), (i < j < k).
    """
    pts = np.asarray(pts, float).reshape(-1, 2)
    n = pts.shape[0]
    edges: set[tuple[int, int]] = set()
    if n >= 2:
        ii, jj = np.triu_indices(n, 1)
        d = np.linalg.norm(pts[ii] - pts[jj], axis=1)
        near = d <= rv
        ii, jj = ii[near], jj[near]
        clear = ~segments_cross(pts[ii], pts[jj], segs)
        edges = {(int(a), int(b)) for a, b in zip(ii[clear], jj[clear])}
    adj: list[set[int]] = [set() for _ in range(n)]
    for a, b in edges:
        adj[a].add(b)
        adj[b].add(a)
    tris = set()
    for a, b in edges:
        for c in adj[a] & adj[b]:
            if c > b:
                tris.add((a, b, c))
    return edges, tris


# ------------------------------------------------------------------------- raster
class Raster:
    """A grid of square cells of side ``cell`` over the map's bounding box (plus a
    one-cell border outside), with the free mask and each free cell's clearance (its
    centre's distance to the nearest wall, from the exact segments)."""

    def __init__(self, pm: PolyMap, cell: float = 0.02):
        self.pm = pm
        self.cell = float(cell)
        lo = pm.outer.min(axis=0) - cell
        hi = pm.outer.max(axis=0) + cell
        self.nx = int(math.ceil((hi[0] - lo[0]) / cell))
        self.ny = int(math.ceil((hi[1] - lo[1]) / cell))
        self.origin = lo
        xs = lo[0] + (np.arange(self.nx) + 0.5) * cell
        ys = lo[1] + (np.arange(self.ny) + 0.5) * cell
        self.xs, self.ys = xs, ys
        X, Y = np.meshgrid(xs, ys)   # (ny, nx)
        self.centres = np.stack([X.ravel(), Y.ravel()], 1)
        self.free = pm.contains(self.centres).reshape(self.ny, self.nx)
        self.segs = pm.walls()
        clr = np.zeros(self.ny * self.nx)
        f = self.free.ravel()
        idx = np.nonzero(f)[0]
        for k in range(0, idx.size, 20000):
            sl = idx[k:k + 20000]
            clr[sl] = _dist_to_segments(self.centres[sl], self.segs)
        self.clearance = clr.reshape(self.ny, self.nx)

    @property
    def cell_area(self) -> float:
        return self.cell * self.cell

    def cell_of(self, p) -> tuple[int, int]:
        """(row, col) of the cell holding point p."""
        c = int((p[0] - self.origin[0]) / self.cell)
        r = int((p[1] - self.origin[1]) / self.cell)
        return min(max(r, 0), self.ny - 1), min(max(c, 0), self.nx - 1)


def coverage(ras: Raster, pts, rv: float) -> np.ndarray:
    """(ny, nx) bool: free cells whose centre is within rv of a robot that sees it (the
    segment robot-centre crosses no wall)."""
    cov = np.zeros((ras.ny, ras.nx), dtype=bool)
    segs = ras.segs
    for p in np.asarray(pts, float).reshape(-1, 2):
        c0 = max(int((p[0] - rv - ras.origin[0]) / ras.cell), 0)
        c1 = min(int((p[0] + rv - ras.origin[0]) / ras.cell) + 1, ras.nx)
        r0 = max(int((p[1] - rv - ras.origin[1]) / ras.cell), 0)
        r1 = min(int((p[1] + rv - ras.origin[1]) / ras.cell) + 1, ras.ny)
        if c0 >= c1 or r0 >= r1:
            continue
        X, Y = np.meshgrid(ras.xs[c0:c1], ras.ys[r0:r1])
        inside = ((X - p[0]) ** 2 + (Y - p[1]) ** 2 <= rv * rv) & ras.free[r0:r1, c0:c1]
        inside &= ~cov[r0:r1, c0:c1]
        if not inside.any():
            continue
        # only walls that come within rv of the robot can block its view inside the disk
        near = _dist_to_segments_each(p, segs) <= rv
        rr, cc = np.nonzero(inside)
        q = np.stack([X[rr, cc], Y[rr, cc]], 1)
        seen = np.ones(q.shape[0], dtype=bool)
        if near.any():
            sub = segs[near]
            for k in range(0, q.shape[0], 4000):
                seen[k:k + 4000] = ~segments_cross(np.broadcast_to(p, (min(4000, q.shape[0] - k), 2)),
                                                    q[k:k + 4000], sub)
        cov[r0 + rr[seen], c0 + cc[seen]] = True
    return cov


def _dist_to_segments_each(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    a = segs[:, 0:2]
    d = segs[:, 2:4] - a
    q = p[None, :] - a
    L2 = np.maximum((d * d).sum(-1), 1e-18)
    t = np.clip((q * d).sum(-1) / L2, 0.0, 1.0)
    r = q - t[:, None] * d
    return np.sqrt((r * r).sum(-1))


_EIGHT = np.ones((3, 3), dtype=bool)


def reachable(ras: Raster, source, radius: float) -> np.ndarray:
    """(ny, nx) bool: free cells a robot body of ``radius`` can reach from ``source``
    (cells with clearance > radius, 4-connected to the source's cell)."""
    ok = ras.free & (ras.clearance > radius)
    r, c = ras.cell_of(source)
    if not ok[r, c]:
        return np.zeros_like(ok)
    lab, _ = ndimage.label(ok)
    return lab == lab[r, c]


@dataclass
class Verdict:
    """What the raster says about a swarm.

    free_area, covered_area: m^2 (covered = free and seen). uncovered_reachable: m^2 of
    uncovered cells a robot can reach. holes: list of (area m^2, max clearance m, centroid
    (x, y)) of deep uncovered reachable components above the tolerance, largest first.
    hole_region: (k, 2) cell centres of the uncovered reachable regions holding a hole.
    """

    free_area: float
    covered_area: float
    uncovered_reachable: float
    holes: list
    hole_region: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def covered_fraction(self) -> float:
        return self.covered_area / self.free_area if self.free_area else 1.0

    @property
    def hole_area(self) -> float:
        return float(sum(h[0] for h in self.holes))

    @property
    def fully_covered(self) -> bool:
        """Nothing a robot can reach, beyond ``deep`` from every wall, is uncovered."""
        return not self.holes


def judge(ras: Raster, pts, source, rv: float, radius: float, *, deep: float | None = None,
          min_area: float = 0.01, cov: np.ndarray | None = None) -> Verdict:
    """Raster verdict on robots at ``pts``: uncovered free area that a robot body of
    ``radius`` can reach from ``source`` and that lies farther than ``deep`` (0.5 rv by
    default) from every wall, in 8-connected components larger than ``min_area`` m^2."""
    deep = 0.5 * rv if deep is None else deep
    if cov is None:
        cov = coverage(ras, pts, rv)
    reach = reachable(ras, source, radius)
    unc = reach & ~cov
    bad = unc & (ras.clearance > deep)
    holes = []
    around = np.zeros((0, 2))
    if bad.any():
        lab, k = ndimage.label(bad, structure=_EIGHT)
        sizes = np.bincount(lab.ravel(), minlength=k + 1)
        big = np.zeros(k + 1, dtype=bool)
        for j in np.nonzero(sizes * ras.cell_area > min_area)[0].tolist():
            if j == 0:
                continue
            big[j] = True
            m = lab == j
            rr, cc = np.nonzero(m)
            holes.append((float(sizes[j] * ras.cell_area), float(ras.clearance[m].max()),
                          (float(ras.xs[cc].mean()), float(ras.ys[rr].mean()))))
        holes.sort(key=lambda h: -h[0])
        if holes:
            # the whole uncovered reachable regions that hold a hole (up to the walls)
            lab_u, _ = ndimage.label(unc, structure=_EIGHT)
            keep = np.unique(lab_u[big[lab]])
            rr, cc = np.nonzero(np.isin(lab_u, keep[keep > 0]))
            around = np.stack([ras.xs[cc], ras.ys[rr]], 1)
    return Verdict(free_area=float(ras.free.sum() * ras.cell_area),
                   covered_area=float((cov & ras.free).sum() * ras.cell_area),
                   uncovered_reachable=float(unc.sum() * ras.cell_area), holes=holes,
                   hole_region=around)


# -------------------------------------------------------------------------- GF(2)
def chain_boundary(triangles) -> set[tuple[int, int]]:
    """GF(2) boundary (set of sorted edges) of a set of triangles (vertex triples)."""
    out: set[tuple[int, int]] = set()
    for t in triangles:
        a, b, c = sorted(int(x) for x in t)
        for e in ((a, b), (a, c), (b, c)):
            out ^= {e}
    return out


def in_boundary_span(triangles, target_edges) -> bool:
    """True when the edge set ``target_edges`` is the GF(2) boundary of some set of the
    ``triangles`` (vertex triples). Gaussian elimination over packed bit rows (one per
    triangle, one bit per edge); an empty target is trivially a boundary."""
    tgt = {tuple(sorted((int(a), int(b)))) for a, b in target_edges}
    if not tgt:
        return True
    eid: dict[tuple[int, int], int] = {}
    tri_e = []
    for t in triangles:
        a, b, c = sorted(int(x) for x in t)
        tri_e.append([eid.setdefault(e, len(eid)) for e in ((a, b), (a, c), (b, c))])
    if any(e not in eid for e in tgt):
        return False   # an edge in no triangle cannot be in a boundary
    E = len(eid)
    W = (E + 63) // 64
    M = np.zeros((len(tri_e), W), dtype=np.uint64)
    if tri_e:
        te = np.array(tri_e, dtype=np.int64)
        rows = np.repeat(np.arange(te.shape[0]), 3)
        np.bitwise_xor.at(M, (rows, te.ravel() // 64),
                          np.left_shift(np.uint64(1), (te.ravel() % 64).astype(np.uint64)))
    z = np.zeros(W, dtype=np.uint64)
    for e in tgt:
        k = eid[e]
        z[k // 64] ^= np.uint64(1) << np.uint64(k % 64)
    free = np.ones(M.shape[0], dtype=bool)
    for bit in range(E):
        w, m = bit // 64, np.uint64(1) << np.uint64(bit % 64)
        has = (M[:, w] & m) != 0
        cand = np.nonzero(has & free)[0]
        zb = bool(z[w] & m)
        if cand.size == 0:
            if zb:
                return False     # no row left can clear this bit of z
            continue
        r = int(cand[0])
        free[r] = False
        has[r] = False
        if has.any():
            M[has] ^= M[r]
        if zb:
            z ^= M[r]
    return not z.any()

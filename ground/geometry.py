"""Plane geometry written once: the world, the hardware bridge and the scene exports use it.

A flat polygon is ``[x0, y0, x1, y1, ...]`` as the wire's WorldInfo carries it. Walls are
segments as rows ``x0, y0, x1, y1`` of an (E, 4) float array; a ring is a closed
polygon given as its vertices ``[[x, y], ...]`` (the last vertex joins the first).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Iterable, Sequence

if TYPE_CHECKING:  # numpy is imported by the array functions only (see ground/__init__.py)
    import numpy as np

__all__ = ["edge_distance", "flat_to_points", "in_lenses", "lens_radii", "lens_reach",
           "point_in_polygon", "rings_to_segments", "signed_area"]


def flat_to_points(flat: Sequence[float]) -> tuple[tuple[float, float], ...]:
    """A flat ``[x0, y0, x1, y1, ...]`` list (a WorldInfo polygon) as ``((x0, y0), (x1, y1),
    ...)`` of floats; an odd last value is left out."""
    return tuple((float(flat[k]), float(flat[k + 1])) for k in range(0, len(flat) - 1, 2))


def rings_to_segments(rings: Iterable[Sequence[Sequence[float]]]) -> np.ndarray:
    """Every edge of every closed ring as an (E, 4) array of x0, y0, x1, y1, ring by ring in
    vertex order; rings of fewer than two vertices and zero-length edges (a repeated
    vertex) are left out. A C-contiguous float array, (0, 4) when nothing is left."""
    import numpy as np
    segs = []
    for ring in rings:
        pts = np.asarray(ring, float).reshape(-1, 2)
        if len(pts) >= 2:
            segs.append(np.concatenate([pts, np.roll(pts, -1, axis=0)], 1))
    if not segs:
        return np.zeros((0, 4))
    w = np.concatenate(segs, 0)
    keep = (w[:, 0] != w[:, 2]) | (w[:, 1] != w[:, 3])
    return np.ascontiguousarray(w[keep])


# scalar forms, pure Python: one point against one polygon (the bridge's geofence at its
# command rate, config checks). world/maps.py keeps the vectorised forms for rasters.

def signed_area(pts: Sequence[Sequence[float]]) -> float:
    """Shoelace area of the closed ring ``pts`` (m^2): positive counter-clockwise."""
    s = 0.0
    n = len(pts)
    for k in range(n):
        x0, y0 = pts[k]
        x1, y1 = pts[(k + 1) % n]
        s += x0 * y1 - x1 * y0
    return 0.5 * s


def point_in_polygon(x: float, y: float, poly: Sequence[Sequence[float]]) -> bool:
    """Even-odd rule; points exactly on an edge may fall either way."""
    inside = False
    n = len(poly)
    for i in range(n):
        x1, y1 = poly[i]
        x2, y2 = poly[(i + 1) % n]
        if (y1 > y) != (y2 > y):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
            if x < xc:
                inside = not inside
    return inside


def edge_distance(x: float, y: float, poly: Sequence[Sequence[float]]) -> float:
    """Distance (m) from (x, y) to the nearest edge of the closed ring ``poly``."""
    best = math.inf
    n = len(poly)
    for i in range(n):
        x1, y1 = poly[i]
        x2, y2 = poly[(i + 1) % n]
        dx, dy = x2 - x1, y2 - y1
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((x - x1) * dx + (y - y1) * dy) / L2))
        best = min(best, math.hypot(x - (x1 + t * dx), y - (y1 + t * dy)))
    return best


# ----------------------------------------------------------------------- lenses at a vertex
def _seg_dist2(x: float, y: float, px: float, py: float) -> float:
    """Squared distance from (x, y) to the segment from the origin to (px, py)."""
    L2 = px * px + py * py
    t = 0.0 if L2 < 1e-24 else min(1.0, max(0.0, (x * px + y * py) / L2))
    return (x - t * px) ** 2 + (y - t * py) ** 2


def lens_radii(q: tuple[float, float], depth: float,
               others: Iterable[tuple[float, float]]) -> list[tuple[float, float, float]]:
    """The lenses at a vertex (the origin) whose edge to ``q`` has the lens ``depth``: every
    point within ``depth`` of the edge is within sqrt(depth^2 + |q|^2 / 4) of one of its ends
    (the reach). A segment from the origin to a point p of ``others`` |p| = L long keeps that
    guarantee within sqrt(reach^2 - L^2 / 4) of it (none when that is not positive).
    Returns (px, py, radius) per lens, the edge's first; units are the points'."""
    reach2 = depth * depth + 0.25 * (q[0] * q[0] + q[1] * q[1])
    out = [(float(q[0]), float(q[1]), float(depth))]
    for px, py in others:
        L2 = px * px + py * py
        h2 = reach2 - 0.25 * L2
        if h2 > 0.0 and L2 > 1e-24:
            out.append((float(px), float(py), math.sqrt(h2)))
    return out


def in_lenses(x: float, y: float, lenses: Sequence[tuple[float, float, float]]) -> bool:
    """Whether (x, y) lies in one of ``lenses`` (:func:`lens_radii`). Each lens is convex and
    holds the origin, so their union is star-shaped from it: a closed curve in the union
    encloses only points of the union."""
    return any(_seg_dist2(x, y, px, py) <= h * h for px, py, h in lenses)


def lens_reach(theta: float, lenses: Sequence[tuple[float, float, float]],
               cap: float = math.inf) -> float:
    """How far (at most ``cap``) a ray from the origin along ``theta`` (rad) stays in the
    union of ``lenses``: the ray meets each convex lens in an interval from the origin, so
    the union's is the longest of them (bisection on the convex distance, to 1e-6 of the
    points' unit)."""
    ux, uy = math.cos(theta), math.sin(theta)
    best = 0.0
    for px, py, h in lenses:
        hi = math.hypot(px, py) + h + 1e-9         # beyond the lens
        if min(hi, cap) <= best:
            continue
        if _seg_dist2(min(hi, cap) * ux, min(hi, cap) * uy, px, py) <= h * h:
            best = min(hi, cap)
            continue
        lo, up = 0.0, min(hi, cap)
        while up - lo > 1e-6:
            mid = 0.5 * (lo + up)
            if _seg_dist2(mid * ux, mid * uy, px, py) <= h * h:
                lo = mid
            else:
                up = mid
        best = max(best, lo)
    return best

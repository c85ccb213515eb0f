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

__all__ = ["edge_distance", "flat_to_points", "point_in_polygon", "rings_to_segments",
           "signed_area"]


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

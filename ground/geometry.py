"""Plane geometry written once: the world, the hardware bridge and the scene exports use it.

A flat polygon is ``[x0, y0, x1, y1, ...]`` as the wire's WorldInfo carries it. Walls are
segments as rows ``x0, y0, x1, y1`` of an (E, 4) float array; a ring is a closed
polygon given as its vertices ``[[x, y], ...]`` (the last vertex joins the first).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Iterable, Sequence

if TYPE_CHECKING:  # numpy is imported by the array functions only (see ground/__init__.py)
    import numpy as np

__all__ = ["flat_to_points", "rings_to_segments"]


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

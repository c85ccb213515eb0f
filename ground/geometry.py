"""Plane geometry shared by the world and the hardware bridge, written once.

Walls are segments as rows ``x0, y0, x1, y1`` of an (E, 4) float array; a ring is a closed
polygon given as its vertices ``[[x, y], ...]`` (the last vertex joins the first).
"""
from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

__all__ = ["rings_to_segments"]


def rings_to_segments(rings: Iterable[Sequence[Sequence[float]]]) -> np.ndarray:
    """Every edge of every closed ring as an (E, 4) array of x0, y0, x1, y1, ring by ring in
    vertex order; rings of fewer than two vertices and zero-length edges (a repeated
    vertex) are left out. A C-contiguous float array, (0, 4) when nothing is left."""
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

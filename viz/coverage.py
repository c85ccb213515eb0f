"""Coverage of the free space by the robots: a pluggable measure for plots and the live view.

``coverage_measure(kind)`` returns ``(fn, label)`` with ``fn(info, truth) -> fraction in
[0, 1] or None``:
  * ``"groundtruth"``: ``world.groundtruth.coverage_fraction``: cells within rv of a robot
    with a clear line of sight (walls occlude), over the map rebuilt from the WorldInfo;
  * ``"disks"``: the fraction of free cells within rv of some robot, on a raster, ignoring
    line of sight (an upper bound on the true coverage);
  * ``"auto"``: groundtruth if available, else disks; ``"none"``: never measured.

All positions are world-frame metres; ``info`` is a WorldInfo, ``truth`` a Truth.
"""
from __future__ import annotations

import importlib
import logging
from functools import lru_cache
from typing import Callable

import numpy as np

log = logging.getLogger("swarmcover.viz")

CoverageFn = Callable[[object, object], "float | None"]
KINDS = ("auto", "groundtruth", "disks", "none")


def polygon_xy(flat) -> np.ndarray:
    """A flat [x0, y0, x1, y1, ...] list as an (n, 2) array."""
    a = np.asarray(flat, dtype=float)
    return a.reshape(-1, 2) if a.size else np.zeros((0, 2))


def map_bounds(info, margin: float = 0.0) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the boundary and obstacles, widened by ``margin`` (m)."""
    pts = [polygon_xy(info.boundary)] + [polygon_xy(p) for p in info.obstacles]
    pts = [p for p in pts if len(p)]
    if not pts:
        return (-margin - 1, 1 + margin, -margin - 1, 1 + margin)
    a = np.vstack(pts)
    return (a[:, 0].min() - margin, a[:, 0].max() + margin,
            a[:, 1].min() - margin, a[:, 1].max() + margin)


@lru_cache(maxsize=8)
def _free_cells(boundary: tuple, obstacles: tuple, res: float) -> tuple[np.ndarray, float]:
    """Centres of free raster cells (m) and the area of one cell (m^2)."""
    from matplotlib.path import Path as MPath
    b = polygon_xy(boundary)
    allpts = [b] + [polygon_xy(o) for o in obstacles]
    allpts = np.vstack([p for p in allpts if len(p)])
    xmin, ymin = allpts.min(axis=0)
    xmax, ymax = allpts.max(axis=0)
    xs = np.arange(xmin + res / 2, xmax, res)
    ys = np.arange(ymin + res / 2, ymax, res)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    free = MPath(b).contains_points(pts) if len(b) >= 3 else np.ones(len(pts), bool)
    for o in obstacles:
        o = polygon_xy(o)
        if len(o) >= 3:
            free &= ~MPath(o).contains_points(pts)
    return pts[free], res * res


def disk_coverage(info, xs, ys, *, res: float | None = None) -> float | None:
    """Fraction of the free space within ``info.rv`` of a robot at (xs, ys), no line of sight.

    res: raster cell size (m), default min(rv/6, largest map side/250).
    """
    if len(polygon_xy(info.boundary)) < 3:
        return None
    x0, x1, y0, y1 = map_bounds(info)
    if res is None:
        res = max(1e-3, min(info.rv / 6.0, max(x1 - x0, y1 - y0) / 250.0))
    cells, _ = _free_cells(tuple(info.boundary), tuple(tuple(o) for o in info.obstacles),
                           float(res))
    if len(cells) == 0:
        return None
    xs = np.asarray(xs, float)
    ys = np.asarray(ys, float)
    if xs.size == 0:
        return 0.0
    from scipy.spatial import cKDTree
    d, _ = cKDTree(np.column_stack([xs, ys])).query(cells, k=1, distance_upper_bound=info.rv)
    return float(np.count_nonzero(np.isfinite(d)) / len(cells))


def _disks(info, truth) -> float | None:
    if truth is None:
        return None
    return disk_coverage(info, truth.x, truth.y)


@lru_cache(maxsize=8)
def _world_map(name: str, boundary: tuple, obstacles: tuple, sources: tuple):
    """world.maps.WorldMap of a WorldInfo (cached: it caches its rasters)."""
    from swarmcover.world.maps import WorldMap
    return WorldMap(name=name, boundary=polygon_xy(boundary),
                    obstacles=[polygon_xy(o) for o in obstacles],
                    sources=np.asarray(sources, float).reshape(-1, 3))


def _groundtruth_fn() -> CoverageFn | None:
    """world.groundtruth.coverage_fraction(wm, positions, rv) adapted to (info, truth)."""
    try:
        gt = importlib.import_module("swarmcover.world.groundtruth")
        importlib.import_module("swarmcover.world.maps")
    except Exception:
        return None
    fn = getattr(gt, "coverage_fraction", None)
    if not callable(fn):
        return None
    failed: list = []

    def measure(info, truth):
        if truth is None or failed or len(polygon_xy(info.boundary)) < 3:
            return None
        try:
            wm = _world_map(info.name, tuple(info.boundary),
                            tuple(tuple(o) for o in info.obstacles), tuple(info.sources))
            pos = np.column_stack([np.asarray(truth.x, float), np.asarray(truth.y, float)])
            return float(fn(wm, pos.reshape(-1, 2), float(info.rv)))
        except Exception as e:  # an incompatible or failing measure: say so once, go on
            failed.append(e)
            log.warning("world.groundtruth.coverage_fraction failed (%s); coverage not measured", e)
            return None
    return measure


def coverage_measure(kind: str = "auto") -> tuple[CoverageFn, str]:
    """The coverage function for ``kind`` (one of KINDS) and a label for axes and headers."""
    if kind not in KINDS:
        raise ValueError(f"coverage kind {kind!r}: expected one of {', '.join(KINDS)}")
    if kind in ("auto", "groundtruth"):
        fn = _groundtruth_fn()
        if fn is not None:
            return fn, "coverage (ground truth)"
        if kind == "groundtruth":
            raise ValueError("coverage kind 'groundtruth': world.groundtruth.coverage_fraction "
                             "is not available")
    if kind == "none":
        return (lambda info, truth: None), "coverage (not measured)"
    return _disks, "coverage (rv disks, no line of sight)"

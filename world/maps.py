"""World maps: polygons, wall segments, free space, and the ROS map_server loader.

A :class:`WorldMap` is one outer ``boundary`` polygon plus ``obstacles`` polygons (world
frame, m). Free space = inside the boundary and outside every obstacle. Every polygon edge is
a wall segment (``walls``: (E, 4) rows x0, y0, x1, y1); walls are what robots collide with
and what blocks lines of sight.

ROS map_server maps (YAML + PGM/PNG/...) are turned into the same geometry: the free cells
(unknown counts as not free) of the free region holding the first source (or the largest
one) are traced with marching squares (contourpy), its outer contour becomes the boundary,
and the non-free islands inside it become obstacles; tiny islands are dropped, contours are
simplified (Douglas-Peucker) and the vertex count is capped. The image is framed by a
non-free border first, so maps whose border is open still close.

Pure functions, no I/O besides reading map files. Entry point for other components:
``build_map(cfg) -> WorldMap`` (or ``map_from_path(config_path)``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmcover.ground.geometry import rings_to_segments

from .config import ConfigError, RunConfig, load_config

# Size limits, checked before anything is allocated. Ground truth rasters the map at rv/20
# (400 cells per rv^2, a few bytes each, several arrays) and sensing grids it at rv/2:
# a 200 rv x 200 rv box is 16 M coverage cells. A 10^6 m map used to allocate 4.7 GB and die.
MAX_MAP_SIDE_RV = 2_000.0          # longest side of the map's bounding box, in rv
MAX_MAP_AREA_RV2 = 40_000.0        # bounding-box area, in rv^2 (e.g. 200 m x 200 m at rv 1 m)
MAX_IMAGE_PIXELS = 50_000_000      # ROS map image (its float copy is 8 bytes a pixel)


def check_extent(file: str, section: str, fieldname: str, value, bounds, rv: float) -> None:
    """Refuse a map whose bounding box (x0, y0, x1, y1) exceeds the size limits."""
    x0, y0, x1, y1 = (float(v) for v in bounds)
    w, h = x1 - x0, y1 - y0
    if not all(math.isfinite(v) for v in (w, h)):
        raise ConfigError(file, section, fieldname, value, "map extent is not finite")
    if max(w, h) > MAX_MAP_SIDE_RV * rv:
        raise ConfigError(file, section, fieldname, value,
                          f"map is {w:.6g} m x {h:.6g} m: a side is longer than the limit of "
                          f"{MAX_MAP_SIDE_RV:g} rv ({MAX_MAP_SIDE_RV * rv:g} m at rv = {rv:g} m)")
    if w * h > MAX_MAP_AREA_RV2 * rv * rv:
        raise ConfigError(file, section, fieldname, value,
                          f"map is {w:.6g} m x {h:.6g} m: its bounding box exceeds the limit of "
                          f"{MAX_MAP_AREA_RV2:g} rv^2 ({MAX_MAP_AREA_RV2 * rv * rv:g} m^2 at "
                          f"rv = {rv:g} m)")


def ros_image_size(meta) -> tuple[int, int]:
    """(width, height) of a ROS map image from its header alone; refuses images over
    MAX_IMAGE_PIXELS (or that PIL calls a decompression bomb) before any pixel is read."""
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(meta.image) as im:
            w, h = im.size
    except Image.DecompressionBombError as e:
        raise ConfigError(meta.yaml_path, "ros_map", "image", meta.image,
                          f"image too large (limit {MAX_IMAGE_PIXELS:,} pixels): {e}") from None
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise ConfigError(meta.yaml_path, "ros_map", "image", meta.image,
                          f"cannot read image: {e}") from None
    if w * h > MAX_IMAGE_PIXELS:
        raise ConfigError(meta.yaml_path, "ros_map", "image", meta.image,
                          f"image is {w} x {h} pixels: more than the limit of "
                          f"{MAX_IMAGE_PIXELS:,} pixels")
    return w, h

# --------------------------------------------------------------------------- geometry


def polygon_area(pts) -> float:
    """Unsigned shoelace area of a polygon (n, 2)."""
    p = np.asarray(pts, float)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def circle_polygon(center, radius: float, n: int = 32) -> np.ndarray:
    """An n-gon inscribed in a circle, (n, 2)."""
    a = np.arange(n) * (2 * math.pi / n)
    return np.stack([center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)], 1)


def points_in_polygon(points, poly) -> np.ndarray:
    """Boolean mask: which points (n, 2) lie inside the polygon (m, 2) (even-odd rule)."""
    from matplotlib.path import Path as MplPath
    pts = np.asarray(points, float).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0, bool)
    return MplPath(np.asarray(poly, float)).contains_points(pts)


def point_segment_distance(points, walls) -> np.ndarray:
    """Distance from each point (n, 2) to each segment (E, 4): (n, E)."""
    p = np.asarray(points, float)[:, None, :]
    a = walls[None, :, 0:2]
    d = walls[None, :, 2:4] - a
    dd = np.maximum((d * d).sum(-1), 1e-300)
    t = np.clip(((p - a) * d).sum(-1) / dd, 0.0, 1.0)
    c = a + t[..., None] * d
    return np.sqrt(((p - c) ** 2).sum(-1))


def segments_intersect(p0, p1, q0, q1) -> np.ndarray:
    """Elementwise: does segment p0-p1 meet segment q0-q1 (touching counts)? Arrays (..., 2)."""
    r = p1 - p0
    s = q1 - q0
    d1 = s[..., 0] * (p0[..., 1] - q0[..., 1]) - s[..., 1] * (p0[..., 0] - q0[..., 0])
    d2 = s[..., 0] * (p1[..., 1] - q0[..., 1]) - s[..., 1] * (p1[..., 0] - q0[..., 0])
    d3 = r[..., 0] * (q0[..., 1] - p0[..., 1]) - r[..., 1] * (q0[..., 0] - p0[..., 0])
    d4 = r[..., 0] * (q1[..., 1] - p0[..., 1]) - r[..., 1] * (q1[..., 0] - p0[..., 0])
    return (d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == 0) & (d2 == 0))


def ray_lengths(origins, dirs, walls, cap: float, chunk: int = 1 << 21) -> np.ndarray:
    """How far (m) each ray runs from ``origins`` (n, 2) along the unit ``dirs`` (n, 2)
    before it meets a segment of ``walls`` (E, 4), at most ``cap``: (n,)."""
    o = np.asarray(origins, float).reshape(-1, 2)
    d = np.asarray(dirs, float).reshape(-1, 2)
    out = np.full(len(o), float(cap))
    if len(walls) == 0 or not len(out):
        return out
    a = walls[None, :, 0:2]
    s = walls[None, :, 2:4] - a
    step = max(1, chunk // len(walls))
    for k in range(0, len(o), step):
        ok, dk = o[k:k + step, None, :], d[k:k + step, None, :]
        den = dk[..., 0] * s[..., 1] - dk[..., 1] * s[..., 0]         # cross(d, s)
        ao = a - ok
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (ao[..., 0] * s[..., 1] - ao[..., 1] * s[..., 0]) / den  # along the ray
            u = (ao[..., 0] * dk[..., 1] - ao[..., 1] * dk[..., 0]) / den  # along the wall
        hit = (np.abs(den) > 1e-12) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
        out[k:k + step] = np.minimum(out[k:k + step], np.where(hit, t, np.inf).min(axis=1))
    return out


# --------------------------------------------------------------------------- wall index

class SegmentGrid:
    """Uniform grid over wall segments for vectorised candidate look-ups.

    Cell (ix, iy) lists the walls that meet its box grown by ``margin`` on every side, so a
    query point in a cell gets every wall within ``margin`` of it, and a segment of length
    <= 2*margin whose midpoint is in the cell gets every wall it can cross.
    """

    def __init__(self, walls: np.ndarray, bounds, cell: float, margin: float):
        self.walls = np.asarray(walls, float).reshape(-1, 4)
        self.cell = float(cell)
        self.margin = float(margin)
        x0, y0, x1, y1 = bounds
        self.x0, self.y0 = x0 - margin, y0 - margin
        self.nx = max(1, int(math.ceil((x1 - x0 + 2 * margin) / cell)))
        self.ny = max(1, int(math.ceil((y1 - y0 + 2 * margin) / cell)))
        w = self.walls
        if len(w) == 0:
            self.start = np.zeros(self.nx * self.ny + 1, np.int64)
            self.flat = np.zeros(0, np.int64)
            return
        lo = np.minimum(w[:, 0:2], w[:, 2:4]) - margin
        hi = np.maximum(w[:, 0:2], w[:, 2:4]) + margin
        ix0 = np.clip(((lo[:, 0] - self.x0) // cell).astype(np.int64), 0, self.nx - 1)
        iy0 = np.clip(((lo[:, 1] - self.y0) // cell).astype(np.int64), 0, self.ny - 1)
        ix1 = np.clip(((hi[:, 0] - self.x0) // cell).astype(np.int64), 0, self.nx - 1)
        iy1 = np.clip(((hi[:, 1] - self.y0) // cell).astype(np.int64), 0, self.ny - 1)
        wx, wy = ix1 - ix0 + 1, iy1 - iy0 + 1
        cnt = wx * wy
        widx = np.repeat(np.arange(len(w)), cnt)
        off = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        cx = ix0[widx] + off % wx[widx]
        cy = iy0[widx] + off // wx[widx]
        # keep (wall, cell) pairs whose segment really meets the grown cell box
        bx0 = self.x0 + cx * cell - margin
        by0 = self.y0 + cy * cell - margin
        keep = _segment_meets_box(w[widx], bx0, by0, bx0 + cell + 2 * margin,
                                  by0 + cell + 2 * margin)
        widx, cid = widx[keep], (cy * self.nx + cx)[keep]
        order = np.argsort(cid, kind="stable")
        self.flat = widx[order]
        self.start = np.zeros(self.nx * self.ny + 1, np.int64)
        np.cumsum(np.bincount(cid, minlength=self.nx * self.ny), out=self.start[1:])

    def cells_of(self, points) -> np.ndarray:
        p = np.asarray(points, float).reshape(-1, 2)
        ix = np.clip(((p[:, 0] - self.x0) // self.cell).astype(np.int64), 0, self.nx - 1)
        iy = np.clip(((p[:, 1] - self.y0) // self.cell).astype(np.int64), 0, self.ny - 1)
        return iy * self.nx + ix

    def candidates(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(query index, wall index) pairs: walls near each query point."""
        cid = self.cells_of(points)
        s = self.start[cid]
        cnt = self.start[cid + 1] - s
        total = int(cnt.sum())
        q = np.repeat(np.arange(len(cid)), cnt)
        off = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        return q, self.flat[np.repeat(s, cnt) + off]


def _segment_meets_box(w, bx0, by0, bx1, by1) -> np.ndarray:
    """Liang-Barsky: does each segment w (n, 4) meet its box (arrays of n)?"""
    x0, y0 = w[:, 0], w[:, 1]
    dx, dy = w[:, 2] - x0, w[:, 3] - y0
    t0 = np.zeros(len(w))
    t1 = np.ones(len(w))
    ok = np.ones(len(w), bool)
    for p, q in ((-dx, x0 - bx0), (dx, bx1 - x0), (-dy, y0 - by0), (dy, by1 - y0)):
        zero = p == 0
        ok &= ~(zero & (q < 0))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(zero, 0.0, q / np.where(zero, 1.0, p))
        neg = (p < 0) & ~zero
        pos = (p > 0) & ~zero
        t0 = np.where(neg, np.maximum(t0, r), t0)
        t1 = np.where(pos, np.minimum(t1, r), t1)
    return ok & (t0 <= t1)


# --------------------------------------------------------------------------- rasters

@dataclass
class Raster:
    """Cell-centre raster: cell (iy, ix) has centre (x0 + (ix+.5)*cell, y0 + (iy+.5)*cell)."""
    x0: float
    y0: float
    cell: float
    free: np.ndarray  # bool (ny, nx)

    @property
    def shape(self):
        return self.free.shape

    def centres(self, iy, ix) -> np.ndarray:
        return np.stack([self.x0 + (ix + 0.5) * self.cell, self.y0 + (iy + 0.5) * self.cell], -1)


def fill_ring(ring, x0: float, y0: float, cell: float, nx: int, ny: int) -> np.ndarray:
    """Even-odd scanline fill of one closed ring at cell centres: bool (ny, nx)."""
    r = np.asarray(ring, float)
    a, b = r, np.roll(r, -1, axis=0)
    ya = (a[:, 1] - y0) / cell - 0.5   # in row-centre units
    yb = (b[:, 1] - y0) / cell - 0.5
    lo, hi = np.minimum(ya, yb), np.maximum(ya, yb)
    # rows j with lo <= j < hi (half-open: each vertex counted once)
    j0 = np.clip(np.ceil(lo).astype(np.int64), 0, ny)
    j1 = np.clip(np.ceil(hi).astype(np.int64), 0, ny)
    cnt = np.maximum(j1 - j0, 0)
    mask = np.zeros((ny, nx + 1), np.int32)
    if cnt.sum() == 0:
        return mask[:, :nx].astype(bool)
    e = np.repeat(np.arange(len(r)), cnt)
    j = j0[e] + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    t = (j - ya[e]) / (yb[e] - ya[e])
    xa = (a[e, 0] - x0) / cell - 0.5
    xb = (b[e, 0] - x0) / cell - 0.5
    xc = xa + t * (xb - xa)
    col = np.clip(np.ceil(xc).astype(np.int64), 0, nx)
    np.add.at(mask, (j, col), 1)
    return (np.cumsum(mask, axis=1)[:, :nx] % 2).astype(bool)


# --------------------------------------------------------------------------- world map

@dataclass(eq=False)
class WorldMap:
    """Boundary polygon (k, 2), obstacle polygons, sources (s, 3) = x, y, theta (world frame).

    ``obstacles_disjoint``: obstacles are known not to overlap each other or the boundary
    (then the free area is exact: boundary area minus obstacle areas).
    """
    name: str
    boundary: np.ndarray
    obstacles: list
    sources: np.ndarray
    obstacles_disjoint: bool = False
    info: dict = field(default_factory=dict)
    walls: np.ndarray = field(init=False)
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        self.boundary = np.asarray(self.boundary, float).reshape(-1, 2)
        self.obstacles = [np.asarray(o, float).reshape(-1, 2) for o in self.obstacles]
        self.sources = np.asarray(self.sources, float).reshape(-1, 3)
        self.walls = rings_to_segments([self.boundary] + self.obstacles)
        self._obb = np.array([[o[:, 0].min(), o[:, 1].min(), o[:, 0].max(), o[:, 1].max()]
                              for o in self.obstacles]).reshape(-1, 4)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        b = self.boundary
        return (float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 0].max()),
                float(b[:, 1].max()))

    @property
    def n_vertices(self) -> int:
        return len(self.boundary) + sum(len(o) for o in self.obstacles)

    def contains(self, points) -> np.ndarray:
        """Which points (n, 2) are in free space (inside boundary, outside obstacles)."""
        p = np.asarray(points, float).reshape(-1, 2)
        inside = points_in_polygon(p, self.boundary)
        for k, o in enumerate(self.obstacles):
            x0, y0, x1, y1 = self._obb[k]
            near = inside & (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)
            if near.any():
                idx = np.nonzero(near)[0]
                inside[idx[points_in_polygon(p[idx], o)]] = False
        return inside

    def clearance(self, points, chunk: int = 4096) -> np.ndarray:
        """Distance (m) from each point to the nearest wall segment."""
        p = np.asarray(points, float).reshape(-1, 2)
        out = np.full(len(p), np.inf)
        if len(self.walls) == 0:
            return out
        step = max(1, chunk * 64 // max(1, len(self.walls)))
        for k in range(0, len(p), step):
            out[k:k + step] = point_segment_distance(p[k:k + step], self.walls).min(1)
        return out

    def is_free(self, points, margin: float = 0.0) -> np.ndarray:
        """In free space with at least ``margin`` (m) clearance to every wall."""
        p = np.asarray(points, float).reshape(-1, 2)
        ok = self.contains(p)
        if margin > 0 and ok.any():
            idx = np.nonzero(ok)[0]
            ok[idx] = self.clearance(p[idx]) >= margin
        return ok

    def raster(self, cell: float) -> Raster:
        """Free-space raster at cell centres (cached per cell size)."""
        key = ("raster", float(cell))
        if key not in self._cache:
            x0, y0, x1, y1 = self.bounds
            nx = max(1, int(math.ceil((x1 - x0) / cell)))
            ny = max(1, int(math.ceil((y1 - y0) / cell)))
            free = fill_ring(self.boundary, x0, y0, cell, nx, ny)
            for k, o in enumerate(self.obstacles):
                bx0, by0, bx1, by1 = self._obb[k]
                i0 = max(0, int((bx0 - x0) / cell) - 1)
                j0 = max(0, int((by0 - y0) / cell) - 1)
                i1 = min(nx, int(math.ceil((bx1 - x0) / cell)) + 1)
                j1 = min(ny, int(math.ceil((by1 - y0) / cell)) + 1)
                if i1 <= i0 or j1 <= j0:
                    continue
                sub = fill_ring(o, x0 + i0 * cell, y0 + j0 * cell, cell, i1 - i0, j1 - j0)
                free[j0:j1, i0:i1] &= ~sub
            self._cache[key] = Raster(x0, y0, cell, free)
        return self._cache[key]

    def segment_grid(self, cell: float, margin: float) -> SegmentGrid:
        key = ("grid", float(cell), float(margin))
        if key not in self._cache:
            self._cache[key] = SegmentGrid(self.walls, self.bounds, cell, margin)
        return self._cache[key]

    @property
    def free_area(self) -> float:
        """Free area (m^2): exact for disjoint obstacles, else from a fine raster."""
        if "free_area" not in self._cache:
            if self.obstacles_disjoint:
                a = polygon_area(self.boundary) - sum(polygon_area(o) for o in self.obstacles)
            else:
                x0, y0, x1, y1 = self.bounds
                cell = max(math.sqrt((x1 - x0) * (y1 - y0) / 4e6), 1e-4)
                a = float(self.raster(cell).free.sum()) * cell * cell
            self._cache["free_area"] = max(0.0, a)
        return self._cache["free_area"]

    def info_fields(self) -> dict:
        """boundary, obstacles, sources, free_area as WorldInfo wants them (flat lists)."""
        return {"boundary": self.boundary.ravel().tolist(),
                "obstacles": [o.ravel().tolist() for o in self.obstacles],
                "sources": self.sources.ravel().tolist(),
                "free_area": float(self.free_area)}


def _disjoint(boundary: np.ndarray, obstacles: list) -> bool:
    """Obstacles pairwise bbox-disjoint and all their vertices inside the boundary."""
    if not obstacles:
        return True
    bb = np.array([[o[:, 0].min(), o[:, 1].min(), o[:, 0].max(), o[:, 1].max()]
                   for o in obstacles])
    ov = ((bb[:, None, 0] < bb[None, :, 2]) & (bb[None, :, 0] < bb[:, None, 2])
          & (bb[:, None, 1] < bb[None, :, 3]) & (bb[None, :, 1] < bb[:, None, 3]))
    np.fill_diagonal(ov, False)
    if ov.any():
        return False
    allv = np.concatenate(obstacles)
    if not points_in_polygon(allv, boundary).all():
        return False
    # no obstacle edge may cross a boundary edge
    bw = rings_to_segments([boundary])
    ow = rings_to_segments(obstacles)
    if len(bw) * len(ow) > 4_000_000:
        return False
    hit = segments_intersect(ow[:, None, 0:2], ow[:, None, 2:4], bw[None, :, 0:2],
                             bw[None, :, 2:4])
    return not hit.any()


# --------------------------------------------------------------------------- ROS maps

@dataclass(frozen=True)
class RosMapMeta:
    """A ROS map_server YAML: image path (absolute), resolution (m/cell), origin (x, y, yaw)
    of the lower-left pixel, negate, thresholds, mode."""
    yaml_path: str
    image: str
    resolution: float
    origin: tuple
    negate: int = 0
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: str = "trinary"


def read_ros_yaml(path) -> RosMapMeta:
    """Parse and validate a map_server YAML; errors name the file, field and value."""
    import yaml
    path = str(path)
    sec = "ros_map"

    def err(fieldname, value, reason):
        return ConfigError(path, sec, fieldname, value, reason)

    try:
        d = yaml.safe_load(Path(path).read_text())
    except FileNotFoundError:
        raise err("<file>", path, "file not found") from None
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise err("<yaml>", None, f"not valid YAML: {e}") from None
    if not isinstance(d, dict):
        raise err("<yaml>", d, "expected a mapping")
    for k in ("image", "resolution", "origin"):
        if k not in d:
            raise err(k, None, "missing (required by map_server)")
    img = d["image"]
    if not isinstance(img, str) or not img:
        raise err("image", img, "expected an image file name")
    ip = Path(img)
    if not ip.is_absolute():
        ip = Path(path).resolve().parent / ip
    if not ip.is_file():
        raise err("image", img, f"file not found ({ip})")
    res = d["resolution"]
    if isinstance(res, bool) or not isinstance(res, (int, float)) or not (
            math.isfinite(res) and res > 0):
        raise err("resolution", res, "expected a positive number (m per cell)")
    org = d["origin"]
    if (not isinstance(org, (list, tuple)) or len(org) not in (2, 3) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in org)):
        raise err("origin", org, "expected [x, y, yaw] (numbers)")
    org = tuple(float(v) for v in org) + ((0.0,) if len(org) == 2 else ())
    neg = d.get("negate", 0)
    if neg not in (0, 1) or isinstance(neg, float):
        raise err("negate", neg, "expected 0 or 1")
    occ = d.get("occupied_thresh", 0.65)
    fre = d.get("free_thresh", 0.196)
    for k, v in (("occupied_thresh", occ), ("free_thresh", fre)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
            raise err(k, v, "expected a number in [0, 1]")
    if fre > occ:
        raise err("free_thresh", fre, f"greater than occupied_thresh {occ}")
    mode = d.get("mode", "trinary")
    if mode not in ("trinary", "scale", "raw"):
        raise err("mode", mode, "expected trinary, scale or raw")
    return RosMapMeta(path, str(ip), float(res), org, int(neg), float(occ), float(fre), mode)


def write_ros_map(stem, free, resolution: float, origin=(0.0, 0.0)) -> None:
    """Write a ROS map_server map: ``stem``.pgm (254 free, 0 occupied) and ``stem``.yaml.
    ``free``: bool (ny, nx), row 0 the lowest y (the image stores it top row first);
    ``origin``: (x, y) of the lower-left pixel's corner (m); ``resolution`` m per cell."""
    from pathlib import Path
    stem = Path(stem)
    free = np.asarray(free, bool)
    ny, nx = free.shape
    img = np.where(free, 254, 0).astype(np.uint8)[::-1]
    with open(stem.with_suffix(".pgm"), "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (nx, ny))
        f.write(img.tobytes())
    stem.with_suffix(".yaml").write_text(
        f"image: {stem.name}.pgm\nresolution: {resolution}\n"
        f"origin: [{float(origin[0])!r}, {float(origin[1])!r}, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")


def ros_free_mask(meta: RosMapMeta) -> np.ndarray:
    """Free cells of the image, bool (H, W), image row 0 at the top (as stored)."""
    from PIL import Image, UnidentifiedImageError
    ros_image_size(meta)
    try:
        im = Image.open(meta.image)
        im.load()
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as e:
        raise ConfigError(meta.yaml_path, "ros_map", "image", meta.image,
                          f"cannot read image: {e}") from None
    alpha = None
    if im.mode in ("LA", "RGBA", "PA"):
        alpha = np.asarray(im.getchannel("A"), np.float64)
    if im.mode in ("I", "I;16", "I;16B", "F"):
        a = np.asarray(im, np.float64)
        a = 255.0 * a / max(1.0, a.max())
    else:
        a = np.asarray(im.convert("L"), np.float64)
    if meta.mode == "raw":
        # raw: values are occupancy in percent (0 free .. 100 occupied, else unknown)
        free = (a >= 0) & (a <= 100) & (a / 100.0 < meta.free_thresh)
    else:
        p = a / 255.0 if meta.negate else (255.0 - a) / 255.0
        free = p < meta.free_thresh
        if alpha is not None and meta.mode == "scale":
            free &= alpha > 0
    return free


def douglas_peucker(points: np.ndarray, tol: float) -> np.ndarray:
    """Simplify an open polyline (n, 2) keeping both ends; iterative Douglas-Peucker."""
    n = len(points)
    if n <= 2 or tol <= 0:
        return points
    keep = np.zeros(n, bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = points[i], points[j]
        seg = points[i + 1:j]
        d = b - a
        L = math.hypot(d[0], d[1])
        if L < 1e-15:
            dist = np.hypot(seg[:, 0] - a[0], seg[:, 1] - a[1])
        else:
            dist = np.abs(d[0] * (seg[:, 1] - a[1]) - d[1] * (seg[:, 0] - a[0])) / L
        k = int(np.argmax(dist))
        if dist[k] > tol:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return points[keep]


def simplify_ring(ring: np.ndarray, tol: float) -> np.ndarray:
    """Simplify a closed ring (n, 2), no repeated end point; returns >= 3 points or fewer if
    it collapses."""
    r = np.asarray(ring, float)
    if len(r) > 1 and np.all(r[0] == r[-1]):
        r = r[:-1]
    if len(r) <= 3 or tol <= 0:
        return r
    # anchor at an extreme point (a true corner, kept by any simplification)
    r = np.roll(r, -int(np.argmax(((r - r.mean(0)) ** 2).sum(1))), axis=0)
    far = int(np.argmax(((r - r[0]) ** 2).sum(1)))
    a = douglas_peucker(r[:far + 1], tol)
    b = douglas_peucker(np.concatenate([r[far:], r[:1]]), tol)
    return np.concatenate([a[:-1], b[:-1]])


def square_corners(ring: np.ndarray) -> np.ndarray:
    """Undo marching-squares chamfers on a binary image's contour (pixel centres at integer
    coordinates): between two consecutive points that differ in both x and y, insert the
    pixel corner (the half-integer coordinate of each), giving the exact pixel boundary."""
    r = np.asarray(ring, float)
    q = np.roll(r, -1, axis=0)
    cham = (np.abs(r[:, 0] - q[:, 0]) > 1e-9) & (np.abs(r[:, 1] - q[:, 1]) > 1e-9)
    if not cham.any():
        return r
    half_x = np.abs(r[:, 0] - np.floor(r[:, 0]) - 0.5) < 1e-6
    half_y = np.abs(r[:, 1] - np.floor(r[:, 1]) - 0.5) < 1e-6
    cx = np.where(half_x, r[:, 0], q[:, 0])
    cy = np.where(half_y, r[:, 1], q[:, 1])
    out = np.empty((len(r) + int(cham.sum()), 2))
    pos = np.arange(len(r)) + np.concatenate([[0], np.cumsum(cham)[:-1]])
    out[pos] = r
    out[pos[cham] + 1] = np.stack([cx[cham], cy[cham]], 1)
    return out


def _block_reduce_free(free: np.ndarray, f: int) -> np.ndarray:
    """A coarse cell is free only if every fine cell in it is free."""
    h, w = free.shape
    H, W = -(-h // f), -(-w // f)
    pad = np.zeros((H * f, W * f), bool)
    pad[:h, :w] = free
    return pad.reshape(H, f, W, f).all(axis=(1, 3))


def trace_free_region(free: np.ndarray, resolution: float, origin, *, seeds=(),
                      simplify: float = 0.0, min_hole_area: float = -1.0,
                      max_vertices: int = 20_000, where: str = "<map>"):
    """Turn a free-cell mask into (boundary, holes) polygons in the world frame.

    free: bool (H, W), row 0 at the TOP (image order). origin: (x, y, yaw) of the lower-left
    pixel's corner. seeds: world points; the free region holding seeds[0] is traced (else the
    largest). Returns (boundary (k,2), [holes], info dict).
    """
    import contourpy
    from scipy import ndimage

    ox, oy, yaw = origin
    up = np.flipud(np.asarray(free, bool))            # row index = y index
    H, W = up.shape
    m = np.zeros((H + 2, W + 2), bool)                # non-free frame: open borders close
    m[1:-1, 1:-1] = up
    four = ndimage.generate_binary_structure(2, 1)
    lab, n = ndimage.label(m, structure=four)
    if n == 0:
        raise ConfigError(where, "map", "image", None, "the map has no free cell")
    c, s = math.cos(yaw), math.sin(yaw)

    def to_world(ij):   # ij: (n, 2) as (col, row) in padded index space (centres at ints)
        u = (ij[:, 0] - 1 + 0.5) * resolution
        v = (ij[:, 1] - 1 + 0.5) * resolution
        return np.stack([ox + c * u - s * v, oy + s * u + c * v], 1)

    def to_cell(p):
        dx, dy = p[0] - ox, p[1] - oy
        u, v = c * dx + s * dy, -s * dx + c * dy
        return int(math.floor(v / resolution)) + 1, int(math.floor(u / resolution)) + 1

    comp = 0
    if len(seeds):
        r, col = to_cell(seeds[0])
        if 0 <= r < H + 2 and 0 <= col < W + 2 and lab[r, col] > 0:
            comp = lab[r, col]
        else:
            raise ConfigError(where, "map", "sources[0]", list(map(float, seeds[0][:2])),
                              "not on a free cell of the map")
    if comp == 0:
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        comp = int(np.argmax(sizes))
    region = lab == comp
    cell_area = resolution * resolution
    if min_hole_area < 0:
        min_hole_area = 4 * cell_area
    # drop tiny non-free islands inside the region (specks of noise)
    eight = ndimage.generate_binary_structure(2, 2)
    hl, nh = ndimage.label(~region, structure=eight)
    if nh > 1:
        sizes = np.bincount(hl.ravel())
        outside = hl[0, 0]
        small = sizes * cell_area < min_hole_area
        small[0] = False
        small[outside] = False
        region |= small[hl]
    z = region.astype(np.float64)
    gen = contourpy.contour_generator(z=z, fill_type=contourpy.FillType.OuterOffset,
                                      corner_mask=False)
    polys, offsets = gen.filled(0.5, 1.5)
    if not polys:
        raise ConfigError(where, "map", "image", None, "could not trace the free region")
    # the outer ring with the largest area is the boundary; its holes are obstacles
    best, best_a = None, -1.0
    for pts, off in zip(polys, offsets):
        a = polygon_area(pts[off[0]:off[1]])
        if a > best_a:
            best, best_a = (pts, off), a
    pts, off = best
    rings = [square_corners(pts[off[k]:off[k + 1]]) for k in range(len(off) - 1)]
    tol = simplify if simplify > 0 else 0.5 * resolution
    tol_cells = tol / resolution
    while True:
        out = []
        for k, r in enumerate(rings):
            sr = simplify_ring(r, tol_cells)
            if len(sr) < 3:
                continue
            if k > 0 and polygon_area(sr) * cell_area < min_hole_area:
                continue
            out.append(sr)
        total = sum(len(r) for r in out)
        if total <= max_vertices or tol_cells > max(H, W):
            break
        tol_cells *= 1.5
    boundary = to_world(out[0])
    holes = [to_world(r) for r in out[1:]]
    info = {"cells": (H, W), "resolution": resolution, "holes": len(holes),
            "vertices": total, "simplify_m": tol_cells * resolution}
    return boundary, holes, info


def load_ros_map(yaml_path, *, seeds=(), simplify=0.0, min_hole_area=-1.0,
                 max_vertices=20_000, max_cells=16_000_000):
    """A ROS map_server map as (boundary, holes, info); see :func:`trace_free_region`."""
    meta = read_ros_yaml(yaml_path)
    free = ros_free_mask(meta)
    res = meta.resolution
    H, W = free.shape
    f = 1
    origin = meta.origin
    if H * W > max_cells:
        f = int(math.ceil(math.sqrt(H * W / max_cells)))
        free = _block_reduce_free(free, f)
        res = res * f
        # padding rows went below the image's bottom edge: move the lower-left corner down
        hh = free.shape[0] * f - H
        ox, oy, yaw = origin
        origin = (ox + math.sin(yaw) * hh * meta.resolution,
                  oy - math.cos(yaw) * hh * meta.resolution, yaw)
    b, holes, info = trace_free_region(free, res, origin, seeds=seeds, simplify=simplify,
                                       min_hole_area=min_hole_area, max_vertices=max_vertices,
                                       where=meta.yaml_path)
    info.update(image=meta.image, image_cells=(H, W), reduce=f)
    return b, holes, info


# --------------------------------------------------------------------------- builders

def pick_source(wm: WorldMap, cell: float | None = None) -> np.ndarray:
    """(x, y, 0): the free point of greatest clearance in the largest free region."""
    from scipy import ndimage
    x0, y0, x1, y1 = wm.bounds
    if cell is None:
        cell = max((x1 - x0), (y1 - y0)) / 400.0
    r = wm.raster(cell)
    lab, n = ndimage.label(r.free)
    if n == 0:
        raise ValueError(f"map {wm.name!r} has no free space")
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    region = np.pad(lab == int(np.argmax(sizes)), 1)
    dist = ndimage.distance_transform_edt(region)[1:-1, 1:-1]
    iy, ix = np.unravel_index(int(np.argmax(dist)), dist.shape)
    p = r.centres(np.array(iy), np.array(ix))
    return np.array([p[0], p[1], 0.0])


def build_map(cfg: RunConfig) -> WorldMap:
    """The WorldMap of a config: TOML polygons or a traced ROS map, with its sources (the
    world's automatic pick if [map].sources is empty). Sources must be in free space."""
    m = cfg.map
    extra = []
    for o in m.obstacles:
        if o.type == "rect":
            (ax, ay), (bx, by) = o.points
            extra.append(np.array([[ax, ay], [bx, ay], [bx, by], [ax, by]], float))
        elif o.type == "circle":
            extra.append(circle_polygon(o.center, o.radius, m.circle_segments))
        else:
            extra.append(np.array(o.points, float))
    info: dict = {}
    if m.ros_map is not None:
        meta = read_ros_yaml(m.ros_map)
        w, h = ros_image_size(meta)
        check_extent(meta.yaml_path, "ros_map", "resolution", meta.resolution,
                     (0.0, 0.0, w * meta.resolution, h * meta.resolution), cfg.rv)
        seeds = [s[:2] for s in m.sources]
        boundary, holes, info = load_ros_map(
            m.ros_map, seeds=seeds, simplify=m.simplify, min_hole_area=m.min_hole_area,
            max_vertices=m.max_vertices, max_cells=m.max_cells)
        obstacles = holes + extra
        disjoint = not extra
    else:
        boundary = np.array(m.boundary, float)
        check_extent(cfg.path, "map", "boundary", [list(p) for p in m.boundary],
                     (*boundary.min(0), *boundary.max(0)), cfg.rv)
        obstacles = extra
        disjoint = _disjoint(boundary, obstacles)
    wm = WorldMap(cfg.name, boundary, obstacles, np.zeros((0, 3)), disjoint, info)
    if m.sources:
        src = np.array(m.sources, float)
        ok = wm.contains(src[:, :2])
        for k in np.nonzero(~ok)[0]:
            raise ConfigError(cfg.path, "map", f"sources[{k}]", list(m.sources[k]),
                              "not in free space")
        wm.sources = src
    else:
        wm.sources = pick_source(wm)[None, :]
        wm.info["auto_source"] = True
    return wm


def map_from_path(path) -> tuple[RunConfig, WorldMap]:
    """(config, map) from a TOML config or a bare ROS YAML -- no Zenoh, for reports."""
    cfg = load_config(path)
    return cfg, build_map(cfg)


def map_from_info(info) -> WorldMap:
    """A WorldMap from a WorldInfo message (e.g. ``session.get(keys.world_info)``), for
    processes without the config files (viewers, reports on another host)."""
    b = np.asarray(info.boundary, float).reshape(-1, 2)
    obs = [np.asarray(o, float).reshape(-1, 2) for o in info.obstacles]
    wm = WorldMap(info.name, b, obs, np.asarray(info.sources, float).reshape(-1, 3),
                  _disjoint(b, obs))
    wm._cache["free_area"] = float(info.free_area)
    return wm

"""The judged map families at the judged scale: does "certified" mean covered there?

``bench/unseen.py``'s random maps hold 20-65 robots and at most one door. The runs are
also judged on office floors, corridors, caves and pillar halls given as ROS map_server
files, at rv = 1 m and 150-700 robots. This bench draws random maps of those four families
(each map its own random size and shape, none of them a config's), writes each as a ROS
map (PGM + YAML at 0.05 m) with its run config, runs the product on it in-process (agents
with the real wall sweep and touch sensors, pymunk physics, the coordinator:
``bench.unseen.judge``) and judges the end by the world's ground truth.

Families (rv = 1 m; "narrow" is below the 0.4 rv ``door_min_rv`` guarantee on purpose):

* ``cave``: 4-8 chambers of overlapping discs joined by winding tunnels 0.7-1.3 m wide, a
  tree of them plus 0-2 extra tunnels (loops: the free space has holes), rocks 0.3-0.7 m
  across in the chambers; 15-22 m x 10-15 m.
* ``corridors``: a grid of junctions 3.6-5 m apart joined by corridors 1.0-1.8 m wide
  along a random spanning tree plus 0-2 extra links (dead ends and loops), and rooms
  between them behind doors 0.3-0.8 m wide, some split by a wall with a side door.
* ``pillars``: a hall 11-18 m x 8-12 m with a jittered grid of pillars 1.6-3 m apart,
  0.2-0.6 m across, square or round, some missing, and 0-3 partition walls from the outer
  wall.
* ``office``: ``bench/configs/maps/make_office.py``'s floor with 4-6 rooms a side, doors to
  the corridor 0.3-0.8 m wide, side doors, desks.

Each map's source is a random free point with 0.4 m clearance, facing a random way; odd
maps have 0.5 deg bearing noise. A map is map ``index`` of campaign ``seed``: the same
pair always gives the same map. With ``--turn`` each map is the same map turned 5-40 deg
either way about its centre (its own random stream) and drawn again on the 0.05 m grid
(:func:`turn_raster`): every wall oblique, in raster steps, as a ROS map of a building
scanned off its axes draws it; the source is drawn on the turned map.

    python bench/families.py --maps 8 --jobs 2                  # maps 0-7: two of each family
    python bench/families.py --maps 4 --seed 1 --families cave office --out /tmp/fam
    python bench/families.py --maps 4 --turn                    # the same maps 0-3, turned

Prints a row per map, a summary, and one JSON object as the last line; exits 1 on a false
certificate or an error.
"""
from __future__ import annotations

import argparse
import importlib.util
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from swarmcover.world.maps import write_ros_map  # noqa: E402

RES = 0.05          # m per cell
FAMILIES = ("cave", "corridors", "pillars", "office")


def _grid(W: float, H: float):
    nx, ny = int(round(W / RES)), int(round(H / RES))
    yy, xx = (np.mgrid[0:ny, 0:nx] + 0.5) * RES
    return xx, yy


def _keep_component(free: np.ndarray, at=None) -> np.ndarray:
    """The connected free part holding point ``at`` (x, y; None: the largest part), with
    a 0.2 m solid rim."""
    free = free.copy()
    free[:4, :] = free[-4:, :] = False
    free[:, :4] = free[:, -4:] = False
    lab, n = ndimage.label(free)
    if at is None:
        if n == 0:
            return free
        return lab == 1 + int(np.argmax(ndimage.sum(free, lab, range(1, n + 1))))
    return lab == lab[int(at[1] / RES), int(at[0] / RES)]


def turn_raster(free: np.ndarray, deg: float) -> np.ndarray:
    """``free`` (bool (ny, nx), row 0 the lowest y, cells of RES m) turned ``deg`` CCW
    about its centre and drawn again on a grid of RES m cells big enough to hold it: a
    cell is free when the old cell under its centre is (outside the old grid: solid).
    Only the largest free part is kept, with the 0.2 m solid rim of every family map.
    Walls 2 cells thick stay closed (4-connected) up to 45 deg."""
    ny, nx = free.shape
    W, H = nx * RES, ny * RES
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    W2, H2 = abs(W * c) + abs(H * s) + 0.4, abs(W * s) + abs(H * c) + 0.4
    xx, yy = _grid(W2, H2)
    xx, yy = xx - W2 / 2, yy - H2 / 2
    i = np.floor((c * xx + s * yy + W / 2) / RES).astype(int)     # the old cell under it
    j = np.floor((-s * xx + c * yy + H / 2) / RES).astype(int)
    inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    out = np.zeros(xx.shape, bool)
    out[inside] = free[j[inside], i[inside]]
    return _keep_component(out)


def cave(rng) -> tuple[np.ndarray, str]:
    W, H = float(rng.uniform(15, 22)), float(rng.uniform(10, 15))
    xx, yy = _grid(W, H)
    free = np.zeros(xx.shape, bool)
    n = int(np.clip(round(W * H / 40), 4, 8))
    centres = [np.array([1.8, 1.8])]
    for _ in range(4000):
        if len(centres) == n:
            break
        c = rng.uniform([1.8, 1.8], [W - 1.8, H - 1.8])
        if min(np.linalg.norm(c - q) for q in centres) > 3.2:
            centres.append(c)
    for c in centres:                    # chambers: a few overlapping discs
        for _ in range(int(rng.integers(2, 5))):
            q = c + rng.normal(0, 0.5, 2)
            r = rng.uniform(0.9, 1.7)
            free |= (xx - q[0]) ** 2 + (yy - q[1]) ** 2 < r * r

    def tunnel(p, q, half):
        k = max(2, int(np.linalg.norm(q - p) / 0.15))
        side = np.array([-(q - p)[1], (q - p)[0]]) / np.linalg.norm(q - p)
        wig = rng.uniform(-1.0, 1.0)
        for t in np.linspace(0, 1, k):
            m = p + t * (q - p) + side * wig * np.sin(np.pi * t)
            r = rng.uniform(*half)
            free[(xx - m[0]) ** 2 + (yy - m[1]) ** 2 < r * r] = True

    half = (0.35, 0.45) if rng.random() < 0.5 else (0.45, 0.65)   # tunnels 0.7-0.9 or 0.9-1.3 m
    order, left, pairs = [0], list(range(1, len(centres))), []
    while left:                          # a tree of tunnels, nearest chamber first
        a, b = min(((a, b) for a in order for b in left),
                   key=lambda ab: np.linalg.norm(centres[ab[0]] - centres[ab[1]]))
        tunnel(centres[a], centres[b], half)
        pairs.append((a, b)); order.append(b); left.remove(b)
    loops = int(rng.integers(0, 3))
    others = [(a, b) for a in range(len(centres)) for b in range(a + 1, len(centres))
              if (a, b) not in pairs and (b, a) not in pairs]
    for k in rng.permutation(len(others))[:loops]:
        a, b = others[int(k)]
        tunnel(centres[a], centres[b], half)
    for _ in range(int(rng.integers(3, 8))):         # rocks in the chambers
        c = centres[int(rng.integers(1, len(centres)))] + rng.normal(0, 0.6, 2)
        r = rng.uniform(0.15, 0.35)
        free &= ~((xx - c[0]) ** 2 + (yy - c[1]) ** 2 < r * r)
    return _keep_component(free, centres[0]), (
        f"{W:.1f} x {H:.1f} m, {len(centres)} chambers, tunnels {2 * half[0]:.1f}-"
        f"{2 * half[1]:.1f} m, {loops} loop(s)")


def corridors(rng) -> tuple[np.ndarray, str]:
    L = float(rng.uniform(3.6, 5.0))                  # junction spacing
    w = float(rng.uniform(1.0, 1.8))                  # corridor width
    gx, gy = int(rng.integers(3, 6)), int(rng.integers(2, 4))   # junctions
    W, H = (gx - 1) * L + w + 0.4, (gy - 1) * L + w + 0.4
    xx, yy = _grid(W, H)
    free = np.zeros(xx.shape, bool)
    o = 0.2 + w / 2                                   # junction (0, 0)

    def box(x0, y0, x1, y1, val):
        free[(xx >= x0) & (xx < x1) & (yy >= y0) & (yy < y1)] = val

    def jx(i):
        return o + i * L

    edges = [((i, j), (i + 1, j)) for i in range(gx - 1) for j in range(gy)] + \
            [((i, j), (i, j + 1)) for i in range(gx) for j in range(gy - 1)]
    parent = {(i, j): (i, j) for i in range(gx) for j in range(gy)}

    def root(a):
        while parent[a] != a:
            a = parent[a]
        return a

    tree, rest = [], []
    for k in rng.permutation(len(edges)):            # Kruskal on random order: a spanning tree
        a, b = edges[int(k)]
        if root(a) != root(b):
            parent[root(a)] = root(b)
            tree.append((a, b))
        else:
            rest.append((a, b))
    links = tree + rest[:int(rng.integers(0, 3))]
    for (i0, j0), (i1, j1) in links:
        box(jx(min(i0, i1)) - w / 2, jx(min(j0, j1)) - w / 2,
            jx(max(i0, i1)) + w / 2, jx(max(j0, j1)) + w / 2, True)
    T = 0.1
    rooms, doors = 0, []
    for i in range(gx - 1):                           # the blocks between junctions
        for j in range(gy - 1):
            x0, x1 = jx(i) + w / 2 + T, jx(i + 1) - w / 2 - T
            y0, y1 = jx(j) + w / 2 + T, jx(j + 1) - w / 2 - T
            walls = {"S": ((i, j), (i + 1, j)), "N": ((i, j + 1), (i + 1, j + 1)),
                     "W": ((i, j), (i, j + 1)), "E": ((i + 1, j), (i + 1, j + 1))}
            sides = [s for s, e in walls.items() if e in links]
            if not sides or rng.random() < 0.2:
                continue                              # a solid block
            box(x0, y0, x1, y1, True)
            rooms += 1
            for s in rng.permutation(sides)[:1 + int(rng.random() < 0.3)]:
                dw = float(rng.choice([0.3, 0.35, 0.4, 0.5, 0.6, 0.8]))
                doors.append(dw)
                if s in "SN":
                    c = rng.uniform(x0 + 0.3 + dw / 2, x1 - 0.3 - dw / 2)
                    yw = y0 - T if s == "S" else y1
                    box(c - dw / 2, yw - 0.01, c + dw / 2, yw + T + 0.01, True)
                else:
                    c = rng.uniform(y0 + 0.3 + dw / 2, y1 - 0.3 - dw / 2)
                    xw = x0 - T if s == "W" else x1
                    box(xw - 0.01, c - dw / 2, xw + T + 0.01, c + dw / 2, True)
            if rng.random() < 0.3:                    # split by a wall with a side door
                xm = (x0 + x1) / 2 + rng.uniform(-0.4, 0.4)
                box(xm - T / 2, y0, xm + T / 2, y1, False)
                dw = float(rng.uniform(0.4, 0.8))
                c = rng.uniform(y0 + 0.3 + dw / 2, y1 - 0.3 - dw / 2)
                box(xm - T, c - dw / 2, xm + T, c + dw / 2, True)
    free = _keep_component(free, (o, o))
    return free, (f"{gx} x {gy} junctions {L:.1f} m apart, corridors {w:.2f} m, "
                  f"{len(links) - len(tree)} loop(s), {rooms} rooms, doors "
                  f"{min(doors, default=0):.2f}-{max(doors, default=0):.2f} m")


def pillars(rng) -> tuple[np.ndarray, str]:
    W, H = float(rng.uniform(11, 18)), float(rng.uniform(8, 12))
    xx, yy = _grid(W, H)
    free = np.zeros(xx.shape, bool)
    free[(xx > 0.2) & (xx < W - 0.2) & (yy > 0.2) & (yy < H - 0.2)] = True
    sx, sy = float(rng.uniform(1.6, 3.0)), float(rng.uniform(1.6, 3.0))
    size = float(rng.uniform(0.2, 0.6))
    jit = float(rng.uniform(0.0, 0.3))
    round_ = rng.random() < 0.5
    n = 0
    kx, ky = int((W - 0.4) / sx), int((H - 0.4) / sy)     # columns, rows: centred
    for cx in (W - (kx - 1) * sx) / 2 + sx * np.arange(kx):
        for cy in (H - (ky - 1) * sy) / 2 + sy * np.arange(ky):
            if rng.random() < 0.12:
                continue                              # a missing pillar
            c = np.array([cx, cy]) + rng.uniform(-jit, jit, 2)
            if round_:
                free &= ~((xx - c[0]) ** 2 + (yy - c[1]) ** 2 < (size / 2) ** 2)
            else:
                free &= ~((abs(xx - c[0]) < size / 2) & (abs(yy - c[1]) < size / 2))
            n += 1
    walls = int(rng.integers(0, 4))
    for _ in range(walls):                            # partitions from the outer wall
        ln = float(rng.uniform(1.0, 3.0))
        if rng.random() < 0.5:
            x = float(rng.uniform(1.0, W - 1.0))
            y0, y1 = (0.0, ln) if rng.random() < 0.5 else (H - ln, H)
            free &= ~((abs(xx - x) < 0.05) & (yy >= y0) & (yy < y1))
        else:
            y = float(rng.uniform(1.0, H - 1.0))
            x0, x1 = (0.0, ln) if rng.random() < 0.5 else (W - ln, W)
            free &= ~((abs(yy - y) < 0.05) & (xx >= x0) & (xx < x1))
    at = np.unravel_index(np.argmax(ndimage.distance_transform_edt(free)), free.shape)
    free = _keep_component(free, ((at[1] + 0.5) * RES, (at[0] + 0.5) * RES))
    return free, (f"{W:.1f} x {H:.1f} m, {n} {'round' if round_ else 'square'} pillars "
                  f"{size:.2f} m, {sx:.1f} x {sy:.1f} m apart, {walls} partition(s)")


def _make_office():
    spec = importlib.util.spec_from_file_location(
        "make_office", ROOT / "bench" / "configs" / "maps" / "make_office.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def office(rng) -> tuple[np.ndarray, str]:
    mo = _make_office()
    n = int(rng.integers(4, 7))                       # rooms a side
    W = round(float(n * rng.uniform(3.0, 4.2)) + 0.4, 2)
    rh = float(rng.uniform(2.4, 3.6))
    cw = float(rng.uniform(1.2, 1.8))
    H = round(2 * rh + cw + 0.4, 2)
    cy0 = 0.2 + rh
    cy1 = cy0 + cw

    def side_door_y(side, w):
        return rng.uniform(0.6 + w / 2, rh - 0.4 - w / 2) + (0.2 if side == 0 else cy1 + 0.1)

    free, doors = mo.floor(rng, W, H, cy0, cy1, n, door_widths=[0.3, 0.35, 0.4, 0.5, 0.6, 0.8],
                           side_door=(0.3, 0.8), side_door_y=side_door_y,
                           desk=((0.6, 1.2), (0.4, 0.7)), desk_margin=(0.7, 0.9, 1.0))
    free = _keep_component(free, (W / 2, (cy0 + cy1) / 2))
    return free, (f"{W:.1f} x {H:.1f} m, {n} rooms a side, corridor {cw:.2f} m, doors "
                  f"{min(doors):.2f}-{max(doors):.2f} m")


@dataclass
class FamilyMap:
    family: str
    free: np.ndarray            # bool (ny, nx), row 0 the lowest y
    source: tuple[float, float, float]   # x, y (m), theta (rad)
    noise_deg: float
    about: str


def make_family_map(seed: int, index: int, families=FAMILIES, turn: bool = False
                    ) -> FamilyMap:
    """Map ``index`` of campaign ``seed``: family ``families[index % len(families)]``;
    with ``turn`` the same map turned 5-40 deg either way (:func:`turn_raster`)."""
    family = families[index % len(families)]
    rng = np.random.default_rng([seed, index, FAMILIES.index(family)])
    free, about = {"cave": cave, "corridors": corridors, "pillars": pillars,
                   "office": office}[family](rng)
    if turn:
        t = np.random.default_rng([seed, index, FAMILIES.index(family), 7])
        deg = float(t.uniform(5.0, 40.0)) * (1.0 if t.random() < 0.5 else -1.0)
        free = turn_raster(free, deg)
        about += f", turned {deg:+.1f} deg"
    clear = ndimage.distance_transform_edt(free) * RES
    ok = np.argwhere(clear >= 0.4)
    r, c = ok[int(rng.integers(len(ok)))]
    source = ((c + 0.5) * RES, (r + 0.5) * RES, float(rng.uniform(-3.14, 3.14)))
    return FamilyMap(family, free, source, 0.5 if index % 2 else 0.0, about)


def write_config(seed: int, index: int, folder: Path, families=FAMILIES, turn: bool = False):
    """Map ``index`` of campaign ``seed`` (turned with ``turn``) as a ROS map and run
    config in ``folder``; returns (path, FamilyMap)."""
    m = make_family_map(seed, index, families, turn)
    name = f"family_s{seed}_m{index}_{m.family}{'_turned' if turn else ''}"
    write_ros_map(folder / name, m.free, RES)
    x, y, th = m.source
    path = folder / f"{name}.toml"
    path.write_text("\n".join([
        f"# bench/families.py: map {index} of campaign {seed}, {m.family}: {m.about}",
        f'name = "{name}"', "rv = 1.0", "", "[map]", f'ros_map = "{name}.yaml"',
        f"sources = [{{x = {x:.3f}, y = {y:.3f}, theta = {th:.4f}}}]", "",
        "[robots]", "radius = 0.06", 'kind = "holonomic"', "",
        "[sensing]", f"noise_deg = {m.noise_deg}", "",
        "[world]", "dt = 0.05", 'mode = "lockstep"', f"seed = {index}", ""]))
    return path, m


def run_map(job) -> dict:
    """One map: write it, run it in-process, judge it by ground truth."""
    seed, index, folder, timeout, families, turn = job
    from bench.unseen import judge
    path, m = write_config(seed, index, Path(folder), families, turn)
    row = dict(seed=seed, index=index, family=m.family, turned=turn, about=m.about,
               noise_deg=m.noise_deg, free_m2=round(float(m.free.sum()) * RES * RES, 1),
               config=str(path))
    return judge(str(path), row, timeout)


def _head(r: dict) -> str:
    return f"map {r['index']:3d} {r['family']:9s} {r['free_m2']:6.1f} m^2"


def main(argv=None) -> int:
    from bench.unseen import campaign
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", type=int, default=8, help="maps START .. START+N-1")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0, help="campaign")
    ap.add_argument("--families", nargs="+", choices=FAMILIES, default=list(FAMILIES),
                    help="map i is of family i %% len(families) (default: all four)")
    ap.add_argument("--turn", action="store_true",
                    help="each map turned 5-40 deg either way and drawn again on its grid")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--timeout", type=float, default=3600.0, help="wall seconds per map")
    ap.add_argument("--out", help="folder for the maps, configs and results.json "
                    "(default: temporary)")
    a = ap.parse_args(argv)
    fam = tuple(a.families)
    return campaign(ap, a, "families", lambda folder: [
        (a.seed, i, folder, a.timeout, fam, a.turn) for i in range(a.start, a.start + a.maps)],
        run_map, _head)


if __name__ == "__main__":
    sys.exit(main())

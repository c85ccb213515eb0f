"""Benchmark: world sensing + physics per tick, against a naive all-pairs ray cast.

    python bench/world.py [--robots 1000] [--ticks 300] [--naive-ticks 3]      (the venv's python, from the repo root)

A 40 m x 30 m room with 20 obstacles (rectangles, circles, polygons) and N robots (30 %
differential drive) wandering with random velocity commands. One tick = physics step (dt,
substeps) + state read + cameras and touch for every robot + splitting into per-robot lists
(what the world node does before encoding). The baseline, run in the same process on the
same states, replaces the vectorised sensing with the naive implementation: a Python loop
over all robot pairs and, for pairs in range, over all wall segments. Progress goes to
stderr; the last line is one JSON object with robots, ticks_per_s, naive_ticks_per_s,
speedup and a per-part breakdown.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarmcover.world.config import parse_config  # noqa: E402
from swarmcover.world.groundtruth import lattice  # noqa: E402
from swarmcover.world.maps import build_map  # noqa: E402
from swarmcover.world.physics import Physics  # noqa: E402
from swarmcover.world.sensing import Sensors  # noqa: E402


def bench_config(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    obstacles = []
    cells = [(x, y) for x in range(5) for y in range(4)]
    for k, (cx, cy) in enumerate(cells):         # 20 obstacles, one per 8 m x 7.5 m cell
        x, y = 4 + cx * 8 + rng.uniform(-1, 1), 3.5 + cy * 7.5 + rng.uniform(-1, 1)
        if k % 3 == 0:
            w, h = rng.uniform(0.8, 2.5, 2)
            obstacles.append({"type": "rect", "min": [x - w / 2, y - h / 2],
                              "max": [x + w / 2, y + h / 2]})
        elif k % 3 == 1:
            obstacles.append({"type": "circle", "center": [x, y], "radius": rng.uniform(0.4, 1.0)})
        else:
            # star-shaped with every angular gap < pi: a simple polygon, which the map
            # check requires (sorted uniform angles could leave a gap > pi and cross)
            a = 2 * math.pi * np.arange(6) / 6 + rng.uniform(-0.4, 0.4, 6)
            r = rng.uniform(0.5, 1.2, 6)
            obstacles.append({"type": "polygon", "points": [[x + r[i] * math.cos(a[i]),
                                                             y + r[i] * math.sin(a[i])]
                                                            for i in range(6)]})
    return {"name": "bench", "rv": 1.0,
            "map": {"boundary": [[0, 0], [40, 0], [40, 30], [0, 30]], "obstacles": obstacles,
                    "sources": [{"x": 0.5, "y": 15.0}]},
            "robots": {"radius": 0.06}, "sensing": {"noise_deg": 0.5, "n_touch": 8},
            "world": {"seed": seed}}


def naive_sense(pos, heading, walls, rv, radius, skin, n_touch):
    """The baseline: per pair Python distance checks, per wall Python segment tests."""
    n = len(pos)
    P = pos.tolist()
    W = walls.tolist()
    out = [[] for _ in range(n)]

    def cross(ax, ay, bx, by, cx, cy):
        return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)

    for i in range(n):
        xi, yi = P[i]
        for j in range(i + 1, n):
            xj, yj = P[j]
            if (xj - xi) ** 2 + (yj - yi) ** 2 > rv * rv:
                continue
            blocked = False
            for x0, y0, x1, y1 in W:
                d1 = cross(x0, y0, x1, y1, xi, yi)
                d2 = cross(x0, y0, x1, y1, xj, yj)
                d3 = cross(xi, yi, xj, yj, x0, y0)
                d4 = cross(xi, yi, xj, yj, x1, y1)
                if d1 * d2 <= 0 and d3 * d4 <= 0:
                    blocked = True
                    break
            if not blocked:
                a = math.atan2(yj - yi, xj - xi)
                out[i].append((j, a - heading[i]))
                out[j].append((i, a + math.pi - heading[j]))
    touch = [[] for _ in range(n)]
    reach = radius + skin
    for i in range(n):
        xi, yi = P[i]
        for x0, y0, x1, y1 in W:
            dx, dy = x1 - x0, y1 - y0
            t = max(0.0, min(1.0, ((xi - x0) * dx + (yi - y0) * dy) / (dx * dx + dy * dy)))
            cx, cy = x0 + t * dx - xi, y0 + t * dy - yi
            if cx * cx + cy * cy < reach * reach:
                touch[i].append(math.atan2(cy, cx) - heading[i])
    return out, touch


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", type=int, default=1000)
    p.add_argument("--ticks", type=int, default=1000)
    p.add_argument("--naive-ticks", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    cfg = parse_config(bench_config(a.seed), "<bench>")
    wm = build_map(cfg)
    rng = np.random.default_rng(a.seed)
    ph = Physics(wm, radius=cfg.robots.radius, v_max=cfg.robots.v_max, w_max=cfg.robots.w_max,
                 dt=cfg.world.dt, substeps=cfg.world.substeps, rng=rng)
    sens = Sensors(wm, cfg.rv, radius=cfg.robots.radius,
                   noise_sigma=math.radians(cfg.sensing.noise_deg), n_touch=cfg.sensing.n_touch,
                   skin=cfg.sensing.touch_skin, rng=rng)
    spots = lattice(0.8, 0.2, (0.1, 0.1), wm.bounds)
    spots = spots[wm.is_free(spots, margin=0.1)]
    if len(spots) < a.robots:
        print(f"only {len(spots)} spots for {a.robots} robots", file=sys.stderr)
        return 2
    spots = spots[rng.permutation(len(spots))[:a.robots]] + rng.uniform(-0.1, 0.1, (a.robots, 2))
    for k, (x, y) in enumerate(spots):
        ph.add(k, x, y, rng.uniform(-math.pi, math.pi), "diffdrive" if k % 10 < 3 else "holonomic",
               exact=True)
    n = len(ph.ids)
    print(f"world bench: {n} robots, {len(wm.obstacles)} obstacles, {len(wm.walls)} walls",
          file=sys.stderr)
    cmd = rng.uniform(-0.4, 0.4, (n, 3))

    def tick(sense_fn):
        nonlocal cmd
        cmd += rng.normal(0, 0.05, cmd.shape)
        np.clip(cmd, -0.4, 0.4, out=cmd)
        t0 = time.perf_counter()
        ph.step(cmd)
        ids, pos, th = ph.state()
        t1 = time.perf_counter()
        sense_fn(ids, pos, th)
        t2 = time.perf_counter()
        return t1 - t0, t2 - t1

    def fast(ids, pos, th):
        sens.sense(pos, th).lists(ids)   # what the node does per tick before encoding

    def naive(ids, pos, th):
        naive_sense(pos, th, wm.walls, cfg.rv, cfg.robots.radius, cfg.sensing.touch_skin,
                    cfg.sensing.n_touch)

    for _ in range(5):
        tick(fast)                          # warm-up
    t_phys = t_sense = 0.0
    pairs = 0
    start = time.perf_counter()
    for k in range(a.ticks):
        dp, ds = tick(fast)
        t_phys += dp
        t_sense += ds
        if k % 100 == 0:
            print(f"  fast tick {k}/{a.ticks}", file=sys.stderr)
    wall = time.perf_counter() - start
    _, pos, th = ph.state()
    pairs = len(sens.sense(pos, th).pairs)
    fast_tps = a.ticks / wall
    nstart = time.perf_counter()
    n_phys = n_sense = 0.0
    for k in range(a.naive_ticks):
        dp, ds = tick(naive)
        n_phys += dp
        n_sense += ds
        print(f"  naive tick {k + 1}/{a.naive_ticks}", file=sys.stderr)
    naive_tps = a.naive_ticks / (time.perf_counter() - nstart)
    # sanity: both see the same robots on the current state
    ids, pos, th = ph.state()
    b = sens.sense(pos, th)
    nv, _ = naive_sense(pos, th, wm.walls, cfg.rv, cfg.robots.radius, cfg.sensing.touch_skin,
                        cfg.sensing.n_touch)
    same = sum(len(x) for x in nv) == len(b.obs)
    res = {"bench": "world", "robots": n, "obstacles": len(wm.obstacles),
           "walls": int(len(wm.walls)), "visible_pairs": int(pairs), "ticks": a.ticks,
           "ticks_per_s": round(fast_tps, 2), "naive_ticks_per_s": round(naive_tps, 3),
           "speedup": round(fast_tps / naive_tps, 1),
           "physics_ms": round(1000 * t_phys / a.ticks, 3),
           "sensing_ms": round(1000 * t_sense / a.ticks, 3),
           "naive_sensing_ms": round(1000 * n_sense / max(1, a.naive_ticks), 1),
           "same_sightings": bool(same), "substeps": cfg.world.substeps,
           "dt": cfg.world.dt}
    print(json.dumps(res), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

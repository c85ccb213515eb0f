"""Cost of one deployment cycle of the coordinator against the swarm size N.

Synthetic swarm states of N robots (default N = 100, 250, 500, 1000, 2000): a jittered
triangular lattice at 0.85 rv spacing in an L-shaped room with two boxes, rv = 1 m.
Who sees whom is bench/truth.py's Swarm (distance <= rv, clear line of sight, 0.5 deg
bearing noise, bearings from the true positions); a robot within 0.3 m of a wall touches
it (contact bearing to the nearest wall point). Two states per N:

* front: the room is sized for about 1.6 N robots and holds the N lattice points nearest
  the source: an open front, pushes planned, not certified;
* closed: the room is sized for N robots and full; every deployment the fence offers is
  fed back as touched (test-drive failures and probe failures, as the deployer's evidence
  would at the end of a run), so the fence closes on the walls, the certificate holds and
  the cycle runs the redundancy pass.

Stages, each timed as the coordinator runs it in one cycle (coordinator/deployer.py
``Deployer._plan`` -> coordinator/planner.py ``plan_cycle``):
  snapshot   Deployer.build_snapshot + _strays from every robot's Status (statuses in)
  complex    build_complex on the snapshot's reports (planner._complex_and_fence)
  fence      detect_fence (with the state's evidence)
  certify    certify(cx, fence)
  redundancy find_redundant (closed state: plan_cycle runs it when certified)
  paths      plan_pushes from sources and redundant vertices (+ the extra source paths)
  lattice    planner._place_on_lattice (align_headings, estimate_shape, lattice targets;
             estimate_shape solves up to 200 vertices densely, larger swarms sparsely)
  plan_cycle the whole planner call
  cycle      Deployer.step in the settle phase (_plan: snapshot, plan_cycle, jobs), then
             its first execute step (the jobs' first tasks out)
  replan     planner.replan_push for the cycle's first push, as the deployer re-plans a
             push whose test drive touched, within the cycle (not part of "cycle")
Each stage after the first runs on the outputs of the stage before (derived arrays of the
complex computed once, as in a cycle). Times are medians of --repeat runs (perf_counter),
in ms (--clock cpu: process time, for a loaded machine). Growth: the log-log slope of the time between consecutive N (1 = linear).

Progress goes to stderr; the last stdout line is one JSON object.
Usage: python bench/cycle.py [--n 100,250,500,1000,2000] [--repeat 5] [--clock wall|cpu]
                             [--kinds front,closed] [--profile N]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.oracle import PolyMap  # noqa: E402
from bench.truth import RV, Swarm, _rect  # noqa: E402
from swarmcover.bus.messages import Status  # noqa: E402
from swarmcover.coordinator import build_complex, certify, detect_fence, find_redundant, plan_pushes  # noqa: E402
from swarmcover.coordinator.actions import SendTask  # noqa: E402
from swarmcover.coordinator.config import CoordinatorConfig  # noqa: E402
from swarmcover.coordinator.deployer import Deployer  # noqa: E402
from swarmcover.coordinator.planner import (  # noqa: E402
    _claimed,
    _place_on_lattice,
    _reports,
    plan_cycle,
    replan_push,
)

SPACING = 0.85 * RV
TOUCH_GAP = 0.3
MARGIN = 0.12            # lattice points at least this far from every wall
NOISE_DEG = 0.5
STAGES = ("snapshot", "complex", "fence", "certify", "redundancy", "paths", "lattice",
          "plan_cycle", "cycle", "replan")


def log(*a):
    print(*a, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------- states
def room(area: float) -> PolyMap:
    """An L-shaped room of free area about ``area`` m^2 (3:2 bounding box, a quarter cut
    away) with two boxes."""
    # free area = 0.75 W H - boxes; W = 1.5 H
    box = 0.012 * area
    H = math.sqrt((area + 2 * box) / (0.75 * 1.5))
    W = 1.5 * H
    outer = np.array([[0, 0], [W, 0], [W, H / 2], [W / 2, H / 2], [W / 2, H], [0, H]], float)
    s = math.sqrt(box)
    holes = [_rect(0.25 * W, 0.2 * H, 0.25 * W + s, 0.2 * H + s),
             _rect(0.7 * W, 0.22 * H, 0.7 * W + s, 0.22 * H + s)]
    return PolyMap(outer, holes)


def lattice_points(pm: PolyMap, rng) -> np.ndarray:
    lo, hi = pm.outer.min(axis=0), pm.outer.max(axis=0)
    dy = SPACING * math.sqrt(3) / 2
    pts = [(x + (r % 2) * SPACING / 2, lo[1] + MARGIN + r * dy)
           for r in range(int((hi[1] - lo[1]) / dy) + 2)
           for x in np.arange(lo[0] + MARGIN, hi[0], SPACING)]
    P = np.array(pts) + rng.normal(0.0, 0.03, (len(pts), 2))
    P = P[pm.contains(P)]
    return P[pm.wall_distance(P) >= MARGIN]


def make_state(n: int, kind: str, seed: int = 1, centre: bool = False):
    """(Swarm, source heading): ``kind`` 'front' or 'closed' (module docstring). The
    source is the lattice point at the room's lower-left corner, or with ``centre`` the
    one nearest the middle of the L's lower bar (a front all around it)."""
    rng = np.random.default_rng([seed, n, 0 if kind == "front" else 1])
    cell = SPACING * SPACING * math.sqrt(3) / 2
    area = n * cell * (1.6 if kind == "front" else 1.0)
    for _ in range(4):     # size the room so that it holds about n lattice points
        pm = room(area)
        P = lattice_points(pm, rng)
        if kind == "front" or abs(len(P) - n) <= 0.02 * n:
            break
        area *= n / max(len(P), 1)
    if centre:
        hi = pm.outer.max(axis=0)
        src = P[np.argmin(np.hypot(P[:, 0] - 0.5 * hi[0], P[:, 1] - 0.25 * hi[1]))]
    else:
        src = P[np.argmin(P[:, 0] + P[:, 1])]      # the lower-left corner of the room
    P = P[np.argsort(np.hypot(*(P - src).T), kind="stable")][:n]
    sw = Swarm(pm, rng, NOISE_DEG)
    wd = pm.wall_distance(P)
    for p, w in zip(P, wd):
        sw.add(p, sw._contact_dir(p) if w <= TOUCH_GAP else None)
    return sw, math.pi / 4


def closing_evidence(sw: Swarm, params, default_bearing: float, rounds: int = 12):
    """Test-drive and probe failures that close every side the fence offers (a full room:
    every remaining deployment faces a wall). Returns (test_drive_failures, evidence kw)."""
    rep = sw.reports()
    cx = build_complex(rep)
    tdf: dict[int, list[float]] = {}
    pfail: set = set()
    for _ in range(rounds):
        fence = detect_fence(cx, params, test_drive_failures=tdf, default_bearing=default_bearing,
                             probe_failures=sorted(pfail))
        if not fence.deployments:
            break
        for f, deps in fence.deployments.items():
            for d in deps:
                if d.kind == "probe":
                    u, v = d.edge
                    g = d.via_frac if d.vertex == u else 1.0 - d.via_frac
                    pfail.add((u, v, d.sigma, round(g, 3)))
                else:
                    tdf.setdefault(int(f), []).append(float(d.bearing))
    return tdf, {"probe_failures": sorted(pfail)}


def make_deployer(sw: Swarm, heading: float, tdf, ev) -> Deployer:
    """A deployer in its settle phase holding every robot at its vertex (robot i at vertex
    i; robot 0 at the source), its statuses from the swarm's reports; its planner is
    plan_cycle with the state's evidence."""
    cfg = CoordinatorConfig(robots_max=100000)

    def planner(snap, params, **kw):
        kw["test_drive_failures"] = tdf
        kw["evidence"] = ev
        return plan_cycle(snap, params, **kw)

    dep = Deployer(cfg, sources=[heading], planner=planner)
    rep = sw.reports()
    for i, r in rep.items():
        nb = r["neighbours"]
        st = Status(robot=i, seq=1, t=1.0, state="holding", vertex=i, task_state="done",
                    nbr_ids=list(nb), nbr_bearings=[float(b) for b in nb.values()],
                    contact=bool(r["touch"]), contact_bearing=float(r["touch_bearing"] or 0.0))
        dep.on_status(st)
        dep.vertex_of[i] = i
    dep.next_vertex = sw.n
    dep.started = True
    dep._set_phase("settle", 0.0)
    return dep


# ------------------------------------------------------------------------- timing
CLOCK = time.perf_counter


def median_ms(fn, repeat: int):
    ts, out = [], None
    for _ in range(repeat):
        t = CLOCK()
        out = fn()
        ts.append(CLOCK() - t)
    return 1e3 * statistics.median(ts), out


def time_state(sw: Swarm, heading: float, kind: str, repeat: int) -> dict:
    cfg = CoordinatorConfig()
    P = cfg.topology()
    if kind == "closed":
        tdf, ev = closing_evidence(sw, P, heading)
    else:
        tdf, ev = {}, {}
    dep = make_deployer(sw, heading, tdf, ev)
    row: dict = {}

    def snapshot():
        s = dep.build_snapshot()
        dep._strays(s)
        return s
    row["snapshot"], snap = median_ms(snapshot, repeat)
    rep = _reports(snap)
    row["complex"], cx = median_ms(lambda: build_complex(rep), repeat)
    fence_kw = dict(test_drive_failures=tdf, default_bearing=snap.source_dirs[0], **ev)
    # the fence's derived arrays of the complex (adjacency, tri_edges, ...) are built on
    # its first call: a fresh complex per run, as in a cycle
    row["fence"], fence = median_ms(lambda: detect_fence(build_complex(rep), P, **fence_kw), repeat)
    row["fence"] -= row["complex"]
    fence = detect_fence(cx, P, **fence_kw)
    row["certify"], cert = median_ms(lambda: certify(cx, fence), repeat)
    certified = bool(cert.certified) and fence.z.size > 0
    if certified:
        row["redundancy"], red = median_ms(
            lambda: find_redundant(cx, fence, cert, protected=set(snap.sources)), repeat)
        redundant = sorted(int(v) for v in red.redundant)
    else:
        row["redundancy"], redundant = 0.0, []

    def paths():
        got = list(plan_pushes(cx, fence, snap.sources, redundant, params=P,
                               max_paths=cfg.max_paths))
        while len(got) < cfg.max_paths:
            used = _claimed(cx, [p.vertices for p in got])
            c = plan_pushes(cx, fence, [0], (), params=P, max_paths=1, exclude=used - {0})
            if not c or c[0].frontier in used:
                break
            got.append(c[0])
        return got
    row["paths"], got = median_ms(paths, repeat) if fence.deployments else (0.0, [])

    kw = dict(cycle=0, redundancy=True, test_drive_failures=tdf, previous_redundant=set(),
              protected=set(), max_paths=cfg.max_paths, scale_correct=False, test_drive=True,
              next_vertex=sw.n, lattice_spacing=cfg.d0, evidence=ev, free_probes=cfg.free_probes)
    plan = plan_cycle(snap, P, **kw)
    if plan.jobs:
        from copy import deepcopy
        row["lattice"], _ = median_ms(
            lambda: _place_on_lattice(snap, deepcopy(plan.jobs), cfg.d0, P, tdf), repeat)
    else:
        row["lattice"] = 0.0
    row["plan_cycle"], plan = median_ms(lambda: plan_cycle(snap, P, **kw), repeat)
    pushes = [j for j in plan.jobs if not j.free]
    if pushes:
        # a push whose test drive touched is re-planned within the cycle (the deployer's
        # _replan): the complex, fence, paths and lattice placement again
        job = pushes[0]
        row["replan"], _ = median_ms(lambda: replan_push(
            snap, P, start=job.path[0], busy=[j for j in plan.jobs if j is not job],
            exclude=set(), test_drive_failures=tdf, new_vertex=sw.n + 100, scale_correct=False,
            test_drive=True, lattice_spacing=cfg.d0, evidence=ev), repeat)
    else:
        row["replan"] = 0.0

    def cycle():
        # settle -> plan (Deployer._plan), then the execute phase's first step sends the
        # jobs' first tasks
        dep.cycle = 0
        dep.done = False
        dep.final_pass = False
        dep.jobs = []
        dep._set_phase("settle", 0.0)
        out = dep.step(1.0)
        return out + dep.step(1.0)
    row["cycle"], out = median_ms(cycle, repeat)
    row.update(n=cx.n, edges=cx.n_edges, triangles=cx.n_triangles, K=int(fence.frontier.size),
               O=int(fence.obstacle.size), z=int(fence.z.size), certified=certified,
               redundant=len(plan.redundant), jobs=len(plan.jobs),
               tasks=sum(1 for a in out if isinstance(a, SendTask)))
    return row


def slope(t0: float, t1: float, n0: int, n1: int) -> float | None:
    if t0 <= 0.05 or t1 <= 0.05:
        return None
    return math.log(t1 / t0) / math.log(n1 / n0)


def table(rows: list[dict], kind: str, out=sys.stdout) -> None:
    rs = [r for r in rows if r["kind"] == kind]
    print(f"\n{kind}: ms per stage (median), growth = log-log slope to the previous N", file=out)
    head = f"{'stage':<11}" + "".join(f"{r['n']:>9}" for r in rs) + "   growth"
    print(head, file=out)
    for s in STAGES:
        cells = "".join(f"{r[s]:>9.2f}" for r in rs)
        g = [slope(a[s], b[s], a["n"], b["n"]) for a, b in zip(rs, rs[1:])]
        gs = " ".join("  -  " if x is None else f"{x:5.2f}" for x in g)
        print(f"{s:<11}{cells}   {gs}", file=out)
    for k in ("edges", "triangles", "K", "O", "z", "certified", "redundant", "jobs", "tasks"):
        print(f"{k:<11}" + "".join(f"{str(r[k]):>9}" for r in rs), file=out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", default="100,250,500,1000,2000", help="comma-separated swarm sizes")
    ap.add_argument("--repeat", type=int, default=5, help="median of K runs per stage")
    ap.add_argument("--kinds", default="front,closed", help="states: front, closed")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall: time.perf_counter (default); cpu: time.process_time, "
                         "less disturbed by other processes on a loaded machine")
    ap.add_argument("--profile", type=int, default=0,
                    help="cProfile plan_cycle and Deployer._plan at this N instead (stderr)")
    a = ap.parse_args(argv)
    ns = [int(x) for x in a.n.split(",") if x]
    global CLOCK
    CLOCK = time.perf_counter if a.clock == "wall" else time.process_time
    kinds = [k for k in a.kinds.split(",") if k]
    if a.profile:
        import cProfile
        import pstats
        for kind in kinds:
            sw, h = make_state(a.profile, kind)
            tdf, ev = closing_evidence(sw, CoordinatorConfig().topology(), h) if kind == "closed" else ({}, {})
            dep = make_deployer(sw, h, tdf, ev)
            pr = cProfile.Profile()
            pr.enable()
            for _ in range(3):
                dep.cycle = 0
                dep.done = False
                dep.final_pass = False
                dep.jobs = []
                dep._set_phase("settle", 0.0)
                dep.step(1.0)
                dep.step(1.0)
            pr.disable()
            log(f"=== {kind} N={a.profile}")
            pstats.Stats(pr, stream=sys.stderr).sort_stats("cumulative").print_stats(35)
        return 0
    rows = []
    for kind in kinds:
        for n in ns:
            t = time.perf_counter()
            sw, h = make_state(n, kind)
            row = time_state(sw, h, kind, max(1, a.repeat))
            row["kind"] = kind
            rows.append(row)
            log(f"[{kind} N={n}] {row['n']} robots, cycle {row['cycle']:.1f} ms, "
                f"plan_cycle {row['plan_cycle']:.1f} ms ({time.perf_counter() - t:.1f} s)")
    for kind in kinds:
        table(rows, kind)
    summary = {"clock": a.clock, "loadavg_1min": round(os.getloadavg()[0], 2), "rows": [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}
                        for r in rows]}
    at = [r for r in rows if r["n"] >= 900 and r["n"] <= 1100]
    if at:
        summary["cycle_ms_at_1000"] = round(max(r["cycle"] for r in at), 3)
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())

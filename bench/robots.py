"""Where a certified swarm's robots go (issue 19: spacing, walls, redundancy).

Runs each config in-process (swarmcover.simloop, the same nodes as ``swarmcover run``) and
looks at the swarm it certifies, with the world's ground truth:

* **by place**: a vertex is a *wall* vertex when its robot stands within 0.5 rv of a wall,
  else *interior*. Rips edges by their ends (interior-interior ``ii``, wall-interior ``wi``,
  wall-wall ``ww``): count, mean length, quantiles, how many are shorter than 0.6 rv; each
  vertex's nearest neighbour (median by class). ``wall_row`` is what a row of robots along
  every wall ring at spacing d0 would need (sum of max(3, ceil(length / d0))), so
  ``wall_vertices - wall_row`` is what the walls cost beyond a spaced row.
* **by origin**: how each wall vertex got there, from the agents' Status messages (the
  bus): the test drive that ended done nearest where it stands (within 0.2 m), with
  reason ``wall`` (a touch far enough out: the robot kept there), ``opening`` or ``room``
  (a wall sweep's: agents/sweep.py), or ``clear`` (a deployment's drive that touched
  nothing); ``other`` when none did. ``no_lattice_point`` counts, of those, the drives of
  deployments the planner found no free lattice point for (JobSpec.placed ``Placed.SPEC``: the
  spec's direction at the lattice spacing), read off the planner's typed output by a
  wrapper, like the redundancy numbers below.
* **spawned**: robots the run started; those not in the final swarm were sent away
  (redundant at the end, or cut off from every source) or failed.
* **redundancy** (spec 5.3-5.4): the distinct vertices the coordinator's local link test
  called redundant over the run (each then started a push instead of a new robot), the
  passes, and what the spec's global greedy (remove a robot off the fence while
  D x = z stays solvable over GF(2) on the triangles left and the 1-skeleton stays
  connected) would remove beyond it on the last certified complex.
* **fence thin** (issue 19 item 3, an oracle): the wall robots an oracle could still take
  out of that complex, one at a time, where the fence can be rerouted across the side
  between a robot's two fence neighbours and ground truth puts a wall within the no-room
  depth behind that side (:func:`fence_thin`): an upper bound on what thinning crowded
  wall rows after certification could free, and ``robots_per_bound_thinned`` what it
  would leave. No sweep of the new side is driven: the run's decisions are unchanged.

The redundancy numbers come from wrapping coordinator.topology.redundancy.find_redundant
(experiment code observing the coordinator; the run's decisions are unchanged).

    python bench/robots.py                                  # every config, seed 0
    python bench/robots.py configs/small.toml --seeds 0 1   # prints a table, then JSON
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import run_configs  # noqa: E402

WALL_RV = 0.5          # a vertex within this of a wall (x rv) is a wall vertex
SHORT_RV = 0.6         # an edge shorter than this (x rv) is counted short
MATCH_M = 0.2          # a wall vertex's origin: a drive's end within this (m)
ORIGINS = ("wall", "opening", "room", "clear")


def _still_certified(cx, alive: np.ndarray, cols: list[int], zmask: int) -> bool:
    """Whether the complex ``cx`` restricted to the vertices ``alive`` still certifies the
    target cycle ``zmask`` (an edge bit mask): z in the span of the surviving triangles'
    boundaries (``cols``, one bit mask per triangle) over GF(2), and the surviving
    1-skeleton connected."""
    from swarmcover.coordinator.topology.gf2 import in_span
    n, u, v = cx.n, cx.edges[:, 0], cx.edges[:, 1]
    if not in_span([cols[t] for t in np.nonzero(alive[cx.triangles].all(axis=1))[0].tolist()],
                   zmask):
        return False
    ke = alive[u] & alive[v]
    idx = np.nonzero(alive)[0]
    re = -np.ones(n, int)
    re[idx] = np.arange(idx.size)
    g = csr_matrix((np.ones(int(ke.sum())), (re[u[ke]], re[v[ke]])), shape=(idx.size, idx.size))
    return connected_components(g, directed=False)[0] == 1


def global_extra(cx, fence, cert, protected) -> list[int]:
    """Robots (node indices) the spec's global greedy (5.3 step 5) removes from ``cx``
    beyond the fence vertices, ``cert.z``'s vertices and ``protected``: one at a time
    (highest degree first), kept out while z stays in the span of the surviving
    triangles' boundaries and the surviving 1-skeleton is connected."""
    n, z = cx.n, np.asarray(cert.z)
    zmask = 0
    for e in z.tolist():
        zmask |= 1 << int(e)
    cols = [(1 << a) | (1 << b) | (1 << c) for a, b, c in cx.tri_edges.tolist()]
    keep = np.zeros(n, bool)
    ids = [p for p in protected if p in cx] + [v for v in fence.fence_vertices if v in cx]
    if ids:
        keep[cx.index(ids)] = True
    if z.size:
        keep[cx.edges[z].ravel()] = True
    alive = np.ones(n, bool)
    removed = []
    for c in sorted(np.nonzero(~keep)[0].tolist(), key=lambda p: (-int(cx.degree[p]), p)):
        alive[c] = False
        if _still_certified(cx, alive, cols, zmask):
            removed.append(c)
            continue
        alive[c] = True
    return removed


def fence_thin(cx, cert, protected, pos: dict, walls, room_depth: float) -> list[int]:
    """Fence robots (node ids) an oracle could still take out of the last certified
    complex ``cx`` (issue 19 item 3: what crowded wall rows cost), each while the rest
    stays certifiable once the new side is found closed.

    A robot c whose target-cycle edges are exactly uc and cw, with uw a Rips edge too, can
    leave when z' = z + uc + cw + uw (the fence rerouted across uw) stays in the span of
    the surviving triangles' boundaries over GF(2), the surviving 1-skeleton stays
    connected, and the new side uw has no room behind it by ground truth: rays from 9
    points along it, on c's side, meet a wall of ``walls`` (E, 4) within ``room_depth`` (m)
    (what a sweep of that side would have to find; none was driven: this is an upper
    bound on what thinning the walls can free, not a rule). ``pos``: node id -> (x, y).
    Greedy, most crowded first (the shorter of uc and cw); repeated until none leaves."""
    from swarmcover.recheck import side_depths
    n = cx.n
    ids = cx.ids
    E = cx.edges
    eidx = {(int(min(a, b)), int(max(a, b))): k for k, (a, b) in enumerate(E.tolist())}
    zset = {int(e) for e in np.asarray(cert.z).tolist()}
    cols = [(1 << a) | (1 << b) | (1 << c) for a, b, c in cx.tri_edges.tolist()]
    keep = np.zeros(n, bool)
    prot = [p for p in protected if p in cx]
    if prot:
        keep[cx.index(prot)] = True
    alive = np.ones(n, bool)
    P = np.array([pos.get(int(i), (math.nan, math.nan)) for i in ids.tolist()], float)

    def candidates():
        inc: dict[int, list[int]] = {}
        for e in zset:
            for x in E[e].tolist():
                inc.setdefault(int(x), []).append(e)
        out = []
        for c, es in inc.items():
            if len(es) != 2 or keep[c] or not alive[c] or not np.isfinite(P[c]).all():
                continue
            (a,) = set(E[es[0]].tolist()) - {c}
            (b,) = set(E[es[1]].tolist()) - {c}
            k = eidx.get((min(a, b), max(a, b)))
            if k is None or k in zset or not (alive[a] and alive[b]):
                continue
            crowd = min(float(np.hypot(*(P[a] - P[c]))), float(np.hypot(*(P[b] - P[c]))))
            out.append((crowd, c, a, b, es, k))
        return sorted(out)

    def shallow(a, b, c) -> bool:
        d = P[b] - P[a]
        ln = float(np.hypot(*d))
        if not ln > 0:
            return False
        nrm = np.array([-d[1], d[0]]) / ln
        if float(np.dot(P[c] - P[a], nrm)) < 0:
            nrm = -nrm
        return bool(side_depths(P[a], P[b], nrm, walls, 2.0 * room_depth)[1].max() <= room_depth)

    removed: list[int] = []
    progress = True
    while progress:
        progress = False
        for _, c, a, b, es, k in candidates():
            if not alive[c] or not (alive[a] and alive[b]) or not set(es) <= zset:
                continue
            if not shallow(a, b, c):
                continue
            z2 = zset ^ {es[0], es[1], k}
            alive[c] = False
            if _still_certified(cx, alive, cols, sum(1 << e for e in z2)):
                zset = z2
                removed.append(int(ids[c]))
                progress = True
            else:
                alive[c] = True
    return removed


def _stats(lengths: list[float], rv: float) -> dict:
    a = np.asarray(lengths, float) / rv
    if not a.size:
        return {"n": 0}
    return {"n": int(a.size), "mean": round(float(a.mean()), 3),
            "q10_50_90": [round(float(x), 2) for x in np.quantile(a, [.1, .5, .9])],
            "short": int((a < SHORT_RV).sum())}


def run(config: str, seed: int, timeout: float) -> dict:
    import swarmcover.coordinator.planner as planner
    import swarmcover.coordinator.topology.redundancy as red
    from swarmcover.run import default_robots_max
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    from swarmcover.world.groundtruth import euler_bound, ring_lengths
    from swarmcover.world.maps import build_map

    cfg = load_config(config)
    cfg, _, _ = default_robots_max(cfg, build_map(cfg), "")
    sim = SimLoop(cfg, seed=seed)
    rv = cfg.rv
    ends: list[tuple[str, bool, np.ndarray]] = []   # (reason, no lattice point, where) of
    #                                                 drives that ended done
    placed: dict[int, str] = {}                      # robot -> JobSpec.placed of its last job
    drives: dict[tuple[int, int], str] = {}          # (robot, task_id) of each test drive ->
    #                                                 its job's JobSpec.placed ("" if none)
    seen: set[tuple[int, int]] = set()               # drives whose end is booked
    flagged: set[int] = set()
    last: dict = {}
    passes = [0]

    sync = sim.coord.sync
    add_status = sync.add_status

    place = planner._place_on_lattice

    def observed_place(snap, jobs, *a, **kw):
        out = place(snap, jobs, *a, **kw)
        for job in jobs:
            r = snap.occupant.get(job.path[-1])
            if job.placed and r is not None:
                placed[r] = job.placed
        return out

    apply = sim._apply

    def observed_apply(actions):
        done, tasks = apply(actions)
        for rid, ts in tasks.items():
            for t in ts:
                if t.kind == "test_drive":   # a deployment's drive keeps its robot at a
                    # far touch (keep_after > 0); probes' and sweeps' never do
                    drives[(rid, t.task_id)] = placed.pop(rid, "") if t.keep_after > 0 else ""
        return done, tasks

    def on_status(st):
        key = (st.robot, st.task_id)
        why = st.reason or "clear"
        if st.task_state == "done" and key in drives and key not in seen and why in ORIGINS:
            seen.add(key)
            ids, pos, _ = sim.physics.state()
            k = list(ids).index(st.robot) if st.robot in ids else -1
            if k >= 0:
                ends.append((why, drives[key] == planner.Placed.SPEC, np.asarray(pos[k][:2], float)))
        return add_status(st)

    sync.add_status = on_status
    sim._apply = observed_apply
    planner._place_on_lattice = observed_place
    find = red.find_redundant

    def observed(cx, fence, certificate=None, protected=()):
        r = find(cx, fence, certificate, protected=protected)
        passes[0] += 1
        flagged.update(r.removed)
        if r.certificate.certified:
            last.update(cx=cx, fence=fence, cert=r.certificate, protected=set(protected))
        return r

    red.find_redundant = observed
    t0 = time.monotonic()
    try:
        res = sim.run(max_sim_s=20000.0, max_wall_s=timeout)
    finally:
        red.find_redundant = find
        planner._place_on_lattice = place
    cx = res.final
    occ = {v: r for v, r in zip(cx.vertices, cx.occupants) if r >= 0 and r in res.positions}
    pos = {v: np.asarray(res.positions[r][:2], float) for v, r in occ.items()}
    V = list(pos)
    P = np.array([pos[v] for v in V])
    clear = sim.wm.clearance(P)
    wall = {v: bool(c < WALL_RV * rv) for v, c in zip(V, clear)}
    by = {"ii": [], "wi": [], "ww": []}
    for a, b in zip(cx.edges[0::2], cx.edges[1::2]):
        if a in pos and b in pos:
            k = "ww" if wall[a] and wall[b] else ("wi" if wall[a] or wall[b] else "ii")
            by[k].append(float(np.hypot(*(pos[a] - pos[b]))))
    D = np.hypot(P[:, None, 0] - P[None, :, 0], P[:, None, 1] - P[None, :, 1])
    np.fill_diagonal(D, np.inf)
    nn = D.min(axis=1) / rv
    wmask = np.array([wall[v] for v in V])
    origin = {k: 0 for k in (*ORIGINS, "other", "no_lattice_point")}
    for v in V:
        if not wall[v]:
            continue
        best = min(((float(np.hypot(*(w - pos[v]))), why, spec) for why, spec, w in ends),
                   default=None, key=lambda e: e[0])
        if best is not None and best[0] <= MATCH_M:
            origin[best[1]] += 1
            origin["no_lattice_point"] += int(best[2])
        else:
            origin["other"] += 1
    d0 = sim.ccfg.d0
    wall_row = sum(max(3, math.ceil(length / d0)) for length in ring_lengths(sim.wm))
    extra = (global_extra(last["cx"], last["fence"], last["cert"], last["protected"])
             if last else None)
    thin = (fence_thin(last["cx"], last["cert"], last["protected"], pos, sim.wm.walls,
                       sim.ccfg.wall_keep) if last else None)
    bound = euler_bound(sim.wm, rv)["robots"]
    return {
        "name": cfg.name, "seed": seed, "certified": bool(res.certified), "robots": len(V),
        "robots_spawned": int(res.robots_spawned),
        "wall_vertices": int(wmask.sum()), "interior_vertices": int((~wmask).sum()),
        "wall_row_at_d0": wall_row, "d0_rv": round(d0 / rv, 3),
        "nn_wall_median_rv": round(float(np.median(nn[wmask])), 3) if wmask.any() else None,
        "nn_interior_median_rv": round(float(np.median(nn[~wmask])), 3) if (~wmask).any() else None,
        "edges": {k: _stats(v, rv) for k, v in by.items()},
        "wall_origin": origin,
        "redundant_over_run": len(flagged), "redundancy_passes": passes[0],
        "global_greedy_extra": None if extra is None else len(extra),
        "euler_bound": int(bound),
        "fence_thin": None if thin is None else len(thin),
        "robots_per_bound": round(len(V) / bound, 3) if bound else None,
        "robots_per_bound_thinned": (round((len(V) - len(thin)) / bound, 3)
                                     if bound and thin is not None else None),
        "wall_s": round(time.monotonic() - t0, 1),
    }


def main(argv=None) -> int:
    runs = run_configs(__doc__.split("\n\n")[0], run, argv)
    print("| config | seed | robots (spawned) | wall / row at d0 | interior | nn wall / interior (rv) "
          "| ww edges mean, short | wall origin wall/opening/room/clear/other (no lattice point) "
          "| redundant over run "
          "| global extra | fence thin (oracle) | robots / bound, thinned |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        ww, o = r["edges"]["ww"], r["wall_origin"]
        print(f"| {r['name']} | {r['seed']} | {r['robots']} ({r['robots_spawned']}) | {r['wall_vertices']} / "
              f"{r['wall_row_at_d0']} | {r['interior_vertices']} | {r['nn_wall_median_rv']} / "
              f"{r['nn_interior_median_rv']} | {ww.get('mean')}, {ww.get('short', 0)} of "
              f"{ww['n']} | {o['wall']}/{o['opening']}/{o['room']}/{o['clear']}/{o['other']} "
              f"({o['no_lattice_point']}) | "
              f"{r['redundant_over_run']} ({r['redundancy_passes']} passes) | "
              f"{r['global_greedy_extra']} | {r['fence_thin']} | {r['robots_per_bound']} -> "
              f"{r['robots_per_bound_thinned']} |")
    print(json.dumps({"bench": "robots", "runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How far a vertex moves each time a push replaces its robot (issue 19).

A push moves every robot on its path one vertex on (spec 4.3): the new occupant homes on
the bearings its predecessor saw to the vertex's neighbours, so whatever it misses by is
where the vertex is from then on, and the misses add up at the vertices many pushes pass
(the source's). This bench runs each config in-process (swarmcover.simloop, the same nodes
as ``swarmcover run``) and, every time a robot reports a goto to a vertex done (its Status:
state holding, task state done, after moving under that task), measures how far it
stands from where the vertex's previous robot stood at the last Complex. Reported per run:
the robots and mean edge length (x rv) of the last Complex; the replacements, their mean
and 50th/90th/99th percentile displacement (m), the same by the number of landmarks the
move's Task gave (fewer fix the point less well: one fixes a ray only) and by push step
(a new robot entering the source, a move along the path, the move onto the frontier
vertex, a settle). ``along``: the same replacements' signed miss along the move (from
where the mover started to where the vertex's previous robot stood; negative: short of
it, on the side it came from), mean and median (m), by landmarks. Without ``--oracle`` the
run is the one ``bench/coverage.py`` makes.

``--oracle``: each replacement is put (teleported, in the simulator) exactly where the
vertex's first robot stood once it reports done: the run without replacement drift, about
what a transport that never replaces a robot could save. The run's decisions are
otherwise unchanged.

    python bench/drift.py configs/open_room.toml --seeds 0
    python bench/drift.py configs/open_room.toml --seeds 0 --oracle
    python bench/drift.py configs/open_room.toml --seeds 0 --plot drift   # drift_open_room_s0.png

Measured (2026-11-28, seed 0, docs/measured.md, "Where the vertices drift"): open_room 966
replacements, mean 1.5 cm (one landmark: 24 moves at 15 cm, 26% of the total; two: 351 at
1.8 cm; four or more: 0.6 cm); pillar_hall 820 at 2.7 cm, 99th percentile 89 cm.
Drift-free (``--oracle``): open_room 136 -> 118 robots (mean edge 0.816 -> 0.864 rv),
pillar_hall 134 -> 122 (0.756 -> 0.794 rv). Along the move (2026-11-29, open_room seed
0): 0.28 cm short on average with homing's knee at 0.3 rad, 0.04 cm at 0.15.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import run_configs  # noqa: E402


def _by_landmarks(D: np.ndarray) -> dict:
    """D: rows (landmarks of the move, value) -> per landmark count (4 and more pooled):
    n, mean of the value and its share of the values' sum."""
    tot = float(D[:, 1].sum()) or 1.0
    by = {}
    for k in (1, 2, 3, 4):
        m = D[(D[:, 0] == k) if k < 4 else (D[:, 0] >= 4), 1]
        if len(m):
            by["4+" if k == 4 else str(k)] = dict(n=int(len(m)), mean=float(m.mean()),
                                                  share=float(m.sum() / tot))
    return by


def displacement_table(rows: list[tuple[int, float]]) -> dict:
    """rows: (landmarks of the move, displacement m) -> summary: n, mean, p50/p90/p99 (m),
    and per landmark count (4 and more pooled) n, mean (m) and share of the total."""
    if not rows:
        return dict(n=0)
    D = np.asarray(rows, float).reshape(-1, 2)
    d = D[:, 1]
    return dict(n=int(len(d)), mean=float(d.mean()), p50=float(np.percentile(d, 50)),
                p90=float(np.percentile(d, 90)), p99=float(np.percentile(d, 99)),
                by_landmarks=_by_landmarks(D))


def along_table(rows: list[tuple[int, float]]) -> dict:
    """rows: (landmarks of the move, signed miss along it, m) -> n, mean, median (m), and
    per landmark count (4 and more pooled) n and mean (m)."""
    if not rows:
        return dict(n=0)
    D = np.asarray(rows, float).reshape(-1, 2)
    by = {k: dict(n=v["n"], mean=v["mean"]) for k, v in _by_landmarks(D).items()}
    return dict(n=int(len(D)), mean=float(D[:, 1].mean()), p50=float(np.median(D[:, 1])),
                by_landmarks=by)


def _step_kind(jobs, rid: int, tid: int) -> str:
    """Which push step robot ``rid``'s task ``tid`` is: "enter" (a new robot to the
    source), "to_f" (the move onto the frontier vertex), "move" (another move along the
    path), "settle", another step's name, or "other" (not a push's)."""
    for job in jobs:
        for s in job.steps:
            if s.robot == rid and s.task_id == tid:
                if s.name == "move" and s.t_index == len(job.spec.path) - 2:
                    return "to_f"
                return str(s.name)
    return "other"


def _shot(cx, phys) -> dict:
    """The swarm at one Complex: member positions (m) by vertex, its edges, its frontier."""
    pos = {v: tuple(phys.robots[o].body.position) for v, o in zip(cx.vertices, cx.occupants)
           if o >= 0 and phys.has(o)}
    E = list(cx.edges)
    edges = [(E[2 * k], E[2 * k + 1]) for k in range(len(E) // 2)]
    return dict(cycle=cx.cycle, t=cx.t, pos=pos, edges=edges, frontier=set(cx.frontier))


def _plot(shots: list[dict], wm, path: str, title: str, panels: int = 4) -> None:
    """The swarm at ``panels`` cycles a quarter of the run apart (the last one included): each
    Rips edge coloured by its true length (red short, green d0 to rv), frontier edges
    blue, robots nearer than 0.6 rv to another red."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.spatial import cKDTree

    from swarmcover.bus.messages import WorldInfo
    from swarmcover.viz.figures import draw_map
    info = WorldInfo(name=title, rv=1.0, robot_radius=0.06, dt=0.05, mode="lockstep", seed=0,
                     **wm.info_fields())           # the map only: walls, obstacles, sources
    pick = sorted({round(k * (len(shots) - 1) / panels) for k in range(1, panels + 1)})
    fig, axs = plt.subplots(1, len(pick), figsize=(4.5 * len(pick), 4), squeeze=False)
    cmap = plt.get_cmap("RdYlGn")
    for ax, k in zip(axs[0], pick):
        sh = shots[k]
        draw_map(ax, info)
        pos = sh["pos"]
        for j, (a, b) in enumerate(sh["edges"]):
            if a in pos and b in pos:
                pa, pb = np.array(pos[a]), np.array(pos[b])
                front = j in sh["frontier"]
                ax.plot([pa[0], pb[0]], [pa[1], pb[1]], lw=1.6 if front else 0.7,
                        color="tab:blue" if front else cmap((np.hypot(*(pa - pb)) - 0.4) / 0.6))
        P = np.array(list(pos.values()), float).reshape(-1, 2)
        nn = cKDTree(P).query(P, 2)[0][:, 1] if len(P) > 1 else np.full(len(P), np.inf)
        ax.scatter(P[:, 0], P[:, 1], s=6, zorder=3, c=np.where(nn < 0.6, "red", "black"))
        ax.set_aspect("equal")
        ax.set_title(f"cycle {sh['cycle']}, t = {sh['t']:.0f} s, {len(P)} robots", fontsize=9)
        ax.axis("off")
    fig.suptitle(title)
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)


def run(config: str, seed: int, timeout: float, args) -> dict:
    from swarmcover.run import default_robots_max
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    from swarmcover.world.maps import build_map
    cfg = load_config(config)
    cfg, _, _ = default_robots_max(cfg, build_map(cfg), "")
    sim = SimLoop(cfg, seed=seed)
    phys = sim.physics
    n_lm: dict[tuple[int, int], int] = {}       # (robot, task id) -> landmarks of its goto
    apply = sim._apply

    def seen_apply(actions):                   # the coordinator's Tasks, as sent
        done, tasks = apply(actions)
        for rid, ts in tasks.items():
            for t in ts:
                if t.kind == "goto":
                    n_lm[(rid, t.task_id)] = len(t.landmarks)
        return done, tasks
    sim._apply = seen_apply
    last_pos: dict[int, tuple[float, float, int]] = {}   # vertex -> (x, y, robot) at last Complex
    first: dict[int, tuple[float, float]] = {}           # vertex -> where its first robot stood
    moved: dict[int, int] = {}                           # robot -> task id it moved under
    start: dict[tuple[int, int], tuple[float, float]] = {}   # (robot, task) -> where it set off
    reported: set[tuple[int, int]] = set()
    rows: list[tuple[int, float]] = []
    along: list[tuple[int, float]] = []                  # (landmarks, signed miss along the move)
    kinds: list[str] = []                                # the push step of each row
    shots: list[dict] = []                               # --plot: the swarm at each Complex
    ncx = 0
    t0 = time.monotonic()
    while not sim.step():
        if sim.t > 20_000 or time.monotonic() - t0 > timeout:
            break
        if len(sim.complexes) > ncx:
            ncx = len(sim.complexes)
            cx = sim.complexes[-1]
            if args.plot:
                shots.append(_shot(cx, phys))
            for v, o in zip(cx.vertices, cx.occupants):
                if o >= 0 and phys.has(o):
                    x, y = phys.robots[o].body.position
                    last_pos[v] = (x, y, o)
                    first.setdefault(v, (x, y))
        for rid, core in sim.agents.items():
            b = core.beh
            if b.task is None:
                continue
            tid = b.task.task_id
            if b.state.value == "moving":
                if moved.get(rid) != tid:
                    start[(rid, tid)] = tuple(phys.robots[rid].body.position)
                moved[rid] = tid
                continue
            if (b.state.value != "holding" or b.task_state.value != "done"
                    or moved.get(rid) != tid or (rid, tid) in reported or (rid, tid) not in n_lm):
                continue
            reported.add((rid, tid))
            v = b.vertex
            prev = last_pos.get(v)
            if prev is None or prev[2] == rid:
                continue
            x, y = phys.robots[rid].body.position
            rows.append((n_lm[(rid, tid)], math.hypot(x - prev[0], y - prev[1])))
            s0 = start.get((rid, tid))
            if s0 is not None and math.dist(s0, prev[:2]) > 0.2:   # entries start on it
                ux, uy = prev[0] - s0[0], prev[1] - s0[1]
                along.append((n_lm[(rid, tid)],
                              ((x - prev[0]) * ux + (y - prev[1]) * uy) / math.hypot(ux, uy)))
            kinds.append(_step_kind(sim.dep.pushes.jobs, rid, tid))
            if args.oracle and v in first:
                phys.teleport(rid, first[v][0], first[v][1], 0.0)
    cx = sim.complexes[-1] if sim.complexes else None
    robots = sum(1 for o in cx.occupants if o >= 0) if cx is not None else 0
    spacing = None
    if cx is not None:
        sh = _shot(cx, phys)
        lens = [math.dist(sh["pos"][a], sh["pos"][b]) for a, b in sh["edges"]
                if a in sh["pos"] and b in sh["pos"]]
        spacing = float(np.mean(lens)) / cfg.rv if lens else None
    out = dict(name=Path(config).stem, seed=seed, oracle=bool(args.oracle),
               certified=bool(sim.dep.certified), robots=robots, mean_spacing=spacing,
               sim_time_s=float(sim.done_t if sim.done_t is not None else sim.t),
               cycles=int(sim.dep.cycle), replacements=displacement_table(rows),
               along=along_table(along),
               by_step={k: displacement_table([r for r, kk in zip(rows, kinds) if kk == k])
                        for k in sorted(set(kinds))})
    if args.plot and shots:
        name = f"{args.plot.removesuffix('.png')}_{out['name']}_s{seed}{'_oracle' if args.oracle else ''}.png"
        _plot(shots, sim.wm, name, f"{out['name']} seed {seed}{' (oracle)' if args.oracle else ''}")
        out["plot"] = name
    r = out["replacements"]
    if r.get("n"):
        by = ", ".join(f"{k}: {v['n']} x {100 * v['mean']:.1f} cm ({100 * v['share']:.0f}%)"
                       for k, v in r["by_landmarks"].items())
        print(f"  {out['name']} seed {seed}{' oracle' if args.oracle else ''}: "
              f"certified={out['certified']} robots={robots} sim={out['sim_time_s']:.0f}s "
              f"spacing={spacing or 0:.3f} rv "
              f"replacements={r['n']} mean {100 * r['mean']:.2f} cm p90 {100 * r['p90']:.1f} "
              f"p99 {100 * r['p99']:.1f}; by landmarks {by}", flush=True)
        print("    by step: " + ", ".join(
            f"{k} {v['n']} x {100 * v['mean']:.1f} cm" for k, v in out["by_step"].items()),
              flush=True)
        al = out["along"]
        if al.get("n"):
            print(f"    along the move: {al['n']} at {100 * al['mean']:+.2f} cm (median "
                  f"{100 * al['p50']:+.2f}; negative: short); by landmarks " + ", ".join(
                      f"{k}: {100 * v['mean']:+.2f}" for k, v in al["by_landmarks"].items()),
                  flush=True)
    return out


def main(argv=None) -> int:
    def flags(ap):
        ap.add_argument("--oracle", action="store_true",
                        help="put every replacement where its vertex's first robot stood")
        ap.add_argument("--plot", metavar="PREFIX", default="",
                        help="also draw the swarm at four cycles to PREFIX_<config>_s<seed>.png")
    runs = run_configs(__doc__.splitlines()[0], run, argv, add_args=flags)
    print(json.dumps(dict(bench="drift", runs=runs)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

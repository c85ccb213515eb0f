"""How far the coordinator's shape estimate is from where the robots are (issue 19).

New robots go to lattice points of the swarm's shape, which the coordinator estimates from
bearings alone (coordinator/topology/shape.py ``estimate_shape``, called by the planner's
lattice placement). This bench runs each config in-process (swarmcover.simloop, the same
nodes as ``swarmcover run``), observes every estimate the planner makes (a wrapper around
``estimate_shape``; the run's decisions are unchanged) and compares it with the robots'
true positions when the cycle's snapshot (the bearings it estimates from) was taken:

* the estimate is fitted to the truth by one similarity (rotation, scale, translation:
  the estimate's frame is the root robot's, its scale the commanded lengths');
* each robot's **local error** is then what is left after a further translation fitted to
  the robots within ``--radius`` (default 2.5 rv) of it: a lattice target is placed
  relative to the robots near it, so a drift of the whole swarm does not count (a part at
  the wrong scale shows on both sides of its hinge: the one similarity compromises);
* the **worst edge ratio** is the largest estimated / true length of an edge (a part
  whose scale the bearings leave free shows up as an edge many times its length).

Reported per run: estimates observed, robots compared, local error quantiles (rv), the
share of robots more than 0.2 rv off, and the worst edge ratio. ``--prior W`` sets
``shape.EDGE_PRIOR`` for the run (0: the estimate before the length prior).

    python bench/shape.py configs/pillar_hall.toml --seeds 2
    python bench/shape.py configs/pillar_hall.toml --seeds 2 --prior 0

Measured (2026-11-27, seed 0, every estimate of the run), prior 0.05 against 0: local
error 99th percentile pillar_hall 0.027 against 0.90 rv, structured 0.055 against 0.80;
robots more than 0.2 rv off 0% against 3.5%, 0.2% against 3.8%; worst edge ratio 1.09
against 8.45, 2.66 against 22.4.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import run_configs  # noqa: E402

OFF_RV = 0.2           # a robot more than this (x rv) off counts as misplaced


def local_errors(est: np.ndarray, true: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """Each point's local error (same unit as ``true``) and the scale of the fit.

    est, true: (n, 2) estimated and true positions of the same points (n >= 3). The
    estimate is fitted to the truth by the least-squares similarity (Umeyama, no
    reflection); each point's error is then what remains after a translation fitted to
    the points whose true position is within ``radius`` of its own."""
    est = np.asarray(est, float).reshape(-1, 2)
    true = np.asarray(true, float).reshape(-1, 2)
    a0, b0 = est.mean(0), true.mean(0)
    A, B = est - a0, true - b0
    U, s, Vt = np.linalg.svd(A.T @ B)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    D = np.diag([1.0, d])
    R = U @ D @ Vt
    var = float((A ** 2).sum())
    scale = float((s * np.diag(D)).sum() / var) if var > 0 else 1.0
    fit = scale * A @ R + b0
    near = np.hypot(*(true[:, None, :] - true[None, :, :]).transpose(2, 0, 1)) <= radius
    out = np.empty(len(true))
    for i in range(len(true)):
        off = (true[near[i]] - fit[near[i]]).mean(0)
        out[i] = float(np.hypot(*(fit[i] + off - true[i])))
    return out, scale


def run(config: str, seed: int, timeout: float, prior: float | None, radius_rv: float) -> dict:
    import swarmcover.coordinator.topology.shape as shape
    from swarmcover.run import default_robots_max
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    from swarmcover.world.maps import build_map

    cfg = load_config(config)
    cfg, _, _ = default_robots_max(cfg, build_map(cfg), "")
    sim = SimLoop(cfg, seed=seed)
    rv = cfg.rv
    errs: list[np.ndarray] = []
    worst_edge = [1.0]
    calls = [0]
    estimate = shape.estimate_shape
    prior_was = shape.EDGE_PRIOR

    take = sim.dep._take_snapshot
    at: dict[int, np.ndarray] = {}

    def taken():
        # the robots' true positions when the snapshot is taken: the estimate is of that
        # snapshot's shape (a push re-planned later in the cycle reuses it, robots moving)
        snap = take()
        ids, pos, _ = sim.physics.state()
        at.clear()
        at.update({int(r): np.asarray(p[:2], float) for r, p in zip(ids, pos)})
        return snap

    def observed(nbrs, headings, known=(), *, root=None, default_edge=0.85):
        X = estimate(nbrs, headings, known, root=root, default_edge=default_edge)
        calls[0] += 1
        snap = sim.dep.snapshot
        vs = [v for v in X if snap is not None and snap.occupant.get(v) in at]
        if len(vs) >= 3:
            E = np.array([X[v] for v in vs])
            T = np.array([at[snap.occupant[v]] for v in vs]) / rv
            e, k = local_errors(E, T, radius_rv)
            errs.append(e)
            col = {v: i for i, v in enumerate(vs)}
            for a in vs:
                for b in nbrs.get(a, {}):
                    if b in col and a < b:
                        t = float(np.hypot(*(T[col[a]] - T[col[b]])))
                        if t > 1e-6:
                            r = k * float(np.hypot(*(E[col[a]] - E[col[b]]))) / t
                            worst_edge[0] = max(worst_edge[0], r)
        return X

    shape.estimate_shape = observed
    sim.dep._take_snapshot = taken
    if prior is not None:
        shape.EDGE_PRIOR = float(prior)
    t0 = time.monotonic()
    try:
        res = sim.run(max_sim_s=20000.0, max_wall_s=timeout)
    finally:
        shape.estimate_shape = estimate
        shape.EDGE_PRIOR = prior_was
    e = np.concatenate(errs) if errs else np.zeros(0)
    q = (lambda p: round(float(np.quantile(e, p)), 4)) if len(e) else (lambda p: None)
    return {
        "name": cfg.name, "seed": seed, "edge_prior": shape.EDGE_PRIOR if prior is None else prior,
        "certified": bool(res.certified), "robots_spawned": int(res.robots_spawned),
        "estimates": calls[0], "robots_compared": int(len(e)),
        "local_error_rv": {"q50": q(0.5), "q90": q(0.9), "q99": q(0.99),
                           "max": round(float(e.max()), 4) if len(e) else None},
        "share_off": round(float((e > OFF_RV).mean()), 4) if len(e) else None,
        "worst_edge_ratio": round(worst_edge[0], 2),
        "wall_s": round(time.monotonic() - t0, 1),
    }


def _flags(ap) -> None:
    ap.add_argument("--prior", type=float, default=None,
                    help="shape.EDGE_PRIOR for the runs (0: no length prior)")
    ap.add_argument("--radius", type=float, default=2.5,
                    help="local fit radius, x rv (default 2.5)")


def main(argv=None) -> int:
    runs = run_configs(__doc__.split("\n\n")[0],
                       lambda c, s, timeout, a: run(c, s, timeout, a.prior, a.radius),
                       argv, add_args=_flags)
    print("| config | seed | prior | estimates | robots compared | local error q50 / q90 / q99 / max (rv) "
          f"| share > {OFF_RV} rv | worst edge ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for r in runs:
        le = r["local_error_rv"]
        print(f"| {r['name']} | {r['seed']} | {r['edge_prior']} | {r['estimates']} | {r['robots_compared']} "
              f"| {le['q50']} / {le['q90']} / {le['q99']} / {le['max']} | {r['share_off']} "
              f"| {r['worst_edge_ratio']} |")
    print(json.dumps({"bench": "shape", "runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

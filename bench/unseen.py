"""The whole swarm on maps no config was tuned on: does "certified" mean covered there?

``bench/truth.py`` judges the coordinator's rules on 500 random maps, but executes each
deployment geometrically (its sweeps are ``bench/sweep.py``'s emulation). This bench runs
the product itself on the same random maps: every robot an agent (bearing-only
controllers, the real wall sweep, touch sensors), pymunk physics, the coordinator, all in
one process (``swarmcover.simloop``, the same nodes as ``swarmcover run``), and judges
the end by the world's ground truth (``swarmcover.run.compute_summary``: raster coverage
and the reachable uncovered area behind a certificate).

Each map (``bench.truth.make_map``: rectangles, L-shapes, boxes, clutter, two rooms joined
by a 0.3-1.2 rv door; a third of the sources 0.3 m from a wall facing it; 0.5 deg bearing
noise on odd maps) is written as a run config into ``--out`` (default: a temporary
folder), so any run can be repeated with ``swarmcover run CONFIG``. With ``--ros K`` every
K-th map is turned 5-40 deg and written as a ROS map_server map (PGM + YAML at 0.05 m):
walls in raster steps, loaded through the world's map import.

    python bench/unseen.py --maps 20 --jobs 2            # maps 0-19 of campaign seed 0
    python bench/unseen.py --maps 40 --seed 1 --ros 2 --out /tmp/unseen
    python bench/unseen.py --maps 20 --doors --jobs 2    # doors at the guarantee's edge

Prints a row per map, a summary, and one JSON object as the last line. A false
certificate is what ``swarmcover run`` calls one: certified while more than
``FALSE_CERT_M2`` x rv^2 of free area a robot could reach is uncovered.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.common import eprint  # noqa: E402
from bench.truth import make_map  # noqa: E402
from swarmcover.world.maps import write_ros_map  # noqa: E402

CELL = 0.05   # m, the ROS maps' resolution (configs/cave.toml's)


def _pts(a) -> str:
    return "[" + ", ".join(f"[{x:.4f}, {y:.4f}]" for x, y in np.asarray(a, float)) + "]"


def _write_pgm(pm, stem: Path) -> None:
    """``pm`` (a raster-traced map: rings on a CELL grid) as ``stem``.pgm + .yaml: free
    where a cell's centre is inside."""
    lo = pm.outer.min(axis=0) - 2 * CELL
    nx, ny = np.round((pm.outer.max(axis=0) + 2 * CELL - lo) / CELL).astype(int)
    xs, ys = lo[0] + (np.arange(nx) + 0.5) * CELL, lo[1] + (np.arange(ny) + 0.5) * CELL
    gx, gy = np.meshgrid(xs, ys)
    free = pm.contains(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(ny, nx)
    write_ros_map(stem, free, CELL, np.round(lo, 4))


def write_config(seed: int, index: int, ros: bool, folder: Path, coordinator=(),
                 doors: bool = False):
    """Map ``index`` of campaign ``seed`` as a run config in ``folder``, with the
    ``[coordinator]`` lines ``coordinator`` (``KEY = VALUE`` strings); ``doors``: the door
    campaign's map (``bench.truth.make_map``: two rooms, a 0.40-0.50 rv door); returns
    (path, case)."""
    case = make_map(seed, index, CELL if ros else 0.0, doors)
    name = f"unseen_s{seed}_m{index}" + ("_doors" if doors else "") + ("_ros" if ros else "")
    lines = [f'# bench/unseen.py: map {index} of campaign {seed} ({case.kind}'
             + (f", door {case.door_w:.2f} rv" if case.door_w else "") + ")",
             f'name = "{name}"', "rv = 1.0", "", "[map]"]
    if ros:
        _write_pgm(case.pm, folder / name)
        lines.append(f'ros_map = "{name}.yaml"')
    else:
        lines.append(f"boundary = {_pts(case.pm.outer)}")
        lines.append("obstacles = [" + ", ".join(
            f'{{type = "polygon", points = {_pts(h)}}}' for h in case.pm.holes) + "]")
    x, y = case.source
    theta = max(-3.1415, min(3.1415, case.source_dir))   # printed to 4 places: inside +-pi
    lines += [f"sources = [{{x = {x:.4f}, y = {y:.4f}, theta = {theta:.4f}}}]", "",
              "[robots]", "radius = 0.06", 'kind = "holonomic"', "",
              "[sensing]", f"noise_deg = {case.noise_deg}", "", "[world]", "dt = 0.05",
              'mode = "lockstep"', f"seed = {index}", ""]
    if coordinator:
        lines += ["[coordinator]", *coordinator, ""]
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines))
    return path, case


def judge(config: str, row: dict, timeout: float) -> dict:
    """Run ``config`` in-process (seed 0) and return ``row`` with the ground truth's
    verdict on its end (a crash is a result here: the row says which map and why)."""
    from bench.coverage import run_inproc
    t0 = time.monotonic()
    try:
        s = run_inproc(config, 0, timeout)
    except Exception as e:
        return dict(row, error=f"{type(e).__name__}: {e}", wall_s=time.monotonic() - t0)
    keep = ("certified", "stop_reason", "coverage", "coverage_complex", "false_certificate", "uncovered_reachable_m2",
            "false_certificate_where", "robots_used", "euler_bound", "robots_per_bound",
            "sim_time_s", "sim_s_per_robot", "cycles")
    audit = (s.get("fence_audit") or {}).get("by_why")
    return dict(row, **{k: s.get(k) for k in keep}, fence_audit=audit,
                wall_s=round(time.monotonic() - t0, 1))


def audit_totals(rows: list[dict]) -> dict:
    """The certified runs' closed sides per reason ('probes' is evidence, the rest
    inference): sides, with room behind (free space deeper than the no-room depth), and of
    those not covered (summary.json's ``fence_audit``)."""
    tot: dict[str, dict] = {}
    for r in rows:
        if not r.get("certified"):
            continue
        for why, a in (r.get("fence_audit") or {}).items():
            t = tot.setdefault(why, dict(sides=0, room_behind=0, room_uncovered=0, maps=0))
            t["maps"] += 1
            for k in ("sides", "room_behind", "room_uncovered"):
                t[k] += int(a.get(k, 0))
    return dict(sorted(tot.items(), key=lambda kv: -kv[1]["sides"]))


def run_map(job) -> dict:
    """One map: write its config, run it in-process, judge it by ground truth."""
    seed, index, ros, folder, timeout, *more = job
    path, case = write_config(seed, index, ros, Path(folder), *more)
    row = dict(seed=seed, index=index, kind=case.kind, ros=ros, facing_wall=case.facing_wall,
               door_rv=case.door_w, noise_deg=case.noise_deg, config=str(path))
    return judge(str(path), row, timeout)


def summarise(rows: list[dict]) -> dict:
    ok = [r for r in rows if "error" not in r]
    cert = [r for r in ok if r["certified"]]
    rpb = [r["robots_per_bound"] for r in cert if r.get("robots_per_bound")]
    return dict(maps=len(rows), errors=len(rows) - len(ok), certified=len(cert),
                false_certificates=sum(bool(r["false_certificate"]) for r in ok),
                not_certified=[r["index"] for r in ok if not r["certified"]],
                false_maps=[r["index"] for r in ok if r["false_certificate"]],
                min_coverage_certified=min((r["coverage"] for r in cert), default=None),
                min_coverage_complex=min((r["coverage_complex"] for r in cert
                                          if r.get("coverage_complex") is not None), default=None),
                robots_per_bound_mean=(sum(rpb) / len(rpb)) if rpb else None,
                sim_s_per_robot_mean=(sum(r["sim_s_per_robot"] for r in cert) / len(cert))
                if cert else None, closed_sides=audit_totals(rows))


def _head(r: dict) -> str:
    return (f"map {r['index']:3d} {r['kind']:9s}{' ros' if r['ros'] else '    '}"
            f" door {r['door_rv'] or 0:.2f} {'facing' if r['facing_wall'] else '      '}")


def line(r: dict, head) -> str:
    """One map's row: ``head(r)`` (what the map is), then the run's verdict."""
    if "error" in r:
        return f"{head(r)}  ERROR {r['error']}"
    warn = "  FALSE CERTIFICATE at %s" % (r.get("false_certificate_where"),) \
        if r["false_certificate"] else ""
    return (f"{head(r)}  {'certified' if r['certified'] else r['stop_reason']:<12s}"
            f" coverage {100 * r['coverage']:6.2f}%"
            + (f" (complex {100 * r['coverage_complex']:6.2f}%)" if r.get("coverage_complex")
               is not None else "")
            + f"  robots {r['robots_used']:3d}"
            f" / bound {r['euler_bound']}  sim {r['sim_time_s']:7.1f} s"
            f"  wall {r['wall_s']:5.1f} s{warn}")


def campaign(ap, a, bench: str, make_jobs, run_map, head) -> int:
    """Run ``run_map`` on each of ``make_jobs(folder)`` over ``a.jobs`` worker processes
    (``a.out`` or a temporary folder), a row per map on stderr as it ends, then every row,
    the summary and one JSON object on stdout; 1 on a false certificate or an error."""
    for name in ("maps", "jobs"):
        if getattr(a, name) < 1:
            ap.error(f"--{name} must be >= 1, got {getattr(a, name)}")
    if a.start < 0:
        ap.error("--start must be >= 0")
    tmp = None
    if a.out:
        folder = Path(a.out)
        folder.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix=f"{bench}-")
        folder = Path(tmp.name)
    jobs = make_jobs(str(folder))
    rows: list[dict] = []
    t0 = time.monotonic()

    def took(r):
        rows.append(r)
        eprint(f"[{len(rows)}/{len(jobs)} {time.monotonic() - t0:.0f} s] {line(r, head)}")

    if a.jobs > 1:
        import multiprocessing as mp
        with mp.get_context("spawn").Pool(a.jobs, maxtasksperchild=1) as pool:
            for r in pool.imap_unordered(run_map, jobs):
                took(r)
    else:
        for j in jobs:
            took(run_map(j))
    rows.sort(key=lambda r: r["index"])
    for r in rows:
        print(line(r, head))
    s = summarise(rows)
    s["wall_s"] = round(time.monotonic() - t0, 1)
    print(f"\n{s['certified']} of {s['maps']} certified, {s['false_certificates']} false "
          f"certificates, {s['errors']} errors; not certified: {s['not_certified'] or 'none'}; "
          f"robots / Euler bound {s['robots_per_bound_mean'] or math.nan:.2f} on average; "
          f"wall {s['wall_s']} s")
    for why, t in s["closed_sides"].items():
        print(f"  closed '{why}': {t['sides']} sides on {t['maps']} maps, {t['room_behind']} "
              f"with room behind, {t['room_uncovered']} of those uncovered")
    if a.out:
        (folder / "results.json").write_text(json.dumps({"summary": s, "maps": rows}, indent=1))
    print(json.dumps({"bench": bench, "seed": a.seed, "summary": s, "maps": rows}))
    if tmp is not None:
        tmp.cleanup()
    return 1 if s["false_certificates"] or s["errors"] else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", type=int, default=20, help="maps START .. START+N-1")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0, help="campaign (bench/truth.py's --seed)")
    ap.add_argument("--doors", action="store_true",
                    help="bench/truth.py's door campaign: every map two rooms joined by a "
                         "0.40-0.50 rv door in a wall 0.05-0.30 m thick")
    ap.add_argument("--ros", type=int, default=0, metavar="K",
                    help="write every K-th map as a turned ROS map (PGM + YAML); 0: none")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--timeout", type=float, default=900.0, help="wall seconds per map")
    ap.add_argument("--out", help="folder for the configs and results.json (default: temporary)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a [coordinator] field for every map, as TOML, e.g. sweep_lenses=false")
    a = ap.parse_args(argv)
    if a.ros < 0:
        ap.error("--ros must be >= 0")
    sets = []
    for kv in a.set:
        k, eq, v = kv.partition("=")
        if not eq or not k.strip():
            ap.error(f"--set {kv!r}: expected FIELD=VALUE")
        sets.append(f"{k.strip()} = {v.strip()}")
    return campaign(ap, a, "unseen", lambda folder: [
        (a.seed, i, bool(a.ros) and i % a.ros == a.ros - 1, folder, a.timeout, tuple(sets),
         a.doors)
        for i in range(a.start, a.start + a.maps)], run_map, _head)

if __name__ == "__main__":
    sys.exit(main())

"""Coverage benchmark: every config in configs/ (or those named), lockstep, fixed seeds.

Default: the real distributed system (`swarmcover run --lockstep`, one process per robot).
``--inproc``: the same parts in one process (swarmcover.simloop), faster, for tuning.
``--both``: each config and seed both ways in this invocation, with the two runs' agreement
(robots, cycles, simulated time: the one runtime, issue 17) and the distributed wall time
over the in-process one (issue 18). Prints each run's numbers against the targets, progress
on stderr, and one JSON object as the last line.

    python bench/coverage.py                       # all configs, distributed
    python bench/coverage.py configs/small.toml --inproc --seeds 0 1 2
    python bench/coverage.py --both --seeds 0      # every config both ways
    python bench/coverage.py --inproc --dropout 0.05   # 5% of the sightings lost

Targets (issue 19, against the Euler lower bound ``euler_bound`` that summary.json reports
for every run): certified with ground-truth coverage >= 99.5%; robots_used <= 1.25 x
euler_bound; simulated time per robot used <= 5 s. Each run also reports the push's own
floor of time per robot (``push_floor_s``: its mean move plus its mean entry, as the
coordinator's Complex carries them: about the pace at which robots leave a source, not a
proven bound, since an entry may overlap the move before it) and the time per robot over
it, with the targets proposed in their place (``proposed``: robots <= 1.15 x the bound
at the deployment spacing d0, ``euler_bound_d0``; time <= 1.5 x the push floor on maps of
100 robots or more). Issue 6's (ratio_same_spacing <= 1.10 open_room, <= 1.15 structured; ratio <= 1.35
open_room; cycles <= 0.5 x robots) are printed per run too. The last table has one row per config and seed, each target marked ok/MISS.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

def _progress(t0: float, robots_max: int, every_s: float = 60.0):
    """An in-process run's progress on stderr (``SimLoop.run``'s on_cycle), at most once
    per ``every_s`` of wall time, starting as ``swarmcover run``'s progress line does."""
    from swarmcover.run import cycle_progress
    last = [t0]

    def show(_sim, cx) -> None:
        now = time.monotonic()
        if now - last[0] >= every_s:
            last[0] = now
            print(f"  {cycle_progress(cx.cycle, cx, robots_max)} | sim {cx.t:.0f}s | "
                  f"wall {now - t0:.0f}s", file=sys.stderr, flush=True)
    return show


def run_distributed(config: str, seed: int, out: Path, timeout: float) -> dict:
    cmd = [sys.executable, "-m", "swarmcover", "run", config, "--lockstep", "--seed", str(seed),
           "--out", str(out), "--quiet", "--port", str(_free_port()), "--wall-timeout", str(timeout)]
    subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=timeout + 120)
    from swarmcover.world.config import load_config
    return dict(json.loads((out / "summary.json").read_text()),
                dropout=load_config(config).sensing.dropout)


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_inproc(config: str, seed: int, timeout: float, overrides: dict | None = None,
               dropout: float | None = None) -> dict:
    from swarmcover.bus.messages import Truth
    from swarmcover.run import compute_summary
    from swarmcover.simloop import SimLoop
    from swarmcover.world.config import load_config
    from swarmcover.run import default_robots_max
    from swarmcover.world.maps import build_map
    cfg = load_config(config)
    if dropout is not None:   # every camera frame loses each sighting with this probability
        cfg = replace(cfg, sensing=replace(cfg.sensing, dropout=dropout))
    cfg, _, limits = default_robots_max(cfg, build_map(cfg), "")  # as `run` does
    sim = SimLoop(cfg, seed=seed, coordinator_overrides=overrides)
    t0 = time.monotonic()
    res = sim.run(max_sim_s=20_000, max_wall_s=timeout, on_cycle=_progress(t0, limits["robots_max"]))
    ids = sorted(r for r in res.positions if r in sim.agents)
    truth = Truth(ids=ids, x=[res.positions[r][0] for r in ids],
                  y=[res.positions[r][1] for r in ids], theta=[0.0] * len(ids),
                  live=[False] * len(ids), t=res.sim_time_s)
    extra = dict(certified=res.certified, cycles=res.cycles, sim_time_s=res.sim_time_s,
                 stop_reason=_inproc_reason(res), stop_detail=res.stop_reason,
                 wall_time_s=time.monotonic() - t0, robots_spawned=res.robots_spawned,
                 failures_healed=res.deployer.failures_healed, config=config, seed=seed,
                 mode="inproc", dropout=cfg.sensing.dropout, d0_m=sim.ccfg.d0, **limits)
    return compute_summary(cfg, sim.wm, truth, res.final, extra)


ROBOTS_PER_BOUND_MAX = 1.25
SIM_S_PER_ROBOT_MAX = 5.0
# the targets proposed in issue 19's notes (stop 41 on), where the two above are out of
# reach: robots against the bound at the deployment spacing d0 (the bound at rv is
# (rv / d0)^2 ~ 1.23 times lower in the area term, so 1.25 there leaves a swarm at d0 about
# 1% for its walls and its errors); time against the push's own pace, judged on maps of
# at least 100 robots (on small maps the walls' sweeps and drives are most of the time)
PROPOSED_PER_BOUND_D0_MAX = 1.15
PROPOSED_OVER_FLOOR_MAX = 1.5
PROPOSED_OVER_FLOOR_MIN_ROBOTS = 100


def targets(s: dict) -> dict:
    """Issue 19's verdicts for one run: name -> (value text, ok)."""
    cov = s.get("coverage") or 0.0
    used, bound = s.get("robots_used") or 0, s.get("euler_bound")
    rpb = used / bound if bound else None           # also when not certified, for the table
    spr = s.get("sim_s_per_robot")
    return {
        "certified, coverage >= 99.5%": (f"{'yes' if s.get('certified') else 'no'}, "
                                         f"{100 * cov:.2f}%",
                                         bool(s.get("certified")) and cov >= 0.995),
        f"robots / bound <= {ROBOTS_PER_BOUND_MAX}": (
            f"{used} / {bound} = {rpb:.2f}" if rpb is not None else "-",
            bool(s.get("certified")) and rpb is not None and rpb <= ROBOTS_PER_BOUND_MAX),
        f"sim s / robot <= {SIM_S_PER_ROBOT_MAX:g}": (
            f"{spr:.1f}" if spr is not None else "-",
            spr is not None and spr <= SIM_S_PER_ROBOT_MAX),
    }


def proposed(s: dict) -> dict:
    """The targets proposed in place of issue 19's (``PROPOSED_*``): name -> (text, ok);
    ok is None where a target does not apply (fewer than 100 robots for the time)."""
    used, b0 = s.get("robots_used") or 0, s.get("euler_bound_d0")
    r0 = used / b0 if b0 else None
    over = s.get("s_per_robot_over_floor")
    big = used >= PROPOSED_OVER_FLOOR_MIN_ROBOTS
    return {
        f"robots / bound at d0 <= {PROPOSED_PER_BOUND_D0_MAX}": (
            f"{used} / {b0} = {r0:.2f}" if r0 is not None else "-",
            bool(s.get("certified")) and r0 is not None and r0 <= PROPOSED_PER_BOUND_D0_MAX),
        f"s / robot over floor <= {PROPOSED_OVER_FLOOR_MAX} (>= {PROPOSED_OVER_FLOOR_MIN_ROBOTS} robots)": (
            f"{over:.2f}" if over is not None else "-",
            (over is not None and over <= PROPOSED_OVER_FLOOR_MAX) if big else None),
    }


def table(results: list[dict]) -> str:
    """One markdown table over configs and seeds, targets marked ok/MISS."""
    heads = list(targets({}).keys()) + [f"proposed: {h}" for h in proposed({})]
    lines = ["| config | seed | stop | " + " | ".join(heads)
             + " | cycles | push floor s (move + entry) |",
             "|---|---|---|" + "---|" * len(heads) + "---|---|"]
    mark = {True: "ok", False: "MISS", None: "n/a"}
    for s in results:
        verdicts = list(targets(s).values()) + list(proposed(s).values())
        cells = [f"{v} {mark[ok]}" for v, ok in verdicts]
        fl = s.get("push_floor_s")
        fl_txt = (f"{fl:.1f} ({s.get('move_s'):.1f} + {s.get('enter_s'):.1f})"
                  if fl is not None else "-")
        lines.append(f"| {s.get('name')} | {s.get('seed')} | {s.get('stop_reason', '-')} | "
                     + " | ".join(cells) + f" | {s.get('cycles')} | {fl_txt} |")
    return "\n".join(lines)


SAME = ("certified", "robots_used", "cycles", "sim_time_s")


def agreement(inproc: dict, dist: dict) -> dict:
    """One config and seed both ways: do they agree, and the wall-time ratio."""
    same = all(inproc.get(k) == dist.get(k) if k != "sim_time_s"
               else abs((inproc.get(k) or 0) - (dist.get(k) or 0)) < 1e-6 for k in SAME)
    wi, wd = inproc.get("wall_time_s"), dist.get("wall_time_s")
    return {"name": dist.get("name"), "seed": dist.get("seed"), "same": same,
            **{f"{k}_inproc": inproc.get(k) for k in SAME},
            **{f"{k}_distributed": dist.get(k) for k in SAME},
            "wall_inproc_s": wi, "wall_distributed_s": wd,
            "wall_ratio": round(wd / wi, 2) if wi and wd else None}


def agreement_table(pairs: list[dict]) -> str:
    lines = ["| config | seed | same | robots | cycles | sim s | wall in-process / "
             "distributed (s) | ratio |", "|---|---|---|---|---|---|---|---|"]
    for p in pairs:
        cell = (lambda k: f"{p[k + '_inproc']}" if p[k + "_inproc"] == p[k + "_distributed"]
                else f"{p[k + '_inproc']} / {p[k + '_distributed']}")
        wi, wd = p["wall_inproc_s"] or 0, p["wall_distributed_s"] or 0
        lines.append(f"| {p['name']} | {p['seed']} | {'yes' if p['same'] else 'NO'} | "
                     f"{cell('robots_used')} | {cell('cycles')} | {cell('sim_time_s')} | "
                     f"{wi:.0f} / {wd:.0f} | {p['wall_ratio']} |")
    return "\n".join(lines)


def _inproc_reason(res) -> str:
    """summary.json's stop_reason for an in-process run."""
    why = res.stop_reason or ""
    if res.certified:
        return "certified"
    if why.startswith("max_wall_s"):
        return "wall_timeout"
    return "robots_max" if "robots_max" in why else "no_progress"


def check(name: str, s: dict) -> list[str]:
    """Target verdicts for one run, as text."""
    out = [f"{k}: {v} ({'ok' if ok else 'MISS'})" for k, (v, ok) in targets(s).items()]
    cov = s.get("coverage", 0.0)
    out.append(f"coverage {100 * cov:.2f}% ({'ok' if cov >= 0.995 else 'MISS'} >= 99.5%)")
    rs = s.get("ratio_same_spacing")
    lim = {"open_room": 1.10, "structured": 1.15}.get(name)
    if rs is not None:
        out.append(f"ratio_same_spacing {rs:.2f}" + (f" ({'ok' if rs <= lim else 'MISS'} <= {lim})"
                                                       if lim else ""))
    r = s.get("ratio")
    if r is not None:
        out.append(f"ratio {r:.2f}" + (f" ({'ok' if r <= 1.35 else 'MISS'} <= 1.35)"
                                       if name == "open_room" else ""))
    c, n = s.get("cycles", 0), s.get("robots_used", 0)
    out.append(f"cycles {c} vs 0.5 x robots {0.5 * n:.0f} ({'ok' if c <= 0.5 * n else 'MISS'})")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("configs", nargs="*", help="default: configs/*.toml except mixed.toml")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--inproc", action="store_true", help="one process (swarmcover.simloop)")
    p.add_argument("--both", action="store_true",
                   help="each run in-process and distributed; report agreement and wall ratio")
    p.add_argument("--timeout", type=float, default=3600.0, help="wall seconds per run")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="with --inproc: override a [coordinator] field, e.g. door_min_rv=0.3 "
                        "(a TOML value; checked like the config's own)")
    p.add_argument("--dropout", type=float, default=None, metavar="P",
                   help="with --inproc: [sensing] dropout for every config (each sighting of "
                        "each camera frame lost with probability P, 0 <= P < 1)")
    args = p.parse_args(argv)
    if args.dropout is not None and not (0.0 <= args.dropout < 1.0):
        p.error(f"--dropout {args.dropout}: expected 0 <= P < 1")
    if args.dropout is not None and not args.inproc:
        p.error("--dropout needs --inproc (a distributed run reads [sensing] from its config)")
    overrides = {}
    for item in args.set:
        import tomllib
        name, eq, val = item.partition("=")
        try:
            overrides.update(tomllib.loads(f"{name.strip()} = {val.strip()}") if eq else {None: 0})
        except tomllib.TOMLDecodeError as e:
            p.error(f"--set {item!r}: not FIELD=VALUE with a TOML value ({e})")
        if None in overrides:
            p.error(f"--set {item!r}: not FIELD=VALUE")
    if overrides and not args.inproc:
        p.error("--set needs --inproc (a distributed run reads [coordinator] from its config)")
    if args.both and args.inproc:
        p.error("--both runs in-process and distributed: drop --inproc")
    configs = args.configs or sorted(str(c.relative_to(ROOT)) for c in (ROOT / "configs").glob("*.toml")
                                     if c.name != "mixed.toml")
    results, pairs = [], []
    t0 = time.monotonic()
    modes = ["inproc", "distributed"] if args.both else \
        ["inproc" if args.inproc else "distributed"]
    for k, config in enumerate(configs):
        name = Path(config).stem
        for seed, mode in ((seed, mode) for seed in args.seeds for mode in modes):
            print(f"[{k + 1}/{len(configs)}] {name} seed {seed} ({mode}) ... "
                  f"elapsed {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
            if mode == "inproc":
                s = run_inproc(config, seed, args.timeout, overrides, args.dropout)
            else:
                with tempfile.TemporaryDirectory() as d:
                    s = run_distributed(config, seed, Path(d) / "run", args.timeout)
            s["name"] = name
            s.setdefault("seed", seed)
            s.setdefault("mode", mode)
            results.append(s)
            if args.both and mode == "distributed":
                pairs.append(agreement(results[-2], s))
            ms = s.get("mean_spacing")
            print(f"  {name} seed {seed}: certified={s['certified']} ({s.get('stop_reason')}) "
                  f"robots_used={s['robots_used']} euler_bound={s.get('euler_bound')} "
                  f"ideal={s['ideal_count']} ideal_same_spacing={s.get('ideal_count_same_spacing')} "
                  f"mean_spacing={'-' if ms is None else f'{ms:.3f}'} cycles={s['cycles']} "
                  f"sim={s['sim_time_s']:.0f}s wall={s['wall_time_s']:.0f}s", flush=True)
            for line in check(name, s):
                print(f"    {line}", flush=True)
    keys = ("name", "seed", "certified", "stop_reason", "robots_used", "robots_spawned",
            "euler_bound",
            "robots_per_bound", "d0_m", "euler_bound_d0", "robots_per_bound_d0",
            "sim_s_per_robot", "ideal_count", "ratio", "mean_spacing",
            "ideal_count_same_spacing", "ratio_same_spacing", "coverage", "coverage_complex",
            "false_certificate",
            "uncovered_reachable_m2", "cycles", "sim_time_s", "wall_time_s", "mode",
            "move_s", "enter_s", "push_floor_s", "s_per_robot_over_floor", "dropout")
    print(table(results), flush=True)
    if pairs:
        print(agreement_table(pairs), flush=True)
    from swarmcover.run import strict_json
    print(strict_json({"bench": "coverage", "overrides": overrides, "dropout": args.dropout,
                       "runs": [dict({k: s.get(k) for k in keys},
                                     fence_audit=(s.get("fence_audit") or {}).get("by_why"))
                                for s in results],
                       "both": pairs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

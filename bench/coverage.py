"""Coverage benchmark: every config in configs/ (or those named), lockstep, fixed seeds.

Default: the real distributed system (`swarmcover run --lockstep`, one process per robot).
``--inproc``: the same parts in one process (swarmcover.simloop), about 10x faster, for
tuning. Prints each run's numbers against the targets, progress on stderr, and one JSON
object as the last line.

    python bench/coverage.py                       # all configs, distributed
    python bench/coverage.py configs/small.toml --inproc --seeds 0 1 2

Targets (issue 6): coverage >= 99.5% everywhere; ratio_same_spacing <= 1.10 (open_room),
<= 1.15 (structured); ratio <= 1.35 (open_room); cycles <= 0.5 x robots used.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

def run_distributed(config: str, seed: int, out: Path, timeout: float) -> dict:
    cmd = [sys.executable, "-m", "swarmcover", "run", config, "--lockstep", "--seed", str(seed),
           "--out", str(out), "--quiet", "--port", str(_free_port()), "--wall-timeout", str(timeout)]
    subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   timeout=timeout + 120)
    return json.loads((out / "summary.json").read_text())


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_inproc(config: str, seed: int, timeout: float) -> dict:
    from bus.messages import Truth
    from swarmcover.run import compute_summary
    from swarmcover.simloop import SimLoop
    from world.config import load_config
    cfg = load_config(config)
    sim = SimLoop(cfg, seed=seed)
    t0 = time.monotonic()
    res = sim.run(max_sim_s=20_000, max_wall_s=timeout)
    ids = sorted(r for r in res.positions if r in sim.agents)
    truth = Truth(ids=ids, x=[res.positions[r][0] for r in ids],
                  y=[res.positions[r][1] for r in ids], theta=[0.0] * len(ids),
                  live=[False] * len(ids), t=res.sim_time_s)
    extra = dict(certified=res.certified, cycles=res.cycles, sim_time_s=res.sim_time_s,
                 wall_time_s=time.monotonic() - t0, robots_spawned=res.robots_spawned,
                 failures_healed=res.deployer.failures_healed, config=config, seed=seed,
                 mode="inproc")
    return compute_summary(cfg, sim.wm, truth, res.final, extra)


def check(name: str, s: dict) -> list[str]:
    """Target verdicts for one run, as text."""
    out = []
    cov = s.get("coverage", 0.0)
    out.append(f"coverage {100 * cov:.2f}% ({'ok' if cov >= 0.995 else 'MISS'} >= 99.5%)")
    rs = s.get("ratio_same_spacing")
    lim = {"open_room": 1.10, "structured": 1.15}.get(name)
    if rs is not None:
        out.append(f"ratio_same_spacing {rs:.2f}" + (f" ({'ok' if rs <= lim else 'MISS'} <= {lim})"
                                                       if lim else ""))
    r = s.get("ratio")
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
    p.add_argument("--timeout", type=float, default=3600.0, help="wall seconds per run")
    args = p.parse_args(argv)
    configs = args.configs or sorted(str(c.relative_to(ROOT)) for c in (ROOT / "configs").glob("*.toml")
                                     if c.name != "mixed.toml")
    results = []
    t0 = time.monotonic()
    for k, config in enumerate(configs):
        name = Path(config).stem
        for seed in args.seeds:
            print(f"[{k + 1}/{len(configs)}] {name} seed {seed} "
                  f"({'in-process' if args.inproc else 'distributed'}) ... "
                  f"elapsed {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
            if args.inproc:
                s = run_inproc(config, seed, args.timeout)
            else:
                with tempfile.TemporaryDirectory() as d:
                    s = run_distributed(config, seed, Path(d) / "run", args.timeout)
            s["name"] = name
            results.append(s)
            print(f"  {name} seed {seed}: certified={s['certified']} robots_used={s['robots_used']} "
                  f"ideal={s['ideal_count']} ideal_same_spacing={s.get('ideal_count_same_spacing')} "
                  f"mean_spacing={s['mean_spacing']:.3f} cycles={s['cycles']} "
                  f"sim={s['sim_time_s']:.0f}s wall={s['wall_time_s']:.0f}s", flush=True)
            for line in check(name, s):
                print(f"    {line}", flush=True)
    keys = ("name", "seed", "certified", "robots_used", "ideal_count", "ratio", "mean_spacing",
            "ideal_count_same_spacing", "ratio_same_spacing", "coverage", "cycles", "sim_time_s",
            "wall_time_s", "mode")
    print(json.dumps({"bench": "coverage", "runs": [{k: s.get(k) for k in keys} for s in results]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

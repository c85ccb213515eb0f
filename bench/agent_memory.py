"""Benchmark: what one idle ``swarmcover agent`` process imports and holds in memory.

Starts a real router and N real agent processes (``python -m swarmcover agent``, as the
supervisor starts them) connected to it, waits until every agent is READY and then a few
seconds more (Zenoh's threads settle, one heartbeat Status goes out), and reads each agent's
/proc/<pid>/smaps_rollup: RSS (resident), PSS (proportional set size: a page shared by k
processes counts 1/k in each) and USS (private pages only). It does this for each N asked
(default 1 and 20): RSS stays flat with N, PSS falls towards USS as the shared pages
(libpython, zenoh's and msgpack's .so files) are split over more agents; PSS at large N is
what each further agent costs.

Agents start as ``swarmcover run`` starts them: ``--run-config FILE`` (default
configs/open_room.toml; ``--run-config ''`` starts them with ``--info-timeout 0`` instead).
No world runs, so they hold with no task: the idle robot.

For scale it measures two reference processes on the same router (``floor``): a bare
interpreter that sleeps, and one that only imports zenoh and opens a client session. The
agent's USS minus the session's is what the agent's own code and state hold.

It also reports the import side, in fresh interpreters: how many modules ``import
agents.node`` loads, which heavy libraries (numpy, scipy, pymunk, matplotlib, PIL) it pulls
in (and which are mapped in the live agents, from /proc/<pid>/maps), and its import cost:
``-X importtime`` wall time and the CPU time of ``python -c "import swarmcover.agents.node"`` minus
that of ``python -c pass``, each the best of a few tries (the box is shared, the best is the
least disturbed). Every child runs with a bytecode cache in a temporary directory
(PYTHONPYCACHEPREFIX), as a deployed install has, even if PYTHONDONTWRITEBYTECODE is set;
``--no-pyc`` runs them with no cache at all (PYTHONDONTWRITEBYTECODE=1: every agent compiles
the project's sources at start, as on a machine that sets it).

    python bench/agent_memory.py [--n 1 20] [--settle-s 3]   (the venv's python, repo root)

Progress goes to stderr; the last line on stdout is one JSON object. Numbers only, nothing
is asserted.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.common import eprint, router_and_starter, wait_line  # noqa: E402

HEAVY = ("numpy", "scipy", "pymunk", "matplotlib", "PIL", "shapely", "networkx")

_PROBE = """
import sys
base = set(sys.modules)
import swarmcover.agents.node
new = sorted(set(sys.modules) - base)
print("\\t".join(new))
"""


def smaps_kb(pid: int) -> dict[str, int]:
    """The kB fields of /proc/<pid>/smaps_rollup (Rss, Pss, Private_Dirty, ...)."""
    out = {}
    with open(f"/proc/{pid}/smaps_rollup") as f:
        for line in f:
            m = re.match(r"(\w+):\s+(\d+) kB", line)
            if m:
                out[m.group(1)] = int(m.group(2))
    return out


def memory_mb(pid: int) -> dict[str, float]:
    s = smaps_kb(pid)
    uss = s.get("Private_Clean", 0) + s.get("Private_Dirty", 0)
    return {"rss": s["Rss"] / 1024, "pss": s["Pss"] / 1024, "uss": uss / 1024,
            "pss_anon": s.get("Pss_Anon", 0) / 1024, "pss_file": s.get("Pss_File", 0) / 1024}


def heavy_mapped(pid: int) -> list[str]:
    """Heavy packages with a file of their package directory mapped into ``pid``."""
    with open(f"/proc/{pid}/maps") as f:
        maps = f.read()
    return [h for h in HEAVY if f"/{h}/" in maps]


def _child_cpu_s(argv, env) -> float:
    """CPU seconds (user + system) one child process used, run to completion."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(argv, env=env, cwd=str(ROOT), timeout=60, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def import_profile(py: str, env: dict, tries: int) -> dict:
    """Modules ``import agents.node`` adds, and its import cost (best of ``tries``)."""
    # fill the bytecode cache with what an agent started by `run` imports
    subprocess.run([py, "-c", "import swarmcover.cli, swarmcover.agents.node, swarmcover.world.config"], env=env,
                   cwd=str(ROOT), timeout=60, check=True)
    r = subprocess.run([py, "-c", _PROBE], capture_output=True, text=True, env=env,
                       cwd=str(ROOT), timeout=60, check=True)
    mods = [m for m in r.stdout.strip().split("\t") if m]
    tops = sorted({m.split(".")[0] for m in mods})
    wall, cpu_imp, cpu_bare = [], [], []
    for _ in range(tries):
        r = subprocess.run([py, "-X", "importtime", "-c", "import swarmcover.agents.node"],
                           capture_output=True, text=True, env=env, cwd=str(ROOT),
                           timeout=60, check=True)
        last = [ln for ln in r.stderr.splitlines() if ln.rstrip().endswith("| swarmcover.agents.node")]
        wall.append(int(last[-1].split("|")[1]) / 1000.0)
        cpu_imp.append(_child_cpu_s([py, "-c", "import swarmcover.agents.node"], env))
        cpu_bare.append(_child_cpu_s([py, "-c", "pass"], env))
    return {"modules_added": len(mods), "top_level_packages": tops,
            "heavy_imported": [h for h in HEAVY if h in tops],
            "import_ms_best": round(min(wall), 1),
            "import_ms_median": round(statistics.median(wall), 1),
            "import_cpu_ms_best": round(1e3 * (min(cpu_imp) - min(cpu_bare)), 1)}


_SESSION_ONLY = """
import argparse, sys, time
from swarmcover.bus.session import add_zenoh_args, open_session
p = argparse.ArgumentParser()
add_zenoh_args(p)
s = open_session(p.parse_args(sys.argv[1:]))
print("READY session", flush=True)
time.sleep(600)
"""


def floor(py: str, env: dict, settle_s: float) -> dict:
    """USS/PSS of a sleeping bare interpreter and of one holding only a Zenoh session."""
    with router_and_starter(py, env, str(ROOT)) as (start, ep, _):
        bare = start([py, "-c", "print('READY bare', flush=True); import time; time.sleep(600)"])
        sess = start([py, "-c", _SESSION_ONLY, "--connect", ep, "--swarm", f"floor{os.getpid()}"])
        wait_line(bare, "READY bare")
        wait_line(sess, "READY session")
        time.sleep(settle_s)
        out = {}
        for name, p in (("bare_interpreter", bare), ("zenoh_session_only", sess)):
            m = memory_mb(p.pid)
            out[name] = {k: round(m[k], 2) for k in ("rss", "pss", "uss")}
    return out


def measure(n: int, py: str, env: dict, run_config: str, settle_s: float) -> dict:
    """Start a router and n agents, let them idle, read their memory; stop them all."""
    swarm = f"mem{os.getpid()}n{n}"
    with router_and_starter(py, env, str(ROOT)) as (start, ep, router):
        how = ["--run-config", run_config] if run_config else ["--info-timeout", "0"]
        agents = [start([py, "-m", "swarmcover", "agent", "--id", str(k), "--log-level",
                         "WARNING", "--connect", ep, "--swarm", swarm, *how])
                  for k in range(n)]
        for a in agents:
            wait_line(a, "READY agent", timeout=60 + 3 * n)
        time.sleep(settle_s)
        per = [memory_mb(a.pid) for a in agents]
        router_mb = memory_mb(router.pid)
        heavy = sorted({h for a in agents for h in heavy_mapped(a.pid)})
        threads = len(os.listdir(f"/proc/{agents[0].pid}/task"))
    res = {"agents": n, "heavy_mapped": heavy, "threads_per_agent": threads}
    for k in ("rss", "pss", "uss", "pss_anon", "pss_file"):
        res[f"{k}_mb_per_agent"] = round(statistics.mean(x[k] for x in per), 2)
    res["pss_mb_sum"] = round(sum(x["pss"] for x in per), 1)
    res["router_pss_mb"] = round(router_mb["pss"], 1)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, nargs="+", default=[1, 20], help="agent counts")
    ap.add_argument("--settle-s", type=float, default=3.0,
                    help="seconds idle after the last READY before reading memory")
    ap.add_argument("--run-config", default="configs/open_room.toml",
                    help="run config the agents read ('' for --info-timeout 0)")
    ap.add_argument("--import-tries", type=int, default=5)
    ap.add_argument("--no-pyc", action="store_true",
                    help="no bytecode cache for the children (PYTHONDONTWRITEBYTECODE=1)")
    args = ap.parse_args(argv)
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="agent_memory_pyc") as pyc:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        if args.no_pyc:
            env["PYTHONDONTWRITEBYTECODE"] = "1"
            env.pop("PYTHONPYCACHEPREFIX", None)
        else:
            env["PYTHONPYCACHEPREFIX"] = pyc
            env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
        result: dict = {"bench": "agent_memory", "run_config": args.run_config or None,
                        "bytecode_cache": not args.no_pyc}
        result["imports"] = imp = import_profile(py, env, args.import_tries)
        eprint(f"imports: {imp}")
        result["floor"] = fl = floor(py, env, args.settle_s)
        eprint(f"floor: {fl}")
        rows = []
        for n in args.n:
            row = measure(n, py, env, args.run_config, args.settle_s)
            eprint(f"N={n}: {row}")
            rows.append(row)
    result["memory"] = rows
    first, last = rows[0], rows[-1]
    result["agent_uss_over_session_uss"] = round(
        first["uss_mb_per_agent"] / fl["zenoh_session_only"]["uss"], 3)
    result["agent_own_uss_mb"] = round(
        first["uss_mb_per_agent"] - fl["zenoh_session_only"]["uss"], 2)
    if len(rows) > 1:
        result["pss_ratio_last_over_first"] = round(last["pss_mb_per_agent"]
                                                    / first["pss_mb_per_agent"], 3)
    # RSS - USS: the pages one agent shares (libpython, zenoh's .so, ...); PSS -> USS as N grows
    result["shared_mb_per_agent"] = round(first["rss_mb_per_agent"]
                                          - first["uss_mb_per_agent"], 2)
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
